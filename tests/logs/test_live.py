"""Still poses of a growing stream (fieldcal.logs.live): runs are due after ``every`` seconds
of new samples, a log cut before its first pose says why, a held pose is captured before it
settles, the final run is the offline answer, and the leading poses are the first ones.
(Fed line by line through a capture: tests/capture/test_live_session.py.)"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fieldcal.logs.inputs import read_log
from fieldcal.logs.live import LiveDetector, leading_poses
from fieldcal.logs.pose_finding import poses_from_log
from fieldcal.simulation.continuous import simulate_continuous


@pytest.fixture(scope="module")
def columns():
    return simulate_continuous("paper", seed=8, n_poses=5).columns


def _log(columns, stop=None):
    return read_log({k: v[:stop] for k, v in columns.items()})


def _ranges(poses):
    return [(int(e["start"]), int(e["stop"])) for e in poses.entries]


def test_a_run_is_due_after_every_seconds_of_new_samples():
    detector = LiveDetector(every=0.5, load=0.0)
    assert not detector.due(49, 100.0) and detector.due(50, 100.0)
    untimed = LiveDetector(every=0.5, load=0.0)  # no rate: at least one new sample
    assert untimed.due(1, None) and not untimed.due(0, None)
    throttled = LiveDetector(every=0.0, load=1e9)
    throttled._took = 1.0  # the last run took a second: the next waits a billion
    throttled._finished = 0.0
    assert not throttled.due(10_000, 100.0)


def test_the_final_run_is_the_offline_answer(columns):
    whole = _log(columns)
    offline = poses_from_log(whole)
    detector = LiveDetector(load=0.0)
    final = detector.update(whole, final=True)
    assert _ranges(final.poses) == _ranges(offline)
    assert final.settled == final.captured == offline.n == 5


def test_a_held_pose_is_captured_before_it_settles(columns):
    whole = _log(columns)
    offline = _ranges(poses_from_log(whole))
    detector = LiveDetector(load=0.0)
    early = detector.update(_log(columns, 5))  # five samples: no pose yet
    assert early.poses is None and early.message and early.captured == 0
    # the stream cut in the middle of the third pose, well after its start
    start, stop = offline[2]
    cut = start + (stop - start) * 3 // 4
    detector.update(_log(columns, cut))
    state = detector.update(_log(columns, cut + 1))
    assert state.settled == 2 and state.captured == 3
    assert state.still_seconds == pytest.approx(
        (cut + 1 - state.poses.entries[2]["start"]) / 100.0, abs=0.05
    )
    captured = state.captured_poses()
    assert captured is not None and len(captured.entries) == 3


def test_leading_poses_are_the_first_ones(columns):
    poses = poses_from_log(_log(columns))
    first = leading_poses(poses, 2)
    assert first.entries == poses.entries[:2]
    for a, b in zip(first.accel, poses.accel[:2], strict=True):
        np.testing.assert_array_equal(a, b)
    assert dataclasses.replace(first, entries=()).entries == ()
