"""The autopilot and tool exports, each applied the way its target applies it.

Re-implemented from the targets' published source (cited per test), applied to the parsed
file, and compared with ``cal.correct_accel`` / ``cal.correct_mag``: exactly (float32, as the
targets store their parameters), or within the bound the file states where the target cannot
hold the calibration (the compass's dropped rotation, the accelerometer's cross-axis terms).
"""

from __future__ import annotations

import dataclasses
import io
import re

import numpy as np
import pytest
import scipy.io
import yaml
from click.testing import CliRunner

import fieldcal
from fieldcal.calibration import Calibration, SensorCalibration
from fieldcal.cli import cli
from fieldcal.errors import InputError
from fieldcal.geometry.rotations import rotation_angle_deg
from fieldcal.output.exports import FORMATS, export, export_bytes

G = 9.80665


@pytest.fixture(scope="module")
def cal():
    # µT and m/s²: the units an autopilot export has to convert
    return fieldcal.simulate("paper", seed=2).truth.with_field_magnitudes(G, 48.5)


def _unit_fields(n, magnitude, seed):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return magnitude * v / np.linalg.norm(v, axis=1, keepdims=True)


def _raw(sensor, body):
    """Readings of body-frame fields ``body`` (N×3): ``gain @ v + bias``."""
    return body @ np.asarray(sensor.gain).T + np.asarray(sensor.bias)


def _f32(x):
    # both autopilots store calibration parameters as 32-bit floats
    return np.float64(np.float32(x))


def _procrustes(a, b):
    """The rotation R minimising ‖a − b Rᵀ‖ (rows are vectors)."""
    W, _, Vt = np.linalg.svd(a.T @ b)
    D = np.diag([1.0, 1.0, np.linalg.det(W @ Vt)])
    return W @ D @ Vt


def _stated(text, pattern):
    return float(re.search(pattern, text).group(1))


# --------------------------------------------------------------------------- ArduPilot
def _parse_parm(text):
    """Mission Planner / MAVProxy: ``NAME VALUE`` (space, comma or tab), ``#`` comments."""
    params = {}
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            name, value = re.split(r"[\s,]+", line)
            params[name] = _f32(float(value))
    return params


def _ardupilot_compass(p, raw):
    """ArduPilot AP_Compass_Backend::correct_field (libraries/AP_Compass/AP_Compass_Backend.cpp,
    commit 00ed6bbc2b29f35c443b509e8e53e4d0a998067a): ``mag += offsets; mag = mat * mag``."""
    ofs = np.array([p[f"COMPASS_OFS_{a}"] for a in "XYZ"])
    d = [p[f"COMPASS_DIA_{a}"] for a in "XYZ"]
    o = [p[f"COMPASS_ODI_{a}"] for a in "XYZ"]
    mat = np.array([[d[0], o[0], o[1]], [o[0], d[1], o[2]], [o[1], o[2], d[2]]])
    return (raw + ofs) @ mat.T


def _ardupilot_accel(p, raw):
    """ArduPilot AP_InertialSensor_Backend::_rotate_and_correct_accel
    (libraries/AP_InertialSensor/AP_InertialSensor_Backend.cpp): ``accel -= _accel_offset``,
    then ``accel.x *= accel_scale.x`` per axis."""
    off = np.array([p[f"INS_ACCOFFS_{a}"] for a in "XYZ"])
    scale = np.array([p[f"INS_ACCSCAL_{a}"] for a in "XYZ"])
    return (raw - off) * scale


# --------------------------------------------------------------------------- PX4
def _parse_qgc(text):
    """QGroundControl's parameter file: ``vehicle<TAB>component<TAB>name<TAB>value<TAB>type``."""
    params = {}
    for line in text.splitlines():
        if line and not line.startswith("#"):
            _, _, name, value, kind = line.split("\t")
            assert kind == "9"  # MAV_PARAM_TYPE_REAL32
            params[name] = _f32(float(value))
    return params


