"""Live streams: the line parser (header variants, bare numbers, garbage counted, fuzzed), the
raw recorder (read back by the offline reader as the parser's very table; crash-safe), the
sources (a simulated board on a pty through pyserial, disconnects, standard input, a
followed file) and the simulated board itself."""

from __future__ import annotations

import importlib.util
import io
import math
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from _device import BINARY, BOOT, DEBUG, HEADER, PARTIAL_FIRST, PtyDevice, needs_serial
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fieldcal
from fieldcal.capture import feeds as sources_module
from fieldcal.capture.feeds import End, Line, LineSplitter, PartialLine, open_source
from fieldcal.capture.recorder import Recorder, escape
from fieldcal.errors import InputError
from fieldcal.geometry.rotations import exp_so3, random_rotations
from fieldcal.logs import text as text_module
from fieldcal.logs.columns import recognise_columns
from fieldcal.logs.log import load_log
from fieldcal.logs.readers import read_table
from fieldcal.logs.stream import (
    ARRIVAL,
    ARRIVAL_AS_TIME,
    GUESS_LINES,
    GUESS_MOST,
    REASONS,
    LineParser,
)
from fieldcal.simulation.continuous import simulate_continuous
from fieldcal.simulation.device import Device, geodesic

COLUMNS = ["t", "ax", "ay", "az", "mx", "my", "mz"]


def _feed(parser: LineParser, lines, start: float = 0.0, step: float = 0.01) -> list[bool]:
    return [parser.feed(line, start + i * step) for i, line in enumerate(lines)]


def _balanced(parser: LineParser) -> bool:
    header = parser.header_index is not None
    return parser.n_rows + sum(parser.skipped.values()) + header == parser.lines


# ----------------------------------------------------------------------------- the parser
def test_header_after_garbage_then_rows_with_their_values():
    parser = LineParser()
    lines = [
        "3,0.1,",  # the end of a line cut at connect
        "MPU9250 ready",
        "[I] calib: 3 poses",
        "t,ax,ay,az,mx,my,mz",
        "0.00,0.01,-0.02,0.98,0.31,0.02,-0.44",
        "0.01, 0.011 ,-2e-2,9.8E-1,.31,+0.02,-44e-2\r\n",
    ]
    kept = _feed(parser, lines)
    assert kept == [False] * 4 + [True, True]
    assert parser.skipped == {"before header": 3}
    assert parser.header == tuple(COLUMNS) and parser.header_index == 3
    assert parser.names == [*COLUMNS, ARRIVAL] and parser.time_column == "t"
    table = parser.table()
    np.testing.assert_array_equal(table.columns["ax"], [0.01, 0.011])
    np.testing.assert_array_equal(table.columns["mz"], [-0.44, -0.44])
    np.testing.assert_array_equal(table.columns[ARRIVAL], [0.04, 0.05])
    assert _balanced(parser)


@pytest.mark.parametrize(
    ("header", "row", "delimiter", "decimal"),
    [
        ("t;ax;ay;az;mx;my;mz", "0,5;0,01;-0,02;0,98;0,3;0,0;-0,4", ";", ","),
        ("t\tax\tay\taz\tmx\tmy\tmz", "0.5\t0.01\t-0.02\t0.98\t0.3\t0\t-0.4", "\t", "."),
        ("t ax ay az mx my mz", " 0.5  0.01 -0.02 0.98 0.3 0 -0.4 ", None, "."),
        ("# t,ax,ay,az,mx,my,mz", "0.5,0.01,-0.02,0.98,0.3,0,-0.4", ",", "."),
        ('"t","ax","ay","az","mx","my","mz"', "0.5,0.01,-0.02,0.98,0.3,0,-0.4", ",", "."),
        ("\ufefft,ax,ay,az,mx,my,mz", "0.5,0.01,-0.02,0.98,0.3,0,-0.4", ",", "."),
    ],
)
def test_header_variants(header, row, delimiter, decimal):
    parser = LineParser()
    assert _feed(parser, [header, row]) == [False, True]
    assert parser.header == tuple(COLUMNS)
    assert (parser.delimiter, parser.decimal) == (delimiter, decimal)
    table = parser.table()
    assert [float(table.columns[n][0]) for n in COLUMNS] == [0.5, 0.01, -0.02, 0.98, 0.3, 0, -0.4]


