"""The seed paper's greedy calibration (Miranda & Ferreira, Sec. 4-5), as published.

Steps of Sec. 5, each implemented by one function here:

1. pose statistics (Eq. 5, 7): done by :func:`fieldcal.summarize` before :func:`fit`;
2. initial values: ``b = 0``, ``K = I``, ``R_i = I``, ``g_z = −1``, ``h = (1, 0, 1)``
   (:func:`initial_state`), ``J[0]`` by Eq. 8 (:func:`cost`);
3. rotations: gradient-based local minimisation of Eq. 9 over each pose's quaternion
   (:func:`rotation_step`);
4. biases and fields by GLS (Eq. 11, 13, 15), sign fix, then the scale constraints of Sec. 4.3
   ``g_z = −1``, ``h_x = 1`` (:func:`bias_field_step`);
5. gains by GLS (Eq. 16, 17) when ``h_z`` moved by less than 1e-3 (:func:`gain_step`);
6. ``J[k]`` by Eq. 8;
7. repeat from 3 while ``J[k−1] − J[k] > γ`` (:func:`run_greedy`).

Every choice the paper leaves open is listed, with the reason, in ``docs/methods/greedy.md``.
This is the reference implementation of the paper: it is deliberately not improved.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration, SensorCalibration
from ..geometry.frames import HALF_TURN_NORTH
from ..geometry.gauge import canonical_gauge
from ..geometry.rotations import quaternion_to_matrix
from ..stats.pose_stats import PoseStats, brief
from .gls import (
    accel_bias_field_design,
    accel_gain_design,
    gls,
    mag_bias_field_design,
    mag_gain_design,
    symmetric_from_vector,
)

__all__ = ["GreedyResult", "GreedyState", "fit", "run_greedy"]

Array = NDArray[np.float64]

#: Sec. 5, step 5: gains are re-estimated only when h_z moved by less than this.
GAIN_TRIGGER = 1e-3
#: ``fit``'s default time limit (seconds), not the paper's: its γ rule can take thousands of
#: iterations of a slowly moving ``h_z`` (minutes; 6 of 100 Table 1 runs reach 1000
#: iterations, docs/benchmarks.md), and a command must answer. A run stopped by it says so
#: (``converged=False``, ``message``, a warning) and the verdict reports ``not_converged``.
MAX_SECONDS = 20.0


_X, _Z = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Data:
    """What Eq. 8 needs from the pose statistics: ``μ̂_s``, ``Δ_s`` and ``Σ̂_s⁻¹``."""

    mean_a: Array
    mean_m: Array
    count_a: Array
    count_m: Array
    weight_a: Array
    weight_m: Array

    @classmethod
    def from_stats(cls, stats: PoseStats) -> Data:
        a, m = stats.sensor("accel"), stats.sensor("mag")
        if a.cov is None or m.cov is None:
            raise ValueError("the greedy algorithm needs Eq. 7's covariance of both sensors")
        return cls(
            mean_a=np.asarray(a.means, float),
            mean_m=np.asarray(m.means, float),
            count_a=np.asarray(a.counts, float),
            count_m=np.asarray(m.counts, float),
            weight_a=cast(Array, np.linalg.inv(a.cov)),
            weight_m=cast(Array, np.linalg.inv(m.cov)),
        )


@dataclass(frozen=True)
class GreedyState:
    """Θ of Sec. 4 in the paper's gauge: ``g = (0, 0, g_z)``, ``h = (h_x, 0, h_z)``.

    ``quaternions`` (N, 4) are unit, scalar first; ``R_i`` maps the world to the body frame.
    """

    accel_gain: Array
    accel_bias: Array
    g_z: float
    mag_gain: Array
    mag_bias: Array
    h_x: float
    h_z: float
    quaternions: Array

    @property
    def gravity(self) -> Array:
        return np.array([0.0, 0.0, self.g_z])

    @property
    def magnetic(self) -> Array:
        return np.array([self.h_x, 0.0, self.h_z])

    @property
    def rotations(self) -> Array:
        return quaternion_to_matrix(self.quaternions)

    def predicted_means(self) -> tuple[Array, Array]:
        """``μ̃_s[i] = K_s R_i f_s + b_s`` (Eq. 4), gauge-free: what Eq. 19 compares."""
        R = self.rotations
        accel = (R @ self.gravity) @ self.accel_gain.T + self.accel_bias
        mag = (R @ self.magnetic) @ self.mag_gain.T + self.mag_bias
        return accel, mag


@dataclass
class GreedyResult:
    """Output of :func:`run_greedy`: the final state, the cost history and bookkeeping."""

    state: GreedyState
    costs: list[float]
    iterations: int
    converged: bool
    timed_out: bool
    gain_updates: int
    sign_fixes: int
    cost_increases: int
    seconds: float


def initial_state(n_poses: int) -> GreedyState:
    """Sec. 5, step 2: null biases, unit gains and rotations, h = (1, 0, 1), g_z = −1."""
    q = np.zeros((n_poses, 4))
    q[:, 0] = 1.0
    return GreedyState(np.eye(3), np.zeros(3), -1.0, np.eye(3), np.zeros(3), 1.0, 1.0, q)


# --------------------------------------------------------------------------- Eq. 8 and 9
def _hat(f: Array) -> Array:
    """Matrices (..., 3, 3) with ``a @ _hat(f) == a × f`` for row vectors ``a``."""
    x, y, z = np.moveaxis(np.asarray(f, dtype=float), -1, 0)
    o = np.zeros_like(x)
    rows = [np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)]
    return np.stack(rows, -2)


@dataclass(frozen=True)
class _Frozen:
    """Eq. 9's fixed parameters during the rotation step, both sensors stacked on axis ``s``."""

    gain: Array  # (2, 3, 3) K_a, K_m
    bias: Array  # (2, 3)
    field: Array  # (2, 3) g, h
    field_hat: Array  # (2, 3, 3)
    weight: Array  # (2, 3, 3) Σ̂⁻¹
    mean: Array  # (N, 2, 3) μ̂
    count: Array  # (N, 2) Δ

    @classmethod
    def of(cls, state: GreedyState, data: Data) -> _Frozen:
        field = np.stack([state.gravity, state.magnetic])
        return cls(
            gain=np.stack([state.accel_gain, state.mag_gain]),
            bias=np.stack([state.accel_bias, state.mag_bias]),
            field=field,
            field_hat=_hat(field),
            weight=np.stack([data.weight_a, data.weight_m]),
            mean=np.stack([data.mean_a, data.mean_m], axis=1),
            count=np.stack([data.count_a, data.count_m], axis=1),
        )


