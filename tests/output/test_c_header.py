"""The ``c-header`` export (fieldcal.output.exports.c_header): the arrays parsed back are the
float32 of ``inv(gain)`` and ``bias``; every C float literal reads back as its float32.
(Compiling and running the header: tests/output/test_exports.py.)"""

from __future__ import annotations

import re

import numpy as np
import pytest
from _known import ACCEL_GAIN, GYRO_BIAS, MAG_BIAS, MAG_GAIN, known_calibration
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldcal.output.exports import c_header


def _arrays(header: str) -> dict[str, np.ndarray]:
    out = {}
    for name, body in re.findall(
        r"static const float (\w+)\[3\](?:\[3\])? = \{(.*?)\};", header, re.S
    ):
        numbers = re.findall(r"[-+0-9.e]+(?=f)", body)
        out[name] = np.array(numbers, dtype=np.float32)
    return out


def test_arrays_are_the_float32_corrections():
    arrays = _arrays(c_header.write(known_calibration(gyro=True)))
    assert np.array_equal(arrays["FIELDCAL_MAG_BIAS"], MAG_BIAS.astype(np.float32))
    assert np.array_equal(
        arrays["FIELDCAL_MAG_MATRIX"], np.linalg.inv(MAG_GAIN).astype(np.float32).ravel()
    )
    assert np.array_equal(
        arrays["FIELDCAL_ACCEL_MATRIX"], np.linalg.inv(ACCEL_GAIN).astype(np.float32).ravel()
    )
    assert np.array_equal(arrays["FIELDCAL_GYRO_BIAS"], GYRO_BIAS.astype(np.float32))


def test_a_calibration_without_gyroscope_writes_no_gyroscope_array():
    header = c_header.write(known_calibration())
    assert "FIELDCAL_GYRO" not in header and "FIELDCAL_MAG_MATRIX" in header
    assert header.count("#ifndef FIELDCAL_CALIBRATION_H") == 1 and header.endswith(
        "#endif /* FIELDCAL_CALIBRATION_H */\n"
    )


@settings(max_examples=300, deadline=None)
@given(st.floats(width=32, allow_nan=False, allow_infinity=False))
def test_every_float32_is_written_as_a_literal_that_reads_back(x):
    text = c_header.c_float(x)
    assert text.endswith("f") and ("." in text)
    assert np.float32(text[:-1]) == np.float32(x)


def test_values_beyond_float32_are_refused():
    with pytest.raises(ValueError, match="a C float holds at most"):
        c_header.c_float(1e39)
    assert c_header.c_float(1e-50) in ("0.0f", "-0.0f", "0.f")
