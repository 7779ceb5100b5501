"""Levenberg–Marquardt on the block-banded normal equations of the continuous model.

Each epoch's rotation meets only its own readings and, through the gyroscope's factor, its two
neighbours: the trajectory's block of ``JᵀWJ`` is block-tridiagonal (3×3 blocks, lower
bandwidth 5), bordered by the dense block of the 34 parameters. A step solves

    [H_tt  H_tp] [Δt]   [b_t]
    [H_pt  H_pp] [Δp] = [b_p]

by one banded Cholesky factorisation of ``H_tt`` (``scipy.linalg.cholesky_banded``), the Schur
complement ``S = H_pp − H_pt H_tt⁻¹ H_tp`` (34×34) and back-substitution: time and memory
linear in the samples. Temperature coefficients (:attr:`.model.State.temps`) widen the border:
each sample's residual meets them through its own temperature, a dense column block like the
other parameters.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cholesky_banded
from scipy.linalg.lapack import dtbtrs

from ...likelihood.marquardt import Schedule, minimise
from .knots import gyro_vector
from .model import (
    Data,
    KnotFactors,
    State,
    accel_columns,
    accel_of,
    columns,
    mag_columns,
    mag_of,
    residuals,
)
from .preintegration import GyroFactors, knot_factors, thermal_factors

__all__ = [
    "Normal",
    "Prior",
    "Weights",
    "add_columns",
    "cost",
    "levenberg_marquardt",
    "normal_equations",
    "schur",
]

Array = NDArray[np.float64]


@dataclass
class Prior:
    """Independent Gaussian priors on the parameters: means and inverse variances."""

    mean: Array
    precision: Array
    #: Parameters held fixed (:mod:`.held_blocks`): the step leaves them where they are.
    fixed: NDArray[np.bool_] | None = None

    def free(self, size: int) -> NDArray[np.bool_]:
        """Which of ``size`` parameters the fit moves (those past ``mean`` always)."""
        out = np.ones(size, dtype=bool)
        if self.fixed is not None:
            out[: len(self.fixed)] = ~self.fixed
        return out

    def cost(self, p: Array) -> float:
        """Half the prior's χ² (temperature coefficients past ``mean`` carry no prior)."""
        return 0.5 * float(np.sum(self.precision * (p[: len(self.mean)] - self.mean) ** 2))


@dataclass
class Weights:
    """Inverse variances per epoch: accelerometer and magnetometer (n,), gyroscope (n − 1,);
    and the parameters' prior."""

    accel: Array
    mag: Array
    gyro: Array
    prior: Prior | None = None

    def scaled(self, accel: float, mag: float, gyro: float) -> Weights:
        return Weights(self.accel / accel, self.mag / mag, self.gyro / gyro, self.prior)


@dataclass
class Normal:
    """``JᵀWJ`` and ``JᵀWr``: the trajectory's banded block in LAPACK's lower form (6, 3n), the
    border ``H_tp`` (3n, 34), ``H_pp``, the right-hand sides and the cost ``½ Σ w r²``."""

    banded: Array
    border: Array
    params: Array
    rhs_t: Array
    rhs_p: Array
    cost: float
    factor: Array | None = None


#: Epochs per chunk of the assembly: the per-sample Jacobians of a chunk stay in the cache, so
#: the cost per sample does not grow with the log.
CHUNK = 4096


def _chunks(n: int) -> list[tuple[int, int]]:
    return [(lo, min(n, lo + CHUNK)) for lo in range(0, n, CHUNK)]


def _part(state: State, data: Data, lo: int, hi: int) -> tuple[State, Data]:
    """Epochs ``lo..hi`` and the next one (the gyroscope's factors ``lo..hi−1`` need it)."""
    stop = min(hi + 1, len(data.time))
    sub = dataclasses.replace(state, rotations=state.rotations[lo:stop])
    return sub, data.rows(lo, stop)


def _own(sub: State, part: Data, m: int) -> tuple[State, Data]:
    """The chunk's own ``m`` epochs (without the next one)."""
    return dataclasses.replace(sub, rotations=sub.rotations[:m]), part.rows(0, m)


