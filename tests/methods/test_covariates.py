"""The magnetometer's interference term fitted jointly by the continuous estimator
(:mod:`fieldcal.methods.continuous.covariates`), on flights of the independent multirotor
simulator (:mod:`fieldcal.simulation.multirotor`) with a known truth."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fieldcal.calibration import ParameterCovariance
from fieldcal.methods.continuous import fit_continuous
from fieldcal.methods.continuous.autopilot_aid import autopilot_held
from fieldcal.methods.continuous.covariates import (
    JOINT,
    interference_inputs,
    interference_labels,
    interference_model,
    interference_shift,
)
from fieldcal.simulation.multirotor import simulate_flight


def _joint(flight, current=None, **options):
    return fit_continuous(
        flight.time,
        flight.accel,
        flight.mag,
        flight.gyro,
        inputs={"current": flight.current if current is None else current},
        prior=autopilot_held("the simulated autopilot", 9.81),
        **options,
    )


def test_the_terms_jacobian_is_the_centred_input_times_the_identity():
    """Eq. C2i is linear in C: the Jacobian applied to C gives the shift exactly, per input."""
    rng = np.random.default_rng(3)
    U = rng.normal(size=(7, 2))
    C = rng.normal(size=(2, 3))
    mag = rng.normal(size=(7, 3))
    less, J = interference_shift(C, mag, U)
    assert J.shape == (7, 3, 6)
    assert mag - less == pytest.approx(J @ C.ravel(), abs=1e-12)
    assert interference_shift(np.zeros((0, 3)), mag, U)[1].shape == (7, 3, 0)


@pytest.mark.parametrize("seed", [2, 7])
def test_joint_fit_recovers_the_coefficients_within_their_error_bars(seed):
    """A 60 s flight, 25 Hz: the coefficients within 4 standard errors of the truth (the
    sandwich's, named in the covariance), the error bars near the Cramér–Rao bound,
    and the magnetometer's gain recovered with the term in the model."""
    flight = simulate_flight(seed, seconds=60.0, rate=25.0, interference_ut=30.0)
    cal = _joint(flight, attitude=flight.attitude)
    model = cal.mag.interference
    assert model is not None and model.identifiable and model.trajectory == JOINT
    c, se = model.coefficients[0], model.std[0]
    assert np.all(np.abs(c - flight.coefficients) < 4 * se)
    assert np.all(se < 0.1 * np.linalg.norm(flight.coefficients))
    assert np.all((se > 0.3 * model.crb[0]) & (se < 5.0 * model.crb[0]))
    assert cal.covariance is not None
    assert cal.covariance.stds(interference_labels(1)) == pytest.approx(se, rel=1e-9)
    assert model.reference[0] == pytest.approx(flight.current.mean())
    # |h| = 1: the gain is in µT per unit of the simulator's 50 µT field
    assert cal.mag.gain == pytest.approx(50.0 * flight.gain, abs=1.0)


def test_current_that_never_rises_is_refused_with_what_to_fly():
    """Current under 3 A all flight: not identifiable, zeros, the issue's advice."""
    flight = simulate_flight(4, seconds=30.0, rate=25.0)
    idle = 0.6 + 0.3 * np.sin(flight.time)
    model = _joint(flight, current=idle).mag.interference
    assert model is not None and not model.identifiable
    assert "current never exceeded 0.9 A" in model.reason and "throttle sweep" in model.reason
    assert np.all(model.coefficients == 0) and np.all(model.std == 0)


def test_current_that_follows_the_heading_is_not_identifiable():
    """An input that is a function of the field's body direction cannot be told from the
    gain: the model says so (the share left free below MIN_FREE)."""
    rng = np.random.default_rng(5)
    R = Rotation.random(400, random_state=6).as_matrix()
    h = np.array([np.cos(1.0), 0.0, np.sin(1.0)])
    current = 20.0 + 10.0 * (R @ h)[:, 0] + 0.01 * rng.normal(size=400)
    drive = interference_inputs({"current": current}, 400)
    assert drive is not None and drive.missing == ""
    names = interference_labels(1)
    cov = ParameterCovariance(tuple(names), np.eye(3))
    model = interference_model(np.ones((1, 3)), drive, R, np.eye(3), 1.0, (cov, cov))
    assert not model.identifiable and "moved with the orientation" in model.reason


def test_inputs_are_checked():
    with pytest.raises(Exception, match="one per sample"):
        interference_inputs({"current": np.ones(3)}, 4)
    with pytest.raises(Exception, match="not current or throttle"):
        interference_inputs({"rpm": np.ones(4)}, 4)
    assert interference_inputs({}, 4) is None


def test_a_magnetometer_axis_map_folds_the_term_back_to_the_raw_axes():
    """Fitted on mapped axes (``--mag-axes``), folded back: the coefficients are the raw
    frame's truth, their covariance entries follow."""
    from fieldcal.pipeline import fold_axes

    flight = simulate_flight(2, seconds=40.0, rate=25.0, interference_ut=30.0)
    P = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    mapped = fit_continuous(
        flight.time,
        flight.accel,
        flight.mag @ P.T,
        flight.gyro,
        inputs={"current": flight.current},
        prior=autopilot_held("the simulated autopilot", 9.81),
        attitude=flight.attitude,
    )
    model = fold_axes(mapped, P, "yx-z").mag.interference
    assert np.all(np.abs(model.coefficients[0] - flight.coefficients) < 4 * model.std[0])
    cov = fold_axes(mapped, P, "yx-z").covariance
    assert cov.stds(interference_labels(1)) == pytest.approx(model.std[0], rel=1e-9)
