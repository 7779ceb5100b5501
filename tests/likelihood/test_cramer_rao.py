"""The Cramér-Rao bound's named map (fieldcal.likelihood.cramer_rao): built once per parameter
layout, the same matrix as building it for the problem at hand."""

from __future__ import annotations

import numpy as np
import pytest

import fieldcal
from fieldcal.likelihood import cramer_rao
from fieldcal.likelihood.levenberg import normal_equations
from fieldcal.likelihood.pose_model import _build_problem, residuals, state_from_calibration


def test_the_named_map_is_shared_by_problems_of_one_layout_and_equals_a_fresh_one():
    s = fieldcal.simulate("paper", seed=3)
    stats = fieldcal.summarize(s.accel, s.mag)
    first = _build_problem(stats, "accel")
    # other poses and another noise model: a new problem, the same layout
    other = _build_problem(stats.subset(np.arange(12)), "accel")
    names, T = cramer_rao.named_map(first)
    again, T2 = cramer_rao.named_map(other)
    assert T2 is T and again == names
    fresh_names, fresh = cramer_rao._named_map(other)
    assert fresh_names == names
    np.testing.assert_array_equal(fresh, T)
    # another layout (the magnetometer's gain symmetric) has its own map
    mag_frame = _build_problem(stats, "mag")
    _, T_mag = cramer_rao.named_map(mag_frame)
    np.testing.assert_array_equal(T_mag, cramer_rao._named_map(mag_frame)[1])
    assert not np.array_equal(T_mag, T)
    assert not T.flags.writeable  # shared: nobody may change it


def test_the_derived_covariance_and_condition_are_the_reduced_systems() -> None:
    """:class:`~fieldcal.likelihood.cramer_rao.Uncertainty` derives the named covariance and
    the condition number on first use: the same numbers as :func:`global_covariance` and the
    named map give (``T C Tᵀ``), computed once."""
    s = fieldcal.simulate("paper", seed=4)
    stats = fieldcal.summarize(s.accel, s.mag)
    problem = _build_problem(stats, "accel")
    cal = fieldcal.calibrate(s.accel, s.mag, pose_noise="none", robust=False)
    state = state_from_calibration(problem, cal)
    ne = normal_equations(problem, state, residuals(problem, state))
    unc = cramer_rao.uncertainty(problem, ne)
    C, _, _, cond = cramer_rao.global_covariance(ne)
    names, T = cramer_rao.named_map(problem)
    expected = T @ C @ T.T
    assert unc.covariance.names == tuple(names)
    scale = float(np.abs(expected).max())
    np.testing.assert_allclose(unc.covariance.matrix, expected, rtol=1e-9, atol=1e-9 * scale)
    assert unc.condition == pytest.approx(cond, rel=1e-9) and cond > 1.0
    assert unc.covariance is unc.covariance  # derived once