def test_units_in_names_and_a_trailing_delimiter():
    """``Acc X (g)`` names are recognised as offline; a trailing delimiter on every line is an
    unnamed column whose empty fields are NaN (as the offline reader reads it)."""
    parser = LineParser()
    assert _feed(parser, ["Acc X (g),Acc Y (g),Acc Z (g),", "0.1,0.2,0.3,", "1,2,3,4"]) == [
        False,
        True,
        True,
    ]
    assert parser.names == ["Acc X (g)", "Acc Y (g)", "Acc Z (g)", "", ARRIVAL_AS_TIME]
    column = parser.table().columns[""]
    assert math.isnan(column[0]) and column[1] == 4.0
    assert parser.has("accel") and not parser.has("mag") and parser.time_column == ARRIVAL_AS_TIME


def test_every_reason_is_counted_and_nothing_is_fatal():
    parser = LineParser()
    lines = [
        "boot",  # before header
        "t,ax,ay,az,mx,my,mz",
        "0," * 500 + "0",  # too long
        "0,1,2,\x003,4,5,6",  # binary (NUL)
        "0,1,2,\ufffd,4,5,6",  # binary (bytes that were not UTF-8)
        "   ",  # blank
        "# a comment",
        "t,ax,ay,az,mx,my,mz",  # repeated header (a device that reset)
        "t,ax,ay,az,mx,my,mz,temp",  # another header
        "[I] calib...",  # text
        "nan,1,2,3,4,5,6",  # not a number: a data line with a NaN reading (a data line lost)
        "0,1,2,3,4,5",  # field count
        "0,1,,3,4,5,6",  # not a number (empty field)
        "0,1.2.3,2,3,4,5,6",  # not a number
        "0,1,2,3,4,5,1e999",  # out of range
        "0,1,2,3,4,5,1e151",  # out of range (LARGEST = 1e150)
        "0,1,2,3,4,5,1e150",  # kept: the largest reading accepted
    ]
    kept = _feed(parser, lines)
    assert kept == [False] * 16 + [True]
    assert dict(parser.skipped) == {
        "before header": 1,
        "too long": 1,
        "binary": 2,
        "blank": 1,
        "comment": 1,
        "repeated header": 1,
        "another header": 1,
        "text": 1,
        "field count": 1,
        "not a number": 3,
        "out of range": 2,
    }
    assert set(parser.skipped) <= set(REASONS)
    assert _balanced(parser) and parser.last_reason is None
    # the data lines lost: garbled, cut, NaN, out of range (not blanks, comments, prints)
    assert parser.dropped == 1 + 2 + 1 + 3 + 2


def test_partial_lines_are_skipped_but_a_header_is_taken():
    parser = LineParser()
    assert not parser.feed("t,ax,ay,az,mx,my,mz", 0.0, partial=True)
    assert parser.last_reason == "header"
    assert not parser.feed("0,1,2,3,4,5,6", 0.1, partial=True)
    assert parser.last_reason == "partial line"
    assert parser.feed("0,1,2,3,4,5,6", 0.2)
    assert parser.n_rows == 1


def test_bare_numbers_with_columns():
    parser = LineParser(COLUMNS)
    lines = ["1,2,3", "0,1,2,3,4,5,6", "0.5 1 2 3 4 5 6", "0.01,1e-3,2,3,4,5,-6"]
    assert _feed(parser, lines) == [False, True, False, True]
    assert parser.skipped == {"field count": 2}
    assert parser.delimiter == "," and parser.header_line is None
    np.testing.assert_array_equal(parser.table().columns["mz"], [6.0, -6.0])
    assert _balanced(parser)


def test_bare_numbers_with_semicolons_and_decimal_commas():
    parser = LineParser(COLUMNS)
    assert _feed(parser, ["0,5;0,01;-0,02;0,98;0,3;0;-0,4", "0.6;1;2;3;4;5;6"]) == [True, False]
    assert (parser.delimiter, parser.decimal) == (";", ",")
    assert parser.skipped == {"not a number": 1}
    assert parser.table().columns["ay"][0] == -0.02
    explicit = LineParser(COLUMNS, decimal=",")
    assert explicit.feed("1 2,5 3 4 5 6 7", 0.0) and explicit.delimiter is None


