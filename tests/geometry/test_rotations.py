"""SO(3) tools against scipy's Rotation and against their defining properties."""

import warnings

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from fieldcal.geometry.rotations import (
    exp_so3,
    log_so3,
    ordered_products,
    project_to_so3,
    quaternion_to_matrix,
    random_rotations,
    rotation_angle_deg,
    wahba,
    wahba_pair,
)

finite = st.floats(-3.0, 3.0, allow_nan=False)


@given(arrays(float, (5, 3), elements=finite))
def test_exp_matches_scipy_and_log_inverts_it(omega):
    R = exp_so3(omega)
    np.testing.assert_allclose(R, Rotation.from_rotvec(omega).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(exp_so3(log_so3(R)), R, atol=1e-10)


def test_exp_near_identity_is_accurate():
    omega = np.array([[1e-9, -2e-9, 3e-9], [1e-5, 0, 0]])
    np.testing.assert_allclose(exp_so3(omega), Rotation.from_rotvec(omega).as_matrix(), atol=1e-15)


def test_quaternion_convention_is_scalar_first():
    q = Rotation.random(7, random_state=3).as_quat()  # scipy: scalar last
    np.testing.assert_allclose(
        quaternion_to_matrix(np.roll(q, 1, axis=-1)),
        Rotation.from_quat(q).as_matrix(),
        atol=1e-12,
    )


def test_kuffner_rotations_are_uniform():
    """Uniform on SO(3): the rotated z axis is uniform on the sphere, so each coordinate of it
    is U[-1, 1] (mean 0, variance 1/3), and the angle has density (1 - cos θ)/π."""
    R = random_rotations(40_000, np.random.default_rng(0))
    np.testing.assert_allclose(
        np.einsum("nij,nkj->nik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12
    )
    z = R[:, :, 2]
    se = np.sqrt(1 / 3 / len(z))
    assert np.all(np.abs(z.mean(axis=0)) < 4 * se)
    assert np.all(np.abs(z.var(axis=0) - 1 / 3) < 0.01)
    # E[θ] for the Haar measure is π/2 + 2/π
    theta = np.radians(rotation_angle_deg(R))
    assert abs(theta.mean() - (np.pi / 2 + 2 / np.pi)) < 0.01


def test_project_to_so3_returns_the_nearest_rotation():
    rng = np.random.default_rng(1)
    R = random_rotations(10, rng)
    noisy = R + 1e-3 * rng.standard_normal(R.shape)
    P = project_to_so3(noisy)
    np.testing.assert_allclose(np.linalg.det(P), 1.0, atol=1e-12)
    assert np.max(np.abs(P - R)) < 5e-3
    np.testing.assert_allclose(project_to_so3(R), R, atol=1e-12)


@settings(max_examples=50)
@given(st.integers(0, 2**32 - 1))
def test_wahba_recovers_the_rotation_from_two_directions(seed):
    rng = np.random.default_rng(seed)
    R = random_rotations(4, rng)
    world = rng.standard_normal((4, 2, 3))
    body = np.einsum("nij,nkj->nki", R, world)
    np.testing.assert_allclose(wahba(body, world), R, atol=1e-9)


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 1.0))
def test_wahba_of_two_directions_in_closed_form_is_the_svds(seed, noise):
    """The bisector frames' rotation is Wahba's optimum (the SVD's) to rounding, for pairs at
    any angle and observations far from any rotation's image."""
    rng = np.random.default_rng(seed)
    R = random_rotations(40, rng)
    r1, r2 = rng.normal(size=(2, 40, 3))
    b1 = np.einsum("nij,nj->ni", R, r1) + noise * rng.normal(size=(40, 3))
    b2 = np.einsum("nij,nj->ni", R, r2) + noise * rng.normal(size=(40, 3))
    b1, b2, r1, r2 = (x / np.linalg.norm(x, axis=1, keepdims=True) for x in (b1, b2, r1, r2))
    svd = wahba(np.stack([b1, b2], axis=1), np.stack([r1, r2], axis=1))
    np.testing.assert_allclose(wahba_pair(b1, b2, r1, r2), svd, atol=1e-9)


def test_wahba_of_parallel_directions_falls_back_to_the_svd():
    rng = np.random.default_rng(4)
    b1 = rng.normal(size=(5, 3))
    b1 /= np.linalg.norm(b1, axis=1, keepdims=True)
    r1 = np.array([0.0, 0.0, -1.0])
    r2 = np.array([0.6, 0.0, 0.8])
    for b2 in (b1, -b1):  # no plane: the SVD's answer (no NaN, no warning)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            got = wahba_pair(b1, b2, r1, r2)
        want = wahba(np.stack([b1, b2], axis=1), np.broadcast_to(np.stack([r1, r2]), (5, 2, 3)))
        np.testing.assert_array_equal(got, want)


def test_ordered_products_match_the_chain_one_step_at_a_time():
    # long enough for the blocked scan (blocks, their carries, a ragged tail)
    steps = exp_so3(np.random.default_rng(3).normal(scale=0.1, size=(5003, 3)))
    chained = ordered_products(steps)
    product = np.eye(3)
    for i in range(len(steps)):
        product = steps[i] @ product
        if i in (0, 31, 32, 127, 128, 4991, 4992, 5002):
            np.testing.assert_allclose(chained[i], product, atol=1e-12)
    np.testing.assert_allclose(chained[-1], product, atol=1e-12)
