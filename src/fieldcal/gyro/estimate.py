"""The gyroscope's gain, misalignment and bias from a log with still poses and motion between
them, by maximum likelihood (``docs/methods/gyro.md`` derives every step).

Model: ``raw = K_g ω + b_g + ε``, ``ω`` the body-frame angular rate (rad/s) in the common body
frame of the calibration, ``dR/dt = −[ω]× R`` with ``R`` world (NED) → body.

1. **Bias.** Each still pose's mean raw rate ``p_i`` (the Earth's rotation, 7.3e-5 rad/s, is
   below a MEMS gyroscope's noise and is left in it); a straight line through them against time
   is the drift, with its significance. The bias at any time during a motion is interpolated
   linearly between the two poses around it; the poses' biases ``b_i`` are parameters of the
   fit with ``p_i`` as their prior, ``p_i ~ N(b_i, Q/T_i + v I)`` (``Q`` the rate noise
   density, ``T_i`` the pose's duration, ``v`` the poses' bias wander beyond white noise).
2. **Segments.** Between consecutive poses ``i → i+1`` the corrected rate
   ``ω = K_g⁻¹ (raw − b(t))`` is integrated exactly (quaternions, :mod:`.integrate`) into
   ``ΔR̂_i``; the observation is ``ΔR_i = R_{i+1} R_iᵀ`` of the joint fit (``method="rotations"``)
   or, with an accelerometer alone, the gravity direction at pose ``i+1`` (``"gravity"``,
   Tedaldi et al. 2014): ``u_{i+1} ≈ ΔR̂_i u_i``.
3. **Likelihood.** Residuals ``log(ΔR_iᵀ ΔR̂_i)`` (body frame at pose ``i``) or the tangent-plane
   components of ``ΔR̂_i u_i`` at ``u_{i+1}``, all segments together whitened by their joint
   covariance: the poses' orientation errors (the joint fit's Cramér-Rao covariance, shared
   between neighbouring segments) plus the integrated white noise of the rate. Gauss-Newton with
   Levenberg-Marquardt damping and analytic Jacobians, in ``M = K_g⁻¹`` (the rate is linear in
   it); the covariance of ``K_g`` and ``b_g`` is the Cramér-Rao bound at the optimum, mapped to
   ``K_g = M⁻¹``, widened by ``χ²/dof`` when the segments' χ² rejects the model at 5 %.
4. **Observability.** The information matrix of the gain, the biases eliminated, tells which
   combinations of ``K_g``'s entries the motions determine; the rest is refused with an
   :class:`~fieldcal.errors.InputError` naming them (or, with ``allow_partial=True``, held at
   the start and left out of :attr:`GyroFit.observable` and the covariance).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import block_diag
from scipy.special import chdtrc, chdtri, fdtrc

from .._frozen import ArrayDataclass, frozen_array
from ..calibration import ParameterCovariance, SensorCalibration
from ..errors import InputError
from ..geometry.rotations import hat, quaternion_to_matrix
from ..stats.poses import power_of_two
from .integrate import (
    HOLDS,
    Hold,
    cumulative_quaternions,
    effective_time,
    quaternion_multiply,
    rotation_vector,
    step_quaternions,
)

__all__ = ["BIAS_NAMES", "GAIN_NAMES", "GyroFit", "fit_gyro"]

Array = NDArray[np.float64]
Method = Literal["rotations", "gravity"]

#: Covariance names of the gyroscope's parameters, in the order of :attr:`GyroFit.covariance`.
GAIN_NAMES = tuple(f"gyro.gain[{j},{k}]" for j in range(3) for k in range(3))
BIAS_NAMES = tuple(f"gyro.bias[{j}]" for j in range(3))

#: Fewest motion segments: 3 turns (9 residuals) about independent axes for the 9 gain entries.
MIN_SEGMENTS = 3
#: A combination of the gain's entries whose standard error exceeds this fraction of the gain's
#: size (``|K|_F/√3``) is not determined by the turns (refused, or left out with
#: ``allow_partial``): a 10 % uncertain gyroscope gain is no calibration.
NULL_STD = 0.1
#: A gain entry whose weight in a unit null vector exceeds this is not determined.
NULL_LOADING = 0.1
#: The segments' χ² test level below which the covariance is widened by χ²/dof.
WIDEN_P = 0.05
#: Family-wise false-alarm rate of the segment tests (Bonferroni over the segments).
REJECT_ALPHA = 0.01
#: The same before a stage is fitted, against the bulk of the segments at the current gain:
#: only gross misfits (a jump in the log) are left out before the fit.
PRESCREEN_ALPHA = 1e-4
#: Block length (seconds) of the still poses' block means that check the white-noise model.
BLOCK_SECONDS = 0.25
#: A gyroscope column flat at its extreme for this many consecutive motion rows saturates.
FLAT_ROWS = 4


@dataclass(frozen=True, eq=False)
class GyroFit(ArrayDataclass):
    """A gyroscope calibration: ``raw = gain @ ω + bias``, ``ω`` in rad/s in the body frame.

    Attributes
    ----------
    gain : (3, 3) array
        ``K_g``, raw units per rad/s: scale, cross-axis coupling and misalignment to the body
        frame of the rotations (or gravity directions) it was fitted to.
    bias : (3,) array
        ``b_g``, raw units: the still poses' biases averaged with their durations as weights.
    noise_cov : (3, 3) array
        Covariance of one raw sample (pooled scatter within the still poses), raw units².
    covariance : ParameterCovariance
        Cramér-Rao covariance of ``gyro.gain[j,k]`` and ``gyro.bias[j]`` (0-based) at the
        optimum, widened by :attr:`widening`; only the :attr:`observable` entries.
    pose_bias : (N, 3) array
        Each still pose's mean raw rate.
    pose_time : (N,) array
        Each still pose's mean time (s).
    drift : float or None
        ``|s|`` of the straight line ``p_i ≈ b + s t`` through :attr:`pose_bias`, raw units per
        second (``None`` with fewer than 3 poses); its vector is :attr:`drift_rate`, its
        significance :attr:`drift_p_value`.
    segment_residual_deg : (M,) array
        Per motion segment, after calibration: the angle between the integrated and the
        fitted rotation (``"rotations"``), or between the predicted and the observed gravity
        direction (``"gravity"``), degrees.
    segments : tuple of (int, int)
        Rows ``(first, last)`` of each motion segment used: from the last row of one pose to
        the first row of the next.
    observable : tuple of str
        The parameter names the data determine (all twelve unless ``allow_partial``).
    method : str
        ``"rotations"`` (orientations from the joint fit) or ``"gravity"`` (accelerometer only).
    drift_rate : (3,) array or None
        The drift line's slope per axis, raw units per second.
    drift_p_value : float or None
        Probability of a slope at least this large with a constant bias (small: it drifts).
    bias_wander : float
        Standard deviation per axis of the still poses' biases about the drift line beyond
        their white noise (raw units; 0 when the data show none).
    rate_noise : (3, 3) array
        ``Q``: the rate's noise density, raw units² · s (``Var ∫ε dt = Q T``).
    statistic, dof, p_value : float, int, float
        The segments' χ² at the optimum, its degrees of freedom (residuals − 9) and upper tail.
    widening : float
        Factor the Cramér-Rao covariance was multiplied by (1: not widened).
    iterations : int
        Gauss-Newton iterations, all rounds.
    converged : bool
        Whether the last round converged.
    rejected : tuple of (int, int)
        Rows of the motion segments left out because they fail their test (a residual beyond
        the χ² quantile ``1 − 0.01/M``): a jump in the log, a bump, a pose whose orientation
        the joint fit got wrong. At most half of them; the worst first, refitting each time.
    rejected_residual_deg : (R,) array
        Their residual angles at the final gain, degrees.
    """

    gain: Array
    bias: Array
    noise_cov: Array
    covariance: ParameterCovariance
    pose_bias: Array
    pose_time: Array
    drift: float | None
    segment_residual_deg: Array
    segments: tuple[tuple[int, int], ...]
    observable: tuple[str, ...]
    method: str
    drift_rate: Array | None = None
    drift_p_value: float | None = None
    bias_wander: float = 0.0
    rate_noise: Array = field(default_factory=lambda: np.zeros((3, 3)))
    statistic: float = 0.0
    dof: int = 0
    p_value: float = 1.0
    widening: float = 1.0
    iterations: int = 0
    converged: bool = True
    rejected: tuple[tuple[int, int], ...] = ()
    rejected_residual_deg: Array = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        for name in ("gain", "bias", "noise_cov", "pose_bias", "pose_time", "rate_noise"):
            object.__setattr__(self, name, frozen_array(getattr(self, name)))
        object.__setattr__(self, "segment_residual_deg", frozen_array(self.segment_residual_deg))
        if self.drift_rate is not None:
            object.__setattr__(self, "drift_rate", frozen_array(self.drift_rate))
        object.__setattr__(self, "segments", tuple((int(a), int(b)) for a, b in self.segments))
        object.__setattr__(self, "rejected", tuple((int(a), int(b)) for a, b in self.rejected))
        object.__setattr__(self, "rejected_residual_deg", frozen_array(self.rejected_residual_deg))
        object.__setattr__(self, "observable", tuple(self.observable))

    @property
    def gain_std(self) -> Array:
        """Standard error of each gain entry (NaN where not :attr:`observable`)."""
        return np.array(
            [self.covariance.std(n) if n in self.observable else np.nan for n in GAIN_NAMES]
        ).reshape(3, 3)

    @property
    def bias_std(self) -> Array:
        """Standard error of each bias entry."""
        return np.array([self.covariance.std(n) for n in BIAS_NAMES])

    @property
    def sensor(self) -> SensorCalibration:
        """The gyroscope as a calibration's sensor (``cal.gyro``): gain, bias, noise."""
        return SensorCalibration(gain=self.gain, bias=self.bias, noise_cov=self.noise_cov)

    def correct(self, raw: ArrayLike) -> Array:
        """Raw readings (..., 3) → body-frame rate in rad/s, ``gain⁻¹ (raw − bias)``
        (:meth:`SensorCalibration.correct`)."""
        return self.sensor.correct(raw)