def test_columns_are_checked():
    for columns, part in (
        (["t", "ax"], "three distinct"),
        (["ax", "ay", "ax"], "three distinct"),
        (["a x", "ay", "az"], "delimiter"),
        (["p", "q", "r"], "no accelerometer or magnetometer"),
    ):
        with pytest.raises(InputError, match=part):
            LineParser(columns)
    with pytest.raises(InputError, match="decimal"):
        LineParser(decimal=";")
    with pytest.raises(ValueError, match="arrival"):
        LineParser().feed("x", math.nan)


def test_arrival_column_names_and_time():
    """``arrival_s`` is not a time name (the stream's time is used: a replay at any speed
    gives the same log); ``time_arrival_s`` is, and carries the time when there is no other."""
    assert recognise_columns(["t", "ax", "ay", "az", ARRIVAL]).get("time") == ["t"]
    assert recognise_columns(["ax", "ay", "az", ARRIVAL]).get("time") is None
    assert recognise_columns(["ax", "ay", "az", ARRIVAL_AS_TIME])["time"] == [ARRIVAL_AS_TIME]
    rows = [f"{0.01 * i:.2f},0.1,0.2,0.98,0.3,0,{0.4 + 0.001 * i:.3f}" for i in range(50)]
    logs = []
    for step in (0.001, 0.05):  # replayed fast, and slower than real time
        parser = LineParser()
        _feed(parser, ["t,ax,ay,az,mx,my,mz", *rows], step=step)
        logs.append(load_log(parser.table()))
    np.testing.assert_array_equal(logs[0].time, logs[1].time)
    np.testing.assert_allclose(logs[0].time, 0.01 * np.arange(50), atol=1e-12)
    bare = LineParser(["ax", "ay", "az"])
    _feed(bare, ["0.1,0.2,0.9"] * 5, start=1.0, step=0.02)
    log = load_log(bare.table())
    assert log.used["time"] == [ARRIVAL_AS_TIME]
    np.testing.assert_allclose(log.time, 0.02 * np.arange(5), atol=1e-12)


def test_arrays_grow_and_tables_are_fixed_views():
    rng = np.random.default_rng(3)
    values = rng.standard_normal((10_000, 7))
    lines = [",".join(repr(float(v)) for v in row) for row in values]
    parser = LineParser()
    parser.feed("t,ax,ay,az,mx,my,mz", 0.0)
    _feed(parser, lines[:3000], start=1.0)
    early = parser.table()
    _feed(parser, lines[3000:], start=1.0 + 3000 * 0.01)
    late = parser.table()
    assert early.n_rows == 3000 and late.n_rows == 10_000
    for j, name in enumerate(COLUMNS):
        np.testing.assert_array_equal(late.columns[name], values[:, j])
        np.testing.assert_array_equal(early.columns[name], values[:3000, j])
        assert not late.columns[name].flags.writeable
    np.testing.assert_array_equal(
        late.columns[ARRIVAL], [float(f"{1.0 + i * 0.01:.6f}") for i in range(10_000)]
    )


# property tests: never an exception, every valid line kept exactly, counts add up
_NUMBERS = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
_FORMATS = st.sampled_from(["{!r}", "{:.6g}", "{:e}", "{:.3f}", " {:.9g} ", "{:+.4E}"])
_GARBAGE = st.one_of(
    st.text(max_size=40).map(lambda s: s + "k"),  # a letter no number holds: never data
    st.binary(max_size=40).map(lambda b: b.decode("utf-8", "replace") + "\x00"),
    st.sampled_from(["", "MPU9250 ready", "t,ax,ay,az,mx,my,mz", "1,2", "#x", "1,,2,3,4,5,6"]),
)


@st.composite
def _stream(draw):
    """A header, then valid rows and garbage mixed; the valid rows' values as written."""
    delimiter = draw(st.sampled_from([",", ";", "\t", " "]))
    lines = [delimiter.join(COLUMNS) if delimiter != " " else " ".join(COLUMNS)]
    expected = []
    for _ in range(draw(st.integers(0, 25))):
        if draw(st.booleans()):
            fmt = draw(_FORMATS)
            cells = [fmt.format(draw(_NUMBERS)) for _ in COLUMNS]
            lines.append(delimiter.join(cells))
            expected.append([float(c) for c in cells])
        else:
            lines.append(draw(_GARBAGE))
    return lines, expected


