"""Which columns of a log hold which sensor: common spellings, explicit overrides.

``ax``, ``acc_x``, ``accel_x``, ``grav_x``, ``ax_g``, ``mag_x``, ``mx_rawdiv10``, ``gyr_x``,
ROS's ``field.linear_acceleration.x`` ... are recognised; a time column and a pose-label column
too. Every problem is an :class:`~fieldcal.errors.InputError` naming the fix.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

from ..errors import InputError

__all__ = ["explicit_columns", "normalise", "recognise_columns"]

# Prefix spellings per sensor, longest first so "accel_x" is not read as "a" + "ccel_x".
_PREFIXES: dict[str, tuple[str, ...]] = {
    "accel": (
        "field_linear_acceleration",
        "linear_acceleration",
        "accelerometer",
        "acceleration",
        "gravity",
        "accel",
        "grav",
        "acc",
        "a",
    ),
    "mag": (
        "field_magnetic_field",
        "magnetic_field",
        "magnetometer",
        "compass",
        "magn",
        "mag",
        "m",
    ),
    "gyro": (
        "field_angular_velocity",
        "angular_velocity",
        "gyroscope",
        "omega",
        "gyro",
        "gyr",
        "g",
        "w",
    ),
}
_SENSOR_RE = {
    sensor: re.compile(rf"^(?P<prefix>{'|'.join(p)})_?(?P<axis>[xyz])(?P<suffix>_.*)?$")
    for sensor, p in _PREFIXES.items()
}
_TIME_RE = re.compile(
    r"^(?:t|time|timestamp|stamp|field_header_stamp|sec|secs|seconds|millis|micros|elapsed)"
    r"(?:_.*)?$"
)
_POSE_NAMES = ("pose", "pose_id", "pose_label", "label")


def normalise(name: str) -> str:
    """``"Acc X (m/s^2)"`` -> ``"acc_x_m_s_2"``: lower case, runs of other characters -> ``_``."""
    return re.sub(r"[^a-z0-9]+", "_", name.strip().lower()).strip("_")


def recognise_columns(names: Sequence[str]) -> dict[str, list[str]]:
    """Guess each role's columns from their names.

    Returns a dict with keys among ``accel``, ``mag``, ``gyro`` (three names each, x, y, z),
    ``time`` and ``pose`` (one name each). The first complete x/y/z triple of a sensor in column
    order wins (``ax_g, ay_g, az_g`` share a prefix and a suffix).
    """
    found: dict[str, list[str]] = {}
    for sensor, pattern in _SENSOR_RE.items():
        groups: dict[tuple[str, str], dict[str, str]] = {}
        for name in names:
            match = pattern.match(normalise(name))
            if match:
                key = (match["prefix"], match["suffix"] or "")
                groups.setdefault(key, {}).setdefault(match["axis"], name)
        for axes in groups.values():
            if len(axes) == 3:
                found[sensor] = [axes["x"], axes["y"], axes["z"]]
                break
    for name in names:
        if "time" not in found and _TIME_RE.match(normalise(name)):
            found["time"] = [name]
        if "pose" not in found and normalise(name) in _POSE_NAMES:
            found["pose"] = [name]
    return found


def explicit_columns(spec: str | Sequence[str] | None) -> list[str] | None:
    """``"ax,ay,az"`` or a sequence of three names as a list; ``None`` stays ``None``."""
    if spec is None:
        return None
    if isinstance(spec, str):
        names = [s.strip() for s in spec.split(",")]
    elif isinstance(spec, Sequence) and all(isinstance(s, str) for s in spec):
        names = list(spec)
    else:
        names = []
    if len(names) != 3 or not all(names):
        raise InputError(f"give three column names x,y,z, e.g. 'ax,ay,az'; got {spec!r}"[:200])
    return names
