"""The ``px4`` export: a QGroundControl parameter file (``.params``) for PX4.

PX4's corrections, as its source states them (PX4/PX4-Autopilot):

- magnetometer, ``calibration::Magnetometer::Correct`` (src/lib/sensor_calibration/
  Magnetometer.hpp, commit 021ee44aee5357b60f166f8e3cc1ed1c3f0b223f):
  ``_rotation * (_scale * (data - _offset))`` (power compensation left at zero), where
  ``ParametersUpdate`` (Magnetometer.cpp, commit 033e9cee3625392e07633088a3ebeb245a9f1dd4)
  builds the symmetric ``_scale`` from ``CAL_MAGn_{X,Y,Z}SCALE`` on the diagonal and
  ``CAL_MAGn_{X,Y,Z}ODIAG`` at (0,1), (0,2), (1,2); the field is in gauss.
- accelerometer, ``calibration::Accelerometer::Correct`` (src/lib/sensor_calibration/
  Accelerometer.hpp, commit 011a4138d02cad755392d73825879e5b90cec1e0):
  ``_rotation * (data - _thermal_offset - _offset).emult(_scale)``, in m/s².

``CAL_MAG0_*OFF = bias`` and the scale matrix is ``c P_m⁻¹`` (the magnetometer-symmetric gauge);
the accelerometer keeps its diagonal only (:func:`.autopilot.autopilot` computes what each
drops, written in the file). ``_rotation`` is the board/sensor rotation, left to the user.

Every name written is a PX4 parameter (src/modules/sensors/sensor_params_mag0.c and
sensor_params_acc0.c define ``CAL_MAG0_XOFF`` … ``CAL_MAG0_ZODIAG`` and ``CAL_ACC0_XOFF`` …
``CAL_ACC0_ZSCALE``, all floats). PX4's parameter definitions state no range for them and its
driver library takes any finite value; its magnetometer calibration
(``check_calibration_result``, src/modules/commander/mag_calibration.cpp) refuses a
non-positive scale and flags offsets longer than ``MAG_MAX_OFFSET_LEN`` = 1.3 G ("the mag will
saturate in some directions"). Those are checked here (:data:`RANGES`); where PX4 states no
bound, plausibility bounds as strict as ArduPilot's for the same quantity are: magnetometer
scales (0.2, 5) and off-diagonals (-1, 1) (ArduPilot's ``CompassCalibrator::fit_acceptable``),
accelerometer scales [0.5, 2] (a log in g comes out near 9.81, one in mg near 0.0098) and
accelerometer offsets within a ±16 g sensor's full scale. A refusal names the raw units PX4's
corrections take (m/s², gauss).

Temperature terms (``docs/methods/temperature.md``), when the calibration has them, become PX4's
thermal compensation parameters (src/modules/temperature_compensation/: the parameter names in
``TemperatureCompensation.cpp``, ``initialize_parameter_handles``, and ``temp_comp_params_*``;
the evaluation in ``TemperatureCompensation::calc_thermal_offsets_3D``, commit
b8ad9bdbe5adcf6d6b8bbc78f0ab3f6ad895cc7a): per axis ``i``, ``offset = X0 + X1 d + X2 d² + X3 d³``
with ``d = T − TREF`` and ``T`` clipped to ``[TMIN, TMAX]``, and the driver library subtracts it
from the raw reading together with the ``CAL_*`` offset (``Accelerometer::Correct``:
``data - _thermal_offset - _offset``; ``Magnetometer::SensorCorrectionsUpdate`` takes the
magnetometer's from ``sensor_correction``). So ``TC_A0_X{k}_{i} = c_k[i]`` in raw units per K^k,
``TREF = T_ref``, ``TMIN``/``TMAX`` the span seen (fieldcal clips the same way). ``X0`` is 0 for
the accelerometer and the magnetometer, whose ``CAL_*0_*OFF`` hold the bias at ``TREF`` (as
PX4's own accelerometer thermal calibration writes it, ``temperature_calibration/accel.cpp``:
"normalise the correction to be zero at the reference temperature"); for the gyroscope, whose
offset PX4's thermal calibration keeps in ``X0`` (``gyro.cpp``), ``TC_G0_X0 = bias`` and
``CAL_GYRO0_*OFF`` must be 0. ``TC_*_ENABLE`` (int32) are set to 1. Without temperature terms
the file is the same as before, byte for byte.

The file is QGroundControl's parameter file: ``Vehicle-Id  Component-Id  Name  Value  Type``,
tab-separated; QGroundControl refuses a file whose vehicle id is not the vehicle's, so the ids
are options (``sysid``, ``compid``; 1 and 1 by default) and stated in the file.
"""