@settings(max_examples=100, suppress_health_check=[HealthCheck.too_slow])
@given(_stream())
def test_fuzz_valid_rows_are_kept_exactly(stream):
    lines, expected = stream
    parser = LineParser()
    _feed(parser, lines)
    table = parser.table()
    got = np.column_stack([table.columns[n] for n in COLUMNS]) if expected else None
    assert parser.n_rows == len(expected)
    if expected:
        np.testing.assert_array_equal(got, np.array(expected))
    assert _balanced(parser)


@settings(max_examples=100)
@given(st.lists(st.binary(max_size=60), max_size=20), st.sampled_from([None, COLUMNS]))
def test_fuzz_any_bytes_never_raise(chunks, columns):
    parser = LineParser(columns)
    splitter = LineSplitter(longest=50)
    for i, chunk in enumerate([b"t,ax,ay,az,mx,my,mz\n", *chunks]):
        for text, cut in splitter.feed(chunk):
            parser.feed(text, 0.001 * i, partial=cut)
    rest = splitter.rest()
    if rest is not None:
        parser.feed(rest, 1.0)
    parser.table()
    assert _balanced(parser)


# ----------------------------------------------------------------------------- the recorder
def _same_table(a, b) -> None:
    assert a.names == b.names
    for name in a.names:
        assert np.array_equal(a.columns[name], b.columns[name], equal_nan=True), name


_SESSIONS = {
    "header": (
        None,
        [
            "0.98,0.1",
            'MPU9250 "ready"',
            "t,ax,ay,az,gx,gy,gz,mx,my,mz",
            *[
                f"{0.01 * i:.2f},0.01,-0.02,0.98,0,0,0,0.3,0.02,{-0.44 - 1e-4 * i:.4f}"
                for i in range(30)
            ],
            "\x00\xff garbage \\ µT",
            "t,ax,ay,az,gx,gy,gz,mx,my,mz",
            "0.31,0.01,-0.02",
            "0.32,0.01,-0.02,0.98,0,0,0,0.3,0.02,-0.44",
        ],
    ),
    "semicolons": (
        None,
        [
            "# t;ax;ay;az;mx;my;mz",
            *[f"{i},0;0,01;-0,02;0,98;0,3;0,02;-0,44" for i in range(20)],
            "1.5;0.1;0.2;0.3;0.4;0.5;0.6",
        ],
    ),
    "bare": (
        ["ax", "ay", "az", "mx", "my", "mz"],
        ["01,0.98", "[I] calib", *["0.01 -0.02 0.98 0.3 0.02 -0.44"] * 20, "1 2 3"],
    ),
}


@pytest.mark.parametrize("kind", list(_SESSIONS))
def test_recorder_round_trip(tmp_path, kind):
    """The recorded file, read by ``fieldcal.read_log`` (the calibrate command's reader, on
    its fast path), gives the parser's table exactly; skipped lines are comments."""
    columns, lines = _SESSIONS[kind]
    parser = LineParser(columns)
    with Recorder(tmp_path, parser) as recorder:
        for i, line in enumerate(lines):
            recorder.feed(line, 0.0123456789 + 0.0137 * i)
        assert recorder.path == tmp_path / "log.csv.partial"
    assert recorder.path == tmp_path / "log.csv" and not (tmp_path / "log.csv.partial").exists()
    written = (tmp_path / "log.csv").read_text(encoding="utf-8").splitlines()
    comments = [w for w in written if w.startswith("# skipped ")]
    assert len(comments) == sum(parser.skipped.values())
    assert all(w.isascii() and '"' not in w for w in comments)
    fast = text_module._read_fast(tmp_path / "log.csv", None, None)  # no fallback needed
    _same_table(fast, parser.table())
    log, mine = fieldcal.read_log(tmp_path / "log.csv"), load_log(parser.table())
    for name in ("accel", "mag", "time"):
        np.testing.assert_array_equal(getattr(log, name), getattr(mine, name))


@settings(max_examples=40, suppress_health_check=[HealthCheck.too_slow])
@given(_stream())
def test_fuzz_recorded_logs_read_back_exactly(stream):
    lines, expected = stream
    parser = LineParser()
    with tempfile.TemporaryDirectory() as folder:
        with Recorder(folder, parser) as recorder:
            for i, line in enumerate(lines):
                recorder.feed(line, 0.37 * i)
        if expected:  # (a header without rows is no log to read)
            _same_table(
                text_module._read_fast(Path(folder) / "log.csv", None, None), parser.table()
            )


