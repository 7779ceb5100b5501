"""Generalised least squares blocks of the greedy method (seed paper, Sec. 4.2 and 4.4).

Every block has the same shape: per pose ``i`` a 3x``p`` design ``X_i``, an observation
``y_i`` (3,) with covariance ``Σ̂ / Δ[i]``, so ``Ω`` of Eq. 10 is block diagonal (Eq. 13) and
Eq. 11 reduces to sums over poses of small matrices, vectorised with ``einsum``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "accel_bias_field_design",
    "accel_gain_design",
    "gls",
    "mag_bias_field_design",
    "mag_gain_design",
    "symmetric_from_vector",
]

Array = NDArray[np.float64]


def gls(X: Array, y: Array, weight: Array, counts: Array) -> Array:
    """Eq. 11, ``β = (Xᵀ Ω⁻¹ X)⁻¹ Xᵀ Ω⁻¹ y``, with ``Ω = blockdiag(Σ̂ / Δ[i])`` (Eq. 13).

    Parameters
    ----------
    X : (N, 3, p) per-pose design blocks.
    y : (N, 3) per-pose observations.
    weight : (3, 3) ``Σ̂⁻¹``.
    counts : (N,) ``Δ[i]``.
    """
    # Ω⁻¹ is block diagonal with blocks Δ[i] Σ̂⁻¹, so both products are sums of per-pose terms.
    normal = np.einsum("n,nap,ab,nbq->pq", counts, X, weight, X)
    rhs = np.einsum("n,nap,ab,nb->p", counts, X, weight, y)
    return np.linalg.solve(normal, rhs)


def accel_bias_field_design(gain: Array, rotations: Array) -> Array:
    """Eq. 13: ``X_i = [K_a R_i z, I₃]`` for ``β = (g_z, b_a)``."""
    n = rotations.shape[0]
    X = np.empty((n, 3, 4))
    X[:, :, 0] = rotations[:, :, 2] @ gain.T  # K_a R_i z: R_i z is R_i's third column
    X[:, :, 1:] = np.eye(3)
    return X


def mag_bias_field_design(gain: Array, rotations: Array) -> Array:
    """Eq. 15: ``X_i = [K_m R_i x, K_m R_i z, I₃]`` for ``β = (h_x, h_z, b_m)``."""
    n = rotations.shape[0]
    X = np.empty((n, 3, 5))
    X[:, :, 0] = rotations[:, :, 0] @ gain.T
    X[:, :, 1] = rotations[:, :, 2] @ gain.T
    X[:, :, 2:] = np.eye(3)
    return X


# Eq. 16's column order for the symmetric K_a: (K11, K12, K13, K22, K23, K33).
_SYM_INDEX = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])


def accel_gain_design(body_gravity: Array) -> Array:
    """Eq. 16: the design for the six entries of a symmetric ``K_a`` given ``g_i^S = R_i g``.

    Row ``r`` of ``K_a g_i^S`` is ``Σ_c K_rc g_i,c``; with ``K`` symmetric each ``K_rc`` is one
    of six unknowns, so ``X_i[r, _SYM_INDEX[r, c]] = g_i,c``.
    """
    n = body_gravity.shape[0]
    X = np.zeros((n, 3, 6))
    for r in range(3):  # three rows of a 3x3 matrix, not a loop over poses
        for c in range(3):
            X[:, r, _SYM_INDEX[r, c]] = body_gravity[:, c]
    return X


def mag_gain_design(body_field: Array) -> Array:
    """Eq. 17 (as intended): ``X_i = I₃ ⊗ (h_i^S)ᵀ`` for the nine entries of ``K_m``, row-major.

    The printed β of Eq. 17 lists ``K_m,31`` twice and omits a row of ``X``; the product
    ``K_m h_i^S`` has nine distinct unknowns, which is what is solved here.
    """
    n = body_field.shape[0]
    X = np.zeros((n, 3, 9))
    for r in range(3):
        X[:, r, 3 * r : 3 * r + 3] = body_field
    return X


def symmetric_from_vector(beta: Array) -> Array:
    """Eq. 16's ``β_a = (K11, K12, K13, K22, K23, K33)`` back to the symmetric matrix."""
    return np.asarray(beta)[_SYM_INDEX]
