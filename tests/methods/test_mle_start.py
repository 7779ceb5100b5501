"""The closed-form starts of method="mle": computed together (shared design, one batched fit per
family, steps 2-3 vectorised over the starts) they equal each start computed alone, plainly."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import fieldcal
from fieldcal.geometry.alignment import constant_angle
from fieldcal.geometry.frames import GRAVITY, magnetic_reference, twin_flip
from fieldcal.geometry.quadrics import family_design, family_fit, family_fits, spd_sqrt
from fieldcal.geometry.rotations import wahba
from fieldcal.likelihood import pose_model
from fieldcal.methods.mle import start

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from _small_sets import shots

ALL = [(a, m) for a in start.FAMILIES for m in start.FAMILIES]


def _plain_start(problem: pose_model.Problem, models: tuple[str, str]) -> pose_model.State | None:
    """One joint start as first written, one step and one sensor at a time."""
    fits = {}
    for s, family in zip(problem.sensors, models, strict=True):
        fit = family_fit(problem.start_mu[s], problem.start_weight[s], family)
        if fit is None:
            return None
        L = problem.start_chol[s]
        K = L @ fit[0]
        fits[s] = (spd_sqrt(K @ K.T)[0], L @ fit[1])
    (Ka, ba), (Km, bm) = fits["accel"], fits["mag"]
    u, vp = (
        np.linalg.solve(K, (problem.means[s] - b).T).T
        for s, K, b in (("accel", Ka, ba), ("mag", Km, bm))
    )
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    vp = vp / np.linalg.norm(vp, axis=1, keepdims=True)
    w = np.minimum(problem.start_weight["accel"], problem.start_weight["mag"])
    Q, c = constant_angle(u, vp, w)
    dip = float(np.arcsin(-c))
    body = np.stack([u, vp @ Q.T], axis=1)
    R = wahba(body, np.broadcast_to(np.stack([GRAVITY, magnetic_reference(dip)]), body.shape))
    gains = {"accel": Ka, "mag": Km @ Q.T}
    f = problem.frame
    if np.linalg.det(gains[f]) < 0:  # the exact twin
        gains[f], dip, R = -gains[f], -dip, R @ twin_flip(f)
    W, _, Vt = np.linalg.svd(gains[f])
    U = W @ Vt
    gains = {k: g @ U.T for k, g in gains.items()}
    gains[f] = 0.5 * (gains[f] + gains[f].T)
    return pose_model.State(gains, {"accel": ba, "mag": bm}, dip, U @ R)


def _problem(kind: str, seed: int) -> pose_model.Problem:
    if kind == "paper":
        s = fieldcal.simulate("paper", seed=seed)
        stats = fieldcal.summarize(s.accel, s.mag)
    else:
        stats = fieldcal.summarize(*shots(24, seed))
        stats = stats.replace(
            accel=stats.accel.with_pose_var(1e-6), mag=stats.mag.with_pose_var(1e-6)
        )
    return pose_model.build_problem(stats, "accel")


def _assert_same(a: pose_model.State, b: pose_model.State) -> None:
    # the same LAPACK routine per matrix, batched or not: equal to rounding (values of order 1)
    for k in a.gains:
        np.testing.assert_allclose(a.gains[k], b.gains[k], rtol=0, atol=1e-11)
        np.testing.assert_allclose(a.biases[k], b.biases[k], rtol=0, atol=1e-11)
    assert a.dip == pytest.approx(b.dip, abs=1e-11)
    np.testing.assert_allclose(a.rotations, b.rotations, rtol=0, atol=1e-11)


@pytest.mark.parametrize(("kind", "seed"), [("paper", 0), ("paper", 4), ("shots", 1)])
def test_starts_computed_together_equal_each_start_computed_plainly(kind, seed):
    problem = _problem(kind, seed)
    together = start.closed_form_starts(problem, ALL)
    for models, state in zip(ALL, together, strict=True):
        plain = _plain_start(problem, models)
        assert (state is None) == (plain is None)
        if state is not None and plain is not None:
            _assert_same(state, plain)
            # the rotations are rotations, the frame sensor's gain symmetric (Sec. 4.3)
            np.testing.assert_allclose(np.linalg.det(state.rotations), 1.0, atol=1e-12)
            K = state.gains[problem.frame]
            np.testing.assert_allclose(K, K.T, atol=1e-15)


def test_asking_for_one_start_computes_its_group_once_and_hands_out_copies():
    problem = _problem("paper", 2)
    first = start.closed_form_start(problem, "full")
    assert ("closed_form_start", ("axes", "axes")) in problem.memo  # its pair, computed with it
    assert ("closed_form_start", ("full", "sphere")) not in problem.memo  # the others' group: not
    assert first is not None
    first.gains["accel"][:] = 0.0  # the solver changes a start in place
    again = start.closed_form_start(problem, ("full", "full"))
    assert again is not None and np.abs(again.gains["accel"]).max() > 0.5
    mixed = start.closed_form_start(problem, ("sphere", "axes"))
    assert all(("closed_form_start", m) in problem.memo for m in ALL)  # the rest, in one batch
    fresh = _problem("paper", 2)  # another problem, nothing remembered: the same start
    alone = start.closed_form_starts(fresh, [("sphere", "axes")])[0]
    assert mixed is not None and alone is not None
    _assert_same(mixed, alone)


@pytest.mark.parametrize("sensor", ["accel", "mag"])
def test_one_sensor_starts_are_computed_by_family(sensor):
    s = fieldcal.simulate("paper", seed=3)
    stats = fieldcal.summarize(s.accel) if sensor == "accel" else fieldcal.summarize(None, s.mag)
    problem = pose_model.build_problem(stats, sensor)
    states = [start.closed_form_start(problem, family) for family in start.FAMILIES]
    assert all(state is not None for state in states)
    assert {key[1] for key in problem.memo if key[0] == "closed_form_start"} == {
        (f,) for f in start.FAMILIES
    }
    y = problem.start_mu[sensor]
    K, c, ok = family_fits(y[None], problem.start_weight[sensor][None], "full")
    assert ok[0]
    L = problem.start_chol[sensor]
    state = states[0]
    assert state is not None
    P = spd_sqrt((L @ K[0]) @ (L @ K[0]).T)[0]
    np.testing.assert_allclose(state.gains[sensor], P, atol=1e-12)
    np.testing.assert_allclose(state.biases[sensor], L @ c[0], atol=1e-12)


def test_a_shared_design_gives_the_fit_of_the_points():
    rng = np.random.default_rng(3)
    y = rng.normal(size=(2, 20, 3)) * [1.0, 1.2, 0.8] + 0.3
    w = rng.uniform(1.0, 2.0, (2, 20))
    for family in start.FAMILIES:
        own = family_fits(y, w, family)
        shared = family_fits(y, w, family, design=family_design(y, w))
        for a, b in zip(own, shared, strict=True):
            np.testing.assert_array_equal(a, b)
