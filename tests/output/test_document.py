"""The ``json`` export (fieldcal.output.exports.document): the calibration document, read
back by ``Calibration.from_json`` and by the json module as the same numbers."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from _known import ACCEL_GAIN, MAG_BIAS, known_calibration

from fieldcal.calibration import Calibration
from fieldcal.output.exports import document


def test_round_trip_gives_the_same_calibration():
    cal = known_calibration(gyro=True, rate=100.0)
    text = document.write(cal)
    assert text.endswith("}\n")
    back = Calibration.from_json(text)
    assert back == cal
    np.testing.assert_array_equal(back.accel.gain, ACCEL_GAIN)
    np.testing.assert_array_equal(back.gyro.bias, cal.gyro.bias)


def test_the_document_holds_the_numbers_for_any_json_reader():
    doc = json.loads(document.write(known_calibration()))
    assert doc["mag"]["bias"] == MAG_BIAS.tolist()
    assert document.FORMULA in json.dumps(doc)


def test_a_singular_gain_is_refused_as_by_every_export():
    cal = known_calibration()
    bad = dataclasses.replace(cal, accel=dataclasses.replace(cal.accel, gain=np.zeros((3, 3))))
    with pytest.raises(ValueError, match="accelerometer's gain is singular"):
        document.write(bad)
