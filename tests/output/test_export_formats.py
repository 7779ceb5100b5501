"""The autopilot and tool exports, each applied the way its target applies it.

Re-implemented from the targets' published source (cited per test), applied to the parsed
file, and compared with ``cal.correct_accel`` / ``cal.correct_mag``: exactly (float32, as the
targets store their parameters), or within the bound the file states where the target cannot
hold the calibration (the compass's dropped rotation, the accelerometer's cross-axis terms).
"""

from __future__ import annotations

import dataclasses
import io
import json
import re
import warnings

import numpy as np
import pytest
import scipy.io
from click.testing import CliRunner

import fieldcal
from fieldcal.calibration import Calibration, Reason, SensorCalibration, Verdict
from fieldcal.cli import cli
from fieldcal.errors import InputError
from fieldcal.geometry.rotations import rotation_angle_deg
from fieldcal.noise import characterise_noise
from fieldcal.output.exports import FORMATS, export, export_bytes, export_files, kalibr
from fieldcal.output.exports.common import verdict_line

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


def _device(cal, target):
    """``cal`` for raw readings in the units the target's drivers deliver (ArduPilot's compass
    in mG, PX4's in gauss, both accelerometers in m/s²), with biases a real board shows
    (1 m/s², 100 mG): the values then lie inside the ranges the autopilots accept."""
    per_uT = TARGETS[target][3]  # raw compass units per µT
    scales = {
        "accel": 1.0 / float(np.mean(np.diag(cal.accel.gain))),
        "mag": per_uT / float(np.mean(np.diag(cal.mag.gain))),
    }
    scaled = cal.with_raw_scale(scales)

    def biased(sensor, size):
        b = np.asarray(sensor.bias)
        return dataclasses.replace(sensor, bias=b * (size / np.abs(b).max()))

    return dataclasses.replace(
        scaled, accel=biased(scaled.accel, 1.0), mag=biased(scaled.mag, 100.0 * per_uT / 10.0)
    )


@pytest.mark.parametrize("target", list(TARGETS))
def test_compass_is_fieldcal_rotated_by_the_stated_misalignment(cal, target):
    parse, compass, _, per_uT = TARGETS[target]
    cal = _device(cal, target)
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
    cal = _device(cal, target)
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
        # raw units of one field: the matrices are far outside the autopilots' ranges
        text = export(cal, target, allow_out_of_range=True)
        got = np.linalg.norm(compass(parse(text), raw), axis=1)
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
    written = out.read_bytes()
    expected = export_bytes(Calibration.from_json(cal.to_json()), "mat")
    # byte for byte after the 116-byte text header, which states the second it was written
    assert written[:10] == expected[:10] == b"MATLAB 5.0" and written[116:] == expected[116:]
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
    got_rate, accel, gyro = kalibr.kalibr_noise(full)
    assert got_rate == rate
    rng = np.random.default_rng(9)
    n = 20_000
    for got, sensor, correct in (
        (accel, full.accel, full.correct_accel),
        (gyro, full.gyro, full.correct_gyro),
    ):
        noise = rng.multivariate_normal(np.zeros(3), np.asarray(sensor.noise_cov), size=n)
        samples = correct(np.asarray(sensor.bias) + noise)  # a still sensor reading zero
        measured = samples.std(axis=0) / np.sqrt(rate)
        # 20000 samples: the standard deviation is known to 0.5 %; 3 % is far outside chance
        np.testing.assert_allclose(got, measured, rtol=0.03)


@pytest.mark.parametrize("fmt", ["kalibr", "openvins"])
def test_imu_yaml_from_a_calibration_is_refused_not_commented_out(cal, fmt):
    """A calibration has no random walks: refused in one line naming fieldcal noise."""
    with pytest.raises(InputError) as info:
        export(_with_gyro(cal, 200.0), fmt)
    message = str(info.value)
    assert "random_walk" in message and f"fieldcal noise LOG --export {fmt}" in message
    assert "\n" not in message


def test_kalibr_refuses_without_gyroscope_or_rate(cal):
    for bad, words in (
        (cal, "no gyroscope"),
        (_with_gyro(cal, None), "no sample rate"),
    ):
        with pytest.raises(InputError, match=words) as info:
            export(bad, "kalibr")
        assert "fieldcal noise LOG --export kalibr" in str(info.value)
        assert "\n" not in str(info.value)