from __future__ import annotations

from ...calibration import Calibration
from ...errors import InputError
from .autopilot import (
    ParameterRange,
    accel_error_text,
    autopilot,
    check_ranges,
    parameter_lines,
    parameters,
)
from .common import NAMES, TEMPERATURE_FORMULA, comment_header, cubic, exact, temperature_terms
from .motor_comp import for_instance, px4_power, zero_input_bias

__all__ = [
    "ACCEL_FULL_SCALE",
    "CONTENT",
    "FORMULA",
    "MAG_MAX_OFFSET",
    "RANGES",
    "TC_LETTER",
    "thermal_parameters",
    "write",
]

#: ``MAG_MAX_OFFSET_LEN`` (gauss) in PX4's mag_calibration.cpp.
MAG_MAX_OFFSET = 1.3

#: The largest full scale of the MEMS accelerometers PX4 drives (±16 g: ICM-20602, ICM-42688-P,
#: BMI088 in their widest setting), m/s²: an offset beyond it cannot be a sensor's.
ACCEL_FULL_SCALE = 16 * 9.80665

_CHECK = "mag_calibration.cpp check_calibration_result"
_PLAUSIBLE = "plausibility: PX4 states no range"
#: The ranges checked: PX4's own where its source states one (the magnetometer's offsets and a
#: positive scale), else plausibility bounds as strict as ArduPilot's for the same quantity
#: (its COMPASS_DIA (0.2, 5) and COMPASS_ODI (-1, 1); an accelerometer scale in [0.5, 2], which a
#: log in g (scale 9.81) or mg fails; an accelerometer offset within the sensor's full scale).
RANGES = (
    ParameterRange("CAL_MAG0_{}OFF", -MAG_MAX_OFFSET, MAG_MAX_OFFSET, False, _CHECK),
    ParameterRange(
        "CAL_MAG0_{}SCALE",
        0.2,
        5.0,
        True,
        f"{_CHECK}: > 0; {_PLAUSIBLE}, as ArduPilot's COMPASS_DIA",
    ),
    ParameterRange(
        "CAL_MAG0_{}ODIAG", -1.0, 1.0, True, f"{_PLAUSIBLE}, as ArduPilot's COMPASS_ODI"
    ),
    ParameterRange(
        "CAL_ACC0_{}OFF",
        -ACCEL_FULL_SCALE,
        ACCEL_FULL_SCALE,
        False,
        f"{_PLAUSIBLE}; a ±16 g sensor's full scale",
    ),
    ParameterRange(
        "CAL_ACC0_{}SCALE",
        0.5,
        2.0,
        False,
        f"{_PLAUSIBLE}; a MEMS sensitivity error is a few percent",
    ),
)

FORMULA = (
    "mag_gauss = S * (raw - CAL_MAG0_OFF), S = [XSCALE XODIAG YODIAG; XODIAG YSCALE ZODIAG; "
    "YODIAG ZODIAG ZSCALE]; accel_mps2 = (raw - CAL_ACC0_OFF) .* CAL_ACC0_SCALE"
)
CONTENT = (
    "`CAL_MAG0_{X,Y,Z}OFF`, `…SCALE`, `…ODIAG` (gauss), `CAL_ACC0_{X,Y,Z}OFF`, `…SCALE` "
    "(m/s²), QGroundControl's tab-separated layout; what is dropped is stated; with temperature "
    "terms PX4's `TC_A0_*`, `TC_M0_*`, `TC_G0_*` (`X0..X3` per axis, `TREF`, `TMIN`, `TMAX`) and "
    "`TC_*_ENABLE`"
)