def cost(state: State, data: Data, w: Weights) -> float:
    """``½ Σ w ‖r‖²`` over the three sensors (Eq. C1–C3)."""
    total = 0.0
    n = len(data.time)
    for lo, hi in _chunks(n):
        sub, part = _part(state, data, lo, hi)
        ra, rm = residuals(*_own(sub, part, hi - lo))
        total += float(np.sum(w.accel[lo:hi] * np.sum(ra**2, 1)))
        total += float(np.sum(w.mag[lo:hi] * np.sum(rm**2, 1)))
        if len(sub.rotations) > 1:
            rg = state_factors(sub, part).residual
            total += float(np.sum(w.gyro[lo : lo + len(rg)] * np.sum(rg**2, 1)))
    prior = 0.0 if w.prior is None else w.prior.cost(state.vector())
    return 0.5 * total + prior


def normal_equations(state: State, data: Data, w: Weights) -> Normal:
    """Assemble the normal equations, vectorised over the epochs of each chunk."""
    n = len(state.rotations)
    size = len(state.vector())
    diag = np.zeros((n, 3, 3))
    off = np.zeros((max(n - 1, 0), 3, 3))
    border = np.zeros((n, 3, size))
    params = np.zeros((size, size))
    rhs_t = np.zeros((n, 3))
    rhs_p = np.zeros(size)
    total = 0.0
    for lo, hi in _chunks(n):
        sub, part = _part(state, data, lo, hi)
        total += _assemble(sub, part, w, lo, hi, diag, off, border, params, rhs_t, rhs_p)
    if w.prior is not None:
        p = state.vector()
        m = len(w.prior.mean)
        params[np.diag_indices(m)] += w.prior.precision
        rhs_p[:m] += w.prior.precision * (w.prior.mean - p[:m])
        total += w.prior.cost(p)
    banded = np.zeros((6, 3 * n))
    for i in range(3):
        for j in range(i + 1):
            banded[i - j, j::3] = diag[:, i, j]
        for j in range(3):
            banded[3 + i - j, j : 3 * (n - 1) : 3] = off[:, i, j]
    return Normal(banded, border.reshape(3 * n, size), params, rhs_t.ravel(), rhs_p, total)


def _assemble(
    sub: State,
    part: Data,
    w: Weights,
    lo: int,
    hi: int,
    diag: Array,
    off: Array,
    border: Array,
    params: Array,
    rhs_t: Array,
    rhs_p: Array,
) -> float:
    """Add epochs ``lo..hi`` (and the factors leaving them) to the normal equations."""
    total = 0.0
    own, rows = _own(sub, part, hi - lo)
    for block, weight, sl in (
        (accel_of(own, rows), w.accel[lo:hi], accel_columns(sub)),
        (mag_of(own, rows), w.mag[lo:hi], mag_columns(sub, rows)),
    ):
        Jt, Jp, r = block.rotation, block.params, block.residual
        WJtT = np.swapaxes(Jt * weight[:, None, None], 1, 2)
        diag[lo:hi] += WJtT @ Jt
        add_columns(border[lo:hi], sl, WJtT @ Jp)
        flat = Jp.reshape(-1, Jp.shape[2])
        params[np.ix_(sl, sl)] += (flat * np.repeat(weight, 3)[:, None]).T @ flat
        rhs_t[lo:hi] += (WJtT @ r[:, :, None])[:, :, 0]
        rhs_p[sl] += flat.T @ (r * weight[:, None]).ravel()
        total += 0.5 * float(np.sum(weight * np.sum(r**2, 1)))
    if len(sub.rotations) < 2:
        return total
    f = state_factors(sub, part)
    k = len(f.dt)  # factors lo .. lo + k − 1, between epochs j and j + 1
    wg = w.gyro[lo : lo + k]
    sl = columns(sub, "gyro")
    eye = wg[:, None, None] * np.eye(3)
    diag[lo : lo + k] += eye  # J0ᵀ J0 = I (J0 is a rotation)
    diag[lo + 1 : lo + k + 1] += eye
    off[lo : lo + k] = f.previous * wg[:, None, None]  # block (j+1, j): J1ᵀ W J0, J1 = I
    WJp = f.params * wg[:, None, None]
    prevT = np.swapaxes(f.previous, 1, 2)
    add_columns(border[lo : lo + k], sl, prevT @ WJp)
    add_columns(border[lo + 1 : lo + k + 1], sl, WJp)
    width = f.params.shape[2]
    flat = f.params.reshape(-1, width)
    params[np.ix_(sl, sl)] += WJp.reshape(-1, width).T @ flat
    Wr = f.residual * wg[:, None]
    rhs_t[lo : lo + k] += (prevT @ Wr[:, :, None])[:, :, 0]
    rhs_t[lo + 1 : lo + k + 1] += Wr
    rhs_p[sl] += flat.T @ Wr.ravel()
    return total + 0.5 * float(np.sum(wg * np.sum(f.residual**2, 1)))


