"""The gauge (seed paper Eq. 2, Sec. 4.3): re-express any parameter set in fieldcal's frames.

A calibration's parameters are defined up to a rotation of the world frame, the field
magnitudes and a rotation of the body frame; :func:`canonical_gauge` fixes all three the way
:mod:`fieldcal.geometry.frames` states, without changing one predicted reading.
"""

from __future__ import annotations

from typing import overload

import numpy as np
from numpy.typing import NDArray

from .frames import GRAVITY, orthogonal_polar_factor

__all__ = ["canonical_gauge"]

Array = NDArray[np.float64]


@overload
def canonical_gauge(
    rotations: Array,
    accel_gain: Array,
    mag_gain: Array,
    gravity: Array,
    magnetic: Array,
    body_frame: str = ...,
) -> tuple[Array, Array, Array, Array, Array]: ...


@overload
def canonical_gauge(
    rotations: Array,
    accel_gain: Array | None,
    mag_gain: Array | None,
    gravity: Array | None,
    magnetic: Array | None,
    body_frame: str = ...,
) -> tuple[Array, Array | None, Array | None, Array | None, Array | None]: ...


def canonical_gauge(
    rotations: Array,
    accel_gain: Array | None,
    mag_gain: Array | None,
    gravity: Array | None,
    magnetic: Array | None,
    body_frame: str = "accel",
) -> tuple[Array, Array | None, Array | None, Array | None, Array | None]:
    """Re-express any parameter set in fieldcal's gauge without changing one prediction.

    1. World frame (Eq. 2): rotate the world so that ``g = (0, 0, −|g|)`` and ``h`` lies in the
       x-z plane with ``h_x > 0``.
    2. Magnitudes (Sec. 4.3): fold ``|g|`` into ``K_a`` and ``|h|`` into ``K_m`` so both fields
       have unit length.
    3. Body frame (Sec. 4.3): write the chosen sensor's gain as ``P U`` (polar decomposition)
       and move the rotation ``U`` into every ``R_i``, leaving that gain symmetric positive
       definite.

    Returns ``(rotations, accel_gain, mag_gain, gravity, magnetic)``; a sensor's gain and its
    field are both given or both ``None``.
    """
    if (accel_gain is None) != (gravity is None) or (mag_gain is None) != (magnetic is None):
        raise ValueError("a sensor's gain and its reference field must be given together")
    R = np.array(rotations, dtype=float)
    Ka = None if accel_gain is None else np.array(accel_gain, dtype=float)
    Km = None if mag_gain is None else np.array(mag_gain, dtype=float)
    g = None if gravity is None else np.array(gravity, dtype=float)
    h = None if magnetic is None else np.array(magnetic, dtype=float)

    # 1. world frame: columns of W^T are the new world axes expressed in the old world frame.
    down = -g / np.linalg.norm(g) if g is not None else None
    if down is not None and h is not None:
        north = h - np.dot(h, down) * down
        north /= np.linalg.norm(north)
    elif down is not None:
        helper = np.eye(3)[int(np.argmin(np.abs(down)))]
        north = helper - np.dot(helper, down) * down
        north /= np.linalg.norm(north)
    else:
        assert h is not None
        north = h / np.linalg.norm(h)
        helper = np.eye(3)[int(np.argmin(np.abs(north)))]
        down = helper - np.dot(helper, north) * north
        down /= np.linalg.norm(down)
    east = np.cross(down, north)
    W = np.stack([north, east, down])  # new_world = W @ old_world
    R = R @ W.T

    # 2. unit fields
    if Ka is not None and g is not None:
        Ka = Ka * np.linalg.norm(g)
        g = GRAVITY.copy()
    if Km is not None and h is not None:
        hw = W @ h
        Km = Km * np.linalg.norm(hw)
        h = hw / np.linalg.norm(hw)

    # 3. symmetric gain for the chosen sensor
    K = Ka if body_frame == "accel" else Km
    if K is None:
        K = Km if Ka is None else Ka
    assert K is not None  # a field is given, and with it its gain
    U = orthogonal_polar_factor(K)
    if np.linalg.det(U) < 0:
        raise ValueError(
            f"the {body_frame} gain has a negative determinant, so it cannot be made symmetric "
            "positive definite by a rotation; choose the other body_frame or remap its axes"
        )
    R = U @ R
    if Ka is not None:
        Ka = Ka @ U.T
    if Km is not None:
        Km = Km @ U.T
    # symmetrise away round-off on the sensor that defines the frame
    if body_frame == "accel" and Ka is not None:
        Ka = 0.5 * (Ka + Ka.T)
    elif Km is not None and (body_frame == "mag" or Ka is None):
        Km = 0.5 * (Km + Km.T)
    return R, Ka, Km, g, h