def _noise_report():
    """``fieldcal noise`` on 200 s of a still IMU (m/s², rad/s) at 100 Hz."""
    rng = np.random.default_rng(21)
    n, rate = 20_000, 100.0
    a = rng.normal(scale=2e-3, size=(n, 3)) + np.array([0.0, 0.0, G])
    g = rng.normal(scale=5e-4, size=(n, 3))
    log = {"t": np.arange(n) / rate}
    log.update({f"a{x}": a[:, i] for i, x in enumerate("xyz")})
    log.update({f"g{x}": g[:, i] for i, x in enumerate("xyz")})
    return characterise_noise(log, accel_unit="m/s^2", gyro_unit="rad/s")


KALIBR_KEYS = {
    "accelerometer_noise_density",
    "accelerometer_random_walk",
    "gyroscope_noise_density",
    "gyroscope_random_walk",
    "update_rate",
}


def test_kalibr_yaml_loads_with_every_figure_as_a_value():
    yaml = pytest.importorskip("yaml", reason="pyyaml (the test extra) not installed")
    report = _noise_report()
    doc = yaml.safe_load(report.kalibr_yaml())
    assert set(doc) == KALIBR_KEYS | {"rostopic"}
    assert doc["rostopic"] == "/imu0" and doc["update_rate"] == pytest.approx(100.0)
    assert all(isinstance(doc[k], float) and doc[k] > 0 for k in KALIBR_KEYS)
    # white noise of sigma per sample at 100 Hz: density sigma / sqrt(100), within 5 %
    assert doc["accelerometer_noise_density"] == pytest.approx(2e-4, rel=0.05)
    assert doc["gyroscope_noise_density"] == pytest.approx(5e-5, rel=0.05)


def test_openvins_yaml_loads_with_opencv_filestorage(tmp_path):
    """OpenVINS reads kalibr_imu_chain.yaml with cv::FileStorage: so does this test."""
    yaml = pytest.importorskip("yaml", reason="pyyaml (the test extra) not installed")
    cv2 = pytest.importorskip("cv2", reason="opencv-python-headless (the test extra) not installed")
    report = _noise_report()
    kalibr_doc = yaml.safe_load(report.kalibr_yaml())
    path = tmp_path / "kalibr_imu_chain.yaml"
    path.write_text(report.openvins_yaml())
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert fs.isOpened()
    imu0 = fs.getNode("imu0")
    assert imu0.isMap()
    for key in KALIBR_KEYS:
        assert imu0.getNode(key).real() == pytest.approx(kalibr_doc[key], rel=1e-6), key
    assert imu0.getNode("rostopic").string() == "/imu0"
    assert imu0.getNode("model").string() == "kalibr"
    T = imu0.getNode("T_i_b")
    assert T.size() == 4 and [T.at(i).at(i).real() for i in range(4)] == [1.0] * 4
    for name, diagonal in (("Tw", 1.0), ("R_IMUtoGYRO", 1.0), ("Ta", 1.0), ("Tg", 0.0)):
        node = imu0.getNode(name)
        rows = [[node.at(i).at(j).real() for j in range(3)] for i in range(3)]
        np.testing.assert_array_equal(rows, diagonal * np.eye(3), err_msg=name)
    fs.release()


# --------------------------------------------------------------------------- the real readers
def test_parm_loads_in_pymavlink_with_every_name_an_ardupilot_parameter(cal, tmp_path):
    mavparm = pytest.importorskip("pymavlink.mavparm", reason="pymavlink (test extra) missing")
    device = _device(cal, "ardupilot")
    text = export(device, "ardupilot")
    path = tmp_path / "cal.parm"
    path.write_text(text)
    params = mavparm.MAVParmDict()
    params.load(str(path))
    # the names cited from ArduPilot's source (AP_Compass.cpp, AP_InertialSensor.cpp var_info)
    names = {
        f"{group}_{axis}"
        for group in ("COMPASS_OFS", "COMPASS_DIA", "COMPASS_ODI", "INS_ACCOFFS", "INS_ACCSCAL")
        for axis in "XYZ"
    }
    assert set(params) == names
    expected = _parse_parm(text)
    for name in names:
        assert _f32(params[name]) == expected[name]


def test_params_file_carries_the_vehicle_and_component_ids(cal):
    device = _device(cal, "px4")
    default = export(device, "px4")
    assert "# Vehicle 1, component 1" in default
    text = export(device, "px4", sysid=7, compid=3)
    lines = [line for line in text.splitlines() if line and not line.startswith("#")]
    assert len(lines) == 15
    assert all(line.split("\t")[:2] == ["7", "3"] for line in lines)
    assert "# Vehicle 7, component 3" in text
    assert _parse_qgc(text) == _parse_qgc(default)
    for bad in (0, 256, True):
        with pytest.raises(InputError, match="--sysid") as info:
            export(device, "px4", sysid=bad)
        assert "\n" not in str(info.value)
    with pytest.raises(InputError, match="does not take sysid"):
        export(device, "ardupilot", sysid=2)


