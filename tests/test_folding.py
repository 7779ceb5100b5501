"""fold_axes: a calibration fitted on mapped readings ``P @ raw`` applies to the raw readings
as logged, with the covariance carried by the same linear map."""

from __future__ import annotations

import numpy as np
import pytest

import fieldcal
from fieldcal.folding import fold_axes
from fieldcal.geometry.frames import parse_axes


@pytest.fixture(scope="module")
def cal():
    s = fieldcal.simulate("paper", seed=11)
    return fieldcal.calibrate(s.accel, s.mag)


def test_an_axis_map_folded_corrects_the_raw_readings_alike(cal):
    P = parse_axes("+y-x-z")
    folded = fold_axes(cal, P, "+y-x-z")
    raw = np.random.default_rng(0).normal(size=(20, 3))
    np.testing.assert_allclose(folded.correct_mag(raw), cal.correct_mag(raw @ P.T), atol=1e-12)
    assert folded.options["mag_axes"] == "+y-x-z"
    # a permutation with signs moves the error bars, never changes their size
    np.testing.assert_allclose(np.sort(folded.mag.bias_std), np.sort(cal.mag.bias_std), rtol=1e-12)
    assert folded.accel == cal.accel


def test_a_sign_folded_twice_is_the_calibration_again(cal):
    once = fold_axes(cal, -np.eye(3), "gravity", sensor="accel")
    assert once.options["accel_sign"] == "gravity"
    np.testing.assert_allclose(once.accel.bias, -cal.accel.bias, rtol=1e-12)
    twice = fold_axes(once, -np.eye(3), "specific-force", sensor="accel")
    np.testing.assert_allclose(twice.accel.gain, cal.accel.gain, rtol=1e-12)
    np.testing.assert_allclose(twice.covariance.matrix, cal.covariance.matrix, rtol=1e-12)


def test_the_pipeline_still_exports_it():
    from fieldcal import pipeline

    assert pipeline.fold_axes is fold_axes
