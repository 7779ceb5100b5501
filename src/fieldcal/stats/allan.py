"""The overlapping Allan deviation of rate-type sensor data and the IMU noise model fitted to it.

Estimator
---------
For samples ``y_k`` of one axis at ``rate`` Hz (``τ0 = 1 / rate``) and a cluster of ``m``
samples (``τ = m τ0``), the overlapping Allan variance (IEEE Std 952-1997; NIST SP 1065)
is ::

    σ²(τ) = 1 / (2 M) Σ_k (ȳ_{k+m}(m) − ȳ_k(m))²,       M = n − 2m + 1 terms,

``ȳ_k(m)`` the mean of ``y_k … y_{k+m−1}``. With ``θ`` the cumulative sum of the (centred)
samples, ``m (ȳ_{k+m} − ȳ_k) = θ_{k+2m} − 2 θ_{k+m} + θ_k``, so every cluster size costs three
vectorised passes over the record and one dot product: O(n) per τ on a log-spaced grid of
cluster sizes (``per_decade`` per decade, from ``m = 1`` to ``n // 2``).

Several records (the still stretches of a log, or the runs between NaN rows) are combined by
their cluster counts: their sums of squared differences are added and divided by the total
count ``Σ M_j`` of each τ. A record shorter than ``2m`` samples adds nothing at that τ, so
the long τ come from the long stretches only, and no difference ever spans two stretches (which
concatenating them would do: a step between two poses' means would read as noise).

Confidence
----------
The estimate at each τ is taken as ``σ̂² ~ σ² χ²_ν / ν`` with the equivalent degrees of freedom
``ν`` of the overlapping estimator (the simple approximations of NIST SP 1065), which depend
on the noise type: white rate noise (angle random walk, the ``N`` term), flicker rate noise
(bias instability, ``B``), random-walk rate noise (rate random walk, ``K``). Each record gives
``ν_j``; records combine as ``ν = (Σ M_j)² / Σ (M_j² / ν_j)`` (the variance of the
count-weighted mean). :func:`allan_deviation` assumes white noise; the fit replaces it by the
EDF of the term that dominates the fitted model at each τ. The band is the central
``confidence`` interval (default 68.3 %, one standard deviation) of the χ² law.

Noise model
-----------
:func:`fit_noise_model` fits, per axis, ::

    σ²(τ) = N² / τ + B² · (2 ln 2 / π) + K² τ / 3

by non-negative weighted least squares in ``(N², B², K²)``, iterated with the weights of the
fitted model: ``N`` is the −½-slope line read at τ = 1 s
(rate/√Hz), ``K`` the +½-slope line read at τ = 3 s (rate/s/√Hz), ``B`` the flat floor over
0.664 (rate). The fit rather than the classic slope-line reads of IEEE Std 952, because it uses
every τ the data support, reads N and K where the curve never shows a clean ±½ segment (the
three terms overlap in short records), and gives standard errors.

The estimates at neighbouring τ share samples and are strongly correlated (a random walk's at
τ and 2τ by 0.89), so standard errors that take them as independent would be several times too
small. The standard errors are the least-squares sandwich with the covariance of the estimates:
variances ``2 σ⁴ / ν`` and, between τ_i and τ_j, the correlation of the two estimates for each
noise type in the long-record limit, a function of ``|log2(τ_j / τ_i)|`` only
(:func:`correlation`, tabulated from the estimator's frequency response), mixed over the types
by their shares of the model. (That covariance is not used to weigh the fit itself: with
errors so correlated and a model that real sensors follow only roughly, generalised least
squares can land beside every point, Peelle's puzzle.) ``benchmarks/noise.py`` checks the
intervals' coverage on simulated records.

The fitted τ range is stated in the result: from the shortest τ (raised by octaves while the
data there lie clearly below what the longer τ predict, the sign of a low-pass filter before
sampling) to the
longest τ at which the records still hold :data:`MIN_WINDOWS` non-overlapping clusters.

Rate samples rounded to a step (quantisation) are white rate noise and fold into ``N``; the
angle-quantisation (τ⁻¹), rate-ramp (τ⁺¹) and sinusoidal terms of IEEE Std 952 are not
modelled.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._frozen import ArrayDataclass, frozen_array
from ..errors import InputError

__all__ = [
    "FLICKER",
    "MIN_WINDOWS",
    "NOISE_TYPES",
    "AllanDeviation",
    "NoiseModel",
    "allan_deviation",
    "chi2_quantile",
    "cluster_sizes",
    "correlation",
    "equivalent_dof",
    "fit_noise_model",
]

Array = NDArray[np.float64]

#: ``2 ln 2 / π``: the flicker (bias instability) term of the Allan variance is ``B² · FLICKER``,
#: so the flat floor of the Allan deviation is ``0.664 B``.
FLICKER = 2.0 * math.log(2.0) / math.pi
#: The noise types of the model, in the order of its parameters ``(N², B², K²)``.
NOISE_TYPES = ("white", "flicker", "random_walk")
#: The fit stops at the longest τ for which the records hold this many non-overlapping clusters
#: (the EDF there is about 10 for white noise, 5 for a random walk: ±25-35 % on σ at 1σ).
MIN_WINDOWS = 8
#: Shortest run of finite samples used (one difference at m = 1 needs two samples).
_SHORTEST = 2
#: The low-pass check: the shortest fitted τ is dropped while its Allan variance lies below the
#: model fitted from the next octave on by more than this fraction and by more than three
#: standard errors of the difference.
_LOW_PASS = 0.02


# --------------------------------------------------------------------------- the χ² law
def _chi2_cdf_series(x: Array, dof: Array) -> Array:
    """P(χ²_ν ≤ x) for ν ≤ 30 by the series of the regularised lower incomplete gamma
    function, ``P(a, z) = z^a e^{−z} / Γ(a + 1) Σ_k z^k / ((a + 1) … (a + k))``, ``a = ν / 2``,
    ``z = x / 2``: enough terms for the z searched (below 100)."""
    a, z = dof / 2.0, np.maximum(x, 0.0) / 2.0
    term = np.ones_like(z)
    total = np.ones_like(z)
    for k in range(1, 400):
        term = term * z / (a + k)
        total += term
        if k % 8 == 0 and np.all(term <= 1e-17 * total):  # checked now and then: it costs
            break
    lgamma = np.vectorize(math.lgamma, otypes=[float])(a + 1.0)
    with np.errstate(divide="ignore"):
        log_p = a * np.log(z) - z - lgamma + np.log(total)
    return np.minimum(np.exp(log_p), 1.0)


def chi2_quantile(p: float, dof: ArrayLike) -> Array:
    """Quantile ``p`` of the χ² law with ``dof`` (any positive, real) degrees of freedom.

    Exact (bisection on the regularised incomplete gamma function) up to 30 degrees of
    freedom; above, the Wilson-Hilferty cube-root normal approximation, whose relative error
    there is below 1e-3 for p from 0.02 to 0.98.

    Parameters
    ----------
    p : float
        Probability in (0, 1).
    dof : array_like
        Degrees of freedom, positive.

    Returns
    -------
    ndarray
        The quantiles, the shape of ``dof``.
    """
    nu = np.asarray(dof, dtype=float)
    if not 0.0 < p < 1.0:
        raise ValueError(f"p must be in (0, 1), got {p!r}")
    if not np.all(nu > 0):
        raise ValueError("degrees of freedom must be positive")
    z = statistics.NormalDist().inv_cdf(p)
    h = 2.0 / (9.0 * nu)
    out = nu * np.maximum(1.0 - h + z * np.sqrt(h), 0.0) ** 3
    small = nu <= 30.0
    if np.any(small):
        out[small] = [_QUANTILES.get((p, v), math.nan) for v in nu[small].tolist()]
        todo = np.unique(nu[small][np.isnan(out[small])])
        if todo.size:
            lo = np.zeros_like(todo)
            hi = todo + 20.0 * np.sqrt(todo) + 40.0  # above every quantile below 1 − 1e-12
            for _ in range(52):  # bisection to the float's precision
                mid = 0.5 * (lo + hi)
                below = _chi2_cdf_series(mid, todo) < p
                lo = np.where(below, mid, lo)
                hi = np.where(below, hi, mid)
            if len(_QUANTILES) > 100_000:  # a bounded memo: the same EDFs recur in a session
                _QUANTILES.clear()
            _QUANTILES.update(
                zip(((p, v) for v in todo.tolist()), (0.5 * (lo + hi)).tolist(), strict=True)
            )
            out[small] = [_QUANTILES[(p, v)] for v in nu[small].tolist()]
    return out


#: Exact χ² quantiles already computed, by (p, dof).
_QUANTILES: dict[tuple[float, float], float] = {}


# --------------------------------------------------------------------------- EDF
def equivalent_dof(lengths: ArrayLike, m: ArrayLike, noise: str = "white") -> Array:
    """Equivalent degrees of freedom of the overlapping Allan variance over several records.

    Per record of ``n`` samples (``N = n + 1`` phase points) and cluster size ``m``, the simple
    approximations of NIST SP 1065 for the overlapping estimator:

    - ``"white"`` (white rate noise): ``(3(N−1)/(2m) − 2(N−2)/N) · 4m² / (4m² + 5)``;
    - ``"flicker"``: ``2(N−2)² / (2.3N − 4.9)`` for ``m = 1``, else ``5N² / (4m(N + 3m))``;
    - ``"random_walk"``: ``(N−2)/m · ((N−1)² − 3m(N−1) + 4m²) / (N−3)²``;

    at least 1 (one squared difference). Records combine as ``(Σ M_j)² / Σ (M_j² / ν_j)`` with
    ``M_j = n_j − 2m + 1`` their counts; records shorter than ``2m`` add nothing.

    Parameters
    ----------
    lengths : array_like of int
        Samples in each record.
    m : array_like of int
        Cluster sizes.
    noise : {"white", "flicker", "random_walk"}
        The noise type.

    Returns
    -------
    ndarray
        One EDF per cluster size (0 where no record is long enough).
    """
    if noise not in NOISE_TYPES:
        raise ValueError(f"noise must be one of {', '.join(NOISE_TYPES)}; got {noise!r}")
    n = np.asarray(lengths, dtype=float).reshape(1, -1)
    mm = np.asarray(m, dtype=float).reshape(-1, 1)
    N = n + 1.0
    count = n - 2.0 * mm + 1.0
    used = count >= 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        if noise == "white":
            nu = (3.0 * (N - 1.0) / (2.0 * mm) - 2.0 * (N - 2.0) / N) * (
                4.0 * mm**2 / (4.0 * mm**2 + 5.0)
            )
        elif noise == "flicker":
            nu = np.where(
                mm == 1.0,
                2.0 * (N - 2.0) ** 2 / (2.3 * N - 4.9),
                5.0 * N**2 / (4.0 * mm * (N + 3.0 * mm)),
            )
        else:
            nu = (
                (N - 2.0)
                / mm
                * ((N - 1.0) ** 2 - 3.0 * mm * (N - 1.0) + 4.0 * mm**2)
                / (N - 3.0) ** 2
            )
        nu = np.maximum(np.nan_to_num(nu, nan=1.0), 1.0)
        count = np.where(used, count, 0.0)
        total = count.sum(axis=1)
        spread = np.where(used, count**2 / nu, 0.0).sum(axis=1)
        out = np.where(total > 0, total**2 / np.where(spread > 0, spread, 1.0), 0.0)
    return np.asarray(out, dtype=float).reshape(np.shape(m))


def _band(avar: Array, edf: Array, confidence: float) -> tuple[Array, Array]:
    """Lower and upper Allan deviation of the central ``confidence`` χ² interval."""
    nu = np.maximum(edf, 1.0)
    flat = nu.reshape(-1)
    # the quantiles of each distinct EDF once: many τ share one on long records
    unique, inverse = np.unique(np.round(flat, 6), return_inverse=True)
    q_hi = chi2_quantile(0.5 + confidence / 2.0, unique)[inverse].reshape(nu.shape)
    q_lo = chi2_quantile(0.5 - confidence / 2.0, unique)[inverse].reshape(nu.shape)
    return np.sqrt(avar * nu / q_hi), np.sqrt(avar * nu / q_lo)


# --------------------------------------------------------------------------- the curve
@dataclass(frozen=True, eq=False)
class AllanDeviation(ArrayDataclass):
    """An overlapping Allan deviation curve, one column per axis.

    Attributes
    ----------
    taus : (k,) array
        Averaging times ``τ = m / rate`` in seconds.
    m : (k,) array of int
        Cluster sizes in samples.
    avar : (k, d) array
        Allan variance (units of the data squared).
    counts : (k,) array of int
        Terms summed at each τ over all records (``Σ M_j``).
    edf : (k, d) array
        Equivalent degrees of freedom behind ``lower`` and ``upper``.
    lower, upper : (k, d) arrays
        The ``confidence`` interval of the Allan deviation.
    lengths : tuple of int
        Samples in each record used (runs of finite samples of at least two).
    rate : float
        Samples per second.
    confidence : float
        Probability of the central interval ``lower`` to ``upper``.
    """

    taus: Array
    m: NDArray[np.int64]
    avar: Array
    counts: NDArray[np.int64]
    edf: Array
    lower: Array
    upper: Array
    lengths: tuple[int, ...]
    rate: float
    confidence: float

    @property
    def adev(self) -> Array:
        """The Allan deviation ``√avar`` (units of the data)."""
        return np.sqrt(self.avar)

    def windows(self) -> NDArray[np.int64]:
        """Non-overlapping clusters the records hold at each τ: ``Σ_j ⌊n_j / m⌋``."""
        n = np.asarray(self.lengths, dtype=np.int64)
        return np.asarray((n[None, :] // self.m[:, None]).sum(axis=1), dtype=np.int64)

    def with_edf(self, edf: ArrayLike) -> AllanDeviation:
        """The same curve with its band recomputed from ``edf`` ((k, d) or (k,))."""
        nu = np.broadcast_to(np.asarray(edf, dtype=float), self.avar.shape)
        lower, upper = _band(self.avar, nu, self.confidence)
        return dataclasses.replace(
            self, edf=frozen_array(nu), lower=frozen_array(lower), upper=frozen_array(upper)
        )


def _records(data: object) -> list[Array]:
    """The records of ``data`` as 2-D float arrays of one width (a record: an (n,) or (n, d)
    array; a list or tuple of them: several records; a list of numbers: one record)."""
    if isinstance(data, np.ndarray) or not isinstance(data, Sequence) or isinstance(data, str):
        items: list[object] = [data]
    elif len(data) and all(np.ndim(x) == 0 for x in data):
        items = [data]
    else:
        items = list(data)
    out: list[Array] = []
    for i, item in enumerate(items):
        try:
            array = np.asarray(item, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(
                f"record {i} of the data cannot be read as numbers; give (n,) or (n, d) arrays"
            ) from None
        if array.ndim == 1:
            array = array[:, None]
        if array.ndim != 2:
            raise InputError(
                f"record {i} has shape {list(array.shape)}; give (n,) or (n, d) arrays of samples"
            )
        out.append(array)
    widths = {a.shape[1] for a in out}
    if len(widths) > 1:
        raise InputError(
            f"the records have different numbers of axes ({sorted(widths)}); give one sensor's "
            "axes in every record"
        )
    return out


def _runs(records: list[Array]) -> list[Array]:
    """Runs of rows finite on every axis, of at least :data:`_SHORTEST` rows: a NaN or inf
    breaks the record (no difference spans it)."""
    runs: list[Array] = []
    for record in records:
        if record.size == 0:
            continue
        finite = np.isfinite(record).all(axis=1)
        if finite.all():
            if len(record) >= _SHORTEST:
                runs.append(record)
            continue
        edges = np.diff(np.concatenate([[0], finite.astype(np.int8), [0]]))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        runs.extend(record[a:b] for a, b in zip(starts, stops, strict=True) if b - a >= _SHORTEST)
    return runs


def _positive(value: object, name: str) -> float:
    ok = not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, float, np.number))
    number = float(value) if ok else math.nan  # type: ignore[arg-type]  # checked just above
    if not (math.isfinite(number) and number > 0):
        raise InputError(f"{name} must be a positive finite number, got {value!r}"[:200])
    return number


def cluster_sizes(longest: int, per_decade: float = 10) -> NDArray[np.int64]:
    """Log-spaced cluster sizes from 1 to ``longest // 2`` (the largest with one term),
    about ``per_decade`` per decade, each once."""
    top = max(longest // 2, 1)
    count = max(2, math.ceil(per_decade * math.log10(top)) + 1) if top > 1 else 1
    m = np.unique(np.round(np.logspace(0.0, math.log10(top), count)).astype(np.int64))
    return m[(m >= 1) & (m <= top)]


def allan_deviation(
    data: ArrayLike | Sequence[ArrayLike],
    rate: float,
    *,
    per_decade: float = 10,
    confidence: float = 0.683,
) -> AllanDeviation:
    """The overlapping Allan deviation of one record or of several, combined by cluster counts.

    Parameters
    ----------
    data : (n,) or (n, d) array, or a list of them
        Rate samples (a gyroscope's angular rate, an accelerometer's specific force ...), one
        column per axis. A list holds separate records (still stretches), never differenced
        across; a row with a NaN or inf on any axis splits its record too. Each record's mean
        is irrelevant (the Allan variance ignores a constant), so poses with different
        readings can be given together.
    rate : float
        Samples per second.
    per_decade : float
        Cluster sizes per decade of τ (log-spaced, rounded to whole samples, each once).
    confidence : float
        Probability of the band ``lower``-``upper`` (white-noise EDF here; see
        :func:`fit_noise_model` for the model's).

    Returns
    -------
    AllanDeviation

    Raises
    ------
    InputError
        No run of two finite samples, a rate or option out of range, records of different
        widths.
    """
    rate = _positive(rate, "rate")
    per_decade = _positive(per_decade, "per_decade")
    confidence = _positive(confidence, "confidence")
    if confidence >= 1:
        raise InputError(f"confidence must be in (0, 1), got {confidence!r}")
    runs = _runs(_records(data))
    if not runs:
        raise InputError(
            f"no run of at least {_SHORTEST} finite samples; the Allan deviation needs "
            "consecutive samples"
        )
    lengths = np.array([len(r) for r in runs], dtype=np.int64)
    longest = int(lengths.max())
    m = cluster_sizes(longest, per_decade)
    d = runs[0].shape[1]
    sums = np.zeros((len(m), d))
    counts = np.zeros(len(m), dtype=np.int64)
    theta = np.empty(longest + 1)
    work = np.empty(longest + 1)
    for run in runs:
        n = len(run)
        usable = m[2 * m <= n]
        counts[: len(usable)] += n - 2 * usable + 1
        for axis in range(d):
            # centred, so the running sum stays near zero and keeps its digits
            column = run[:, axis]
            th = theta[: n + 1]
            th[0] = 0.0
            np.cumsum(column - column.mean(), out=th[1:])
            for i, size in enumerate(usable):
                k = int(size)
                length = n + 1 - 2 * k
                buf = work[:length]
                middle = th[k : n + 1 - k]
                np.subtract(th[2 * k :], middle, out=buf)
                np.subtract(buf, middle, out=buf)
                np.add(buf, th[:length], out=buf)
                sums[i, axis] += float(np.dot(buf, buf))
    keep = counts > 0
    m, sums, counts = m[keep], sums[keep], counts[keep]
    avar = sums / (2.0 * (m.astype(float) ** 2 * counts)[:, None])
    edf = np.repeat(equivalent_dof(lengths, m, "white")[:, None], d, axis=1)
    lower, upper = _band(avar, edf, confidence)
    return AllanDeviation(
        taus=frozen_array(m / rate),
        m=_frozen_int(m),
        avar=frozen_array(avar),
        counts=_frozen_int(counts),
        edf=frozen_array(edf),
        lower=frozen_array(lower),
        upper=frozen_array(upper),
        lengths=tuple(int(n) for n in lengths),
        rate=rate,
        confidence=confidence,
    )


def _frozen_int(values: ArrayLike) -> NDArray[np.int64]:
    array = np.array(values, dtype=np.int64)
    array.setflags(write=False)
    return array


# --------------------------------------------------------------------------- the model
def _design(taus: Array) -> Array:
    """Columns of σ²(τ) per unit of ``(N², B², K²)``."""
    t = np.asarray(taus, dtype=float)
    return np.column_stack([1.0 / t, np.full_like(t, FLICKER), t / 3.0])


@dataclass(frozen=True, eq=False)
class NoiseModel(ArrayDataclass):
    """The noise model fitted to an Allan variance curve, per axis (one entry per column).

    Units: ``noise_density`` N in the data's unit × √s (= unit/√Hz), ``random_walk`` K in the
    unit / √s (= unit/s/√Hz), ``bias_instability`` B in the unit. A term fitted at zero has as
    its standard error the square root of its square's standard error: the size the data
    could have detected at one standard error.

    Attributes
    ----------
    noise_density, noise_density_std : (d,) arrays
        N, the −½-slope line read at τ = 1 s, and its standard error.
    bias_instability, bias_instability_std : (d,) arrays
        B, the flat floor over 0.664.
    random_walk, random_walk_std : (d,) arrays
        K, the +½-slope line read at τ = 3 s.
    tau_range : (float, float)
        Shortest and longest τ fitted (s).
    edf : (k, d) array
        EDF of each τ of the curve for the noise type the fitted model says dominates there.
    covariance : (d, 3, 3) array
        Covariance of ``(N², B², K²)`` (sandwich estimate); a term fitted at zero has only
        its diagonal entry, the variance its square would have if left free.
    reduced_chi2 : (d,) array
        The weighted misfit per degree of freedom, an octave counted as one (about 1 or below
        when the model holds; far above 1: noise the model does not have, a drift or a
        temperature swing, or a filter).
    low_pass : bool
        The shortest τ were left out of the fit because they lie below the white-noise line
        (the sensor filters before sampling).
    """

    noise_density: Array
    noise_density_std: Array
    bias_instability: Array
    bias_instability_std: Array
    random_walk: Array
    random_walk_std: Array
    tau_range: tuple[float, float]
    edf: Array
    covariance: Array
    reduced_chi2: Array
    low_pass: bool = False

    def to_dict(self) -> dict[str, Any]:
        """The fitted values as plain numbers and lists, for JSON."""
        return {
            "noise_density": self.noise_density.tolist(),
            "noise_density_std": self.noise_density_std.tolist(),
            "bias_instability": self.bias_instability.tolist(),
            "bias_instability_std": self.bias_instability_std.tolist(),
            "random_walk": self.random_walk.tolist(),
            "random_walk_std": self.random_walk_std.tolist(),
            "tau_range": list(self.tau_range),
            # NaN (too few τ for a misfit) as null: JSON has no NaN
            "reduced_chi2": [None if math.isnan(v) else v for v in self.reduced_chi2.tolist()],
            "low_pass": self.low_pass,
        }

    def avar(self, taus: ArrayLike) -> Array:
        """(k, d): the fitted Allan variance at ``taus`` (s)."""
        X = _design(np.asarray(taus, dtype=float).reshape(-1))
        p = np.column_stack([self.noise_density, self.bias_instability, self.random_walk]) ** 2
        return X @ p.T


def _nnls3(A: Array, b: Array) -> tuple[Array, NDArray[np.bool_]]:
    """Non-negative least squares ``min ‖A p − b‖, p ≥ 0`` for up to three parameters: every
    subset of free parameters is solved and the best feasible one kept (exact, and cheap for
    seven subsets)."""
    k = A.shape[1]
    best: tuple[float, Array, NDArray[np.bool_]] = (
        float(b @ b),
        np.zeros(k),
        np.zeros(k, dtype=bool),
    )
    for mask_bits in range(1, 2**k):
        free = np.array([(mask_bits >> j) & 1 == 1 for j in range(k)])
        sub = A[:, free]
        scale = np.linalg.norm(sub, axis=0)
        scale[scale == 0] = 1.0
        solution = np.linalg.lstsq(sub / scale, b, rcond=None)[0] / scale
        if np.any(solution < 0):
            continue
        p = np.zeros(k)
        p[free] = solution
        residual = A @ p - b
        cost = float(residual @ residual)
        if cost < best[0]:
            best = (cost, p, free)
    return best[1], best[2]


#: Correlation of two Allan variance estimates ``|log2(m_j / m_i)|`` octaves apart, per noise
#: type, at steps of :data:`_RHO_STEP` octaves from 0 to 8 (beyond, the last step's decay goes
#: on geometrically). Long-record, large-m limit of
#: ``∫ S(f)² |H_i|² |H_j|² df / √(∫ S² |H_i|⁴ df ∫ S² |H_j|⁴ df)``, ``|H_m(f)|² =
#: 4 sin⁴(π m f) / sin²(π f)`` the overlapping estimator's filter and ``S`` the rate's spectrum
#: (white: 1; flicker: 1/f; random walk: 1/(4 sin²(π f))), summed on 2²³ frequencies at
#: m_i = 32 (the values are the same at m_i = 8 to three digits: scale invariance). A test
#: recomputes some of them.
_RHO_STEP = 0.25
_RHO = {
    "white": (
        1.0000, 0.9510, 0.8320, 0.6802, 0.5302, 0.4088, 0.3153, 0.2431, 0.1875, 0.1446,
        0.1115, 0.0860, 0.0663, 0.0511, 0.0394, 0.0304, 0.0234, 0.0181, 0.0139, 0.0107,
        0.0083, 0.0064, 0.0049, 0.0038, 0.0029, 0.0023, 0.0017, 0.0013, 0.0010, 0.0008,
        0.0006, 0.0005, 0.0004,
    ),
    "flicker": (
        1.0000, 0.9743, 0.9037, 0.8030, 0.6893, 0.5771, 0.4745, 0.3850, 0.3093, 0.2465,
        0.1953, 0.1540, 0.1209, 0.0947, 0.0739, 0.0576, 0.0448, 0.0348, 0.0270, 0.0209,
        0.0162, 0.0125, 0.0097, 0.0075, 0.0058, 0.0045, 0.0035, 0.0027, 0.0021, 0.0016,
        0.0012, 0.0009, 0.0007,
    ),
    "random_walk": (
        1.0000, 0.9919, 0.9686, 0.9327, 0.8876, 0.8368, 0.7832, 0.7291, 0.6759, 0.6247,
        0.5762, 0.5306, 0.4880, 0.4484, 0.4118, 0.3781, 0.3469, 0.3183, 0.2920, 0.2679,
        0.2457, 0.2253, 0.2066, 0.1895, 0.1738, 0.1594, 0.1461, 0.1340, 0.1229, 0.1127,
        0.1033, 0.0948, 0.0869,
    ),
}  # fmt: skip


def correlation(noise: str, octaves: ArrayLike) -> Array:
    """Correlation of two overlapping Allan variance estimates ``octaves`` apart
    (``|log2(τ_j / τ_i)|``) for one noise type, in the long-record limit (:data:`_RHO`)."""
    table = np.asarray(_RHO[noise])
    k = np.abs(np.asarray(octaves, dtype=float))
    grid = np.arange(len(table)) * _RHO_STEP
    inside = np.interp(k, grid, table)
    decay = table[-1] / table[-2]
    beyond = table[-1] * decay ** ((k - grid[-1]) / _RHO_STEP)
    return np.where(k <= grid[-1], inside, beyond)


def _dominant_edf(edfs: Array, terms: Array) -> Array:
    """(k,) EDF of the noise type whose term is largest at each τ (``edfs``, ``terms``:
    (k, 3), one column per type)."""
    pick = np.argmax(terms, axis=1)
    return edfs[np.arange(len(pick)), pick]


def _estimate_covariance(m: NDArray[np.int64], model: Array, edf: Array, terms: Array) -> Array:
    """Covariance of the Allan variance estimates at cluster sizes ``m``: variances
    ``2 σ⁴ / ν`` and, between τ, the correlations of :func:`correlation`, mixed over the noise
    types by their shares of the squared model (a sum of positive semi-definite matrices)."""
    sd = np.sqrt(2.0 / edf) * model
    squared = terms**2
    total = squared.sum(axis=1, keepdims=True)
    share = np.where(total > 0, squared / np.where(total > 0, total, 1.0), [1.0, 0.0, 0.0])
    octaves = np.abs(np.subtract.outer(np.log2(m), np.log2(m)))
    cov = np.zeros((len(m), len(m)))
    for t, noise in enumerate(NOISE_TYPES):
        if np.any(share[:, t] > 0):
            w = sd * np.sqrt(share[:, t])
            cov += np.outer(w, w) * correlation(noise, octaves)
    return cov


def _octave_density(m: NDArray[np.int64]) -> Array:
    """Grid points in the octave ``[m/√2, m√2)`` around each cluster size (at least 1)."""
    log = np.log2(m.astype(float))
    lo = np.searchsorted(log, log - 0.5, side="left")
    hi = np.searchsorted(log, log + 0.5, side="left")
    return np.maximum(hi - lo, 1).astype(float)


def _fit_axis(
    X: Array, y: Array, m: NDArray[np.int64], edfs: Array
) -> tuple[Array, NDArray[np.bool_], Array, Array, float]:
    """Iteratively reweighted, non-negative weighted least squares of one axis (the rows to
    fit only), then the sandwich covariance: parameters ``(N², B², K²)``, free mask, their
    covariance, EDF (k,), χ² per degree of freedom.

    The weights are each estimate's inverse variance ``ν / (2 σ⁴)`` (of the model), over the
    grid points in its octave so that a dense stretch of the grid does not outweigh the rest.
    The estimate is not the generalised least-squares one with the full covariance ``C``: with
    errors this correlated and a model that real sensors never follow exactly, GLS can land
    beside every point (Peelle's puzzle); ``C`` gives the standard errors instead,
    ``(Xᵀ W X)⁻¹ Xᵀ W C W X (Xᵀ W X)⁻¹``.
    """
    scale = float(np.median(y)) or 1.0  # variances near one: the algebra below stays in range
    v = y / scale  # v = X (p / scale): the parameters found are over scale
    density = _octave_density(m)
    terms = np.column_stack([v, np.zeros_like(v), np.zeros_like(v)])  # first pass: white
    model = np.maximum(v, np.finfo(float).tiny)
    p = np.full(3, np.nan)
    free = np.ones(3, dtype=bool)
    for _ in range(50):
        edf = _dominant_edf(edfs, terms)
        w = np.sqrt(edf / (2.0 * density)) / model
        new, free = _nnls3(X * w[:, None], v * w)
        terms = X * new[None, :]
        model = np.maximum(X @ new, np.finfo(float).tiny)
        done = np.allclose(new, p, rtol=1e-8, atol=1e-300)
        p = new
        if done:
            break
    edf = _dominant_edf(edfs, terms)
    weight = edf / (2.0 * density) / model**2
    C = _estimate_covariance(m, model, edf, terms)
    cov = np.zeros((3, 3))
    cols = np.sqrt(np.einsum("ij,i,ij->j", X, weight, X))
    cols[cols == 0] = 1.0
    Xn = X / cols  # unit columns: the 1/τ and τ columns differ by orders of magnitude

    def sandwich(idx: NDArray[np.int64]) -> Array:
        A = Xn[:, idx]
        bread = np.linalg.pinv(A.T @ (A * weight[:, None]))
        meat = (A * weight[:, None]).T @ C @ (A * weight[:, None])
        return np.asarray(bread @ meat @ bread / np.outer(cols[idx], cols[idx]))

    idx = np.flatnonzero(free)
    if idx.size:
        cov[np.ix_(idx, idx)] = sandwich(idx)
    # a term at zero: the unconstrained variance of its square, as a detection scale
    full = sandwich(np.arange(3))
    for j in np.flatnonzero(~free):
        cov[j, j] = full[j, j]
    residual = (X @ p - v) * np.sqrt(weight)
    dof = float(np.sum(1.0 / density)) - int(free.sum())
    chi2 = float(residual @ residual) / dof if dof > 0 else math.nan
    return p * scale, free, cov * scale**2, edf, chi2


def fit_noise_model(
    curve: AllanDeviation, *, tau_min: float | None = None, tau_max: float | None = None
) -> NoiseModel:
    """Fit ``σ²(τ) = N²/τ + B² (2 ln 2/π) + K² τ/3`` to each axis of an Allan curve.

    Parameters
    ----------
    curve : AllanDeviation
        From :func:`allan_deviation`.
    tau_min : float, optional
        Shortest τ fitted (s). Default: the shortest of the curve, raised by octaves while the
        data there lie below the model fitted from the next octave on by more than 2 % and
        three standard errors (a sensor that low-pass filters before sampling reads below the
        white-noise line at the shortest τ), keeping three octaves at least.
    tau_max : float, optional
        Longest τ fitted (s). Default: the longest at which the records hold
        :data:`MIN_WINDOWS` non-overlapping clusters.

    Returns
    -------
    NoiseModel

    Raises
    ------
    InputError
        Fewer than three τ in the range.
    """
    taus = np.asarray(curve.taus)
    windows = curve.windows()
    if tau_max is None:
        enough = taus[windows >= MIN_WINDOWS]
        tau_max = float(enough.max()) if enough.size else float(taus.min())
    else:
        tau_max = _positive(tau_max, "tau_max")
    auto = tau_min is None
    low = float(taus.min()) if tau_min is None else _positive(tau_min, "tau_min")
    X = _design(taus)
    edfs = np.column_stack([equivalent_dof(curve.lengths, curve.m, t) for t in NOISE_TYPES])
    y = np.asarray(curve.avar)
    d = y.shape[1]
    low_pass = False
    flat = np.flatnonzero(~np.any(y > 0, axis=0))
    if flat.size:  # a constant signal: nothing to fit (and LAPACK would say so in Fortran)
        raise InputError(
            f"axis {int(flat[0])} of the readings never changes (Allan variance zero at every "
            "τ): no noise to measure; check the column (a stuck sensor or a placeholder)"
        )

    def fit(start: float) -> tuple[NDArray[np.bool_], list[tuple[Any, ...]]]:
        rows = (taus >= start * (1 - 1e-12)) & (taus <= tau_max * (1 + 1e-12))
        if int(rows.sum()) < 3:
            raise InputError(
                f"only {int(rows.sum())} averaging time(s) from {start:.3g} s to {tau_max:.3g} "
                "s: too few to fit the noise model; record longer still stretches (or widen "
                "tau_min/tau_max)"
            )
        m = np.asarray(curve.m)[rows]
        return rows, [_fit_axis(X[rows], y[rows, j], m, edfs[rows]) for j in range(d)]

    rows, fits = fit(low)
    while auto:
        # the shortest τ against the model the next octaves predict: a filter before sampling
        # leaves it low, by a share that shrinks as 1/τ
        later = taus[rows & (taus >= 2.0 * low * (1 - 1e-12))]
        if later.size == 0 or later.min() * 8.0 > tau_max:  # keep three octaves at least
            break
        first = int(np.flatnonzero(rows)[0])
        _, ahead = fit(float(later.min()))
        below = False
        for j, (p, *_) in enumerate(ahead):
            model = float(X[first] @ p)
            relative = y[first, j] / model - 1.0 if model > 0 else 0.0
            sd = math.sqrt(2.0 / max(float(edfs[first, 0]), 1.0))
            below |= relative < -max(_LOW_PASS, 3.0 * math.sqrt(2.0) * sd)
        if not below:
            break
        low, low_pass = float(later.min()), True
        rows, fits = fit(low)
    p_all = np.array([f[0] for f in fits])
    cov = np.array([f[2] for f in fits])
    # the EDF of every τ of the curve (fitted or not) for the type the model says dominates
    edf = np.column_stack([_dominant_edf(edfs, X * p[None, :]) for p in p_all])
    chi2 = np.array([f[4] for f in fits])
    values = np.sqrt(np.maximum(p_all, 0.0))
    var = np.array([np.diag(c) for c in cov])
    std_sq = np.sqrt(np.maximum(var, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        # delta method, √p: σ(√p) = σ(p) / (2 √p); at zero, √σ(p)
        stds = np.where(values > 0, std_sq / (2.0 * values), np.sqrt(std_sq))
    return NoiseModel(
        noise_density=frozen_array(values[:, 0]),
        noise_density_std=frozen_array(stds[:, 0]),
        bias_instability=frozen_array(values[:, 1]),
        bias_instability_std=frozen_array(stds[:, 1]),
        random_walk=frozen_array(values[:, 2]),
        random_walk_std=frozen_array(stds[:, 2]),
        tau_range=(float(taus[rows].min()), float(taus[rows].max())),
        edf=frozen_array(edf),
        covariance=frozen_array(cov),
        reduced_chi2=frozen_array(chi2),
        low_pass=low_pass,
    )
