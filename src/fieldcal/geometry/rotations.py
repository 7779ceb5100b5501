"""The few SO(3) tools fieldcal needs beyond :class:`scipy.spatial.transform.Rotation`.

Every function is vectorised over a leading batch axis. Rotation matrices act on column vectors:
``v_sensor = R @ v_world`` (see ``docs/conventions.md``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "exp_so3",
    "eye_plus",
    "hat",
    "log_so3",
    "ordered_products",
    "project_to_so3",
    "random_rotations",
    "rotation_angle_deg",
    "wahba",
    "wahba_pair",
]


def random_rotations(n: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """Draw ``n`` rotation matrices uniformly on SO(3) (Kuffner 2004, Algorithm 2).

    Kuffner's "effective sampling" draws a unit quaternion from three uniforms (Shoemake's
    subgroup algorithm): ``s ~ U[0, 1]``, ``σ1 = √(1 − s)``, ``σ2 = √s``, ``θ1, θ2 ~ U[0, 2π)``,
    ``q = (w, x, y, z) = (cos θ2 σ2, sin θ1 σ1, cos θ1 σ1, sin θ2 σ2)``.
    """
    s = rng.uniform(0.0, 1.0, n)
    theta1 = rng.uniform(0.0, 2.0 * np.pi, n)
    theta2 = rng.uniform(0.0, 2.0 * np.pi, n)
    sigma1, sigma2 = np.sqrt(1.0 - s), np.sqrt(s)
    w, x = np.cos(theta2) * sigma2, np.sin(theta1) * sigma1
    y, z = np.cos(theta1) * sigma1, np.sin(theta2) * sigma2
    return quaternion_to_matrix(np.stack([w, x, y, z], axis=-1))


def quaternion_to_matrix(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation matrices (..., 3, 3) from unit quaternions (..., 4), scalar first."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def hat(omega: NDArray[np.float64]) -> NDArray[np.float64]:
    """Skew-symmetric matrices (..., 3, 3) with ``hat(w) @ v == cross(w, v)``."""
    omega = np.asarray(omega, dtype=float)
    out = np.zeros((*omega.shape, 3))  # filled in place: nested stacks cost a third more
    x, y, z = omega[..., 0], omega[..., 1], omega[..., 2]
    out[..., 0, 1], out[..., 0, 2] = -z, y
    out[..., 1, 0], out[..., 1, 2] = z, -x
    out[..., 2, 0], out[..., 2, 1] = -y, x
    return out


def exp_so3(omega: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rodrigues' formula, batched: rotation vectors (..., 3) -> matrices (..., 3, 3).

    Uses the Taylor series of the coefficients below 1e-4 rad so it is exact to machine
    precision near the identity, where the Levenberg-Marquardt updates live.
    """
    omega = np.asarray(omega, dtype=float)
    theta2 = np.sum(omega * omega, axis=-1)
    theta = np.sqrt(theta2)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    return eye_plus(omega, a, b, theta2)


def eye_plus(
    omega: NDArray[np.float64],
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    theta2: NDArray[np.float64],
) -> NDArray[np.float64]:
    """``I + a [ω]× + b [ω]×²`` (..., 3, 3), with ``[ω]×² = ω ωᵀ − |ω|² I`` (``theta2``:
    ``|ω|²``) as an outer product rather than a stacked 3×3 product."""
    out = hat(omega) * a[..., None, None]
    out += b[..., None, None] * (omega[..., :, None] * omega[..., None, :])
    diagonal = 1.0 - b * theta2
    for i in range(3):
        out[..., i, i] += diagonal
    return out