def test_recorder_format(tmp_path):
    parser = LineParser()
    with Recorder(tmp_path, parser) as recorder:
        recorder.feed("boot\x01", 0.5)
        recorder.feed("t,ax,ay,az", 1.0)
        recorder.feed("0,1,2,3\r\n", 1.25)
    assert (tmp_path / "log.csv").read_text().splitlines() == [
        "# skipped binary at 0.500000: boot\\x01",
        "t,ax,ay,az,arrival_s",
        "0,1,2,3,1.250000",
    ]
    assert escape('a"\\\tµ') == "a\\x22\\\\\\t\\xb5"
    assert escape("x" * 1000).endswith("... (1000 characters)")
    (tmp_path / "log.csv").unlink()
    Recorder(tmp_path, LineParser())  # left open: an interrupted capture
    with pytest.raises(InputError, match=r"log\.csv\.partial: exists"):
        Recorder(tmp_path, LineParser())


_KILLED = """
import sys, time
from fieldcal.capture.recorder import Recorder
from fieldcal.logs.stream import LineParser
recorder = Recorder(sys.argv[1], LineParser(), flush_seconds=0.2, flush_lines=1000)
recorder.feed("t,ax,ay,az", 0.0)
for i in range(1500):
    recorder.feed(f"{i},0.1,0.2,{i}", 0.001 * i)
    if i == 10:
        recorder.feed("garbage", 0.0105)
time.sleep(0.3)  # more than flush_seconds
print("ready", flush=True)
time.sleep(30)
"""