def _rotate(q: Array, fz: _Frozen) -> Array:
    """``R(q) f_s`` (N, 2, 3) for unit quaternions (N, 4): ``(w² − v·v) f + 2 (v·f) v + 2 w v × f``.

    Eq. 9 only needs ``R_i g`` and ``R_i h``; rotating the two vectors directly is cheaper than
    building N matrices at every trial step of the line search.
    """
    w, v = q[:, :1, None], q[:, 1:]
    vf = v @ fz.field.T  # (N, 2)
    v_cross_f = np.einsum("nb,sbc->nsc", v, fz.field_hat)
    scale = w * w - np.sum(v * v, axis=1)[:, None, None]
    return scale * fz.field + 2.0 * (vf[:, :, None] * v[:, None, :] + w * v_cross_f)


def _residual_cost(q: Array, fz: _Frozen) -> tuple[Array, Array, Array]:
    """Eq. 9 per pose, the residuals ``r_s`` (N, 2, 3) and ``Σ̂_s⁻¹ r_s``."""
    r = np.einsum("nsb,sab->nsa", _rotate(q, fz), fz.gain) + fz.bias - fz.mean
    wr = np.einsum("nsa,sab->nsb", r, fz.weight)
    return np.sum(fz.count * np.sum(r * wr, axis=2), axis=1), r, wr


