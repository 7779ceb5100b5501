"""What a log adds to the continuous fit (:func:`fieldcal.trust.interference_stage.
flight_options`): the interference inputs, and for a flight log the blocks held and the start."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.logs.log import Log
from fieldcal.trust.interference_stage import flight_options


def _log(frame: str | None, *, current: bool = True, attitude: bool = True) -> Log:
    n = 5
    metadata = {"log_format": "PX4 ULog"}
    if frame is not None:
        metadata["accel_frame"] = frame
    return Log(
        "f.ulg",
        np.zeros((n, 3)),
        np.zeros((n, 3)),
        np.zeros((n, 3)),
        np.arange(n, dtype=float),
        None,
        np.arange(n),
        {},
        [],
        metadata=metadata,
        inputs={"current": np.arange(n, dtype=float)} if current else {},
        attitude=np.tile([1.0, 0, 0, 0], (n, 1)) if attitude else None,
    )


def test_a_calibrated_flight_log_holds_the_autopilots_calibration_and_starts_from_its_attitude():
    options, notes = flight_options(_log("body FRD, calibrated by PX4"), None)
    assert set(options) == {"inputs", "prior", "attitude"}
    assert "PX4's calibration" in options["prior"].source
    assert any("held at PX4's calibration" in n for n in notes)


def test_a_raw_flight_log_is_held_at_nominal_values_without_the_attitude_start():
    """A raw sensor-frame stream: the autopilot's body-frame attitude is not its frame."""
    options, notes = flight_options(_log("sensor frame, uncalibrated"), None)
    assert set(options) == {"inputs", "prior"}
    assert "nominal" in options["prior"].source and "nominal values" in notes[0]


@pytest.mark.parametrize("hold", ["gyro.gain", None])
def test_blocks_the_user_holds_and_other_logs_are_left_alone(hold):
    frame = "body FRD" if hold else None  # a CSV has no accel_frame
    options, notes = flight_options(_log(frame, current=False), hold)
    assert options == {} and notes == []


def test_a_simulated_dataflash_flight_gets_the_joint_term_through_the_command_line(tmp_path):
    """A multirotor flight (the independent simulator) written as ArduPilot logs it and read
    back through pymavlink: ``fieldcal calibrate flight.bin`` holds the IMU at ArduPilot's
    calibration and fits the term jointly, within 4 standard errors of the truth."""
    pytest.importorskip("pymavlink", reason="the [dataflash] extra (pymavlink) is not installed")
    from _dataflash import write_dataflash
    from click.testing import CliRunner
    from scipy.spatial.transform import Rotation

    from fieldcal.calibration import Calibration
    from fieldcal.cli import cli
    from fieldcal.simulation.multirotor import simulate_flight

    f = simulate_flight(8, seconds=60.0, rate=25.0, interference_ut=30.0)
    yaw, pitch, roll = (
        Rotation.from_quat(f.attitude, scalar_first=True).as_euler("ZYX", degrees=True).T
    )
    msgs: list[tuple[str, tuple]] = [("PARM", (0, f"COMPASS_OFS_{a}", 0.0)) for a in "XYZ"]
    msgs += [("PARM", (0, f"COMPASS_DIA_{a}", 1.0)) for a in "XYZ"]
    msgs += [("PARM", (0, f"COMPASS_ODI_{a}", 0.0)) for a in "XYZ"]
    for k, t in enumerate(1_000_000 + np.round(f.time * 1e6).astype(int)):
        msgs.append(("IMU", (int(t), 0, *f.gyro[k], *f.accel[k], 35.0)))
        msgs.append(("MAG", (int(t) + 100, 0, *(10.0 * f.mag[k]), 0.0, 0.0, 0.0)))  # mGauss
        msgs.append(("ATT", (int(t), roll[k], pitch[k], yaw[k] % 360)))
        msgs.append(("BAT", (int(t), 0, 16.0, f.current[k])))
    path = write_dataflash(tmp_path / "flight.bin", msgs)
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(cli, ["calibrate", str(path), "--poses", "continuous", "-o", out])
    assert out.is_file(), result.output
    assert "held at ArduPilot's calibration" in result.output
    model = Calibration.from_json(out.read_text()).mag.interference
    assert model is not None and model.identifiable and "jointly" in model.trajectory
    truth = 10.0 * f.coefficients  # mGauss per A
    assert np.all(np.abs(model.coefficients[0] - truth) < 4 * model.std[0])
