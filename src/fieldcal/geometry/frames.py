"""fieldcal's conventions, each defined once: the world frame, the dip, handedness, axis maps.

World frame (seed paper Eq. 2). North-East-Down. The accelerometer's reference vector is the
specific force it reads at rest, ``GRAVITY = (0, 0, −1)`` ("up" in NED), and the magnetic field
is ``magnetic_reference(dip) = (cos dip, 0, sin dip)``: the dip is positive when the field
points below the horizon (northern magnetic hemisphere). Both have unit length; physical
magnitudes are folded into the gains (Sec. 4.3) and restored by
:meth:`fieldcal.Calibration.with_field_magnitudes`.

Rotations act on column vectors: ``v_body = R_i @ v_world`` in pose ``i``.

Handedness twin. Static poses cannot tell a magnetometer mirrored relative to the
accelerometer from one in the opposite magnetic hemisphere: negating one sensor's gain, with
``h → (h_x, 0, −h_z)`` and ``R_i → R_i D``, predicts identical readings (:func:`twin_flip`).

Axis maps. ``"+y+x-z"`` is the matrix ``P`` with ``mapped = P @ raw`` (:func:`parse_axes`).

``docs/conventions.md`` states the same in prose and points here.
"""

from __future__ import annotations

import re

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .rotations import rotation_angle_deg

__all__ = [
    "ACCEL_SIGNS",
    "GRAVITY",
    "dip_of",
    "magnetic_derivative",
    "magnetic_reference",
    "misalignment_angle_deg",
    "misalignment_rotvec",
    "nearest_signed_permutation",
    "orthogonal_polar_factor",
    "parse_axes",
    "twin_flip",
]

Array = NDArray[np.float64]

#: The accelerometer's reference vector in the NED world frame: the specific force at rest.
GRAVITY: Array = np.array([0.0, 0.0, -1.0])
GRAVITY.setflags(write=False)

#: What an accelerometer may report at rest: the specific force (+1 g on the up axis, what
#: ``GRAVITY`` above models) or gravity (−1 g up, some loggers: its readings are negated for the
#: fit and the sign folded back into the gain and bias, ``fieldcal.pipeline.fold_axes``).
ACCEL_SIGNS = ("specific-force", "gravity")

#: ``R_i → R_i @ HALF_TURN_DOWN`` maps the world by a half turn about the down axis: it leaves
#: ``GRAVITY`` alone and negates ``h_x`` (used when a fit lands with ``h_x < 0``).
HALF_TURN_DOWN: Array = np.diag([-1.0, -1.0, 1.0])
HALF_TURN_DOWN.setflags(write=False)

#: A half turn about north: negates ``GRAVITY`` and ``h_z``, leaves ``h_x``.
HALF_TURN_NORTH: Array = np.diag([1.0, -1.0, -1.0])
HALF_TURN_NORTH.setflags(write=False)


def magnetic_reference(dip_rad: float | Array) -> Array:
    """The unit magnetic field in the NED world frame for a dip (radians, positive down);
    (..., 3) for an array of dips."""
    if isinstance(dip_rad, np.ndarray):
        out = np.zeros((*dip_rad.shape, 3))
        out[..., 0], out[..., 2] = np.cos(dip_rad), np.sin(dip_rad)
        return out
    return np.array([np.cos(dip_rad), 0.0, np.sin(dip_rad)])


def magnetic_derivative(dip_rad: float) -> Array:
    """``d magnetic_reference / d dip``."""
    return np.array([-np.sin(dip_rad), 0.0, np.cos(dip_rad)])


def dip_of(magnetic: Array) -> float:
    """Dip (inclination) in degrees of a field ``(h_x, 0, h_z)`` in the NED world frame.

    Positive when the field points below the horizon: ``dip = atan2(h_z, h_x)``.
    """
    return float(np.degrees(np.arctan2(magnetic[2], magnetic[0])))


