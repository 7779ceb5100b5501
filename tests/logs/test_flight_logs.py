"""Flight logs read directly: PX4 ULog through pyulog (the real samples in ../shared/data),
ArduPilot DataFlash written by a small writer and read back through pymavlink."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from _dataflash import write_dataflash

from fieldcal.errors import InputError
from fieldcal.logs import load_log
from fieldcal.reference import expected_field

ULOGS = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "px4-ulog"


def _ulog(name: str) -> Path:
    pytest.importorskip("pyulog", reason="the [ulog] extra (pyulog) is not installed")
    path = ULOGS / name
    if not path.is_file():
        pytest.skip(f"{path} is absent (../shared/data beside the repository)")
    return path


@pytest.mark.parametrize("name", ["sample_log_small.ulg", "sample_px4_events.ulg"])
def test_ulog_matches_pyulogs_own_values(name):
    """The table's accelerometer and magnetometer are pyulog's sensor_combined and
    vehicle_magnetometer at the magnetometer's timestamps; |accel| ≈ 9.8 m/s² on a vehicle
    at rest or hovering; the field's norm within 15 % of WMM's at the logged GPS position."""
    from pyulog import ULog

    path = _ulog(name)
    log = load_log(path)
    ulog = ULog(str(path), ["vehicle_magnetometer", "sensor_combined"])
    mag = next(d for d in ulog.data_list if d.name == "vehicle_magnetometer").data
    t_mag = mag.get("timestamp_sample", mag["timestamp"]) * 1e-6
    raw = np.column_stack([mag[f"magnetometer_ga[{k}]"] for k in range(3)])
    start = np.searchsorted(t_mag, t_mag[0] + 0)  # the rows are the magnetometer's samples
    assert log.n >= len(t_mag) - 3
    # each row's field is one of pyulog's samples, exactly
    assert np.min(np.abs(raw[start:, None, 0] - log.mag[None, :5, 0]), axis=0).max() < 1e-6
    acc = next(d for d in ulog.data_list if d.name == "sensor_combined").data
    pyulog_norm = np.linalg.norm(
        np.column_stack([acc[f"accelerometer_m_s2[{k}]"] for k in range(3)]), axis=1
    )
    ours = np.linalg.norm(log.accel, axis=1)
    assert abs(np.median(ours) - np.median(pyulog_norm)) < 0.05
    assert 9.3 < np.median(ours) < 10.3  # at rest or hovering: gravity
    lat, lon, alt = map(float, log.metadata["gps_location"].split(","))
    wmm = expected_field((lat, lon, alt), log.metadata.get("date"))
    norm_ut = 100.0 * np.median(np.linalg.norm(log.mag, axis=1))  # gauss -> µT
    assert abs(norm_ut / (wmm.intensity / 1000.0) - 1.0) < 0.15, (norm_ut, wmm.intensity / 1000.0)
    assert log.metadata["mag_unit"] == "gauss"
    assert any("vehicle_magnetometer" in n and "gauss" in n for n in log.notes)


def test_ulog_instances_and_inputs():
    path = _ulog("sample_log_small.ulg")
    log = load_log(path)
    assert set(log.inputs) == {"current"}
    assert log.attitude is not None and np.allclose(np.linalg.norm(log.attitude, axis=1), 1)
    with pytest.raises(InputError, match="no mag instance 5"):
        load_log(path, mag_instance=5)


def _flight(tmp_path, *, params=True, current=True):
    """A level vehicle yawing at 20°/s, a 500 mG field, current 5-25 A adding 2 mG/A on x;
    ArduPilot's correction applied as correct_field does (offsets, M, motor offsets)."""
    rng = np.random.default_rng(4)
    ofs = np.array([30.0, -20.0, 10.0])
    msgs: list[tuple[str, tuple]] = []
    if params:
        msgs += [("PARM", (0, f"COMPASS_OFS_{a}", v)) for a, v in zip("XYZ", ofs, strict=True)]
        msgs += [("PARM", (0, f"COMPASS_DIA_{a}", 1.0)) for a in "XYZ"]
        msgs += [("PARM", (0, f"COMPASS_ODI_{a}", 0.0)) for a in "XYZ"]
    truth = []
    for k in range(400):
        t = 1_000_000 + k * 20_000
        yaw = np.radians(20.0 * k * 0.02)
        field = 500.0 * np.array([np.cos(-yaw) * 0.4, np.sin(-yaw) * 0.4, 0.9])
        amps = 15.0 + 10.0 * np.sin(k / 30.0)
        raw = field + np.array([2.0, 0.0, 0.0]) * amps - ofs
        mot = np.array([0.5, 0.0, 0.0]) * amps
        logged = (raw + ofs) + mot
        truth.append(raw)
        msgs.append(("IMU", (t, 0, 0.0, 0.0, np.radians(20.0), 0.0, 0.0, -9.81, 35.0)))
        msgs.append(("MAG", (t + 100, 0, *logged, *mot)))
        msgs.append(("ATT", (t, 0.0, 0.0, np.degrees(yaw) % 360)))
        if current and k % 5 == 0:
            msgs.append(("BAT", (t, 0, 16.0, amps)))
        if k % 50 == 0:
            lat, lon = 47.4 + rng.normal(0, 1e-6), 8.5
            msgs.append(("GPS", (t, 3, lat, lon, 420.0)))
    return write_dataflash(tmp_path / "flight.bin", msgs), np.array(truth)


