"""The ``ardupilot`` export: a ``.parm`` file for Mission Planner or MAVProxy.

ArduPilot's corrections, as its source states them:

- compass, ``AP_Compass_Backend::correct_field`` (libraries/AP_Compass/AP_Compass_Backend.cpp,
  ArduPilot/ardupilot commit 00ed6bbc2b29f35c443b509e8e53e4d0a998067a): ``mag += offsets`` then
  ``mag = mat * mag`` with the symmetric ``mat`` of rows ``(DIA_X, ODI_X, ODI_Y)``,
  ``(ODI_X, DIA_Y, ODI_Z)``, ``(ODI_Y, ODI_Z, DIA_Z)``; the field is in milligauss.
- accelerometer, ``AP_InertialSensor_Backend::_rotate_and_correct_accel``
  (libraries/AP_InertialSensor/AP_InertialSensor_Backend.cpp): ``accel -= ACCOFFS`` then
  ``accel.x *= ACCSCAL.x`` (per axis), in m/s².

So ``COMPASS_OFS = −bias`` and ``M = c P_m⁻¹`` (the magnetometer-symmetric gauge), and the
accelerometer keeps its diagonal only; what each drops is computed by
:func:`.autopilot.autopilot` and written in the file.

Every name written is an ArduPilot parameter (``COMPASS_OFS_X`` … in AP_Compass.cpp's
``var_info``, ``INS_ACCOFFS_X``/``INS_ACCSCAL_X`` in AP_InertialSensor.cpp's). Each value is
checked against what ArduPilot accepts (:data:`RANGES`):

- ``COMPASS_OFS_*`` (mG): ``|ofs| < COMPASS_OFFS_MAX`` per axis
  (``CompassCalibrator::fit_acceptable``, libraries/AP_Compass/CompassCalibrator.cpp, commit
  015eed715961c0686bffa5c924a4600f50c8eead), with the default ``AP_COMPASS_OFFSETS_MAX_DEFAULT``
  1800 (libraries/AP_Compass/AP_Compass.cpp); the arming check ("Compass offsets too high")
  compares the offsets' length with the same maximum;
- ``COMPASS_DIA_*``: ``0.2 < dia < 5``; ``COMPASS_ODI_*``: ``|odi| < 1`` (``fit_acceptable``);
- ``INS_ACCOFFS_*`` (m/s²): ``@Range: -3.5 3.5``; ``INS_ACCSCAL_*``: ``@Range: 0.8 1.2``
  (libraries/AP_InertialSensor/AP_InertialSensor.cpp, parameter metadata; the accelerometer
  calibrator's ``AccelCalibrator::accept_result`` refuses scales outside 0.8-1.2 too).

Outside a range the export is refused in one line naming the parameter, its value and the range,
unless ``allow_out_of_range``, which writes it with a marking comment above it.
"""

from __future__ import annotations

import warnings

import numpy as np

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
from .common import comment_header, exact
from .motor_comp import ardupilot_motor, for_instance, zero_input_bias

__all__ = ["CONTENT", "FORMULA", "OFFSETS_MAX", "RANGES", "write"]

#: ``COMPASS_OFFS_MAX``'s default (mG), ``AP_COMPASS_OFFSETS_MAX_DEFAULT`` in AP_Compass.cpp.
OFFSETS_MAX = 1800.0

_FIT = "CompassCalibrator::fit_acceptable"
#: The ranges ArduPilot accepts, with where its source states them.
RANGES = (
    ParameterRange("COMPASS_OFS_{}", -OFFSETS_MAX, OFFSETS_MAX, True, f"{_FIT}, COMPASS_OFFS_MAX"),
    ParameterRange("COMPASS_DIA_{}", 0.2, 5.0, True, _FIT),
    ParameterRange("COMPASS_ODI_{}", -1.0, 1.0, True, _FIT),
    ParameterRange("INS_ACCOFFS_{}", -3.5, 3.5, False, "AP_InertialSensor.cpp @Range"),
    ParameterRange("INS_ACCSCAL_{}", 0.8, 1.2, False, "AP_InertialSensor.cpp @Range"),
    ParameterRange("COMPASS_MOT_{}", -1000.0, 1000.0, False, "AP_Compass.cpp MOT_X @Range"),
)

