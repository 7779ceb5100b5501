"""Closed-form starting points for the joint solve (no iteration, no luck).

1. Per-sensor ellipsoid fit of the pose means (Eq. 5) in noise-whitened coordinates
   ``y = L⁻¹ μ̂`` (where Eq. 6's noise is isotropic), weighted by ``Δ_i``: the quadric
   ``(y − c)ᵀ M (y − c) = 1`` gives the bias and ``K Kᵀ = M⁻¹``; the symmetric square root is
   directly the symmetric gain of Sec. 4.3. ``model`` chooses the ellipsoid family: ``"full"``
   (9 parameters, regularised towards a sphere so that 8 poses still give one answer),
   ``"axes"`` (axis-aligned, 6) or ``"sphere"`` (4).
2. Both sensors' unit directions ``u_i`` (gravity) and ``v'_i`` (field, up to an unknown
   orthogonal Q) keep a constant angle: ``u_iᵀ Q v'_i = −sin(dip)``. This is linear in
   (Q, sin dip): solved by SVD, the best member of the two smallest singular vectors' pencil
   is taken and projected onto O(3) (Q may be a reflection: mirrored magnetometer).
3. Each pose's rotation from its two vectors (Wahba's problem, batched SVD).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ...geometry.rotations import exp_so3, wahba
from ...geometry.frames import GRAVITY, magnetic_reference, twin_flip
from .model import Problem, State, field

Array = NDArray[np.float64]


def _sqrtm_spd(M: Array) -> tuple[Array, Array]:
    """Symmetric square root of an SPD matrix and of its inverse."""
    w, V = np.linalg.eigh(M)
    w = np.maximum(w, 1e-300)
    return (V * np.sqrt(w)) @ V.T, (V / np.sqrt(w)) @ V.T


def ellipsoid(y: Array, weights: Array, model: str = "full") -> tuple[Array, Array] | None:
    """Weighted algebraic fit; returns (symmetric gain K_y, centre) or None if not an ellipsoid."""
    wsum = weights.sum()
    c0 = weights @ y / wsum
    d = y - c0
    s0 = np.sqrt(weights @ np.einsum("ni,ni->n", d, d) / wsum)
    if not s0 > 0:
        return None
    z = d / s0
    x1, x2, x3 = z.T
    if model == "full":
        quad = [x1 * x1, x2 * x2, x3 * x3, 2 * x1 * x2, 2 * x1 * x3, 2 * x2 * x3]
    elif model == "axes":
        quad = [x1 * x1, x2 * x2, x3 * x3]
    else:
        quad = [x1 * x1 + x2 * x2 + x3 * x3]
    D = np.column_stack([*quad, 2 * z, np.ones(len(z))])
    D *= np.sqrt(weights / wsum)[:, None]
    if model == "full":
        # Tie-breaker when the poses do not determine all 9 parameters (N = 8): the member of
        # the quadric pencil closest to a sphere. Weak enough to leave well-posed fits alone.
        D = np.vstack([D, _SPHERE_PULL])
    theta = np.linalg.svd(D, full_matrices=False)[2][-1]
    if model == "full":
        A = theta[_SYM_INDEX]
    elif model == "axes":
        A = np.diag(theta[:3])
    else:
        A = np.eye(3) * theta[0]
    beta, gamma = theta[-4:-1], theta[-1]
    try:
        zc = -np.linalg.solve(A, beta)
    except np.linalg.LinAlgError:
        return None
    M = A / (zc @ A @ zc - gamma)
    if not np.all(np.isfinite(M)):
        return None
    w, V = np.linalg.eigh(M)
    if w[0] <= 0:
        return None
    return s0 * (V / np.sqrt(w)) @ V.T, c0 + s0 * zc


_SYM_INDEX = np.array([[0, 3, 4], [3, 1, 5], [4, 5, 2]])
_SPHERE_PULL = np.zeros((5, 10))
_SPHERE_PULL[0, [0, 1]] = (1e-4, -1e-4)
_SPHERE_PULL[1, [1, 2]] = (1e-4, -1e-4)
_SPHERE_PULL[2, 3] = _SPHERE_PULL[3, 4] = _SPHERE_PULL[4, 5] = 1e-4


def sensor_start(problem: Problem, sensor: str, model: str) -> tuple[Array, Array] | None:
    """Symmetric gain and bias of one sensor, in raw units, from its ellipsoid."""
    w = problem.start_weight[sensor]
    fit = ellipsoid(problem.start_mu[sensor], w, model)
    if fit is None:
        return None
    Ky, cy = fit
    L = problem.start_chol[sensor]
    K = L @ Ky
    # symmetric factor of the polar decomposition K = P U (Sec. 4.3): the body frame of start
    P, _ = _sqrtm_spd(K @ K.T)
    return P, L @ cy


def _directions(problem: Problem, sensor: str, K: Array, b: Array) -> Array:
    means = problem.means[sensor]
    u = np.linalg.solve(K, (means - b).T).T
    return u / np.linalg.norm(u, axis=1, keepdims=True)


#: Poses below which the constant-angle system's two-dimensional pencil is searched.
PENCIL_BELOW = 12


def align(u: Array, v: Array, weights: Array) -> tuple[Array, float]:
    """Orthogonal Q and c with ``u_iᵀ Q v_i ≈ c`` for all poses (constant gravity-field angle)."""
    rows = np.concatenate([np.einsum("ni,nj->nij", u, v).reshape(-1, 9), -np.ones((len(u), 1))], 1)
    rows *= np.sqrt(weights)[:, None]
    Vt = np.linalg.svd(rows, full_matrices=len(rows) < 10)[2]
    Z = Vt[-2:]  # smallest two: the pencil holding the answer even when N is small
    # with many poses the smallest singular vector is the answer; search the pencil otherwise
    phi = np.linspace(0.0, np.pi, 37)[:-1] if len(u) < PENCIL_BELOW else np.array([np.pi / 2])
    cand = np.cos(phi)[:, None] * Z[0] + np.sin(phi)[:, None] * Z[1]
    Ms = cand[:, :9].reshape(-1, 3, 3)
    Uq, _, Vq = np.linalg.svd(Ms)
    Q = Uq @ Vq  # orthogonal polar factor, keeps the sign of det (reflections allowed)
    proj = np.einsum("ni,kij,nj->kn", u, Q, v)
    c = proj @ weights / np.sum(weights)
    resid = ((proj - c[:, None]) ** 2) @ weights
    best = int(np.argmin(resid))
    return Q[best], float(np.clip(c[best], -1.0, 1.0))


def min_rotations(f: Array, u: Array) -> Array:
    """Smallest rotations taking the world vector ``f`` to each body direction ``u_i``."""
    axis = np.cross(f, u)
    s = np.linalg.norm(axis, axis=1)
    c = u @ f
    angle = np.arctan2(s, c)
    helper = np.eye(3)[int(np.argmin(np.abs(f)))]
    perp = np.cross(f, helper)
    perp /= np.linalg.norm(perp)
    axis = np.where(s[:, None] > 1e-12, axis / np.maximum(s, 1e-300)[:, None], perp)
    return exp_so3(axis * angle[:, None])


def closed_form_start(problem: Problem, model: str | tuple[str, str] = "full") -> State | None:
    """A full starting state, or None when an ellipsoid fit fails for this model."""
    models = (model, model) if isinstance(model, str) else model
    fits = {}
    for s, m in zip(problem.sensors, models, strict=False):
        fit = sensor_start(problem, s, m)
        if fit is None:
            return None
        fits[s] = fit
    return start_from_fits(problem, fits)


def start_from_fits(problem: Problem, fits: dict[str, tuple[Array, Array]]) -> State:
    """Steps 2-3: orientation and dip from the constant angle, rotations by Wahba."""
    if not problem.joint:
        s = problem.sensors[0]
        K, b = fits[s]
        u = _directions(problem, s, K, b)
        R = min_rotations(field(problem, s, 0.0), u)
        return State({s: K}, {s: b}, 0.0, R)
    (Ka, ba), (Km, bm) = fits["accel"], fits["mag"]
    u = _directions(problem, "accel", Ka, ba)
    vp = _directions(problem, "mag", Km, bm)
    w = np.minimum(problem.start_weight["accel"], problem.start_weight["mag"])
    Q, c = align(u, vp, w)
    dip = float(np.arcsin(-c))  # u·v = g·h = −sin(dip) in the world frame of Eq. 2
    v = vp @ Q.T
    h = magnetic_reference(dip)
    world = np.stack([GRAVITY, h])
    body = np.stack([u, v], axis=1)
    R = wahba(body, np.broadcast_to(world, body.shape))
    gains = {"accel": Ka, "mag": Km @ Q.T}
    state = State(gains, {"accel": ba, "mag": bm}, dip, R)
    return to_frame(problem, state)


def to_frame(problem: Problem, state: State) -> State:
    """Move the body frame to the one where ``problem.frame``'s gain is symmetric (Sec. 4.3)."""
    s = problem.frame
    K = state.gains[s]
    if problem.joint and np.linalg.det(K) < 0:
        state = flip_other(problem, state, other=s)
        K = state.gains[s]
    W, _, Vt = np.linalg.svd(K)
    U = W @ Vt
    state = state.copy()
    for k in state.gains:
        state.gains[k] = state.gains[k] @ U.T
    state.gains[s] = 0.5 * (state.gains[s] + state.gains[s].T)
    state.rotations = U @ state.rotations
    return state


