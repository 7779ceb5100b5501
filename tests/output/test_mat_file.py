"""The ``mat`` export (fieldcal.output.exports.mat_file): read back by scipy.io.loadmat as
the ``matlab`` script's numbers, bit for bit, with its formula and provenance."""

from __future__ import annotations

import io

import numpy as np
import pytest
import scipy.io
from _known import MAG_BIAS, MAG_GAIN, known_calibration

from fieldcal.errors import InputError
from fieldcal.output.exports import mat_file


def test_loadmat_reads_magcals_matrices_bit_for_bit():
    cal = known_calibration(gyro=True)
    data = scipy.io.loadmat(io.BytesIO(mat_file.write_bytes(cal)))
    assert np.array_equal(data["A_mag"], np.linalg.inv(MAG_GAIN).T)
    assert np.array_equal(data["b_mag"], MAG_BIAS[None, :])
    assert data["A_gyro"].shape == (3, 3) and data["b_gyro"].shape == (1, 3)
    assert str(data["formula"][0]) == mat_file.FORMULA
    assert "Sensor calibration written by fieldcal." in str(data["provenance"][0])
    assert "temperature_formula" not in data


def test_text_output_is_refused_in_one_line():
    with pytest.raises(InputError, match=r"binary file: write it with -o FILE\.mat") as info:
        mat_file.write(known_calibration())
    assert "\n" not in str(info.value)
