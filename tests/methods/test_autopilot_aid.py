"""What a flight log's autopilot gives the continuous fit (:mod:`fieldcal.methods.continuous.
autopilot_aid`): its calibration held, its attitude as the start."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fieldcal.methods.continuous.autopilot_aid import (
    attitude_start,
    autopilot_held,
    quaternion_rotations,
)
from fieldcal.methods.continuous.initial import start
from fieldcal.methods.continuous.model import Data, mag_block
from fieldcal.simulation.multirotor import simulate_flight

ULOGS = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "px4-ulog"


def test_quaternions_become_world_to_body_matrices_as_scipy_has_them():
    q = Rotation.random(5, random_state=1)
    scalar_first = q.as_quat(scalar_first=True)
    assert quaternion_rotations(scalar_first) == pytest.approx(q.inv().as_matrix(), abs=1e-12)


def test_held_blocks_are_the_accelerometer_and_the_gyroscopes_gain():
    held = autopilot_held("PX4")
    assert held.names == ("accel.gain", "accel.bias", "gyro.gain")
    assert np.flatnonzero(held.mask).tolist() == [*range(9), *range(22, 31)]
    assert held.values["accel.gain"].reshape(3, 3) == pytest.approx(9.80665 * np.eye(3))
    assert "PX4" in held.source


def test_attitude_start_fits_the_readings_it_starts_from():
    """From the autopilot's (perfect) attitude, the start's magnetometer explains the readings
    to the sensor's noise apart from the interference (not in ``inputs`` here)."""
    flight = simulate_flight(3, seconds=40.0, rate=25.0, interference_ut=5.0, attitude_error_deg=0)
    data = Data(flight.time, flight.accel, flight.mag, flight.gyro)
    state = attitude_start(start(data), data, flight.attitude)
    dip = np.arcsin(flight.field[2] / np.linalg.norm(flight.field))
    assert state.dip == pytest.approx(dip, abs=np.radians(1.0))
    residual = mag_block(state, data.mag).residual
    assert np.sqrt(np.mean(residual**2)) < 2.0  # µT: the 5 µT term's share, the 0.3 µT noise


def test_real_ulog_holds_the_autopilots_calibration_and_judges_the_compass(tmp_path):
    """PX4's sample log through ``fieldcal calibrate``: the accelerometer held at PX4's
    calibration (said in the report), no refusal for the missing tilts; the verdict fails on
    what the 6 s log cannot determine (the compass), not on the gyroscope's unit."""
    pytest.importorskip("pyulog", reason="the [ulog] extra (pyulog) is not installed")
    path = ULOGS / "sample_log_small.ulg"
    if not path.is_file():
        pytest.skip(f"{path} is absent (../shared/data beside the repository)")
    from click.testing import CliRunner

    from fieldcal.cli import cli

    out = tmp_path / "cal.json"
    result = CliRunner().invoke(cli, ["calibrate", str(path), "-o", str(out)])
    assert result.exit_code == 3, result.output
    assert "held at PX4's calibration" in result.output
    doc = json.loads(out.read_text())
    cal = doc.get("calibration", doc)
    assert cal["accel"]["bias"] == pytest.approx([0.0, 0.0, 0.0])
    codes = {r["code"] for r in cal["verdict"]["reasons"]}
    assert "continuous_undetermined" in codes
    assert "gyro_units" not in codes and "implausible_gain" not in codes
    assert "interference_not_identifiable" in codes


def test_real_ulog_with_gps_is_scaled_to_the_models_field_and_exports_to_px4(tmp_path):
    """A flight log with a GPS fix: the magnetometer scaled to the World Magnetic Model's
    intensity there in the log's own unit (gauss for PX4), so ``fieldcal export --format px4``
    writes the parameters instead of asking for a field strength; the log's placeholder
    temperature (a simulator's constant 0 °C) is no thermometer."""
    pytest.importorskip("pyulog", reason="the [ulog] extra (pyulog) is not installed")
    path = ULOGS / "sample_px4_events.ulg"
    if not path.is_file():
        pytest.skip(f"{path} is absent (../shared/data beside the repository)")
    from click.testing import CliRunner

    from fieldcal.cli import cli
    from fieldcal.reference import expected_field

    out, params = tmp_path / "cal.json", tmp_path / "cal.params"
    result = CliRunner().invoke(cli, ["calibrate", str(path), "-o", str(out)])
    assert result.exit_code in (0, 1, 3), result.output
    from fieldcal import Calibration

    cal = Calibration.from_json(out.read_text())
    assert cal.field_reference is not None
    ref = cal.field_reference
    model = expected_field((ref.latitude_deg, ref.longitude_deg, ref.altitude_m), ref.date)
    assert cal.field_strength == pytest.approx(model.intensity_in("G"), rel=1e-6)
    assert 0.2 < model.intensity_in("G") < 0.7  # Zürich: about 0.48 G
    doc = json.loads(out.read_text())
    codes = {r["code"] for r in doc["verdict"]["reasons"]}
    assert "temperature_span" not in codes
    exported = CliRunner().invoke(cli, ["export", str(out), "--format", "px4", "-o", str(params)])
    assert exported.exit_code == 0, exported.output
    text = params.read_text()
    assert "CAL_MAG0_XSCALE" in text
    assert text.count("# Power compensation") <= 1