# --------------------------------------------------------------------------- autopilot ranges
def test_ardupilot_refuses_the_issue_example_and_writes_it_marked_when_allowed(cal, tmp_path):
    """An accelerometer logged in g exported as m/s² (INS_ACCSCAL about 9.8, as in the
    ck-explorer report): refused with the parameter, its value and the range, in one line."""
    in_g = _device(cal, "ardupilot").with_raw_scale({"accel": 1.0 / G})
    with pytest.raises(InputError) as info:
        export(in_g, "ardupilot")
    message = str(info.value)
    assert re.search(r"INS_ACCSCAL_[XYZ] = 9\.\d+ is outside .* \[0\.8, 1\.2\]", message)
    assert "--allow-out-of-range" in message and "\n" not in message
    text = export(in_g, "ardupilot", allow_out_of_range=True)
    marked = [line for line in text.splitlines() if line.startswith("# OUT OF RANGE")]
    assert len(marked) == 3 and all("INS_ACCSCAL" in line for line in marked)
    mavparm = pytest.importorskip("pymavlink.mavparm", reason="pymavlink (test extra) missing")
    path = tmp_path / "marked.parm"
    path.write_text(text)
    params = mavparm.MAVParmDict()
    params.load(str(path))
    assert len(params) == 15 and params["INS_ACCSCAL_X"] > 9


@pytest.mark.parametrize(
    ("target", "change", "name"),
    [
        ("ardupilot", {"mag_bias": 2000.0}, "COMPASS_OFS_X"),  # |ofs| < COMPASS_OFFS_MAX
        ("ardupilot", {"mag_bias": 1100.0, "all_axes": True}, "length of COMPASS_OFS"),
        ("ardupilot", {"accel_bias": 4.0}, "INS_ACCOFFS_X"),  # @Range -3.5 3.5
        ("ardupilot", {"mag_scale": 8.0}, "COMPASS_DIA_X"),  # 0.2 < dia < 5
        ("px4", {"mag_bias": 1.5}, "CAL_MAG0_XOFF"),  # MAG_MAX_OFFSET_LEN 1.3 G
        ("px4", {"accel_scale": -1.0}, "CAL_ACC0_XSCALE"),  # a positive scale
        ("px4", {"accel_bias": 1e30}, "CAL_ACC0_XOFF"),  # within a ±16 g sensor's range
        ("px4", {"mag_scale": 8.0}, "CAL_MAG0_XSCALE"),  # plausibility, as COMPASS_DIA
    ],
)
def test_autopilot_ranges_refuse_in_one_line(cal, target, change, name):
    device = _device(cal, target)
    accel, mag = device.accel, device.mag
    if "mag_bias" in change:
        b = np.asarray(mag.bias).copy()
        if change.get("all_axes"):
            b[:] = change["mag_bias"] * TARGETS[target][3] / 10.0
        else:
            b[0] = change["mag_bias"] * (1.0 if target == "ardupilot" else -1.0)
        mag = dataclasses.replace(mag, bias=b)
    if "accel_bias" in change:
        size = 4.0 if target == "ardupilot" else change["accel_bias"]
        accel = dataclasses.replace(accel, bias=np.asarray(accel.bias) * 0 + [size, 0.0, 0.0])
    if "mag_scale" in change:
        gain = np.asarray(mag.gain).copy()
        gain[0] /= change["mag_scale"]
        mag = dataclasses.replace(mag, gain=gain)
    if "accel_scale" in change:
        gain = np.asarray(accel.gain) * [[-1.0], [1.0], [1.0]]
        accel = dataclasses.replace(accel, gain=gain)
    bad = dataclasses.replace(device, accel=accel, mag=mag)
    if "accel_scale" in change:
        # a negative per-axis scale is a mirrored accelerometer: refused before the ranges
        with pytest.raises(InputError, match="mirrored"):
            export(bad, target)
        return
    with pytest.raises(InputError) as info:
        export(bad, target)
    message = str(info.value)
    assert name in message and ("outside" in message or "exceeds" in message), message
    assert "--allow-out-of-range" in message and "\n" not in message
    with pytest.warns(UserWarning, match=f"outside the range .*{name}"):
        text = export(bad, target, allow_out_of_range=True)
    assert "# OUT OF RANGE" in text