def add_columns(target: Array, columns: NDArray[np.intp], value: Array) -> None:
    """``target[..., columns] += value`` by runs of consecutive columns: a slice adds in place,
    a fancy index gathers, adds and scatters (twice the time on the border ``H_tp``)."""
    breaks = np.flatnonzero(np.diff(columns) != 1) + 1
    start = 0
    for stop in (*breaks.tolist(), len(columns)):
        first = int(columns[start])
        target[..., first : first + stop - start] += value[..., start:stop]
        start = stop


def state_factors(sub: State, part: Data) -> GyroFactors:
    """The gyroscope's factors of ``part`` (a chunk or the whole log) at ``sub``, the bias
    following temperature when it has terms; between knots, pre-integrated
    (:func:`.preintegration.knot_factors`)."""
    if part.factors is not None:
        return _knot_factors(sub, part.factors)
    return thermal_factors(
        sub.rotations,
        part.time,
        part.gyro,
        sub.gyro_gain,
        sub.gyro_bias,
        part.hold,
        sub.temps.get("gyro"),
        part.temperature,
    )


def _knot_factors(sub: State, factors: KnotFactors) -> GyroFactors:
    """The knots' factors at ``sub``'s gyroscope (its temperature orders' columns only)."""
    orders = (len(factors.anchor) - 12) // 3
    width = 12 + 3 * len(sub.temps.get("gyro", ()))
    moved = (gyro_vector(sub, orders) - factors.anchor)[:width]
    f = knot_factors(sub.rotations, factors.turn, factors.jacobian[:, :, :width], moved)
    return dataclasses.replace(f, dt=np.sqrt(factors.dt2))


def schur(normal: Normal, damping: float = 0.0) -> tuple[Array, Array, Array, Array]:
    """Factor ``H_tt = L Lᵀ`` (damped by ``1 + damping`` on its diagonal) and eliminate it.

    One forward substitution with 35 right-hand sides, ``[W | z] = L⁻¹ [H_tp | b_t]``, gives
    the Schur complement ``S = H_pp − WᵀW`` (34×34) and ``g = b_p − Wᵀz``; the trajectory's
    step then needs one back-substitution (:func:`_step`). Returns ``(S, g, W, z)`` and keeps
    the factor in ``normal`` for that.
    """
    size = normal.params.shape[0]
    ab = normal.banded.copy()
    ab[0] *= 1.0 + damping
    ab[0] += 1e-12 * max(float(np.max(ab[0])), 1.0)
    factor = cholesky_banded(ab, lower=True, check_finite=False)
    rhs = np.empty((len(normal.rhs_t), size + 1), order="F")
    rhs[:, :size] = normal.border
    rhs[:, size] = normal.rhs_t
    Z, info = dtbtrs(factor, rhs, uplo="L", overwrite_b=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"banded triangular solve failed (info {info})")
    product = Z.T @ Z[:, :size]  # (35, 34): one pass over the samples
    Hpp = normal.params.copy()
    Hpp[np.diag_indices_from(Hpp)] *= 1.0 + damping
    S = Hpp - product[:size]
    normal.factor = factor
    g = normal.rhs_p - product[size]
    return 0.5 * (S + S.T), g, Z[:, :size], Z[:, size]