def _quaternion_gradient(q: Array, fz: _Frozen) -> tuple[Array, Array]:
    """Eq. 9 and its analytic gradient on the unit sphere of quaternions, for all poses.

    With ``λ_s = ∂J_i/∂(R_i f_s) = 2 Δ_s[i] K_sᵀ Σ̂_s⁻¹ r_s`` and ``R f`` as in :func:`_rotate`:
    ``∂J/∂w = Σ_s 2 (w λ·f + λ·(v × f))``,
    ``∂J/∂v = Σ_s 2 (−(λ·f) v + (v·f) λ + (λ·v) f + w f × λ)``,
    then projected on the tangent plane ``q⊥``: the normalisation ``q / |q|`` removes the
    radial part, so this is the gradient of ``J_i(R(q / |q|))`` at ``|q| = 1``.
    """
    J, _, wr = _residual_cost(q, fz)
    lever = 2.0 * fz.count[:, :, None] * np.einsum("nsa,sab->nsb", wr, fz.gain)
    w, v = q[:, :1], q[:, 1:]
    lf = np.einsum("nsa,sa->ns", lever, fz.field)
    vf = v @ fz.field.T
    v_cross_f = np.einsum("nb,sbc->nsc", v, fz.field_hat)
    lever_cross_f = np.einsum("nsb,sbc->nsc", lever, fz.field_hat)
    d_w = 2.0 * (w[:, 0] * lf.sum(axis=1) + np.sum(lever * v_cross_f, axis=(1, 2)))
    d_v = 2.0 * (
        -lf.sum(axis=1)[:, None] * v
        + np.einsum("ns,nsa->na", vf, lever)
        + np.einsum("nsa,na,sb->nb", lever, v, fz.field)
        - w * lever_cross_f.sum(axis=1)
    )
    grad = np.concatenate([d_w[:, None], d_v], axis=1)
    grad -= np.sum(grad * q, axis=1, keepdims=True) * q
    return J, grad


def pose_costs(state: GreedyState, data: Data, quaternions: Array | None = None) -> Array:
    """Eq. 9: ``J_i(R_i) = Σ_s Δ_s[i] rᵀ Σ̂_s⁻¹ r``, ``r = K_s R_i f_s + b_s − μ̂_s[i]``."""
    q = _normalise(state.quaternions if quaternions is None else quaternions)
    return _residual_cost(q, _Frozen.of(state, data))[0]


def cost(state: GreedyState, data: Data) -> float:
    """Eq. 8: the sum over poses of Eq. 9."""
    return float(pose_costs(state, data).sum())


def _normalise(q: Array) -> Array:
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def rotation_step(
    state: GreedyState, data: Data, tol: float = 1e-9, max_iterations: int = 200
) -> GreedyState:
    """Sec. 4.1: minimise Eq. 9 over each pose's quaternion by gradient descent, all poses at once.

    Steepest descent on the unit sphere from the current rotations (warm start), with a
    per-pose Barzilai-Borwein step length and Armijo backtracking so every pose's Eq. 9 never
    increases. A pose stops when one step lowers its Eq. 9 by no more than ``tol (1 + J_i)``.
    Poses are independent (Eq. 9), so all are evaluated together and only the active ones move:
    with N <= 30 one batched evaluation is cheaper than indexing out the active subset.
    """
    fz = _Frozen.of(state, data)
    q = state.quaternions.copy()
    J, grad = _quaternion_gradient(q, fz)
    step = _initial_step(state, data) * np.ones(q.shape[0])
    active = np.ones(q.shape[0], dtype=bool)
    for _ in range(max_iterations):
        q_new, J_new, grad_new, t = _armijo(fz, q, J, grad, step, active)
        s, y = q_new - q, grad_new - grad
        ss, sy = np.sum(s * s, axis=1), np.sum(s * y, axis=1)
        # BB1 step s·s / s·y where the curvature is positive; otherwise double the last step.
        step = np.where(active, np.where(sy > 0, ss / np.where(sy > 0, sy, 1.0), 2.0 * t), step)
        still = J - J_new > tol * (1.0 + J_new)
        q, J, grad = q_new, J_new, grad_new
        active &= still
        if not active.any():
            break
    return dataclasses.replace(state, quaternions=q)


def _initial_step(state: GreedyState, data: Data) -> Array:
    """A first step length of the order of 1 / curvature of Eq. 9 in the quaternion."""
    curv_a = np.linalg.eigvalsh(state.accel_gain.T @ data.weight_a @ state.accel_gain)[-1]
    curv_m = np.linalg.eigvalsh(state.mag_gain.T @ data.weight_m @ state.mag_gain)[-1]
    curvature = 8.0 * (
        data.count_a * curv_a * state.g_z**2 + data.count_m * curv_m * (state.h_x**2 + state.h_z**2)
    )
    return 1.0 / curvature


