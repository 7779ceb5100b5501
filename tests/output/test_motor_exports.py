"""The interference term exported as ArduPilot's COMPASS_MOT and PX4's CAL_MAG*_COMP, checked
by evaluating each firmware's formula (cited in fieldcal.output.exports.motor_comp) on the
parsed file: with the compensation, a reading carrying the interference comes out as the
calibration without it gives the clean reading."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import fieldcal
from fieldcal.interference import InterferenceModel
from fieldcal.output.exports import export

G = 9.80665


def _f32(x):
    return float(np.float32(x))  # both autopilots store their parameters as 32-bit floats


def _parse_parm(text):
    """Mission Planner / MAVProxy: ``NAME VALUE``, ``#`` comments."""
    rows = (ln.split() for ln in text.splitlines() if ln.strip() and not ln.startswith("#"))
    return {name: _f32(value) for name, value in rows}


def _parse_qgc(text):
    """QGroundControl: ``vehicle<TAB>component<TAB>name<TAB>value<TAB>type``."""
    rows = (ln.split("\t") for ln in text.splitlines() if ln and not ln.startswith("#"))
    return {name: _f32(value) for _, _, name, value, _ in rows}


C = np.array([0.8, -0.3, 0.5])  # µT per A, raw units of the fixture
MEAN_CURRENT = 18.0


def _with_term(cal, *, identifiable=True, kind="current"):
    per = 10.0 if np.abs(cal.mag.gain).max() > 1 else 0.01
    model = InterferenceModel(
        (kind,),
        ("A",),
        [C * per if identifiable else np.zeros(3)],
        [MEAN_CURRENT],
        [[0.01] * 3],
        [[0.001] * 3],
        [[3.0, 45.0]],
        identifiable=identifiable,
        reason="" if identifiable else "current never exceeded 2 A: hover longer",
        field_share=0.2,
    )
    return dataclasses.replace(cal, mag=dataclasses.replace(cal.mag, interference=model))


PER_UT = {"ardupilot": 10.0, "px4": 0.01}  # raw compass units per µT the drivers deliver


def _device(target):
    """The paper's truth for raw readings in the target's units (mG, gauss; m/s²), with
    biases a real board shows: the parameters then lie in the ranges the autopilots accept."""
    cal = fieldcal.simulate("paper", seed=2).truth.with_field_magnitudes(G, 48.5)
    per = PER_UT[target]
    cal = cal.with_raw_scale(
        {
            "accel": 1.0 / float(np.mean(np.diag(cal.accel.gain))),
            "mag": per / float(np.mean(np.diag(cal.mag.gain))),
        }
    )
    b, a = np.asarray(cal.mag.bias), np.asarray(cal.accel.bias)
    return dataclasses.replace(
        cal,
        accel=dataclasses.replace(cal.accel, bias=a / np.abs(a).max()),
        mag=dataclasses.replace(cal.mag, bias=b * 10.0 * per / np.abs(b).max()),
    )


def _readings(cal, seed):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(50, 3))
    v = 48.5 * v / np.linalg.norm(v, axis=1, keepdims=True)
    clean = v @ np.asarray(cal.mag.gain).T + np.asarray(cal.mag.bias)
    u = rng.uniform(0.0, 60.0, 50)
    c = cal.mag.interference.coefficients[0] if cal.mag.interference is not None else C
    return clean, clean + (u - MEAN_CURRENT)[:, None] * c, u


def _ardupilot(p, raw, u, suffix=""):
    """AP_Compass_Backend::correct_field: mag += offsets; mag = mat * mag; mag += mot * u."""
    ofs = np.array([p[f"COMPASS_OFS_{a}"] for a in "XYZ"])
    d = [p[f"COMPASS_DIA_{a}"] for a in "XYZ"]
    o = [p[f"COMPASS_ODI_{a}"] for a in "XYZ"]
    mat = np.array([[d[0], o[0], o[1]], [o[0], d[1], o[2]], [o[1], o[2], d[2]]])
    mot = np.array([p.get(f"COMPASS_MOT{suffix}_{a}", 0.0) for a in "XYZ"])
    on = p.get("COMPASS_MOTCT", 0.0) == 2.0
    return (raw + ofs) @ mat.T + (u[:, None] * mot if on else 0.0)


def _px4(p, raw, u):
    """Magnetometer::Correct: _scale * ((data + _power * _power_compensation) - _offset), with
    power = current_a * 0.001f (VehicleMagnetometer::UpdatePowerCompensation, type 2)."""
    off = np.array([p[f"CAL_MAG0_{a}OFF"] for a in "XYZ"])
    d = [p[f"CAL_MAG0_{a}SCALE"] for a in "XYZ"]
    o = [p[f"CAL_MAG0_{a}ODIAG"] for a in "XYZ"]
    scale = np.array([[d[0], o[0], o[1]], [o[0], d[1], o[2]], [o[1], o[2], d[2]]])
    comp = np.array([p.get(f"CAL_MAG0_{a}COMP", 0.0) for a in "XYZ"])
    on = p.get("CAL_MAG_COMP_TYP", 0.0) == 2.0
    power = u * 0.001 if on else 0.0 * u
    return (raw + power[:, None] * comp - off) @ scale.T