#: MAV_PARAM_TYPE_REAL32: every calibration parameter of PX4 is a float.
_REAL32 = 9
#: MAV_PARAM_TYPE_INT32: the ``TC_*_ENABLE`` switches.
_INT32 = 6
#: PX4's letter of each sensor in the thermal compensation's parameter names.
TC_LETTER = {"accel": "A", "mag": "M", "gyro": "G"}


def write(
    cal: Calibration, *, sysid: int = 1, compid: int = 1, allow_out_of_range: bool = False
) -> str:
    """PX4 parameters in QGroundControl's file layout.

    Parameters
    ----------
    cal : Calibration
        Both sensors; the magnetometer scaled to a field strength (``--field-strength``).
    sysid, compid : int
        The MAVLink system (vehicle) and component ids of every line, 1-255; QGroundControl
        loads the file only onto the vehicle with that id.
    allow_out_of_range : bool
        Write values outside the range PX4 accepts (:data:`RANGES`), each marked by a comment
        line above it; by default such a value is refused.

    Returns
    -------
    str

    Raises
    ------
    InputError
        A unit that cannot be converted, a missing sensor, mirrored magnetometer axes, an id
        outside 1-255, a value outside its range (without ``allow_out_of_range``).
    """
    for option, value in (("sysid", sysid), ("compid", compid)):
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 255:
            raise InputError(f"--{option} must be a MAVLink id from 1 to 255, got {value!r}")
    ap = autopilot(cal, "G")
    names = (
        "CAL_MAG0_{}OFF",
        "CAL_MAG0_{}SCALE",
        "CAL_MAG0_{}ODIAG",
        "CAL_ACC0_{}OFF",
        "CAL_ACC0_{}SCALE",
    )
    params = parameters(ap, zero_input_bias(cal, ap), names)
    power, power_lines = px4_power(cal)
    params += power
    outside = check_ranges(params, RANGES, "PX4", allow_out_of_range=allow_out_of_range)
    lines = comment_header(cal, "#")
    lines += [
        f"# PX4 convention: {FORMULA}",
        "# (calibration::Magnetometer::Correct and Accelerometer::Correct, then CAL_*_ROT)",
        f"# units: magnetometer gauss (fieldcal's magnetometer units x {ap.mag_factor:g}), "
        f"accelerometer m/s² (fieldcal's x {ap.accel_factor:g}).",
        "# ASSUMED: the raw readings fieldcal calibrated are what PX4's drivers publish (sensor",
        "# frame, gauss and m/s²) with the calibration reset (OFF 0, SCALE 1, ODIAG 0).",
        "# Set CAL_MAG0_ID / CAL_ACC0_ID to your sensors' device ids before loading.",
        "# DROPPED: PX4's scale matrix is symmetric, so the magnetometer comes out in its own",
        f"# (symmetric) frame: rotated by {ap.misalignment_deg:.4f} deg from the accelerometer's.",
        "# DROPPED: CAL_ACC0_*SCALE is per axis, so the cross-axis terms are lost:",
        f"# {accel_error_text(ap)}",
        "# Checked against what PX4 accepts (mag_calibration.cpp: |CAL_MAG0_*OFF| <= "
        f"{MAG_MAX_OFFSET:g} G, scales > 0) and plausibility (CAL_MAG0 scales (0.2, 5), "
        "ODIAG (-1, 1),",
        f"# CAL_ACC0 scales [0.5, 2], |offsets| <= {ACCEL_FULL_SCALE:.5g} m/s²): "
        + (f"{len(outside)} OUTSIDE, written marked." if outside else "all inside."),
        f"# Vehicle {sysid}, component {compid} (fieldcal export --sysid/--compid): QGroundControl",
        "# loads these lines only onto the vehicle with that system id.",
        *power_lines,
        "#",
        "# Vehicle-Id\tComponent-Id\tName\tValue\tType",
    ]
    params, outside, instance_lines = for_instance(params, outside, cal, "px4")
    lines[-2:-2] = instance_lines
    lines += parameter_lines(
        params,
        outside,
        lambda name, value: (
            f"{sysid}\t{compid}\t{name}\t{int(value)}\t{_INT32}"
            if name == "CAL_MAG_COMP_TYP"
            else f"{sysid}\t{compid}\t{name}\t{exact(value)}\t{_REAL32}"
        ),
    )
    lines += _thermal_lines(cal, sysid, compid)
    return "\n".join(lines) + "\n"


