"""Reading text logs: header variants with known answers, and the fast path against the careful
reader on random files (the same table, or the same one-line error); apply's vectorised chunks
against its line-by-line path (the same bytes, or the same error)."""

from __future__ import annotations

import csv
import importlib.util
import string
import subprocess
import sys
import warnings
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from _logs import _Double
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fieldcal.logs.streamed_text as streamed_module
from fieldcal.errors import InputError
from fieldcal.logs import apply_to_file, read_table, text_lines
from fieldcal.logs import text as text_module
from fieldcal.logs.text import Table, read_careful, read_text


def _write(path: Path, content: str) -> Path:
    path.write_bytes(content.encode("utf-8"))
    return path


def _fast(path: Path, decimal: str | None = None) -> Table:
    """The fast path alone (fails the test if it gives up)."""
    return text_module._read_fast(path, decimal, None)


def _same(a: Table, b: Table) -> None:
    assert (a.path, a.names, a.notes, a.decimal) == (b.path, b.names, b.notes, b.decimal)
    assert a.metadata == b.metadata
    for name in a.names:
        x, y = a.columns[name], b.columns[name]
        assert x.dtype.kind == y.dtype.kind, name
        if x.dtype.kind == "f":
            assert x.dtype == y.dtype == np.float64
            # equal bit for bit but for NaN payloads: values, NaNs and the signs of zeros
            assert np.array_equal(x, y, equal_nan=True), name
            assert np.array_equal(np.signbit(x), np.signbit(y)), name
        else:
            assert x.tolist() == y.tolist(), name