def _armijo(
    fz: _Frozen,
    q: Array,
    J: Array,
    grad: Array,
    step: Array,
    active: NDArray[np.bool_],
) -> tuple[Array, Array, Array, Array]:
    """Backtrack each active pose's step until Eq. 9 drops by 1e-4 · t |∇|² (Armijo).

    Every trial evaluates Eq. 9 and its gradient together, so the accepted point's gradient
    (needed by the next BB step) costs nothing extra. Inactive poses do not move.
    """
    t = step.copy()
    slope = np.sum(grad * grad, axis=1)
    failed = active.copy()
    q_new, J_new, grad_new = q.copy(), J.copy(), grad.copy()
    for _ in range(60):
        trial = _normalise(q - t[:, None] * grad)
        J_trial, grad_trial = _quaternion_gradient(trial, fz)
        q_new[failed], J_new[failed], grad_new[failed] = (
            trial[failed],
            J_trial[failed],
            grad_trial[failed],
        )
        failed &= J_trial > J - 1e-4 * t * slope
        if not failed.any():
            break
        t[failed] *= 0.5
    # A pose whose step underflowed keeps its rotation: Eq. 9 must never increase.
    q_new[failed], J_new[failed], grad_new[failed] = q[failed], J[failed], grad[failed]
    return q_new, J_new, grad_new, t


# --------------------------------------------------------------------------- Eq. 13, 15
def bias_field_step(state: GreedyState, data: Data) -> tuple[GreedyState, int]:
    """Sec. 4.2-4.3: GLS for ``(g_z, b_a)`` (Eq. 13) and ``(h_x, h_z, b_m)`` (Eq. 15).

    Then the sign fix of Sec. 4.2 (a wrong sign of ``g_z`` or ``h_x`` is flipped, nothing
    else changes) and the scale constraints of Sec. 4.3: ``K_a ← |g_z| K_a``, ``g_z = −1``;
    ``K_m ← |h_x| K_m``, ``h_z ← h_z / |h_x|``, ``h_x = 1``. Returns the state and the
    number of signs fixed.
    """
    R = state.rotations
    X_a, X_m = (
        accel_bias_field_design(state.accel_gain, R),
        mag_bias_field_design(state.mag_gain, R),
    )
    g_z, *b_a = gls(X_a, data.mean_a, data.weight_a, data.count_a)
    h_x, h_z, *b_m = gls(X_m, data.mean_m, data.weight_m, data.count_m)
    fixes = int(g_z > 0) + int(h_x < 0)
    return (
        dataclasses.replace(
            state,
            accel_gain=abs(g_z) * state.accel_gain,
            accel_bias=np.array(b_a),
            g_z=-1.0,
            mag_gain=abs(h_x) * state.mag_gain,
            mag_bias=np.array(b_m),
            h_x=1.0,
            h_z=h_z / abs(h_x),
        ),
        fixes,
    )


# --------------------------------------------------------------------------- Eq. 16, 17
def gain_step(state: GreedyState, data: Data) -> GreedyState:
    """Sec. 4.4: GLS for the symmetric ``K_a`` (Eq. 16) and the full ``K_m`` (Eq. 17)."""
    R = state.rotations
    beta_a = gls(
        accel_gain_design(R @ state.gravity),
        data.mean_a - state.accel_bias,
        data.weight_a,
        data.count_a,
    )
    beta_m = gls(
        mag_gain_design(R @ state.magnetic),
        data.mean_m - state.mag_bias,
        data.weight_m,
        data.count_m,
    )
    return dataclasses.replace(
        state, accel_gain=symmetric_from_vector(beta_a), mag_gain=beta_m.reshape(3, 3)
    )