@pytest.mark.parametrize("scale", [8.6, 1.0 / G, 12.2])
def test_px4_refuses_scales_that_ardupilot_refuses_naming_the_raw_units(cal, scale):
    """The issue's CAL_ACC0_XSCALE 8.6, 9.98 (a log in g) and 12.2: refused as ArduPilot
    refuses INS_ACCSCAL, naming the units PX4's drivers deliver; allowed, one warning line
    names the values written."""
    device = _device(cal, "px4")
    off = device.with_raw_scale({"accel": scale if scale < 1 else 1.0 / scale})
    for target in ("ardupilot", "px4"):
        dev = _device(cal, target).with_raw_scale({"accel": scale if scale < 1 else 1 / scale})
        with pytest.raises(InputError, match="outside the range") as info:
            export(dev, target)
        assert "m/s²" in str(info.value) and "\n" not in str(info.value)
    with pytest.warns(UserWarning) as caught:
        text = export(off, "px4", allow_out_of_range=True)
    (warning,) = caught
    assert re.search(r"CAL_ACC0_XSCALE = \d+\.\d+", str(warning.message))
    assert text.count("# OUT OF RANGE") == 3
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # inside the ranges: no warning at all
        assert "all inside" in export(device, "px4")


def test_ardupilot_advice_does_not_contradict_a_folded_axis_map(cal):
    device = _device(cal, "ardupilot")
    mirrored = dataclasses.replace(
        device,
        mag=dataclasses.replace(device.mag, gain=np.asarray(device.mag.gain) * [1, 1, -1]),
    )
    with pytest.raises(InputError, match="--mag-axes"):
        export(mirrored, "ardupilot")  # no map folded in: the advice names the option
    folded = dataclasses.replace(mirrored, options={**mirrored.options, "mag_axes": "+y+x+z"})
    with pytest.raises(InputError) as info:
        export(folded, "ardupilot")
    message = str(info.value)
    assert "+y+x+z" in message and "--mag-axes" not in message and "\n" not in message


# --------------------------------------------------------------------------- the verdict
def test_every_export_carries_the_verdict_and_its_codes(cal, tmp_path):
    judged = dataclasses.replace(
        _device(cal, "ardupilot"),
        verdict=Verdict(
            "warn",
            (
                Reason("accuracy", "warn", "heading 3.1 deg predicted, target 2"),
                Reason("untested", "warn", "6 degrees of freedom"),
            ),
        ),
    )
    line = verdict_line(judged)
    assert line == "verdict: WARN (codes: accuracy, untested)"
    for name, fmt in FORMATS.items():
        if name in ("kalibr", "openvins"):
            continue  # refused from a calibration (above); fieldcal noise writes them
        if fmt.files is not None:
            texts = [b.decode() for b in export_files(judged, name).values()]
        elif fmt.binary is not None:
            data = scipy.io.loadmat(io.BytesIO(export_bytes(judged, name)))
            texts = [str(data["provenance"][0])]
        elif name == "px4":
            texts = [export(_device(judged, "px4"), name)]
        else:
            texts = [export(judged, name)]
        if name == "json":
            assert json.loads(texts[0])["verdict"]["level"] == "warn"
        else:
            assert all(line in text for text in texts), name


# --------------------------------------------------------------------------- the command line
def test_cli_export_options_and_the_c_library_folder(cal, tmp_path):
    path = tmp_path / "cal.json"
    path.write_text(_device(cal, "px4").to_json())
    run = CliRunner().invoke
    result = run(cli, ["export", str(path), "--format", "px4", "--sysid", "4", "--compid", "2"])
    assert result.exit_code == 0, result.output
    assert "# Vehicle 4, component 2" in result.output
    result = run(cli, ["export", str(path), "--format", "matlab", "--sysid", "4"])
    assert result.exit_code == 2 and "does not take sysid" in result.output
    folder = tmp_path / "lib"
    result = run(cli, ["export", str(path), "--format", "c-library", "-o", str(folder)])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in folder.iterdir()) == ["fieldcal_cal.c", "fieldcal_cal.h"]
    result = run(cli, ["export", str(path), "--format", "c-library"])
    assert result.exit_code == 2 and "-o DIR" in result.output
    in_g = tmp_path / "in_g.json"
    in_g.write_text(_device(cal, "ardupilot").with_raw_scale({"accel": 1.0 / G}).to_json())
    result = run(cli, ["export", str(in_g), "--format", "ardupilot"])
    assert result.exit_code == 2 and "INS_ACCSCAL_X" in result.output
    assert len(result.output.strip().splitlines()) == 1
    result = run(cli, ["export", str(in_g), "--format", "ardupilot", "--allow-out-of-range"])
    assert result.exit_code == 0 and "# OUT OF RANGE" in result.output