def test_ardupilot_motor_compensation_as_correct_field_applies_it(tmp_path):
    cal = _device("ardupilot")
    clean, loaded, u = _readings(_with_term(cal), 1)
    plain = _parse_parm(export(cal, "ardupilot"))
    text = export(_with_term(cal), "ardupilot")
    params = _parse_parm(text)
    assert params["COMPASS_MOTCT"] == 2.0
    expected = _ardupilot(plain, clean, u)
    got = _ardupilot(params, loaded, u)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(got, expected, atol=2e-6 * scale)
    # without the compensation the interference stays: hundreds of mG here
    assert np.abs(_ardupilot(plain, loaded, u) - expected).max() > 100.0
    mavparm = pytest.importorskip("pymavlink.mavparm", reason="pymavlink (test extra) missing")
    path = tmp_path / "cal.parm"
    path.write_text(text)
    loaded_params = mavparm.MAVParmDict()
    loaded_params.load(str(path))
    assert {f"COMPASS_MOT_{a}" for a in "XYZ"} | {"COMPASS_MOTCT"} <= set(loaded_params)


def test_px4_power_compensation_as_correct_applies_it():
    cal = _device("px4")
    clean, loaded, u = _readings(_with_term(cal), 2)
    plain = _parse_qgc(export(cal, "px4"))
    text = export(_with_term(cal), "px4")
    lines = [ln.split("\t") for ln in text.splitlines() if ln and not ln.startswith("#")]
    kinds = {name: kind for _, _, name, _, kind in lines}
    assert kinds["CAL_MAG_COMP_TYP"] == "6"  # MAV_PARAM_TYPE_INT32
    params = {name: float(value) for _, _, name, value, _ in lines}
    assert params["CAL_MAG_COMP_TYP"] == 2
    expected = _px4(plain, clean, u)
    got = _px4(params, loaded, u)
    np.testing.assert_allclose(got, expected, atol=2e-6 * np.abs(expected).max())
    # the sign and unit: -c per kA, in the raw unit PX4 takes (the file's factor to gauss)
    c = _with_term(cal).mag.interference.coefficients[0]
    assert params["CAL_MAG0_XCOMP"] == pytest.approx(-1000.0 * c[0], rel=1e-6)
    assert params["CAL_MAG0_ZCOMP"] == pytest.approx(-1000.0 * c[2], rel=1e-6)


def test_unidentified_term_is_not_exported():
    cal = _device("ardupilot")
    text = export(_with_term(cal, identifiable=False), "ardupilot")
    assert "COMPASS_MOT" not in text.replace("# Motor compensation not written", "")
    assert "hover longer" in text
    assert _parse_parm(text) == _parse_parm(export(cal, "ardupilot"))


def test_second_compass_gets_its_own_names():
    cal = _with_term(_device("ardupilot"))
    cal = dataclasses.replace(cal, options={**cal.options, "mag_instance": 1})
    params = _parse_parm(export(cal, "ardupilot"))
    assert {f"COMPASS_{g}2_X" for g in ("OFS", "DIA", "ODI", "MOT")} <= set(params)
    assert "COMPASS_OFS_X" not in params and params["COMPASS_MOTCT"] == 2.0
    px4 = _with_term(_device("px4"))
    px4 = dataclasses.replace(px4, options={**px4.options, "mag_instance": 1})
    assert {"CAL_MAG1_XOFF", "CAL_MAG1_XCOMP"} <= set(_parse_qgc(export(px4, "px4")))


def test_c_library_applies_the_term(tmp_path):
    """fieldcal_mag_driven takes c (u - u_ref) off the raw reading, then the calibration:
    equal to the calibration of the clean reading to float32 precision; without a term the
    library is as before (no such function)."""
    import ctypes

    from _clib import Library, v3

    cal = _with_term(fieldcal.calibrate(*_table1()))
    lib = Library(cal, tmp_path / "lib")
    P, f = ctypes.POINTER, ctypes.c_float
    lib.lib.fieldcal_mag_driven.argtypes = [P(type(lib.factory)), P(f), f, P(f)]
    clean, loaded, u = _readings(cal, 3)
    out = (ctypes.c_float * 3)()
    got = []
    for raw, amps in zip(loaded, u, strict=True):
        lib.lib.fieldcal_mag_driven(ctypes.byref(lib.factory), v3(raw), amps, out)
        got.append(list(out))
    want = cal.correct_mag(clean)
    np.testing.assert_allclose(got, want, atol=1e-4 * np.abs(want).max())
    plain = Library(fieldcal.calibrate(*_table1()), tmp_path / "plain")
    assert "fieldcal_mag_driven" not in (plain.folder / "fieldcal_cal.h").read_text()


def _table1():
    session = fieldcal.simulate("paper", seed=3)
    return session.accel, session.mag
