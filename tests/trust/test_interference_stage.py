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
