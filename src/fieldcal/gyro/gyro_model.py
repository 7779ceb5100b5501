"""The gyroscope's measurement model: each motion segment's integrated turn against the poses'
rotations (or gravity directions), the residuals, their Jacobians and their response to the
poses' orientation errors (``docs/methods/gyro.md``, *The likelihood*)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..geometry.rotations import hat, quaternion_to_matrix
from .gyro_data import Segments, interval_bias
from .integrate import (
    cumulative_quaternions,
    quaternion_multiply,
    rotation_vector,
    step_quaternions,
)

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


def conjugate(q: Array) -> Array:
    out = q.copy()
    out[..., 1:] *= -1.0
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
    ) -> None:
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

    @property
    def n_params(self) -> int:
        return 9 + 3 * self.n

    def rates(self, x: Array) -> tuple[Array, Array]:
        """Corrected raw ``raw − b(t)`` (J, 3) and the rate (J, 3)."""
        M = x[:9].reshape(3, 3)
        bias = interval_bias(self.data, x[9:].reshape(self.n, 3))
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
        rel = quaternion_multiply(prev, conjugate(base[D.seg]))
        total = quaternion_multiply(c[D.last], conjugate(base))
        return quaternion_to_matrix(total), quaternion_to_matrix(rel), phi

    def path_length(self, x: Array) -> Array:
        """The angle (rad) each segment turns through, ``∫ |ω| dt``."""
        _, w = self.rates(x)
        out: Array = np.add.reduceat(np.linalg.norm(w, axis=1) * self.data.dt, self.data.first)
        return out

    def evaluate(self, x: Array, *, with_jacobian: bool = True, linear: bool = False) -> Evaluation:
        """Residuals and Jacobians at ``x``; ``linear``: the rotation residual's Jacobian as at
        a zero residual (for the observability check far from the optimum)."""
        D = self.data
        M = x[:9].reshape(3, 3)
        u_corr, w = self.rates(x)
        total, P, phi = self.integrate(w)
        m = len(D.first)
        if self.method == "rotations":
            r = rotation_vector(np.transpose(self.observed, (0, 2, 1)) @ total)
            H = -right_jacobian_inv(0.0 * r if linear else r)  # dr = H v
        else:
            u = self.observed
            pred = np.einsum("mij,mj->mi", total, u[D.before])
            r = np.einsum("mia,mi->ma", self.basis_next, pred)
            # ΔR̂ exp(−[v]) u ≈ ΔR̂ u + ΔR̂ [u]× v
            H = np.einsum("mia,mij,mjk->mak", self.basis_next, total, hat(u[D.before]))
        # v = Σ_j dt_j P_{j−1}ᵀ J_r(φ_j) δω_j: the change of the segment's rotation (right)
        Pt = np.transpose(P, (0, 2, 1))
        Dj = D.dt[:, None, None] * (Pt @ right_jacobian(phi))
        noise = D.dt[:, None, None] * (Pt @ (M @ self.Q @ M.T) @ P)
        cov_int = np.add.reduceat(noise, D.first, axis=0)
        J_gain = np.zeros((m, self.d, 9))
        J_before = np.zeros((m, self.d, 3))
        J_after = np.zeros((m, self.d, 3))
        if with_jacobian:
            dv_dM = np.einsum("jca,jb->jcab", Dj, u_corr).reshape(-1, 3, 9)
            dM = np.add.reduceat(dv_dM, D.first, axis=0)
            DM = Dj @ M
            lam = D.lam[:, None, None]
            # the biases of the poses before (b0) and after (b1) each segment
            J_gain = H @ dM
            J_before = H @ -np.add.reduceat(DM * (1.0 - lam), D.first, axis=0)
            J_after = H @ -np.add.reduceat(DM * lam, D.first, axis=0)
        return Evaluation(r, J_gain, J_before, J_after, total, cov_int, H)

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
