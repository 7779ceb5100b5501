"""Uncertainty at the optimum: Cramér-Rao bound from the reduced (Schur) system.

With whitened residuals the Fisher information is ``JᵀJ``; eliminating the rotations, the
covariance of the G globals is ``S⁻¹`` with ``S = V − Σ W_iᵀ U_i⁻¹ W_i`` (undamped). The named
parameters are linear in the globals (entries of symmetric gains, both off-diagonal copies; the
dip in degrees). The hat matrix's diagonal blocks give each pose's leverage: they split the
residual degrees of freedom between sensors (pose-level noise) and standardise each pose's
residual (outlier tests).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

from ...calibration import ParameterCovariance
from .lm import Normal, reduce
from .model import SYM_MAP, Problem

Array = NDArray[np.float64]


@dataclass
class Uncertainty:
    """Cramér-Rao covariance of the named parameters, the reduced system's condition number and
    the hat matrix's diagonal blocks (N, m, m): how much of each pose's whitened residual the
    fit itself absorbs (leverage)."""

    covariance: ParameterCovariance
    condition: float
    leverage: Array

    def dof_share(self, problem: Problem) -> dict[str, float]:
        """Expected share of Eq. 8's J per sensor, ``3N − tr(H_ss)``."""
        diag = np.einsum("nii->ni", self.leverage)
        return {
            s: float(3 * problem.n - np.sum(diag[:, 3 * k : 3 * k + 3]))
            for k, s in enumerate(problem.sensors)
        }


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
    cached = problem.memo.get("named_map")
    if cached is None:
        cached = problem.memo["named_map"] = _named_map(problem)
    names, T = cast(tuple[list[str], Array], cached)
    return list(names), T


def _named_map(problem: Problem) -> tuple[list[str], Array]:
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


def leverage_blocks(ne: Normal, C: Array, Uinv: Array, Y: Array) -> Array:
    """Diagonal blocks of the hat matrix ``J (JᵀJ)⁻¹ Jᵀ`` per pose, (N, m, m).

    With the arrow structure, ``H_ii = Jp_i U_i⁻¹ Jp_iᵀ + X_i C X_iᵀ`` and
    ``X_i = Jg_i − Jp_i U_i⁻¹ W_i`` (block inverse through the Schur complement)."""
    Jp, Jg = ne.Jp, ne.Jg
    # matrix products, not three-operand einsums (those loop over every index combination)
    H = (Jp @ Uinv) @ Jp.transpose(0, 2, 1)
    X = Jg - Jp @ Y
    return H + (X @ C) @ X.transpose(0, 2, 1)


def uncertainty(problem: Problem, ne: Normal) -> Uncertainty:
    """Covariance of the named parameters (CRB), condition number and leverage at a point."""
    C, Uinv, Y, cond = global_covariance(ne)
    names, T = named_map(problem)
    Cn = T @ C @ T.T
    return Uncertainty(
        ParameterCovariance(tuple(names), 0.5 * (Cn + Cn.T)),
        cond,
        leverage_blocks(ne, C, Uinv, Y),
    )


def wishart_std(cov: Array, dof: int) -> Array:
    """Standard error of Eq. 7's entries: ``Var Σ̂_ij = (Σ_ij² + Σ_ii Σ_jj)/ν``."""
    d = np.diag(cov)
    return np.sqrt((cov**2 + np.outer(d, d)) / max(dof, 1))