def _px4_mag(p, raw):
    """PX4 calibration::Magnetometer::Correct (src/lib/sensor_calibration/Magnetometer.hpp,
    commit 021ee44aee5357b60f166f8e3cc1ed1c3f0b223f): ``_scale * (data - _offset)``, the scale
    built in Magnetometer::ParametersUpdate (Magnetometer.cpp, commit 033e9cee3625): diag
    ``SCALE``, ``ODIAG`` at (0,1), (0,2), (1,2), mirrored."""
    off = np.array([p[f"CAL_MAG0_{a}OFF"] for a in "XYZ"])
    d = [p[f"CAL_MAG0_{a}SCALE"] for a in "XYZ"]
    o = [p[f"CAL_MAG0_{a}ODIAG"] for a in "XYZ"]
    scale = np.array([[d[0], o[0], o[1]], [o[0], d[1], o[2]], [o[1], o[2], d[2]]])
    return (raw - off) @ scale.T


def _px4_accel(p, raw):
    """PX4 calibration::Accelerometer::Correct (src/lib/sensor_calibration/Accelerometer.hpp,
    commit 011a4138d02c): ``(data - _thermal_offset - _offset).emult(_scale)``."""
    off = np.array([p[f"CAL_ACC0_{a}OFF"] for a in "XYZ"])
    scale = np.array([p[f"CAL_ACC0_{a}SCALE"] for a in "XYZ"])
    return (raw - off) * scale


TARGETS = {
    # name: (parser, compass, accel, compass units per µT)
    "ardupilot": (_parse_parm, _ardupilot_compass, _ardupilot_accel, 10.0),
    "px4": (_parse_qgc, _px4_mag, _px4_accel, 0.01),
}


@pytest.mark.parametrize("target", list(TARGETS))
def test_compass_is_fieldcal_rotated_by_the_stated_misalignment(cal, target):
    parse, compass, _, per_uT = TARGETS[target]
    text = export(cal, target)
    rng = np.random.default_rng(4)
    raw = rng.normal(size=(200, 3)) * 2 + np.asarray(cal.mag.bias)
    got = compass(parse(text), raw)
    want = per_uT * cal.correct_mag(raw)
    R = _procrustes(got, want)
    # the target's compass is fieldcal's, rotated (not stretched): float32 precision
    scale = np.abs(want).max()
    assert np.abs(got - want @ R.T).max() < 1e-5 * scale
    stated = _stated(text, r"rotated by ([\d.]+) deg")
    assert rotation_angle_deg(R) == pytest.approx(stated, abs=1e-3)
    # the dropped rotation is the misalignment of the two sensors' axes
    assert stated == pytest.approx(cal.misalignment_deg, abs=1e-3) and stated > 1.0


@pytest.mark.parametrize("target", list(TARGETS))
def test_accelerometer_error_is_within_and_near_the_stated_bound(cal, target):
    parse, _, accel, _ = TARGETS[target]
    text = export(cal, target)
    bound = _stated(text, r"error up to ([\d.e+-]+) m/s")
    body = _unit_fields(4000, G, seed=5)  # every direction of a 1 g specific force
    raw = _raw(cal.accel, body)
    error = np.linalg.norm(accel(parse(text), raw) - cal.correct_accel(raw), axis=1)
    assert error.max() <= bound * (1 + 1e-5)
    assert error.max() >= 0.95 * bound  # the bound is the worst case, not a loose guess
    # a calibration with no cross-axis terms loses nothing: exact to float32
    diagonal = dataclasses.replace(
        cal, accel=dataclasses.replace(cal.accel, gain=np.diag(np.diag(cal.accel.gain)))
    )
    text = export(diagonal, target)
    assert _stated(text, r"error up to ([\d.e+-]+) m/s") == 0.0
    got = accel(parse(text), raw)
    assert np.abs(got - diagonal.correct_accel(raw)).max() < 1e-5 * G


@pytest.mark.parametrize(("strength", "unit"), [(48.5, "µT"), (0.485, "G"), (485.0, "mG")])
def test_field_strength_units_are_read_from_their_size(strength, unit):
    cal = fieldcal.simulate("paper", seed=2).truth.with_field_magnitudes(G, strength)
    body = _unit_fields(50, strength, seed=6)
    raw = _raw(cal.mag, body)
    for target, expected in (("ardupilot", 485.0), ("px4", 0.485)):
        parse, compass, _, _ = TARGETS[target]
        got = np.linalg.norm(compass(parse(export(cal, target)), raw), axis=1)
        np.testing.assert_allclose(got, expected, rtol=1e-5, err_msg=f"{target}, {unit}")


