"""Simulated sessions follow Table 1 and Eq. 18 of the seed paper."""

import numpy as np
import pytest

import fieldcal
from fieldcal.metrics import reconstruction_error
from fieldcal.simulation.session import PRESETS


def test_draws_follow_table_1():
    sessions = [fieldcal.simulate("paper", seed=s) for s in range(200)]
    counts = np.concatenate([s.counts for s in sessions])
    assert counts.min() >= 400 and counts.max() <= 600 and abs(counts.mean() - 500) < 3
    gz = np.array([s.drawn["gravity"][2] for s in sessions])
    hx = np.array([s.drawn["magnetic"][0] for s in sessions])
    hz = np.array([s.drawn["magnetic"][2] for s in sessions])
    assert -1.5 <= gz.min() and gz.max() <= -0.5
    assert 0.5 <= hx.min() and hx.max() <= 1.5 and -1.5 <= hz.min() and hz.max() <= 1.5
    dK = np.array([s.drawn["accel_gain"] - np.eye(3) for s in sessions])
    assert np.abs(dK).max() <= 0.1 and abs(dK.std() - 0.2 / np.sqrt(12)) < 0.003
    bias = np.array([s.drawn["mag_bias"] for s in sessions])
    assert np.abs(bias).max() <= 1 and abs(bias.std() - 2 / np.sqrt(12)) < 0.03
    for s in sessions[:20]:
        cov = s.drawn["accel_cov"]
        alpha_bounds = np.diag(cov) / np.array([0.5, 0.5, 0.5]), np.diag(cov) / 2.0
        assert np.all(alpha_bounds[0] >= 1e-4 * 0.999) and np.all(alpha_bounds[1] <= 1e-2)
        assert np.all(np.linalg.eigvalsh(cov) > 0) and np.allclose(cov, cov.T)


def test_samples_are_drawn_around_the_true_means_with_the_true_covariance():
    s = fieldcal.simulate("paper", seed=11)
    stats = fieldcal.summarize(s.accel, s.mag)
    for sensor, mean in zip((stats.accel, stats.mag), s.truth.predicted_means(), strict=True):
        cov = s.truth.accel.noise_cov if sensor is stats.accel else s.truth.mag.noise_cov
        # the pose means scatter around μ with covariance Σ/Δ_i, so ΣΔ·δ² of Eq. 19 is a
        # χ² variate with 3N = 45 degrees of freedom (mean 45, sd 9.5)
        delta = reconstruction_error(mean, sensor.means, cov, sensor.counts)
        assert 45 - 3 * 9.5 < sensor.counts.sum() * delta**2 < 45 + 3 * 9.5
        # Eq. 7's estimate is Wishart with ν ≈ 7500: relative error ~ sqrt(2/ν) ≈ 1.6 %
        sd = np.sqrt((cov**2 + np.outer(np.diag(cov), np.diag(cov))) / sensor.dof)
        assert np.all(np.abs(sensor.cov - cov) < 5 * sd)


def test_truth_is_the_drawn_model_in_fieldcal_gauge():
    s = fieldcal.simulate("paper", seed=2, n_poses=12)
    d = s.drawn
    a = np.einsum("ij,njk,k->ni", d["accel_gain"], d["rotations"], d["gravity"]) + d["accel_bias"]
    m = np.einsum("ij,njk,k->ni", d["mag_gain"], d["rotations"], d["magnetic"]) + d["mag_bias"]
    pa, pm = s.truth.predicted_means()
    np.testing.assert_allclose(pa, a, atol=1e-12)
    np.testing.assert_allclose(pm, m, atol=1e-12)
    assert len(s.accel) == 12 and s.truth.rotations.shape == (12, 3, 3)
    np.testing.assert_allclose(s.truth.accel.gain, s.truth.accel.gain.T, atol=1e-14)


def test_same_seed_same_session():
    a, b = fieldcal.simulate(seed=7), fieldcal.simulate(seed=7)
    assert all(np.array_equal(x, y) for x, y in zip(a.mag, b.mag, strict=True))
    assert a.truth.accel == b.truth.accel
    c = fieldcal.simulate(seed=8)
    assert not np.array_equal(a.mag[0][:5], c.mag[0][:5])


def test_unknown_preset_or_option_is_refused():
    with pytest.raises(ValueError, match="unknown preset"):
        fieldcal.simulate("nope")
    with pytest.raises(ValueError, match="unknown simulate option"):
        fieldcal.simulate(seed=1, gain=3)


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"preset": 1}, "unknown preset"),
        ({"preset": ["paper"]}, "unknown preset"),
        ({"seed": 1.5}, "seed must be a whole number"),
        ({"seed": -1}, "seed must be a whole number"),
        ({"n_poses": 2.5}, "n_poses must be a whole number"),
        ({"n_poses": "10"}, "n_poses must be a whole number"),
        ({"n_poses": 0}, "n_poses must be a whole number >= 1"),
        ({"samples": (5, 2)}, "samples must be"),
        ({"samples": (0, 0)}, "samples must be"),
        ({"samples": (2.5, 4)}, "samples must be"),
        ({"samples": "x"}, "samples must be"),
        ({"noise_alpha": 0.1}, "noise_alpha must be a"),
        ({"noise_alpha": (-1.0, 1.0)}, "noise_alpha must be >= 0"),
        ({"noise_alpha": (float("nan"), 1.0)}, "noise_alpha must be a"),
        ({"dip_deg": (91.0, 95.0)}, "dip_deg must be"),
        ({"dip_deg": "x"}, "dip_deg must be"),
        ({"gain_spread": -1.0}, "gain_spread must be"),
        ({"bias": float("inf")}, "bias must be"),
        ({"pose_noise": -1.0}, "pose_noise must be"),
        ({"pose_noise": "x"}, "pose_noise must be"),
        ({"pose_noise": (0.1, 0.2, 0.3)}, "pose_noise must be"),
        ({"mag_axes": [[1, 0], [0, 1]]}, "mag_axes must be"),
    ],
)
def test_options_it_cannot_draw_from_are_refused_in_one_line(kwargs, words):
    """Every option is checked before drawing: a one-line ValueError naming it and its form,
    never numpy's TypeError from deep inside (found by benchmarks/fuzz.py)."""
    with pytest.raises(ValueError, match=words) as info:
        fieldcal.simulate(**kwargs)
    assert "\n" not in str(info.value)


def test_the_checks_accept_every_preset_and_the_documented_forms():
    for preset, drawn in PRESETS.items():
        assert len(fieldcal.simulate(preset, seed=0).accel) == drawn["n_poses"]
    s = fieldcal.simulate(
        seed=np.int64(3), n_poses=np.int64(9), samples=[3, 3], pose_noise=(0.01, 0.0),
        dip_deg=(-90, 90), mag_axes=np.diag([1, -1, 1]),
    )  # fmt: skip
    assert len(s.accel) == 9 and all(len(p) == 3 for p in s.accel)


def test_handheld_poses_are_mostly_tilted_less_than_60_degrees():
    s = fieldcal.simulate("paper", seed=3, n_poses=40, pose_distribution="handheld")
    up = s.drawn["rotations"][:, 2, 2]  # cos(tilt) of the body z axis from the world z axis
    tilt = np.degrees(np.arccos(np.clip(up, -1, 1)))
    assert np.sum(tilt > 120) == 2 and np.sum(tilt <= 60 + 1e-9) == 38
