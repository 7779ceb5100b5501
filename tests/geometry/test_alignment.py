"""The constant-angle alignment: the batched solve against the plain one-problem computation."""

import numpy as np
import pytest

from fieldcal.geometry.alignment import (
    PENCIL_BELOW,
    constant_angle,
    constant_angle_rows,
    constant_angles,
)
from fieldcal.geometry.frames import magnetic_reference
from fieldcal.geometry.rotations import random_rotations


def _directions(
    n: int, mirrored: bool, seed: int
) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Gravity and field directions of ``n`` poses seen by two sensors that differ by a fixed
    orthogonal matrix (a reflection when ``mirrored``), with a noise of 1e-4."""
    rng = np.random.default_rng(seed)
    dip = np.radians(rng.uniform(20, 70))
    R = random_rotations(n, rng)
    M = random_rotations(1, rng)[0] @ (np.diag([1.0, 1.0, -1.0]) if mirrored else np.eye(3))
    u = R @ np.array([0.0, 0.0, -1.0]) + 1e-4 * rng.standard_normal((n, 3))
    v = (R @ magnetic_reference(dip)) @ M.T + 1e-4 * rng.standard_normal((n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return u, v, dip, M


def _plain(u: np.ndarray, v: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, float]:
    """The closed form one problem at a time, as first written: SVD of the weighted rows, the
    pencil of the two smallest singular vectors (searched below PENCIL_BELOW poses), each
    member's orthogonal polar factor, the member whose angle fits best."""
    rows = constant_angle_rows(u, v) * np.sqrt(w)[:, None]
    Z = np.linalg.svd(rows)[2][-2:]
    phi = np.linspace(0.0, np.pi, 37)[:-1] if len(u) < PENCIL_BELOW else np.array([np.pi / 2])
    cand = np.cos(phi)[:, None] * Z[0] + np.sin(phi)[:, None] * Z[1]
    W, _, Vt = np.linalg.svd(cand[:, :9].reshape(-1, 3, 3))
    Q = W @ Vt
    proj = np.einsum("ni,kij,nj->kn", u, Q, v)
    c = proj @ w / w.sum()
    best = int(np.argmin(((proj - c[:, None]) ** 2) @ w))
    return Q[best], float(np.clip(c[best], -1.0, 1.0))


@pytest.mark.parametrize("n", [8, 11, 15, 40])
def test_batched_constant_angles_equal_the_plain_solve_of_each_problem(n):
    problems = [_directions(n, mirrored=k % 2 == 1, seed=10 * n + k) for k in range(4)]
    w = np.random.default_rng(n).uniform(0.5, 2.0, n)
    Q, c = constant_angles(
        np.array([p[0] for p in problems]), np.array([p[1] for p in problems]), w
    )
    for k, (u, v, dip, M) in enumerate(problems):
        Q1, c1 = _plain(u, v, w)
        # the same numbers up to the null vector's sign, which the SVD of the R factor (used
        # for tall designs) may choose otherwise: (−Q, −c) is the same solution
        same = np.sign(np.trace(Q[k] @ Q1.T))
        np.testing.assert_allclose(Q[k], same * Q1, atol=1e-12)
        assert c[k] == pytest.approx(same * c1, abs=1e-12)
        # and the simulated answer: Q = ±Mᵀ (a reflection when the sensors' difference is one)
        # with u·Qv = ∓sin(dip); below PENCIL_BELOW poses the pencil's grid of 5° limits it
        sign = np.sign(np.trace(Q[k] @ M))
        close = 0.05 if n < PENCIL_BELOW else 2e-3
        np.testing.assert_allclose(Q[k], sign * M.T, atol=close)
        assert c[k] == pytest.approx(-sign * np.sin(dip), abs=close)
        single = constant_angle(u, v, w)  # the one-problem call is the batch of one
        np.testing.assert_array_equal(single[0], constant_angles(u[None], v[None], w)[0][0])


def test_magnetic_reference_of_an_array_of_dips_is_each_dips_reference():
    dips = np.array([[-1.2, 0.0], [0.3, 1.5]])
    stacked = magnetic_reference(dips)
    assert stacked.shape == (2, 2, 3)
    for index in np.ndindex(dips.shape):
        np.testing.assert_array_equal(stacked[index], magnetic_reference(float(dips[index])))