FORMULA = (
    "mag_mG = M * (raw + COMPASS_OFS), M = [DIA_X ODI_X ODI_Y; ODI_X DIA_Y ODI_Z; "
    "ODI_Y ODI_Z DIA_Z]; accel_mps2 = (raw - INS_ACCOFFS) .* INS_ACCSCAL"
)
CONTENT = (
    "`COMPASS_OFS_*`, `COMPASS_DIA_*`, `COMPASS_ODI_*` (mG), `INS_ACCOFFS_*`, `INS_ACCSCAL_*` "
    "(m/s²); the misalignment and cross-axis terms dropped are stated"
)


def write(cal: Calibration, *, allow_out_of_range: bool = False) -> str:
    """ArduPilot parameters, ``NAME VALUE`` per line, ``#`` comments.

    Parameters
    ----------
    cal : Calibration
        Both sensors; the magnetometer scaled to a field strength (``--field-strength``).
    allow_out_of_range : bool
        Write values outside the range ArduPilot accepts (:data:`RANGES`), each marked by a
        comment line above it; by default such a value is refused.

    Returns
    -------
    str

    Raises
    ------
    InputError
        A unit that cannot be converted, a missing sensor, mirrored magnetometer axes, a value
        outside its range (without ``allow_out_of_range``).
    """
    ap = autopilot(cal, "mG")
    names = (
        "COMPASS_OFS_{}",
        "COMPASS_DIA_{}",
        "COMPASS_ODI_{}",
        "INS_ACCOFFS_{}",
        "INS_ACCSCAL_{}",
    )
    params = parameters(ap, -zero_input_bias(cal, ap), names)
    motor, motor_lines = ardupilot_motor(cal, ap)
    params += motor
    outside = check_ranges(params, RANGES, "ArduPilot", allow_out_of_range=allow_out_of_range)
    length = float(np.linalg.norm(ap.mag_bias))
    long_offsets = not length <= OFFSETS_MAX
    if long_offsets and not allow_out_of_range:
        raise InputError(
            f"cannot export: the length of COMPASS_OFS_X/Y/Z = {length:.6g} mG exceeds "
            f"COMPASS_OFFS_MAX {OFFSETS_MAX:g} (ArduPilot's arming check: Compass offsets too "
            "high); check the calibration's units, or pass --allow-out-of-range to write it marked"
        )
    if long_offsets:
        warnings.warn(
            "wrote a value outside the range ArduPilot accepts, marked in the file "
            f"(--allow-out-of-range): the length of COMPASS_OFS_X/Y/Z = {length:.6g} mG",
            UserWarning,
            stacklevel=2,
        )
    lines = comment_header(cal, "#")
    lines += [
        f"# ArduPilot convention: {FORMULA}",
        "# (AP_Compass_Backend::correct_field,",
        "# AP_InertialSensor_Backend::_rotate_and_correct_accel)",
        f"# units: compass milligauss (fieldcal's magnetometer units x {ap.mag_factor:g}), "
        f"accelerometer m/s² (fieldcal's x {ap.accel_factor:g}).",
        "# ASSUMED: the raw readings fieldcal calibrated are what ArduPilot's drivers deliver",
        "# (compass in mG after COMPASS_ORIENT, accelerometer in m/s²), recorded with",
        "# COMPASS_OFS=0, COMPASS_DIA=1, COMPASS_ODI=0, INS_ACCOFFS=0, INS_ACCSCAL=1.",
        "# DROPPED: ArduPilot's compass matrix is symmetric, so the compass comes out in the",
        "# magnetometer's own (symmetric) frame: rotated by "
        f"{ap.misalignment_deg:.4f} deg from the accelerometer's.",
        "# DROPPED: INS_ACCSCAL is per axis, so the accelerometer's cross-axis terms are lost:",
        f"# {accel_error_text(ap)}",
        "# The gyroscope is not written: ArduPilot estimates its offsets at boot.",
        "# Checked against the ranges ArduPilot accepts (CompassCalibrator::fit_acceptable,",
        f"# COMPASS_OFFS_MAX {OFFSETS_MAX:g}, INS_ACCOFFS/INS_ACCSCAL @Range): "
        + (
            f"{len(outside) + long_offsets} OUTSIDE, written marked."
            if outside or long_offsets
            else "all inside."
        ),
    ]
    if long_offsets:
        lines.append(
            f"# OUT OF RANGE (--allow-out-of-range): the length of COMPASS_OFS_X/Y/Z, {length:.6g},"
            f" exceeds COMPASS_OFFS_MAX {OFFSETS_MAX:g}"
        )
    params, outside, instance_lines = for_instance(params, outside, cal, "ardupilot")
    lines += motor_lines + instance_lines
    lines += parameter_lines(params, outside, lambda name, value: f"{name} {exact(value)}")
    return "\n".join(lines) + "\n"