# ----------------------------------------------------------------------------- SO(3) pieces
def _right_jacobian(phi: Array) -> Array:
    """``J_r(φ)`` (..., 3, 3): ``exp(φ + δ) ≈ exp(φ) exp(J_r(φ) δ)``."""
    t2 = np.einsum("...i,...i->...", phi, phi)
    t = np.sqrt(t2)
    small = t < 1e-3
    s = np.where(small, 1.0, t)
    a = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(s)) / (s * s))
    b = np.where(small, 1.0 / 6.0 - t2 / 120.0, (s - np.sin(s)) / (s * s * s))
    K = hat(phi)
    out: Array = np.eye(3) - a[..., None, None] * K + b[..., None, None] * (K @ K)
    return out


def _right_jacobian_inv(phi: Array) -> Array:
    """``J_r(φ)⁻¹`` (..., 3, 3): ``log(exp(φ) exp(ε)) ≈ φ + J_r(φ)⁻¹ ε``."""
    t2 = np.einsum("...i,...i->...", phi, phi)
    t = np.sqrt(t2)
    small = t < 1e-3
    s = np.where(small, 1.0, t)
    c = np.where(
        small, 1.0 / 12.0 + t2 / 720.0, 1.0 / (s * s) - (1.0 + np.cos(s)) / (2.0 * s * np.sin(s))
    )
    K = hat(phi)
    out: Array = np.eye(3) + 0.5 * K + c[..., None, None] * (K @ K)
    return out


def _conj(q: Array) -> Array:
    out = q.copy()
    out[..., 1:] *= -1.0
    return out


def _tangent_basis(u: Array) -> Array:
    """(..., 3, 2) orthonormal bases of the planes orthogonal to unit vectors ``u``."""
    helper = np.eye(3)[np.argmin(np.abs(u), axis=-1)]
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(u, e1)
    return np.stack([e1, e2], axis=-1)


# ----------------------------------------------------------------------------- the data
@dataclass
class _Segments:
    """The motion segments' intervals, concatenated: what the model needs of the log."""

    raw: Array  # (J, 3) the interval's raw rate (hold applied), scaled units
    dt: Array  # (J,)
    lam: Array  # (J,) interpolation weight of the later pose's bias
    seg: NDArray[np.int64]  # (J,) segment of each interval
    first: NDArray[np.int64]  # (M,) first interval of each segment
    last: NDArray[np.int64]  # (M,) last interval of each segment
    before: NDArray[np.int64]  # (M,) pose before each segment (the later one is before + 1)
    rows: tuple[tuple[int, int], ...]


@dataclass
class _Eval:
    """The model at one point: residuals and their Jacobians (unwhitened)."""

    r: Array  # (M, d) segment residuals
    J: Array  # (M, d, P) their Jacobian
    total: Array  # (M, 3, 3) integrated rotations
    cov_int: Array  # (M, 3, 3) integration noise of v per segment
    H: Array  # (M, d, 3) map from v to the residual (for the noise)


def _check_rows(poses: Sequence[Sequence[int]], n: int) -> NDArray[np.int64]:
    try:
        rows = np.array([[int(a), int(b)] for a, b in poses], dtype=np.int64)
    except (TypeError, ValueError):
        raise InputError(
            "poses must be a sequence of (start, stop) row pairs, one per still pose"
        ) from None
    if rows.ndim != 2 or len(rows) < 2:
        raise InputError(f"{len(rows)} still pose(s) given; the gyroscope needs at least 4")
    bad = (rows[:, 0] < 0) | (rows[:, 1] > n) | (rows[:, 1] - rows[:, 0] < 2)
    if np.any(bad):
        i = int(np.argmax(bad))
        raise InputError(
            f"pose {i} has rows {rows[i, 0]}..{rows[i, 1]}; each pose needs at least 2 rows "
            f"within the log's {n} (start inclusive, stop exclusive)"
        )
    overlap = rows[1:, 0] < rows[:-1, 1]
    if np.any(overlap):
        i = int(np.argmax(overlap)) + 1
        raise InputError(
            f"pose {i} starts at row {rows[i, 0]} before pose {i - 1} ends ({rows[i - 1, 1]}); "
            "give the still poses in time order, without overlap"
        )
    return rows


