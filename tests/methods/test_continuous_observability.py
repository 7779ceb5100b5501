"""The continuous estimator's identifiability check: it names the rotations to add, and only
those (never "add turns about x, y, z" for a log that turns about all three)."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.errors import InputError
from fieldcal.methods.continuous import fit_continuous
from fieldcal.methods.continuous.observability import motion_advice
from fieldcal.simulation.handwave import simulate_handwave
from fieldcal.trust.continuous_motion import trust_continuous


def _fit(log, **options):
    """The estimator, judged by the registered rules (it builds no verdict itself)."""
    cols = [np.column_stack([log.columns[p + a] for a in "xyz"]) for p in "amg"]
    cal = fit_continuous(log.columns["t"], *cols, **options)
    assert cal.verdict is None and cal.findings.motion is not None
    return trust_continuous(cal)


def test_turns_about_x_and_y_only_name_z():
    cal = _fit(simulate_handwave(seed=4, seconds=60.0, axes=(1.0, 1.0, 0.0)))
    assert cal.verdict.level == "fail"
    assert "continuous_undetermined" in cal.verdict.codes
    advice = " ".join(cal.options["identifiability"]["advice"])
    assert "about z" in advice
    assert "x" not in advice.split("about")[-1]


def test_a_log_turning_about_every_axis_gets_no_advice():
    cal = _fit(simulate_handwave(seed=4, seconds=40.0))
    assert cal.options["identifiability"]["advice"] == []
    assert "continuous_undetermined" not in cal.verdict.codes
    assert not any("add turns" in r.text for r in cal.verdict.reasons)


def test_turning_about_one_axis_names_the_others():
    # turns about the body's z only: gravity traces a cone about z, nothing fixes x and y
    cal = _fit(simulate_handwave(seed=4, seconds=30.0, axes=(0.0, 0.0, 1.0)), max_iter=8)
    assert cal.verdict.level == "fail"
    texts = [r.text for r in cal.verdict.reasons if r.code == "continuous_undetermined"]
    assert any("add turns about the body's x, y axes" in t for t in texts), texts
    assert not any("x, y, z" in t for t in texts)


def test_gravity_in_one_plane_is_refused_before_the_fit():
    # a tumble about the body's x only: gravity stays in the body's y-z plane
    log = simulate_handwave(seed=4, seconds=30.0, axes=(1.0, 0.0, 0.0))
    with pytest.raises(InputError, match=r"add turns about the body's y, z axes"):
        _fit(log)


def test_a_log_that_turned_about_every_axis_is_told_which_axis_to_point():
    # the body's "up" stays within 20° of the x-y plane, while the log turned a lot about
    # every axis: the advice is to point z up and down, never "add turns about x, y, z"
    rng = np.random.default_rng(0)
    azimuth = rng.uniform(0, 2 * np.pi, 500)
    elevation = rng.uniform(-np.radians(20), np.radians(20), 500)
    up = np.column_stack(
        [
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            np.sin(elevation),
        ]
    )
    advice = motion_advice(up, np.array([2000.0, 2500.0, 1800.0]))
    assert advice is not None and "its z axis points up, then down" in advice
    assert "add turns" not in advice
    # the same log with z turned little is told to turn about z
    advice = motion_advice(up, np.array([2000.0, 2500.0, 20.0]))
    assert advice is not None and "add turns about the body's z axis" in advice
    # full coverage: nothing to add
    assert motion_advice(rng.standard_normal((500, 3)), np.array([1e3, 1e3, 1e3])) is None
