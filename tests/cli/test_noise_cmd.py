"""``noise``: Allan deviation and Kalibr's imu.yaml from a still recording."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from fieldcal.cli import cli


def test_noise_command_writes_kalibr_yaml(tmp_path):
    """``fieldcal noise`` on a still recording of white noise of known σ: the yaml's densities
    are σ/√rate (within the estimate's few-percent spread) in SI units, the figure is written,
    and ``-o`` without ``--export`` is a usage error."""
    yaml = pytest.importorskip("yaml", reason="pyyaml (the test extra) not installed")
    rng = np.random.default_rng(5)
    rate, n = 100.0, 60_000
    sigma_g, sigma_a = 0.5, 0.002  # deg/s and g per sample
    columns = {"t": np.arange(n) / rate}
    for axis in "xyz":
        columns[f"gyr_{axis}_dps"] = rng.normal(scale=sigma_g, size=n)
        columns[f"acc_{axis}_g"] = rng.normal(scale=sigma_a, size=n) + (axis == "z")
    path = tmp_path / "still.csv"
    np.savetxt(
        path,
        np.column_stack(list(columns.values())),
        delimiter=",",
        header=",".join(columns),
        comments="",
    )
    runner = CliRunner()
    args = ["noise", str(path), "--still", "all", "--accel-unit", "g", "--gyro-unit", "deg/s"]
    result = runner.invoke(
        cli,
        [
            *args,
            "--export",
            "kalibr",
            "-o",
            str(tmp_path / "imu.yaml"),
            "--plot",
            str(tmp_path / "allan.png"),
        ],
    )
    assert result.exit_code == 0, result.output
    values = yaml.safe_load((tmp_path / "imu.yaml").read_text())  # as Kalibr reads it
    assert values["rostopic"] == "/imu0"
    gyro_density = np.radians(sigma_g) / np.sqrt(rate)
    accel_density = 9.80665 * sigma_a / np.sqrt(rate)
    # the largest of three axes, each within a few percent of the truth
    assert values["gyroscope_noise_density"] == pytest.approx(gyro_density, rel=0.06)
    assert values["accelerometer_noise_density"] == pytest.approx(accel_density, rel=0.06)
    assert values["update_rate"] == pytest.approx(rate)
    assert (tmp_path / "allan.png").stat().st_size > 1000
    bad = runner.invoke(cli, [*args, "-o", str(tmp_path / "x.yaml")])
    assert bad.exit_code == 2 and "--export" in bad.stderr
