"""The continuous estimator's options on the command line (issue 33 item 5): the gyroscope's
sampling convention, its noise, and blocks held at an earlier calibration's values."""

from __future__ import annotations

import numpy as np
import pytest
from _cli import run, user_error

import fieldcal
from fieldcal.simulation.handheld import simulate_handheld

COLUMNS = ("t", "ax", "ay", "az", "mx", "my", "mz", "gx", "gy", "gz")


@pytest.fixture(scope="module")
def log_csv(tmp_path_factory):
    """20 s at 50 Hz, the gyroscope reporting interval means."""
    log = simulate_handheld(7, seconds=20.0, rate=50.0, gyro_sampling="mean", max_rate=4.0)
    path = tmp_path_factory.mktemp("continuous") / "log.csv"
    data = np.column_stack([log.columns[c] for c in COLUMNS])
    np.savetxt(path, data, delimiter=",", header=",".join(COLUMNS), comments="")
    return path


def _cal(path):
    return fieldcal.Calibration.from_json(path.read_text())


def test_sampling_given_and_recorded(log_csv, tmp_path):
    out = tmp_path / "c.json"
    run(
        "calibrate",
        log_csv,
        "--poses",
        "continuous",
        "--gyro-sampling",
        "mean",
        "-o",
        out,
        ok=False,
    )
    cal = _cal(out)
    assert cal.options["gyro_sampling"] == {"used": "mean", "how": "given"}
    assert cal.options["hold"] == "previous"


def test_summary_speaks_of_the_motion_not_of_poses(log_csv, tmp_path):
    """A continuous fit's summary names where its gyroscope noise came from and prints no
    pose-level noise (it has no pose means)."""
    result = run("calibrate", log_csv, "--poses", "continuous", "-o", tmp_path / "c.json", ok=False)
    assert result.exit_code in (0, 1, 3), result.output
    assert "pose-level noise" not in result.output
    assert "from the still poses" not in result.output
    cal = _cal(tmp_path / "c.json")
    assert cal.gyro is not None and cal.gyro.noise_source in result.output


def test_hold_gyro_gain_at_the_prior(log_csv, tmp_path):
    first, second = tmp_path / "a.json", tmp_path / "b.json"
    run(
        "calibrate",
        log_csv,
        "--poses",
        "continuous",
        "--gyro-noise",
        "0.004",
        "-o",
        first,
        ok=False,
    )
    a = _cal(first)
    assert a.gyro is not None and a.gyro.noise_source == "given (gyro_noise)"
    args = ("--hold", "gyro.gain", "--prior", first, "-o", second)
    run("calibrate", log_csv, "--poses", "continuous", *args, ok=False)
    b = _cal(second)
    assert b.options["held"] == ["gyro.gain"]
    assert np.allclose(b.gyro.gain, a.gyro.gain, rtol=0, atol=1e-12)
    names = [f"gyro.gain[{i},{j}]" for i in range(3) for j in range(3)]
    assert np.all(b.covariance.stds(names) == 0)
    assert np.all(b.covariance.stds(["gyro.bias[0]", "accel.bias[0]"]) > 0)


def test_hold_needs_a_prior_and_a_known_block(log_csv, tmp_path):
    user_error("calibrate", log_csv, "--poses", "continuous", "--hold", "gyro.gain",
               "-o", tmp_path / "x.json", match="--prior")  # fmt: skip
    user_error("calibrate", log_csv, "--poses", "continuous", "--hold", "gyro.scale",
               "--prior", log_csv, "-o", tmp_path / "x.json", match="gyro.scale")  # fmt: skip