def _saturation(
    raw: Array,
    rows: NDArray[np.int64],
    links: NDArray[np.int64],
    full_scale: float | None,
    bias: Array,
    sigma: Array,
) -> None:
    """Refuse a gyroscope that clips during the turns: its integral would be short."""
    motion = np.zeros(len(raw), dtype=bool)
    for k in links:
        motion[rows[k, 1] - 1 : rows[k + 1, 0] + 1] = True
    for j, axis in enumerate("xyz"):
        x = raw[:, j]
        if full_scale is not None:
            hit = motion & (np.abs(x) >= 0.999 * full_scale)
            if np.any(hit):
                r = int(np.argmax(hit))
                raise InputError(
                    f"the gyroscope saturates on axis {axis} at row {r} ({x[r]:.6g}, full scale "
                    f"{full_scale:.6g}): the turns are faster than its range; turn more slowly "
                    "or record with a larger full-scale range"
                )
            continue
        for extreme in (float(x.max()), float(x.min())):
            if abs(extreme - bias[j]) <= 20.0 * max(float(sigma[j]), 1e-300):
                continue
            flat = motion & (x == extreme)
            if np.count_nonzero(flat) < FLAT_ROWS:
                continue
            # a run of FLAT_ROWS consecutive rows at the extreme: clipped, not a peak
            run = np.convolve(flat.astype(np.int64), np.ones(FLAT_ROWS, dtype=np.int64), "valid")
            if np.any(run == FLAT_ROWS):
                r = int(np.argmax(run == FLAT_ROWS))
                raise InputError(
                    f"the gyroscope saturates on axis {axis}: {extreme:.6g} raw units held for "
                    f"{FLAT_ROWS}+ rows from row {r} during a turn; turn more slowly or record "
                    "with a larger full-scale range (or pass full_scale if this is not clipping)"
                )


def _segments(
    t: Array,
    raw: Array,
    rows: NDArray[np.int64],
    links: NDArray[np.int64],
    pose_time: Array,
    hold: Hold,
) -> _Segments:
    raws, dts, lams, segs, firsts, lasts, spans = [], [], [], [], [], [], []
    position = 0
    for m, k in enumerate(links):
        a, c = int(rows[k, 1] - 1), int(rows[k + 1, 0])  # last row of pose k, first of k + 1
        x = raw[a : c + 1]
        tt = t[a : c + 1]
        u = 0.5 * (x[1:] + x[:-1]) if hold == "midpoint" else x[:-1]
        mid = 0.5 * (tt[1:] + tt[:-1]) if hold == "midpoint" else tt[:-1]
        lam = (mid - pose_time[k]) / (pose_time[k + 1] - pose_time[k])
        raws.append(u)
        dts.append(np.diff(tt))
        lams.append(lam)
        segs.append(np.full(len(u), m, dtype=np.int64))
        firsts.append(position)
        position += len(u)
        lasts.append(position - 1)
        spans.append((a, c))
    return _Segments(
        np.concatenate(raws),
        np.concatenate(dts),
        np.concatenate(lams),
        np.concatenate(segs),
        np.array(firsts, dtype=np.int64),
        np.array(lasts, dtype=np.int64),
        np.asarray(links, dtype=np.int64),
        tuple(spans),
    )


# ----------------------------------------------------------------------------- the model
class _Model:
    """Residuals of every segment and their Jacobians with respect to ``x = (vec M, b_0..)``."""

    def __init__(
        self,
        data: _Segments,
        method: Method,
        n_poses: int,
        observed: Array,
        noise_density: Array,
    ) -> None:
        self.data = data
        self.method = method
        self.n = n_poses
        self.Q = noise_density
        self.d = 3 if method == "rotations" else 2
        before = data.before
        if method == "rotations":
            # (M, 3, 3) the turns ΔR_i = R_{i+1} R_iᵀ of the segments, from the poses' R_i
            self.observed = observed[before + 1] @ np.transpose(observed[before], (0, 2, 1))
        else:
            self.observed = observed  # (N, 3) unit gravity directions
            self.basis_next = _tangent_basis(observed[before + 1])  # (M, 3, 2)

    @property
    def n_params(self) -> int:
        return 9 + 3 * self.n

    def rates(self, x: Array) -> tuple[Array, Array]:
        """Corrected raw ``raw − b(t)`` (J, 3) and the rate (J, 3)."""
        M = x[:9].reshape(3, 3)
        bias = _interval_bias(self.data, x[9:].reshape(self.n, 3))
        u = self.data.raw - bias
        return u, u @ M.T

    def integrate(self, w: Array) -> tuple[Array, Array, Array]:
        """Each segment's integrated rotation (M, 3, 3) of the rates ``w`` (J, 3), the rotation
        before each interval relative to its segment's start (J, 3, 3) and the interval steps'
        rotation vectors."""
        D = self.data
        phi = -w * D.dt[:, None]
        c = cumulative_quaternions(step_quaternions(w * D.dt[:, None]))
        prev = np.concatenate([[[1.0, 0.0, 0.0, 0.0]], c[:-1]])
        base = prev[D.first]  # (M, 4) product of everything before each segment
        rel = quaternion_multiply(prev, _conj(base[D.seg]))
        total = quaternion_multiply(c[D.last], _conj(base))
        return quaternion_to_matrix(total), quaternion_to_matrix(rel), phi

    def path_length(self, x: Array) -> Array:
        """The angle (rad) each segment turns through, ``∫ |ω| dt``."""
        _, w = self.rates(x)
        out: Array = np.add.reduceat(np.linalg.norm(w, axis=1) * self.data.dt, self.data.first)
        return out

    def evaluate(self, x: Array, *, with_jacobian: bool = True, linear: bool = False) -> _Eval:
        """Residuals and Jacobians at ``x``; ``linear``: the rotation residual's Jacobian as at
        a zero residual (for the observability check far from the optimum)."""
        D = self.data
        M = x[:9].reshape(3, 3)
        u_corr, w = self.rates(x)
        total, P, phi = self.integrate(w)
        m = len(D.first)
        if self.method == "rotations":
            r = rotation_vector(np.transpose(self.observed, (0, 2, 1)) @ total)
            H = -_right_jacobian_inv(0.0 * r if linear else r)  # dr = H v
        else:
            u = self.observed
            pred = np.einsum("mij,mj->mi", total, u[D.before])
            r = np.einsum("mia,mi->ma", self.basis_next, pred)
            # ΔR̂ exp(−[v]) u ≈ ΔR̂ u + ΔR̂ [u]× v
            H = np.einsum("mia,mij,mjk->mak", self.basis_next, total, hat(u[D.before]))
        # v = Σ_j dt_j P_{j−1}ᵀ J_r(φ_j) δω_j: the change of the segment's rotation (right)
        Pt = np.transpose(P, (0, 2, 1))
        Dj = D.dt[:, None, None] * (Pt @ _right_jacobian(phi))
        noise = D.dt[:, None, None] * (Pt @ (M @ self.Q @ M.T) @ P)
        cov_int = np.add.reduceat(noise, D.first, axis=0)
        J = np.zeros((m, self.d, self.n_params))
        if with_jacobian:
            dv_dM = np.einsum("jca,jb->jcab", Dj, u_corr).reshape(-1, 3, 9)
            dM = np.add.reduceat(dv_dM, D.first, axis=0)
            DM = Dj @ M
            lam = D.lam[:, None, None]
            db0 = -np.add.reduceat(DM * (1.0 - lam), D.first, axis=0)
            db1 = -np.add.reduceat(DM * lam, D.first, axis=0)
            J[:, :, :9] = H @ dM
            # the biases of the poses before (b0) and after (b1) each segment
            seg = np.arange(m)[:, None, None]
            cols = 9 + 3 * D.before[:, None, None] + np.arange(3)
            J[seg, np.arange(self.d)[:, None], cols] = H @ db0
            J[seg, np.arange(self.d)[:, None], cols + 3] = H @ db1
        return _Eval(r, J, total, cov_int, H)

    def pose_map(self, ev: _Eval) -> Array:
        """``B`` (M·d, N·k): the residuals' first-order response to the poses' errors."""
        D = self.data
        m = len(D.first)
        if self.method == "rotations":
            B = np.zeros((m, 3, self.n, 3))
            for k in range(m):
                i = int(D.before[k])
                B[k, :, i] = np.eye(3)
                B[k, :, i + 1] = -self.observed[k].T
            return B.reshape(3 * m, 3 * self.n)
        B = np.zeros((m, 2, self.n, 3))
        for k in range(m):
            i = int(D.before[k])
            E = self.basis_next[k]
            B[k, :, i] = E.T @ ev.total[k]
            B[k, :, i + 1] = -E.T
        return B.reshape(2 * m, 3 * self.n)


