"""The constant-angle alignment: one rotation that keeps the angle between two fields fixed.

Two sensors at rest read directions ``u_i`` (gravity) and ``v_i`` (the magnetic field) in their
own axes; their world angle is the same in every pose, so a single orthogonal ``Q`` and a
constant ``c`` satisfy ``u_iᵀ Q v_i = c`` (the CK-Explorer seed's Eq. 16, ``c = β = cos θ``;
the joint method's second closed-form step). The equation is linear in ``vec(Q)`` and ``c``:
each pose gives the row ``[vec(u_i v_iᵀ), −1]``, and the solution is the design's null vector,
projected onto the orthogonal matrices.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .frames import orthogonal_polar_factor
from .rotations import project_to_so3

__all__ = ["PENCIL_BELOW", "constant_angle", "constant_angle_rows", "constant_angles"]

Array = NDArray[np.float64]

#: Below this many poses the null space is (nearly) two-dimensional: search its pencil.
PENCIL_BELOW = 12


def constant_angle_rows(u: Array, v: Array) -> Array:
    """Rows ``[vec(u_i v_iᵀ), −1]`` (n, 10): ``u_iᵀ Q v_i − c = row · (vec Q, c)``."""
    return np.concatenate([np.einsum("ni,nj->nij", u, v).reshape(-1, 9), -np.ones((len(u), 1))], 1)


def constant_angle(
    u: Array, v: Array, weights: Array | None = None, *, proper: bool = False
) -> tuple[Array, float]:
    """``Q`` and ``c`` with ``u_iᵀ Q v_i ≈ c`` for all poses, in closed form.

    Parameters
    ----------
    u, v : (n, 3) arrays
        Unit directions of the two fields in each pose.
    weights : (n,) array, optional
        Weight of each pose's equation.
    proper : bool
        ``True``: ``Q`` a rotation (the null vector's sign chosen so, then projected onto
        SO(3)). ``False``: the orthogonal polar factor, which keeps a reflection when the data
        ask for one (a mirrored sensor). With fewer than :data:`PENCIL_BELOW` poses the pencil
        of the two smallest singular vectors is searched for the member whose ``c`` fits best.

    Returns
    -------
    Q : (3, 3) array
    c : float
        In [−1, 1].
    """
    w = np.ones(len(u)) if weights is None else np.asarray(weights, dtype=float)
    if not proper:
        Q, c = constant_angles(u[None], v[None], w)
        return Q[0], float(c[0])
    rows = constant_angle_rows(u, v) * np.sqrt(w)[:, None]
    # the right singular vectors of the thin R factor are those of the tall matrix
    Vt = np.linalg.svd(np.linalg.qr(rows, mode="r") if len(rows) >= 10 else rows)[2]
    x = Vt[-1] * (np.sign(np.linalg.det(Vt[-1, :9].reshape(3, 3))) or 1.0)
    scale = 3.0 / np.sum(np.linalg.svd(x[:9].reshape(3, 3), compute_uv=False))
    return project_to_so3(scale * x[:9].reshape(3, 3)), float(np.clip(scale * x[9], -1, 1))


def constant_angles(u: Array, v: Array, weights: Array) -> tuple[Array, Array]:
    """:func:`constant_angle` (``proper=False``) for B problems on the same poses at once.

    Parameters
    ----------
    u, v : (B, n, 3) arrays
        Unit directions of the two fields in each pose, per problem.
    weights : (n,) array
        Weight of each pose's equation (the same for every problem).

    Returns
    -------
    Q : (B, 3, 3) array
    c : (B,) array
        In [−1, 1].

    One call of each LAPACK routine for all the problems (the closed-form starts of several
    ellipsoid families are solved together).
    """
    B, n = u.shape[:2]
    # rows [vec(u_i v_iᵀ), −1] of every problem (the outer products as constant_angle_rows)
    rows = np.empty((B, n, 10))
    rows[:, :, :9] = (u[:, :, :, None] * v[:, :, None, :]).reshape(B, n, 9)
    rows[:, :, 9] = -1.0
    rows *= np.sqrt(weights)[:, None]
    # the right singular vectors of the thin R factor are those of the tall matrix
    Vt = np.linalg.svd(np.linalg.qr(rows, mode="r") if n >= 10 else rows)[2]
    Z = Vt[:, -2:]
    phi = np.linspace(0.0, np.pi, 37)[:-1] if n < PENCIL_BELOW else np.array([np.pi / 2])
    cand = np.cos(phi)[:, None] * Z[:, None, 0] + np.sin(phi)[:, None] * Z[:, None, 1]
    Q = orthogonal_polar_factor(cand[..., :9].reshape(B, len(phi), 3, 3))  # (B, P, 3, 3)
    # u_iᵀ Q v_i for every candidate: (B, P, n)
    proj = np.sum(u[:, None] * (v[:, None] @ np.swapaxes(Q, -1, -2)), axis=-1)
    c = proj @ weights / np.sum(weights)
    if len(phi) == 1:
        best = np.zeros(B, dtype=np.intp)
    else:
        best = np.argmin(((proj - c[..., None]) ** 2) @ weights, axis=1)
    pick = np.arange(B)
    return Q[pick, best], np.clip(c[pick, best], -1.0, 1.0)
