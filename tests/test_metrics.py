"""δ of Eq. 19 against a hand computation."""

import numpy as np
import pytest

from fieldcal.metrics import reconstruction_error


def test_reconstruction_error_known_values():
    cov = np.diag([4.0, 1.0, 1.0])
    true = np.zeros((2, 3))
    # pose 0 off by 2 along x (one σ), pose 1 exact; weights 3 and 1
    predicted = np.array([[2.0, 0, 0], [0, 0, 0]])
    assert reconstruction_error(true, predicted, cov, [3, 1]) == pytest.approx(np.sqrt(3 / 4))
    assert reconstruction_error(true, true, cov, [3, 1]) == 0.0


def test_reconstruction_error_is_invariant_to_units():
    rng = np.random.default_rng(0)
    true, pred = rng.normal(size=(2, 10, 3))
    cov = np.diag([0.1, 0.2, 0.3])
    counts = rng.integers(1, 9, 10)
    d = reconstruction_error(true, pred, cov, counts)
    assert reconstruction_error(1e3 * true, 1e3 * pred, 1e6 * cov, counts) == pytest.approx(d)


def test_reconstruction_error_rejects_mismatched_shapes():
    with pytest.raises(ValueError, match="must both be"):
        reconstruction_error(np.zeros((3, 3)), np.zeros((4, 3)), np.eye(3), [1, 1, 1])
    with pytest.raises(ValueError, match="counts"):
        reconstruction_error(np.zeros((3, 3)), np.zeros((3, 3)), np.eye(3), [1, 1])