def _step(normal: Normal, damping: float, free: NDArray[np.bool_]) -> tuple[Array, Array]:
    S, g, W, z = schur(normal, damping)
    Sf = S[np.ix_(free, free)]
    dp = np.zeros(len(S))
    dp[free] = np.linalg.solve(Sf + 1e-14 * np.trace(Sf) * np.eye(len(Sf)), g[free])
    x, info = dtbtrs(normal.factor, (z - W @ dp)[:, None], uplo="L", trans="T")
    if info != 0:
        raise np.linalg.LinAlgError(f"banded triangular solve failed (info {info})")
    return dp, x[:, 0].reshape(-1, 3)


class _Trajectory:
    """The continuous problem for the shared loop (:func:`fieldcal.likelihood.marquardt.
    minimise`): a point is a :class:`State`; its linearisation the banded normal equations."""

    def __init__(
        self,
        data: Data,
        w: Weights,
        free: NDArray[np.bool_],
        on_iteration: Callable[[int], None] | None = None,
    ) -> None:
        self.data, self.w, self.free = data, w, free
        self.on_iteration, self.iterations = on_iteration, 0

    def linearise(self, state: State) -> tuple[State, Normal]:
        if self.on_iteration is not None:
            self.on_iteration(self.iterations)
        self.iterations += 1
        return state, normal_equations(state, self.data, self.w)

    def level(self, linear: tuple[State, Normal]) -> float | None:
        """The cost as the normal equations summed it (the one a trial is compared with)."""
        return linear[1].cost

    def propose(self, linear: tuple[State, Normal], lam: float) -> tuple[State, float] | None:
        state, normal = linear
        try:
            dp, dt = _step(normal, lam, self.free)
        except np.linalg.LinAlgError:
            return None
        return state.updated(dp, dt), math.nan

    def cost(self, state: State) -> float:
        return cost(state, self.data, self.w)


class _Fivefold(Schedule):
    """The continuous estimator's rules: a step is taken when it does not raise the cost, λ
    shrinks fivefold after it (down to 1e-9) and grows tenfold after a refusal (beyond 1e8 no
    further decrease is possible); the loop stops when a step lowered the cost by at most
    ``tol`` (absolute: half a χ²)."""

    def __init__(self, tol: float) -> None:
        super().__init__(1e-8)
        self.tol = tol

    def accepts(self, gain: float, rho: float, new: float, cost: float) -> bool:
        return bool(np.isfinite(new) and new <= cost)

    def accepted(self, gain: float, rho: float, cost: float) -> bool:
        self.lam = max(self.lam / 5.0, 1e-9)
        return gain <= self.tol

    def refused(self, predicted: float, cost: float) -> bool | None:
        self.lam *= 10.0
        return True if self.lam > 1e8 else None


def levenberg_marquardt(
    state: State,
    data: Data,
    w: Weights,
    *,
    max_iter: int = 50,
    tol: float = 1e-3,
    on_iteration: Callable[[int], None] | None = None,
) -> tuple[State, int, bool]:
    """Minimise ``½ Σ w ‖r‖²`` from ``state``; returns the state, iterations and whether a
    step lowered the cost by less than ``tol`` (converged) before ``max_iter``.

    ``tol`` is absolute, in units of the cost (half a χ²): a step that lowers it by ``tol``
    moves the estimate by about ``sqrt(2 tol)`` standard errors (Mahalanobis), so the default
    stops when the steps are a twentieth of the error bars or less. The shared loop
    (:func:`fieldcal.likelihood.marquardt.minimise`) with the rules of :class:`_Fivefold`;
    parameters a prior holds (``w.prior.free``) do not move. ``on_iteration`` hears the
    number of iterations done before each (for progress)."""
    size = len(state.vector())
    free = np.ones(size, dtype=bool) if w.prior is None else w.prior.free(size)
    out = minimise(
        _Trajectory(data, w, free, on_iteration), state, math.nan, _Fivefold(tol), max_iter
    )
    return out.point, out.iterations, out.converged
