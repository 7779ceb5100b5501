"""Temperature terms in the continuous-motion estimator (issue 26): biases as polynomials in
T − T_ref, fitted jointly with the trajectory, the order chosen by the span rule and the
forward test at 1 % (fieldcal.methods.continuous.thermal_terms).

Simulated warm-up logs (simulate_handwave(warmup=..., drift=...)), every RNG seeded; the
tolerances are the fit's own standard errors.
"""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.geometry.rotations import exp_so3
from fieldcal.methods.continuous import fit_continuous
from fieldcal.methods.continuous.model import Data, State, accel_block, mag_block
from fieldcal.methods.continuous.preintegration import thermal_factors
from fieldcal.methods.continuous.uncertainty import LEVER_NAMES, NAMES
from fieldcal.simulation.handwave import simulate_handwave
from fieldcal.trust.continuous_motion import trust_continuous

#: Linear bias drift per kelvin: accelerometer (m/s²), magnetometer (µT), gyroscope (rad/s).
DRIFT = {
    "accel": [[0.02, -0.015, 0.01]],
    "mag": [[0.3, -0.2, 0.25]],
    "gyro": [[0.002, -0.001, 0.0015]],
}


def _columns(log, prefix):
    return np.column_stack([log.columns[prefix + axis] for axis in "xyz"])


def _fit(log, **options):
    return fit_continuous(
        log.columns["t"], _columns(log, "a"), _columns(log, "m"), _columns(log, "g"), **options
    )


def _log(seed, warmup=(20.0, 40.0), drift=None):
    return simulate_handwave(seed=seed, seconds=20.0, rate=50.0, warmup=warmup, drift=drift)


def test_linear_drift_recovered_within_error_bars():
    log = _log(1, drift=DRIFT)
    cal = _fit(log, temperature=log.columns["temp"])
    record = cal.options["temperature"]
    assert record["orders"] == {"accel": 1, "mag": 1, "gyro": 1}
    assert record["reference_c"] == pytest.approx(np.mean(log.columns["temp"]), abs=1e-9)
    for sensor in ("accel", "mag", "gyro"):
        model = getattr(cal, sensor).temperature
        truth = getattr(log.truth, sensor).temperature
        assert model.order == 1 and not model.refused
        assert model.std is not None and np.all(model.std > 0)
        z = (model.coefficients - truth.coefficients) / model.std
        assert np.all(np.abs(z) < 4.0), (sensor, z)
        # the bias is the one at T_ref
        bias = getattr(cal, sensor)
        assert np.all(np.abs(bias.bias - getattr(log.truth, sensor).bias) < 4.0 * bias.bias_std)
    assert "accel.temp[1,0]" in cal.covariance.names
    assert "temperature_span" not in trust_continuous(cal).verdict.codes


def test_no_drift_selects_no_terms():
    log = _log(2)
    cal = _fit(log, temperature=log.columns["temp"])
    record = cal.options["temperature"]
    assert record["allowed_order"] >= 1 and record["tests"]
    assert record["orders"] == {}
    for sensor in ("accel", "mag", "gyro"):
        model = getattr(cal, sensor).temperature
        assert model.order == 0 and not model.refused
    assert tuple(cal.covariance.names) == (*NAMES, *LEVER_NAMES)  # no temperature terms


def test_small_span_refused_with_one_line():
    log = _log(3, warmup=(30.0, 32.0), drift=DRIFT)
    cal = _fit(log, temperature=log.columns["temp"])
    assert "at least 5 K" in cal.options["temperature"]["refused"]
    assert all(getattr(cal, s).temperature.refused for s in ("accel", "mag", "gyro"))
    assert all(getattr(cal, s).temperature.order == 0 for s in ("accel", "mag", "gyro"))
    assert cal.findings.temperature_span is not None
    assert "temperature_span" in trust_continuous(cal).verdict.codes


def test_without_temperature_no_terms():
    log = _log(4, drift=DRIFT)
    cal = _fit(log)
    assert "temperature" not in cal.options
    assert cal.accel.temperature is None and cal.gyro.temperature is None
    assert tuple(cal.covariance.names) == (*NAMES, *LEVER_NAMES)  # no temperature terms


def test_temperature_jacobians_match_finite_differences():
    rng = np.random.default_rng(5)
    n = 6
    rotations = np.stack([np.linalg.qr(rng.standard_normal((3, 3)))[0] for _ in range(n)])
    rotations *= np.sign(np.linalg.det(rotations))[:, None, None]
    d = rng.uniform(-10, 10, n)
    temps = {s: rng.normal(0, 0.01, (2, 3)) for s in ("accel", "mag", "gyro")}
    state = State(
        np.eye(3) * 9.8, rng.normal(0, 0.1, 3), np.eye(3) * 40, rng.normal(0, 5, 3), 0.8,
        np.eye(3), rng.normal(0, 0.01, 3), rotations, temps,
    )  # fmt: skip
    data = Data(
        np.arange(n) * 0.02, rng.normal(0, 9.8, (n, 3)), rng.normal(0, 40, (n, 3)),
        rng.normal(0, 1, (n, 3)), "midpoint", d,
    )  # fmt: skip
    h = 1e-6
    for sensor, block in (("accel", accel_block), ("mag", mag_block)):
        jac = block(state, getattr(data, sensor), d).params[:, :, -6:]
        for i in range(6):
            moved = state.copy()
            moved.temps[sensor].flat[i] += h
            num = (
                -(
                    block(moved, getattr(data, sensor), d).residual
                    - block(state, getattr(data, sensor), d).residual
                )
                / h
            )
            assert np.allclose(num, jac[:, :, i], atol=1e-6)

    def factors(s):
        return thermal_factors(
            s.rotations, data.time, data.gyro, s.gyro_gain, s.gyro_bias, "midpoint",
            s.temps["gyro"], d,
        )  # fmt: skip

    # rotations that the rates carry (the factor's Jacobian is the one at e = 0)
    rates = factors(state).rates
    for j in range(n - 1):
        state.rotations[j + 1] = exp_so3(-rates[j] * 0.02) @ state.rotations[j]
    assert np.max(np.abs(factors(state).residual)) < 1e-9
    jac = factors(state).params[:, :, -6:]
    for i in range(6):
        moved = state.copy()
        moved.temps["gyro"].flat[i] += h
        num = -(factors(moved).residual - factors(state).residual) / h
        assert np.allclose(num, jac[:, :, i], rtol=1e-4, atol=1e-8)


def test_allowances_keep_the_drift_terms():
    """With ``allowances=True`` (Eq. C6a–C6b) the orders are still chosen on the noise's own
    weights: a drift not yet modelled is not counted as body acceleration and hidden (counted
    so, this log kept only a magnetometer term of order 2)."""
    log = _log(1, drift=DRIFT)
    cal = _fit(log, temperature=log.columns["temp"], allowances=True)
    assert cal.options["temperature"]["orders"] == {"accel": 1, "mag": 1, "gyro": 1}
