"""Knots (issue 33 item 6): the reduced windows against the samples, the pre-integration's
Jacobians against re-integration, and the knots' fit against the per-sample one."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fieldcal.geometry.rotations import exp_so3, log_so3
from fieldcal.methods.continuous import fit_continuous
from fieldcal.methods.continuous import knots as knots_module
from fieldcal.methods.continuous.knots import reduce, sample_rotations
from fieldcal.methods.continuous.model import (
    Data,
    State,
    accel_columns,
    accel_of,
    mag_columns,
    mag_of,
    residuals,
)
from fieldcal.methods.continuous.preintegration import thermal_factors
from fieldcal.simulation.handheld import simulate_handheld

STEP = 10


def _case(hold: str = "midpoint") -> tuple[Data, State]:
    """Random rates (5 rad/s RMS) over 4 knots of 10 samples, a gyroscope gain and bias, a
    lever arm, a temperature."""
    rng = np.random.default_rng(7)
    n = 4 * STEP
    t = np.cumsum(0.01 + 0.001 * rng.random(n))
    data = Data(
        t,
        rng.normal(size=(n, 3)),
        rng.normal(size=(n, 3)),
        5.0 * rng.normal(size=(n, 3)),
        hold,
        temperature=np.linspace(-3.0, 4.0, n),
    )
    state = State(
        np.diag([1.0, 1.1, 0.9]),
        0.1 * rng.normal(size=3),
        np.eye(3) + 0.1 * rng.normal(size=(3, 3)),
        0.1 * rng.normal(size=3),
        0.3,
        np.eye(3) + 0.05 * rng.normal(size=(3, 3)),
        0.1 * rng.normal(size=3),
        exp_so3(rng.normal(size=(4, 3))),
        {"accel": 0.01 * rng.normal(size=(1, 3)), "gyro": 0.01 * rng.normal(size=(2, 3))},
        np.array([0.1, -0.05, 0.2]),
    )
    return data, state


@pytest.mark.parametrize("hold", ["midpoint", "previous"])
def test_a_knot_is_its_windows_mean(hold):
    """The knot's prediction (``M_k``, the lever arm's mean from the rates' moments, the
    temperature's mean powers) equals the mean over its window of the samples' predictions with
    the rotations the gyroscope carries from the knot: exactly, not to first order."""
    data, state = _case(hold)
    knots = reduce(data, state, STEP)
    per_sample = dataclasses.replace(state, rotations=sample_rotations(data, state, STEP))
    ra, rm = residuals(per_sample, data)
    ka, km = residuals(state, knots)
    assert np.abs(ra.reshape(4, STEP, 3).mean(axis=1) - ka).max() < 1e-12
    assert np.abs(rm.reshape(4, STEP, 3).mean(axis=1) - km).max() < 1e-12
    assert np.abs(accel_of(state, knots).residual - ka).max() < 1e-12
    # knots chained by the pre-integrated turns (R_{k+1} = Γ_kᵀ R_k) give samples that the
    # gyroscope's own factors (Eq. C3) join without a misfit, across the knots too
    chained = [state.rotations[0]]
    for turn in knots.factors.turn:
        chained.append(turn.T @ chained[-1])
    joined = sample_rotations(data, dataclasses.replace(state, rotations=np.array(chained)), STEP)
    f = thermal_factors(
        joined,
        data.time,
        data.gyro,
        state.gyro_gain,
        state.gyro_bias,
        hold,
        state.temps["gyro"],
        data.temperature,
    )
    assert np.abs(f.residual).max() < 1e-12


def _gyro_moved(state: State, theta: np.ndarray) -> State:
    temps = dict(state.temps, gyro=theta[12:].reshape(-1, 3))
    return dataclasses.replace(
        state, gyro_gain=theta[:9].reshape(3, 3), gyro_bias=theta[9:12], temps=temps
    )


def test_pre_integration_jacobians_match_re_integration():
    """``G_k`` (the factor's turn) and ``D_c`` (``∂(M u)/∂θ``) against central differences of
    the whole reduction redone at moved gyroscope parameters (gain, bias, temperature)."""
    data, state = _case()
    knots = reduce(data, state, STEP)
    theta = knots.factors.anchor
    u = state.rotations @ np.array([0.0, 0.0, -1.0])
    mixing_jac = np.einsum("nc,ncij->nij", u, knots.mixing_jacobian)
    h = 1e-6
    for i in range(len(theta)):
        d = np.zeros_like(theta)
        d[i] = h
        up = reduce(data, _gyro_moved(state, theta + d), STEP)
        down = reduce(data, _gyro_moved(state, theta - d), STEP)
        back = np.swapaxes(knots.factors.turn, 1, 2)
        numeric = (log_so3(back @ up.factors.turn) - log_so3(back @ down.factors.turn)) / (2 * h)
        scale = np.abs(knots.factors.jacobian).max()
        assert np.abs(numeric - knots.factors.jacobian[:, :, i]).max() < 1e-6 * scale
        if i < 12:
            moved = ((up.mixing - down.mixing) @ u[:, :, None])[:, :, 0] / (2 * h)
            assert np.abs(moved - mixing_jac[:, :, i]).max() < 1e-6 * np.abs(mixing_jac).max()


def test_knot_jacobians_match_differences():
    """The knots' analytic Jacobians (the field sensors' through ``M_k`` included) against
    central differences of their residuals."""
    data, state = _case()
    knots = reduce(data, state, STEP)
    p0 = state.vector()
    for block in (accel_of, mag_of):
        cols = accel_columns(state) if block is accel_of else mag_columns(state, knots)
        J = block(state, knots).params
        assert J.shape[2] == len(cols)
        for k, col in enumerate(cols):
            d = np.zeros_like(p0)
            d[col] = 1e-6
            up = block(state.updated(d, np.zeros((4, 3))), knots).residual
            down = block(state.updated(-d, np.zeros((4, 3))), knots).residual
            numeric = -(up - down) / 2e-6
            assert np.abs(numeric - J[:, :, k]).max() < 1e-6 * (np.abs(J).max() + 1.0)


def _fit(log, **options):
    c = log.columns
    cols = [np.column_stack([c[p + a] for a in "xyz"]) for p in "amg"]
    return fit_continuous(c["t"], *cols, gravity=log.gravity, **options)


def _values(cal, names):
    out = []
    for name in names:
        sensor, rest = name.split(".")
        sc = getattr(cal, sensor)
        if rest.startswith("gain"):
            out.append(sc.gain[int(rest[5]), int(rest[7])])
        else:
            out.append(sc.bias[int(rest[5])])
    return np.array(out)


def test_knots_agree_with_the_per_sample_fit(monkeypatch):
    """A hand-held log (lever arm, translation; seeded) fitted on knots and on every sample
    (the knots' spacing forced to one sample: the per-sample model of Eq. C1–C3): every gain
    and bias within 1.5 of the per-sample fit's standard errors and their RMS under 0.5 (six
    seeds of 60 s: at most 0.56–1.25, RMS 0.17–0.28), the error bars within a factor of 2."""
    log = simulate_handheld(11, seconds=60.0, rate=100.0, internal_rate=200.0)
    knots = _fit(log)
    assert knots.options["knots"]["step"] >= 4
    monkeypatch.setattr(knots_module, "KNOT_SECONDS", 1e-9)
    reference = _fit(log)
    assert reference.options["knots"]["step"] == 1
    names = [
        f"{s}.{what}[{i},{j}]" if what == "gain" else f"{s}.{what}[{i}]"
        for s in ("accel", "mag", "gyro")
        for what in ("gain", "bias")
        for i in range(3)
        for j in range(3 if what == "gain" else 1)
    ]
    se = reference.covariance.stds(names)
    z = (_values(knots, names) - _values(reference, names)) / se
    assert np.max(np.abs(z)) < 1.5, z
    assert np.sqrt(np.mean(z**2)) < 0.5
    ratio = knots.covariance.stds(names) / se
    assert np.all((ratio > 0.5) & (ratio < 2.0)), ratio