def test_dataflash_through_pymavlink(tmp_path):
    pytest.importorskip("pymavlink", reason="the [dataflash] extra (pymavlink) is not installed")
    path, truth = _flight(tmp_path)
    log = load_log(path)
    assert log.n >= 395
    # ArduPilot's correction undone: the raw field, as the writer made it
    assert np.abs(log.mag - truth[: log.n]).max() < 1e-2
    assert np.allclose(log.accel[:, 2], -9.81, atol=1e-4)
    assert np.allclose(log.gyro[:, 2], np.radians(20.0), atol=1e-6)
    assert 5.0 <= log.inputs["current"].min() and log.inputs["current"].max() <= 25.0
    assert log.metadata["gps_location"].startswith("47.4")
    assert log.metadata["mag_unit"] == "mGauss"
    # the attitude's yaw follows the logged one
    q = log.attitude
    yaw = np.degrees(
        np.arctan2(
            2 * (q[:, 0] * q[:, 3] + q[:, 1] * q[:, 2]), 1 - 2 * (q[:, 2] ** 2 + q[:, 3] ** 2)
        )
    )
    assert np.abs(((np.diff(yaw) + 180) % 360) - 180).max() < 1.0


def test_dataflash_without_parameters_says_so(tmp_path):
    pytest.importorskip("pymavlink", reason="the [dataflash] extra (pymavlink) is not installed")
    path, _ = _flight(tmp_path, params=False, current=False)
    log = load_log(path)
    assert any("COMPASS_OFS not in the log" in n for n in log.notes)
    assert log.inputs == {}


def test_damaged_flight_logs_are_refused_in_one_line(tmp_path):
    pytest.importorskip("pymavlink", reason="the [dataflash] extra (pymavlink) is not installed")
    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"not a log at all")
    with pytest.raises(InputError, match="not a readable ArduPilot DataFlash log"):
        load_log(bad)
    with pytest.raises(InputError, match="--mag/--imu choose a flight log"):
        csv = tmp_path / "a.csv"
        csv.write_text("ax,ay,az\n1,2,3\n")
        load_log(csv, mag_instance=1)


def test_real_ulog_says_what_the_interference_term_lacks(tmp_path):
    """The CubeOrange sample hovers at under 1 A: the term is not identifiable, and the verdict
    says what to fly; the GPS position is the location (the WMM's field)."""
    from click.testing import CliRunner

    from fieldcal.cli import cli

    path = _ulog("sample_log_small.ulg")
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(
        cli, ["calibrate", str(path), "--sensors", "mag", "--poses", "samples", "-o", str(out)]
    )
    assert out.is_file(), result.output
    assert "from the log's GPS" in result.output
    doc = json.loads(out.read_text())
    cal = doc.get("calibration", doc)
    model = cal["mag"]["interference"]
    assert model["identifiable"] is False
    assert "current never exceeded" in model["reason"] and "throttle sweep" in model["reason"]
    codes = [r["code"] for r in cal["verdict"]["reasons"]]
    assert "interference_not_identifiable" in codes
