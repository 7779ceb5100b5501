"""``apply`` with a calibration whose biases have temperature terms: each row corrected with the
bias at its temperature (the log's column, ``--temp-col`` or ``--temperature``), on every path
(text streamed fast or line by line, Parquet/NPZ tables); refused in one line without a
temperature."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner

import fieldcal
from fieldcal.cli import cli
from fieldcal.errors import InputError
from fieldcal.logs.apply import apply_to_file
from fieldcal.simulation.warmup import simulate_warmup_log


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    w = simulate_warmup_log(seed=2, n_poses=18, span=20.0)
    folder = tmp_path_factory.mktemp("apply")
    path = folder / "warm.csv"
    w.write_csv(str(path))
    cal = fieldcal.calibrate_log(path, gyro=False)
    assert cal.accel.temperature.order >= 1 and cal.mag.temperature.order >= 1
    table = np.genfromtxt(path, delimiter=",", names=True)
    written = SimpleNamespace(written={name: table[name] for name in table.dtype.names})
    return written, path, cal


def _expected(w, cal, temperature):
    """The library's correction of the log's readings as written (9 significant digits)."""
    cols = w.written
    a = np.column_stack([cols[f"a{x}"] for x in "xyz"])
    m = np.column_stack([cols[f"m{x}"] for x in "xyz"])
    at = {"temperature": temperature}
    return cal.correct_accel(a, **at), cal.correct_mag(m, **at)


def _read(path):
    table = np.genfromtxt(path, delimiter=",", names=True)
    a = np.column_stack([table[f"a{x}_cal"] for x in "xyz"])
    m = np.column_stack([table[f"m{x}_cal"] for x in "xyz"])
    return a, m


@pytest.mark.parametrize("chunk_rows", [None, 7], ids=["fast", "chunks"])
def test_each_row_is_corrected_at_its_temperature(warm, tmp_path, chunk_rows):
    w, path, cal = warm
    out = tmp_path / "out.csv"
    used = apply_to_file(cal, path, out, chunk_rows=chunk_rows)
    assert used["temperature"] == ["temp"]
    a, m = _read(out)
    T = w.written["temp"]
    want_a, want_m = _expected(w, cal, T)
    assert np.abs(a - want_a).max() < 1e-9 * np.abs(want_a).max()
    assert np.abs(m - want_m).max() < 1e-9 * np.abs(want_m).max()
    # the terms matter: at the reference temperature the rows differ far beyond that
    at_ref = _expected(w, cal, None)[0]
    assert np.abs(at_ref - want_a).max() > 1e-4 * np.abs(want_a).max()


def test_a_line_by_line_chunk_reads_the_temperature_too(warm, tmp_path):
    """A quoted field sends a chunk through the csv module: the same values."""
    w, path, cal = warm
    text = path.read_text().splitlines()
    text[5] = ",".join(f'"{v}"' for v in text[5].split(","))
    quoted = tmp_path / "quoted.csv"
    quoted.write_text("\n".join(text) + "\n")
    out = tmp_path / "out.csv"
    apply_to_file(cal, quoted, out, chunk_rows=10)
    a, _ = _read(out)
    want_a = _expected(w, cal, w.written["temp"])[0]
    assert np.abs(a - want_a).max() < 1e-9 * np.abs(want_a).max()


def test_tables_and_a_constant_temperature(warm, tmp_path):
    w, path, cal = warm
    out = tmp_path / "out.npz"
    apply_to_file(cal, path, out)
    with np.load(out) as data:
        got = np.column_stack([data[f"m{x}_cal"] for x in "xyz"])
        T = data["temp"]
    want = _expected(w, cal, T)[1]
    assert np.abs(got - want).max() < 1e-12 * np.abs(want).max()
    # one temperature for every row, the column ignored
    out2 = tmp_path / "const.csv"
    used = apply_to_file(cal, path, out2, temperature=25.0)
    assert "temperature" not in used
    a, _ = _read(out2)
    want_a = _expected(w, cal, 25.0)[0]
    assert np.abs(a - want_a).max() < 1e-9 * np.abs(want_a).max()


def test_no_temperature_is_refused_in_one_line_and_named_columns_work(warm, tmp_path):
    _, path, cal = warm
    renamed = tmp_path / "renamed.csv"
    renamed.write_text(path.read_text().replace(",temp\n", ",board_heat\n", 1))
    with pytest.raises(InputError, match="no temperature column; name it with --temp-col"):
        apply_to_file(cal, renamed, tmp_path / "x.csv")
    used = apply_to_file(cal, renamed, tmp_path / "y.csv", temp_col="board_heat")
    assert used["temperature"] == ["board_heat"]
    cal_path = tmp_path / "cal.json"
    cal_path.write_text(cal.to_json())
    result = CliRunner().invoke(cli, ["apply", str(cal_path), str(renamed), "-o", "z.csv"])
    assert result.exit_code == 2 and result.output.startswith("Error: ")
    assert "--temp-col" in result.output and "Traceback" not in result.output
    ok = CliRunner().invoke(
        cli,
        [
            "apply",
            str(cal_path),
            str(renamed),
            "-o",
            str(tmp_path / "z.csv"),
            "--temperature",
            "30",
        ],
    )
    assert ok.exit_code == 0, ok.output


def test_a_calibration_without_terms_applies_as_before(warm, tmp_path):
    _, path, cal = warm
    stripped = dataclasses.replace(
        cal,
        accel=dataclasses.replace(cal.accel, temperature=None),
        mag=dataclasses.replace(cal.mag, temperature=None),
    )
    used = apply_to_file(stripped, path, tmp_path / "out.csv")
    assert "temperature" not in used
