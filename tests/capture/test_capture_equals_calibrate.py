"""``capture --from LOG`` and ``calibrate LOG`` choose the same mode and give the same numbers
(within 1e-9 relative) on logs of each kind, with the same options (issue 34, item 2)."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

import fieldcal
from fieldcal.cli import cli
from fieldcal.simulation.continuous import simulate_continuous
from fieldcal.simulation.handwave import simulate_handwave


def _rests(path):
    simulate_continuous("paper", seed=7, n_poses=12).write_csv(str(path))


def _waved(path):
    simulate_handwave(seed=7, seconds=25.0).write_csv(str(path))


def _warm_rests(path):
    from fieldcal.simulation.warmup import simulate_warmup_log

    simulate_warmup_log(seed=7, n_poses=12).write_csv(str(path))


KINDS = {
    "rests": (_rests, [], "still"),
    "hand-waved (auto)": (_waved, [], "continuous"),
    "hand-waved (--poses continuous)": (_waved, ["--poses", "continuous"], "continuous"),
    "warm-up with a temperature column": (_warm_rests, [], "still"),
}


@pytest.mark.parametrize("kind", list(KINDS))
def test_capture_and_calibrate_agree(kind, tmp_path):
    make, options, mode = KINDS[kind]
    log = tmp_path / "log.csv"
    make(log)
    out = tmp_path / "cap"
    runner = CliRunner()
    captured = runner.invoke(cli, ["capture", "--from", str(log), "--plain", "--out", str(out),
                                   *options])  # fmt: skip
    assert captured.exit_code in (0, 3), captured.output
    direct = tmp_path / "direct.json"
    done = runner.invoke(cli, ["calibrate", str(log), "-o", str(direct), "-q", *options])
    assert done.exit_code in (0, 3), done.output
    a = fieldcal.Calibration.from_json((out / "cal.json").read_text())
    b = fieldcal.Calibration.from_json(direct.read_text())
    continuous = "trajectory" in b.options
    assert continuous == (mode == "continuous")
    assert ("trajectory" in a.options) == continuous  # the same mode chosen
    assert a.verdict.level == b.verdict.level and a.verdict.codes == b.verdict.codes
    for sensor in ("accel", "mag", "gyro"):
        x, y = getattr(a, sensor), getattr(b, sensor)
        assert (x is None) == (y is None), sensor
        if x is None:
            continue
        for name in ("gain", "bias"):
            want = np.asarray(getattr(y, name))
            scale = np.abs(want).max()
            np.testing.assert_allclose(getattr(x, name), want, rtol=0, atol=1e-9 * scale)
