"""The magnetometer's interference term (:mod:`fieldcal.interference`) as each autopilot's
motor compensation, with the units and signs its firmware applies them in.

- ArduPilot, ``AP_Compass_Backend::correct_field`` (libraries/AP_Compass/AP_Compass_Backend.cpp):
  ``mag += offsets; mag = mat * mag; ... state.motor_offset = mot * current`` (``COMPASS_MOTCT``
  2; ``mot * _compass._thr`` for 1, throttle 0–1) and ``mag += state.motor_offset``: the
  compensation is *added after* the soft-iron matrix, in milligauss per amp
  (``COMPASS_MOT_X``: "@Units: mGauss/A", "@Range: -1000 1000", AP_Compass.cpp ``var_info``).
  fieldcal's term is ``raw − c (u − ū)`` before the matrix, so ``COMPASS_MOT = −M c`` and
  the offsets hold at zero current: ``COMPASS_OFS = −(bias − c ū)``.
- PX4, ``VehicleMagnetometer::UpdatePowerCompensation`` (src/modules/sensors/
  vehicle_magnetometer/VehicleMagnetometer.cpp): ``power = bat_stat.current_a * 0.001f;
  // current in [kA]`` (``CAL_MAG_COMP_TYP`` 2: battery 0, 3: battery 1; 1: throttle,
  ``actuator_controls_0`` ``control[3]``), and ``calibration::Magnetometer::Correct``:
  ``_rotation * (_scale * ((data + _power * _power_compensation) - _offset))``: added to the
  raw reading before the offset, per kA. So ``CAL_MAGn_XCOMP = −1000 c`` (raw units, taken as
  gauss, per kA; ``−c`` per full throttle) and ``CAL_MAGn_XOFF = bias − c ū``.

A term the log did not identify, or a temperature row, is not written (the file says so).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ...calibration import Calibration
from ...interference import InterferenceModel
from .autopilot import AutopilotCalibration, ParameterRange

__all__ = ["ardupilot_motor", "for_instance", "px4_power", "zero_input_bias"]

Array = NDArray[np.float64]


def _usable(cal: Calibration) -> InterferenceModel | None:
    model = None if cal.mag is None else cal.mag.interference
    if model is None or not model.identifiable or model.inputs[0] == "temperature":
        return None
    return model


def zero_input_bias(cal: Calibration, ap: AutopilotCalibration) -> Array:
    """The magnetometer bias (raw units) at zero current or throttle: where the autopilots'
    offsets hold (the calibration's bias holds at the log's mean input)."""
    model = _usable(cal)
    return ap.mag_bias if model is None else ap.mag_bias - model.at_zero()


def _skipped(cal: Calibration, comment: str) -> list[str]:
    model = None if cal.mag is None else cal.mag.interference
    if model is None:
        return []
    why = model.reason if not model.identifiable else "only a temperature term was fitted"
    return [f"{comment} Motor compensation not written: {why}."]


def ardupilot_motor(
    cal: Calibration, ap: AutopilotCalibration, suffix: str = ""
) -> tuple[list[tuple[str, float]], list[str]]:
    """``COMPASS_MOT{suffix}_X/Y/Z`` (mG per A, or per full throttle) and ``COMPASS_MOTCT``;
    the comment lines. Empty without an identified term."""
    model = _usable(cal)
    if model is None:
        return [], _skipped(cal, "#")
    mot = -ap.mag_matrix @ model.coefficients[0]
    kind = 2.0 if model.inputs[0] == "current" else 1.0
    params = [(f"COMPASS_MOT{suffix}_{a}", float(v)) for a, v in zip("XYZ", mot, strict=True)]
    unit = "mG/A" if kind == 2 else "mG at full throttle"
    lines = [
        f"# Motor compensation ({model.inputs[0]}, {unit}): correct_field adds MOT * u after",
        "# the matrix, so COMPASS_MOT = -M c and COMPASS_OFS holds at zero current:",
        f"# {100 * model.field_share:.0f} % of the field at {model.span[0, 1]:.3g} "
        f"{model.units[0]}, +/- {_relative(model):.2g} (1 sigma, relative).",
    ]
    return [*params, ("COMPASS_MOTCT", kind)], lines


def px4_power(cal: Calibration, instance: int = 0) -> tuple[list[tuple[str, float]], list[str]]:
    """``CAL_MAG{instance}_X/Y/ZCOMP`` (raw units per kA, or per full throttle) and
    ``CAL_MAG_COMP_TYP``; the comment lines. Empty without an identified term."""
    model = _usable(cal)
    if model is None:
        return [], _skipped(cal, "#")
    current = model.inputs[0] == "current"
    comp = -model.coefficients[0] * (1000.0 if current else 1.0)
    params = [(f"CAL_MAG{instance}_{a}COMP", float(v)) for a, v in zip("XYZ", comp, strict=True)]
    lines = [
        "# Power compensation: Correct adds power * COMP to the raw reading before the offset,",
        "# power = current_a * 0.001 (kA) with CAL_MAG_COMP_TYP 2 (battery 0), or the throttle",
        "# with 1: CAL_MAG0_*COMP = -c per kA (per full throttle); *OFF holds at zero current.",
    ]
    return [*params, ("CAL_MAG_COMP_TYP", 2.0 if current else 1.0)], lines


def _relative(model: InterferenceModel) -> float:
    size = float(np.linalg.norm(model.coefficients[0]))
    return float(np.linalg.norm(model.std[0])) / size if size > 0 else 0.0


def for_instance(
    params: list[tuple[str, float]],
    outside: dict[str, ParameterRange],
    cal: Calibration,
    firmware: str,
) -> tuple[list[tuple[str, float]], dict[str, ParameterRange], list[str]]:
    """The compass parameters renamed for the magnetometer instance the calibration was made
    from (``cal.options["mag_instance"]``, a flight log's ``--mag N``): ArduPilot's second and
    third compasses are ``COMPASS_OFS2_X``, ``COMPASS_MOT2_X`` ... (AP_Compass.cpp
    ``var_info``), PX4's ``CAL_MAG1_XOFF`` ...; the ranges are the same for every instance."""
    instance = int(cal.options.get("mag_instance", 0) or 0)
    if instance == 0:
        return params, outside, []

    def rename(name: str) -> str:
        if firmware != "ardupilot":
            return name.replace("CAL_MAG0_", f"CAL_MAG{instance}_")
        for group in ("COMPASS_OFS_", "COMPASS_DIA_", "COMPASS_ODI_", "COMPASS_MOT_"):
            if name.startswith(group):
                return name.replace(group, f"{group[:-1]}{instance + 1}_")
        return name

    renamed = [(rename(name), value) for name, value in params]
    marked = {rename(name): rng for name, rng in outside.items()}
    return renamed, marked, [f"# Magnetometer instance {instance} (the log's --mag {instance})."]
