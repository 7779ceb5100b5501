"""Temperature terms in the exports (issue 26): PX4's ``TC_*`` parameters evaluated as PX4
evaluates them, the C header's and the C library's apply-with-temperature compiled and run,
MATLAB's script and ``.mat`` file evaluated by their stated formula; each against
``cal.correct_*(raw, temperature=T)``, at temperatures inside and outside the span seen (both
clip). A calibration whose temperature terms were refused exports exactly what one without a
temperature column does.
"""

from __future__ import annotations

import ctypes
import dataclasses
import io
import re
import shutil
import subprocess

import numpy as np
import pytest
import scipy.io
from _clib import CFLAGS, compiler

import fieldcal
from fieldcal.calibration import SensorCalibration
from fieldcal.output.exports import FORMATS, c_library, export, export_bytes, export_files
from fieldcal.output.exports.c_header import c_float
from fieldcal.simulation.warmup import simulate_warmup
from fieldcal.thermal import TemperatureModel

G = 9.80665
EPS32 = float(np.finfo(np.float32).eps)
SENSORS = ("accel", "mag", "gyro")
needs_cc = pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler on this machine")


@pytest.fixture(scope="module")
def cal():
    """A warm-up calibration (accelerometer and magnetometer terms chosen by the data) in m/s²
    and µT, with a gyroscope whose bias has linear and cubic terms."""
    w = simulate_warmup(seed=3, n_poses=24)
    fitted = fieldcal.calibrate(w.accel, w.mag, temperature=w.temperature)
    fitted = fitted.with_field_magnitudes(G, 48.5)
    assert fitted.accel.temperature.order >= 1 and fitted.mag.temperature.order >= 1
    rng = np.random.default_rng(8)
    model = TemperatureModel(
        reference=31.0,
        coefficients=np.array([[2e-3, -1e-3, 5e-4], [0.0, 0.0, 0.0], [1e-6, 2e-6, -1e-6]]),
        span=np.array([21.0, 39.0]),
    )
    gyro = SensorCalibration(
        gain=np.eye(3) + rng.normal(scale=0.01, size=(3, 3)),
        bias=np.array([0.02, -0.01, 0.005]),
        noise_cov=np.diag([1e-6, 1e-6, 1e-6]),
        temperature=model,
    )
    return dataclasses.replace(fitted, gyro=gyro)


def _readings(cal, sensor, n=60, seed=1):
    """Raw readings of ``sensor`` and a temperature per reading, 10 K below to 10 K above the
    span seen (the models clip there)."""
    s = cal.sensor(sensor)
    rng = np.random.default_rng(seed)
    raw = np.asarray(s.bias) + rng.normal(size=(n, 3)) @ np.asarray(s.gain).T
    low, high = s.temperature.span
    return raw, rng.uniform(low - 10.0, high + 10.0, n)


# ------------------------------------------------------------------------------- PX4
def _parse_qgc(text):
    """QGroundControl's parameter file, with the types PX4 declares: REAL32 (9) stored as a
    float32, INT32 (6) as an integer."""
    params = {}
    for line in text.splitlines():
        if line and not line.startswith("#"):
            _, _, name, value, kind = line.split("\t")
            params[name] = int(value) if kind == "6" else np.float64(np.float32(float(value)))
            assert kind in ("6", "9"), line
    return params


def _px4_thermal_offset(p, letter, temperature):
    """PX4 TemperatureCompensation::calc_thermal_offsets_3D (src/modules/temperature_
    compensation/TemperatureCompensation.cpp, commit b8ad9bdbe5ad): the temperature clipped to
    [TMIN, TMAX], ``delta = T − TREF``, ``offset[i] = x0[i] + x1[i] δ + x2[i] δ² + x3[i] δ³``;
    in float32, as PX4 computes it."""
    f = np.float32
    tag = f"TC_{letter}0"
    t = np.clip(temperature.astype(f), f(p[f"{tag}_TMIN"]), f(p[f"{tag}_TMAX"]))
    d = (t - f(p[f"{tag}_TREF"]))[:, None]
    x = [np.array([p[f"{tag}_X{k}_{i}"] for i in range(3)], dtype=f) for k in range(4)]
    return (x[0] + x[1] * d + x[2] * (d * d) + x[3] * (d * d * d)).astype(float)