def _bdiag(blocks: Array) -> Array:
    m, d, _ = blocks.shape
    out = np.zeros((m * d, m * d))
    for k in range(m):
        out[k * d : (k + 1) * d, k * d : (k + 1) * d] = blocks[k]
    return out


class _Whitening:
    """The segments' joint covariance ``B C_pose Bᵀ + s² B C_unit Bᵀ + blockdiag(H C_int Hᵀ)``
    and the bias priors', fixed during one round of Gauss-Newton."""

    def __init__(self, seg_cov: Array, prior_cov: Array) -> None:
        self.seg_chol = np.linalg.cholesky(seg_cov)
        self.prior_chol = np.linalg.cholesky(prior_cov)  # (N, 3, 3)

    def residuals(self, ev: _Eval, x: Array, p: Array) -> Array:
        seg = np.linalg.solve(self.seg_chol, ev.r.ravel())
        b = x[9:].reshape(-1, 3)
        prior = np.linalg.solve(self.prior_chol, (b - p)[:, :, None])[:, :, 0]
        return np.concatenate([seg, prior.ravel()])

    def jacobian(self, ev: _Eval, n_params: int) -> Array:
        m, d, _ = ev.J.shape
        seg = np.linalg.solve(self.seg_chol, ev.J.reshape(m * d, n_params))
        n = self.prior_chol.shape[0]
        prior = np.zeros((3 * n, n_params))
        prior[:, 9:] = block_diag(*np.linalg.inv(self.prior_chol))  # each pose's own bias
        return np.vstack([seg, prior])


def _gauss_newton(
    model: _Model,
    white: _Whitening,
    x: Array,
    p: Array,
    basis: Array | None,
    max_iter: int,
) -> tuple[Array, float, int, bool]:
    """Levenberg-Marquardt on the whitened residuals; ``basis`` (9, r) restricts the gain's
    step to the determined directions (``None``: all)."""

    def cost_at(y: Array) -> tuple[float, _Eval | None]:
        try:
            ev = model.evaluate(y, with_jacobian=False)
        except (FloatingPointError, np.linalg.LinAlgError):
            return math.inf, None
        e = white.residuals(ev, y, p)
        c = float(e @ e)
        return (c if math.isfinite(c) else math.inf), ev

    lam = 1e-3
    it = 0
    converged = False
    cost, _ = cost_at(x)
    while it < max_iter:
        it += 1
        ev = model.evaluate(x)
        e = white.residuals(ev, x, p)
        J = white.jacobian(ev, model.n_params)
        if basis is not None:
            J = np.hstack([J[:, :9] @ basis, J[:, 9:]])
        A = J.T @ J
        g = J.T @ e
        diag = np.diag(A).copy()
        while True:
            step = np.linalg.solve(A + lam * np.diag(np.maximum(diag, 1e-12)), -g)
            full = (
                step
                if basis is None
                else np.concatenate([basis @ step[: basis.shape[1]], step[basis.shape[1] :]])
            )
            trial = x + full
            new, _ = cost_at(trial)
            if new < cost:
                pred = float(-(step @ g))
                rho = (cost - new) / max(pred, 1e-300)
                x, gain = trial, cost - new
                cost = new
                lam = max(lam * (1.0 / 3.0 if rho > 0.75 else 1.0), 1e-12)
                break
            lam *= 10.0
            if lam > 1e12:
                return x, cost, it, True  # no descent left: at the minimum to round-off
        # J is a χ² variate of size ~dof: a change of 1e-6 in it means nothing statistically
        if gain <= 1e-6 * (1.0 + cost):
            converged = True
            break
    return x, cost, it, converged


# ----------------------------------------------------------------------------- the fit
def _pose_statistics(
    t: Array, raw: Array, rows: NDArray[np.int64]
) -> tuple[Array, Array, Array, Array, int, Array]:
    """Pose means, mean times, durations, pooled sample covariance (and its dof), and the
    block-mean check of the white-noise model (the rate noise density's factor)."""
    n_pose = len(rows)
    means = np.empty((n_pose, 3))
    times = np.empty(n_pose)
    durations = np.empty(n_pose)
    scatter = np.zeros((3, 3))
    dof = 0
    steps = np.diff(t)
    typical = float(np.median(steps[steps > 0])) if np.any(steps > 0) else 1.0
    block_scatter = np.zeros((3, 3))
    block_dof = 0
    block_len = max(4, round(BLOCK_SECONDS / typical))
    for i, (a, b) in enumerate(rows):
        x = raw[a:b]
        means[i] = x.mean(axis=0)
        times[i] = float(t[a:b].mean())
        durations[i] = float(t[b - 1] - t[a]) + typical
        d = x - means[i]
        scatter += d.T @ d
        dof += len(x) - 1
    for a, b in rows:
        count = (b - a) // block_len
        if count >= 2:
            blocks = raw[a : a + count * block_len].reshape(count, block_len, 3).mean(axis=1)
            d = blocks - blocks.mean(axis=0)
            block_scatter += d.T @ d
            block_dof += count - 1
    cov = scatter / max(dof, 1)
    q_white = cov * typical
    factor = 1.0
    if block_dof >= 10 and np.trace(cov) > 0:
        q_block = block_scatter / block_dof * (block_len * typical)
        ratio = float(np.trace(np.linalg.solve(q_white, q_block))) / 3.0
        # a low-pass filter or a wandering bias: block means vary more than white noise says
        if ratio > 1.0 + 3.0 * math.sqrt(2.0 / block_dof):
            factor = ratio
    return means, times, durations, cov, dof, q_white * factor


def _drift(
    means: Array, times: Array, durations: Array, Q: Array
) -> tuple[Array | None, float | None, float, Array]:
    """The bias line through the poses' means: slope, its p-value, the wander ``v`` (raw²)
    beyond white noise and the per-pose prior covariance ``Q/T_i + v I``."""
    n = len(means)
    base = Q[None] / durations[:, None, None]
    if n < 3:
        return None, None, 0.0, base
    tau = times - np.average(times, weights=durations)
    X = np.zeros((n, 3, 6))
    X[:, :, :3] = np.eye(3)
    X[:, :, 3:] = tau[:, None, None] * np.eye(3)

    def gls(cov: Array) -> tuple[Array, Array, float]:
        inv = np.linalg.inv(cov)
        A = np.einsum("nai,nab,nbj->ij", X, inv, X)
        rhs = np.einsum("nai,nab,nb->i", X, inv, means)
        C = np.linalg.inv(A)
        beta = C @ rhs
        res = means - np.einsum("nai,i->na", X, beta)
        chi2 = float(np.einsum("na,nab,nb->", res, inv, res))
        return beta, C, chi2

    dof = 3 * (n - 2)
    beta, C, chi2 = gls(base)
    v = 0.0
    if chdtrc(dof, chi2) < 0.01:
        # the poses' biases wander beyond white noise: v I added to each, χ² = dof
        lo, hi = 0.0, float(np.max(np.var(means, axis=0))) * 4.0 + 1e-300
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            if gls(base + mid * np.eye(3))[2] > dof:
                lo = mid
            else:
                hi = mid
        v = hi
        beta, C, chi2 = gls(base + v * np.eye(3))
    slope, Cs = beta[3:], C[3:, 3:]
    z2 = float(slope @ np.linalg.solve(Cs, slope))
    p = float(fdtrc(3, dof, z2 / 3.0)) if v > 0 else float(chdtrc(3, z2))
    return slope, p, v, base + v * np.eye(3)


