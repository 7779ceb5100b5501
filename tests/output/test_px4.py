"""The ``px4`` export (fieldcal.output.exports.px4) on a hand-built calibration in gauss: every
parameter a known answer in QGroundControl's layout, the ids on every line, and the thermal
compensation's ``TC_*`` parameters from known temperature terms."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from _known import ACCEL_BIAS, ACCEL_GAIN, MAG_BIAS, MAG_GAIN, known_calibration

from fieldcal.errors import InputError
from fieldcal.output.exports import px4
from fieldcal.thermal import TemperatureModel


def _in_gauss():
    return known_calibration().with_raw_scale({"mag": 1e-3})  # raw milligauss -> gauss


def _rows(text: str) -> list[list[str]]:
    return [line.split("\t") for line in text.splitlines() if line and not line.startswith("#")]


def test_parameters_are_the_known_answers():
    rows = _rows(px4.write(_in_gauss(), sysid=4, compid=2))
    assert all(r[:2] == ["4", "2"] and r[4] == "9" for r in rows)  # MAV_PARAM_TYPE_REAL32
    got = {r[2]: float(r[3]) for r in rows}
    # gauss = S (raw - off): raw gauss = 1e-3 MAG_GAIN µT, S = 0.01 G/µT x inv(1e-3 MAG_GAIN)
    S = 10.0 * np.linalg.inv(MAG_GAIN)
    expected = {f"CAL_MAG0_{a}OFF": 1e-3 * MAG_BIAS[i] for i, a in enumerate("XYZ")}
    expected |= {f"CAL_MAG0_{a}SCALE": S[i, i] for i, a in enumerate("XYZ")}
    expected |= {"CAL_MAG0_XODIAG": S[0, 1], "CAL_MAG0_YODIAG": S[0, 2], "CAL_MAG0_ZODIAG": S[1, 2]}
    expected |= {f"CAL_ACC0_{a}OFF": ACCEL_BIAS[i] for i, a in enumerate("XYZ")}
    expected |= {f"CAL_ACC0_{a}SCALE": 1 / ACCEL_GAIN[i, i] for i, a in enumerate("XYZ")}
    assert list(got) == list(expected)
    for name, value in expected.items():
        assert got[name] == pytest.approx(value, rel=1e-12), name


def test_offsets_in_milligauss_are_refused_as_outside_pxs_range():
    with pytest.raises(InputError, match=r"CAL_MAG0_XOFF = 100 is outside .* \[-1\.3, 1\.3\]"):
        px4.write(known_calibration())


def test_thermal_parameters_from_known_terms():
    cal = _in_gauss()
    model = TemperatureModel(
        reference=25.0, coefficients=np.array([[1e-3, -2e-3, 3e-3]]), span=np.array([10.0, 40.0])
    )
    cal = dataclasses.replace(cal, accel=dataclasses.replace(cal.accel, temperature=model))
    params = dict(px4.thermal_parameters(cal))
    assert params["TC_A0_X1_0"] == 1e-3 and params["TC_A0_X1_2"] == 3e-3
    assert all(params[f"TC_A0_X{k}_{i}"] == 0.0 for k in (0, 2, 3) for i in range(3))
    assert (params["TC_A0_TREF"], params["TC_A0_TMIN"], params["TC_A0_TMAX"]) == (25.0, 10.0, 40.0)
    assert len(params) == 15
    text = px4.write(cal)
    rows = {r[2]: r for r in _rows(text)}
    assert rows["TC_A_ENABLE"][3:] == ["1", "6"]  # MAV_PARAM_TYPE_INT32
    assert float(rows["TC_A0_X1_1"][3]) == -2e-3
    assert px4.thermal_parameters(_in_gauss()) == []