def log_so3(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation vectors (..., 3) of rotation matrices (..., 3, 3); inverse of :func:`exp_so3`."""
    from scipy.spatial.transform import Rotation

    R = np.asarray(R, dtype=float)
    flat = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec()
    return flat.reshape((*R.shape[:-2], 3))


def rotation_angle_deg(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation angle in degrees of rotation matrices (..., 3, 3), in [0, 180]."""
    R = np.asarray(R, dtype=float)
    cos = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def project_to_so3(M: NDArray[np.float64]) -> NDArray[np.float64]:
    """Nearest rotation (Frobenius norm) to each matrix (..., 3, 3), by batched SVD."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=float))
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt


def wahba(
    body: NDArray[np.float64],
    world: NDArray[np.float64],
    weights: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Solve Wahba's problem for a batch: ``R = argmin Σ_k w_k |body_k − R world_k|²``.

    ``body`` and ``world`` have shape (..., K, 3) (K observed directions per problem, K >= 2 and
    not all parallel); ``weights`` (..., K) defaults to ones. Returns (..., 3, 3) rotations that
    map world vectors to body vectors, via the batched SVD of the attitude profile matrix
    ``B = Σ w_k body_k world_kᵀ`` (Markley 1988).
    """
    body = np.asarray(body, dtype=float)
    world = np.asarray(world, dtype=float)
    if weights is None:  # unit weights: the same sums without multiplying by them
        B = np.einsum("...ki,...kj->...ij", body, world)
    else:
        B = np.einsum("...k,...ki,...kj->...ij", weights, body, world)
    return project_to_so3(B)


def wahba_pair(
    b1: NDArray[np.float64],
    b2: NDArray[np.float64],
    r1: NDArray[np.float64],
    r2: NDArray[np.float64],
) -> NDArray[np.float64]:
    """:func:`wahba` for two unit directions of equal weight, in closed form: the rotations
    (..., 3, 3) with ``b_k ≈ R r_k`` (arrays (..., 3), broadcast together).

    With two observations the optimal rotation maps the plane of the reference pair onto the
    plane of the body pair, normal ``r1 × r2`` onto normal ``b1 × b2`` (Markley 1993,
    "Attitude determination using two vector measurements"), and within that plane turns by
    the mean of the two vectors' angles (equal weights): it maps the bisector ``r1 + r2``
    onto ``b1 + b2``. So ``R = E Fᵀ`` with the orthonormal frames (bisector, normal ×
    bisector, normal) of the two pairs: the SVD's rotation to rounding, in a few elementwise
    steps instead of one 3x3 SVD per pose. Pairs nearly parallel or opposed (no plane, or a
    frame known to few digits) go to :func:`wahba`.
    """
    body = _pair_frame(b1, b2)
    world = _pair_frame(r1, r2)
    if body is None or world is None:
        b = np.stack(np.broadcast_arrays(b1, b2), axis=-2)
        r = np.stack(np.broadcast_arrays(r1, r2), axis=-2)
        return wahba(*np.broadcast_arrays(b, r))
    return body @ np.swapaxes(world, -1, -2)


#: Index maps of the cross product's terms: ``(a × b)_i = a_{i+1} b_{i+2} − a_{i+2} b_{i+1}``.
_NEXT, _LAST = [1, 2, 0], [2, 0, 1]


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a × b`` over the last axis (np.cross's numbers without its wrapper's cost)."""
    out: NDArray[np.float64] = a[..., _NEXT] * b[..., _LAST] - a[..., _LAST] * b[..., _NEXT]
    return out


def _pair_frame(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """The frames (..., 3, 3) whose columns are the bisector of the unit vectors ``a`` and
    ``b``, normal × bisector and the normal; ``None`` when a pair is within 1e-4 rad of
    parallel or opposed."""
    s = a + b
    n = _cross(a, b)
    s_len = np.sqrt(np.sum(s * s, axis=-1, keepdims=True))
    n_len = np.sqrt(np.sum(n * n, axis=-1, keepdims=True))
    if not (np.all(s_len > 1e-4) and np.all(n_len > 1e-4)):
        return None
    s = s / s_len
    n = n / n_len
    return np.stack([s, _cross(n, s), n], axis=-1)


def ordered_products(steps: NDArray[np.float64]) -> NDArray[np.float64]:
    """Chained rotations: ``c_i = S_i S_{i−1} … S_0`` for every ``i`` of ``steps`` (n, 3, 3),
    later steps on the left (a world → body rotation advanced step by step), by a log-depth
    (Hillis–Steele) scan of matrix products: ``log₂ n`` vectorised rounds instead of ``n``
    Python-level products. A long chain is scanned in blocks of :data:`SCAN_BLOCK` (every
    block's scan at once, then each block carried by the product of the blocks before it, a
    scan of the blocks' last products): a third of the work of one scan over the chain."""
    c = np.array(steps, dtype=float)
    n = len(c)
    if n <= 4 * SCAN_BLOCK:
        return _scan(c)
    whole = n - n % SCAN_BLOCK
    blocks = _scan(c[:whole].reshape(-1, SCAN_BLOCK, 3, 3), axis=1)
    carry = ordered_products(blocks[:-1, -1])  # the blocks before each block, chained
    blocks[1:] = blocks[1:] @ carry[:, None]
    if whole < n:
        c[whole:] = _scan(c[whole:]) @ c[whole - 1]
    return c


#: Rotations per block of :func:`ordered_products`' scan.
SCAN_BLOCK = 32


def _scan(c: NDArray[np.float64], axis: int = 0) -> NDArray[np.float64]:
    """In place along ``axis`` (0 or 1): ``c_i ← c_i c_{i−1} … c_0`` (Hillis–Steele)."""
    view = c if axis == 0 else np.moveaxis(c, 1, 0)
    d = 1
    while d < len(view):
        view[d:] = view[d:] @ view[:-d]
        d *= 2
    return c
