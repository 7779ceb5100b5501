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
"""

from __future__ import annotations

from ...calibration import Calibration
from .autopilot import accel_error_text, autopilot, parameters
from .common import comment_header, exact

__all__ = ["CONTENT", "FORMULA", "write"]

FORMULA = (
    "mag_gauss = S * (raw - CAL_MAG0_OFF), S = [XSCALE XODIAG YODIAG; XODIAG YSCALE ZODIAG; "
    "YODIAG ZODIAG ZSCALE]; accel_mps2 = (raw - CAL_ACC0_OFF) .* CAL_ACC0_SCALE"
)
CONTENT = (
    "`CAL_MAG0_{X,Y,Z}OFF`, `…SCALE`, `…ODIAG` (gauss), `CAL_ACC0_{X,Y,Z}OFF`, `…SCALE` "
    "(m/s²), QGroundControl's tab-separated layout; what is dropped is stated"
)

#: MAV_PARAM_TYPE_REAL32: every calibration parameter of PX4 is a float.
_REAL32 = 9


def write(cal: Calibration) -> str:
    """PX4 parameters in QGroundControl's file layout (vehicle 1, component 1).

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
    ap = autopilot(cal, "G")
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
        "#",
        "# Vehicle-Id\tComponent-Id\tName\tValue\tType",
    ]
    names = (
        "CAL_MAG0_{}OFF",
        "CAL_MAG0_{}SCALE",
        "CAL_MAG0_{}ODIAG",
        "CAL_ACC0_{}OFF",
        "CAL_ACC0_{}SCALE",
    )
    params = parameters(ap, ap.mag_bias, names)
    lines += [f"1\t1\t{name}\t{exact(value)}\t{_REAL32}" for name, value in params]
    return "\n".join(lines) + "\n"
