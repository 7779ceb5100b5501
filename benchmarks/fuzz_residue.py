"""Issue 22's fuzzing residue as cases of ``benchmarks/fuzz.py`` (category ``residue``).

Each item the issue listed is one case (or a few): a full file system under ``capture``,
``batch --scheduler bogus``, the greedy method on data scaled by 1e-30, ``plan_poses(cal,
10**6)``, a capture dropping a fifth of its lines, a log without its ``ax`` or ``mz`` column,
absurd calibration values, non-ASCII digits and ``1_000``, ``apply`` on 10,000 NUL bytes,
``store list`` across different ``--gravity``, and a board whose header came before the port
was opened. A case that must be refused and is accepted is ``nonsense``; a case that must be
accepted and is refused is a ``traceback`` (the classifiers of ``fuzz.py``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import io
import json
import os
import threading
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np

import fieldcal
from fieldcal.capture import recorder as recorder_module
from fieldcal.limits import MOST_PLANNED
from fieldcal.simulation.continuous import simulate_continuous

CATEGORY = "residue"
#: The outcome of one case: (outcome, detail).
Outcome = tuple[str, str]
Cli = Callable[..., Outcome]
Library = Callable[..., Outcome]


def _csv(path: Path, columns: dict[str, np.ndarray]) -> Path:
    names = list(columns)
    data = np.column_stack([np.asarray(columns[k], float) for k in names])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.9g")
    return path


def _stream(folder: Path) -> tuple[Path, list[str], list[str]]:
    """A continuous log (header, rows) written to ``folder/stream.csv``."""
    path = folder / "stream.csv"
    simulate_continuous("paper", seed=3, n_poses=10).write_csv(str(path))
    header, *rows = path.read_text().splitlines()
    return path, [header], rows


class _FullDisk(io.StringIO):
    """A file on a disk that is full after ``room`` characters (ENOSPC on write and flush)."""

    def __init__(self, real: Any, room: int) -> None:
        super().__init__()
        self.real, self.room, self.written = real, room, 0

    def write(self, text: str) -> int:
        self.written += len(text)
        if self.written > self.room:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return int(self.real.write(text))

    def flush(self) -> None:
        if self.written > self.room:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.real.flush()

    def fileno(self) -> int:
        return int(self.real.fileno())

    def close(self) -> None:
        self.real.close()
        super().close()


@contextlib.contextmanager
def _thread_errors() -> Iterator[list[BaseException]]:
    """Exceptions escaping a thread while the case runs (each would print a traceback)."""
    seen: list[BaseException] = []
    old = threading.excepthook
    threading.excepthook = lambda args: seen.append(args.exc_value)  # type: ignore[assignment]
    try:
        yield seen
    finally:
        threading.excepthook = old


def _full_disk(cli: Cli) -> Callable[[Path], Outcome]:
    def run(folder: Path) -> Outcome:
        path, _, _ = _stream(folder)
        real_open = open

        def opener(*args: Any, **kwargs: Any) -> _FullDisk:
            return _FullDisk(real_open(*args, **kwargs), 20_000)

        with (
            _thread_errors() as seen,
            mock.patch.object(recorder_module, "open", opener, create=True),
        ):
            outcome = cli(["capture", "--from", path, "--plain", "--out", folder / "cap"])
        if seen:
            return "traceback", f"a thread raised {type(seen[0]).__name__}: {seen[0]}"
        if outcome[0] == "error" and "No space left on device" not in outcome[1]:
            return "nonsense", f"the error does not say the disk is full: {outcome[1]}"
        return outcome if outcome[0] != "ok" else ("nonsense", "a full disk went unnoticed")

    return run


def _dropped_lines(cli: Cli) -> Callable[[Path], Outcome]:
    def run(folder: Path) -> Outcome:
        _, header, rows = _stream(folder)
        rows = ["0,nan,1,2,3,4,5,6,7,8" if i % 5 == 4 else r for i, r in enumerate(rows)]
        path = folder / "garbled.csv"
        path.write_text("\n".join(header + rows) + "\n")
        out = folder / "cap"
        outcome = cli(["capture", "--from", path, "--plain", "--out", out])
        if outcome[0] != "ok":
            return outcome
        document = json.loads((out / "cal.json").read_text())
        codes = [r["code"] for r in document["verdict"]["reasons"]]
        skipped = document["capture"].get("skipped", {})
        if "dropped_lines" not in codes or not skipped.get("not a number"):
            return "nonsense", f"20 % of the lines dropped, verdict codes {codes}"
        return outcome

    return run


def _headerless(cli: Cli) -> Callable[[Path], Outcome]:
    def run(folder: Path) -> Outcome:
        _, _, rows = _stream(folder)
        path = folder / "bare.csv"
        path.write_text("\n".join(rows[300:]) + "\n")
        out = folder / "cap"
        outcome = cli(["capture", "--from", path, "--plain", "--out", out])
        if outcome[0] == "ok" and not (out / "cal.json").exists():
            return "traceback", "no calibration written"
        return outcome

    return run


def _missing_column(cli: Cli, drop: str, sensors: str | None) -> Callable[[Path], Outcome]:
    def run(folder: Path) -> Outcome:
        s = fieldcal.simulate("paper", seed=2, n_poses=12, samples=(40, 40))
        a, m = np.concatenate(s.accel), np.concatenate(s.mag)
        columns = {"pose": np.repeat(np.arange(12), 40).astype(float)}
        columns.update({f"a{c}": a[:, j] for j, c in enumerate("xyz")})
        columns.update({f"m{c}": m[:, j] for j, c in enumerate("xyz")})
        del columns[drop]
        path = _csv(folder / "log.csv", columns)
        args: list[object] = ["calibrate", path, "-o", folder / "c.json"]
        if sensors is None:
            return cli(args, nonsense=True)  # must be refused, naming the column
        return cli([*args, "--sensors", sensors], output=folder / "c.json")

    return run


def _odd_number(cli: Cli, cell: str) -> Callable[[Path], Outcome]:
    def run(folder: Path) -> Outcome:
        s = fieldcal.simulate("paper", seed=2, n_poses=12, samples=(40, 40))
        a, m = np.concatenate(s.accel), np.concatenate(s.mag)
        lines = ["pose,ax,ay,az,mx,my,mz"]
        lines += [f"{i // 40},{','.join(f'{v:.9g}' for v in (*a[i], *m[i]))}" for i in range(480)]
        lines[200] = lines[200].split(",", 1)[0] + f",{cell}," + lines[200].split(",", 2)[2]
        path = folder / "log.csv"
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")
        return cli(["calibrate", path, "-o", folder / "c.json"], nonsense=True)

    return run


def _absurd_file(cli: Cli, base_doc: dict[str, Any], key: str, value: float) -> Callable:
    """A calibration file with one absurd gain or bias: refused on load, naming the key."""

    def run(folder: Path) -> Outcome:
        doc = json.loads(json.dumps(base_doc))
        sensor, part = key.split(".")
        if value < 1:  # a uniformly tiny gain: well conditioned, its inverse beyond the range
            doc[sensor][part] = (value * np.eye(3)).tolist()
        elif part == "gain":
            doc[sensor][part][0][0] = value
        else:
            doc[sensor][part][0] = value
        path = folder / "cal.json"
        path.write_text(json.dumps(doc))
        outcome = cli(["export", path, "--format", "c-header", "-o", folder / "c.h"], nonsense=True)
        if outcome[0] == "error" and key not in outcome[1]:
            return "nonsense", f"refused without naming {key}: {outcome[1]}"
        return outcome

    return run


def _nul_apply(cli: Cli, base_doc: dict[str, Any]) -> Callable[[Path], Outcome]:
    def run(folder: Path) -> Outcome:
        cal = folder / "cal.json"
        cal.write_text(json.dumps(base_doc))
        log = folder / "log.csv"
        log.write_bytes(b"\x00" * 10_000)
        outcome = cli(["apply", cal, log, "-o", folder / "out.csv"], nonsense=True)
        if outcome[0] == "error" and ("\x00" in outcome[1] or len(outcome[1]) > 300):
            return "noisy", f"the error echoes the file ({len(outcome[1])} characters)"
        return outcome

    return run


def _store_gravity(cli: Cli, cal: fieldcal.Calibration) -> Callable[[Path], Outcome]:
    def run(folder: Path) -> Outcome:
        store = fieldcal.Store(folder / "store")
        store.add(dataclasses.replace(cal, created="2026-01-01T00:00:00Z"), device="d")
        later = cal.with_field_magnitudes(gravity=9.80665)
        store.add(dataclasses.replace(later, created="2026-02-01T00:00:00Z"), device="d")
        return cli(["store", "list", "d", "--store", folder / "store"])

    return run


def residue_cases(
    base_doc: dict[str, Any],
    cal: fieldcal.Calibration,
    cli: Cli,
    library: Library,
    case: Callable[[str, str, Callable[[Path], Outcome], float], Any],
) -> Sequence[Any]:
    """The residue's cases; ``cli``/``library`` classify a command line / a call (``fuzz.py``'s
    ``cli_outcome``/``library_outcome``), ``case(category, name, run, timeout)`` makes one."""

    def scheduler(folder: Path) -> Outcome:
        log = _csv(folder / "log.csv", {c: np.ones(20) for c in ("ax", "ay", "az")})
        return cli(["batch", log, "--out", folder / "out", "--scheduler", "bogus"], nonsense=True)

    def greedy(folder: Path) -> Outcome:
        # 1,200 rows; seed 3 descends for minutes: the time limit (20 s) stops it
        s = fieldcal.simulate("paper", seed=3, n_poses=15, samples=(80, 80))
        tiny = 1e-30
        return library(
            lambda: fieldcal.calibrate(
                [x * tiny for x in s.accel], [x * tiny for x in s.mag], method="greedy"
            )
        )

    def plan(folder: Path) -> Outcome:
        return library(lambda: fieldcal.plan_poses(cal, 10**6), nonsense=True)

    def plan_most(folder: Path) -> Outcome:
        return library(lambda: fieldcal.plan_poses(cal, MOST_PLANNED)[-1])

    items: list[tuple[str, Callable[[Path], Outcome], float]] = [
        ("capture onto a full file system", _full_disk(cli), 60.0),
        ("batch --scheduler bogus", scheduler, 10.0),
        ("greedy on data scaled by 1e-30 (1,200 rows)", greedy, 60.0),
        ("plan_poses(cal, 10**6)", plan, 20.0),
        (f"plan_poses(cal, {MOST_PLANNED})", plan_most, 60.0),
        ("capture with a fifth of its lines NaN", _dropped_lines(cli), 60.0),
        ("capture of a board whose header came before the port opened", _headerless(cli), 60.0),
        ("a log without its ax column", _missing_column(cli, "ax", None), 20.0),
        ("a log without its mz column", _missing_column(cli, "mz", None), 20.0),
        ("a log without its ax column, --sensors mag", _missing_column(cli, "ax", "mag"), 20.0),
        ("a log without its mz column, --sensors accel", _missing_column(cli, "mz", "accel"), 20),
        ("apply on 10,000 NUL bytes", _nul_apply(cli, base_doc), 20.0),
        ("store list across different --gravity", _store_gravity(cli, cal), 20.0),
    ]
    for key, value in (("accel.gain", 1e300), ("mag.gain", 1e-300), ("mag.bias", 1e308)):
        name = f"a calibration file with {key} {value:g}"
        items.append((name, _absurd_file(cli, base_doc, key, value), 20.0))
    for cell in ("\uff11\uff12", "\u0661\u0662", "1_000"):
        items.append((f"a log with the number {cell!r}", _odd_number(cli, cell), 20.0))
    return [case(CATEGORY, name, run, timeout) for name, run, timeout in items]