def flip_other(problem: Problem, state: State, other: str) -> State:
    """The exact twin of a joint solution: ``K → −K`` for one sensor, ``dip → −dip``.

    ``K_m R h = (−K_m)(R R_z(π))h'`` with ``h'`` the field of dip ``−dip`` (and likewise for the
    accelerometer with ``R_x(π)``), so the likelihood cannot choose: the magnetometer's
    handedness relative to the accelerometer decides (see ``mle.py``).
    """
    T = twin_flip(other)
    state = state.copy()
    state.gains[other] = -state.gains[other]
    state.dip = -state.dip
    state.rotations = state.rotations @ T
    return state


def _pencil(y: Array, weights: Array, n_grid: int) -> tuple[Array, Array, Array]:
    """Ellipsoids through few points (N < 12): the pencil of the two smallest singular vectors.

    Returns per grid member the symmetric gain ``K_y``, the centre (whitened coordinates) and a
    validity mask (an ellipsoid, not another quadric).
    """
    wsum = weights.sum()
    c0 = weights @ y / wsum
    d = y - c0
    s0 = np.sqrt(weights @ np.einsum("ni,ni->n", d, d) / wsum)
    z = d / s0
    x1, x2, x3 = z.T
    D = np.column_stack(
        [x1 * x1, x2 * x2, x3 * x3, 2 * x1 * x2, 2 * x1 * x3, 2 * x2 * x3, 2 * z, np.ones(len(z))]
    )
    D *= np.sqrt(weights / wsum)[:, None]
    Z = np.linalg.svd(D, full_matrices=True)[2][-2:]
    t = np.linspace(0.0, np.pi, n_grid, endpoint=False)
    theta = np.cos(t)[:, None] * Z[0] + np.sin(t)[:, None] * Z[1]
    A = theta[:, _SYM_INDEX]
    beta, gamma = theta[:, 6:9], theta[:, 9]
    ok = np.abs(np.linalg.det(A)) > 1e-12
    A = np.where(ok[:, None, None], A, np.eye(3))
    zc = -np.linalg.solve(A, beta[:, :, None])[:, :, 0]
    k = np.einsum("ti,tij,tj->t", zc, A, zc) - gamma
    M = A / np.where(np.abs(k) > 1e-300, k, 1.0)[:, None, None]
    w, V = np.linalg.eigh(M)
    ok &= np.all(w > 0, axis=1)
    w = np.where(w > 0, w, 1.0)
    K = s0 * (V / np.sqrt(w)[:, None, :]) @ V.transpose(0, 2, 1)
    return K, c0 + s0 * zc, ok


