"""The start of the continuous fit: ellipsoids, the constant-angle alignment, Wahba per epoch.

1. Each field sensor's samples outline an ellipsoid: the symmetric gain and centre of the
   full-family fit (:func:`fieldcal.geometry.quadrics.family_fit`) for the magnetometer (soft
   iron can stretch it by tens of percent), of the sphere family for the accelerometer (a
   MEMS accelerometer's axes agree within a few percent, and the body's acceleration blurs its
   cloud: on half a log with rests in few orientations — BROAD trial 04's second half — the
   full family's start had one axis 30 % short and Levenberg–Marquardt diverged from it);
   samples far off the unit sphere given less weight in a second pass.
2. The magnetometer's axes relative to the accelerometer's and the dip: one orthogonal ``Q``
   keeping the angle between the two directions constant
   (:func:`fieldcal.geometry.alignment.constant_angle`), ``K_m = K_m,sym Qᵀ``, ``sin δ = −c``.
3. The trajectory: the raw gyroscope integrated (gain the identity, bias zero), cut into windows
   of :data:`WINDOW` seconds; within a window the integrated turn is trusted, and one Wahba
   problem per window (every sample's two directions turned back to the window's start)
   gives the window's first rotation. The hand's acceleration averages out over a window, so
   the start is smooth and consistent with the gyroscope — a rotation per sample from its own
   two directions is not, and on fast motion Levenberg–Marquardt did not recover from it.
4. The gyroscope: gain the identity (the log's rate units are rad/s), bias zero; the first
   Gauss–Newton step fits both.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ...errors import InputError
from ...geometry.alignment import constant_angle
from ...geometry.frames import GRAVITY, magnetic_reference
from ...geometry.quadrics import family_fit
from ...geometry.rotations import exp_so3, ordered_products, project_to_so3
from .model import Data, State

__all__ = ["start"]

Array = NDArray[np.float64]

#: At most this many samples go into the closed-form fits (evenly spaced).
_SUBSAMPLE = 4000
#: Seconds of gyroscope integration trusted in the start's trajectory.
WINDOW = 1.0


def _ellipsoid(y: Array, what: str, families: tuple[str, ...]) -> tuple[Array, Array]:
    """The first of ``families`` (full, axis-aligned, sphere) whose fit is an ellipsoid: a log
    that covers too few directions still gets a start, and the identifiability check
    (:mod:`.observability`) then says what the motion leaves undetermined."""
    for family in families:
        w = np.ones(len(y))
        fitted = None
        for _ in range(2):
            fitted = family_fit(y, w, family)
            if fitted is None:
                break
            K, c = fitted
            radius = np.linalg.norm(np.linalg.solve(K, (y - c).T).T, axis=1)
            w = 1.0 / (1.0 + ((radius - 1.0) / 0.05) ** 2)
        if fitted is not None and np.all(np.linalg.eigvalsh(fitted[0]) > 0):
            return fitted
    raise InputError(
        f"the {what} readings do not outline an ellipsoid, not even a sphere; turn the device "
        "through every orientation (each axis up and down) while recording"
    )


def start(data: Data) -> State:
    """A state near the likelihood's maximum (steps 1–4 of the module docstring)."""
    n = len(data.accel)
    pick = np.unique(np.linspace(0, n - 1, min(n, _SUBSAMPLE)).astype(int))
    Ka, ba = _ellipsoid(data.accel[pick], "accelerometer", ("sphere",))
    Ks, bm = _ellipsoid(data.mag[pick], "magnetometer", ("full", "axes", "sphere"))
    u = np.asarray(np.linalg.solve(Ka, (data.accel - ba).T).T, dtype=np.float64)
    quiet = np.exp(-(((np.linalg.norm(u, axis=1) - 1.0) / 0.05) ** 2))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.asarray(np.linalg.solve(Ks, (data.mag - bm).T).T, dtype=np.float64)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    Q, c = constant_angle(u[pick], v[pick], quiet[pick] + 1e-3)
    Km = Ks @ Q.T
    dip = float(-np.arcsin(np.clip(c, -1.0, 1.0)))
    R = _trajectory(data, u, v @ Q.T, quiet, magnetic_reference(dip))
    return State(Ka, ba, Km, bm, dip, np.eye(3), np.zeros(3), R)


def _trajectory(data: Data, up: Array, field: Array, quiet: Array, h: Array) -> Array:
    """Step 3: windows of integrated gyroscope, each aligned by one Wahba problem."""
    t = data.time
    rates = 0.5 * (data.gyro[1:] + data.gyro[:-1]) * np.diff(t)[:, None]
    G = np.concatenate([np.eye(3)[None], ordered_products(exp_so3(-rates))])  # body 0 → j
    window = np.floor((t - t[0]) / WINDOW).astype(int)
    first = np.flatnonzero(np.diff(np.concatenate([[-1], window])))  # each window's start
    which = np.repeat(np.arange(len(first)), np.diff(np.concatenate([first, [len(t)]])))
    rel = G @ np.swapaxes(G[first], 1, 2)[which]  # window start → sample j
    back_u = np.einsum("nji,nj->ni", rel, up)  # relᵀ u: the direction at the window's start
    back_v = np.einsum("nji,nj->ni", rel, field)
    profile = np.einsum("n,ni,j->nij", quiet + 1e-3, back_u, GRAVITY)
    profile += 0.5 * np.einsum("ni,j->nij", back_v, h)
    B = np.zeros((len(first), 3, 3))
    np.add.at(B, which, profile)
    R: Array = rel @ project_to_so3(B)[which]
    return R
