"""Calibration exports in the conventions other tools and firmware use, each stated in the text.

fieldcal's correction is ``v = inv(gain) @ (raw − bias)`` on column vectors. The same numbers
are written as

- ``c-header``: ``float FIELDCAL_<S>_BIAS[3]`` and ``float FIELDCAL_<S>_MATRIX[3][3]`` (row major,
  ``MATRIX = inv(gain)``) with ``out[i] = Σ_j MATRIX[i][j] * (raw[j] − BIAS[j])``;
- ``matlab``: magcal's ``C = (D - b) * A`` with row vectors, so ``A = inv(gain).'`` and ``b`` a
  1x3 row;
- ``magneto``: Magneto's ``h_cal = A⁻¹ (h − b)`` on column vectors, printed in its layout
  ("Combined bias (b)", "Correction for combined scale factors, misalignments and soft iron
  (A^-1)"), so ``A⁻¹ = inv(gain)``;
- ``json``: the full :class:`~fieldcal.model.Calibration` document.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..calibration import Calibration

__all__ = ["FORMATS", "export"]

FORMATS = ("c-header", "matlab", "magneto", "json")
_NAMES = {"accel": "accelerometer", "mag": "magnetometer"}


def _sensors(cal: Calibration) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(name, correction matrix inv(gain), bias) for each calibrated sensor."""
    out = []
    for name in ("accel", "mag"):
        sensor = getattr(cal, name)
        if sensor is not None:
            out.append((name, np.linalg.inv(sensor.gain), np.asarray(sensor.bias)))
    return out


def _num(x: float) -> str:
    """9 significant digits: every float32 exactly (the C header's type)."""
    return f"{float(x):.9g}"


def _floats(values: np.ndarray) -> str:
    """C float literals, comma separated."""
    return ", ".join(_num(v) + "f" for v in values)


def _exact(x: float) -> str:
    """The shortest text that reads back as the same double (MATLAB, Magneto)."""
    return repr(float(x))


def _provenance(cal: Calibration) -> list[str]:
    lines = [f"fieldcal {cal.version}, method {cal.method}, created {cal.created}"]
    units = cal.units or {}
    lines.append(
        f"calibrated units: accelerometer {units.get('accel_calibrated', '?')}, "
        f"magnetometer {units.get('mag_calibrated', '?')}"
    )
    if cal.options.get("mag_axes"):
        lines.append(
            f"the magnetometer axis map {cal.options['mag_axes']} is folded in: apply to the raw "
            "columns as logged"
        )
    return lines


def c_header(cal: Calibration) -> str:
    """A C header with ``static const float`` arrays and the formula in a comment."""
    lines = ["/* Sensor calibration written by fieldcal."]
    lines += [f" * {text}" for text in _provenance(cal)]
    lines += [
        " *",
        " * Apply to each raw reading (x, y, z as logged):",
        " *   for (i = 0; i < 3; i++)",
        " *     out[i] = M[i][0] * (raw[0] - B[0]) + M[i][1] * (raw[1] - B[1])",
        " *            + M[i][2] * (raw[2] - B[2]);",
        " * with M = FIELDCAL_<SENSOR>_MATRIX = inv(gain) (row major) and",
        " * B = FIELDCAL_<SENSOR>_BIAS, i.e. out = inv(gain) * (raw - bias).",
        " * Both sensors' outputs are in one common body frame.",
        " */",
        "#ifndef FIELDCAL_CALIBRATION_H",
        "#define FIELDCAL_CALIBRATION_H",
        "",
    ]
    for name, M, b in _sensors(cal):
        tag = name.upper()
        lines.append(f"/* {_NAMES[name]} */")
        lines.append(f"static const float FIELDCAL_{tag}_BIAS[3] = {{{_floats(b)}}};")
        rows = ",\n    ".join("{" + _floats(row) + "}" for row in M)
        lines.append(f"static const float FIELDCAL_{tag}_MATRIX[3][3] = {{\n    {rows}\n}};")
        lines.append("")
    lines += [
        "static inline void fieldcal_apply(const float M[3][3], const float B[3],",
        "                                  const float raw[3], float out[3]) {",
        "  const float d[3] = {raw[0] - B[0], raw[1] - B[1], raw[2] - B[2]};",
        "  for (int i = 0; i < 3; i++) out[i] = M[i][0] * d[0] + M[i][1] * d[1] + M[i][2] * d[2];",
        "}",
        "",
        "#endif /* FIELDCAL_CALIBRATION_H */",
        "",
    ]
    return "\n".join(lines)


def _matlab_matrix(M: np.ndarray) -> str:
    return "[" + "; ".join(" ".join(_exact(v) for v in row) for row in np.atleast_2d(M)) + "]"


def matlab(cal: Calibration) -> str:
    """A MATLAB script in magcal's convention ``C = (D - b) * A`` (rows of D are readings)."""
    lines = [f"% {text}" for text in ["Sensor calibration written by fieldcal.", *_provenance(cal)]]
    lines += [
        "% Convention of MATLAB's magcal: C = (D - b) * A, where D is N-by-3 (one raw reading",
        "% per row), b is 1-by-3 and A is 3-by-3; fieldcal's inv(gain) is A.' (transpose).",
    ]
    for name, M, b in _sensors(cal):
        lines.append(f"% {_NAMES[name]}")
        lines.append(f"A_{name} = {_matlab_matrix(M.T)};")
        lines.append(f"b_{name} = {_matlab_matrix(b)};")
    lines.append("% usage: C_accel = (D_accel - b_accel) * A_accel;")
    return "\n".join(lines) + "\n"


def magneto(cal: Calibration) -> str:
    """Magneto's printout: ``h_cal = A⁻¹ (h − b)`` on column vectors, one block per sensor."""
    lines = [f"# {text}" for text in ["Sensor calibration written by fieldcal.", *_provenance(cal)]]
    lines.append("# Magneto convention: h_calibrated = A^-1 * (h - b), h a column vector.")
    for name, M, b in _sensors(cal):
        lines += [
            "",
            f"[{_NAMES[name]}]",
            "Combined bias (b):",
            "  ".join(f"{_exact(v):>22}" for v in b),
        ]
        lines.append("")
        lines.append("Correction for combined scale factors, misalignments and soft iron (A^-1):")
        lines += ["  ".join(f"{_exact(v):>22}" for v in row) for row in M]
    return "\n".join(lines) + "\n"


def export(cal: Calibration, fmt: str) -> str:
    """The calibration as text in format ``fmt`` (one of :data:`FORMATS`)."""
    if fmt == "c-header":
        return c_header(cal)
    if fmt == "matlab":
        return matlab(cal)
    if fmt == "magneto":
        return magneto(cal)
    if fmt == "json":
        return cal.to_json()
    raise InputError(f"unknown export format {fmt!r}; choose one of {', '.join(FORMATS)}")