def _unwrap(phi: Array, predicted: Array) -> Array:
    """The rotation vectors ``φ + 2πm φ/|φ|`` nearest to ``predicted`` (turns beyond half a
    turn have the same rotation; the integrated rate says how far the device went)."""
    angle = np.linalg.norm(phi, axis=1)
    axis = phi / np.where(angle > 0, angle, 1.0)[:, None]
    along = np.einsum("mi,mi->m", axis, predicted)
    m = np.round((along - angle) / (2.0 * np.pi))
    out: Array = axis * (angle + 2.0 * np.pi * m)[:, None]
    return out


def _linear_gain(s: Array, phi: Array) -> tuple[Array, bool]:
    """``K`` minimising ``Σ |s_k − K φ_k|²`` and whether the turns span three axes; along axes
    no turn spans, ``K`` is the mean scale of the others (the observability check names them).
    """
    A = phi.T @ phi
    w, V = np.linalg.eigh(A)
    full = bool(w[0] > 1e-6 * w[-1])
    keep = w > 1e-6 * w[-1] if w[-1] > 0 else np.zeros(3, dtype=bool)
    if not np.any(keep):
        return np.eye(3), False
    Vk = V[:, keep]
    K = (s.T @ phi) @ Vk @ np.diag(1.0 / w[keep]) @ Vk.T
    if not full:
        scale = float(np.mean(np.linalg.svd(K @ Vk, compute_uv=False)))
        Vn = V[:, ~keep]
        K = K + scale * Vn @ Vn.T
    return K, full


def _guess_matrix(gain_guess: float | ArrayLike | None, unit: float) -> Array | None:
    if gain_guess is None:
        return None
    G = np.asarray(gain_guess, dtype=float)
    if G.shape == ():
        G = float(G) * np.eye(3)
    if G.shape != (3, 3) or not np.all(np.isfinite(G)) or abs(np.linalg.det(G)) == 0:
        raise InputError(
            "gain_guess must be a number (raw units per rad/s, e.g. from the datasheet) or an "
            "invertible 3x3 matrix"
        )
    out: Array = G / unit
    return out


def _interval_bias(data: _Segments, b: Array) -> Array:
    """The bias (J, 3) over each interval, linear in time between the poses' biases ``b``."""
    lam = data.lam[:, None]
    pose = data.before[data.seg]
    out: Array = (1.0 - lam) * b[pose] + lam * b[pose + 1]
    return out


def _segment_sums(data: _Segments, p: Array) -> Array:
    """``∫ (raw − b(t)) dt`` of each segment with the still poses' biases (scaled units·s)."""
    u = data.raw - _interval_bias(data, p)
    out: Array = np.add.reduceat(u * data.dt[:, None], data.first, axis=0)
    return out


def _start_rotations(data: _Segments, p: Array, observed: Array, guess: Array | None) -> Array:
    """A start for ``M = K⁻¹``: the guess, else ``s_k ≈ K φ_k`` by least squares, ``s_k`` the
    segment's integrated raw rate and ``φ_k`` its turn (exact for a turn about a fixed axis),
    over the turns under 120° (no doubt how far they went) whose ``|s_k| / |φ_k|`` is within a
    factor 1.5 of the median (a jump in the log, a turn the gyroscope never saw, is left out),
    then with every turn counted by that gain."""
    if guess is not None:
        out: Array = np.asarray(np.linalg.inv(guess), dtype=float)
        return out
    s = _segment_sums(data, p)
    phi = -rotation_vector(observed)  # ΔR = exp(−[∫ω]×) for a turn about a fixed axis
    angle = np.linalg.norm(phi, axis=1)
    ratio = np.linalg.norm(s, axis=1) / np.maximum(angle, 1e-300)
    turned = angle > np.radians(10.0)
    c = float(np.median(ratio[turned])) if np.any(turned) else float(np.median(ratio))
    usable = turned & (ratio > c / 1.5) & (ratio < 1.5 * c)
    small = usable & (angle < 2.0 * np.pi / 3.0)
    K, full = _linear_gain(s[small], phi[small])
    if not full:
        K, full = _linear_gain(s[usable], phi[usable])
    if not full:
        K, _ = _linear_gain(s, phi)
    pick = usable if np.count_nonzero(usable) >= 3 else np.ones(len(s), dtype=bool)
    K, _ = _linear_gain(s[pick], _unwrap(phi[pick], np.linalg.solve(K, s[pick].T).T))
    if not np.all(np.isfinite(K)) or abs(np.linalg.det(K)) == 0:
        raise InputError(
            "the turns between the poses give no start for the gyroscope's gain; pass "
            "gain_guess (raw units per rad/s, e.g. from the datasheet)"
        )
    out = np.asarray(np.linalg.inv(K), dtype=float)
    return out


def _start_gravity(data: _Segments, p: Array, u: Array, guess: Array | None, n_poses: int) -> Array:
    if guess is not None:
        out: Array = np.asarray(np.linalg.inv(guess), dtype=float)
        return out
    # a scalar gain c (either sign), searched on a log grid: the integrated turns must carry
    # each gravity direction to the next
    s = _segment_sums(data, p)
    angle = np.arccos(np.clip(np.einsum("mi,mi->m", u[data.before], u[data.before + 1]), -1, 1))
    c0 = float(np.median(np.linalg.norm(s, axis=1)) / max(float(np.median(angle)), 1e-3))
    model = _Model(data, "gravity", n_poses, u, np.zeros((3, 3)))
    x = np.concatenate([np.zeros(9), p.ravel()])
    best, best_cost = np.eye(3) / c0, math.inf
    for sign in (1.0, -1.0):
        for factor in np.geomspace(0.1, 10.0, 31):
            x[:9] = (np.eye(3) / (sign * c0 * factor)).ravel()
            r = model.evaluate(x, with_jacobian=False).r
            cost = float(np.sum(r * r))
            if cost < best_cost:
                best, best_cost = x[:9].reshape(3, 3).copy(), cost
    return best


def _null_space(information: Array, K: Array) -> tuple[Array, tuple[str, ...]]:
    """The gain's undetermined combinations at ``K``: an orthonormal basis (9, r) of the
    directions of ``M = K⁻¹`` the fit may move along (those orthogonal to the undetermined ones)
    and the names of the ``K`` entries the undetermined combinations touch.

    ``information`` is the gain's information matrix in ``M``'s entries (biases eliminated);
    mapped to ``K``'s entries (``dK = −K dM K``), a combination is undetermined when its
    standard error exceeds :data:`NULL_STD` of the gain's size."""
    T = -np.kron(K, K.T)  # dK = −K dM K, row-major
    Tinv = np.linalg.inv(T)
    IK = Tinv.T @ information @ Tinv
    w, V = np.linalg.eigh(0.5 * (IK + IK.T))
    size = float(np.linalg.norm(K)) / math.sqrt(3.0)
    null = w * (NULL_STD * size) ** 2 < 1.0
    if not np.any(null):
        return np.eye(9), ()
    touched = np.max(np.abs(V[:, null]), axis=1) > NULL_LOADING
    names = tuple(n for n, hit in zip(GAIN_NAMES, touched, strict=True) if hit)
    in_M, _ = np.linalg.qr(Tinv @ V[:, null])
    return _complement(in_M), names


