"""The ``c-header`` export: ``static const float`` arrays and an apply function for firmware."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ...calibration import Calibration
from .common import NAMES, TEMPERATURE_FORMULA, corrections, cubic, provenance, temperature_terms

__all__ = ["CONTENT", "FORMULA", "c_float", "write"]

#: The correction as the header's comment states it (M and B are the header's arrays).
FORMULA = "out[i] = sum_j M[i][j] * (raw[j] - B[j]), M = inv(gain), B = bias"
CONTENT = (
    "`static const float FIELDCAL_ACCEL_BIAS[3]`, `FIELDCAL_ACCEL_MATRIX[3][3]` (row major), "
    "the same for `MAG` (and `GYRO`, in rad/s, when calibrated), and "
    "`fieldcal_apply(M, B, raw, out)`; for a Kalman filter each sensor's `NOISE_COV` and "
    "`RESIDUAL_COV` (calibrated units²), `FIELDCAL_GRAVITY_NED`, `FIELDCAL_MAGNETIC_NED` and, "
    "with `--location`, `FIELDCAL_DECLINATION_DEG`; with temperature terms each such sensor's "
    "`FIELDCAL_<SENSOR>_TEMP[3]` (T_ref, T_min, T_max), `FIELDCAL_<SENSOR>_TEMP_COEF[3][3]` "
    "(c1, c2, c3 per row) and `fieldcal_apply_at(M, B, TEMP, C, raw, t, out)`"
)

_FLOAT32 = np.finfo(np.float32)


def c_float(x: float) -> str:
    """A C ``float`` literal of ``x``: the shortest text that reads back as its nearest float32.

    The text always has a decimal point (``1.0f``, ``0.1f``; ``1f`` is not C) and an exponent
    outside [1e-4, 1e7) (``1.0e+30f``). A value float32 cannot hold is a ``ValueError``; one too
    small for it is written as the zero a ``float`` would hold, because compilers refuse a
    nonzero literal that truncates to zero.

    Parameters
    ----------
    x : float

    Returns
    -------
    str
    """
    if not np.isfinite(x) or abs(x) > float(_FLOAT32.max):
        raise ValueError(
            f"the c-header export cannot write {float(x)!r}: a C float holds at most "
            f"{float(_FLOAT32.max):.9g}; export in another format (matlab, magneto, json)"
        )
    f = np.float32(x)
    if f == 0 or 1e-4 <= abs(f) < 1e7:
        text = np.format_float_positional(f, unique=True, trim="0")
    else:
        text = np.format_float_scientific(f, unique=True, trim="0", exp_digits=2)
    return text + "f"


def _floats(values: NDArray[np.float64]) -> str:
    return ", ".join(c_float(v) for v in values)


def _array(name: str, values: NDArray[np.float64], comment: str) -> list[str]:
    """``static const float name[3]`` or ``[3][3]`` with its comment; a comment saying why
    instead when a float cannot hold the values (the correction itself was written)."""
    values = values + 0.0  # -0.0 as 0.0
    try:
        if values.ndim == 1:
            body = f"[3] = {{{_floats(values)}}};"
        else:
            rows = ",\n    ".join("{" + _floats(row) + "}" for row in values)
            body = f"[3][3] = {{\n    {rows}\n}};"
    except ValueError:
        return [f"/* {name}: not written, a C float cannot hold it */"]
    return [f"/* {comment} */", f"static const float {name}{body}"]


def _filter_lines(cal: Calibration) -> list[str]:
    """What a Kalman filter needs beside the corrections: noise, residual error, the fields."""
    lines: list[str] = []
    for name, M, _ in corrections(cal):
        sensor = cal.sensor(name)
        tag, unit = name.upper(), "(rad/s)^2" if name == "gyro" else "calibrated units^2"
        lines += _array(
            f"FIELDCAL_{tag}_NOISE_COV",
            M @ sensor.noise_cov @ M.T,
            f"{NAMES[name]}: noise covariance of one corrected sample, {unit} (R of a filter)",
        )
        if name != "gyro":
            lines += _array(
                f"FIELDCAL_{tag}_RESIDUAL_COV",
                sensor.pose_noise_std**2 * (M @ M.T),
                f"{NAMES[name]}: error every corrected reading keeps however long it is "
                f"averaged (pose-level noise), {unit}: add to R",
            )
    fields = (("GRAVITY", cal.gravity, "accelerometer"), ("MAGNETIC", cal.magnetic, "magnetometer"))
    for tag, vector, sensor_name in fields:
        if vector is not None:
            lines += _array(
                f"FIELDCAL_{tag}_NED",
                np.asarray(vector, dtype=float),
                f"what the corrected {sensor_name} reads at rest in the world frame "
                "(North-East-Down): v_body = R v_world",
            )
    ref = cal.field_reference
    if ref is not None:
        lines += [
            f"/* {ref.model} at {ref.place} on {ref.date}: true heading = magnetic heading + "
            "declination (east positive) */",
            f"#define FIELDCAL_DECLINATION_DEG {c_float(ref.declination_deg)}",
        ]
    return [*lines, ""]


def _temperature_lines(cal: Calibration) -> list[str]:
    """Each sensor's temperature terms and ``fieldcal_apply_at`` (nothing without terms, so the
    header is then the one a calibration without a temperature column gives)."""
    terms = temperature_terms(cal)
    if not terms:
        return []
    lines = [f"/* temperature terms: {TEMPERATURE_FORMULA} */"]
    for name, model in terms:
        tag = name.upper()
        span = np.array([model.reference, *model.span], dtype=float)
        lines += _array(
            f"FIELDCAL_{tag}_TEMP",
            span,
            f"{NAMES[name]}: T_ref, T_min, T_max (deg C, the die temperature as logged)",
        )
        lines += _array(
            f"FIELDCAL_{tag}_TEMP_COEF",
            cubic(model),
            f"{NAMES[name]}: c1, c2, c3 per row (raw units per K, K^2, K^3)",
        )
    return [
        *lines,
        "static inline void fieldcal_apply_at(const float M[3][3], const float B[3],",
        "                                     const float TEMP[3], const float C[3][3],",
        "                                     const float raw[3], float t, float out[3]) {",
        "  const float u = (t < TEMP[1] ? TEMP[1] : (t > TEMP[2] ? TEMP[2] : t)) - TEMP[0];",
        "  float b[3];",
        "  for (int j = 0; j < 3; j++) b[j] = B[j] + ((C[2][j] * u + C[1][j]) * u + C[0][j]) * u;",
        "  fieldcal_apply(M, b, raw, out);",
        "}",
        "",
    ]


def write(cal: Calibration) -> str:
    """A C header with ``static const float`` arrays and the formula in a comment.

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    str
        The header; it compiles with ``cc -std=c99 -Wall -Werror``.
    """
    lines = ["/* Sensor calibration written by fieldcal."]
    lines += [f" * {text}" for text in provenance(cal)]
    lines += [
        " *",
        " * Apply to each raw reading (x, y, z as logged):",
        f" *   {FORMULA}",
        " * with M = FIELDCAL_<SENSOR>_MATRIX (row major) and B = FIELDCAL_<SENSOR>_BIAS,",
        " * as fieldcal_apply(M, B, raw, out) below does.",
        " * Every sensor's output is in one common body frame (the gyroscope's in rad/s).",
    ]
    if temperature_terms(cal):
        lines += [
            " * With the die temperature t (deg C): fieldcal_apply_at(M, B, TEMP, C, raw, t, out),",
            " * TEMP = FIELDCAL_<SENSOR>_TEMP, C = FIELDCAL_<SENSOR>_TEMP_COEF: the bias at t.",
        ]
    lines += [
        " */",
        "#ifndef FIELDCAL_CALIBRATION_H",
        "#define FIELDCAL_CALIBRATION_H",
        "",
    ]
    for name, M, b in corrections(cal):
        tag = name.upper()
        lines.append(f"/* {NAMES[name]} */")
        lines.append(f"static const float FIELDCAL_{tag}_BIAS[3] = {{{_floats(b)}}};")
        rows = ",\n    ".join("{" + _floats(row) + "}" for row in M)
        lines.append(f"static const float FIELDCAL_{tag}_MATRIX[3][3] = {{\n    {rows}\n}};")
        lines.append("")
    lines += _filter_lines(cal)
    lines += [
        "static inline void fieldcal_apply(const float M[3][3], const float B[3],",
        "                                  const float raw[3], float out[3]) {",
        "  const float d[3] = {raw[0] - B[0], raw[1] - B[1], raw[2] - B[2]};",
        "  for (int i = 0; i < 3; i++) out[i] = M[i][0] * d[0] + M[i][1] * d[1] + M[i][2] * d[2];",
        "}",
        "",
        *_temperature_lines(cal),
        "#endif /* FIELDCAL_CALIBRATION_H */",
        "",
    ]
    return "\n".join(lines)
