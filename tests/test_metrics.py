"""δ of Eq. 19 against a hand computation."""

import warnings

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


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"cov": -np.eye(3)}, "positive definite"),
        ({"cov": np.eye(2)}, "symmetric 3x3"),
        ({"cov": np.array([[1.0, 0.5, 0], [0, 1, 0], [0, 0, 1]])}, "symmetric 3x3"),
        ({"cov": "x"}, "cov must be an array of numbers"),
        ({"predicted": np.full((4, 3), np.nan)}, "NaN or inf"),
        ({"predicted": np.zeros((4, 3), complex)}, "complex"),
        ({"predicted": [{"a": 1}] * 4}, "array of numbers"),
        ({"counts": [0, 0, 0, 0]}, "at least one positive"),
        ({"counts": [1, -1, 1, 1]}, "none negative"),
    ],
)
def test_reconstruction_error_refuses_what_has_no_distance(change, words):
    """Input with no Mahalanobis distance (a covariance that is not one, non-finite or complex
    means, no samples) is refused in one line naming it: never a NaN, a numpy warning or a
    LinAlgError."""
    args = {"true": np.zeros((4, 3)), "predicted": np.ones((4, 3)), "cov": np.eye(3)}
    args["counts"] = [1, 1, 1, 1]
    args.update(change)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=words) as info:
            reconstruction_error(args["true"], args["predicted"], args["cov"], args["counts"])
    assert "\n" not in str(info.value)
