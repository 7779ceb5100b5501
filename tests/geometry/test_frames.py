"""World and body frames (fieldcal.geometry.frames): the magnetic reference and its dip, the
handedness twins, polar factors, the misalignment with a known rotation, axis maps."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldcal.errors import InputError
from fieldcal.geometry import frames


def _rotation_z(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])


@settings(max_examples=100, deadline=None)
@given(st.floats(-89.0, 89.0))
def test_dip_round_trip_and_derivative(dip_deg):
    dip = np.radians(dip_deg)
    h = frames.magnetic_reference(dip)
    assert np.linalg.norm(h) == pytest.approx(1.0) and h[1] == 0.0
    assert frames.dip_of(h) == pytest.approx(dip_deg, abs=1e-9)
    step = 1e-6
    numeric = (frames.magnetic_reference(dip + step) - frames.magnetic_reference(dip - step)) / (
        2 * step
    )
    np.testing.assert_allclose(frames.magnetic_derivative(dip), numeric, atol=1e-8)


def test_batched_reference_is_the_scalar_one_per_dip():
    dips = np.radians(np.array([[-30.0, 0.0], [45.0, 70.0]]))
    batch = frames.magnetic_reference(dips)
    assert batch.shape == (2, 2, 3)
    for idx in np.ndindex(2, 2):
        np.testing.assert_array_equal(batch[idx], frames.magnetic_reference(float(dips[idx])))


@pytest.mark.parametrize("sensor", ["accel", "mag"])
def test_each_twin_negates_the_dip(sensor):
    D = frames.twin_flip(sensor)
    h = frames.magnetic_reference(np.radians(60.0))
    g = np.array([0.0, 0.0, -1.0])
    # the twin's world: the negated sensor's field negated, the other unchanged (both through D)
    if sensor == "mag":
        np.testing.assert_array_equal(D @ g, g)
        twin_h = -(D @ h)
    else:
        np.testing.assert_array_equal(D @ g, -g)
        twin_h = D @ h
    assert frames.dip_of(twin_h) == pytest.approx(-60.0)
    with pytest.raises(ValueError, match="sensor must be 'accel' or 'mag'"):
        frames.twin_flip("gyro")


def test_polar_factor_and_a_known_misalignment():
    P = np.array([[1.1, 0.05, 0.0], [0.05, 0.9, 0.02], [0.0, 0.02, 1.0]])
    R = _rotation_z(7.0)
    np.testing.assert_allclose(frames.orthogonal_polar_factor(P @ R), R, atol=1e-12)
    assert frames.misalignment_angle_deg(P, P @ R) == pytest.approx(7.0, abs=1e-9)
    # a magnetometer wired +y+x-z is not 90° off: the signed permutation is taken out
    S = frames.parse_axes("+y+x-z")
    assert frames.misalignment_angle_deg(P, S @ P @ R) == pytest.approx(7.0, abs=1e-9)
    assert np.array_equal(frames.nearest_signed_permutation(S @ R), S)
    rv = frames.misalignment_rotvec(P, P @ R, np.eye(3))
    np.testing.assert_allclose(np.degrees(rv), [0.0, 0.0, 7.0], atol=1e-9)


def test_axis_maps():
    P = frames.parse_axes(" +y+X-z ")
    np.testing.assert_array_equal(P @ np.array([1.0, 2.0, 3.0]), [2.0, 1.0, -3.0])
    np.testing.assert_array_equal(frames.parse_axes("xyz"), np.eye(3))
    with pytest.raises(InputError, match="is not three signed axes"):
        frames.parse_axes("+x+y")
    with pytest.raises(InputError, match="must use each of x, y and z once"):
        frames.parse_axes("+x+x-z")