def test_a_killed_recorder_leaves_every_flushed_line(tmp_path):
    process = subprocess.Popen(
        [sys.executable, "-c", _KILLED, str(tmp_path)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert process.stdout is not None and process.stdout.readline().strip() == "ready"
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    partial = tmp_path / "log.csv.partial"
    assert not (tmp_path / "log.csv").exists()
    table = read_table(partial)
    np.testing.assert_array_equal(table.columns["t"], np.arange(1500))
    arrival = [float(f"{0.001 * i:.6f}") for i in range(1500)]  # to the microsecond
    np.testing.assert_array_equal(table.columns["arrival_s"], arrival)
    assert partial.read_text().count("# skipped text at 0.010500: garbage") == 1


# ----------------------------------------------------------------------------- the sources
def _collect(source, timeout: float = 10.0) -> list:
    source.start()
    items = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        item = source.get(timeout=1.0)
        if item is None:
            continue
        items.append(item)
        if isinstance(item, End):
            return items
    raise AssertionError(f"no end within {timeout} s ({len(items)} items)")


def _poses(n: int, seed: int = 0):
    return list(random_rotations(n, np.random.default_rng(seed)))


@needs_serial
def test_serial_port_delivers_every_line_in_order():
    """A board on a pty read through pyserial: every line written, in order, the first marked
    as possibly cut; the board unplugged at the end gives "disconnected"."""
    with PtyDevice(_poses(3), seed=1, garbage=True, hold=1.0, end="disconnect") as device:
        with open_source(port=device.port) as source:
            source.start()
            device.start()
            items = _collect(source)
        assert device.wait(5)
    *lines, end = items
    assert [line.text for line in lines] == device.lines()
    assert isinstance(lines[0], PartialLine) and lines[0].text == PARTIAL_FIRST.decode().strip()
    assert not any(isinstance(line, PartialLine) for line in lines[1:])
    assert end.kind == "disconnected" and end.reason.startswith(f"disconnected: {device.port}")
    arrivals = [line.arrival for line in lines]
    assert arrivals == sorted(arrivals) and 0 <= arrivals[0] <= end.arrival < 10
    assert source.get(0) is end  # the end stays
    assert {BOOT, DEBUG, BINARY, (HEADER + "\n").encode()} <= set(device.written)


@needs_serial
def test_device_asks_for_each_pose_and_paces_its_rows():
    """A callable plays the user (asked for pose i when it is due; None ends); ``speed``
    paces the rows in real time (here 5x: 2 s of rows take about 0.4 s)."""
    rotations = _poses(2, seed=6)
    asked = []

    def next_pose(i):
        asked.append(i)
        return rotations[i] if i < 2 else None

    device = PtyDevice(next_pose, hold=0.5, move=(1.0, 1.0), speed=5.0, end="disconnect")
    with device, open_source(port=device.port) as source:
        source.start()
        device.start()
        items = _collect(source)
    *lines, end = items
    assert asked == [0, 1, 2] and end.kind == "disconnected"
    assert device.pose_rows == [(0, 50), (150, 200)] and device.rows == 200
    np.testing.assert_array_equal(device.rotations, rotations)
    assert 0.3 < lines[-1].arrival - lines[1].arrival < 2.0


@needs_serial
def test_serial_disconnect_mid_stream_keeps_every_line_before_it(tmp_path):
    """Unplugged after 250 lines: the lines before it all arrive, then "disconnected"; the
    capture's pieces (parser, recorder) keep the rows, and the rows of each pose are the
    board's readings in that pose (the truth's prediction, within the noise)."""
    rotations = _poses(4, seed=2)
    with PtyDevice(rotations, seed=2, disconnect_after=250, hold=1.0) as device:
        source = open_source(port=device.port)
        source.start()
        device.start()
        items = _collect(source)
        source.close()
    *lines, end = items
    assert end.kind == "disconnected" and len(lines) == 250
    assert [line.text for line in lines] == device.lines()
    parser = LineParser()
    with Recorder(tmp_path, parser) as recorder:
        for line in lines:
            recorder.feed(line.text, line.arrival, partial=isinstance(line, PartialLine))
    assert parser.n_rows == 249 and parser.skipped == {}
    log = fieldcal.read_log(tmp_path / "log.csv")
    truth = device.device.drawn
    start, stop = device.pose_rows[0]
    mean = log.accel[start:stop].mean(axis=0)
    expected = truth["accel_gain"] @ rotations[0] @ truth["gravity"] + truth["accel_bias"]
    sigma = np.sqrt(np.diag(truth["accel_cov"]) / (stop - start))
    assert np.all(np.abs(mean - expected) < 5 * sigma)


@needs_serial
def test_close_is_prompt_for_every_source(tmp_path, monkeypatch):
    read, write = os.pipe()
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(os.fdopen(read, "rb")))
    followed = tmp_path / "grow.csv"
    followed.write_text("t,ax,ay,az\n0,1,2")  # a partial line being written
    with PtyDevice(_poses(1), hold=0.5) as device:
        for source in (
            open_source(port=device.port),
            open_source(path="-"),
            open_source(path=followed, follow=True),
        ):
            source.start()
            if source.name == device.port:
                device.start()
            time.sleep(0.15)
            started = time.monotonic()
            source.close()
            assert time.monotonic() - started < 5.0, (
                source.name
            )  # no hang (a blocked read would wait forever)
            items = []
            while (item := source.get(0)) is not None and not isinstance(item, End):
                items.append(item)
            if source.name == str(followed):
                assert items == [
                    Line(items[0].arrival, "t,ax,ay,az"),
                    PartialLine(items[1].arrival, "0,1,2"),
                ]
    os.close(write)


def test_standard_input_from_a_pipe(monkeypatch):
    read, write = os.pipe()
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(os.fdopen(read, "rb")))
    source = open_source(path="-", t0=time.monotonic() - 100.0)
    source.start()
    os.write(write, b"t,ax,ay,az\r\n0,1,")
    time.sleep(0.15)
    os.write(write, b"2,3\r")
    time.sleep(0.15)
    os.write(write, b"\n1,1,2,3")  # the CR LF split between writes: one line end
    os.close(write)
    items = _collect(source)
    source.close()
    assert [i.text for i in items[:-1]] == ["t,ax,ay,az", "0,1,2,3", "1,1,2,3"]
    assert not any(isinstance(i, PartialLine) for i in items)  # the end of a pipe ends lines
    assert items[-1] == End("end", "end of input", items[-1].arrival)
    assert all(100.0 <= i.arrival < 110.0 for i in items)


def test_standard_input_in_memory(monkeypatch):
    """Standard input without a file descriptor (a test runner's) is read too."""
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(b"t,ax,ay,az\n0,1,2,3")))
    items = _collect(open_source(path="-"))
    assert [i.text for i in items[:-1]] == ["t,ax,ay,az", "0,1,2,3"]
    assert items[-1].reason == "end of input"


