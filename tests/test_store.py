"""The calibration store: a folder by device and date; latest, closest, drift."""

from __future__ import annotations

import dataclasses
import importlib.util

import numpy as np
import pytest
from click.testing import CliRunner

import fieldcal
from fieldcal.cli import cli
from fieldcal.errors import InputError

#: The drift plot needs matplotlib (the plot extra); without it the table is still checked.
PLOT = importlib.util.find_spec("matplotlib") is not None


@pytest.fixture(scope="module")
def cal():
    session = fieldcal.simulate("paper", seed=4)
    return fieldcal.calibrate(session.accel, session.mag)


def _at(cal, created):
    return dataclasses.replace(cal, created=created)


def test_add_latest_closest_and_files(cal, tmp_path):
    store = fieldcal.Store(tmp_path / "store")
    dates = ["2026-01-05T10:00:00+00:00", "2026-03-01T08:30:00+00:00", "2026-02-01T00:00:00+00:00"]
    paths = [store.add(_at(cal, d), device="board-7") for d in dates]
    assert [p.name for p in paths] == [
        "2026-01-05T100000Z.json",
        "2026-03-01T083000Z.json",
        "2026-02-01T000000Z.json",
    ]
    again = store.add(_at(cal, dates[0]), device="board-7")  # same second: never replaced
    assert again.name == "2026-01-05T100000Z-2.json" and paths[0].exists()
    assert store.devices() == ["board-7"]
    assert [e.created.month for e in store.entries("board-7")] == [1, 1, 2, 3]
    assert store.latest("board-7").created == dates[1]
    assert store.closest("board-7", "2026-02-10").created == dates[2]
    assert store.latest("board-7") == cal  # the JSON round trip keeps every value
    with pytest.raises(InputError, match="device id"):
        store.add(cal, device="../escape")
    with pytest.raises(InputError, match="no calibration of device 'other'"):
        store.latest("other")


def test_drift_flags_what_moved_and_nothing_else(cal, tmp_path):
    store = fieldcal.Store(tmp_path)
    store.add(_at(cal, "2026-01-01T00:00:00Z"), device="d1")
    store.add(_at(cal, "2026-02-01T00:00:00Z"), device="d1")
    moved_bias = cal.accel.bias + np.array([20 * cal.accel.bias_std[0], 0.0, 0.0])
    moved = dataclasses.replace(cal, accel=dataclasses.replace(cal.accel, bias=moved_bias))
    store.add(_at(moved, "2026-03-01T00:00:00Z"), device="d1")
    rows = store.drift("d1")
    assert rows[0].since_previous is None
    assert rows[1].since_previous.changed == ()
    assert [c.name for c in rows[2].since_previous.changed] == ["accel.bias[0]"]
    plot = ["--plot", str(tmp_path / "d.png")] if PLOT else []  # the plot needs matplotlib
    result = CliRunner().invoke(cli, ["store", "drift", "d1", "--store", str(tmp_path), *plot])
    assert result.exit_code == 0, result.output
    assert "accel.bias[0] (+14.1)" in result.output  # 20 σ over √2 combined
    assert not PLOT or (tmp_path / "d.png").stat().st_size > 1000
    listed = CliRunner().invoke(cli, ["store", "list", "--store", str(tmp_path)])
    assert listed.output.strip() == "d1: 3 calibration(s), latest 2026-03-01"


def test_store_add_needs_a_device(cal, tmp_path):
    path = tmp_path / "cal.json"
    path.write_text(cal.to_json())
    result = CliRunner().invoke(cli, ["store", "add", str(path), "--store", str(tmp_path / "s")])
    assert result.exit_code == 2 and "--device" in result.stderr
    ok = CliRunner().invoke(
        cli, ["store", "add", str(path), "--device", "b1", "--store", str(tmp_path / "s")]
    )
    assert ok.exit_code == 0 and np.all(
        fieldcal.Store(tmp_path / "s").latest("b1").mag.gain == cal.mag.gain
    )


def test_device_id_from_the_log(tmp_path):
    """A log that names its device (``# device: ID`` above the header) needs no --device:
    calibrate records it and store add files the calibration under it."""
    log = tmp_path / "log.csv"
    assert CliRunner().invoke(cli, ["simulate", "--seed", "3", "-o", str(log)]).exit_code == 0
    log.write_text("# device: line4-unit17\n" + log.read_text())
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(cli, ["calibrate", str(log), "-o", str(out), "-q"])
    assert result.exit_code == 0, result.output
    cal = fieldcal.Calibration.from_json(out.read_text())
    assert cal.options["device"] == "line4-unit17"
    store = tmp_path / "store"
    added = CliRunner().invoke(cli, ["store", "add", str(out), "--store", str(store)])
    assert added.exit_code == 0, added.output
    (device,) = fieldcal.Store(store).devices()
    assert fieldcal.Store(store).latest(device) == cal
    assert fieldcal.Store(store).add(cal).parent.name == device  # the library too


def test_listing_a_device_calibrated_with_different_gravity_lists_it(cal, tmp_path):
    """``store list ID`` lists every calibration; two made with different --gravity are not
    compared (that failed: "different units"), and the row says so."""
    store = fieldcal.Store(tmp_path)
    store.add(_at(cal, "2026-01-01T00:00:00Z"), device="d2")
    store.add(_at(cal.with_field_magnitudes(gravity=9.80665), "2026-02-01T00:00:00Z"), device="d2")
    store.add(_at(cal.with_field_magnitudes(gravity=9.80665), "2026-03-01T00:00:00Z"), device="d2")
    rows = store.drift("d2")
    assert rows[1].since_previous is None and "different units" in rows[1].note
    assert rows[2].since_previous is not None and rows[2].note == ""  # same units: compared
    for command in ("list", "drift"):
        result = CliRunner().invoke(cli, ["store", command, "d2", "--store", str(tmp_path)])
        assert result.exit_code == 0, result.output
        assert "3 calibrations" in result.output and "not compared" in result.output
    with pytest.raises(InputError, match="sigmas must be a positive number"):
        store.drift("d2", sigmas=0)
