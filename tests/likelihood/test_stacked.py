"""Problems stacked on a batch axis (fieldcal.likelihood.stacked): a problem's residuals,
Jacobians and steps do not depend on which problems share its stack, nor where it sits in it,
and only problems of one layout stack. (Stacked against the single model:
tests/likelihood/test_lockstep.py.)"""

from __future__ import annotations

import numpy as np
import pytest

import fieldcal
from fieldcal.likelihood import stacked
from fieldcal.likelihood.pose_model import build_problem, state_from_calibration
from fieldcal.stats.pose_stats import summarize


def _problem(seed: int, sensors: tuple[str, ...] = ("accel", "mag"), n: int = 10):
    s = fieldcal.simulate("paper", seed=seed, n_poses=n)
    stats = summarize(s.accel if "accel" in sensors else None, s.mag if "mag" in sensors else None)
    problem = build_problem(stats, sensors[0])
    rng = np.random.default_rng(seed)  # the problem's own step, wherever it is stacked
    dg = 1e-3 * rng.standard_normal(problem.n_global)
    dp = 1e-3 * rng.standard_normal((problem.n, problem.rot_dim))
    return problem, state_from_calibration(problem, s.truth), dg, dp


def _run(pairs):
    problems, states, dg, dp = zip(*pairs, strict=True)
    sp = stacked.stack(problems)
    st = stacked.stack_states(problems, states)
    basis = stacked.rotation_bases(sp, st)
    e = stacked.residuals(sp, st)
    Jp, Jg = stacked.jacobians(sp, st, basis)
    moved = stacked.apply_steps(sp, st, np.stack(dg), np.stack(dp), basis)
    return e, Jp, Jg, moved


@pytest.mark.parametrize("sensors", [("accel", "mag"), ("mag",)])
def test_a_problems_numbers_do_not_depend_on_its_stack(sensors):
    pairs = [_problem(seed, sensors) for seed in range(3)]
    alone = _run([pairs[1]])
    shuffled = _run([pairs[2], pairs[1], pairs[0]])
    np.testing.assert_allclose(shuffled[0][1], alone[0][0], rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(shuffled[1][1], alone[1][0], rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(shuffled[2][1], alone[2][0], rtol=1e-14, atol=1e-14)
    a, b = stacked.unstack_state(alone[3], 0), stacked.unstack_state(shuffled[3], 1)
    np.testing.assert_allclose(b.rotations, a.rotations, rtol=1e-14, atol=1e-14)
    for s in a.gains:
        np.testing.assert_allclose(b.gains[s], a.gains[s], rtol=1e-14, atol=1e-14)


def test_only_problems_of_one_layout_share_a_key():
    joint = [_problem(seed)[0] for seed in range(2)]
    assert stacked.layout(joint[0]) == stacked.layout(joint[1])
    others = [
        _problem(0, ("accel",))[0],
        _problem(0, ("mag",))[0],
        _problem(0, n=11)[0],
    ]
    keys = {stacked.layout(p) for p in [joint[0], *others]}
    assert len(keys) == 4
    subset = stacked.stack([joint[0], joint[1]]).take(np.array([1]))
    assert subset.size == 1