def test_standard_input_of_a_process():
    code = textwrap.dedent(
        """
        from fieldcal.capture.feeds import End, open_source
        source = open_source(path="-")
        source.start()
        while not isinstance(item := source.get(), End):
            print(ascii(item.text))
        print(item.reason)
        """
    )
    data = b"t,ax,ay,az\n\xff\xfe\n0,1,2,3\r1,1,2,3"
    out = subprocess.run(
        [sys.executable, "-c", code], input=data, capture_output=True, check=True, timeout=60
    )
    assert out.stdout.decode().splitlines() == [
        "'t,ax,ay,az'",
        "'\\ufffd\\ufffd'",
        "'0,1,2,3'",
        "'1,1,2,3'",
        "end of input",
    ]


def test_follow_a_growing_file(tmp_path):
    """Lines appended by a writer arrive, a line written in two parts arrives once whole,
    and a truncated file stops the source, saying so."""
    path = tmp_path / "log.csv"
    path.write_text("t,ax,ay,az\n0,0.1,0.2,0.9\n")
    source = open_source(path=path, follow=True)
    source.start()

    def writer():
        with path.open("a") as handle:
            for i in range(1, 4):
                handle.write(f"{i},0.1,0.2,0.9\n")
                handle.flush()
                time.sleep(0.05)
            handle.write("4,0.1,")
            handle.flush()
            time.sleep(0.3)  # longer than the poll: the reader sees the partial line
            handle.write("0.2,0.9\n")
            handle.flush()
            time.sleep(0.3)
        path.write_text("")  # truncated

    thread = threading.Thread(target=writer)
    thread.start()
    items = _collect(source)
    thread.join()
    source.close()
    *lines, end = items
    assert [line.text for line in lines] == ["t,ax,ay,az", *(f"{i},0.1,0.2,0.9" for i in range(5))]
    assert end.kind == "disconnected" and "was truncated" in end.reason


def test_a_file_is_read_to_its_end(tmp_path):
    path = tmp_path / "log.csv"
    path.write_bytes(b"t,ax,ay,az\r0,1,2,3\r\n1,1,2,3\n2,1,2,3")
    items = _collect(open_source(path=str(path)))
    assert [i.text for i in items[:-1]] == ["t,ax,ay,az", "0,1,2,3", "1,1,2,3", "2,1,2,3"]
    assert items[-1].reason == "end of input"


def test_the_splitter():
    splitter = LineSplitter(longest=8)
    assert splitter.feed(b"a\r") == [("a", False)]
    assert splitter.feed(b"\nb\n\nc\r\r\n") == [
        ("b", False),
        ("", False),
        ("c", False),
        ("", False),
    ]
    assert splitter.feed(b"0123456789") == [("0123456789", True)]
    assert splitter.feed(b"\xe2\x82") == [] and splitter.feed(b"\xac\n") == [("€", False)]
    assert splitter.feed(b"x") == [] and splitter.rest() == "x" and splitter.rest() is None


def test_opening_errors_are_one_line(tmp_path, monkeypatch):
    def one_line(match: str, **options):
        with pytest.raises(InputError, match=match) as info:
            open_source(**options)
        assert "\n" not in str(info.value)
        return str(info.value)

    one_line("port, or a file")
    one_line("port, or a file", port="/dev/x", path="-")
    one_line("follow", path="-", follow=True)
    one_line("no such file", path=tmp_path / "missing.csv")
    one_line("is a folder", path=tmp_path)
    one_line("is a device", path=os.devnull)
    if importlib.util.find_spec("serial") is not None:  # a port's own checks need pyserial
        message = one_line("/dev/ttyNOPE42: no such serial port", port="/dev/ttyNOPE42")
        assert "ports found" in message or "no serial ports found" in message
        one_line("not a serial port", port=os.devnull)
        one_line("baud", port="/dev/x", baud=0)
        with PtyDevice(_poses(1)) as device, open_source(port=device.port):
            one_line("in use by another program", port=device.port)
    real = sources_module.importlib.import_module

    def without_serial(name, *args):
        if name == "serial":
            raise ImportError(name)
        return real(name, *args)

    monkeypatch.setattr(sources_module.importlib, "import_module", without_serial)
    assert one_line("pyserial", port="/dev/x") == (
        "reading a serial port needs pyserial: pip install 'fieldcal[serial]'"
    )