def test_autopilot_exports_refuse_what_they_cannot_hold(cal):
    unscaled = fieldcal.simulate("paper", seed=2).truth  # |h| = 1: no field strength
    mirrored = dataclasses.replace(
        cal, mag=dataclasses.replace(cal.mag, gain=np.asarray(cal.mag.gain) * [1, 1, -1])
    )
    odd_g = cal.with_field_magnitudes(3.0, None)
    for target in TARGETS:
        for bad, words in (
            (unscaled, "--field-strength"),
            (mirrored, "mirrored"),
            (odd_g, "--gravity 9.80665"),
        ):
            with pytest.raises(InputError, match=words) as info:
                export(bad, target)
            assert "\n" not in str(info.value)


# --------------------------------------------------------------------------- .mat
def test_mat_file_reads_back_and_applies_like_magcal(cal, tmp_path):
    data = scipy.io.loadmat(io.BytesIO(export_bytes(cal, "mat")))
    raw = np.random.default_rng(7).normal(size=(50, 3)) * 2
    # magcal's convention, C = (D - b) * A: doubles, bit for bit the same numbers
    for name, correct in (("accel", cal.correct_accel), ("mag", cal.correct_mag)):
        A, b = data[f"A_{name}"], data[f"b_{name}"]
        assert A.shape == (3, 3) and b.shape == (1, 3)
        np.testing.assert_allclose((raw - b) @ A, correct(raw), rtol=1e-12, atol=1e-12)
    assert str(data["formula"][0]) == FORMATS["mat"].formula
    assert "fieldcal" in str(data["provenance"][0])
    with pytest.raises(InputError, match=r"-o FILE\.mat"):
        export(cal, "mat")


def test_cli_writes_the_mat_file_and_refuses_stdout(cal, tmp_path):
    path = tmp_path / "cal.json"
    path.write_text(cal.to_json())
    out = tmp_path / "cal.mat"
    result = CliRunner().invoke(cli, ["export", str(path), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_bytes() == export_bytes(Calibration.from_json(cal.to_json()), "mat")
    result = CliRunner().invoke(cli, ["export", str(path), "--format", "mat"])
    assert result.exit_code == 2 and "-o FILE.mat" in result.output


# --------------------------------------------------------------------------- Kalibr
def _with_gyro(cal, rate):
    rng = np.random.default_rng(8)
    gyro = SensorCalibration(
        gain=np.eye(3) * 50.0 + rng.normal(scale=0.5, size=(3, 3)),
        bias=rng.normal(size=3),
        noise_cov=np.diag([0.04, 0.09, 0.0625]),
    )
    options = {**cal.options, "rate": rate} if rate is not None else dict(cal.options)
    return dataclasses.replace(cal, gyro=gyro, options=options, units={})


def test_kalibr_densities_are_the_corrected_sample_noise_over_root_rate(cal):
    """Independent check: correct simulated noisy samples and measure their spread."""
    rate = 200.0
    full = _with_gyro(cal, rate)
    doc = yaml.safe_load(export(full, "kalibr"))
    assert doc["update_rate"] == rate
    assert "accelerometer_random_walk" not in doc and "gyroscope_random_walk" not in doc
    rng = np.random.default_rng(9)
    n = 20_000
    for key, sensor, correct in (
        ("accelerometer_noise_density", full.accel, full.correct_accel),
        ("gyroscope_noise_density", full.gyro, full.correct_gyro),
    ):
        noise = rng.multivariate_normal(np.zeros(3), np.asarray(sensor.noise_cov), size=n)
        samples = correct(np.asarray(sensor.bias) + noise)  # a still sensor reading zero
        measured = samples.std(axis=0).max() / np.sqrt(rate)
        # 20000 samples: the standard deviation is known to 0.5 %; 3 % is far outside chance
        assert doc[key] == pytest.approx(measured, rel=0.03)


def test_kalibr_refuses_without_gyroscope_or_rate(cal):
    for bad, words in (
        (cal, "no gyroscope"),
        (_with_gyro(cal, None), "no sample rate"),
    ):
        with pytest.raises(InputError, match=words) as info:
            export(bad, "kalibr")
        assert "fieldcal noise LOG --export kalibr" in str(info.value)
        assert "\n" not in str(info.value)
