"""Each export, applied the way its target tool applies it, gives fieldcal's calibrated values;
the registry is the one list of formats; every number parses in its target."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import fieldcal
from fieldcal.calibration import Calibration, SensorCalibration
from fieldcal.errors import InputError
from fieldcal.output.exports import (
    DEFAULT,
    FORMATS,
    export,
    export_bytes,
    export_files,
    for_path,
    markdown_table,
)
from fieldcal.output.exports.c_header import c_float

DOCS = Path(__file__).resolve().parents[2] / "docs"
#: A C float literal with a decimal point, e.g. 1.0f, -0.25f, 1.5e-30f.
_C_FLOAT = r"-?\d+\.\d+(e[-+]\d+)?f"


@pytest.fixture(scope="module")
def cal():
    return fieldcal.simulate("paper", seed=2).truth.with_field_magnitudes(9.80665, 48.5)


@pytest.fixture(scope="module")
def raw(cal):
    rng = np.random.default_rng(3)
    return {"accel": rng.normal(size=(50, 3)) * 2, "mag": rng.normal(size=(50, 3)) * 2}


def _expected(cal, raw):
    return {"accel": cal.correct_accel(raw["accel"]), "mag": cal.correct_mag(raw["mag"])}


def _numbers(text):
    return np.array([float(v.rstrip("f")) for v in re.findall(r"-?[\d.]+(?:e[-+]?\d+)?f?", text)])


def _cal(accel_gain, accel_bias, mag_gain, mag_bias):
    def sensor(gain, bias):
        return SensorCalibration(gain=gain, bias=bias, noise_cov=np.eye(3))

    return Calibration(
        accel=sensor(accel_gain, accel_bias),
        mag=sensor(mag_gain, mag_bias),
        gravity=np.array([0.0, 0.0, -1.0]),
        magnetic=np.array([0.5, 0.0, 0.8]),
        rotations=np.zeros((0, 3, 3)),
        method="truth",
    )


def test_registry(cal):
    # every registered format is checked below, whatever it is: adding one needs no list here
    assert DEFAULT in FORMATS and len(FORMATS) >= 10
    assert for_path("out/folder") is None  # a folder format is never picked by a suffix
    for name, fmt in FORMATS.items():
        if fmt.files is not None:  # a folder of files (c-library)
            assert fmt.suffix == "" and export_files(cal, name)
            continue
        assert fmt.name == name and fmt.suffix.startswith(".")
        if name != "openvins":  # .yaml names kalibr, the first with that suffix
            assert for_path(f"out/cal{fmt.suffix.upper()}") is fmt
        if fmt.binary is not None:  # a binary file (.mat): bytes, never text
            assert export_bytes(cal, name)
            continue
        try:
            text = export(cal, name)
        except InputError as exc:  # autopilots need physical units, Kalibr a gyroscope
            assert "\n" not in str(exc)
            continue
        assert fmt.formula in text  # the text states the formula word for word
        assert fmt.write(cal) == text
    # one format per suffix (kalibr and openvins share .yaml; c-library is a folder)
    assert len({f.suffix for f in FORMATS.values()}) == len(FORMATS) - 1
    assert for_path("cal.xlsx") is None


def test_docs_table_is_the_registry():
    assert markdown_table() in (DOCS / "cli.md").read_text(encoding="utf-8")


@pytest.mark.parametrize(
    ("x", "text"),
    [
        (1.0, "1.0f"),
        (0.0, "0.0f"),
        (-0.0, "-0.0f"),
        (-3.0, "-3.0f"),
        (1e30, "1.0e+30f"),
        (-1e-30, "-1.0e-30f"),
        (0.1, "0.1f"),
        (123456789.0, "1.2345679e+08f"),  # the nearest float32, 123456792
        (1e-50, "0.0f"),  # below float32: the zero a float holds (a nonzero literal is refused)
    ],
)
def test_c_float_literals(x, text):
    assert c_float(x) == text


def test_c_float_reads_back_as_the_same_float32():
    rng = np.random.default_rng(7)
    values = rng.normal(size=200) * 10.0 ** rng.integers(-35, 35, size=200)
    for v in values:
        text = c_float(v)
        assert re.fullmatch(_C_FLOAT, text), text
        assert np.float32(text[:-1]) == np.float32(v)


def test_c_float_refuses_what_a_float_cannot_hold():
    for x in (1e39, -1e39, float("inf"), float("nan")):
        with pytest.raises(ValueError, match="C float"):
            c_float(x)


def test_c_header_formula_in_float32(cal, raw):
    text = export(cal, "c-header")
    assert FORMATS["c-header"].formula in text
    for sensor, want in _expected(cal, raw).items():
        tag = sensor.upper()
        b = _numbers(re.search(rf"FIELDCAL_{tag}_BIAS\[3\] = \{{(.*?)\}};", text).group(1))
        m = _numbers(
            re.search(rf"FIELDCAL_{tag}_MATRIX\[3\]\[3\] = \{{(.*?)\}};", text, re.S).group(1)
        ).reshape(3, 3)
        # what the C code does: float arithmetic, out[i] = Σ_j M[i][j] (raw[j] − B[j])
        d = raw[sensor].astype(np.float32) - b.astype(np.float32)
        got = d @ m.astype(np.float32).T
        assert np.allclose(got, want, rtol=1e-5, atol=1e-5 * np.abs(want).max())


def _compile_and_apply(tmp_path, cal, raw):
    """Compile the header with ``cc -Wall -Wextra -Werror`` and apply it to one reading per
    sensor; the outputs as the C program prints them."""
    (tmp_path / "cal.h").write_text(export(cal, "c-header"))
    calls = []
    for sensor, r in raw.items():
        tag = sensor.upper()
        literals = ", ".join(c_float(v) for v in r)
        calls.append(
            f"  {{ const float raw[3] = {{{literals}}}; float out[3];\n"
            f"    fieldcal_apply(FIELDCAL_{tag}_MATRIX, FIELDCAL_{tag}_BIAS, raw, out);\n"
            '    printf("%.9g %.9g %.9g\\n", out[0], out[1], out[2]); }'
        )
    (tmp_path / "main.c").write_text(
        '#include <stdio.h>\n#include "cal.h"\nint main(void) {\n'
        + "\n".join(calls)
        + "\n  return 0;\n}\n"
    )
    exe = tmp_path / "a.out"
    flags = ["-std=c99", "-Wall", "-Wextra", "-Werror"]
    subprocess.run(["cc", *flags, "-o", str(exe), str(tmp_path / "main.c")], check=True)
    out = subprocess.run([str(exe)], check=True, capture_output=True, text=True)
    rows = [np.array(line.split(), dtype=float) for line in out.stdout.splitlines()]
    return dict(zip(raw, rows, strict=True))


needs_cc = pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler on this machine")


@needs_cc
def test_c_header_compiles_and_runs(cal, raw, tmp_path):
    one = {s: raw[s][0] for s in ("accel", "mag")}
    got = _compile_and_apply(tmp_path, cal, one)
    assert np.allclose(got["mag"], cal.correct_mag(one["mag"]), rtol=1e-5, atol=1e-4)
    assert np.allclose(got["accel"], cal.correct_accel(one["accel"]), rtol=1e-5, atol=1e-4)


@needs_cc
@pytest.mark.parametrize(
    ("gains", "biases"),
    [
        ((1.0, 1.0), (0.0, 0.0)),  # identity and zero: 1.0f and 0.0f, never 1f
        ((1e30, 1e-30), (1e30, -1e-30)),  # extreme but float32 entries: 1e-30f, 1e+30f
    ],
    ids=["identity", "extreme"],
)
def test_c_header_compiles_for_any_float32_calibration(gains, biases, tmp_path):
    cal = _cal(
        gains[0] * np.eye(3), np.full(3, biases[0]), gains[1] * np.eye(3), np.full(3, biases[1])
    )
    text = export(cal, "c-header")
    arrays = re.findall(r"FIELDCAL_\w+(?:MATRIX|BIAS)(?:\[3\])+ = \{(.*?)\};", text, re.S)
    literals = [v.strip(" {}\n") for a in arrays for v in a.split(",")]
    assert len(literals) == 24 and all(re.fullmatch(_C_FLOAT, v) for v in literals), literals
    # readings one field unit from the bias along each axis come out as (1, 2, 3)
    raw = {
        "accel": biases[0] + gains[0] * np.array([1.0, 2.0, 3.0]),
        "mag": biases[1] + gains[1] * np.array([1.0, 2.0, 3.0]),
    }
    got = _compile_and_apply(tmp_path, cal, raw)
    for sensor in ("accel", "mag"):
        assert np.allclose(got[sensor], cal.sensor(sensor).correct(raw[sensor]), rtol=1e-5)
        assert np.allclose(got[sensor], [1.0, 2.0, 3.0], rtol=1e-5)


def test_matlab_magcal_convention(cal, raw):
    text = export(cal, "matlab")
    assert "C = (D - b) * A" in text and FORMATS["matlab"].formula in text
    for sensor, want in _expected(cal, raw).items():
        A = _numbers(re.search(rf"A_{sensor} = \[(.*?)\];", text).group(1)).reshape(3, 3)
        b = _numbers(re.search(rf"b_{sensor} = \[(.*?)\];", text).group(1)).reshape(1, 3)
        got = (raw[sensor] - b) @ A  # MATLAB: rows of D are readings
        assert np.allclose(got, want, rtol=1e-7, atol=1e-9)


def test_magneto_convention(cal, raw):
    text = export(cal, "magneto")
    assert "A^-1 * (h - b)" in text
    for sensor, want in _expected(cal, raw).items():
        block = text.split(f"[{'accelerometer' if sensor == 'accel' else 'magnetometer'}]")[1]
        lines = block.strip().splitlines()
        b = _numbers(lines[1])
        Ainv = np.array([_numbers(line) for line in lines[4:7]])
        got = (Ainv @ (raw[sensor] - b).T).T  # Magneto: column vectors
        assert np.allclose(got, want, rtol=1e-7, atol=1e-9)


def test_json_round_trip(cal, raw):
    back = fieldcal.Calibration.from_json(export(cal, "json"))
    assert np.allclose(back.correct_mag(raw["mag"]), cal.correct_mag(raw["mag"]))


def test_unknown_format(cal):
    with pytest.raises(ValueError, match="c-header, matlab, magneto, json") as info:
        export(cal, "excel")
    assert "\n" not in str(info.value) and "'excel'" in str(info.value)


@pytest.mark.parametrize(
    ("gain", "bias", "match"),
    [
        (np.full((3, 3), np.nan), np.zeros(3), "not finite"),
        (np.eye(3), np.array([np.inf, 0.0, 0.0]), "not finite"),
        (np.zeros((3, 3)), np.zeros(3), "singular"),
        (np.eye(3) * 1e-320, np.zeros(3), "overflows a double"),
    ],
)
def test_every_export_refuses_what_no_target_can_hold(gain, bias, match):
    bad = _cal(np.eye(3), np.zeros(3), gain, bias)
    for name in FORMATS:
        with pytest.raises(ValueError, match=match) as info:
            export(bad, name)
        assert "\n" not in str(info.value) and "magnetometer" in str(info.value)


def test_extreme_finite_values_read_back_exactly():
    """MATLAB, Magneto and JSON numbers are exact doubles at both ends of the range a
    calibration file may hold (gains down to 1e-200, entries up to 1e150); the C header refuses
    what a float cannot hold and says which formats can."""
    big = _cal(np.eye(3) * 1e-199, np.full(3, -1.5e149), np.eye(3) * 3e149, np.full(3, 5e-324))
    matlab = " ".join(re.findall(r"= \[(.*?)\];", export(big, "matlab")))
    magneto = [line for line in export(big, "magneto").splitlines() if line[:1] == " "]
    for name, text in (("matlab", matlab), ("magneto", " ".join(magneto))):
        values = {float(v) for v in text.replace(";", " ").split()}
        assert {1 / 1e-199, -1.5e149, 1 / 3e149, 5e-324} <= values, name
    back = fieldcal.Calibration.from_json(export(big, "json"))
    assert np.array_equal(back.mag.gain, big.mag.gain) and back.mag.bias[0] == 5e-324
    with pytest.raises(ValueError, match=r"c-header.*matlab, magneto, json") as info:
        export(big, "c-header")
    assert "np.float64" not in str(info.value)  # the number as the user knows it


def _c_array(text, name):
    found = re.search(rf"{name}(?:\[3\])+ = \{{(.*?)\}};", text, re.S)
    values = _numbers(found.group(1))
    return values.reshape(3, 3) if values.size == 9 else values


def test_c_header_filter_numbers_match_the_data():
    """The header's Kalman-filter numbers against an independent computation: NOISE_COV is the
    scatter of the corrected samples within each pose (pooled; Wishart error ~ 1/√(n) ≈ 1 %),
    the NED fields are what the corrected readings average to at rest (through the simulated
    rotations), and the declination is the reference's."""
    session = fieldcal.simulate("paper", seed=5)
    cal = fieldcal.calibrate(
        session.accel, session.mag, gravity=9.80665, location=(52.0, 4.37), date="2026-06-01",
        field_strength="wmm",
    )  # fmt: skip
    text = export(cal, "c-header")
    for sensor, samples in (("accel", session.accel), ("mag", session.mag)):
        corrected = [cal.sensor(sensor).correct(p) for p in samples]
        pooled = sum((c - c.mean(axis=0)).T @ (c - c.mean(axis=0)) for c in corrected)
        dof = sum(len(c) - 1 for c in corrected)
        cov = _c_array(text, f"FIELDCAL_{sensor.upper()}_NOISE_COV")
        np.testing.assert_allclose(cov, pooled / dof, rtol=0.05, atol=0.05 * np.abs(cov).max())
        residual = _c_array(text, f"FIELDCAL_{sensor.upper()}_RESIDUAL_COV")
        M = np.linalg.inv(cal.sensor(sensor).gain)
        q = cal.sensor(sensor).pose_noise_std
        np.testing.assert_allclose(residual, q**2 * M @ M.T, rtol=1e-6, atol=1e-12)
    ned = {
        "accel": _c_array(text, "FIELDCAL_GRAVITY_NED"),
        "mag": _c_array(text, "FIELDCAL_MAGNETIC_NED"),
    }
    assert ned["accel"] == pytest.approx([0.0, 0.0, -9.80665], abs=1e-5)
    assert np.linalg.norm(ned["mag"]) == pytest.approx(
        cal.field_reference.intensity / 1000, rel=1e-6
    )
    # the fields' angle is the one between the corrected readings at rest: sin(dip) = −â·m̂
    a = np.array([cal.correct_accel(p.mean(axis=0)) for p in session.accel])
    m = np.array([cal.correct_mag(p.mean(axis=0)) for p in session.mag])
    cos = np.einsum("ij,ij->i", a, m) / np.linalg.norm(a, axis=1) / np.linalg.norm(m, axis=1)
    dip = np.degrees(np.arcsin(ned["mag"][2] / np.linalg.norm(ned["mag"])))
    assert np.degrees(np.arcsin(-cos)).mean() == pytest.approx(dip, abs=0.3)
    declination = float(re.search(r"#define FIELDCAL_DECLINATION_DEG (\S+)f", text).group(1))
    assert declination == pytest.approx(cal.field_reference.declination_deg, rel=1e-6)