def _px4(cal):
    """The PX4 file of the fixture, whose raw units are not PX4's (accelerometer scales near
    18): written marked, with the one-line warning that names the values."""
    with pytest.warns(UserWarning, match=r"outside the range PX4 accepts.*CAL_ACC0_XSCALE = "):
        return export(cal, "px4", allow_out_of_range=True)


def test_px4_tc_parameters_are_pxs_names_and_switches(cal):
    p = _parse_qgc(_px4(cal))
    for letter in "AMG":
        assert p[f"TC_{letter}_ENABLE"] == 1
        names = [f"TC_{letter}0_X{k}_{i}" for k in range(4) for i in range(3)]
        names += [f"TC_{letter}0_{x}" for x in ("TREF", "TMIN", "TMAX")]
        assert all(name in p for name in names)
    # the accelerometer's and magnetometer's X0 are 0: CAL_*0_*OFF hold the bias at TREF
    assert all(p[f"TC_{x}0_X0_{i}"] == 0.0 for x in "AM" for i in range(3))
    assert p["TC_A0_TREF"] == pytest.approx(cal.accel.temperature.reference, rel=1e-6)


@pytest.mark.parametrize(("sensor", "letter"), [("accel", "A"), ("mag", "M"), ("gyro", "G")])
def test_px4_subtracts_the_bias_fieldcal_has_at_each_temperature(cal, sensor, letter):
    """PX4's driver library subtracts the thermal offset and CAL_*_OFF from the raw reading
    (Accelerometer::Correct: ``data - _thermal_offset - _offset``); what remains is fieldcal's
    ``raw − bias(T) = gain @ cal.correct_*(raw, temperature=T)``."""
    p = _parse_qgc(_px4(cal))
    raw, T = _readings(cal, sensor)
    offset_names = {"accel": "CAL_ACC0_{}OFF", "mag": "CAL_MAG0_{}OFF"}
    if sensor in offset_names:
        off = np.array([p[offset_names[sensor].format(a)] for a in "XYZ"])
    else:
        off = np.zeros(3)  # the file says: CAL_GYRO0_*OFF = 0, TC_G0_X0 holds the bias
    px4 = raw - _px4_thermal_offset(p, letter, T) - off
    s = cal.sensor(sensor)
    corrected = getattr(cal, f"correct_{sensor}")(raw, temperature=T)
    want = corrected @ np.asarray(s.gain).T
    # float32 parameters: a few eps of the bias and of the largest thermal offset
    tol = 8 * EPS32 * (np.abs(s.bias).max() + np.abs(s.temperature.shift(T)).max() + 1.0)
    assert np.abs(px4 - want).max() <= tol
    # and the temperature matters at this tolerance (the test sees the terms)
    assert np.abs(raw - off - want).max() > 100 * tol


def test_px4_compass_with_temperature_is_fieldcals_rotated(cal):
    """The whole compass chain (thermal offset, CAL_MAG0_OFF, the symmetric scale) gives
    fieldcal's field in gauss, rotated by the stated misalignment, at every temperature."""
    text = _px4(cal)
    p = _parse_qgc(text)
    raw, T = _readings(cal, "mag", n=200)
    off = np.array([p[f"CAL_MAG0_{a}OFF"] for a in "XYZ"])
    d = [p[f"CAL_MAG0_{a}SCALE"] for a in "XYZ"]
    o = [p[f"CAL_MAG0_{a}ODIAG"] for a in "XYZ"]
    S = np.array([[d[0], o[0], o[1]], [o[0], d[1], o[2]], [o[1], o[2], d[2]]])
    got = (raw - _px4_thermal_offset(p, "M", T) - off) @ S.T
    want = 0.01 * cal.correct_mag(raw, temperature=T)  # µT to gauss
    W, _, Vt = np.linalg.svd(got.T @ want)
    R = W @ np.diag([1.0, 1.0, np.linalg.det(W @ Vt)]) @ Vt
    assert np.abs(got - want @ R.T).max() < 1e-5 * np.abs(want).max()
    stated = float(re.search(r"rotated by ([\d.]+) deg", text).group(1))
    angle = np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
    assert angle == pytest.approx(stated, abs=1e-3)


