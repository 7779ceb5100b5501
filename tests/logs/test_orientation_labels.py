"""Orientation labels: the grid search against the N x N definition; unit directions about the
mid-range point."""

from __future__ import annotations

import numpy as np

from fieldcal.logs.orientation_labels import orientation_labels, unit_directions


def test_orientation_labels_match_the_pairwise_definition():
    """The grid search gives the labels of the N x N definition (its linear time is measured
    in benchmarks/, never asserted here)."""

    def pairwise(directions, tol_deg=3.0):
        same = np.ones((len(directions[0]),) * 2, dtype=bool)
        for d in directions:
            same &= d @ d.T > np.cos(np.radians(tol_deg))
        label = np.full(len(same), -1)
        for i in range(len(same)):
            if label[i] < 0:
                label[same[i] & (label < 0)] = i
        return np.unique(label, return_inverse=True)[1]

    rng = np.random.default_rng(0)

    def unit(x):
        return x / np.linalg.norm(x, axis=1, keepdims=True)

    centres = unit(rng.normal(size=(40, 3)))
    for n in (1, 7, 300, 1500):
        d1 = unit(centres[rng.integers(0, 40, n)] + rng.normal(0, 0.03, (n, 3)))
        d2 = np.where(rng.random((n, 1)) < 0.5, d1, unit(rng.normal(size=(n, 3))))
        for directions in ([d1], [d1, d2]):
            assert np.array_equal(orientation_labels(directions), pairwise(directions))
    spread = unit(rng.normal(size=(10_000, 3)))
    labels = orientation_labels([spread, spread])  # the grid search: no N x N matrix
    assert np.array_equal(orientation_labels([spread[:2000]] * 2), pairwise([spread[:2000]] * 2))
    assert 1000 < len(set(labels)) < 10_000  # about one per 3° cap of the sphere


def test_unit_directions_about_the_mid_range_point():
    points = np.array([[3.0, 0, 0], [-1.0, 0, 0], [1.0, 2.0, 0], [1.0, -2.0, 0], [1.0, 0, 0]])
    d = unit_directions(points)
    np.testing.assert_allclose(d[:4], [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], atol=1e-15)
    assert np.array_equal(d[4], np.zeros(3))  # the centre itself: no direction
