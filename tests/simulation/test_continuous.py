"""A synthetic continuous log (fieldcal.simulation.continuous): each pose's rows are the
session's samples unchanged, the gyroscope's rates between poses integrate to the turn from one
pose to the next, and a seed gives the same log."""

from __future__ import annotations

import numpy as np

from fieldcal.geometry.rotations import exp_so3, log_so3
from fieldcal.simulation.continuous import simulate_continuous


def _columns(log, prefix):
    return np.column_stack([log.columns[prefix + axis] for axis in "xyz"])


def test_still_rows_are_the_sessions_samples():
    log = simulate_continuous(seed=4, n_poses=5)
    accel, mag = _columns(log, "a"), _columns(log, "m")
    assert len(log.segments) == 5
    for i, (start, stop) in enumerate(log.segments):
        np.testing.assert_array_equal(accel[start:stop], log.session.accel[i])
        np.testing.assert_array_equal(mag[start:stop], log.session.mag[i])
    t = log.columns["t"]
    np.testing.assert_allclose(np.diff(t), 1 / log.rate)
    starts = [s for s, _ in log.segments]
    assert starts == sorted(starts) and log.segments[-1][1] == len(t)


def test_the_gyroscope_integrates_to_the_turn_between_poses():
    log = simulate_continuous(seed=5, n_poses=4, ideal_gyro=True, gyro_noise=0.0)
    rates = _columns(log, "g")
    R = np.asarray(log.session.drawn["rotations"])
    for i in range(3):
        _, stop = log.segments[i]
        start_next, _ = log.segments[i + 1]
        assert np.all(rates[stop - 1] == 0)  # still: no rate (ideal gyroscope, no noise)
        # dR/dt = −[ω]× R: step the rotation by each sample's rate over 1/rate
        Rk = R[i]
        for w in rates[stop:start_next]:
            Rk = exp_so3(-w / log.rate) @ Rk
        angle = np.degrees(np.linalg.norm(log_so3(Rk @ R[i + 1].T)))
        assert angle < 0.01, angle  # turns of 60-110°; the rates sampled at mid-steps


def test_a_seed_gives_the_same_log_and_the_gyroscope_stream_is_its_own():
    a = simulate_continuous(seed=6, n_poses=3)
    b = simulate_continuous(seed=6, n_poses=3)
    for name in a.columns:
        np.testing.assert_array_equal(a.columns[name], b.columns[name])
    ideal = simulate_continuous(seed=6, n_poses=3, ideal_gyro=True)
    np.testing.assert_array_equal(ideal.columns["ax"], a.columns["ax"])  # other columns unchanged
    assert not np.array_equal(ideal.columns["gx"], a.columns["gx"])
    assert a.gyro_truth is not None and a.gyro_truth.frame == "gauge"
