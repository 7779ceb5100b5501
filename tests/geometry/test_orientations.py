"""Orientations and the words for them (fieldcal.geometry.orientations): the candidate sets,
each candidate described as itself, TRIAD against a known rotation, angles between rotations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fieldcal.errors import InputError
from fieldcal.geometry import orientations as ori

G_WORLD = np.array([0.0, 0.0, -1.0])  # specific force at rest, NED: "up"
H_WORLD = np.array([np.cos(np.radians(60)), 0.0, np.sin(np.radians(60))])


def test_the_candidate_sets_are_distinct_proper_rotations():
    joint, free = ori.candidates(), ori.candidates(heading=False)
    assert (len(joint), len(free)) == (104, 26)
    R = np.stack([c.rotation for c in joint])
    np.testing.assert_allclose(
        R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12
    )
    assert np.allclose(np.linalg.det(R), 1.0)
    for c in joint:
        np.testing.assert_allclose(c.down, c.rotation[:, 2], atol=1e-12)
    # no two candidates are the same orientation
    angles = ori.angle_deg(R[:, None], R[None, :])
    assert np.min(angles + 360 * np.eye(len(R))) > 1.0
    assert {c.kind for c in free} == {"face", "edge", "corner"}
    assert all(c.heading_deg is None for c in free)


def test_each_candidate_is_described_by_its_own_words():
    for c in ori.candidates():
        assert ori.describe(c.rotation) == c.words
    tilted = Rotation.from_euler("x", 12, degrees=True).as_matrix() @ ori.candidates()[0].rotation
    assert ori.describe(tilted).endswith("(12° away)")


def test_triad_recovers_a_known_rotation():
    for seed in range(5):
        R = Rotation.random(random_state=seed).as_matrix()
        got = ori.orientation_from_vectors(3.0 * (R @ G_WORLD), 40.0 * (R @ H_WORLD))
        np.testing.assert_allclose(got, R, atol=1e-12)
        assert float(ori.angle_deg(got, R)) < 1e-5


def test_without_a_magnetometer_heading_is_zero():
    R = ori.orientation_from_vectors([0.0, 0.0, -9.8])  # lying flat: down is body +z
    np.testing.assert_allclose(R, np.eye(3), atol=1e-15)


def test_refusals():
    with pytest.raises(InputError, match="parallel to gravity"):
        ori.orientation_from_vectors([0, 0, -1.0], [0, 0, 2.0])
    with pytest.raises(InputError, match="accel_body must be a finite, non-zero"):
        ori.orientation_from_vectors([0, 0, 0])
    with pytest.raises(InputError, match="not a proper rotation"):
        ori.describe(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(InputError, match="finite 3x3"):
        ori.describe(np.eye(2))