def _reset_null(M: Array, basis: Array, M0: Array) -> Array:
    """``M`` with its undetermined part (orthogonal to ``basis``) put back at the start's: those
    directions change no prediction (to first order), so the gain keeps the start's values
    there (``K``'s entries along the null directions, least squares)."""
    K = np.linalg.inv(M)
    null = -np.kron(K, K.T) @ _complement(basis)
    a = np.linalg.lstsq(null, (np.linalg.inv(M0) - K).ravel(), rcond=None)[0]
    out: Array = np.linalg.inv(K + (null @ a).reshape(3, 3))
    return out


def _complement(basis: Array) -> Array:
    """An orthonormal basis (9, 9 − r) of the complement of an orthonormal basis (9, r)."""
    U, _, _ = np.linalg.svd(basis, full_matrices=True)
    out: Array = U[:, basis.shape[1] :]
    return out


def _gain_information(J: Array) -> Array:
    """The gain block of the information matrix with the biases eliminated (Schur)."""
    F = J.T @ J
    Fmm, Fmb, Fbb = F[:9, :9], F[:9, 9:], F[9:, 9:]
    out: Array = Fmm - Fmb @ np.linalg.solve(Fbb, Fmb.T)
    return 0.5 * (out + out.T)


def fit_gyro(
    time: ArrayLike,
    gyro_raw: ArrayLike,
    poses: Sequence[Sequence[int]],
    rotations: ArrayLike | None = None,
    *,
    rotation_cov: ArrayLike | None = None,
    gravity_body: ArrayLike | None = None,
    gravity_cov: ArrayLike | None = None,
    links: Sequence[int] | None = None,
    gain_guess: float | ArrayLike | None = None,
    full_scale: float | None = None,
    hold: Hold = "midpoint",
    allow_partial: bool = False,
    max_iter: int = 50,
) -> GyroFit:
    """Fit the gyroscope's gain and bias from still poses and the motion between them.

    Parameters
    ----------
    time : (n,) array_like
        Seconds, non-decreasing (repeated timestamps are spread, :func:`.effective_time`).
    gyro_raw : (n, 3) array_like
        Raw gyroscope readings, any units.
    poses : sequence of (start, stop)
        Rows of each still pose (stop exclusive), in time order.
    rotations : (N, 3, 3) array_like, optional
        Each pose's rotation world (NED) → body from the joint fit (``cal.rotations``):
        ``method="rotations"``.
    rotation_cov : (N, 3, 3) or (3N, 3N) array_like, optional
        Covariance of the poses' small body-frame rotation errors (``R ← exp([δ]×) R``),
        radians²: per pose, or joint with the poses' shared errors
        (:func:`fieldcal.methods.mle.uncertainty.pose_rotation_covariance`). Without it an
        isotropic orientation error is estimated from the fit (needs more than 3 segments).
    gravity_body : (N, 3) array_like, optional
        Without ``rotations``: each pose's calibrated accelerometer reading (any length; the
        direction is used), ``method="gravity"``.
    gravity_cov : (N, 3, 3) or (3N, 3N) array_like, optional
        Covariance of ``gravity_body`` (its units squared), per pose or joint; for an
        accelerometer calibration ``X C Xᵀ`` with ``X = blockdiag(−[g_i]×)`` and ``C`` its
        :func:`~fieldcal.methods.mle.uncertainty.pose_rotation_covariance`. Without it an
        isotropic direction error is estimated from the fit.
    links : sequence of int, optional
        The segments to use, ``k`` for the motion from pose ``k`` to ``k + 1`` (default all):
        leave out gaps where the log was cut.
    gain_guess : float or (3, 3) array_like, optional
        An approximate gain (raw units per rad/s, e.g. the datasheet's), to count the turns of
        segments that turn by more than half a turn (a full turn ends where it began).
    full_scale : float, optional
        The gyroscope's range in raw units: readings beyond 99.9 % of it during a turn are
        refused as saturated (without it, a reading held at the log's extreme for 4 rows is).
    hold : {"midpoint", "previous"}
        The rate over each interval between samples (:mod:`.integrate`).
    allow_partial : bool
        Fit what the data determine instead of refusing: the fit moves only along the
        determined combinations of the gain's entries and puts the undetermined ones back at
        the start's values (``gain_guess``, else the linear start); the entries they touch are
        left out of ``observable`` and the covariance (their values are not to be trusted).
    max_iter : int
        Gauss-Newton iterations per round.

    Returns
    -------
    GyroFit

    Raises
    ------
    InputError
        For input that cannot give a calibration, in one line naming the fix: too few poses or
        motion segments, time going backwards, a saturating gyroscope, turns that do not
        determine every gain entry (unless ``allow_partial``).
    """
    raw_given = np.asarray(gyro_raw, dtype=float)
    if raw_given.ndim != 2 or raw_given.shape[1] != 3:
        raise InputError(f"gyro_raw must have shape (n, 3), got {raw_given.shape}")
    if not np.all(np.isfinite(raw_given)):
        row = int(np.argmin(np.all(np.isfinite(raw_given), axis=1)))
        raise InputError(f"gyro_raw has a NaN or inf value at row {row}; drop or fix that row")
    if hold not in HOLDS:
        raise InputError(f"hold must be one of {', '.join(HOLDS)}; got {hold!r}")
    t = effective_time(time)
    if len(t) != len(raw_given):
        raise InputError(
            f"time has {len(t)} rows but gyro_raw has {len(raw_given)}; pass equal rows"
        )
    n = len(t)
    # the fit runs in units of an exact power of two: the same numbers whatever the raw unit
    unit = power_of_two(float(np.max(np.abs(raw_given))) or 1.0)
    raw = raw_given / unit
    rows = _check_rows(poses, n)
    n_poses = len(rows)
    if links is None:
        link = np.arange(n_poses - 1, dtype=np.int64)
    else:
        link = np.unique(np.asarray(list(links), dtype=np.int64))
        if link.size and (link.min() < 0 or link.max() > n_poses - 2):
            raise InputError(f"links must be pose numbers from 0 to {n_poses - 2}")
    if len(link) < MIN_SEGMENTS:
        raise InputError(
            f"{len(link)} motion segment(s) between still poses; the gyroscope's 9 gain entries "
            f"need at least {MIN_SEGMENTS} turns about different axes, each between two rests"
        )
    method: Method
    if rotations is not None:
        method = "rotations"
        Rs = np.asarray(rotations, dtype=float)
        if Rs.shape != (n_poses, 3, 3) or not np.all(np.isfinite(Rs)):
            raise InputError(
                f"rotations must have shape ({n_poses}, 3, 3), one per pose; got {Rs.shape}"
            )
        if not np.allclose(Rs @ np.transpose(Rs, (0, 2, 1)), np.eye(3), atol=1e-6):
            raise InputError("rotations must be rotation matrices (orthonormal, det +1)")
        observed = Rs
    elif gravity_body is not None:
        method = "gravity"
        g = np.asarray(gravity_body, dtype=float)
        if g.shape != (n_poses, 3) or not np.all(np.isfinite(g)):
            raise InputError(f"gravity_body must have shape ({n_poses}, 3), one per pose")
        norm = np.linalg.norm(g, axis=1)
        if not np.all(norm > 0):
            raise InputError("gravity_body has a zero vector; give calibrated accelerometer means")
        observed = g / norm[:, None]
    else:
        raise InputError(
            "give the poses' rotations (a joint calibration's cal.rotations) or, with an "
            "accelerometer alone, gravity_body (its calibrated pose means)"
        )

    means, times, durations, noise_cov, _, Q = _pose_statistics(t, raw, rows)
    if np.any(np.diff(times) <= 0):
        raise InputError("the still poses must be in time order")
    sigma = np.sqrt(np.diag(noise_cov))
    _saturation(
        raw, rows, link, None if full_scale is None else full_scale / unit, means.mean(0), sigma
    )
    slope, drift_p, wander, prior_cov = _drift(means, times, durations, Q)
    if not np.all(np.linalg.eigvalsh(prior_cov) > 0):
        raise InputError(
            "the still poses show no gyroscope noise at all (identical readings); give the raw "
            "readings, not a smoothed or constant column"
        )
    data = _segments(t, raw, rows, link, times, hold)
    full = _Model(data, method, n_poses, observed, Q)
    guess = _guess_matrix(gain_guess, unit)
    if method == "rotations":
        M0 = _start_rotations(data, means, full.observed, guess)
    else:
        M0 = _start_gravity(data, means, observed, guess, n_poses)
    x = np.concatenate([M0.ravel(), means.ravel()])

    # the poses' part of the residual covariance: given, or s² times a unit shape
    d = full.d
    m = len(link)
    unit_pose: Array
    pose_given: Array | None = None
    if method == "rotations":
        if rotation_cov is not None:
            pose_given = _pose_covariance(rotation_cov, n_poses, "rotation_cov")
        unit_pose = np.eye(3 * n_poses)
    else:
        across = np.eye(3) - np.einsum("ni,nj->nij", observed, observed)
        if gravity_cov is not None:
            C = _pose_covariance(gravity_cov, n_poses, "gravity_cov")
            gnorm = np.linalg.norm(np.asarray(gravity_body, dtype=float), axis=1)
            # the unit direction's error: the part across the vector, over its length
            Pp = _bdiag(across / gnorm[:, None, None])
            pose_given = Pp @ C @ Pp
        unit_pose = _bdiag(across)
    dof = d * m - 9
    if pose_given is None and dof < 1:
        raise InputError(
            f"{m} motion segments leave no residual to estimate the poses' orientation error "
            f"from; give {'rotation_cov' if method == 'rotations' else 'gravity_cov'} or record "
            "more poses"
        )

    def covariance(model: _Model, ev: _Eval, scale2: float) -> Array:
        B = model.pose_map(ev)
        pose = pose_given if pose_given is not None else scale2 * unit_pose
        integ = _bdiag(ev.H @ ev.cov_int @ np.transpose(ev.H, (0, 2, 1)))
        total = B @ pose @ B.T + integ
        total = 0.5 * (total + total.T)
        # the smallest part any residual may carry: round-off, not information
        jitter = 1e-12 * float(np.max(np.diag(total)))
        return total + jitter * np.eye(len(total))

    # which gain combinations the turns determine, linearised at the start
    ev = full.evaluate(x, linear=True)
    scale2 = _initial_scale(ev)
    info = _gain_information(
        _Whitening(covariance(full, ev, scale2), prior_cov).jacobian(ev, full.n_params)
    )
    basis, unobservable = _null_space(info, np.asarray(np.linalg.inv(M0), dtype=float))
    if unobservable and not allow_partial:
        raise InputError(_unobservable_message(unobservable, method))
    restrict = None if basis.shape[1] == 9 else basis
    iterations = 0
    converged = False
    dropped: list[int] = []  # segments (positions in link) refused as not fitting
    models: dict[tuple[int, ...], _Model] = {}

    def model_of(chosen: Sequence[int]) -> _Model:
        key = tuple(int(k) for k in chosen)
        if len(key) == m:
            return full
        if key not in models:
            picked = _segments(t, raw, rows, link[list(key)], times, hold)
            models[key] = _Model(picked, method, n_poses, observed, Q)
        return models[key]

    def fit_set(chosen: list[int], x: Array, scale2: float, last: bool) -> tuple[Array, float]:
        """Fit the chosen segments; drop the worst one that fails its test and refit, until
        none fails (at most half of all segments dropped, at least 3 kept)."""
        nonlocal iterations, converged
        # before fitting, refuse the segments that stand out from the rest at the current
        # gain (a jump in the log: a turn the gyroscope never saw); their size against the
        # bulk's, so a rough start does not condemn good segments
        model = model_of(chosen)
        ev = model.evaluate(x, with_jacobian=False)
        stat = _segment_statistics(ev, covariance(model, ev, scale2), d)
        bulk = max(float(np.median(stat)) / float(chdtri(d, 0.5)), 1.0)
        p_seg = chdtrc(d, stat / bulk)
        for k in np.argsort(p_seg):
            # only the gross ones: the fit's own tests below catch the rest
            if p_seg[k] >= PRESCREEN_ALPHA / len(chosen) or len(dropped) + 1 > m // 2:
                break
            if len(chosen) - 1 < MIN_SEGMENTS:
                break
            dropped.append(chosen[k])
        chosen = [k for k in chosen if k not in dropped]
        while True:
            model = model_of(chosen)
            ev = model.evaluate(x)
            free = pose_given is None
            cov_of = functools.partial(covariance, model)
            if free:
                scale2 = _robust_scale(ev, cov_of, d)
            for _ in range(4 if last else 1):
                white = _Whitening(covariance(model, ev, scale2), prior_cov)
                x, _, it, converged = _gauss_newton(model, white, x, means, restrict, max_iter)
                iterations += it
                ev = model.evaluate(x)
                if free:
                    new = _robust_scale(ev, cov_of, d)
                    done = abs(new - scale2) <= 1e-3 * max(scale2, 1e-300)
                    scale2 = new
                    if done:
                        break
                elif converged:
                    break
            stat = _segment_statistics(ev, covariance(model, ev, scale2), d)
            p_seg = chdtrc(d, stat)
            worst = int(np.argmin(p_seg))
            if p_seg[worst] >= REJECT_ALPHA / len(chosen):
                return x, scale2
            if len(dropped) + 1 > m // 2 or len(chosen) - 1 < MIN_SEGMENTS:
                return x, scale2
            dropped.append(chosen.pop(worst))

    # continuation: the segments that turn least first (a gain error of ε puts a segment's
    # integral off by ε times the angle it turns through, and a residual past half a turn
    # wraps), then ever longer ones, until every segment is in
    path = full.path_length(x)
    for stage in _stages(path):
        chosen = [int(k) for k in stage if int(k) not in dropped]
        x, scale2 = fit_set(chosen, x, scale2, len(stage) == m)
    used = [k for k in range(m) if k not in dropped]
    final = model_of(used)
    ev = final.evaluate(x)
    # the turns may determine less at the optimum than the start suggested (a full turn ends
    # where it began whatever its axis): check again, and refit what is determined
    info = _gain_information(
        _Whitening(covariance(final, ev, scale2), prior_cov).jacobian(ev, final.n_params)
    )
    basis, more = _null_space(info, np.linalg.inv(x[:9].reshape(3, 3)))
    if set(more) - set(unobservable):
        if not allow_partial:
            raise InputError(_unobservable_message(more, method))
        unobservable = tuple(n for n in GAIN_NAMES if n in set(more) | set(unobservable))
        restrict = basis
        x[:9] = _reset_null(x[:9].reshape(3, 3), restrict, M0).ravel()
        x, scale2 = fit_set(used, x, scale2, True)
        used = [k for k in range(m) if k not in dropped]
        final = model_of(used)
        ev = final.evaluate(x)
    dof = d * len(used) - 9
    if pose_given is None:
        scale2 = _match_chi2(ev, lambda e, s2: covariance(final, e, s2), dof, scale2)
    full = final
    white = _Whitening(covariance(full, ev, scale2), prior_cov)
    chi2 = float(np.sum(np.linalg.solve(white.seg_chol, ev.r.ravel()) ** 2))
    J = white.jacobian(ev, full.n_params)
    M = x[:9].reshape(3, 3)
    K: Array = np.asarray(np.linalg.inv(M), dtype=float)
    if restrict is not None:
        M = _reset_null(M, restrict, M0)
        K = np.asarray(np.linalg.inv(M), dtype=float)
        x[:9] = M.ravel()
        ev = full.evaluate(x)
        white = _Whitening(covariance(full, ev, scale2), prior_cov)
    biases = x[9:].reshape(n_poses, 3)
    weights = durations / durations.sum()
    # the named parameters' map: dK = −K dM K (row-major), bias = Σ w_i b_i
    L = np.zeros((12, full.n_params))
    L[:9, :9] = -np.kron(K, K.T)
    L[9:, 9:] = np.kron(weights[None, :], np.eye(3))
    if restrict is None:
        Cx = np.linalg.inv(J.T @ J)
    else:
        Jr = np.hstack([J[:, :9] @ restrict, J[:, 9:]])
        E = np.zeros((full.n_params, Jr.shape[1]))
        E[:9, : restrict.shape[1]] = restrict
        E[9:, restrict.shape[1] :] = np.eye(3 * n_poses)
        Cx = E @ np.linalg.inv(Jr.T @ Jr) @ E.T
    p_value = float(chdtrc(dof, chi2)) if dof > 0 else 1.0
    widen = 1.0
    if pose_given is not None and dof > 0 and p_value < WIDEN_P:
        widen = chi2 / dof
    C12 = widen * (L @ Cx @ L.T) * unit * unit
    names = list(GAIN_NAMES + BIAS_NAMES)
    keep = [i for i, nm in enumerate(names) if nm not in unobservable]
    covariance_named = ParameterCovariance(
        tuple(names[i] for i in keep), 0.5 * (C12 + C12.T)[np.ix_(keep, keep)]
    )
    if method == "rotations":
        residual_deg = np.degrees(np.linalg.norm(ev.r, axis=1))
    else:
        residual_deg = np.degrees(np.arcsin(np.clip(np.linalg.norm(ev.r, axis=1), 0.0, 1.0)))
    refused: tuple[tuple[int, int], ...] = ()
    refused_deg = np.zeros(0)
    if dropped:
        out = model_of(sorted(dropped))
        ev_out = out.evaluate(x, with_jacobian=False)
        refused = out.data.rows
        norms = np.linalg.norm(ev_out.r, axis=1)
        refused_deg = np.degrees(
            norms if method == "rotations" else np.arcsin(np.clip(norms, 0.0, 1.0))
        )
    return GyroFit(
        gain=K * unit,
        bias=weights @ biases * unit,
        noise_cov=noise_cov * unit * unit,
        covariance=covariance_named,
        pose_bias=means * unit,
        pose_time=times,
        drift=None if slope is None else float(np.linalg.norm(slope)) * unit,
        segment_residual_deg=residual_deg,
        segments=full.data.rows,
        observable=tuple(names[i] for i in keep),
        method=method,
        drift_rate=None if slope is None else slope * unit,
        drift_p_value=drift_p,
        bias_wander=math.sqrt(wander) * unit,
        rate_noise=Q * unit * unit,
        statistic=chi2,
        dof=dof,
        p_value=p_value,
        widening=widen,
        iterations=iterations,
        converged=converged,
        rejected=refused,
        rejected_residual_deg=refused_deg,
    )