# ------------------------------------------------------------------------- byte for byte
def _without_terms(cal):
    return dataclasses.replace(
        cal,
        **{s: dataclasses.replace(cal.sensor(s), temperature=None) for s in ("accel", "mag")},
    )


def test_exports_without_temperature_terms_are_unchanged():
    """Terms refused (span under 5 K): every export is that of the same calibration with no
    temperature model at all, byte for byte (the .mat file's header carries its time)."""
    w = simulate_warmup(seed=4, n_poses=15, span=0.0, drift={})
    refused = fieldcal.calibrate(w.accel, w.mag, temperature=w.temperature)
    refused = refused.with_field_magnitudes(G, 48.5)
    assert refused.accel.temperature.refused and refused.accel.temperature.order == 0
    plain = _without_terms(refused)
    for name, fmt in FORMATS.items():
        if name in ("kalibr", "openvins", "ardupilot", "px4", "json"):
            continue  # need a gyroscope and a rate, or raw units of their own; the document
        if fmt.files is not None:
            assert export_files(refused, name) == export_files(plain, name), name
        else:
            a, b = export_bytes(refused, name), export_bytes(plain, name)
            header = 128 if name == "mat" else 0
            assert a[header:] == b[header:], name
    with pytest.warns(UserWarning, match="outside the range PX4 accepts"):
        a, b = (export(c, "px4", allow_out_of_range=True) for c in (refused, plain))
    assert a == b
    # and the document says what it is: the JSON keeps the (refused) model
    assert '"refused": true' in export(refused, "json")


# ------------------------------------------------------------------------------ C header
@needs_cc
def test_c_header_applies_the_bias_at_the_temperature(cal, tmp_path):
    (tmp_path / "cal.h").write_text(export(cal, "c-header"))
    cases, want = [], []
    for sensor in SENSORS:
        raw, T = _readings(cal, sensor, n=8)
        tag = sensor.upper()
        for r, t in zip(raw, T, strict=True):
            literals = ", ".join(c_float(v) for v in r)
            cases.append(
                f"  {{ const float raw[3] = {{{literals}}}; float out[3];\n"
                f"    fieldcal_apply_at(FIELDCAL_{tag}_MATRIX, FIELDCAL_{tag}_BIAS, "
                f"FIELDCAL_{tag}_TEMP, FIELDCAL_{tag}_TEMP_COEF, raw, {c_float(t)}, out);\n"
                '    printf("%.9g %.9g %.9g\\n", out[0], out[1], out[2]); }'
            )
        f32 = np.float32(T).astype(float)  # the literal the program holds
        want.append(getattr(cal, f"correct_{sensor}")(np.float32(raw).astype(float), f32))
    (tmp_path / "main.c").write_text(
        '#include <stdio.h>\n#include "cal.h"\nint main(void) {\n'
        + "\n".join(cases)
        + "\n  return 0;\n}\n"
    )
    exe = tmp_path / "a.out"
    cmd = ["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-o", str(exe)]
    subprocess.run([*cmd, str(tmp_path / "main.c")], check=True)
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout
    got = np.array([line.split() for line in out.splitlines()], dtype=float)
    want = np.concatenate(want)
    assert np.allclose(got, want, rtol=1e-5, atol=1e-5 * np.abs(want).max())


