"""Orientations a person can reproduce by hand, each with the words that say how.

The candidates an experiment design chooses from (``fieldcal.planning.next_pose``) are a fixed set:
the down direction (gravity) in the body frame is one of

- the 6 **faces**: one axis pointing straight down or straight up;
- the 12 **edges**: two axes each 45° below (or above) the horizon, the third axis level;
- the 8 **corners**: all three axes each 35.26° (``asin(1/√3)``) below or above the horizon;

and, for a joint (accelerometer + magnetometer) calibration, each at 4 headings: a named body
axis, or the horizontal part of it, pointing to magnetic north, east, south or west. The named
axis is the level one for an edge, the first axis (in X, Y, Z order) that is horizontal for a
face, and +X (its horizontal part) for a corner. Words name only positive axes for faces (the
"+X axis pointing straight up" is clearer than "-X pointing down") and the axes that point
*below* the horizon for edges and corners, so each sentence has one reading.

Conventions (``docs/conventions.md``): ``rotation`` maps world (North-East-Down) vectors to the
body frame, ``v_body = R v_world``; its columns are the body-frame directions of north, east and
down. ``down`` is ``R @ (0, 0, 1)``; an accelerometer at rest reads the specific force, which
points *up*: ``−down``. "Magnetic north" is the horizontal direction of the field, the world
frame's north in fieldcal's gauge (the field lies in the North-Down plane).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._frozen import ArrayDataclass, frozen_array
from ..errors import InputError
from .rotations import rotation_angle_deg

__all__ = [
    "CANDIDATES",
    "DOWN_CANDIDATES",
    "HEADINGS",
    "Orientation",
    "angle_deg",
    "candidates",
    "describe",
    "fibonacci_sphere",
    "orientation_from_vectors",
]

Array = NDArray[np.float64]


def fibonacci_sphere(n: int) -> Array:
    """``n`` unit vectors spread evenly on the sphere (a Fibonacci lattice): the orientations
    the predicted accuracy averages over (:mod:`fieldcal.trust.accuracy`) and its measurement
    against a simulated truth (:mod:`fieldcal.simulation.measured`)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (1.0 + 5**0.5) * k
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


AXES = ("X", "Y", "Z")
#: Headings of the named axis, degrees clockwise from magnetic north seen from above.
HEADINGS: dict[float, str] = {
    0.0: "magnetic north",
    90.0: "magnetic east",
    180.0: "magnetic south",
    270.0: "magnetic west",
}
#: Beyond this angle (degrees) :func:`describe` says how far the nearest candidate is.
NEAR_DEG = 5.0


@dataclass(frozen=True, eq=False)
class Orientation(ArrayDataclass):
    """One candidate orientation and the words that tell a person how to hold the device.

    Attributes
    ----------
    rotation : (3, 3) array
        World (NED) → body rotation, ``v_body = rotation @ v_world``. With ``heading_deg``
        ``None`` it is the orientation at heading 0 (any heading is as good).
    down : (3,) array
        Unit body-frame vector pointing down (``rotation[:, 2]``); the accelerometer at rest
        reads ``−down`` times ``|g|``.
    heading_deg : float or None
        Heading of the named axis (or of its horizontal part), degrees clockwise from magnetic
        north: 0, 90, 180 or 270; ``None`` when the heading is free (accelerometer alone).
    words : str
        How to hold the device, e.g. ``"lying on a face: +Z axis pointing straight down, +X
        axis towards magnetic north"``.
    kind : str
        ``"face"``, ``"edge"`` or ``"corner"``.
    heading_axis : str or None
        The named axis (``"+X"``, ``"+Y"``, ``"+Z"``), ``None`` when the heading is free.
    """

    rotation: Array = field(metadata={"shape": (3, 3)})
    down: Array = field(metadata={"shape": (3,)})
    heading_deg: float | None
    words: str
    kind: str
    heading_axis: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "rotation", frozen_array(self.rotation))
        object.__setattr__(self, "down", frozen_array(self.down))

    def __repr__(self) -> str:
        return f"Orientation({self.words!r})"