# ----------------------------------------------------------------------------- the device
def test_device_is_deterministic_and_follows_the_model():
    R = _poses(2, seed=4)
    a, b = Device(seed=7), Device(seed=7)
    for device in (a, b):
        device.still(R[0], 1.0)
    x, y = a.move(R[0], R[1], 1.5), b.move(R[0], R[1], 1.5)
    np.testing.assert_array_equal(x.accel, y.accel)
    np.testing.assert_array_equal(x.gyro, y.gyro)
    assert a.session.truth == fieldcal.simulate("paper", seed=7).truth
    np.testing.assert_allclose(x.t, 1.0 + np.arange(150) / 100.0)
    still = a.still(R[1], 5.0)
    d = a.drawn
    for sensor, field in (("accel", "gravity"), ("mag", "magnetic")):
        values = getattr(still, sensor)
        expected = d[f"{sensor}_gain"] @ R[1] @ d[field] + d[f"{sensor}_bias"]
        sigma = np.sqrt(np.diag(d[f"{sensor}_cov"]) / len(values))
        assert np.all(np.abs(values.mean(axis=0) - expected) < 5 * sigma)
        cov = np.cov(values.T)
        np.testing.assert_allclose(np.diag(cov), np.diag(d[f"{sensor}_cov"]), rtol=0.3)


def test_gyroscope_reads_the_body_frame_turn():
    """Integrating the noise-free reading (dR/dt = -[ω]× R, v_body = R v_world) from the
    start rotation ends at the stop rotation."""
    start, stop = _poses(2, seed=5)
    m, rate = 400, 100.0
    rotations, omega = geodesic(start, stop, m, rate)
    R = start
    for w in omega:
        R = exp_so3(-w / rate) @ R
    np.testing.assert_allclose(R, stop, atol=1e-4)
    np.testing.assert_allclose(rotations[-1], stop, atol=1e-4)


# ----------------------------------------------------------------------------- no header
@pytest.fixture(scope="module")
def moving():
    """A continuous log whose rows from 300 on start mid-motion (the port opened late)."""
    return simulate_continuous("paper", seed=5).columns


def _bare(columns, names, start=300, count=1500):
    return [",".join(f"{columns[n][i]:.7g}" for n in names) for i in range(start, start + count)]


TEN = ("t", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz")


@pytest.mark.parametrize(
    "names",
    [TEN, TEN[1:], ("t", "ax", "ay", "az", "mx", "my", "mz"), ("ax", "ay", "az", "mx", "my", "mz")],
)
def test_a_stream_without_its_header_is_read_by_its_layout(moving, names):
    """9 or 10 numbers: [t,] acc, gyro, mag; 6 or 7: [t,] acc, mag; said in a note."""
    parser = LineParser()
    lines = _bare(moving, names)
    _feed(parser, lines)
    assert parser.header == names and parser.layout_problem is None
    assert f"{len(names)} numbers per line read as {','.join(names)}" in parser.layout_note
    skipped = parser.skipped["before header"]
    assert GUESS_LINES <= skipped <= GUESS_MOST and parser.n_rows == len(lines) - skipped
    assert _balanced(parser)
    table = parser.table()
    first = lines[skipped].split(",")
    assert [table.columns[n][0] for n in names] == [float(x) for x in first]
    if len(names) >= 9:  # the board moved within the lines read: the gyroscope was checked
        assert "the middle three read near zero at rest: the gyroscope" in parser.layout_note


@pytest.mark.parametrize(
    ("names", "problem"),
    [
        (TEN[1:4] + TEN[7:] + TEN[4:7], "the last three read near zero at rest"),
        (TEN[4:7] + TEN[1:4] + TEN[7:], "the first three read near zero at rest"),
        (TEN[:8], "lines of 8 numbers fit no layout fieldcal knows"),
        (("t", "ax", "ay", "az", "mx", "my"), "their first number increases like a time"),
        (TEN[1:8], "does not increase as a time would"),  # 7 numbers, the first not a time
    ],
)
def test_a_layout_that_does_not_fit_is_refused_naming_why(moving, names, problem):
    parser = LineParser()
    _feed(parser, _bare(moving, names))
    assert parser.header is None and parser.n_rows == 0
    assert problem in parser.layout_problem and parser.layout_note is None


def test_a_board_at_rest_waits_for_motion_then_takes_the_usual_order(moving):
    parser = LineParser()
    _feed(parser, _bare(moving, TEN[1:], start=0, count=GUESS_MOST + 10))
    assert parser.header == TEN[1:] and parser.skipped["before header"] == GUESS_MOST
    assert "not checked: no motion yet" in parser.layout_note