# ------------------------------------------------------------------------------ C library
class _Cal(ctypes.Structure):
    _fields_ = [
        ("sensor_id", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("f", ctypes.c_float * c_library.N_FLOATS_TEMPERATURE),
    ]


@needs_cc
def test_c_library_applies_the_bias_at_the_temperature_and_keeps_it(cal, tmp_path):
    files = export_files(cal, "c-library")
    for name, content in files.items():
        (tmp_path / name).write_bytes(content)
    header = files["fieldcal_cal.h"].decode()
    assert "#define FIELDCAL_BLOB_VERSION 2u" in header
    assert f"#define FIELDCAL_N_FLOATS {c_library.N_FLOATS_TEMPERATURE}u" in header
    so = tmp_path / "libfc.so"
    cmd = [compiler(), *CFLAGS, "-pedantic", "-shared", "-fPIC", str(tmp_path / "fieldcal_cal.c")]
    out = subprocess.run([*cmd, "-o", str(so), "-lm"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    lib = ctypes.CDLL(str(so))
    factory = _Cal.in_dll(lib, "FIELDCAL_FACTORY")
    assert factory.flags & 0x20  # FIELDCAL_HAS_TEMPERATURE
    V3 = ctypes.c_float * 3
    for sensor in SENSORS:
        fn = getattr(lib, f"fieldcal_{sensor}_at")
        fn.argtypes = [ctypes.POINTER(_Cal), V3, ctypes.c_float, V3]
        raw, T = _readings(cal, sensor)
        got = []
        for r, t in zip(raw, T, strict=True):
            o = V3()
            fn(ctypes.byref(factory), V3(*r), ctypes.c_float(t), o)
            got.append(list(o))
        want = getattr(cal, f"correct_{sensor}")(raw, temperature=T)
        s = cal.sensor(sensor)
        M = np.linalg.inv(s.gain)
        scale = np.abs(M).sum(axis=1) * (np.abs(raw).max(axis=1, keepdims=True) + 1.0)
        assert np.all(np.abs(np.array(got) - want) <= 16 * EPS32 * scale), sensor
    # the blob: version 2, the python writer's bytes, loaded back whole
    buf = ctypes.create_string_buffer(1024)
    lib.fieldcal_save.argtypes = [ctypes.POINTER(_Cal), ctypes.c_char_p, ctypes.c_size_t]
    n = lib.fieldcal_save(ctypes.byref(factory), buf, 1024)
    saved = buf.raw[:n]
    assert n == 16 + 4 * c_library.N_FLOATS_TEMPERATURE + 4
    assert saved == c_library.blob(cal)
    assert int.from_bytes(saved[4:6], "little") == c_library.VERSION_TEMPERATURE
    loaded = _Cal()
    lib.fieldcal_load.argtypes = [
        ctypes.POINTER(_Cal),
        ctypes.c_char_p,
        ctypes.c_size_t,
        ctypes.c_uint32,
    ]
    sid = c_library.sensor_id_of(cal)
    assert lib.fieldcal_load(ctypes.byref(loaded), saved, n, sid) == 0
    assert bytes(loaded) == bytes(factory)
    # a version-1 blob (a calibration without terms) is refused by this library, not misread
    old = c_library.blob(_without_terms(dataclasses.replace(cal, gyro=None)))
    assert lib.fieldcal_load(ctypes.byref(loaded), old, len(old), sid) == -1  # its size


# --------------------------------------------------------------------------------- MATLAB
def _script_values(text):
    values = {}
    for name, body in re.findall(r"^(\w+) = \[(.*?)\];$", text, re.M):
        values[name] = np.array([row.split() for row in body.split(";")], dtype=float)
    return values


def _matlab_usage(v, s, D, T):
    """The script's stated usage (matlab.TEMPERATURE_USAGE) in numpy."""
    Ts, c = v[f"T_{s}"].ravel(), v[f"c_{s}"]
    d = (np.minimum(np.maximum(T, Ts[1]), Ts[2]) - Ts[0])[:, None]
    b_at = v[f"b_{s}"] + d * c[0] + d**2 * c[1] + d**3 * c[2]
    return (D - b_at) @ v[f"A_{s}"]


def test_matlab_script_and_mat_file_apply_the_bias_at_the_temperature(cal, tmp_path):
    script = _script_values(export(cal, "matlab"))
    mat = scipy.io.loadmat(io.BytesIO(export_bytes(cal, "mat")))
    assert "T_accel" in mat and "temperature_formula" in mat
    for sensor in SENSORS:
        raw, T = _readings(cal, sensor)
        want = getattr(cal, f"correct_{sensor}")(raw, temperature=T)
        for values in (script, mat):
            got = _matlab_usage(values, sensor, raw, T)
            assert np.allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