def _outcome(read, path: Path, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # never a numpy warning on the way
        try:
            return read(path, **options)
        except InputError as exc:
            message = str(exc)
            assert "\n" not in message and len(message) < 400, message
            return message


def _agree(path: Path, **options) -> Table | str:
    """read_text and read_careful: the same table or the same message."""
    fast, careful = _outcome(read_text, path, **options), _outcome(read_careful, path, **options)
    if isinstance(careful, str):
        assert fast == careful
    else:
        assert isinstance(fast, Table), fast
        _same(fast, careful)
    return careful


# ----------------------------------------------------------------------------- known answers
def _columns(table: Table) -> dict[str, list[object]]:
    return {k: v.tolist() for k, v in table.columns.items()}


def test_preamble_lines_are_skipped(tmp_path):
    path = _write(
        tmp_path / "log.csv",
        "Fs,100\nLogger v2\nDate: 2026-01-01\n\nt,ax,ay\n0,1.5,2\n0.01,-3,4e-3\n",
    )
    table = _fast(path)
    _same(table, read_careful(path))
    assert table.names == ["t", "ax", "ay"]
    assert table.notes == ["skipped 3 preamble line(s)"]
    assert _columns(table) == {"t": [0, 0.01], "ax": [1.5, -3], "ay": [2, 4e-3]}
    path = _write(tmp_path / "b.tsv", "Logger v2\nFs\t100\nt\tax\tay\n0\t1\t2\n1\t3\t4\n")
    table = _fast(path)
    assert table.names == ["t", "ax", "ay"] and table.notes == ["skipped 2 preamble line(s)"]


def test_hash_headers(tmp_path):
    for header in ("# t,ax,ay", "#t,ax,ay", "  # t , ax , ay"):
        path = _write(tmp_path / "log.csv", f"# logger v2\n{header}\n0,1,2\n\n1,3,4\n")
        table = _fast(path)
        _same(table, read_careful(path))
        assert table.names == ["t", "ax", "ay"]
        assert table.notes == ["header read from the '#' line 2"]
        assert _columns(table) == {"t": [0, 1], "ax": [1, 3], "ay": [2, 4]}
    path = _write(tmp_path / "tab.tsv", "Logger v2\n#t\tax\tay\n0\t1\t2\n")
    table = read_table(path)
    assert table.names == ["t", "ax", "ay"]
    assert table.notes == ["skipped 1 preamble line(s)", "header read from the '#' line 2"]
    # another header wins: the '#' line stays a comment
    path = _write(tmp_path / "both.csv", "# a,b,c\nt,ax,ay\n0,1,2\n")
    assert read_table(path).names == ["t", "ax", "ay"] and read_table(path).notes == []


@pytest.mark.parametrize(
    ("content", "message"),
    [
        # no header at all: the last '#' line does not fit the data
        ("# t,ax\n0,1,2\n", "the first line is numbers, not a header"),
        ("# t,ax,ay\n# units: g\n0,1,2\n", "the first line is numbers, not a header"),
        # a commented-out data row is not a header
        ("#0,1,2\n0,1,2\n", "the first line is numbers, not a header"),
        # a preamble with no header below it
        ("Logger v2\n0,1,2\n3,4,5\n", r"first line 'Logger v2' is not a header"),
        ("device,imu-7\n0,1,2\n3,4,5\n", r"header line 'device,imu-7' has 2 field"),
        # a data-like line above the header would be data left out: ambiguous, refused
        ("1,2,3\nLogger\nt,a,b\n4,5,6\n", r"first line is numbers"),
        # two lines as wide as the data above it (a header and a units row?): ambiguous
        ("Logger v2\nt,ax,ay\nunits,g,g\n0,1,2\n", r"first line 'Logger v2' is not a header"),
    ],
)
def test_ambiguous_layouts_keep_todays_errors(tmp_path, content, message):
    path = _write(tmp_path / "log.csv", content)
    with pytest.raises(InputError, match=message):
        read_table(path)
    _agree(path)


def test_decimal_commas(tmp_path):
    path = _write(tmp_path / "log.csv", "t;ax;ay;pose\n0,5;-9,81;1e-3;a\n1,5;0,25;nan;b\n")
    table = _fast(path)
    _same(table, read_careful(path))
    assert table.decimal == "," and table.notes == ["decimal commas read as points"]
    assert table.columns["t"].tolist() == [0.5, 1.5]
    assert table.columns["ax"].tolist() == [-9.81, 0.25]
    assert table.columns["ay"][0] == 1e-3 and np.isnan(table.columns["ay"][1])
    assert table.columns["pose"].tolist() == ["a", "b"]
    # tab separated, asked for; and blank separated only when asked for
    path = _write(tmp_path / "log.tsv", "t\tax\n0,5\t-1,25\n")
    assert _columns(read_table(path, decimal=",")) == {"t": [0.5], "ax": [-1.25]}
    assert read_table(path).notes == ["decimal commas read as points"]
    path = _write(tmp_path / "log.txt", "t ax\n0,5 -1,25\n")
    with pytest.raises(InputError, match="separated by ','"):  # not recognised with blanks
        read_table(path)
    assert _columns(read_table(path, decimal=",")) == {"t": [0.5], "ax": [-1.25]}
    # a point anywhere in the numbers: not recognised, and refused when asked for
    path = _write(tmp_path / "mixed.csv", "t;ax\n0,5;1.5\n")
    assert read_table(path).decimal == "."
    table = read_table(path, decimal=",")
    with pytest.raises(
        InputError, match=r"column 'ax' has a non-numeric value '1.5' at data row 1"
    ):
        table.numeric("ax")
    # a text column of a decimal-comma log is read as numbers with commas
    path = _write(tmp_path / "bad.csv", "t;ax\n0,5;1,5\n1,5;oops\n")
    table = read_table(path)
    assert table.decimal == ","
    with pytest.raises(InputError, match=r"'ax' has a non-numeric value 'oops' at data row 2"):
        table.numeric("ax")


def test_decimal_option_is_checked(tmp_path):
    path = _write(tmp_path / "log.csv", "t,ax\n0,1\n")
    with pytest.raises(InputError, match=r"decimal must be '\.' or ','.*got ';'"):
        read_table(path, decimal=";")
    with pytest.raises(InputError, match=r"decimal=',' needs columns separated by ';'"):
        read_table(path, decimal=",")
    assert read_table(path, decimal=".").columns["ax"].tolist() == [1.0]


def test_text_columns_empty_fields_and_line_endings(tmp_path):
    content = (
        "\ufeff# banner\r\ndevice,t,pose,ax\r\n\r\nimu-7,0,still 1,1\r\n# between\r\n"
        "imu-7,1,,\r\n  imu-8 , 2 ,still 2, -0\r\n"
    )
    path = _write(tmp_path / "log.csv", content)
    table = _fast(path)
    _same(table, read_careful(path))
    assert table.columns["device"].tolist() == ["imu-7", "imu-7", "imu-8"]
    assert table.columns["pose"].tolist() == ["still 1", "", "still 2"]
    assert table.columns["t"].tolist() == [0, 1, 2]
    ax = table.columns["ax"]
    assert ax[0] == 1 and np.isnan(ax[1]) and ax[2] == 0 and np.signbit(ax[2])
    path = _write(tmp_path / "log.txt", "t  ax ay\n\n0 1 2\n  1\t3   4  \n")
    assert _columns(_fast(path)) == {"t": [0, 1], "ax": [1, 3], "ay": [2, 4]}


def test_blocks_progress_and_one_array(tmp_path):
    rng = np.random.default_rng(5)
    data = rng.normal(size=(3000, 4))
    lines = ["t,ax,ay,az"] + [",".join(repr(v) for v in row) for row in data.tolist()]
    path = _write(tmp_path / "log.csv", "\n".join(lines) + "\n")
    seen: list[str] = []
    with (
        mock.patch.object(text_module, "BLOCK_BYTES", 4096),
        mock.patch.object(text_module, "PROGRESS_ROWS", 1000),
    ):
        table = read_table(path, on_progress=seen.append)
    assert seen == [f"reading log.csv: {n:,} rows" for n in (1000, 2000, 3000)]
    assert np.array_equal(np.column_stack([table.columns[n] for n in table.names]), data)
    # the numeric columns are views of one array: memory is the numbers, nothing per column
    base = table.columns["t"].base
    assert base is not None and all(table.columns[n].base is base for n in table.names)
    _same(table, read_careful(path))
    # the careful reader (a quote) reports once, at the end
    _write(path, "t,ax\n" + '"1",2\n' * 5)
    seen.clear()
    assert read_table(path, on_progress=seen.append).columns["t"].tolist() == [1.0] * 5
    assert seen == ["reading log.csv: 5 rows"]


def test_limits_are_kept(tmp_path):
    rows = "".join(f"{i},{i},{i}\n" for i in range(5))
    long = _write(tmp_path / "a.csv", f"ax,ay,az\n{rows}1,{'9' * 1001},3\n{rows}")
    with pytest.raises(InputError, match=r"data row 6 has a field of 1,001 characters"):
        read_table(long)  # a number of 1,001 digits, which numpy would read
    with pytest.raises(InputError, match=r"column name 'ay' appears twice"):
        read_table(_write(tmp_path / "b.csv", f"ax,ay,ay\n{rows}"))
    with pytest.raises(InputError, match=r"data row 3 has 2 fields but the header has 3"):
        read_table(_write(tmp_path / "c.csv", "ax,ay,az\n1,2,3\n1,2,3\n1,2\n1,2,3\n"))


# ----------------------------------------------------------------------------- random files
_NAMES = ["t", "ax", "ay", "az", "mx", "my", "mz", "pose", "Accel X (g)", "dev", "n_samples"]
_LABELS = st.text(alphabet=string.ascii_letters + string.digits + " -_.#", max_size=6)


def _number(decimal: str) -> st.SearchStrategy[str]:
    values = st.one_of(
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
        st.floats(-1e4, 1e4).map(lambda v: f"{v:.3f}"),
        st.floats(-1e4, 1e4).map(lambda v: f"{v:.6g}"),
        st.integers(-(10**12), 10**12).map(str),
        st.sampled_from(["", " ", "nan", "-0", "1e-320", " 2.5 ", "inf", "-Infinity"]),
    )
    return values.map(lambda v: v.replace(".", ",")) if decimal == "," else values


@st.composite
def _logs(draw: st.DrawFn) -> tuple[str, str | None]:
    """A well-formed text log (as its content) and the decimal option to read it with."""
    delimiter = draw(st.sampled_from([",", ";", "\t", " "]))
    decimal = "," if delimiter != "," and draw(st.booleans()) else "."
    n_cols = draw(st.integers(1, 6))
    names = draw(st.lists(st.sampled_from(_NAMES), min_size=n_cols, max_size=n_cols, unique=True))
    if delimiter == " ":
        names = [n.replace(" ", "_") for n in names]
    text_cols = draw(st.sets(st.integers(0, n_cols - 1), max_size=2))
    n_rows = draw(st.integers(1, 40))
    rows = []
    for _ in range(n_rows):
        row = []
        for j in range(n_cols):
            cell = draw(_LABELS if j in text_cols else _number(decimal))
            if delimiter == " ":
                cell = cell.replace(" ", "") or "0"
            row.append(cell)
        rows.append(row)
    sep = delimiter if delimiter != " " else draw(st.sampled_from([" ", "  ", "\t", " \t "]))
    lines = [sep.join(row) for row in rows]
    for _ in range(draw(st.integers(0, 3))):  # blank and comment lines among the data
        at = draw(st.integers(0, len(lines)))
        lines.insert(at, draw(st.sampled_from(["", "  ", "# note", "#", " # x,1"])))
    header = sep.join(names)
    if draw(st.booleans()) and draw(st.booleans()):
        header = draw(st.sampled_from(["# ", "#"])) + header
    preamble = draw(
        st.lists(
            st.sampled_from(["Logger v2", "Fs,100", "Date: 2026-01-01", "sep=;", "# banner"]),
            max_size=3,
        )
    )
    eol = draw(st.sampled_from(["\n", "\r\n"]))
    content = eol.join([*preamble, header, *lines])
    if draw(st.booleans()):
        content += eol
    if draw(st.booleans()):
        content = "\ufeff" + content
    option = draw(st.sampled_from([None, decimal]))
    return content, option


_MUTATIONS = ['"', "\x00", "\r", "\n", "é", "\u00a0", "x", ",", ";", "\t", " ", "#", "1_0",
              "\uff11", "\x0c", "\x1c", "9" * 1001, "\u2028", "\ufeff", ".", "-"]  # fmt: skip


@st.composite
def _damaged(draw: st.DrawFn) -> tuple[str, str | None]:
    content, option = draw(_logs())
    for _ in range(draw(st.integers(1, 3))):
        at = draw(st.integers(0, len(content)))
        if draw(st.booleans()) and at < len(content):
            content = content[:at] + content[at + 1 :]
        else:
            content = content[:at] + draw(st.sampled_from(_MUTATIONS)) + content[at:]
    return content, option


_SETTINGS = settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def _blocks(block: int, arrow: bool):
    """Blocks of ``block`` bytes, parsed by pyarrow (``arrow``, as large files are) or numpy."""
    return mock.patch.multiple(text_module, BLOCK_BYTES=block, **_parser(arrow))


def _parser(arrow: bool) -> dict[str, int]:
    """The thresholds that send every file to pyarrow (``arrow``) or to numpy's parser, whether
    or not this process has loaded pyarrow already."""
    at = 0 if arrow else 1 << 62
    return {"ARROW_MIN_BYTES": at, "ARROW_MIN_BYTES_LOADED": at}


@_SETTINGS
@given(log=_logs(), block=st.integers(16, 600), arrow=st.booleans())
def test_fast_and_careful_agree_on_well_formed_logs(tmp_path, log, block, arrow):
    content, decimal = log
    path = _write(tmp_path / "log.csv", content)
    with _blocks(block, arrow):
        _agree(path, decimal=decimal)


@_SETTINGS
@given(log=_damaged(), block=st.integers(16, 600), arrow=st.booleans())
def test_fast_and_careful_agree_on_damaged_logs(tmp_path, log, block, arrow):
    content, decimal = log
    path = _write(tmp_path / "log.csv", content)
    with _blocks(block, arrow):
        _agree(path, decimal=decimal)


def _head_outcome(read, path: Path):
    """The head's lines and byte-order mark as ``read`` gives them, or "unusual"."""
    with path.open("rb") as handle:
        try:
            return read(handle)
        except text_module._UnusualError:
            return "unusual"


def _head_line_by_line(handle):
    bom = 3 if handle.read(3) == b"\xef\xbb\xbf" else 0
    handle.seek(bom)
    return text_module._head_by_line(handle), bom


@_SETTINGS
@given(log=st.one_of(_logs(), _damaged()), lines=st.integers(1, 12), size=st.integers(1, 300))
def test_the_head_split_at_once_is_the_head_read_line_by_line(tmp_path, log, lines, size):
    """A head read as one block and split (small heads and blocks here, so that the head ends
    inside the file and a block inside a line) is the head read line by line: the same lines,
    or the same giving up (a long line, a lone carriage return, NUL, bytes that are not
    UTF-8 ...)."""
    path = _write(tmp_path / "log.csv", log[0])
    with mock.patch.multiple(text_module, HEAD_LINES=lines, _HEAD_BYTES=size):
        fast = _head_outcome(text_module._read_head, path)
        assert fast == _head_outcome(_head_line_by_line, path)


_ROWS = "".join(f"{i},{i / 7:.6f},-{i}\n" for i in range(40))


@pytest.mark.parametrize(
    ("content", "unusual"),
    [
        (f"t,ax,ay\n{_ROWS}", False),
        (f"t,ax,ay\n{_ROWS}".replace("\n", "\r\n"), False),
        (f"t,ax,ay\n1,2\r3\n{_ROWS}", True),  # a lone carriage return in the head
        (f"t,ax,ay\n{_ROWS}1,2,3\r", True),  # ... ending the file
        (f"t,ax,ay\n{_ROWS}1,2,{'9' * 1000}\n", True),  # a line over LONGEST_FIELD
        (f"t,ax,ay\n{_ROWS}{'9' * 999}\n", False),  # 1,000 bytes with its line break
        (f"t,ax,ay\n{_ROWS}{'9' * 2000}\n", True),
        (f"t,ax,ay\n{_ROWS * 8}1,2,{'9' * 2000}\n", False),  # long, but below the head
        (f"t,ax,ay\n1,2,\x003\n{_ROWS}", True),
        (f"t,ax,ay\n1,2,é\n{_ROWS}", False),  # UTF-8: line by line
        ("t,ax,ay\n1,2,\udcff\n" + _ROWS, True),  # not UTF-8
        (f"\ufefft,ax,ay\n{_ROWS}", False),
        (f"t,ax,ay\n{_ROWS}9,9,9", False),  # no line break at the end
    ],
    ids=lambda v: repr(v)[:24] if isinstance(v, str) else str(v),
)
def test_the_head_split_at_once_gives_up_where_line_by_line_does(tmp_path, content, unusual):
    path = tmp_path / "log.csv"
    path.write_bytes(content.encode("utf-8", "surrogateescape"))
    with mock.patch.multiple(text_module, HEAD_LINES=60, _HEAD_BYTES=64):
        fast = _head_outcome(text_module._read_head, path)
        assert fast == _head_outcome(_head_line_by_line, path)
    assert (fast == "unusual") == unusual


def test_a_plain_head_is_split_at_once(tmp_path):
    """A plain ASCII log's head (LF or CRLF) is one read and one split, not line by line."""
    rows = "".join(f"{i},{i / 7:.6f},-{i}\n" for i in range(3 * text_module.HEAD_LINES))
    for eol in ("\n", "\r\n"):
        path = _write(tmp_path / "log.csv", f"# logger\nt,ax,ay\n{rows}".replace("\n", eol))
        with mock.patch.object(text_module, "_head_by_line", side_effect=AssertionError):
            lines, bom = _head_outcome(text_module._read_head, path)
        assert bom == 0 and len(lines) == text_module.HEAD_LINES + 1
        assert lines[:3] == [f"# logger{eol}", f"t,ax,ay{eol}", f"0,0.000000,-0{eol}"]


@settings(max_examples=300, deadline=None)
@given(line=st.text(alphabet=',;\t "\r\n\x00a1é#', max_size=12))
def test_fields_split_as_the_csv_module_does(line):
    """:func:`text_lines._fields` splits a plain line itself: the csv module's fields, or None
    where it cannot split the line."""
    for delimiter in (",", ";", "\t"):
        try:
            expected = next(csv.reader([line], delimiter=delimiter), [])
        except csv.Error:
            expected = None
        assert text_lines._fields(line, delimiter) == expected


@pytest.mark.parametrize("arrow", [False, True])
@pytest.mark.parametrize("delimiter", [",", ";", "\t", " "])
def test_the_fast_path_reads_well_formed_logs(tmp_path, delimiter, arrow):
    """Well-formed logs (text columns, decimal commas, empty fields) go through the fast path,
    not the careful reader: it reads them alone, and the same; large files (``arrow``) by
    pyarrow alone, blank-separated ones by numpy."""
    values = np.random.default_rng(11).normal(size=(50, 3))
    decimal = "," if delimiter in ";\t" else "."
    lines = [delimiter.join(["pose", "ax", "ay", "az"])]
    for i, row in enumerate(values.tolist()):
        lines.append(delimiter.join([f"p{i // 10}", *(repr(v).replace(".", decimal) for v in row)]))
    if delimiter != " ":
        lines.append(delimiter.join(["", "", "-0", ""]))  # empty fields: NaN, and an empty label
        values = np.vstack([values, [np.nan, -0.0, np.nan]])
    path = _write(tmp_path / "log.csv", "# banner\n" + "\n".join(lines) + "\n")
    with mock.patch.multiple(text_module, **_parser(arrow)):
        if arrow and delimiter != " ":  # numpy's parser is not needed
            with mock.patch.object(text_module, "_block", side_effect=AssertionError):
                table = _fast(path)
        else:
            table = _fast(path)
    _same(table, read_careful(path))
    numbers = np.column_stack([table.columns[n] for n in ("ax", "ay", "az")])
    assert np.array_equal(numbers, values, equal_nan=True)
    assert np.array_equal(np.signbit(numbers), np.signbit(values))
    labels = [f"p{i // 10}" for i in range(50)] + ([""] if delimiter != " " else [])
    assert table.columns["pose"].tolist() == labels


_NO_PANDAS = """
import sys, numpy as np
import fieldcal.logs.apply as a, fieldcal.logs.streamed_text as s, fieldcal.logs.text as t
t.ARROW_MIN_BYTES = s.ARROW_MIN_ROWS = 0
class Cal:
    accel, mag = type("Sensor", (), {"temperature": None})(), None
    correct_accel = staticmethod(lambda raw, temperature=None: 2 * np.asarray(raw))
t.read_text(sys.argv[1])
a.apply_to_file(Cal(), sys.argv[1], sys.argv[2], accel_cols="ax,ay,az")
print(sorted(m for m in ("pyarrow.csv", "pyarrow.compute", "pandas") if m in sys.modules))
"""


@pytest.mark.skipif(importlib.util.find_spec("pandas") is None, reason="pandas not installed")
def test_pyarrow_paths_do_not_load_pandas(tmp_path):
    """pyarrow's ``to_numpy``, ``array`` and ``scalar`` import pandas (a second on a busy
    machine): the reader and apply's bulk formatting use pyarrow without them."""
    lines = ["t,ax,ay,az", *(f"{i},{i / 7},,-{i}" for i in range(50))]
    src = _write(tmp_path / "log.csv", "\n".join(lines) + "\n")
    argv = [sys.executable, "-c", _NO_PANDAS, str(src), str(tmp_path / "out.csv")]
    out = subprocess.run(argv, capture_output=True, text=True, check=True).stdout
    assert out.split() == ["['pyarrow.compute',", "'pyarrow.csv']"]


def test_a_small_log_goes_to_pyarrow_once_it_is_loaded(tmp_path):
    """Below ARROW_MIN_BYTES a log is numpy's unless this process has loaded pyarrow's reader
    (a batch worker does): then pyarrow reads it, the same table."""
    pytest.importorskip(
        "pyarrow.csv", reason="pyarrow (the parquet extra) not installed"
    )  # loaded now, as in a batch worker
    rows = "".join(f"{i},{i / 7},-{i}\n" for i in range(200))
    path = _write(tmp_path / "log.csv", f"t,ax,ay\n{rows}")
    assert path.stat().st_size < text_module.ARROW_MIN_BYTES
    with mock.patch.object(text_module, "_block", side_effect=AssertionError):
        table = _fast(path)  # numpy's parser not needed
    _same(table, read_careful(path))
    with mock.patch.object(text_module, "ARROW_MIN_BYTES_LOADED", 1 << 62):
        spy = mock.patch.object(text_module, "_block", wraps=text_module._block)
        with spy as block:
            _same(_fast(path), table)
        assert block.called


@pytest.mark.parametrize("arrow", [False, True])
def test_quoted_names_stay_on_the_fast_path(tmp_path, arrow):
    """A header quoting its names (R's write.csv, pyarrow) is read by the fast path; a quote
    left open on it (which joins the lines below for the careful reader) is not."""
    rows = "".join(f"{i},{i / 4},-{i}\n" for i in range(20))
    path = _write(tmp_path / "log.csv", f'"t","a,x","ay"\n{rows}')
    with mock.patch.multiple(text_module, **_parser(arrow)):
        table = _fast(path)
        _same(table, read_careful(path))
        assert table.names == ["t", "a,x", "ay"]
        _write(path, f't,ax,"ay\n{rows}')
        with pytest.raises(text_module._UnusualError):
            _fast(path)
        _agree(path)


# ----------------------------------------------------------------------------- apply
@st.composite
def _apply_logs(draw: st.DrawFn) -> str:
    """A log with accelerometer columns, comment and blank lines, either line ending."""
    delimiter = draw(st.sampled_from([",", ";", "\t", " "]))
    decimal = "." if delimiter == "," else draw(st.sampled_from(".,"))
    cell = _number(decimal).map(lambda v: v.strip() or "0" if delimiter == " " else v)
    rows = draw(st.lists(st.lists(cell, min_size=4, max_size=5), min_size=1, max_size=30))
    body = [delimiter.join(["t", "ax", "ay", "az"]), *(delimiter.join(r) for r in rows)]
    for _ in range(draw(st.integers(0, 2))):
        body.insert(draw(st.integers(0, len(body))), draw(st.sampled_from(["", "# c", "  "])))
    eol = draw(st.sampled_from(["\n", "\r\n"]))
    return eol.join(body) + (eol if draw(st.booleans()) else "")


def _apply_outcome(src: Path, dst: Path, chunk: int) -> bytes | str:
    try:
        apply_to_file(_Double(), src, dst, chunk_rows=chunk, mag_cols=None)
    except InputError as exc:
        assert "\n" not in str(exc)
        return str(exc)
    return dst.read_bytes()


@_SETTINGS
@given(content=_apply_logs(), damage=st.lists(st.sampled_from(_MUTATIONS), max_size=2),
       where=st.integers(0, 10**6), chunk=st.integers(1, 12), arrow=st.booleans())  # fmt: skip
def test_apply_vectorised_is_the_line_by_line_result(
    tmp_path, content, damage, where, chunk, arrow
):
    """The same bytes or error, the values formatted in bulk (``arrow``, as large chunks are)
    or one line at a time."""
    for piece in damage:
        at = where % (len(content) + 1)
        content = content[:at] + piece + content[at:]
    src = _write(tmp_path / "log.csv", content)
    with mock.patch.object(streamed_module, "ARROW_MIN_ROWS", 0 if arrow else 1 << 62):
        fast = _apply_outcome(src, tmp_path / "fast.csv", chunk)
    with mock.patch.object(streamed_module, "_fast_chunk", lambda *args: None):
        slow = _apply_outcome(src, tmp_path / "slow.csv", chunk)
    assert fast == slow


def test_apply_formats_in_bulk_as_repr_does():
    """pyarrow formats the calibrated values as ``repr`` would, at the edges of its layout too
    (exponents, whole numbers, zeros, NaN, the limits of positional notation)."""
    rng = np.random.default_rng(3)
    edges = [0.0, -0.0, np.nan, np.inf, -np.inf, 1e16, 9999999999999998.0, 1e15, 1e-4,
             0.00009999999999999999, 123.0, -5e-324, 1.7976931348623157e308,
             202493980069443.22]  # fmt: skip
    values = np.concatenate([edges, 10.0 ** rng.uniform(-8, 20, 3000) * rng.choice([-1, 1], 3000)])
    columns = [values, rng.normal(size=values.size), np.round(rng.normal(size=values.size), 2)]
    rows = zip(*(c.tolist() for c in columns), strict=True)
    expected = [";" + ";".join(map(repr, row)) for row in rows]
    assert streamed_module._bulk_tails(columns, ";", ".") == expected
    commas = streamed_module._bulk_tails(columns, ";", ",")
    assert commas == [t.replace(".", ",") for t in expected]


def test_apply_keeps_a_preamble_a_hash_header_and_decimal_commas(tmp_path):
    src = _write(
        tmp_path / "log.csv",
        "Logger v2\r\n# t;ax;ay;az\r\n0,5;1,25;-2;3e-3\r\n# mid\r\n1,5;0,5;1;nan\r\n",
    )
    apply_to_file(_Double(), src, tmp_path / "out.csv", mag_cols=None)
    assert (tmp_path / "out.csv").read_bytes().decode() == (
        "Logger v2\r\n# t;ax;ay;az;ax_cal;ay_cal;az_cal\r\n0,5;1,25;-2;3e-3;2,5;-4,0;0,006\r\n"
        "# mid\r\n1,5;0,5;1;nan;1,0;2,0;nan\r\n"
    )
    table = read_table(tmp_path / "out.csv")  # and it reads back
    assert table.names[-3:] == ["ax_cal", "ay_cal", "az_cal"]
    assert table.columns["ax_cal"].tolist() == [2.5, 1.0]


# ----------------------------------------------------------------------------- metadata
_BODY = "t,ax,ay,az\n0,1,2,3\n1,4,5,6\n"


@pytest.mark.parametrize(
    "preamble, expected",
    [
        ("# device: IMU-0042\n# Firmware Version = 1.2\n", {"device": "IMU-0042",
         "firmware_version": "1.2"}),
        ("Serial Number,SN-77\nLogger v2\n", {"serial_number": "SN-77"}),
        ("# board_id: A 1\n# device: first\n# device: second\n",
         {"board_id": "A 1", "device": "first"}),
        ("# x,y,z\n", {}),  # a three-field line is not metadata
        ("", {}),
    ],
)  # fmt: skip
def test_text_metadata_above_the_header(tmp_path, preamble, expected):
    path = _write(tmp_path / "log.csv", preamble + _BODY)
    fast, careful = _fast(path), read_careful(path)
    _same(fast, careful)
    assert fast.metadata == expected
    assert fast.names == ["t", "ax", "ay", "az"]


def test_log_device_from_each_format(tmp_path):
    from fieldcal.logs import load_log

    rows = "t,ax,ay,az,mx,my,mz\n" + "".join(f"{i},{i % 3},1,2,{i % 5},4,5\n" for i in range(10))
    csv = _write(tmp_path / "a.csv", "# Serial Number: SN-1\n# device: IMU-7\n" + rows)
    assert load_log(str(csv)).device == "IMU-7"  # "device" outranks "serial_number"
    data = np.loadtxt(csv, delimiter=",", skiprows=3)
    np.savez(tmp_path / "b.npz", t=data[:, 0], accel=data[:, 1:4], mag=data[:, 4:7], sn="SN-9")
    assert load_log(str(tmp_path / "b.npz")).device == "SN-9"
    pa = pytest.importorskip("pyarrow", reason="pyarrow (the parquet extra) not installed")
    pq = pytest.importorskip("pyarrow.parquet", reason="pyarrow (the parquet extra) not installed")
    names = ["t", "ax", "ay", "az", "mx", "my", "mz"]
    table = pa.table({n: data[:, j] for j, n in enumerate(names)})
    table = table.replace_schema_metadata({b"Device ID": b"PQ-3"})
    pq.write_table(table, tmp_path / "c.parquet")
    assert load_log(str(tmp_path / "c.parquet")).device == "PQ-3"
    plain = _write(tmp_path / "d.csv", rows)
    assert load_log(str(plain)).device is None


@pytest.mark.parametrize("cell", ["\uff11\uff12", "\u0661\u0662", "\u0967", "1_000", "1e1_0"])
@pytest.mark.parametrize("rows", [40, 30_000])
def test_non_ascii_digits_and_underscores_are_not_numbers(tmp_path, cell, rows):
    """Python's float() reads '１２' (full width), '١٢' (Arabic-Indic) and '1_000'; numpy's
    and pyarrow's parsers do not: neither reader takes them, and the error names the cell."""
    body = "\n".join(f"{i % 7},0.{i % 9},1,2,3,4" for i in range(rows))
    path = tmp_path / "log.csv"
    path.write_text(f"ax,ay,az,mx,my,mz\n{body}\n{cell},1,1,1,1,1\n", encoding="utf-8")
    for reader in (read_text, read_careful):
        table = reader(path)
        assert table.columns["ax"].dtype.kind != "f"  # text, not numbers
        with pytest.raises(InputError, match=f"non-numeric value '{cell}' at data row {rows + 1}"):
            table.numeric("ax")
    assert read_text(path).columns["ay"].dtype.kind == "f"  # the other columns stay numbers


def test_a_truncated_npz_is_refused_and_closed(tmp_path):
    """np.load hands its file to the zip reader, which fails on a cut archive: the reader
    opens the file itself, so nothing is left open (a ResourceWarning at the next collection)."""
    import gc
    import io

    buf = io.BytesIO()
    np.savez(buf, ax=np.ones(100), ay=np.ones(100), az=np.ones(100))
    path = tmp_path / "log.npz"
    path.write_bytes(buf.getvalue()[:200])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(InputError, match=r"not a readable \.npz archive"):
            read_table(path)
        gc.collect()
    assert not [w for w in caught if issubclass(w.category, ResourceWarning)]
