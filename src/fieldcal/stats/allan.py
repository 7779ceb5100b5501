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
import importlib
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
    "allan_deviation",
    "chi2_quantile",
    "cluster_sizes",
    "equivalent_dof",
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
    number = math.nan  # anything but a number (a bool is not one here) fails below
    if isinstance(value, (int, float, np.number)) and not isinstance(value, (bool, np.bool_)):
        number = float(value)
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


def __getattr__(name: str) -> Any:
    """The noise model's names, moved to :mod:`.allan_model` (old path, for one release)."""
    if name in ("NoiseModel", "correlation", "fit_noise_model"):
        return getattr(importlib.import_module("fieldcal.stats.allan_model"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
