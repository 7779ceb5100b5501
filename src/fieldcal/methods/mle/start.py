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

from typing import cast

import numpy as np
from numpy.typing import NDArray

from ...geometry.alignment import constant_angle, constant_angle_rows
from ...geometry.frames import GRAVITY, magnetic_reference, orthogonal_polar_factor, twin_flip
from ...geometry.quadrics import family_fit, family_fits, pencil_fits, spd_sqrt
from ...geometry.rotations import exp_so3, wahba
from ...likelihood.pose_model import Problem, State, field

Array = NDArray[np.float64]


def sensor_start(problem: Problem, sensor: str, model: str) -> tuple[Array, Array] | None:
    """Symmetric gain and bias of one sensor, in raw units, from its ellipsoid (each sensor
    and family fitted once per problem: the mixed starts share them, ``problem.memo``)."""
    key = ("sensor_start", sensor, model)
    if key not in problem.memo:
        problem.memo[key] = _sensor_start(problem, sensor, model)
    fit = cast(tuple[Array, Array] | None, problem.memo[key])
    return None if fit is None else (fit[0].copy(), fit[1].copy())  # a start is changed


def _sensor_start(problem: Problem, sensor: str, model: str) -> tuple[Array, Array] | None:
    w = problem.start_weight[sensor]
    fit = family_fit(problem.start_mu[sensor], w, model)
    if fit is None:
        return None
    Ky, cy = fit
    L = problem.start_chol[sensor]
    K = L @ Ky
    # symmetric factor of the polar decomposition K = P U (Sec. 4.3): the body frame of start
    P, _ = spd_sqrt(K @ K.T)
    return P, L @ cy


def _directions(problem: Problem, sensor: str, K: Array, b: Array) -> Array:
    means = problem.means[sensor]
    u = np.linalg.solve(K, (means - b).T).T
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _both_directions(
    problem: Problem, gains: tuple[Array, Array], biases: tuple[Array, Array]
) -> tuple[Array, Array]:
    """:func:`_directions` of the accelerometer and the magnetometer in one solve (the same
    numbers: one LAPACK solve per matrix either way)."""
    means = np.stack([problem.means["accel"], problem.means["mag"]])
    u = np.linalg.solve(np.stack(gains), (means - np.stack(biases)[:, None, :]).transpose(0, 2, 1))
    u = u.transpose(0, 2, 1)
    u = u / np.linalg.norm(u, axis=2, keepdims=True)
    return u[0], u[1]


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


def sensor_starts(problem: Problem, model: str) -> dict[str, tuple[Array, Array]] | None:
    """:func:`sensor_start` of every sensor with the same ellipsoid family, all at once."""
    sensors = problem.sensors
    K, c, ok = family_fits(
        np.stack([problem.start_mu[s] for s in sensors]),
        np.stack([problem.start_weight[s] for s in sensors]),
        model,
    )
    if not ok.all():
        return None
    L = np.stack([problem.start_chol[s] for s in sensors])
    K = L @ K
    # symmetric factor of the polar decomposition K = P U (Sec. 4.3): the body frame of start
    P, _ = spd_sqrt(K @ K.transpose(0, 2, 1))
    b = (L @ c[:, :, None])[:, :, 0]
    return {s: (P[k], b[k]) for k, s in enumerate(sensors)}


def closed_form_start(problem: Problem, model: str | tuple[str, str] = "full") -> State | None:
    """A full starting state, or None when an ellipsoid fit fails for this model."""
    models = (model, model) if isinstance(model, str) else model
    if len(set(models[: len(problem.sensors)])) == 1:
        fits = sensor_starts(problem, models[0])
        return None if fits is None else start_from_fits(problem, fits)
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
    u, vp = _both_directions(problem, (Ka, Km), (ba, bm))
    w = np.minimum(problem.start_weight["accel"], problem.start_weight["mag"])
    Q, c = constant_angle(u, vp, w)
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
    U = orthogonal_polar_factor(K)
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
        K, c, ok = pencil_fits(problem.start_mu[s], problem.start_weight[s], n_grid)
        y = problem.start_mu[s]
        u = np.linalg.solve(K[:, None], (y[None] - c[:, None])[..., None])[..., 0]
        u /= np.linalg.norm(u, axis=-1, keepdims=True)
        dirs[s], pens[s] = u, (K, c, ok)
    ia, im = np.nonzero(pens["accel"][2][:, None] & pens["mag"][2][None, :])
    if len(ia) == 0:
        return []
    u, v = dirs["accel"][ia], dirs["mag"][im]  # (P, N, 3)
    rows = np.stack([constant_angle_rows(a, b) for a, b in zip(u, v, strict=True)])
    rows *= np.sqrt(w)[None, :, None]
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
            P, _ = spd_sqrt(Kr @ Kr.T)
            fits[s] = (P, L @ centre[i])
        starts.append(start_from_fits(problem, fits))
    return starts
