"""Issue 35's outside-fuzzing residue, each reproducer run as it was reported: an unusable
``--temp-col`` (S1), raw data whose scale no unit explains (S3), noise units outside any
sensor's (S4), wrong types into public functions, a constant log into ``noise``, ``-o`` a
dangling symbolic link, a log of one or two rows, an unreachable ``--target-tilt`` and an
``apply`` killed half-way."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from _cli import run, user_error

import fieldcal
from fieldcal.errors import InputError
from fieldcal.noise import characterise_noise


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """``fieldcal demo``'s continuous log (time, accelerometer, gyroscope, magnetometer) and
    its calibration."""
    folder = tmp_path_factory.mktemp("demo35")
    run("demo", "--out", folder, "--no-report", "--seed", 3)
    return folder


def _with(demo: Path, name: str, change) -> Path:
    table = pd.read_csv(demo / "session.csv")
    change(table)
    path = demo / f"{name}.csv"
    table.to_csv(path, index=False)
    return path


def _reasons(cal_json: Path) -> list[str]:
    return [r["code"] for r in json.loads(cal_json.read_text())["verdict"]["reasons"]]


# ------------------------------------------------------------------------------------- S1
_BAD_TEMPERATURES = {
    "all-nan": lambda n: np.full(n, np.nan),
    "some-nan": lambda n: np.where(np.arange(n) % 3 == 0, np.nan, 25.0),
    "inf": lambda n: np.full(n, np.inf),
    "1e6": lambda n: np.full(n, 1e6),
    "minus-300": lambda n: np.full(n, -300.0),
    "kelvin": lambda n: 298.0 + np.linspace(0.0, 10.0, n),
}


@pytest.mark.parametrize("kind", list(_BAD_TEMPERATURES))
def test_s1_an_unusable_temp_col_is_an_error_naming_the_fix(demo, kind):
    log = _with(
        demo, f"temp-{kind}", lambda t: t.insert(1, "temp", _BAD_TEMPERATURES[kind](len(t)))
    )
    line = user_error(
        "calibrate", log, "--temp-col", "temp", "-o", demo / "x.json", "-q", match="'temp'"
    )
    assert "°C" in line and "--ignore-bad-temp" in line
    if kind == "kelvin":
        assert "kelvins" in line


def test_s1_going_on_is_a_reason_code_in_the_json(demo):
    log = _with(demo, "temp-k", lambda t: t.insert(1, "temp", 298.0 + np.linspace(0, 10, len(t))))
    out = demo / "k.json"
    run("calibrate", log, "--temp-col", "temp", "--ignore-bad-temp", "-o", out, "--json", "-q")
    saved = json.loads(out.read_text())
    assert "temperature_ignored" in _reasons(out)
    assert saved["verdict"]["level"] in ("warn", "fail")


# ------------------------------------------------------------------------------------- S3
@pytest.mark.parametrize(
    ("factor", "columns", "sensors"),
    [
        (1e30, "ax ay az mx my mz", {"accelerometer", "magnetometer"}),
        (1e-30, "ax ay az mx my mz", {"accelerometer", "magnetometer"}),
        (1e30, "gx gy gz", {"gyroscope"}),
    ],
    ids=["x1e30", "x1e-30", "gyro-x1e30"],
)
def test_s3_a_scale_no_unit_explains_is_a_reason_code(demo, factor, columns, sensors):
    cols = columns.split()

    def scale(t):
        t[cols] = t[cols] * factor

    log = _with(demo, f"scaled-{factor:g}-{cols[0]}", scale)
    out = demo / f"scaled-{factor:g}-{cols[0]}.json"
    run("calibrate", log, "-o", out, "-q", "--gyro", ok=False)
    saved = json.loads(out.read_text())
    texts = [r["text"] for r in saved["verdict"]["reasons"] if r["code"] == "unexplained_scale"]
    assert {
        s for s in ("accelerometer", "magnetometer", "gyroscope") if any(s in x for x in texts)
    } == sensors
    assert saved["verdict"]["level"] != "pass"


def test_s3_a_log_in_ordinary_units_has_no_scale_reason(demo):
    out = demo / "plain.json"
    run("calibrate", demo / "session.csv", "-o", out, "-q", "--gyro")
    assert "unexplained_scale" not in _reasons(out)


# ------------------------------------------------------------------------------------- S4
@pytest.mark.parametrize(
    "units", [("--accel-unit", "m/s^2", "--gyro-unit", "1e-300"), ("--accel-unit", "1e300")]
)
def test_s4_noise_units_outside_any_sensor_are_refused(demo, units):
    user_error(
        "noise",
        demo / "session.csv",
        *units,
        "--export",
        "kalibr",
        "-o",
        demo / "imu.yaml",
        match="outside any sensor's raw unit",
    )
    assert not (demo / "imu.yaml").exists()
    with pytest.raises(InputError, match="outside any sensor"):
        characterise_noise(demo / "session.csv", gyro_unit=1e-300, accel_unit="g")


# ---------------------------------------------------------------------------- smaller items
@pytest.mark.parametrize("call", [lambda: fieldcal.expected_field(5), lambda: fieldcal.Store(5)])
def test_wrong_types_into_public_functions_are_input_errors(call):
    with pytest.raises(InputError):
        call()


def test_noise_on_a_million_constant_rows_is_one_line(tmp_path):
    n = 10**6
    path = tmp_path / "const.npz"
    zero = np.zeros(n)
    np.savez(path, ax=zero, ay=zero, az=zero + 9.81, gx=zero, gy=zero, gz=zero)
    line = user_error(
        "noise",
        path,
        "--rate",
        100,
        "--accel-unit",
        "m/s^2",
        "--gyro-unit",
        "rad/s",
        match="reads the same value in every still row",
    )
    assert "SVD" not in line


@pytest.mark.parametrize("command", ["export", "demo"])
def test_output_onto_a_dangling_symlink_says_so(demo, tmp_path, command):
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "nowhere" / "x")
    args = (
        ["export", demo / "cal.json", "--format", "c-library", "-o", link]
        if command == "export"
        else ["demo", "--out", link, "--no-report"]
    )
    line = user_error(*args, match="symbolic link")
    assert "does not exist" in line and "Errno" not in line


@pytest.mark.parametrize("rows", [1, 2])
def test_a_log_of_one_or_two_rows_gets_a_true_message(demo, rows):
    path = demo / f"rows{rows}.csv"
    lines = (demo / "session.csv").read_text().splitlines()
    path.write_text("\n".join(lines[: rows + 1]) + "\n")
    line = user_error("calibrate", path, "-o", demo / "r.json", match=f"{rows} data row")
    assert "increase strictly" not in line


def test_plan_says_a_target_cannot_be_met(demo):
    result = run("plan", demo / "cal.json", "--target-tilt", "1e-300")
    assert "cannot be met" in result.output
    assert max(len(w) for w in result.output.split()) < 40  # no 300-digit number


def test_a_killed_apply_leaves_no_temporary_file(demo, tmp_path):
    table = pd.read_csv(demo / "session.csv")
    big = tmp_path / "big.csv"
    pd.concat([table] * 40).to_csv(big, index=False)
    out = tmp_path / "out.csv"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "fieldcal",
            "apply",
            str(demo / "cal.json"),
            str(big),
            "-o",
            str(out),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
    )
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(".out.csv.*.part")) and proc.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.005)
    assert proc.poll() is None, "apply finished before the temporary file could be seen"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert b"Interrupted" in err
    assert not list(tmp_path.glob(".*.part")) and not out.exists()
