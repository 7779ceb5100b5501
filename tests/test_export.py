"""Each export, applied the way its target tool applies it, gives fieldcal's calibrated values."""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest

import fieldcal
from fieldcal.errors import InputError
from fieldcal.output.exports import export


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


def test_c_header_formula_in_float32(cal, raw):
    text = export(cal, "c-header")
    assert "out = inv(gain) * (raw - bias)" in text
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


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler on this machine")
def test_c_header_compiles_and_runs(cal, raw, tmp_path):
    (tmp_path / "cal.h").write_text(export(cal, "c-header"))
    r = [float(v) for v in raw["mag"][0]]
    (tmp_path / "main.c").write_text(
        '#include <stdio.h>\n#include "cal.h"\nint main(void) {\n'
        f"  const float raw[3] = {{{r[0]!r}f, {r[1]!r}f, {r[2]!r}f}}; float out[3];\n"
        "  fieldcal_apply(FIELDCAL_MAG_MATRIX, FIELDCAL_MAG_BIAS, raw, out);\n"
        '  printf("%.9g %.9g %.9g\\n", out[0], out[1], out[2]); return 0; }\n'
    )
    subprocess.run(
        [
            "cc",
            "-std=c99",
            "-Wall",
            "-Werror",
            "-o",
            str(tmp_path / "a.out"),
            str(tmp_path / "main.c"),
        ],
        check=True,
    )
    out = subprocess.run([str(tmp_path / "a.out")], check=True, capture_output=True, text=True)
    got = np.array(out.stdout.split(), dtype=float)
    assert np.allclose(got, cal.correct_mag(r), rtol=1e-5, atol=1e-4)


def test_matlab_magcal_convention(cal, raw):
    text = export(cal, "matlab")
    assert "C = (D - b) * A" in text
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
    with pytest.raises(InputError, match="c-header"):
        export(cal, "excel")