def thermal_parameters(cal: Calibration) -> list[tuple[str, float]]:
    """PX4's thermal compensation parameters of the sensors with temperature terms (see the
    module docstring): ``TC_{A,M,G}0_X{k}_{axis}`` for k = 0..3, ``TREF``, ``TMIN``, ``TMAX``
    per sensor; empty without temperature terms. The ``TC_*_ENABLE`` switches are not in the
    list (:func:`write` adds them, as int32).

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    list of (str, float)
    """
    out: list[tuple[str, float]] = []
    for name, model in temperature_terms(cal):
        tag = f"TC_{TC_LETTER[name]}0"
        x0 = cal.sensor(name).bias if name == "gyro" else [0.0, 0.0, 0.0]
        rows = [x0, *cubic(model)]
        out += [(f"{tag}_X{k}_{i}", float(rows[k][i])) for k in range(4) for i in range(3)]
        low, high = (float(t) for t in model.span)
        out += [(f"{tag}_TREF", model.reference), (f"{tag}_TMIN", low), (f"{tag}_TMAX", high)]
    return out


def _thermal_lines(cal: Calibration, sysid: int, compid: int) -> list[str]:
    """The thermal compensation's comment and parameter lines (none without terms)."""
    terms = temperature_terms(cal)
    if not terms:
        return []
    names = ", ".join(NAMES[name] for name, _ in terms)
    lines = [
        "#",
        f"# Temperature compensation ({names}), fieldcal's",
        f"#   {TEMPERATURE_FORMULA};",
        "# PX4 (TemperatureCompensation::calc_thermal_offsets_3D, then *::Correct):",
        "#   thermal_offset = X0 + X1*d + X2*d^2 + X3*d^3, d = clip(T, TMIN, TMAX) - TREF,",
        "#   subtracted from the raw reading with CAL_*_OFF. X1..X3 are fieldcal's c1..c3 (raw",
        "# units per K^k), TREF its T_ref, TMIN/TMAX the temperatures seen (deg C, the die",
        "# temperature the driver reports). X0 is 0 where CAL_*0_*OFF holds the bias at TREF.",
    ]
    if any(name == "gyro" for name, _ in terms):
        lines += [
            "# Gyroscope: TC_G0_X0 holds its bias at TREF (raw units, taken as rad/s): set",
            "# CAL_GYRO0_XOFF/YOFF/ZOFF to 0. Its scale and misalignment are not PX4 parameters.",
        ]
    if any(name == "mag" for name, _ in terms):
        lines.append(
            "# TC_M_* needs PX4 1.15 or later (no magnetometer thermal compensation before)."
        )
    ids = ", ".join(f"TC_{TC_LETTER[name]}0_ID" for name, _ in terms)
    lines.append(f"# Set {ids} to the sensors' device ids (as CAL_*_ID) before loading.")
    lines += [f"{sysid}\t{compid}\tTC_{TC_LETTER[n]}_ENABLE\t1\t{_INT32}" for n, _ in terms]
    lines += [
        f"{sysid}\t{compid}\t{name}\t{exact(value)}\t{_REAL32}"
        for name, value in thermal_parameters(cal)
    ]
    return lines
