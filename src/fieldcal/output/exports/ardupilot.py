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
"""

from __future__ import annotations

from ...calibration import Calibration
from .autopilot import accel_error_text, autopilot, parameters
from .common import comment_header, exact

__all__ = ["CONTENT", "FORMULA", "write"]

FORMULA = (
    "mag_mG = M * (raw + COMPASS_OFS), M = [DIA_X ODI_X ODI_Y; ODI_X DIA_Y ODI_Z; "
    "ODI_Y ODI_Z DIA_Z]; accel_mps2 = (raw - INS_ACCOFFS) .* INS_ACCSCAL"
)
CONTENT = (
    "`COMPASS_OFS_*`, `COMPASS_DIA_*`, `COMPASS_ODI_*` (mG), `INS_ACCOFFS_*`, `INS_ACCSCAL_*` "
    "(m/s²); the misalignment and cross-axis terms dropped are stated"
)


def write(cal: Calibration) -> str:
    """ArduPilot parameters, ``NAME VALUE`` per line, ``#`` comments.

    Parameters
    ----------
    cal : Calibration
        Both sensors; the magnetometer scaled to a field strength (``--field-strength``).

    Returns
    -------
    str

    Raises
    ------
    InputError
        A unit that cannot be converted, a missing sensor, mirrored magnetometer axes.
    """
    ap = autopilot(cal, "mG")
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
    ]
    names = (
        "COMPASS_OFS_{}",
        "COMPASS_DIA_{}",
        "COMPASS_ODI_{}",
        "INS_ACCOFFS_{}",
        "INS_ACCSCAL_{}",
    )
    lines += [f"{name} {exact(value)}" for name, value in parameters(ap, -ap.mag_bias, names)]
    return "\n".join(lines) + "\n"