@needs_cc
def test_kalman_page_program_runs(tmp_path):
    """docs/kalman-c.md's program, compiled as the page says, on raw pose means: its corrected
    vectors are cal.correct_* to float precision, its tilt and heading those the same formulas
    give in float64 on fieldcal's output, plus the declination."""
    page = (DOCS / "kalman-c.md").read_text(encoding="utf-8")
    (program,) = re.findall(r"```c\n(.*?)```", page, re.S)
    session = fieldcal.simulate("paper", seed=6)
    cal = fieldcal.calibrate(session.accel, session.mag, location=(52.0, 4.37), date="2026-06-01")
    (tmp_path / "fieldcal_cal.h").write_text(export(cal, "c-header"))
    (tmp_path / "heading.c").write_text(program)
    exe = tmp_path / "heading"
    flags = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror"]
    subprocess.run(["cc", *flags, "-o", str(exe), str(tmp_path / "heading.c"), "-lm"], check=True)
    raw_a = np.array([p.mean(axis=0) for p in session.accel])
    raw_m = np.array([p.mean(axis=0) for p in session.mag])
    rows = "ax,ay,az,mx,my,mz\n" + "".join(
        ",".join(f"{v:.9g}" for v in (*a, *m)) + "\n" for a, m in zip(raw_a, raw_m, strict=True)
    )
    out = subprocess.run([str(exe)], input=rows, capture_output=True, text=True, check=True)
    got = np.array([line.split() for line in out.stdout.splitlines()], dtype=float)
    a, m = cal.correct_accel(raw_a), cal.correct_mag(raw_m)
    np.testing.assert_allclose(got[:, 0:3], a, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(got[:, 3:6], m, rtol=1e-5, atol=1e-5)
    down = -a / np.linalg.norm(a, axis=1, keepdims=True)
    east = np.cross(down, m)
    east /= np.linalg.norm(east, axis=1, keepdims=True)
    north = np.cross(east, down)
    tilt = np.degrees(np.arccos(np.abs(down[:, 2])))
    heading = np.degrees(np.arctan2(east[:, 0], north[:, 0])) + cal.field_reference.declination_deg
    np.testing.assert_allclose(got[:, 6], tilt, atol=1e-2)
    wrapped = (got[:, 7] - heading + 180.0) % 360.0 - 180.0
    np.testing.assert_allclose(wrapped, 0.0, atol=1e-2)