def _stages(path: Array) -> list[NDArray[np.int64]]:
    """Growing sets of segments, by the angle each turns through: those under half a turn
    (at least the four shortest), then each doubling of the limit, the last set all of them."""
    order = np.argsort(path)
    out: list[NDArray[np.int64]] = []
    limit = np.pi
    while True:
        count = max(int(np.count_nonzero(path <= limit)), min(4, len(path)))
        chosen = np.sort(order[:count])
        if not out or len(chosen) > len(out[-1]):
            out.append(chosen)
        if count == len(path):
            return out
        limit *= 2.0


def _unobservable_message(names: tuple[str, ...], method: str) -> str:
    """One line naming the gain entries the turns leave free and what to record."""
    rows = sorted({int(n[-4]) for n in names})  # gyro.gain[j,k]: j the raw axis, k the body's
    columns = sorted({int(n[-2]) for n in names})
    turn = ", ".join("xyz"[a] for a in columns)
    if len(names) == 9:
        why = (
            "no turn tilts the device (gravity sees only tilts)"
            if method == "gravity"
            else "the turns do not span the body axes"
        )
    elif len(columns) < 3:
        why = "no turn is about body axis " + " or ".join("xyz"[a] for a in columns)
    elif len(rows) == 1:
        why = f"the turns kept hardly move the gyroscope's raw axis {'xyz'[rows[0]]}"
        turn = "x, y and z"
    else:
        why = "the turns do not span the body axes"
    return (
        f"the turns between the poses do not determine {', '.join(names)} ({why}): add turns "
        f"about body axis {turn} (library: allow_partial=True fits the rest)"
    )


