"""The continuous fit's rounds (:mod:`fieldcal.methods.continuous.rounds`): the progress lines."""

from __future__ import annotations

import numpy as np

from fieldcal.methods.continuous import fit_continuous, rounds
from fieldcal.simulation.handheld import simulate_handheld


def _fit(log, **options):
    c = log.columns
    cols = [np.column_stack([c[p + a] for a in "xyz"]) for p in "amg"]
    return fit_continuous(c["t"], *cols, gravity=log.gravity, **options)


def test_progress_says_the_iteration_and_round():
    """``on_progress`` hears the knots, the round and the iteration as fractions."""
    heard: list[str] = []
    _fit(
        simulate_handheld(4, seconds=20.0, rate=100.0, internal_rate=200.0),
        on_progress=heard.append,
    )
    assert any("round 1/3, iteration 1/50" in line for line in heard), heard
    assert any("knots" in line for line in heard)
    assert any("error bars" in line for line in heard)


def test_progress_estimates_the_time_left(monkeypatch):
    """After a round of 10 iterations at 1 s each, the next round's first iteration says 10 s
    left for it (the mean round) and the settling round's 10; lines within
    :data:`~fieldcal.methods.continuous.rounds.PROGRESS_SECONDS` of the last are held back."""
    clock = [0.0]
    monkeypatch.setattr(rounds.time_module, "monotonic", lambda: clock[0])
    heard: list[str] = []
    progress = rounds.Progress(heard.append, knots=100, max_iter=50)
    progress.round(0, 2)
    for i in range(10):
        progress.iteration(i)
        clock[0] += 1.0
    progress.iteration(10)  # the round's last linearisation: done 10
    progress.round(1, 2)
    progress.iteration(0)
    assert heard[0] == "continuous fit (100 knots): round 1/3, iteration 1/50"
    assert len(heard) == 12
    # 10 iterations in 10 s; rounds of 10 / 2 = 5 on average: 5 left in this one, 5 after
    assert heard[-1].endswith("round 2/3, iteration 1/50, about 10 s left"), heard[-1]
    clock[0] += 0.1
    progress.iteration(1)
    assert len(heard) == 12
