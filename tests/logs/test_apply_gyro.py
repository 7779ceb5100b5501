"""``apply`` writes the gyroscope's corrected columns (rad/s) beside the others, and a
calibration's temperature terms with the column it was fitted with (issue 34, item 3)."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from _cli import run, user_error

import fieldcal
from fieldcal.simulation.warmup import simulate_warmup_log


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    """A warm-up log with a gyroscope, its temperature column named so nothing recognises it,
    calibrated with --temp-col."""
    folder = tmp_path_factory.mktemp("warm")
    log = simulate_warmup_log(seed=2, n_poses=14)
    columns = {("die_c" if k == "temp" else k): v for k, v in log.columns.items()}
    path = folder / "warm.csv"
    names = list(columns)
    np.savetxt(path, np.column_stack([columns[k] for k in names]), delimiter=",",
               header=",".join(names), comments="", fmt="%.9g")  # fmt: skip
    cal = folder / "cal.json"
    run("calibrate", path, "-o", cal, "--temp-col", "die_c", "--quiet", ok=False)
    return path, cal, columns


def _read(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    head = rows[0]
    return {name: np.array([float(r[i]) for r in rows[1:]]) for i, name in enumerate(head)}


def test_apply_writes_the_gyroscope_in_rad_per_second_with_the_recorded_temperature(warm, tmp_path):
    path, cal_path, _ = warm
    cal = fieldcal.Calibration.from_json(cal_path.read_text())
    assert cal.gyro is not None and cal.gyro.temperature is not None
    assert cal.options["columns"]["temperature"] == ["die_c"]
    out = tmp_path / "out.csv"
    result = run("apply", cal_path, path, "-o", out)  # no --temp-col: the recorded column
    assert "gyro: gx,gy,gz" in result.output and "temperature: die_c" in result.output
    got = _read(out)
    raw = np.column_stack([got[f"g{a}"] for a in "xyz"])  # as written in the log
    want = cal.correct_gyro(raw, got["die_c"])
    np.testing.assert_allclose(np.column_stack([got[f"g{a}_cal"] for a in "xyz"]), want,
                               rtol=1e-12, atol=1e-15)  # fmt: skip
    # the terms applied: without them the corrected rates differ by the bias's drift
    plain = cal.correct_gyro(raw, np.full(len(raw), cal.gyro.temperature.reference))
    assert np.max(np.abs(plain - want)) > 1e-4


def test_apply_takes_the_gyroscope_columns_given(warm, tmp_path):
    _, cal_path, columns = warm
    renamed = {("rx" if k == "gx" else k): v for k, v in columns.items()}
    src = tmp_path / "renamed.csv"
    names = list(renamed)
    np.savetxt(src, np.column_stack([renamed[k] for k in names]), delimiter=",",
               header=",".join(names), comments="", fmt="%.9g")  # fmt: skip
    out = tmp_path / "out.csv"
    run("apply", cal_path, src, "-o", out, "--gyro-cols", "rx,gy,gz", "--quiet")
    got = _read(out)
    assert "rx_cal" in got and "gy_cal" in got
    user_error("apply", cal_path, src, "-o", tmp_path / "x.csv", "--gyro-cols", "q,gy,gz",
               match="no column 'q'")  # fmt: skip


def test_npz_gets_the_gyroscope_too(warm, tmp_path):
    _, cal_path, columns = warm
    src = tmp_path / "log.npz"
    np.savez(src, **columns)
    out = tmp_path / "out.npz"
    run("apply", cal_path, src, "-o", out, "--quiet")
    with np.load(out) as z:
        assert {"gx_cal", "gy_cal", "gz_cal"} <= set(z.files)
        cal = fieldcal.Calibration.from_json(cal_path.read_text())
        raw = np.column_stack([columns[f"g{a}"] for a in "xyz"])
        want = cal.correct_gyro(raw, columns["die_c"])
        np.testing.assert_allclose(z["gx_cal"], want[:, 0], rtol=1e-12, atol=1e-15)