def few_pose_starts(problem: Problem, n_grid: int = 24, keep: int = 3) -> list[State]:
    """Starts for few poses (N < 12); with 8-9 each sensor's ellipsoid is not even determined.

    Every pair of members of the two sensors' quadric pencils is scored by how well the poses'
    gravity and field directions keep a constant angle (step 2, with its pencil search); the
    ``keep`` best pairs become starts. Batched over all pairs.
    """
    if not problem.joint:
        return []
    w = np.minimum(problem.start_weight["accel"], problem.start_weight["mag"])
    dirs, pens = {}, {}
    for s in ("accel", "mag"):
        K, c, ok = _pencil(problem.start_mu[s], problem.start_weight[s], n_grid)
        y = problem.start_mu[s]
        u = np.linalg.solve(K[:, None], (y[None] - c[:, None])[..., None])[..., 0]
        u /= np.linalg.norm(u, axis=-1, keepdims=True)
        dirs[s], pens[s] = u, (K, c, ok)
    ia, im = np.nonzero(pens["accel"][2][:, None] & pens["mag"][2][None, :])
    if len(ia) == 0:
        return []
    u, v = dirs["accel"][ia], dirs["mag"][im]  # (P, N, 3)
    rows = (
        np.concatenate(
            [np.einsum("pni,pnj->pnij", u, v).reshape(len(ia), -1, 9), -np.ones((*u.shape[:2], 1))],
            axis=2,
        )
        * np.sqrt(w)[None, :, None]
    )
    Z = np.linalg.svd(rows, full_matrices=True)[2][:, -2:]  # (P, 2, 10)
    phi = np.linspace(0.0, np.pi, 24, endpoint=False)
    cand = np.cos(phi)[None, :, None] * Z[:, None, 0] + np.sin(phi)[None, :, None] * Z[:, None, 1]
    Uq, _, Vq = np.linalg.svd(cand[..., :9].reshape(len(ia), len(phi), 3, 3))
    Q = Uq @ Vq
    proj = np.einsum("pni,pfij,pnj->pfn", u, Q, v)
    c = proj @ w / w.sum()
    resid = (((proj - c[..., None]) ** 2) @ w).min(axis=1)
    starts = []
    for p in np.argsort(resid)[:keep]:
        fits = {}
        for s, i in (("accel", ia[p]), ("mag", im[p])):
            K, centre, _ = pens[s]
            L = problem.start_chol[s]
            Kr = L @ K[i]
            P, _ = _sqrtm_spd(Kr @ Kr.T)
            fits[s] = (P, L @ centre[i])
        starts.append(start_from_fits(problem, fits))
    return starts