def _signed(axis: int, sign: float) -> str:
    return ("+" if sign > 0 else "-") + AXES[axis]


def _join(names: list[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _down_words(down: Array) -> tuple[str, str]:
    """(kind, words) for a face, edge or corner down direction (entries 0 or ±1/√k)."""
    nonzero = [i for i in range(3) if abs(down[i]) > 1e-9]
    if len(nonzero) == 1:
        i = nonzero[0]
        way = "down" if down[i] > 0 else "up"
        return "face", f"lying on a face: +{AXES[i]} axis pointing straight {way}"
    below = _join([_signed(i, down[i]) for i in nonzero])
    if len(nonzero) == 2:
        level = next(i for i in range(3) if i not in nonzero)
        level_words = f"{AXES[level]} axis level"
        return "edge", f"resting on an edge: {below} axes each 45° below the horizon, {level_words}"
    return "corner", f"balanced on a corner: {below} axes each 35° below the horizon"


def _heading_axis(down: Array) -> int:
    """The body axis whose heading the words name (see the module docstring)."""
    nonzero = [i for i in range(3) if abs(down[i]) > 1e-9]
    if len(nonzero) == 3:
        return 0
    return next(i for i in range(3) if i not in nonzero)


def _rotation(down: Array, axis: int, heading_deg: float) -> Array:
    """World → body rotation with ``down`` and the horizontal part of body ``axis`` pointing at
    ``heading_deg`` clockwise from north: columns north, east, down in the body frame."""
    d = down / np.linalg.norm(down)
    a = np.eye(3)[axis]
    horizontal = a - (a @ d) * d
    horizontal /= np.linalg.norm(horizontal)
    psi = np.radians(heading_deg)
    # the named axis is at heading ψ: a_h = cos ψ n + sin ψ e, e = d × n, so n is a_h turned
    # back by ψ about the down axis
    north = np.cos(psi) * horizontal - np.sin(psi) * np.cross(d, horizontal)
    east = np.cross(d, north)
    R = np.column_stack([north, east, d])
    # exact angles (0, 90, 180, 270): clean the round-off so the words' rotation is exact
    R[np.abs(R) < 1e-15] = 0.0
    return R


def _down_directions() -> list[Array]:
    """The 26 down directions: faces, edges, corners, each in a fixed order."""
    out: list[Array] = []
    for k in (1, 2, 3):
        for idx in itertools.combinations(range(3), k):
            for signs in itertools.product((1.0, -1.0), repeat=k):
                v = np.zeros(3)
                v[list(idx)] = signs
                out.append(v / np.sqrt(k))
    return out


def _build(heading: bool) -> tuple[Orientation, ...]:
    out = []
    for down in _down_directions():
        kind, words = _down_words(down)
        axis = _heading_axis(down)
        if not heading:
            R = _rotation(down, axis, 0.0)
            out.append(Orientation(R, R[:, 2], None, words, kind, None))
            continue
        for psi, where in HEADINGS.items():
            R = _rotation(down, axis, psi)
            part = " (its horizontal part)" if kind == "corner" else ""
            text = f"{words}, +{AXES[axis]} axis{part} towards {where}"
            out.append(Orientation(R, R[:, 2], psi, text, kind, "+" + AXES[axis]))
    return tuple(out)


#: The 104 joint candidates: 26 down directions (6 faces, 12 edges, 8 corners, in that
#: order) each at 4 headings (north, east, south, west).
CANDIDATES: tuple[Orientation, ...] = _build(heading=True)
#: The 26 down directions with the heading free (accelerometer alone).
DOWN_CANDIDATES: tuple[Orientation, ...] = _build(heading=False)


def candidates(heading: bool = True) -> tuple[Orientation, ...]:
    """The fixed candidate set: :data:`CANDIDATES` (``heading=True``, 104) or
    :data:`DOWN_CANDIDATES` (heading free, 26)."""
    return CANDIDATES if heading else DOWN_CANDIDATES


def angle_deg(R1: ArrayLike, R2: ArrayLike) -> Array:
    """Angle in degrees of the rotation taking ``R2`` to ``R1`` (``R1 R2ᵀ``), in [0, 180].

    Broadcast over leading axes: (..., 3, 3) and (..., 3, 3); two single rotations give a 0-d
    array (``float()`` it)."""
    A = np.asarray(R1, dtype=float)
    B = np.asarray(R2, dtype=float)
    return np.asarray(rotation_angle_deg(A @ np.swapaxes(B, -1, -2)))


def _checked_rotation(rotation: ArrayLike) -> Array:
    try:
        R = np.asarray(rotation, dtype=float)
    except (TypeError, ValueError):
        raise InputError("rotation must be a 3x3 array of numbers") from None
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise InputError(f"rotation must be a finite 3x3 array, got shape {R.shape}")
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise InputError(
            "rotation is not a proper rotation (R Rᵀ = I, det R = +1); "
            "pass a world→body rotation matrix such as cal.rotations[i]"
        )
    return R


_STACK = np.stack([c.rotation for c in CANDIDATES])
_DOWNS = np.stack([c.down for c in DOWN_CANDIDATES])


def describe(rotation: ArrayLike, heading: bool = True) -> str:
    """The words of the candidate nearest to ``rotation`` (world → body), with how far it is
    when that is more than 5°.

    Parameters
    ----------
    rotation : (3, 3) array
        A proper rotation, world (NED) → body.
    heading : bool
        Compare whole rotations against the 104 joint candidates (default), or only the down
        direction against the 26 heading-free ones (accelerometer alone).

    Returns
    -------
    str
        E.g. ``"lying on a face: +Z axis pointing straight down, +X axis towards magnetic
        north"``, or ``"... (12° away)"``.
    """
    R = _checked_rotation(rotation)
    if heading:
        angles = angle_deg(R, _STACK)
        best = int(np.argmin(angles))
        words, off = CANDIDATES[best].words, float(angles[best])
    else:
        cos = np.clip(_DOWNS @ R[:, 2], -1.0, 1.0)
        best = int(np.argmax(cos))
        words, off = DOWN_CANDIDATES[best].words, float(np.degrees(np.arccos(cos[best])))
    return words if off <= NEAR_DEG else f"{words} ({off:.0f}° away)"


def _vector(value: ArrayLike, name: str) -> Array:
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be 3 numbers (a body-frame vector)") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)) or not np.linalg.norm(v) > 0:
        raise InputError(f"{name} must be a finite, non-zero body-frame vector of 3 numbers")
    return v / np.linalg.norm(v)


def orientation_from_vectors(accel_body: ArrayLike, mag_body: ArrayLike | None = None) -> Array:
    """World (NED) → body rotation from one corrected accelerometer and magnetometer reading.

    TRIAD: down is ``−accel`` (the specific force points up at rest), north is the field's
    component orthogonal to down, east is ``down × north``; the rotation's columns are north,
    east and down in the body frame. Without a magnetometer the heading is 0: north is taken as
    the horizontal part of the body x axis (of y when x is vertical).

    Parameters
    ----------
    accel_body : (3,) array
        Corrected specific force, e.g. ``cal.correct_accel(raw)`` (any magnitude).
    mag_body : (3,) array, optional
        Corrected field in the same body frame (``cal.correct_mag(raw)``).

    Returns
    -------
    (3, 3) array
        The rotation ``R`` with ``R @ (0, 0, 1)`` = down and ``R @ (1, 0, 0)`` = north.
    """
    down = -_vector(accel_body, "accel_body")
    if mag_body is None:
        # body x unless it is vertical (its horizontal part, |(d1, d2)|, under 1e-3)
        ref = np.eye(3)[0] if np.hypot(down[1], down[2]) > 1e-3 else np.eye(3)[1]
    else:
        ref = _vector(mag_body, "mag_body")
    north = ref - (ref @ down) * down
    norm = float(np.linalg.norm(north))
    if norm < 1e-6:
        raise InputError(
            "mag_body is parallel to gravity, so it gives no heading; "
            "check the readings are from the same instant and both corrected"
        )
    north /= norm
    return np.column_stack([north, np.cross(down, north), down])