def _pose_covariance(value: ArrayLike, n: int, name: str) -> Array:
    C = np.asarray(value, dtype=float)
    if C.shape == (n, 3, 3):
        C = _bdiag(C)
    if C.shape != (3 * n, 3 * n) or not np.all(np.isfinite(C)):
        raise InputError(f"{name} must have shape ({n}, 3, 3) or ({3 * n}, {3 * n})")
    return 0.5 * (C + C.T)


def _segment_statistics(ev: _Eval, cov: Array, d: int) -> Array:
    """Each segment's ``rᵀ Σ_kk⁻¹ r`` with its own block of the joint covariance: χ²(d) for a
    segment that fits (a little less, as the fit absorbs part of every residual)."""
    m = len(ev.r)
    blocks = np.stack([cov[k * d : (k + 1) * d, k * d : (k + 1) * d] for k in range(m)])
    out: Array = np.einsum("mi,mi->m", ev.r, np.linalg.solve(blocks, ev.r[:, :, None])[:, :, 0])
    return out


def _robust_scale(ev: _Eval, cov: Callable[[_Eval, float], Array], d: int) -> float:
    """The orientation variance ``s²`` at which the median segment statistic is χ²(d)'s
    median: a few segments that do not fit cannot inflate it."""
    target = float(chdtri(d, 0.5))

    def median_stat(s2: float) -> float:
        return float(np.median(_segment_statistics(ev, cov(ev, s2), d)))

    return _falls_to(median_stat, target, _initial_scale(ev), 50)


def _initial_scale(ev: _Eval) -> float:
    """A first orientation variance: the residuals' mean square per component."""
    return max(float(np.mean(ev.r * ev.r)), 1e-12)


def _match_chi2(ev: _Eval, cov: Callable[[_Eval, float], Array], dof: int, scale2: float) -> float:
    """The orientation variance ``s²`` at which the segments' χ² equals its degrees of freedom
    (0 when the integration noise alone already explains the residuals)."""
    r = ev.r.ravel()

    def chi2(s2: float) -> float:
        Lc = np.linalg.cholesky(cov(ev, s2))
        z = np.linalg.solve(Lc, r)
        return float(z @ z)

    return _falls_to(chi2, dof, scale2, 60)


def _falls_to(f: Callable[[float], float], target: float, start: float, steps: int) -> float:
    """The variance ``s ≥ 0`` at which the decreasing ``f(s)`` falls to ``target`` (0 when
    ``f(0)`` already does): bracketed by quadrupling from ``start`` (given up above 10⁶),
    then ``steps`` bisections."""
    if f(0.0) <= target:
        return 0.0
    lo, hi = 0.0, max(start, 1e-12)
    while f(hi) > target:
        hi *= 4.0
        if hi > 1e6:
            return hi
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if f(mid) > target:
            lo = mid
        else:
            hi = mid
    return hi
