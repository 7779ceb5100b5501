"""The units of an accelerometer's and a gyroscope's readings, for noise densities in SI
units: from a calibration (``cal.units``), an option (a unit name, or SI units per raw unit
for raw counts) or the column names (``ax_g``, ``gx_dps``)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from .calibration import Calibration
from .errors import InputError
from .logs.columns import normalise

__all__ = [
    "PHYSICAL_UNIT",
    "SI_NAMES",
    "STANDARD_GRAVITY",
    "UNITS",
    "UNIT_OPTIONS",
    "calibration_unit",
    "column_unit",
    "option_unit",
]

Array = NDArray[np.float64]


#: m/s² per g (standard gravity, CGPM 1901), for accelerometers in g.
STANDARD_GRAVITY = 9.80665


#: Units understood per sensor, with their SI factor (m/s² or rad/s per unit).
UNITS: dict[str, dict[str, float]] = {
    "accel": {"g": STANDARD_GRAVITY, "mg": STANDARD_GRAVITY / 1000.0, "m/s^2": 1.0},
    "gyro": {"deg/s": math.pi / 180.0, "rad/s": 1.0},
}


_ALIASES = {
    "m/s2": "m/s^2",
    "m/s²": "m/s^2",
    "mps2": "m/s^2",
    "m/s/s": "m/s^2",
    "dps": "deg/s",
    "°/s": "deg/s",
    "deg/sec": "deg/s",
    "rad/sec": "rad/s",
}


#: Column-name endings (normalised: ``gx_dps``, ``acc_x_m_s_2``) that state a unit.
_COLUMN_UNITS: dict[str, tuple[tuple[str, str], ...]] = {
    "accel": (
        ("_m_s_2", "m/s^2"),
        ("_m_s2", "m/s^2"),
        ("_mps2", "m/s^2"),
        ("_ms2", "m/s^2"),
        ("_mg", "mg"),
        ("_g", "g"),
    ),
    "gyro": (
        ("_deg_s", "deg/s"),
        ("_dps", "deg/s"),
        ("_degps", "deg/s"),
        ("_rad_s", "rad/s"),
        ("_rads", "rad/s"),
        ("_radps", "rad/s"),
    ),
}


SI_NAMES = {"accel": "m/s^2", "gyro": "rad/s"}


UNIT_OPTIONS = {"accel": "accel_unit (--accel-unit)", "gyro": "gyro_unit (--gyro-unit)"}


#: The raw units a number may give (SI units per raw unit): from a 24-bit converter's count to
#: ten g (m/s²), from a navigation gyroscope's count to a revolution per second (rad/s); a number
#: beyond makes noise densities no sensor has.
PHYSICAL_UNIT = {"accel": (1e-9, 1e3), "gyro": (1e-10, 1e2)}


_SI = {"accel": "m/s^2", "gyro": "rad/s"}


def _unit_name(value: str, sensor: str) -> str:
    key = value.strip().lower().replace(" ", "")
    key = _ALIASES.get(key, key)
    if key not in UNITS[sensor]:
        raise InputError(
            f"{UNIT_OPTIONS[sensor].split()[0]} must be one of {', '.join(UNITS[sensor])} or a "
            f"number (SI units per raw unit), got {value!r}"[:200]
        )
    return key


def option_unit(value: object, sensor: str) -> tuple[str, float] | None:
    """``(unit, SI factor)`` from an ``accel_unit``/``gyro_unit`` option (``None``: not given)."""
    if value is None:
        return None
    if isinstance(value, str):
        name = _unit_name(value, sensor)
        return name, UNITS[sensor][name]
    ok = not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, float, np.number))
    number = float(value) if ok else math.nan  # type: ignore[arg-type]  # checked just above
    if not (math.isfinite(number) and number > 0):
        raise InputError(
            f"{UNIT_OPTIONS[sensor].split()[0]} must be a unit name or a positive number (SI "
            f"units per raw unit), got {value!r}"[:200]
        )
    low, high = PHYSICAL_UNIT[sensor]
    if not low <= number <= high:
        raise InputError(
            f"{UNIT_OPTIONS[sensor].split()[0]} {number:.3g} is outside any sensor's raw unit "
            f"({low:g} to {high:g} {_SI[sensor]} per raw unit); give a unit name or the "
            "sensor's scale per count"[:300]
        )
    return "raw", number


def column_unit(columns: Sequence[str], sensor: str) -> str | None:
    """The unit all three column names state (``ax_g``, ``gx_dps``), else ``None``."""
    found = set()
    for name in columns:
        norm = normalise(name)
        unit = next((u for end, u in _COLUMN_UNITS[sensor] if norm.endswith(end)), None)
        found.add(unit)
    return found.pop() if len(found) == 1 else None


def calibration_unit(cal: Calibration, sensor: str) -> tuple[str, float | None]:
    """The unit of ``cal``'s corrected readings of ``sensor`` and its SI factor."""
    if sensor == "gyro":
        return "rad/s", 1.0
    if sensor == "mag":
        return cal.units.get("mag_calibrated", "calibrated"), None
    magnitude = cal.gravity_norm
    g = 1.0 if magnitude is None else float(magnitude)
    if g == 1.0:
        return "g", STANDARD_GRAVITY
    if abs(g / STANDARD_GRAVITY - 1.0) < 0.02:
        return "m/s^2", 1.0
    if g == 1000.0:
        return "mg", STANDARD_GRAVITY / 1000.0
    return f"|g| = {g:g}", None
