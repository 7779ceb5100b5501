"""The noise model fitted to an Allan deviation curve (:mod:`.allan`): white noise N, bias
instability B (flicker) and rate random walk K per axis, by non-negative least squares on the
curve's clusters weighted by their equivalent degrees of freedom, with standard errors from the
clusters' correlation (``docs/noise.md``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._frozen import ArrayDataclass, frozen_array
from ..errors import InputError
from .allan import (
    _LOW_PASS,
    FLICKER,
    MIN_WINDOWS,
    NOISE_TYPES,
    AllanDeviation,
    _positive,
    equivalent_dof,
)

__all__ = ["NoiseModel", "correlation", "fit_noise_model"]

Array = NDArray[np.float64]


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

    def to_dict(self) -> dict[str, object]:
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


#: One axis's fit (:func:`_fit_axis`).
_AxisFit: TypeAlias = tuple[Array, NDArray[np.bool_], Array, Array, float]


def _fit_axis(X: Array, y: Array, m: NDArray[np.int64], edfs: Array) -> _AxisFit:
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

    def fit(start: float) -> tuple[NDArray[np.bool_], list[_AxisFit]]:
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
        if not _below_model(ahead, X[first], y[first], float(edfs[first, 0])):
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


def _below_model(ahead: list[_AxisFit], x: Array, y: Array, edf: float) -> bool:
    """Whether the shortest τ (design row ``x``, Allan variances ``y`` per axis, ``edf`` its
    white-noise degrees of freedom) lies below the model fitted from the next octaves on
    (``ahead``) on some axis, by more than :data:`_LOW_PASS` and three standard errors."""
    below = False
    for j, (p, *_) in enumerate(ahead):
        model = float(x @ p)
        relative = y[j] / model - 1.0 if model > 0 else 0.0
        sd = math.sqrt(2.0 / max(edf, 1.0))
        below |= relative < -max(_LOW_PASS, 3.0 * math.sqrt(2.0) * sd)
    return below