# --------------------------------------------------------------------------- Sec. 5
def run_greedy(
    stats: PoseStats,
    gamma: float = 1e-4,
    max_iterations: int = 2000,
    callback: Callable[[int, float, GreedyState, float], None] | None = None,
    *,
    rotation_tol: float = 1e-9,
    rotation_max_iterations: int = 200,
    max_seconds: float | None = None,
) -> GreedyResult:
    """The algorithm of Sec. 5 in the paper's gauge, for any number of poses.

    ``stats`` must hold both sensors with a covariance each. ``callback(k, J[k], state,
    seconds)`` is called after step 2 (``k = 0``) and after every iteration, with the seconds
    elapsed since the start; the algorithm is deterministic and only its stopping rule depends
    on ``γ``, so one run with a small ``γ`` and a callback gives the result for every larger
    ``γ``. ``max_seconds`` (None: no limit) stops it after the iteration that passes that time
    (``timed_out``), as ``max_iterations`` does after a number of iterations.
    """
    data = Data.from_stats(stats)
    start = time.perf_counter()
    state = initial_state(stats.n_poses)
    costs = [cost(state, data)]
    if callback is not None:
        callback(0, costs[0], state, time.perf_counter() - start)
    gain_updates = sign_fixes = increases = 0
    converged = timed_out = False
    k = 0
    while k < max_iterations:
        k += 1
        h_z_before = state.h_z
        state = rotation_step(state, data, rotation_tol, rotation_max_iterations)  # step 3
        state, fixes = bias_field_step(state, data)  # step 4
        sign_fixes += fixes
        if abs(state.h_z - h_z_before) < GAIN_TRIGGER:  # step 5
            state = gain_step(state, data)
            gain_updates += 1
        costs.append(cost(state, data))  # step 6
        increases += costs[-1] > costs[-2]
        if callback is not None:
            callback(k, costs[-1], state, time.perf_counter() - start)
        if costs[-2] - costs[-1] <= gamma:  # step 7
            converged = True
            break
        if max_seconds is not None and time.perf_counter() - start > max_seconds:
            timed_out = True
            break
    return GreedyResult(
        state=state,
        costs=costs,
        iterations=k,
        converged=converged,
        timed_out=timed_out,
        gain_updates=gain_updates,
        sign_fixes=sign_fixes,
        cost_increases=int(increases),
        seconds=time.perf_counter() - start,
    )


# --------------------------------------------------------------------------- public fit
_M = HALF_TURN_NORTH  # half turn about the world x axis: M g = −g, M h = (h_x, 0, −h_z)


def to_fieldcal_gauge(
    state: GreedyState, body_frame: str = "accel"
) -> tuple[Array, Array, Array, Array, Array, bool]:
    """Re-express the paper's gauge in fieldcal's: unit fields, SPD gain for ``body_frame``.

    Sec. 4.3 only makes ``K_a`` symmetric (``U = diag(±1, ±1, ±1)``). A symmetric ``K_a`` with
    ``det < 0`` is exactly equivalent to ``−K_a`` (``det > 0``) with every ``R_i`` followed by a
    half turn ``M`` about the world x axis and ``h_z → −h_z``: ``(−K_a) R_i M g = K_a R_i g``
    and ``K_m R_i M (M h) = K_m R_i h``. After that flip :func:`canonical_gauge` moves the
    remaining rotation (``det U = +1``) into the ``R_i`` and folds ``|h|`` into ``K_m``.
    Returns ``(rotations, accel_gain, mag_gain, gravity, magnetic, flipped)``.
    """
    R, Ka, h = state.rotations, state.accel_gain, state.magnetic
    flipped = bool(np.linalg.det(Ka) < 0)
    if flipped:
        R, Ka, h = R @ _M, -Ka, _M @ h
    out = canonical_gauge(R, Ka, state.mag_gain, state.gravity, h, body_frame)
    return (*out, flipped)


def _check(
    stats: PoseStats,
    gamma: float,
    max_iterations: int,
    rotation_tol: float,
    rotation_max: int,
    max_seconds: float = MAX_SECONDS,
) -> None:
    if stats is None or stats.accel is None or stats.mag is None:
        raise ValueError(
            "method='greedy' (--method greedy) needs both accelerometer and magnetometer "
            "poses; use method='mle' (--method mle) to calibrate one sensor"
        )
    for name in ("accel", "mag"):
        if stats.sensor(name).cov is None:
            raise ValueError(
                f"{name}: one sample per pose gives no within-pose scatter (Eq. 7); record "
                "several samples per pose or pass noise=... (the sample's standard deviation)"
            )
    for label, value in (
        ("gamma", gamma),
        ("rotation_tol", rotation_tol),
        ("max_seconds", max_seconds),
    ):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
            raise ValueError(f"{label} must be a positive number, got {brief(value)}")
        if not np.isfinite(value) and label != "max_seconds":  # inf seconds: no limit
            raise ValueError(f"{label} must be finite, got {brief(value)}")
    for label, count in (
        ("max_iterations", max_iterations),
        ("rotation_max_iterations", rotation_max),
    ):
        if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
            raise ValueError(f"{label} must be a whole number of at least 1, got {brief(count)}")


