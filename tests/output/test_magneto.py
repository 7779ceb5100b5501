"""The ``magneto`` export (fieldcal.output.exports.magneto): Magneto's printout parsed back
gives the exact bias and ``A^-1 = inv(gain)`` of each sensor."""

from __future__ import annotations

import numpy as np
from _known import GYRO_GAIN, MAG_BIAS, MAG_GAIN, known_calibration

from fieldcal.output.exports import magneto


def _blocks(text: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Magneto's printout as a reader would take it: a ``[sensor]`` line, the bias line after
    ``Combined bias (b):``, three matrix rows after ``Correction ...``."""
    lines = text.splitlines()
    out = {}
    for i, line in enumerate(lines):
        if line.startswith("[") and line.endswith("]"):
            assert lines[i + 1] == "Combined bias (b):"
            bias = np.array(lines[i + 2].split(), dtype=float)
            assert lines[i + 4].startswith("Correction for combined scale factors")
            matrix = np.array([row.split() for row in lines[i + 5 : i + 8]], dtype=float)
            out[line[1:-1]] = (bias, matrix)
    return out


def test_blocks_read_back_exactly():
    cal = known_calibration(gyro=True)
    blocks = _blocks(magneto.write(cal))
    assert list(blocks) == ["accelerometer", "magnetometer", "gyroscope"]
    bias, A_inv = blocks["magnetometer"]
    assert np.array_equal(bias, MAG_BIAS)
    assert np.array_equal(A_inv, np.linalg.inv(MAG_GAIN))  # exact doubles
    assert np.array_equal(blocks["gyroscope"][1], np.linalg.inv(GYRO_GAIN))


def test_applying_the_printout_gives_the_calibrated_field():
    cal = known_calibration()
    bias, A_inv = _blocks(magneto.write(cal))["magnetometer"]
    h = np.random.default_rng(5).normal(size=(50, 3))
    raw = h @ MAG_GAIN.T + MAG_BIAS
    np.testing.assert_allclose((raw - bias) @ A_inv.T, cal.correct_mag(raw), rtol=1e-12)
    np.testing.assert_allclose((raw - bias) @ A_inv.T, h, rtol=1e-9, atol=1e-12)
