"""Where the gyroscope's fit starts: the gain from the segments' integrated raw rates against the
turns they made (least squares, turns counted), or a scalar searched on a grid for the gravity
directions; a datasheet guess when given."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError
from .data import Segments, segment_sums
from .integrate import rotation_vector
from .model import Array, SegmentModel


def guess_matrix(gain_guess: float | ArrayLike | None, unit: float) -> Array | None:
    if gain_guess is None:
        return None
    G = np.asarray(gain_guess, dtype=float)
    if G.shape == ():
        G = float(G) * np.eye(3)
    if G.shape != (3, 3) or not np.all(np.isfinite(G)) or abs(np.linalg.det(G)) == 0:
        raise InputError(
            "gain_guess must be a number (raw units per rad/s, e.g. from the datasheet) or an "
            "invertible 3x3 matrix"
        )
    out: Array = G / unit
    return out


def unwrap(phi: Array, predicted: Array) -> Array:
    """The rotation vectors ``φ + 2πm φ/|φ|`` nearest to ``predicted`` (turns beyond half a
    turn have the same rotation; the integrated rate says how far the device went)."""
    angle = np.linalg.norm(phi, axis=1)
    axis = phi / np.where(angle > 0, angle, 1.0)[:, None]
    along = np.einsum("mi,mi->m", axis, predicted)
    m = np.round((along - angle) / (2.0 * np.pi))
    out: Array = axis * (angle + 2.0 * np.pi * m)[:, None]
    return out


def linear_gain(s: Array, phi: Array) -> tuple[Array, bool]:
    """``K`` minimising ``Σ |s_k − K φ_k|²`` and whether the turns span three axes; along axes
    no turn spans, ``K`` is the mean scale of the others (the observability check names them).
    """
    A = phi.T @ phi
    w, V = np.linalg.eigh(A)
    full = bool(w[0] > 1e-6 * w[-1])
    keep = w > 1e-6 * w[-1] if w[-1] > 0 else np.zeros(3, dtype=bool)
    if not np.any(keep):
        return np.eye(3), False
    Vk = V[:, keep]
    K = (s.T @ phi) @ Vk @ np.diag(1.0 / w[keep]) @ Vk.T
    if not full:
        scale = float(np.mean(np.linalg.svd(K @ Vk, compute_uv=False)))
        Vn = V[:, ~keep]
        K = K + scale * Vn @ Vn.T
    return K, full


def start_rotations(data: Segments, p: Array, observed: Array, guess: Array | None) -> Array:
    """A start for ``M = K⁻¹``: the guess, else ``s_k ≈ K φ_k`` by least squares, ``s_k`` the
    segment's integrated raw rate and ``φ_k`` its turn (exact for a turn about a fixed axis),
    over the turns under 120° (no doubt how far they went) whose ``|s_k| / |φ_k|`` is within a
    factor 1.5 of the median (a jump in the log, a turn the gyroscope never saw, is left out),
    then with every turn counted by that gain."""
    if guess is not None:
        out: Array = np.asarray(np.linalg.inv(guess), dtype=float)
        return out
    s = segment_sums(data, p)
    phi = -rotation_vector(observed)  # ΔR = exp(−[∫ω]×) for a turn about a fixed axis
    angle = np.linalg.norm(phi, axis=1)
    ratio = np.linalg.norm(s, axis=1) / np.maximum(angle, 1e-300)
    turned = angle > np.radians(10.0)
    c = float(np.median(ratio[turned])) if np.any(turned) else float(np.median(ratio))
    usable = turned & (ratio > c / 1.5) & (ratio < 1.5 * c)
    small = usable & (angle < 2.0 * np.pi / 3.0)
    K, full = linear_gain(s[small], phi[small])
    if not full:
        K, full = linear_gain(s[usable], phi[usable])
    if not full:
        K, _ = linear_gain(s, phi)
    pick = usable if np.count_nonzero(usable) >= 3 else np.ones(len(s), dtype=bool)
    K, _ = linear_gain(s[pick], unwrap(phi[pick], np.linalg.solve(K, s[pick].T).T))
    if not np.all(np.isfinite(K)) or abs(np.linalg.det(K)) == 0:
        raise InputError(
            "the turns between the poses give no start for the gyroscope's gain; pass "
            "gain_guess (raw units per rad/s, e.g. from the datasheet)"
        )
    out = np.asarray(np.linalg.inv(K), dtype=float)
    return out


def start_gravity(data: Segments, p: Array, u: Array, guess: Array | None, n_poses: int) -> Array:
    if guess is not None:
        out: Array = np.asarray(np.linalg.inv(guess), dtype=float)
        return out
    # a scalar gain c (either sign), searched on a log grid: the integrated turns must carry
    # each gravity direction to the next
    s = segment_sums(data, p)
    angle = np.arccos(np.clip(np.einsum("mi,mi->m", u[data.before], u[data.before + 1]), -1, 1))
    c0 = float(np.median(np.linalg.norm(s, axis=1)) / max(float(np.median(angle)), 1e-3))
    model = SegmentModel(data, "gravity", n_poses, u, np.zeros((3, 3)))
    x = np.concatenate([np.zeros(9), p.ravel()])
    best, best_cost = np.eye(3) / c0, math.inf
    for sign in (1.0, -1.0):
        for factor in np.geomspace(0.1, 10.0, 31):
            x[:9] = (np.eye(3) / (sign * c0 * factor)).ravel()
            r = model.residuals(x)
            cost = float(np.sum(r * r))
            if cost < best_cost:
                best, best_cost = x[:9].reshape(3, 3).copy(), cost
    return best
