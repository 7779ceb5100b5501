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
3. Each pose's rotation from its two vectors (Wahba's problem, in closed form for two
   directions: :func:`fieldcal.geometry.rotations.wahba_pair`).

The starts a fit asks for share their work: the whitened means' design is built once, each
(sensor, family) ellipsoid is fitted once, and steps 2-3 run for a group of starts at once,
vectorised over the starts (:func:`closed_form_starts`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import numpy as np
from numpy.typing import NDArray

from ...geometry.alignment import constant_angle_rows, constant_angles
from ...geometry.frames import GRAVITY, magnetic_reference, orthogonal_polar_factor, twin_flip
from ...geometry.quadrics import family_design, family_fits, pencil_fits, spd_sqrt
from ...geometry.rotations import exp_so3, wahba_pair
from ...likelihood.pose_model import Problem, State, field

Array = NDArray[np.float64]


#: The ellipsoid families of the starts (``model`` of :func:`closed_form_start`).
FAMILIES = ("full", "axes", "sphere")
#: The starts a cold fit of :mod:`fieldcal.methods.mle` always tries first, one after the
#: other (its ``STARTS[:2]``); when the poses are few or the certificate is doubtful it asks
#: for every other pair of families, one after the other. Asked for one start of either
#: group, :func:`closed_form_start` computes the whole group in one batch
#: (:func:`closed_form_starts`) and keeps the others for their calls.
PAIRED: tuple[tuple[str, str], ...] = (("full", "full"), ("axes", "axes"))

Fit = tuple[Array, Array]


def _design(problem: Problem) -> tuple[Array, Array, tuple[Array, Array, Array, Array]]:
    """Every sensor's whitened pose means and weights, stacked (S, N, 3) and (S, N), and their
    normalised design (:func:`fieldcal.geometry.quadrics.family_design`): the same for every
    ellipsoid family, computed once per problem."""
    key = "start.design"
    if key not in problem.memo:
        y = np.array([problem.start_mu[s] for s in problem.sensors])
        w = np.array([problem.start_weight[s] for s in problem.sensors])
        problem.memo[key] = (y, w, family_design(y, w))
    return cast(tuple[Array, Array, tuple[Array, Array, Array, Array]], problem.memo[key])


def _sensor_fits(
    problem: Problem, wanted: set[tuple[str, str]]
) -> dict[tuple[str, str], Fit | None]:
    """Step 1: the ellipsoid start (symmetric gain and bias, in raw units) of each (sensor,
    family) in ``wanted``, or ``None`` where the fit is no ellipsoid. Each is fitted once per
    problem (``problem.memo``: the mixed starts share them); the missing ones in one batched
    fit per family, for the sensors that need it."""
    memo = problem.memo
    missing = sorted(pair for pair in wanted if ("sensor_start", *pair) not in memo)
    if missing:
        y, w, (z, c0, s0, sw) = _design(problem)
        order = {s: k for k, s in enumerate(problem.sensors)}
        gains, centres, fitted, done = [], [], [], []
        for family in dict.fromkeys(f for _, f in missing):
            pairs = [(s, f) for s, f in missing if f == family]
            i = [order[s] for s, _ in pairs]
            K, c, ok = family_fits(y[i], w[i], family, design=(z[i], c0[i], s0[i], sw[i]))
            gains.append(K)
            centres.append(c)
            fitted.extend(ok.tolist())
            done.extend(pairs)
        L = np.array([problem.start_chol[s] for s, _ in done])
        K = L @ np.concatenate(gains)
        # symmetric factor of the polar decomposition K = P U (Sec. 4.3): the body frame of
        # start; every new fit's in one call
        P, _ = spd_sqrt(K @ K.transpose(0, 2, 1))
        b = (L @ np.concatenate(centres)[:, :, None])[:, :, 0]
        for k, (pair, ok) in enumerate(zip(done, fitted, strict=True)):
            memo[("sensor_start", *pair)] = (P[k], b[k]) if ok else None
    return {pair: cast(Fit | None, memo[("sensor_start", *pair)]) for pair in wanted}


def _directions(problem: Problem, sensor: str, K: Array, b: Array) -> Array:
    means = problem.means[sensor]
    u = np.linalg.solve(K, (means - b).T).T
    return u / np.linalg.norm(u, axis=1, keepdims=True)


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


def _models(problem: Problem, model: str | tuple[str, ...]) -> tuple[str, ...]:
    """The family of each sensor of the problem."""
    models = (model, model) if isinstance(model, str) else tuple(model)
    return models[: len(problem.sensors)]


def closed_form_start(problem: Problem, model: str | tuple[str, str] = "full") -> State | None:
    """A full starting state, or None when an ellipsoid fit fails for this model.

    The starts of :data:`PAIRED`, and all the others, are computed in two batches (asked for
    one, the rest of its group is kept in ``problem.memo`` for its call: a fit asks for all of
    them)."""
    models = _models(problem, model)
    key = ("closed_form_start", models)
    if key not in problem.memo:
        paired = [_models(problem, pair) for pair in PAIRED]
        every = dict.fromkeys(_models(problem, (a, m)) for a in FAMILIES for m in FAMILIES)
        group = paired if models in paired else [m for m in every if m not in paired]
        batch = [models] + [
            m for m in group if m != models and ("closed_form_start", m) not in problem.memo
        ]
        for m, state in zip(batch, closed_form_starts(problem, batch), strict=True):
            problem.memo[("closed_form_start", m)] = state
    state = cast(State | None, problem.memo[key])
    return None if state is None else state.copy()  # a start is changed by the solver


def closed_form_starts(
    problem: Problem, models: Sequence[str | tuple[str, ...]]
) -> list[State | None]:
    """:func:`closed_form_start` of several models at once: each (sensor, family) ellipsoid
    fitted once (one batched fit per family), then steps 2-3 of every start in one vectorised
    pass (:func:`starts_from_fits`)."""
    per_start = [_models(problem, m) for m in models]
    fits = _sensor_fits(
        problem, {(s, f) for ms in per_start for s, f in zip(problem.sensors, ms, strict=True)}
    )
    chosen: list[dict[str, Fit] | None] = []
    for ms in per_start:
        found = {s: fits[s, f] for s, f in zip(problem.sensors, ms, strict=True)}
        ok = all(f is not None for f in found.values())
        chosen.append(cast(dict[str, Fit], found) if ok else None)
    states = starts_from_fits(problem, [f for f in chosen if f is not None])
    out: list[State | None] = []
    for f in chosen:
        out.append(None if f is None else states.pop(0))
    return out


def starts_from_fits(problem: Problem, fits: list[dict[str, Fit]]) -> list[State]:
    """Steps 2-3 for several starts of one problem (each a sensor → (gain, bias) of step 1):
    orientation and dip from the constant angle, rotations by Wahba. Vectorised over the
    starts: one call of each LAPACK routine for all of them."""
    if not fits:
        return []
    if not problem.joint:
        s = problem.sensors[0]
        states = []
        for fit in fits:
            K, b = fit[s]
            u = _directions(problem, s, K, b)
            R = min_rotations(field(problem, s, 0.0), u)
            states.append(State({s: K.copy()}, {s: b.copy()}, 0.0, R))  # not the memo's
        return states
    K = np.array([[f["accel"][0], f["mag"][0]] for f in fits])  # (B, 2, 3, 3)
    b = np.array([[f["accel"][1], f["mag"][1]] for f in fits])  # (B, 2, 3)
    means = np.array([problem.means["accel"], problem.means["mag"]])  # (2, N, 3)
    # each sensor's unit directions (B, 2, N, 3): one LAPACK solve per matrix
    raw = np.swapaxes(
        np.linalg.solve(K, np.swapaxes(means[None] - b[:, :, None, :], -1, -2)), -1, -2
    )
    dirs = raw / np.linalg.norm(raw, axis=3, keepdims=True)
    w = np.minimum(problem.start_weight["accel"], problem.start_weight["mag"])
    Q, c = constant_angles(dirs[:, 0], dirs[:, 1], w)
    dip = np.arcsin(-c)  # u·v = g·h = −sin(dip) in the world frame of Eq. 2
    v = dirs[:, 1] @ np.swapaxes(Q, -1, -2)
    # Wahba's problem of each pose's two directions, in closed form
    R = wahba_pair(dirs[:, 0], v, GRAVITY, magnetic_reference(dip)[:, None])  # (B, N, 3, 3)
    gains = {"accel": K[:, 0], "mag": K[:, 1] @ np.swapaxes(Q, -1, -2)}
    return _to_frames(problem, gains, {"accel": b[:, 0], "mag": b[:, 1]}, dip, R)


def _to_frames(
    problem: Problem, gains: dict[str, Array], biases: dict[str, Array], dip: Array, R: Array
) -> list[State]:
    """Move the body frame of B joint starts to the one where ``problem.frame``'s gain is
    symmetric (Sec. 4.3), all at once: gains (B, 3, 3), biases (B, 3), dips (B,), rotations
    (B, N, 3, 3). A start whose frame gain is a reflection is first replaced by its exact twin
    (:func:`flip_other`)."""
    s = problem.frame
    # a reflected frame gain: the exact twin (flip_other) of those starts
    flip = np.linalg.det(gains[s]) < 0
    if flip.any():
        gains = {**gains, s: np.where(flip[:, None, None], -gains[s], gains[s])}
        dip = np.where(flip, -dip, dip)
        R = np.where(flip[:, None, None, None], R @ twin_flip(s), R)
    U = orthogonal_polar_factor(gains[s])
    Ut = np.swapaxes(U, -1, -2)
    moved = {k: g @ Ut for k, g in gains.items()}
    moved[s] = 0.5 * (moved[s] + np.swapaxes(moved[s], -1, -2))
    R = U[:, None] @ R
    return [
        State(
            {k: g[i] for k, g in moved.items()},
            {k: x[i].copy() for k, x in biases.items()},
            float(dip[i]),
            R[i],
        )
        for i in range(len(dip))
    ]


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
    chosen = []
    for p in np.argsort(resid)[:keep]:
        fits = {}
        for s, i in (("accel", ia[p]), ("mag", im[p])):
            K, centre, _ = pens[s]
            L = problem.start_chol[s]
            Kr = L @ K[i]
            P, _ = spd_sqrt(Kr @ Kr.T)
            fits[s] = (P, L @ centre[i])
        chosen.append(fits)
    return starts_from_fits(problem, chosen)
