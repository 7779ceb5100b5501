"""The capture's raw log on a disk that fills up, and the lines a stream loses: one ``Error:``
line and no thread's traceback; dropped data lines counted by reason, shown, and warned of by
the verdict (``dropped_lines``) beyond 1 %."""

from __future__ import annotations

import errno
import json
import os
import threading
import time

import pytest
from click.testing import CliRunner

import fieldcal
from fieldcal.capture import recorder as recorder_module
from fieldcal.capture.recorder import Recorder
from fieldcal.cli import cli
from fieldcal.errors import InputError
from fieldcal.logs.stream import DROPPED_REASONS, LineParser
from fieldcal.simulation.continuous import simulate_continuous
from fieldcal.trust.verdict import DROPPED_LINES, with_dropped_lines


class _FullDisk:
    """A text file on a disk with ``room`` characters left: writes beyond it and every flush
    after it fail with ENOSPC, as a real full file system does (the buffer's flush fails);
    with ``room`` 0 the writes are buffered and the first flush fails."""

    def __init__(self, real, room):
        self.real, self.room, self.written, self.closed = real, room, 0, False

    def _full(self):
        return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def write(self, text):
        self.written += len(text)
        if 0 < self.room < self.written:
            raise self._full()
        return self.real.write(text)

    def flush(self):
        if self.written > self.room:
            raise self._full()
        self.real.flush()

    def fileno(self):
        return self.real.fileno()

    def close(self):
        self.closed = True
        self.real.close()
        if self.written > self.room:
            raise self._full()


@pytest.fixture
def full_disk(monkeypatch):
    """The recorder's files open on a disk with ``room[0]`` characters left."""
    room = [0]

    def opener(*args, **kwargs):
        return _FullDisk(open(*args, **kwargs), room[0])

    monkeypatch.setattr(recorder_module, "open", opener, raising=False)
    return room


@pytest.fixture
def thread_errors(monkeypatch):
    """Exceptions that escaped a thread (each would print a traceback)."""
    seen = []
    monkeypatch.setattr(threading, "excepthook", lambda args: seen.append(args.exc_value))
    return seen


def test_the_flushing_thread_records_a_full_disk_quietly(tmp_path, full_disk, thread_errors):
    parser = LineParser()
    rec = Recorder(tmp_path / "cap", parser, flush_seconds=0.01, flush_lines=10**9)
    rec.feed("t,ax,ay,az,mx,my,mz", 0.0)  # buffered: the thread's flush is the first to fail
    for _ in range(500):  # the thread flushes every 10 ms
        if rec.failure is not None:
            break
        time.sleep(0.01)
    assert rec.failure is not None and "No space left on device" in rec.failure
    with pytest.raises(InputError, match=r"cannot be written .* give another --out folder"):
        rec.feed("0,0,0,1,1,0,0", 0.1)
    assert rec.close() == rec.partial and rec.partial.exists()  # incomplete: keeps its name
    assert thread_errors == []


def test_capture_onto_a_full_disk_is_one_error_line(tmp_path, full_disk, thread_errors):
    path = tmp_path / "log.csv"
    simulate_continuous("paper", seed=4, n_poses=8).write_csv(str(path))
    full_disk[0] = 20_000
    out = tmp_path / "cap"
    result = CliRunner().invoke(cli, ["capture", "--from", str(path), "--plain", "--out", out])
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    assert "log.csv.partial: cannot be written (No space left on device)" in lines[0]
    assert "Traceback" not in result.output and thread_errors == []
    assert (out / "log.csv.partial").exists() and not (out / "cal.json").exists()


def _garbled(path, every, bad="0,nan,0,0,0,0,0,0,0,0"):
    """The log with every ``every``-th data line replaced by a line the parser drops."""
    header, *rows = path.read_text().splitlines()
    rows = [bad if i % every == every - 1 else r for i, r in enumerate(rows)]
    return header, rows


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    path = tmp_path_factory.mktemp("log") / "session.csv"
    simulate_continuous("paper", seed=5).write_csv(str(path))
    return path


@pytest.mark.parametrize(("every", "warned"), [(20, True), (400, False)])
def test_dropped_data_lines_are_counted_shown_and_warned_of(recorded, tmp_path, every, warned):
    header, rows = _garbled(recorded, every)
    rows[10] = "MPU9250 ready"  # a debug print: skipped, not a data line lost
    out = tmp_path / "cap"
    result = CliRunner().invoke(
        cli, ["capture", "--from", "-", "--plain", "--out", out], input="\n".join([header, *rows])
    )
    assert result.exit_code in (0, 3), result.output
    dropped = sum(1 for i in range(len(rows)) if i % every == every - 1 and i != 10)
    document = json.loads((out / "cal.json").read_text())
    assert document["capture"]["skipped"] == {"not a number": dropped, "text": 1}
    assert document["capture"]["dropped"] == dropped
    shown = [line for line in result.output.splitlines() if line.startswith("skipped ")]
    assert shown == [f"skipped {dropped + 1} line(s): text 1, not a number {dropped}; "
                     f"{dropped} of them data lines lost"]  # fmt: skip
    codes = [r["code"] for r in document["verdict"]["reasons"]]
    assert ("dropped_lines" in codes) == warned
    assert (dropped / (dropped + document["capture"]["rows"]) > DROPPED_LINES) == warned
    if warned:
        assert document["verdict"]["level"] in ("warn", "fail")
        final = [line for line in result.output.splitlines() if line.startswith("calibration: ")]
        assert "dropped_lines" in final[-1]  # the running line carries the codes


def test_the_dropped_lines_rule():
    s = fieldcal.simulate("paper", seed=1)
    verdict = fieldcal.calibrate(s.accel, s.mag).verdict
    assert verdict.level == "pass"
    assert with_dropped_lines(verdict, {"not a number": 10}, 990) is verdict  # 1.0 %: not more
    warned = with_dropped_lines(verdict, {"not a number": 8, "field count": 3}, 990)
    assert warned.level == "warn" and warned.codes == ("dropped_lines", *verdict.codes)
    assert "11 of 1001 data lines (1.1%)" in warned.reasons[0].text
    assert "not a number 8, field count 3" in warned.reasons[0].text
    assert set(DROPPED_REASONS) >= {"not a number", "field count", "binary"}
    assert "partial line" not in DROPPED_REASONS and "text" not in DROPPED_REASONS
