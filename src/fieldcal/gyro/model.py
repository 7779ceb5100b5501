"""The gyroscope's measurement model: each motion segment's integrated turn against the poses'
rotations (or gravity directions), the residuals, their Jacobians and their response to the
poses' orientation errors (``docs/methods/gyro.md``, *The likelihood*)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..geometry.rotations import hat
from .data import Segments
from .integrate import rotation_vector
from .passes import JACOBIAN, NOISE, TURNS, Integrator, Pass

Array = NDArray[np.float64]
Method = Literal["rotations", "gravity"]


def right_jacobian(phi: Array) -> Array:
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


def right_jacobian_inv(phi: Array) -> Array:
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


def tangent_basis(u: Array) -> Array:
    """(..., 3, 2) orthonormal bases of the planes orthogonal to unit vectors ``u``."""
    helper = np.eye(3)[np.argmin(np.abs(u), axis=-1)]
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(u, e1)
    return np.stack([e1, e2], axis=-1)


@dataclass
class Evaluation:
    """The model at one point: residuals and their Jacobians (unwhitened). Segment ``k`` depends
    on the gain and on the biases of its two poses only: the Jacobian is kept in those parts."""

    r: Array  # (M, d) segment residuals
    J_gain: Array  # (M, d, 9) with respect to vec M
    J_before: Array  # (M, d, 3) with respect to the bias of the pose before the segment
    J_after: Array  # (M, d, 3) with respect to the bias of the pose after it
    total: Array  # (M, 3, 3) integrated rotations
    cov_int: Array  # (M, 3, 3) integration noise of v per segment
    H: Array  # (M, d, 3) map from v to the residual (for the noise)


class SegmentModel:
    """Residuals of every segment and their Jacobians with respect to ``x = (vec M, b_0..)``."""

    def __init__(
        self,
        data: Segments,
        method: Method,
        n_poses: int,
        observed: Array,
        noise_density: Array,
        *,
        share: tuple[SegmentModel, NDArray[np.int64]] | None = None,
    ) -> None:
        """``share = (model, positions)``: these segments are those at ``positions`` of
        ``model``'s, whose passes (and kept passes) serve this model too."""
        self.data = data
        self.method = method
        self.n = n_poses
        self.Q = noise_density
        self.d = 3 if method == "rotations" else 2
        self.observed_poses = observed  # (N, 3, 3) rotations or (N, 3) gravity directions
        before = data.before
        if method == "rotations":
            # (M, 3, 3) the turns ΔR_i = R_{i+1} R_iᵀ of the segments, from the poses' R_i
            self.observed = observed[before + 1] @ np.transpose(observed[before], (0, 2, 1))
        else:
            self.observed = observed  # (N, 3) unit gravity directions
            self.basis_next = tangent_basis(observed[before + 1])  # (M, 3, 2)
        if share is None:
            self._integrator = Integrator(data, noise_density)
            self._positions: NDArray[np.int64] | None = None
        else:
            self._integrator, self._positions = share[0]._integrator, share[1]
        self._last: tuple[bytes, bool, bool, Evaluation] | None = None

    @property
    def n_params(self) -> int:
        return 9 + 3 * self.n

    def path_length(self, x: Array) -> Array:
        """The angle (rad) each segment turns through, ``∫ |ω| dt``."""
        out = self._integrator.path_length(x)
        return out if self._positions is None else out[self._positions]

    def residuals(self, x: Array) -> Array:
        """The residuals (M, d) at ``x`` alone (the cost of a trial step): the segments' turns
        only, no Jacobian, no noise."""
        cached = self._cached(x, linear=None)
        if cached is not None:
            return cached.r
        return self._residual(self._pass(x, TURNS).total)

    def evaluate(self, x: Array, *, with_jacobian: bool = True, linear: bool = False) -> Evaluation:
        """Residuals and Jacobians at ``x``; ``linear``: the rotation residual's Jacobian as at
        a zero residual (for the observability check far from the optimum). One pass over the
        intervals (:class:`.passes.Integrator`, which keeps the last few); the last
        evaluation is kept (the solver asks for the same point more than once)."""
        cached = self._cached(x, linear, with_jacobian)
        if cached is not None:
            return cached
        D = self.data
        M = x[:9].reshape(3, 3)
        m = len(D.first)
        done = self._pass(x, JACOBIAN if with_jacobian else NOISE)
        total, sums = done.total, done.sums
        # cov_int = Σ_j dt_j P_{j−1}ᵀ (M Q Mᵀ) P_{j−1}: the integration noise of v per segment
        cov_int = np.transpose(sums[:9].reshape(3, 3, m), (2, 0, 1))
        r = self._residual(total)
        if self.method == "rotations":
            H = -right_jacobian_inv(0.0 * r if linear else r)  # dr = H v
        else:
            u = self.observed
            # ΔR̂ exp(−[v]) u ≈ ΔR̂ u + ΔR̂ [u]× v
            H = np.einsum("mia,mij,mjk->mak", self.basis_next, total, hat(u[D.before]))
        J_gain = np.zeros((m, self.d, 9))
        J_before = np.zeros((m, self.d, 3))
        J_after = np.zeros((m, self.d, 3))
        if with_jacobian:
            # v = Σ_j dt_j P_{j−1}ᵀ J_r(φ_j) δω_j, δω_j = δM u_j − M δb(t_j): the change of the
            # segment's rotation (right); Σ D_j u_jᵀ, Σ D_j (1 − λ_j) and Σ D_j λ_j per segment
            dM = np.transpose(sums[9:36].reshape(3, 9, m), (2, 0, 1))
            S0 = np.transpose(sums[36:45].reshape(3, 3, m), (2, 0, 1))
            S1 = np.transpose(sums[45:54].reshape(3, 3, m), (2, 0, 1))
            # the biases of the poses before (b0) and after (b1) each segment
            J_gain = H @ dM
            J_before = H @ -(S0 @ M)
            J_after = H @ -(S1 @ M)
        ev = Evaluation(r, J_gain, J_before, J_after, total, cov_int, H)
        self._last = (x.tobytes(), linear, with_jacobian, ev)
        return ev

    def _pass(self, x: Array, level: int) -> Pass:
        """The pass over this model's segments at ``x``."""
        done = self._integrator.run(x, level)
        return done if self._positions is None else done.pick(self._positions)

    def _cached(
        self, x: Array, linear: bool | None, with_jacobian: bool = False
    ) -> Evaluation | None:
        """The last evaluation if it was at ``x`` with what is asked (``linear=None``: the
        residuals only, which every evaluation has)."""
        if self._last is None:
            return None
        key, was_linear, had_jacobian, ev = self._last
        if key != x.tobytes() or (linear is not None and linear != was_linear):
            return None
        return ev if had_jacobian or not with_jacobian else None

    def _residual(self, total: Array) -> Array:
        """The residuals (M, d) of the segments' integrated turns."""
        if self.method == "rotations":
            out: Array = rotation_vector(np.transpose(self.observed, (0, 2, 1)) @ total)
            return out
        pred = np.einsum("mij,mj->mi", total, self.observed[self.data.before])
        out = np.einsum("mia,mi->ma", self.basis_next, pred)
        return out

    def dense_jacobian(self, ev: Evaluation) -> Array:
        """The Jacobian (M, d, 9 + 3N) with every column (for checks against the dense
        computation; the fit never forms it)."""
        m = len(ev.r)
        J = np.zeros((m, self.d, self.n_params))
        J[:, :, :9] = ev.J_gain
        seg = np.arange(m)[:, None, None]
        cols = 9 + 3 * self.data.before[:, None, None] + np.arange(3)
        J[seg, np.arange(self.d)[:, None], cols] = ev.J_before
        J[seg, np.arange(self.d)[:, None], cols + 3] = ev.J_after
        return J

    def pose_blocks(self, ev: Evaluation) -> tuple[Array, Array]:
        """Each segment's first-order response (M, d, 3) to the orientation errors of the pose
        before it and of the pose after it (``r_k ≈ B_before δ_i + B_after δ_{i+1}``)."""
        if self.method == "rotations":
            before = np.broadcast_to(np.eye(3), self.observed.shape).copy()
            return before, -np.transpose(self.observed, (0, 2, 1))
        Et = np.transpose(self.basis_next, (0, 2, 1))
        return Et @ ev.total, -Et

    def pose_map(self, ev: Evaluation) -> Array:
        """``B`` (M·d, 3N): the residuals' first-order response to the poses' errors (dense, for
        checks; the fit uses :meth:`pose_blocks`)."""
        m = len(ev.r)
        before, after = self.pose_blocks(ev)
        B = np.zeros((m, self.d, self.n, 3))
        B[np.arange(m), :, self.data.before] = before
        B[np.arange(m), :, self.data.before + 1] = after
        return B.reshape(m * self.d, 3 * self.n)
