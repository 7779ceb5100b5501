"""The ``ardupilot`` export (fieldcal.output.exports.ardupilot) on a hand-built calibration:
every parameter a known answer, read back by pymavlink's parameter reader, and the ranges
ArduPilot accepts enforced at their bounds."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from _known import ACCEL_BIAS, ACCEL_GAIN, MAG_BIAS, MAG_GAIN, known_calibration

from fieldcal.errors import InputError
from fieldcal.output.exports import ardupilot


def _params(text: str) -> dict[str, float]:
    return {
        name: float(value)
        for name, value in (line.split() for line in text.splitlines() if not line.startswith("#"))
    }


def _expected() -> dict[str, float]:
    # compass mG = M (raw - bias), M = 10 mG/µT x inv(gain) (the gain is symmetric: no rotation
    # dropped); accelerometer (raw - bias) * 1/diag(gain)
    M = 10.0 * np.linalg.inv(MAG_GAIN)
    out = {f"COMPASS_OFS_{a}": -MAG_BIAS[i] for i, a in enumerate("XYZ")}
    out |= {f"COMPASS_DIA_{a}": M[i, i] for i, a in enumerate("XYZ")}
    out |= dict(
        zip(
            ("COMPASS_ODI_X", "COMPASS_ODI_Y", "COMPASS_ODI_Z"),
            (M[0, 1], M[0, 2], M[1, 2]),
            strict=True,
        )
    )
    out |= {f"INS_ACCOFFS_{a}": ACCEL_BIAS[i] for i, a in enumerate("XYZ")}
    out |= {f"INS_ACCSCAL_{a}": 1.0 / ACCEL_GAIN[i, i] for i, a in enumerate("XYZ")}
    return out


def test_parameters_are_the_known_answers():
    got = _params(ardupilot.write(known_calibration()))
    expected = _expected()
    assert list(got) == list(expected)
    for name, value in expected.items():
        assert got[name] == pytest.approx(value, rel=1e-12, abs=1e-15), name


def test_pymavlink_reads_the_same_numbers(tmp_path):
    mavparm = pytest.importorskip(
        "pymavlink.mavparm", reason="pymavlink (test extra) not installed"
    )
    path = tmp_path / "cal.parm"
    path.write_text(ardupilot.write(known_calibration()))
    params = mavparm.MAVParmDict()
    params.load(str(path))
    expected = _expected()
    assert set(params) == set(expected)
    for name, value in expected.items():
        assert params[name] == pytest.approx(value, rel=1e-12, abs=1e-15), name


def test_the_compass_offsets_length_is_checked_beyond_each_axis():
    # each axis inside ±1800 mG but the length 1905 over COMPASS_OFFS_MAX (the arming check)
    cal = known_calibration()
    far = dataclasses.replace(cal, mag=dataclasses.replace(cal.mag, bias=np.full(3, 1100.0)))
    with pytest.raises(InputError, match=r"length of COMPASS_OFS_X/Y/Z = 1905\.26 mG exceeds"):
        ardupilot.write(far)
    text = ardupilot.write(far, allow_out_of_range=True)
    assert "# OUT OF RANGE (--allow-out-of-range): the length of COMPASS_OFS_X/Y/Z" in text
    assert _params(text)["COMPASS_OFS_X"] == -1100.0


def test_every_range_is_ardupilots():
    by_template = {r.template: r for r in ardupilot.RANGES}
    assert by_template["INS_ACCSCAL_{}"].accepts(1.2) and not by_template["INS_ACCSCAL_{}"].accepts(
        1.2001
    )
    assert not by_template["COMPASS_DIA_{}"].accepts(0.2)  # strict: fit_acceptable uses <
    assert by_template["COMPASS_OFS_{}"].text() == "(-1800, 1800)"
    assert by_template["INS_ACCOFFS_{}"].text() == "[-3.5, 3.5]"
