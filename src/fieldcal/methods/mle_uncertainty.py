"""Uncertainty at the optimum: Cramér-Rao bound from the reduced (Schur) system.

With whitened residuals the Fisher information is ``JᵀJ``; eliminating the rotations, the
covariance of the G globals is ``S⁻¹`` with ``S = V − Σ W_iᵀ U_i⁻¹ W_i`` (undamped). Derived
quantities use the delta method: entries of symmetric gains (both off-diagonal copies), the dip
in degrees, and the misalignment angle of :func:`fieldcal.model.misalignment_angle_deg`
(finite differences of its rotation vector, the same polar decomposition and signed
permutation). The hat-matrix diagonal splits the residual degrees of freedom between sensors
for the noise-from-residuals fixed point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..model import ParameterCovariance, _nearest_signed_permutation
from .mle_lm import Normal, reduce
from .mle_model import SYM_MAP, Problem, State

Array = NDArray[np.float64]


@dataclass
class Uncertainty:
    covariance: ParameterCovariance
    gain_std: dict[str, Array]
    bias_std: dict[str, Array]
    dip_std_deg: float | None
    misalignment_std_deg: float | None
    dof_share: dict[str, float]
    condition: float


def global_covariance(ne: Normal) -> tuple[Array, Array, Array, float]:
    """``S⁻¹`` (CRB of the globals), the pose blocks' inverses, ``U⁻¹W``, and S's condition
    number after Jacobi scaling (large: the poses do not determine every parameter)."""
    Uinv, Y, S, _, _ = reduce(ne, 0.0)
    d = np.sqrt(np.maximum(np.diag(S), 1e-300))
    Sn = S / np.outer(d, d)
    ev = np.linalg.eigvalsh(Sn)
    cond = float(ev[-1] / max(ev[0], 1e-300))
    C = np.linalg.inv(Sn) / np.outer(d, d)
    return 0.5 * (C + C.T), Uinv, Y, cond


def named_map(problem: Problem) -> tuple[list[str], Array]:
    """Names and the linear map from the G globals to the named parameters."""
    names: list[str] = []
    blocks = []
    G = problem.n_global
    for s in problem.sensors:
        gs = problem.gain_slice[s]
        T = np.zeros((9, G))
        T[:, gs] = SYM_MAP if problem.symmetric(s) else np.eye(9)
        names += [f"{s}.gain[{j},{k}]" for j in range(3) for k in range(3)]
        blocks.append(T)
        B = np.zeros((3, G))
        B[:, problem.bias_slice[s]] = np.eye(3)
        names += [f"{s}.bias[{j}]" for j in range(3)]
        blocks.append(B)
    if problem.joint:
        D = np.zeros((1, G))
        D[0, problem.dip_index] = np.degrees(1.0)
        names.append("dip_deg")
        blocks.append(D)
    return names, np.vstack(blocks)


def _polar(K: Array) -> Array:
    W, _, Vt = np.linalg.svd(K)
    return W @ Vt


def _rotvec(M: Array) -> Array:
    """Rotation vectors of a batch of rotation matrices (angle below 180°)."""
    angle = np.arccos(np.clip((np.trace(M, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0))
    axis = np.stack(
        [M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]],
        axis=-1,
    )
    s = np.sin(angle)
    scale = np.where(s > 1e-12, 0.5 * angle / np.where(s > 1e-12, s, 1.0), 0.5)
    return axis * scale[..., None]


def misalignment_std(problem: Problem, state: State, C: Array) -> float | None:
    """Delta-method standard error (degrees) of the misalignment angle.

    Far from 0 the angle is smooth: ``σ = sqrt(nᵀ C_θ n)`` along its rotation vector θ (the
    rotation of ``U_m U_aᵀ`` with the signed permutation taken out, as in
    :func:`fieldcal.model.misalignment_angle_deg`). Near 0 (within 3σ) the angle is the norm of
    a nearly centred vector; ``sqrt(tr C_θ)`` is then reported (its root mean square spread).
    """
    if not problem.joint:
        return None
    Ka, Km = state.gains["accel"], state.gains["mag"]
    S = _nearest_signed_permutation(_polar(Km) @ _polar(Ka).T)
    # differences over every gain parameter, all perturbed gains in one batch
    cols, Kas, Kms, steps = [], [Ka], [Km], []
    # a symmetric positive definite gain has U = I for any small symmetric change: only the
    # other sensor's gain moves the angle
    for s in [k for k in ("accel", "mag") if not problem.symmetric(k)]:
        sl = problem.gain_slice[s]
        size = sl.stop - sl.start
        h = 1e-6 * max(1.0, float(np.max(np.abs(state.gains[s]))))
        basis = np.eye(size) * h
        dK = (basis @ SYM_MAP.T if problem.symmetric(s) else basis).reshape(size, 3, 3)
        base = state.gains[s]
        other = Km if s == "accel" else Ka
        pert = base + dK  # forward differences: O(h) error is far below any σ
        fixed = np.broadcast_to(other, pert.shape)
        Kas.append(pert if s == "accel" else fixed)
        Kms.append(fixed if s == "accel" else pert)
        cols.append(np.arange(sl.start, sl.stop))
        steps.append(np.full(size, h))
    Kab = np.concatenate([np.asarray(k).reshape(-1, 3, 3) for k in Kas])
    Kmb = np.concatenate([np.asarray(k).reshape(-1, 3, 3) for k in Kms])
    theta = _rotvec(S.T @ _polar(Kmb) @ _polar(Kab).transpose(0, 2, 1))
    theta0, rest = theta[0], theta[1:]
    Jt = np.zeros((3, problem.n_global))
    pos = 0
    for idx, h in zip(cols, steps, strict=True):
        size = len(idx)
        Jt[:, idx] = ((rest[pos : pos + size] - theta0) / h[:, None]).T
        pos += size
    Ct = Jt @ C @ Jt.T
    norm = np.linalg.norm(theta0)
    spread = np.sqrt(max(np.trace(Ct), 0.0))
    if norm > 3.0 * spread:
        n = theta0 / norm
        return float(np.degrees(np.sqrt(max(n @ Ct @ n, 0.0))))
    return float(np.degrees(spread))


def dof_shares(problem: Problem, ne: Normal, C: Array, Uinv: Array, Y: Array) -> dict[str, float]:
    """Expected share of Eq. 8's J per sensor, ``3N − tr(H_ss)`` (hat-matrix diagonal)."""
    Jp, Jg = ne.Jp, ne.Jg
    # diag of [Jp Jg] (JᵀJ)⁻¹ [Jp Jg]ᵀ = Jp U⁻¹ Jpᵀ + X C Xᵀ with X = Jg − Jp U⁻¹ W
    lev = np.einsum("nmi,nij,nmj->nm", Jp, Uinv, Jp)
    X = Jg - Jp @ Y
    lev += np.einsum("nmi,ij,nmj->nm", X, C, X)
    out = {}
    for k, s in enumerate(problem.sensors):
        out[s] = float(3 * problem.n - np.sum(lev[:, 3 * k : 3 * k + 3]))
    return out


def uncertainty(problem: Problem, state: State, ne: Normal, shares: bool = True) -> Uncertainty:
    C, Uinv, Y, cond = global_covariance(ne)
    names, T = named_map(problem)
    Cn = T @ C @ T.T
    cov = ParameterCovariance(tuple(names), 0.5 * (Cn + Cn.T))
    std = np.sqrt(np.maximum(np.diag(cov.matrix), 0.0))
    gain_std, bias_std = {}, {}
    for s in problem.sensors:
        i = names.index(f"{s}.gain[0,0]")
        gain_std[s] = std[i : i + 9].reshape(3, 3)
        bias_std[s] = std[i + 9 : i + 12]
    dip_std = float(std[-1]) if problem.joint else None
    return Uncertainty(
        cov,
        gain_std,
        bias_std,
        dip_std,
        misalignment_std(problem, state, C),
        dof_shares(problem, ne, C, Uinv, Y) if shares else {},
        cond,
    )


def wishart_std(cov: Array, dof: int) -> Array:
    """Standard error of Eq. 7's entries: ``Var Σ̂_ij = (Σ_ij² + Σ_ii Σ_jj)/ν``."""
    d = np.diag(cov)
    return np.sqrt((cov**2 + np.outer(d, d)) / max(dof, 1))