def twin_flip(negated: str) -> Array:
    """``D`` of the handedness twin when the gain of sensor ``negated`` changes sign.

    Negating the magnetometer's gain needs ``D = HALF_TURN_DOWN`` (``g`` unchanged, ``h``'s
    horizontal part turned round); negating the accelerometer's needs ``D = HALF_TURN_NORTH``.
    In both cases the twin's field is ``(h_x, 0, −h_z)``: the dip changes sign.
    """
    if negated not in ("accel", "mag"):
        raise ValueError(f"sensor must be 'accel' or 'mag', got {negated!r}")
    return HALF_TURN_DOWN if negated == "mag" else HALF_TURN_NORTH


def orthogonal_polar_factor(K: Array) -> Array:
    """``U`` of the polar decomposition ``K = P U`` (``P`` symmetric positive semi-definite);
    batched over leading axes. Keeps the sign of ``det K`` (reflections allowed)."""
    W, _, Vt = np.linalg.svd(K)
    return W @ Vt


def nearest_signed_permutation(U: Array) -> Array:
    """The signed permutation matrix closest to ``U`` (greedy on the largest entries)."""
    S = np.zeros((3, 3))
    order = np.argsort(-np.abs(U), axis=None)
    used_rows: set[int] = set()
    used_cols: set[int] = set()
    for flat in order:
        r, c = divmod(int(flat), 3)
        if r not in used_rows and c not in used_cols:
            S[r, c] = np.sign(U[r, c]) or 1.0
            used_rows.add(r)
            used_cols.add(c)
    return S


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


def misalignment_rotvec(accel_gain: Array, mag_gain: Array, permutation: Array) -> Array:
    """Rotation vector(s) of ``Sᵀ U_m U_aᵀ`` (batched over leading axes of the gains)."""
    U = orthogonal_polar_factor(mag_gain) @ np.swapaxes(orthogonal_polar_factor(accel_gain), -1, -2)
    return _rotvec(permutation.T @ U)


def misalignment_angle_deg(accel_gain: Array, mag_gain: Array) -> float:
    """Angle between the accelerometer's and the magnetometer's axis triads, in degrees.

    Each gain splits (polar decomposition) into a symmetric stretch and an orthogonal factor
    ``U_s``: the direction the sensor's own axes point in the body frame. The misalignment is
    the rotation angle of ``U_m U_aᵀ`` once a mirrored or permuted axis convention (the nearest
    signed permutation) is taken out, so a magnetometer wired ``+y+x−z`` is not "90° off".
    """
    U = orthogonal_polar_factor(mag_gain) @ orthogonal_polar_factor(accel_gain).T
    S = nearest_signed_permutation(U)
    return float(rotation_angle_deg(S.T @ U))


def parse_axes(spec: str) -> Array:
    """A signed axis map like ``"+y+x-z"`` as the 3x3 matrix ``P`` with ``mapped = P @ raw``.

    Output axis ``i`` is the ``i``-th term: ``"+y+x-z"`` maps ``(x, y, z)`` to ``(y, x, −z)``
    (the convention of sap6's ``axes`` strings). A missing sign means ``+``.
    """
    text = spec.strip().lower()
    terms = re.findall(r"([+-]?)([xyz])", text)
    if "".join(s + a for s, a in terms) != text or len(terms) != 3:
        raise InputError(
            f"axis map {spec!r} is not three signed axes; write e.g. '+y+x-z' (output x = raw y, "
            "output y = raw x, output z = −raw z)"
        )
    if sorted(a for _, a in terms) != ["x", "y", "z"]:
        raise InputError(f"axis map {spec!r} must use each of x, y and z once, e.g. '+x-y-z'")
    P = np.zeros((3, 3))
    for i, (sign, axis) in enumerate(terms):
        P[i, "xyz".index(axis)] = -1.0 if sign == "-" else 1.0
    return P