def _reporter(
    progress: Callable[[str], None], cap: int
) -> Callable[[int, float, GreedyState, float], None]:
    """A run_greedy callback that reports about once a second, not every iteration."""
    last = [-1.0]

    def report(k: int, J: float, state: GreedyState, seconds: float) -> None:
        if seconds - last[0] >= 1.0:
            last[0] = seconds
            progress(f"greedy: iteration {k} of at most {cap}, J = {J:.6g}, {seconds:.0f} s")

    return report


def fit(
    stats: PoseStats,
    *,
    raw_accel: object = None,
    raw_mag: object = None,
    body_frame: str = "accel",
    progress: Callable[[str], None] | None = None,
    gamma: float = 1e-4,
    max_iterations: int = 2000,
    rotation_tol: float = 1e-9,
    rotation_max_iterations: int = 200,
    max_seconds: float = MAX_SECONDS,
) -> Calibration:
    """Calibrate both sensors with the greedy algorithm of Sec. 5.

    Parameters
    ----------
    stats : PoseStats
        Pose means, counts and Eq. 7's covariances of both sensors.
    raw_accel, raw_mag
        The raw samples (unused).
    body_frame : {"accel", "mag"}
        Which sensor's gain is symmetric in the result.
    progress : callable, optional
        Told the iteration, J and the time about once a second (the method can take minutes).
    gamma : float
        Stop when ``J[k−1] − J[k] <= γ`` (Table 1: 1e-4).
    max_iterations : int
        Cap on Sec. 5 iterations; reaching it is reported (``converged=False``).
    rotation_tol, rotation_max_iterations : float, int
        The gradient descent of Sec. 4.1 per pose.
    max_seconds : float
        Stop after the iteration that passes this many seconds (:data:`MAX_SECONDS`, not the
        paper's), reported as the iteration cap is (``converged=False``).

    Returns
    -------
    Calibration
        In fieldcal's gauge. ``options`` records the iteration cap, the time taken and the
        counts of gain updates, sign fixes and cost increases.
    """
    _check(stats, gamma, max_iterations, rotation_tol, rotation_max_iterations, max_seconds)
    result = run_greedy(
        stats,
        float(gamma),
        int(max_iterations),
        rotation_tol=float(rotation_tol),
        rotation_max_iterations=int(rotation_max_iterations),
        callback=None if progress is None else _reporter(progress, int(max_iterations)),
        max_seconds=float(max_seconds),
    )
    R, Ka, Km, g, h, flipped = to_fieldcal_gauge(result.state, body_frame)
    cov_a, cov_m = stats.sensor("accel").cov, stats.sensor("mag").cov
    assert cov_a is not None and cov_m is not None  # checked above
    if result.timed_out:
        stopped = f"time limit reached ({max_seconds:g} s, {result.iterations} iterations)"
        warnings.warn(
            f"greedy: stopped at the time limit of {max_seconds:g} s after {result.iterations} "
            "iterations before J[k-1] - J[k] <= gamma; raise max_seconds or gamma, or use "
            "method='mle'",
            stacklevel=3,
        )
    elif not result.converged:
        stopped = "iteration cap reached"
        warnings.warn(
            f"greedy: stopped at the cap of {max_iterations} iterations before "
            f"J[k-1] - J[k] <= gamma; raise max_iterations or gamma, or use method='mle'",
            stacklevel=3,
        )
    return Calibration(
        accel=SensorCalibration(Ka, result.state.accel_bias, cov_a),
        mag=SensorCalibration(Km, result.state.mag_bias, cov_m),
        gravity=g,
        magnetic=h,
        rotations=R,
        method="greedy",
        iterations=result.iterations,
        converged=result.converged,
        message="converged" if result.converged else stopped,
        options={
            "gamma": float(gamma),
            "max_iterations": int(max_iterations),
            "rotation_tol": float(rotation_tol),
            "rotation_max_iterations": int(rotation_max_iterations),
            "max_seconds": float(max_seconds) if np.isfinite(max_seconds) else None,
            "gain_updates": result.gain_updates,
            "sign_fixes": result.sign_fixes,
            "cost_increases": result.cost_increases,
            "accel_gain_flipped": flipped,
        },
    )
