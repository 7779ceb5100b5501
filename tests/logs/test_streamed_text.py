"""The streamed text path of ``apply`` on a large text log: the bulk path (pyarrow reads,
formats and joins whole blocks of lines) writes the bytes the line-by-line path writes, and is
the one taken; a file that is not text is refused in one line."""

from __future__ import annotations

from unittest import mock

import numpy as np
import pytest
from _logs import _Double

import fieldcal.logs.streamed_text as streamed
from fieldcal.logs.apply import apply_to_file

pytest.importorskip("pyarrow", reason="pyarrow (the parquet extra) not installed")


def _log(eol: str, ended: bool) -> str:
    rng = np.random.default_rng(8)
    n = 2 * streamed.ARROW_MIN_ROWS + 123
    values = rng.normal(size=(n, 6)) * np.array([1, 1, 1, 30, 30, 30])
    values[5, 0] = 1e-7  # positional text out of repr's range: written by repr
    values[6, 1] = 12345678.0  # a whole number
    rows = [f"{0.01 * i:.2f},{','.join(f'{v:.9g}' for v in row)}" for i, row in enumerate(values)]
    rows[7] = rows[7].replace(",", ",,", 1).replace(",,", ",", 1)  # still seven fields
    text = eol.join(["t,ax,ay,az,mx,my,mz", *rows])
    return text + (eol if ended else "")


@pytest.mark.parametrize(("eol", "ended"), [("\n", True), ("\r\n", False)])
def test_bulk_blocks_write_what_the_line_by_line_path_writes(tmp_path, eol, ended):
    src = tmp_path / "log.csv"
    src.write_bytes(_log(eol, ended).encode())
    fast, slow = tmp_path / "fast.csv", tmp_path / "slow.csv"
    bulk, original = [], streamed._arrow_block

    def spy(*args):
        bulk.append(original(*args))
        return bulk[-1]

    with mock.patch.object(streamed, "_arrow_block", spy):
        apply_to_file(_Double(), src, fast, chunk_rows=3 * streamed.ARROW_MIN_ROWS // 2)
    assert sum(b is not None for b in bulk) >= 1  # (a last block under the rows: numpy)
    with (
        mock.patch.object(streamed, "_arrow_block", lambda *args: None),
        mock.patch.object(streamed, "_fast_chunk", lambda *args: None),
    ):
        apply_to_file(_Double(), src, slow, chunk_rows=1000)
    assert fast.read_bytes() == slow.read_bytes()
    lines = fast.read_bytes().decode().split(eol)
    assert lines[0] == "t,ax,ay,az,mx,my,mz,ax_cal,ay_cal,az_cal,mx_cal,my_cal,mz_cal"
    first = lines[1].split(",")
    assert [float(v) for v in first[7:]] == [2 * float(v) for v in first[1:7]]


def test_a_block_with_an_unusual_line_goes_the_careful_way(tmp_path):
    text = _log("\n", True)
    at = text.index("\n", len(text) // 2)
    src = tmp_path / "log.csv"
    src.write_text(text[:at] + "\n# a comment in the middle" + text[at:])
    out = tmp_path / "out.csv"
    apply_to_file(_Double(), src, out)
    written = out.read_text().split("\n")
    assert "# a comment in the middle" in written
    assert len(written) == len(text.split("\n")) + 1
