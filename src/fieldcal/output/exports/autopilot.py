"""What ArduPilot's and PX4's parameter exports share: units, the magnetometer-symmetric gauge
and the accelerometer's per-axis approximation, each with what it drops, computed.

Both autopilots correct the compass with a **symmetric** matrix and the accelerometer with
**per-axis** scales only (sources cited in :mod:`.ardupilot` and :mod:`.px4`):

- compass: ``m = M (raw − b)``, ``M`` symmetric. fieldcal's ``inv(gain) = U_mᵀ P_m⁻¹`` (polar
  decomposition ``gain = P_m U_m``), so ``M = c P_m⁻¹`` gives ``U_m`` times fieldcal's corrected
  field, exactly: the compass comes out in the magnetometer-symmetric body frame, rotated from
  the accelerometer's by ``U_m U_aᵀ``. That rotation (the misalignment) is what is dropped; its
  angle is reported.
- accelerometer: ``a = diag(s) (raw − b)`` with ``s_i = c / (P_a)_ii``. For a specific force
  ``w`` of magnitude ``|g|`` in the accelerometer-symmetric frame the error is
  ``(diag(s) P_a / c − I) c w``; its largest value over all directions, ``σ_max(E) c |g|``, is the
  stated bound.

``c`` converts fieldcal's calibrated units into the autopilot's (:func:`mag_factor`,
:func:`accel_factor`). The raw readings are taken as the autopilot's driver delivers them: the
offsets are in those raw units, which fieldcal cannot check (every file says so).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...calibration import Calibration
from ...errors import InputError
from ...geometry.frames import orthogonal_polar_factor
from ...geometry.rotations import rotation_angle_deg
from .common import corrections

__all__ = [
    "RAW_UNITS",
    "STANDARD_GRAVITY",
    "AutopilotCalibration",
    "ParameterRange",
    "accel_error_text",
    "accel_factor",
    "autopilot",
    "check_ranges",
    "mag_factor",
    "parameter_lines",
    "parameters",
]

Array = NDArray[np.float64]

#: m/s² per g (the standard gravity, ISO 80000-3).
STANDARD_GRAVITY = 9.80665

#: Gauss per unit for the units a field strength may be given in; Earth's field is 0.2-0.7 G,
#: so the bands below (x 0.15-0.8 G) never overlap and the magnitude names the unit.
_GAUSS_PER = {"G": 1.0, "mG": 1e-3, "uT": 1e-2, "nT": 1e-5, "T": 1e4}
_EARTH_GAUSS = (0.15, 0.8)


def mag_factor(cal: Calibration, unit: str) -> float:
    """Factor from the calibration's magnetometer units to ``unit`` (``"G"`` or ``"mG"``).

    The unit of ``cal.field_strength`` is read from its size: Earth's field is 0.15-0.8 gauss,
    150-800 mG, 15-80 µT, 15000-80000 nT, which do not overlap.

    Raises
    ------
    InputError
        The magnetometer is not scaled to a field strength, or one outside Earth's range.
    """
    strength = cal.field_strength
    fix = "calibrate --field-strength with the local field (e.g. 48.5 for 48.5 µT)"
    if strength is None or strength == 1.0:
        raise InputError(
            f"cannot export: the magnetometer is not scaled to a field strength; {fix}"
        )
    for gauss in _GAUSS_PER.values():
        if _EARTH_GAUSS[0] <= strength * gauss <= _EARTH_GAUSS[1]:
            return gauss / _GAUSS_PER[unit]
    raise InputError(
        f"cannot export: field strength {strength:g} is not Earth's field in G, mG, µT, nT or T; "
        f"{fix}"
    )


def accel_factor(cal: Calibration) -> float:
    """Factor from the calibration's accelerometer units to m/s².

    ``|g|`` within 2 % of 9.80665 is m/s² (factor 1); ``|g| = 1`` (the default) is taken as g.

    Raises
    ------
    InputError
        Any other ``|g|``.
    """
    g = cal.gravity_norm
    if g is None or abs(g - 1.0) <= 0.02:
        return STANDARD_GRAVITY
    if abs(g / STANDARD_GRAVITY - 1.0) <= 0.02:
        return 1.0
    raise InputError(
        f"cannot export: gravity {g:g} is neither g (1) nor m/s² (9.80665); "
        "calibrate --gravity 9.80665"
    )


@dataclass(frozen=True)
class AutopilotCalibration:
    """The calibration in an autopilot's form: symmetric compass matrix, per-axis accelerometer.

    Attributes
    ----------
    mag_matrix : (3, 3) array
        Symmetric ``M``: compass ``= M (raw − mag_bias)`` in the target's field unit.
    mag_bias : (3,) array
        Raw units (as the autopilot's compass driver delivers them).
    accel_scale : (3,) array
        Accelerometer ``= accel_scale * (raw − accel_bias)`` in m/s².
    accel_bias : (3,) array
        Raw units (as the autopilot's accelerometer driver delivers them).
    mag_factor, accel_factor : float
        Target units per fieldcal calibrated unit.
    misalignment_deg : float
        Angle of the rotation dropped between the compass and the accelerometer frames.
    accel_error_bound : float
        Largest error (m/s²) of the per-axis accelerometer at a specific force of 1 g.
    """

    mag_matrix: Array
    mag_bias: Array
    accel_scale: Array
    accel_bias: Array
    mag_factor: float
    accel_factor: float
    misalignment_deg: float
    accel_error_bound: float


def _polar(gain: Array) -> tuple[Array, Array]:
    """``(P, U)`` with ``gain = P U``, ``P`` symmetric positive definite."""
    U = orthogonal_polar_factor(gain)
    return gain @ U.T, U


def autopilot(cal: Calibration, mag_unit: str) -> AutopilotCalibration:
    """The numbers both autopilots take, and what they drop.

    Parameters
    ----------
    cal : Calibration
        Needs both sensors; gains must be finite and invertible.
    mag_unit : str
        ``"G"`` (PX4) or ``"mG"`` (ArduPilot).

    Returns
    -------
    AutopilotCalibration

    Raises
    ------
    InputError
        A sensor is missing, a unit cannot be converted, or the magnetometer's axes are
        mirrored (no symmetric positive matrix can hold that).
    ValueError
        A gain that no target can represent (from :func:`.common.corrections`).
    """
    corrections(cal)  # refuse a singular or non-finite gain first, in its own words
    if cal.accel is None or cal.mag is None:
        raise InputError(
            "cannot export: an autopilot's parameters need both the accelerometer and the "
            "magnetometer; calibrate both (a joint calibration)"
        )
    cm, ca = mag_factor(cal, mag_unit), accel_factor(cal)
    P_m, U_m = _polar(np.asarray(cal.mag.gain, dtype=float))
    P_a, U_a = _polar(np.asarray(cal.accel.gain, dtype=float))
    if np.linalg.det(U_m) < 0 or np.linalg.det(U_a) < 0:
        folded = cal.options.get("mag_axes")
        if folded:
            # the map is already in the calibration: advising --mag-axes would contradict it
            raise InputError(
                f"cannot export: with the axis map {folded} folded in, the magnetometer's axes "
                "are still mirrored relative to the accelerometer's, which an autopilot's "
                "symmetric matrix cannot hold; check the map (one axis sign is likely wrong) "
                "and calibrate again"
            )
        raise InputError(
            "cannot export: the magnetometer's axes are mirrored relative to the accelerometer's; "
            "an autopilot's symmetric matrix cannot hold that: set the compass orientation "
            "parameter, or calibrate with --mag-axes so the map is folded in"
        )
    M = cm * np.linalg.inv(P_m)
    M = 0.5 * (M + M.T)  # symmetric to the last bit, as the target stores one off-diagonal
    d = np.diag(P_a)
    # E maps a unit specific force (accelerometer-symmetric frame) to the per-axis error
    E = P_a / d[:, None] - np.eye(3)
    g = cal.gravity_norm or 1.0
    return AutopilotCalibration(
        mag_matrix=M,
        mag_bias=np.asarray(cal.mag.bias, dtype=float),
        accel_scale=ca / d,
        accel_bias=np.asarray(cal.accel.bias, dtype=float),
        mag_factor=cm,
        accel_factor=ca,
        misalignment_deg=float(rotation_angle_deg(U_m @ U_a.T)),
        accel_error_bound=float(np.linalg.norm(E, 2) * ca * g),
    )


def parameters(
    ap: AutopilotCalibration, mag_offset: Array, names: tuple[str, str, str, str, str]
) -> list[tuple[str, float]]:
    """The fifteen parameters both autopilots take, in the order both files write them.

    ``names`` are the templates (``{}`` for the axis X, Y, Z) of the compass offset
    (``mag_offset``), the compass matrix's diagonal, its off-diagonal at (0,1), (0,2), (1,2),
    the accelerometer offset (``accel_bias``) and its per-axis scale.
    """
    M = ap.mag_matrix
    groups = (mag_offset, np.diag(M), M[[0, 0, 1], [1, 2, 2]], ap.accel_bias, ap.accel_scale)
    return [
        (name.format(axis), float(values[i]))
        for name, values in zip(names, groups, strict=True)
        for i, axis in enumerate("XYZ")
    ]


def accel_error_text(ap: AutopilotCalibration) -> str:
    """The stated bound of the per-axis accelerometer, as both files write it."""
    bound = ap.accel_error_bound
    return (
        f"error up to {bound:.6g} m/s² at 1 g ({100 * bound / STANDARD_GRAVITY:.4g} % of g), "
        "any direction."
    )


@dataclass(frozen=True)
class ParameterRange:
    """The values an autopilot accepts for a group of parameters.

    Attributes
    ----------
    template : str
        The parameter name with ``{}`` for the axis (``"COMPASS_DIA_{}"``).
    low, high : float
        The bounds; ``None`` for no bound on that side.
    strict : bool
        Whether the bounds themselves are refused (``low < v < high``).
    source : str
        Where the firmware states it (file and function or parameter metadata).
    """

    template: str
    low: float | None
    high: float | None
    strict: bool
    source: str

    def accepts(self, value: float) -> bool:
        """Whether ``value`` is inside the range (a non-finite value never is)."""
        if not np.isfinite(value):
            return False
        if self.low is not None and (value <= self.low if self.strict else value < self.low):
            return False
        return not (
            self.high is not None and (value >= self.high if self.strict else value > self.high)
        )

    def text(self) -> str:
        """The range as the error states it: ``(0.2, 5)``, ``[-3.5, 3.5]``, ``> 0``."""
        if self.low is None:
            return f"{'<' if self.strict else '<='} {self.high:g}"
        if self.high is None:
            return f"{'>' if self.strict else '>='} {self.low:g}"
        a, b = ("(", ")") if self.strict else ("[", "]")
        return f"{a}{self.low:g}, {self.high:g}{b}"


#: The raw units each autopilot's corrections take (its drivers' output), for the refusal.
RAW_UNITS = {
    "PX4": "accelerometer m/s², magnetometer gauss",
    "ArduPilot": "accelerometer m/s², compass milligauss",
}


def _raw_units(autopilot_name: str) -> str:
    """The raw units an autopilot's drivers report (:data:`RAW_UNITS`)."""
    return RAW_UNITS.get(autopilot_name, "in the units its drivers report")


def check_ranges(
    params: list[tuple[str, float]],
    ranges: tuple[ParameterRange, ...],
    autopilot_name: str,
    *,
    allow_out_of_range: bool,
) -> dict[str, ParameterRange]:
    """The parameters outside the range the autopilot accepts.

    Parameters
    ----------
    params : list of (str, float)
        The parameters as they will be written.
    ranges : tuple of ParameterRange
        The autopilot's ranges (a parameter without one is not checked).
    autopilot_name : str
        ``"ArduPilot"`` or ``"PX4"``, for the message.
    allow_out_of_range : bool
        Write them anyway (each marked in the file); otherwise the first one is refused.

    Returns
    -------
    dict
        Name -> the range it is outside (empty when every value is accepted).

    Raises
    ------
    InputError
        A value outside its range, unless ``allow_out_of_range``: one line naming the
        parameter, its value, the range and the option.
    """
    by_name = {r.template.format(axis): r for r in ranges for axis in "XYZ"}
    outside = {
        name: by_name[name]
        for name, value in params
        if name in by_name and not by_name[name].accepts(value)
    }
    values = dict(params)
    if outside and not allow_out_of_range:
        name, rng = next(iter(outside.items()))
        more = f" (and {len(outside) - 1} more)" if len(outside) > 1 else ""
        raise InputError(
            f"cannot export: {name} = {values[name]:.6g} is outside the range "
            f"{autopilot_name} accepts, {rng.text()} ({rng.source}){more}; {autopilot_name} "
            f"corrects its drivers' raw readings, {_raw_units(autopilot_name)}: calibrate a log "
            "recorded in those units (a log in g gives accelerometer scales near 9.81, one in "
            "µT magnetometer scales near 100x off), or pass --allow-out-of-range to write it "
            "marked"
        )
    if outside:
        listed = ", ".join(f"{name} = {values[name]:.6g}" for name in outside)
        warnings.warn(
            f"wrote {len(outside)} value(s) outside the range {autopilot_name} accepts, each "
            f"marked in the file (--allow-out-of-range): {listed}",
            UserWarning,
            stacklevel=2,
        )
    return outside


def parameter_lines(
    params: list[tuple[str, float]],
    outside: dict[str, ParameterRange],
    line: Callable[[str, float], str],
) -> list[str]:
    """The parameter lines, each one outside its range preceded by a marking comment."""
    out: list[str] = []
    for name, value in params:
        if name in outside:
            rng = outside[name]
            out.append(
                f"# OUT OF RANGE (--allow-out-of-range): {name} {value:.6g} is outside "
                f"{rng.text()} ({rng.source})"
            )
        out.append(line(name, value))
    return out
