"""Fuzzing fieldcal's input paths (issue #10, "nothing lost, never a traceback").

Seeded generators of malformed input; every case runs in this process with a timeout and its
outcome is classified:

- ``ok`` — a result: a calibration (exit code 0, or 3 for a fail verdict), a table, a text;
- ``error`` — one line: ``Error: ...`` on stderr and exit code 2 from the command line, a
  ``ValueError`` (:class:`fieldcal.InputError`) with a one-line message from the library;
- ``usage`` — click's own block for an option value of the wrong type (``Usage:``, ``Try ...``
  and one ``Error: ...`` line, exit code 2), before fieldcal sees the value;
- ``traceback`` — any other exception or exit code: a bug;
- ``hang`` — no answer within the per-case timeout: a bug;
- ``noisy`` — an error of more than one line (or over 400 characters), or warnings (numpy's
  ``RuntimeWarning`` ...) printed: a bug;
- ``nonsense`` — a result for input that has none: the same columns for both sensors, pose
  labels shuffled across the rows, a singular or non-finite gain in a calibration file. Such a
  case must give an error or the verdict ``fail``; anything else is a bug.

Categories: ``log files`` (mutated CSV, NPZ and Parquet logs and special files, through
``fieldcal calibrate``), ``options`` (command-line option sets on valid logs), ``calibration
files`` (mutated JSON through ``Calibration.from_json`` and whatever reads a calibration:
corrections, every export format, ``fieldcal export``, ``apply`` and ``report``) and ``library
calls`` (``fieldcal.calibrate`` and the other public functions with odd inputs and options);
a last row, apart, fuzzes ``fieldcal.simulate`` and ``fieldcal.metrics`` (outside this work).

    python benchmarks/fuzz.py               # the full corpus, writes docs/benchmarks.md (fuzz)
    python benchmarks/fuzz.py --quick       # a small corpus, no docs update
    python benchmarks/fuzz.py --keep DIR    # keep the inputs of every failing case in DIR

``tests/test_fuzz.py`` runs a bounded corpus with fixed seeds in CI and asserts no bug.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import shutil
import signal
import stat
import sys
import tempfile
import time
import traceback
import warnings
import zipfile
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from fuzz_residue import CATEGORY as RESIDUE
from fuzz_residue import residue_cases

import fieldcal
from fieldcal.calibration import Calibration
from fieldcal.serialize import SCHEMA_VERSION

#: The row of the functions outside this work (simulation/, metrics.py), kept apart.
OUTSIDE = "simulate, metrics"
CATEGORIES = ("log files", "options", "calibration files", "library calls", RESIDUE, OUTSIDE)
OUTCOMES = ("ok", "error", "usage", "traceback", "hang", "noisy", "nonsense")
#: Outcomes that are bugs.
BUGS = ("traceback", "hang", "noisy", "nonsense")
#: Longest acceptable one-line error message.
LONGEST_MESSAGE = 400

#: Cases per category: the full corpus and the quick one.
FULL = {
    "log files": 1200,
    "options": 800,
    "calibration files": 800,
    "library calls": 3000,
    RESIDUE: 1,  # every case of issue 22's list, whatever the count
    OUTSIDE: 200,
}
QUICK = {
    "log files": 60,
    "options": 40,
    "calibration files": 60,
    "library calls": 150,
    RESIDUE: 1,
    OUTSIDE: 20,
}

NAN, INF = float("nan"), float("inf")


# ============================================================================ outcomes
@dataclass
class Result:
    category: str
    name: str
    outcome: str
    detail: str = ""
    seconds: float = 0.0


@dataclass
class Case:
    """One fuzz case: ``run(folder)`` writes its inputs into ``folder`` and returns
    (outcome, detail); ``name`` says what was done, so the case can be rebuilt."""

    category: str
    name: str
    run: Callable[[Path], tuple[str, str]]
    timeout: float = 20.0


class _Timeout(BaseException):
    """Raised by the alarm; a BaseException so no ``except Exception`` swallows it."""


@contextlib.contextmanager
def _alarm(seconds: float) -> Iterator[None]:
    def handler(signum: int, frame: object) -> None:
        raise _Timeout

    old = signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _one_line(message: str) -> bool:
    return bool(message.strip()) and "\n" not in message.strip() and len(message) <= LONGEST_MESSAGE


def _where(exc: BaseException) -> str:
    """The innermost frame of fieldcal's code (or the last frame) that raised ``exc``."""
    frames = traceback.extract_tb(exc.__traceback__)
    ours = [f for f in frames if "fieldcal" in f.filename and "benchmarks" not in f.filename]
    f = (ours or frames or [None])[-1]
    if f is None:
        return ""
    return f" at {Path(f.filename).name}:{f.lineno}"


def _exception(exc: BaseException) -> str:
    text = " ".join(str(exc).split())[:200]
    return f"{type(exc).__name__}: {text}{_where(exc)}"


def _noise(caught: Sequence[warnings.WarningMessage]) -> list[str]:
    """Warnings a user should never see: numpy's floating-point and conversion warnings (not
    fieldcal's own, which say something about the result)."""
    loud = (RuntimeWarning, np.exceptions.ComplexWarning, DeprecationWarning)
    return [
        f"{w.category.__name__}: {w.message} ({Path(w.filename).name}:{w.lineno})"
        for w in caught
        if issubclass(w.category, loud) and not w.category.__module__.startswith("fieldcal")
    ]


#: numpy's own messages, which tell a user nothing about the input (numpy's words exactly:
#: fieldcal's own "... did not converge either" names the input and the fix).
OPAQUE = (
    "Singular matrix",
    "SVD did not converge",
    "Eigenvalues did not converge",
    "Array must not contain infs or NaNs",
)


def library_outcome(
    call: Callable[[], object], *, nonsense: bool = False, check: Callable[[Any], str] | None = None
) -> tuple[str, str]:
    """Classify a library call: its value (checked by ``check``, which returns a problem or
    ""), a one-line ValueError, or anything else."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            value = call()
            problem = "" if check is None else check(value)
        except np.linalg.LinAlgError as exc:  # a ValueError, but numpy's words
            return "traceback", f"opaque {_exception(exc)}"
        except ValueError as exc:  # InputError too
            message = str(exc)
            noise = _noise(caught)
            if noise:
                return "noisy", f"{noise[0]} before ValueError: {message[:120]}"
            if not _one_line(message):
                return "noisy", f"ValueError of {len(message)} chars: {message[:200]!r}"
            return "error", message
        except _Timeout:
            raise
        except RecursionError as exc:
            return "traceback", f"RecursionError{_where(exc)}"
        except Exception as exc:
            return "traceback", _exception(exc)
        noise = _noise(caught)
    if noise:
        return "noisy", noise[0]
    if problem:
        return ("nonsense" if problem.startswith("nonsense") else "traceback"), problem
    if nonsense:
        level = getattr(getattr(value, "verdict", None), "level", None)
        if level != "fail":
            return "nonsense", f"accepted with verdict {level!r}"
    return "ok", ""


def cli_outcome(
    args: Sequence[object], *, nonsense: bool = False, output: Path | None = None
) -> tuple[str, str]:
    """Run ``fieldcal ARGS`` in this process and classify what it printed and returned.

    A JSON ``output`` it wrote must read back; for a ``nonsense`` case its verdict must be
    ``fail`` (exit code 3) unless the command refused the input.
    """
    from click.testing import CliRunner

    from fieldcal.cli import cli

    runner = CliRunner()
    with warnings.catch_warnings():
        warnings.simplefilter("always")  # every warning shows on stderr, not only the first
        result = runner.invoke(cli, [str(a) for a in args], catch_exceptions=True)
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        return "traceback", _exception(result.exception)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    code = result.exit_code
    if code == 2:
        if any(word in line for word in OPAQUE for line in lines):
            return "traceback", f"numpy's message: {lines[-1][:200]}"
        if len(lines) == 1 and lines[0].startswith("Error: ") and _one_line(lines[0]):
            return "error", lines[0]
        if (
            len(lines) == 3
            and lines[0].startswith("Usage: ")
            and lines[1].startswith("Try ")
            and lines[2].startswith("Error: ")
        ):
            return "usage", lines[2]
        return "noisy", " | ".join(lines)[:300]
    if code not in (0, 3):
        return "traceback", f"exit code {code}: {' | '.join(lines)[:200]}"
    noisy = [line for line in lines if "Warning" in line or "Traceback" in line]
    if noisy:
        return "noisy", noisy[0][:200]
    if output is not None and output.exists():
        try:
            cal = Calibration.from_json(output.read_text(encoding="utf-8"))
        except ValueError as exc:
            return "traceback", f"the JSON written does not read back: {exc}"
        if nonsense and (cal.verdict is None or cal.verdict.level != "fail"):
            level = None if cal.verdict is None else cal.verdict.level
            return "nonsense", f"accepted with verdict {level!r} (exit code {code})"
    elif nonsense and code != 3:
        return "nonsense", f"accepted (exit code {code})"
    return "ok", f"exit code {code}"


# ============================================================================ base data
@dataclass
class Base:
    """Valid inputs every mutation starts from (written once into the work folder)."""

    folder: Path
    texts: dict[str, str] = field(default_factory=dict)  # name -> CSV text
    arrays: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)  # name -> columns
    sessions: list[fieldcal.Session] = field(default_factory=list)
    documents: dict[str, dict[str, Any]] = field(default_factory=dict)  # calibration JSON
    calibrations: dict[str, Calibration] = field(default_factory=dict)


def _csv(columns: dict[str, np.ndarray], fmt: str = "%.9g") -> str:
    names = list(columns)
    buf = io.StringIO()
    data = np.column_stack([columns[k] for k in names])
    np.savetxt(buf, data, delimiter=",", header=",".join(names), comments="", fmt=fmt)
    return buf.getvalue()


def make_base(folder: Path, seed: int = 0, *, slow: bool = True) -> Base:
    """Small valid logs (continuous and pose-labelled), sessions and calibration files
    (``slow``: also the greedy method's, which takes a second)."""
    from fieldcal.simulation.continuous import simulate_continuous

    base = Base(folder)
    cont = simulate_continuous("paper", seed=seed, rate=50.0, n_poses=12, samples=(100, 150))
    base.arrays["continuous"] = {k: np.asarray(v) for k, v in cont.columns.items()}
    base.texts["continuous"] = _csv(base.arrays["continuous"])
    s = fieldcal.simulate("paper", seed=seed + 1, n_poses=12, samples=(25, 40))
    pose = np.repeat(np.arange(s.n_poses if hasattr(s, "n_poses") else len(s.accel)), s.counts)
    acc, mag = np.concatenate(s.accel), np.concatenate(s.mag)
    cols = {"pose": pose.astype(float)}
    cols.update({f"a{a}": acc[:, i] for i, a in enumerate("xyz")})
    cols.update({f"m{a}": mag[:, i] for i, a in enumerate("xyz")})
    base.arrays["poses"] = cols
    base.texts["poses"] = _csv(cols)
    for k in range(3):
        base.sessions.append(
            fieldcal.simulate("paper", seed=seed + 10 + k, n_poses=10 + 2 * k, samples=(20, 40))
        )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s0 = base.sessions[0]
        cals = {
            "mle": fieldcal.calibrate(s0.accel, s0.mag),
            "accel only": fieldcal.calibrate(s0.accel, None),
            "mag only": fieldcal.calibrate(None, s0.mag),
            "ellipsoid": fieldcal.calibrate(s0.accel, s0.mag, method="ellipsoid"),
        }
        if slow:
            cals["greedy"] = fieldcal.calibrate(s0.accel, s0.mag, method="greedy")
    base.calibrations = cals
    base.documents = {k: json.loads(c.to_json()) for k, c in cals.items()}
    data = Path(__file__).resolve().parents[1] / "tests" / "data"
    for path in sorted(data.glob("calibration-*.json")):
        base.documents[path.stem] = json.loads(path.read_text())
    # the files the calibration-file cases apply and report on, and the log cases' calibration
    (folder / "small.csv").write_text(base.texts["poses"])
    (folder / "cases").mkdir(exist_ok=True)
    (folder / "cases" / "valid.json").write_text(cals["mle"].to_json())
    return base


# ============================================================================ log files
#: Values written into sensor cells.
ODD_CELLS = (
    "nan",
    "NaN",
    "inf",
    "-inf",
    "Infinity",
    "1e300",
    "-1e300",
    "1e-320",
    "1e308",
    "1e400",
    "",
    " ",
    "abc",
    "1,5",
    "0x1A",
    "\uff11",
    "1e",
    "--1",
    "+1",
    "1_000",
    "True",
    "\u221e",
    "1e151",
    "-0",
    "9" * 400,
    "\x00",
)
PREAMBLES = ("Logger v2.1", "Date: 2024-01-01 12:00", "sep=,", "device;imu-7", "\ufeffx", "ax ay")


def _rows(text: str) -> tuple[list[str], list[list[str]]]:
    lines = text.splitlines()
    return lines[0].split(","), [line.split(",") for line in lines[1:]]


def _join(header: list[str], rows: list[list[str]], delim: str = ",") -> str:
    return "\n".join([delim.join(header), *(delim.join(r) for r in rows)]) + "\n"


def _sensor_columns(header: list[str]) -> list[int]:
    return [j for j, h in enumerate(header) if h[:1] in "agm" and h[1:] in ("x", "y", "z")]


def _scaled(columns: dict[str, np.ndarray], factor: float) -> dict[str, np.ndarray]:
    out = dict(columns)
    with np.errstate(all="ignore"):
        for k, v in columns.items():
            if k[:1] in "agm" and k[1:] in ("x", "y", "z"):
                out[k] = v * factor
    return out


def _text_mutations(
    base: Base, rng: np.random.Generator
) -> tuple[str, bytes, list[str], bool, str]:
    """One mutated CSV: (description, content, extra CLI args, nonsense, suffix)."""
    which = str(rng.choice(["continuous", "poses"]))
    text = base.texts[which]
    header, rows = _rows(text)
    kind = str(
        rng.choice(
            [
                "truncate",
                "garbage",
                "huge field",
                "odd cells",
                "scale",
                "duplicate header",
                "no header",
                "header only",
                "empty header name",
                "preamble",
                "ragged",
                "delimiter",
                "blank lines",
                "crlf",
                "bom",
                "empty",
                "comments only",
                "one row",
                "constant",
                "wide",
                "time",
                "pose labels",
                "same columns",
                "copied columns",
                "shuffled labels",
                "shuffled mag",
                "quotes",
                "latin-1",
                "long line count",
            ]
        )
    )
    args: list[str] = []
    nonsense = False
    desc = f"{which}: {kind}"
    data = text.encode()
    if kind == "truncate":
        cut = int(rng.integers(0, len(data)))
        data = data[:cut]
        desc += f" at byte {cut}"
    elif kind == "garbage":
        n = int(rng.integers(1, 60))
        flavour = str(rng.choice(["nul", "high", "ascii", "quotes", "mixed"]))
        pool = {
            "nul": b"\x00",
            "high": bytes(range(128, 256)),
            "ascii": bytes(range(32, 127)),
            "quotes": b'"\'"',
            "mixed": bytes(range(256)),
        }[flavour]
        buf = bytearray(data)
        for _ in range(n):
            pos = int(rng.integers(0, len(buf) + 1))
            buf[pos:pos] = bytes([pool[int(rng.integers(0, len(pool)))]])
        data = bytes(buf)
        desc += f" ({n} {flavour} bytes)"
    elif kind == "huge field":
        size = int(rng.choice([131_073, 200_000, 1_000_000]))
        filler = str(rng.choice(["x", "1", " ", '"']))
        i = int(rng.integers(0, len(rows)))
        j = int(rng.integers(0, len(header)))
        rows[i][j] = filler * size
        data = _join(header, rows).encode()
        desc += f" of {size} {filler!r} at row {i + 1} col {j + 1}"
    elif kind == "odd cells":
        k = int(rng.integers(1, 8))
        cols = [*_sensor_columns(header), 0]
        for _ in range(k):
            i = int(rng.integers(0, len(rows)))
            j = int(rng.choice(cols))
            rows[i][j] = str(rng.choice(ODD_CELLS))
        data = _join(header, rows).encode()
        desc += f" ({k} cells)"
        args = ["--drop-nan"] if rng.random() < 0.3 else []
    elif kind == "scale":
        f = float(rng.choice([1e-30, 1e30, 1e300, 1e-300, 1e150, 1e-150, 2.0**-1000, 1e200]))
        data = _csv(_scaled(base.arrays[which], f), "%.9g").encode()
        desc += f" x{f:g}"
    elif kind == "duplicate header":
        i, j = rng.choice(len(header), 2, replace=False)
        header[int(j)] = header[int(i)]
        data = _join(header, rows).encode()
        desc += f" (col {j + 1} named {header[int(i)]!r})"
    elif kind == "no header":
        data = _join(rows[0], rows[1:]).encode()
    elif kind == "header only":
        data = (",".join(header) + "\n").encode()
    elif kind == "empty header name":
        j = int(rng.integers(0, len(header)))
        header[j] = str(rng.choice(["", " ", '""']))
        data = _join(header, rows).encode()
        desc += f" (col {j + 1})"
    elif kind == "preamble":
        k = int(rng.integers(1, 4))
        lines = [str(rng.choice(PREAMBLES)) for _ in range(k)]
        data = ("\n".join(lines) + "\n" + text).encode()
        desc += f" {lines!r}"
    elif kind == "ragged":
        i = int(rng.integers(0, len(rows)))
        if rng.random() < 0.5:
            rows[i] = rows[i][:-1]
        else:
            rows[i] = [*rows[i], "1"]
        data = _join(header, rows).encode()
        desc += f" row {i + 1}"
    elif kind == "delimiter":
        delim = str(rng.choice([";", "\t", " ", "|", ", "]))
        data = _join(header, rows, delim).encode()
        desc += f" {delim!r}"
    elif kind == "blank lines":
        lines = text.splitlines()
        for _ in range(int(rng.integers(1, 20))):
            lines.insert(int(rng.integers(0, len(lines) + 1)), str(rng.choice(["", "  ", "#"])))
        data = ("\n".join(lines) + "\n").encode()
    elif kind == "crlf":
        data = text.replace("\n", "\r\n").encode()
    elif kind == "bom":
        data = b"\xef\xbb\xbf" + text.encode()
    elif kind == "empty":
        data = str(rng.choice(["", "\n", "   \n\n", "\x00"])).encode()
    elif kind == "comments only":
        data = b"# a log\n# nothing else\n"
    elif kind == "one row":
        k = int(rng.integers(1, 4))
        data = _join(header, rows[:k]).encode()
        desc += f" ({k} rows)"
    elif kind == "constant":
        rows = [rows[0]] * len(rows)
        data = _join(header, rows).encode()
    elif kind == "wide":
        extra = int(rng.choice([100, 2000, 20000]))
        names = [*header, *(f"c{k}" for k in range(extra))]
        body = [[*r, *(["0"] * extra)] for r in rows[:50]]
        data = _join(names, body).encode()
        desc += f" (+{extra} columns, 50 rows)"
    elif kind == "time":
        cols = dict(base.arrays["continuous"])
        how = str(rng.choice(["reversed", "constant", "ns", "1e300", "shuffled", "negative"]))
        t = cols["t"]
        cols["t"] = {
            "reversed": t[::-1],
            "constant": np.zeros_like(t),
            "ns": t * 1e9,
            "1e300": t * 1e300,
            "shuffled": rng.permutation(t),
            "negative": -t,
        }[how]
        data = _csv(cols, "%.17g").encode()
        desc = f"continuous: time {how}"
    elif kind == "pose labels":
        cols = dict(base.arrays["poses"])
        how = str(rng.choice(["per row", "nan", "text", "one label", "empty"]))
        n = len(cols["pose"])
        if how == "per row":
            cols["pose"] = np.arange(n, dtype=float)
        elif how == "nan":
            cols["pose"] = np.full(n, np.nan)
        elif how == "one label":
            cols["pose"] = np.zeros(n)
        text_cols = _csv(cols)
        if how in ("text", "empty"):
            h, r = _rows(text_cols)
            for row in r:
                row[0] = f"pose {row[0]}!" if how == "text" else ""
            text_cols = _join(h, r)
        data = text_cols.encode()
        desc = f"poses: pose labels {how}"
    elif kind == "same columns":
        nonsense = True
        args = str(rng.choice(["--accel-cols mx,my,mz", "--mag-cols ax,ay,az"])).split()
        desc += f" ({' '.join(args)})"
    elif kind == "copied columns":
        nonsense = True
        cols = dict(base.arrays[which])
        src, dst = ("a", "m") if rng.random() < 0.5 else ("m", "a")
        for axis in "xyz":
            cols[f"{dst}{axis}"] = cols[f"{src}{axis}"]
        data = _csv(cols).encode()
        desc += f" ({dst}x..z = {src}x..z)"
    elif kind == "shuffled labels":
        nonsense = True
        cols = dict(base.arrays["poses"])
        cols["pose"] = rng.permutation(cols["pose"])
        data = _csv(cols).encode()
        desc = "poses: pose labels shuffled across the rows"
    elif kind == "shuffled mag":
        nonsense = True
        cols = dict(base.arrays["poses"])
        order = rng.permutation(len(cols["pose"]))
        for axis in "xyz":
            cols[f"m{axis}"] = cols[f"m{axis}"][order]
        data = _csv(cols).encode()
        desc = "poses: magnetometer rows shuffled against the accelerometer's"
    elif kind == "quotes":
        rows = [[f'"{c}"' for c in r] for r in rows]
        if rng.random() < 0.5:
            rows[int(rng.integers(0, len(rows)))][0] = '"unterminated'
        data = _join([f'"{h}"' for h in header], rows).encode()
    elif kind == "latin-1":
        data = text.replace("ax", "\xe4x").encode("latin-1")
    elif kind == "long line count":
        data = (text + "\n".join(",".join(r) for r in rows * 20) + "\n").encode()
        desc += " (rows x21)"
    return desc, data, args, nonsense, ".csv"


def _npz_bytes(arrays: dict[str, np.ndarray], pickle: bool = False) -> bytes:
    buf = io.BytesIO()
    if pickle:
        np.savez(buf, **{k: np.asarray(v, dtype=object) for k, v in arrays.items()})
    else:
        np.savez(buf, **arrays)
    return buf.getvalue()


def _npz_mutations(base: Base, rng: np.random.Generator) -> tuple[str, bytes, list[str], bool, str]:
    cols = base.arrays["continuous"]
    acc = np.column_stack([cols["ax"], cols["ay"], cols["az"]])
    mag = np.column_stack([cols["mx"], cols["my"], cols["mz"]])
    gyro = np.column_stack([cols["gx"], cols["gy"], cols["gz"]])
    arrays: dict[str, np.ndarray] = {"t": cols["t"], "accel": acc, "mag": mag, "gyro": gyro}
    kind = str(
        rng.choice(
            [
                "valid",
                "dtype",
                "shape",
                "lengths",
                "values",
                "truncate",
                "flip bytes",
                "empty file",
                "text",
                "npy",
                "foreign member",
                "pickled",
                "no arrays",
                "zero rows",
                "scale",
            ]
        )
    )
    desc = f"npz: {kind}"
    pickle = False
    if kind == "dtype":
        dtype = str(
            rng.choice(
                [
                    "float16",
                    "float32",
                    "int8",
                    "int64",
                    "uint16",
                    "bool",
                    "complex64",
                    "complex128",
                    "U12",
                    "S12",
                    "datetime64[s]",
                    "timedelta64[ms]",
                    "longdouble",
                ]
            )
        )
        key = str(rng.choice(["accel", "mag", "t"]))
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if dtype.startswith("complex") and rng.random() < 0.5:
                arrays[key] = arrays[key] + 1j * 1e-3
            arrays[key] = arrays[key].astype(dtype)
        desc += f" {key} as {dtype}"
    elif kind == "shape":
        key = str(rng.choice(["accel", "mag"]))
        how = str(rng.choice(["transposed", "four columns", "3-d", "scalar", "flat"]))
        x = arrays[key]
        arrays[key] = {
            "transposed": x.T,
            "four columns": np.column_stack([x, x[:, :1]]),
            "3-d": x[:, :, None],
            "scalar": np.array(1.0),
            "flat": x.ravel(),
        }[how]
        desc += f" {key} {how}"
    elif kind == "lengths":
        key = str(rng.choice(["accel", "mag", "t"]))
        arrays[key] = arrays[key][: -int(rng.integers(1, 50))]
        desc += f" {key} shorter"
    elif kind == "values":
        key = str(rng.choice(["accel", "mag", "t"]))
        value = float(rng.choice([NAN, INF, -INF, 1e300, 1e-320]))
        x = arrays[key].copy()
        x.flat[int(rng.integers(0, x.size))] = value
        arrays[key] = x
        desc += f" {key} gets {value!r}"
    elif kind == "pickled":
        pickle = True
    elif kind == "no arrays":
        arrays = {"x": np.ones((2, 2, 2))}
    elif kind == "zero rows":
        arrays = {k: v[:0] for k, v in arrays.items()}
    elif kind == "scale":
        f = float(rng.choice([1e-30, 1e30, 1e300, 1e-300]))
        arrays = {k: (v * f if k != "t" else v) for k, v in arrays.items()}
        desc += f" x{f:g}"
    data = _npz_bytes(arrays, pickle)
    if kind == "truncate":
        cut = int(rng.integers(0, len(data)))
        data = data[:cut]
        desc += f" at byte {cut}"
    elif kind == "flip bytes":
        buf = bytearray(data)
        k = int(rng.integers(1, 20))
        for _ in range(k):
            buf[int(rng.integers(0, len(buf)))] = int(rng.integers(0, 256))
        data = bytes(buf)
        desc += f" ({k} bytes)"
    elif kind == "empty file":
        data = b""
    elif kind == "text":
        data = base.texts["poses"].encode()
    elif kind == "npy":
        buf = io.BytesIO()
        np.save(buf, acc)
        data = buf.getvalue()
    elif kind == "foreign member":
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as z:
            z.writestr("accel.npy", b"not an array")
            z.writestr("readme.txt", "hello")
        data = buf.getvalue()
    return desc, data, [], False, ".npz"


def _parquet_mutations(
    base: Base, rng: np.random.Generator
) -> tuple[str, bytes, list[str], bool, str]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = dict(base.arrays["continuous"])
    kind = str(rng.choice(["valid", "strings", "nulls", "list column", "truncate", "flip"]))
    table_cols: dict[str, Any] = {k: pa.array(v) for k, v in cols.items()}
    if kind == "strings":
        table_cols["ax"] = pa.array([f"{v:.6g}" for v in cols["ax"]])
    elif kind == "nulls":
        values = list(cols["mx"])
        values[int(rng.integers(0, len(values)))] = None
        table_cols["mx"] = pa.array(values)
    elif kind == "list column":
        table_cols["ax"] = pa.array([[v, v] for v in cols["ax"]])
    buf = io.BytesIO()
    pq.write_table(pa.table(table_cols), buf)
    data = buf.getvalue()
    if kind == "truncate":
        data = data[: int(rng.integers(0, len(data)))]
    elif kind == "flip":
        b = bytearray(data)
        for _ in range(int(rng.integers(1, 10))):
            b[int(rng.integers(0, len(b)))] = int(rng.integers(0, 256))
        data = bytes(b)
    return f"parquet: {kind}", data, [], False, ".parquet"


SPECIAL = ("fifo", "fifo.npz", "directory", "/dev/null", "/dev/zero", "missing", "broken link")


def _special_case(kind: str) -> Callable[[Path], tuple[str, str]]:
    def run(folder: Path) -> tuple[str, str]:
        out = folder / "cal.json"
        if kind.startswith("fifo"):
            path = folder / ("log.npz" if kind.endswith("npz") else "log.csv")
            os.mkfifo(path)
        elif kind == "directory":
            path = folder / "log.csv"
            path.mkdir()
        elif kind.startswith("/dev/"):
            path = Path(kind)
            if not path.exists():
                return "ok", "no such device here"
        elif kind == "missing":
            path = folder / "nothing.csv"
        else:
            path = folder / "link.csv"
            path.symlink_to(folder / "gone.csv")
        return cli_outcome(["calibrate", path, "-o", out, "-q"], output=out)

    return run


def log_cases(base: Base, n: int, seed: int) -> list[Case]:
    """``n`` mutated logs (CSV, NPZ, Parquet) and the special files, through calibrate."""
    cases = [Case("log files", f"special file: {k}", _special_case(k), 5.0) for k in SPECIAL]
    try:
        import pyarrow  # noqa: F401

        parquet = True
    except ImportError:
        parquet = False
    for k in range(max(0, n - len(cases))):
        rng = np.random.default_rng([seed, 1, k])
        r = rng.random()
        if r < 0.2:
            made = _npz_mutations(base, rng)
        elif r < 0.25 and parquet:
            made = _parquet_mutations(base, rng)
        else:
            made = _text_mutations(base, rng)
        via = str(rng.choice(["calibrate", "apply", "report"], p=[0.8, 0.15, 0.05]))
        if via != "calibrate" and (made[3] or made[2]):
            via = "calibrate"  # options and nonsense are the calibration's
        cases.append(_file_case("log files", f"#{k} {made[0]}", *made[1:], via=via))
    return cases


def _file_case(
    category: str,
    name: str,
    data: bytes,
    args: list[str],
    nonsense: bool,
    suffix: str,
    via: str = "calibrate",
) -> Case:
    """A log through ``fieldcal calibrate`` (or ``apply`` / ``report`` with a valid
    calibration file, where nonsense does not apply)."""

    def run(folder: Path) -> tuple[str, str]:
        path = folder / f"log{suffix}"
        path.write_bytes(data)
        cal = folder.parent / "valid.json"
        if via == "apply":
            return cli_outcome(["apply", cal, path, "-o", folder / f"out{suffix}", "-q"])
        if via == "report":
            return cli_outcome(["report", cal, path, "-o", folder / "report.html"])
        out = folder / "cal.json"
        return cli_outcome(
            ["calibrate", path, "-o", out, "-q", *args], nonsense=nonsense, output=out
        )

    return Case(category, f"{name} via {via}", run, 60.0 if via == "report" else 20.0)


# ============================================================================ options
#: Option values a user may well mean (the case then reaches the calibration).
GOOD_OPTIONS: dict[str, list[str]] = {
    "--window": ["0.3", "0.5", "1"],
    "--min-still": ["0.5", "1", "1.5"],
    "--still-trim": ["0", "0.1", "0.2"],
    "--still-threshold": ["0.05", "0.2", "0.5"],
    "--rate": ["50", "100", "25"],
    "--gravity": ["9.80665", "1", "0.5"],
    "--field-strength": ["48.5", "1", "1e-5"],
    "--noise": ["0.01", "accel=0.01,mag=0.02", "mag=0.05"],
    "--pose-noise": ["auto", "none", "0.01", "accel=none,mag=auto"],
    "--method": ["mle", "ellipsoid", "greedy"],
    "--mag-axes": ["+y+x-z", "+x+y+z", "-x-y-z"],
    "--accel-cols": ["ax,ay,az"],
    "--mag-cols": ["mx,my,mz"],
    "--gyro-cols": ["gx,gy,gz"],
    "--time-col": ["t"],
    "--pose-col": ["pose"],
}


def _option_values(rng: np.random.Generator) -> dict[str, list[str]]:
    """Odd values per option (the good ones are in :data:`GOOD_OPTIONS`)."""
    numbers = ["inf", "-inf", "nan", "0", "-1", "1e300", "1e-300", "1e-12", "abc", "", "1e999",
               "99999999999999999999", "2", "25", "-0", "1e5"]  # fmt: skip
    return {
        "--window": numbers,
        "--min-still": numbers,
        "--still-trim": numbers,
        "--still-threshold": numbers,
        "--rate": numbers,
        "--gravity": numbers,
        "--field-strength": numbers,
        "--noise": [
            "-1",
            "nan",
            "inf",
            "accel=",
            "=",
            ",",
            "1e300",
            "0",
            "accel=nan,mag=1",
            "x",
            "gyro=1",
            "accel=0.01,accel=0.02",
        ],
        "--pose-noise": ["-1", "nan", "inf", "mag=x", "gyro=1", "", "1e300", "AUTO", "0"],
        "--method": ["nope", "", "MLE"],
        "--mag-axes": ["xyz", "+x+x+z", "+x+y", "garbage", "", "+X+Y+Z", "+x +y +z"],
        "--accel-cols": [
            "mx,my,mz",
            "a,b",
            "ax,ay,nope",
            ",,",
            "ax ay az",
            "t,t,t",
            "ax,ax,ax",
            "pose,ax,ay",
            "gx,gy,gz",
        ],
        "--mag-cols": ["ax,ay,az", "mx,my", "mz,my,mx", "gx,gy,gz"],
        "--gyro-cols": ["ax,ay,az", "nope,no,n", "mx,my,mz"],
        "--time-col": ["ax", "nope", "pose", "mx"],
        "--pose-col": ["ax", "t", "nope", "mx"],
    }


FLAGS = ("--drop-nan", "--no-robust", "--mag-mirrored", "--json", "--quiet")


def option_cases(base: Base, n: int, seed: int, *, slow: bool = True) -> list[Case]:
    cases = []
    for k in range(n):
        rng = np.random.default_rng([seed, 2, k])
        values = _option_values(rng)
        which = str(rng.choice(["continuous", "poses"]))
        args: list[str] = []
        names = list(values)
        for opt in rng.choice(names, int(rng.integers(1, 4)), replace=False):
            pool = GOOD_OPTIONS[str(opt)] if rng.random() < 0.6 else values[str(opt)]
            args += [str(opt), str(rng.choice(pool))]
        if rng.random() < 0.3:
            args.append(str(rng.choice(FLAGS)))
        if "--method" in args and args[args.index("--method") + 1] == "greedy":
            which = "poses"  # keeps greedy's minutes out of the timeout
            if not slow:
                args[args.index("--method") + 1] = "mle"
        nonsense = _same_columns(args)
        cases.append(_option_case(f"#{k} {which}: {' '.join(args)}", which, args, nonsense))
    return cases


def _same_columns(args: list[str]) -> bool:
    """Whether the options make the two sensors read the same columns (nonsense)."""
    accel = args[args.index("--accel-cols") + 1] if "--accel-cols" in args else "ax,ay,az"
    mag = args[args.index("--mag-cols") + 1] if "--mag-cols" in args else "mx,my,mz"
    return accel.replace(" ", "") == mag.replace(" ", "")


def _option_case(name: str, which: str, args: list[str], nonsense: bool) -> Case:
    def run(folder: Path) -> tuple[str, str]:
        path = folder / "log.csv"
        if not path.exists():
            path.write_text(BASE_TEXTS[which])
        out = folder / "cal.json"
        return cli_outcome(["calibrate", path, "-o", out, *args], nonsense=nonsense, output=out)

    return Case("options", name, run)


BASE_TEXTS: dict[str, str] = {}


# ============================================================================ calibration files
ODD_VALUES: tuple[object, ...] = (
    None,
    True,
    False,
    "false",
    "true",
    "nan",
    "inf",
    "-inf",
    "abc",
    "",
    0,
    -1,
    1.5,
    1e308,
    -1e308,
    1e-308,
    [],
    {},
    [1, 2],
    [[1, 2, 3], [4, 5, 6]],
    [[0.0] * 3] * 3,
    "1",
    [None] * 3,
    {"a": 1},
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, "x"]],
)


def _paths(node: object, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every path (keys and indices) into a JSON tree."""
    out = [prefix]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _paths(v, (*prefix, i))
    return out


def _get(node: Any, path: tuple[Any, ...]) -> Any:
    for p in path:
        node = node[p]
    return node


def _set(doc: Any, path: tuple[Any, ...], value: object) -> Any:
    if not path:
        return value
    _get(doc, path[:-1])[path[-1]] = value
    return doc


def _cal_mutation(base: Base, rng: np.random.Generator) -> tuple[str, str, bool]:
    """(description, JSON text, must be refused)."""
    name = str(rng.choice(list(base.documents)))
    doc = json.loads(json.dumps(base.documents[name]))
    kind = str(
        rng.choice(
            [
                "replace",
                "replace",
                "replace",
                "delete",
                "non-finite",
                "shape",
                "singular",
                "converged",
                "deep",
                "schema",
                "top level",
                "truncate",
                "bytes",
                "wrap",
                "big",
                "valid",
                "number text",
                "negative noise",
            ]
        )
    )
    refuse = False
    desc = f"{name}: {kind}"
    text: str | None = None
    sensors = [s for s in ("accel", "mag") if isinstance(doc.get(s), dict)]
    sensor = str(rng.choice(sensors)) if sensors else "accel"
    if kind == "replace":
        paths = _paths(doc)[1:]
        path = paths[int(rng.integers(0, len(paths)))]
        value = ODD_VALUES[int(rng.integers(0, len(ODD_VALUES)))]
        doc = _set(doc, path, value)
        desc += f" {'.'.join(map(str, path))} = {value!r}"[:160]
        top = path[0]
        if top in ("accel", "mag") and len(path) >= 2 and path[1] in ("gain", "bias"):
            refuse = True  # a gain or bias must be finite numbers of the right shape
        if path == ("converged",) and not isinstance(value, bool):
            refuse = True
    elif kind == "delete":
        paths = [p for p in _paths(doc)[1:] if isinstance(_get(doc, p[:-1]), dict)]
        path = paths[int(rng.integers(0, len(paths)))]
        del _get(doc, path[:-1])[path[-1]]
        desc += f" {'.'.join(map(str, path))}"
        if path in ((sensor, "gain"), (sensor, "bias")) or path == ("schema",):
            refuse = True
    elif kind == "non-finite":
        part = str(rng.choice(["gain", "bias", "noise_cov"]))
        value = str(rng.choice(["nan", "inf", "-inf"]))
        if part == "bias":
            doc[sensor][part][int(rng.integers(0, 3))] = value
        else:
            doc[sensor][part][int(rng.integers(0, 3))][int(rng.integers(0, 3))] = value
        desc += f" {sensor}.{part} gets {value!r}"
        refuse = True
    elif kind == "shape":
        part = str(rng.choice(["gain", "bias", "noise_cov"]))
        how = str(rng.choice(["drop row", "extra", "flat", "wrap", "empty"]))
        x = doc[sensor][part]
        doc[sensor][part] = {
            "drop row": x[:-1],
            "extra": [*x, x[0]],
            "flat": list(np.ravel(np.array(x, dtype=object))),
            "wrap": [x],
            "empty": [],
        }[how]
        desc += f" {sensor}.{part} {how}"
        refuse = True
    elif kind == "singular":
        how = str(rng.choice(["zero", "zero row", "rank one", "tiny"]))
        g = np.array(doc[sensor]["gain"], dtype=float)
        g = {
            "zero": np.zeros((3, 3)),
            "zero row": np.vstack([g[:2], np.zeros(3)]),
            "rank one": np.outer(g[0], [1.0, 2.0, 3.0]),
            "tiny": g * np.array([1.0, 1.0, 1e-300])[:, None],
        }[how]
        doc[sensor]["gain"] = g.tolist()
        desc += f" {sensor}.gain {how}"
        refuse = True
    elif kind == "converged":
        value = [0, 1, "false", "true", "no", None][int(rng.integers(0, 6))]
        doc["converged"] = value
        desc += f" = {value!r}"
        refuse = True
    elif kind == "deep":
        depth = int(rng.choice([10, 100, 5000, 100_000]))
        where = str(rng.choice(["options", "accel.gain", "poses", "units"]))
        marker = '"__DEEP__"'
        if where == "accel.gain" and isinstance(doc.get("accel"), dict):
            doc["accel"]["gain"] = "__DEEP__"
            refuse = True
        elif where in doc:
            doc[where] = "__DEEP__"
        text = json.dumps(doc).replace(marker, "[" * depth + "1" + "]" * depth)
        desc += f" {where} nested {depth} deep"
    elif kind == "schema":
        field_, value = [
            ("schema", "fieldcal.calibration.v3"),
            ("schema", None),
            ("schema_version", "2"),
            ("schema_version", SCHEMA_VERSION + 1),  # newer than this fieldcal
            ("schema_version", 2.0),
            ("schema_version", True),
            ("schema_version", 0),
            ("schema_version", -1),
            ("schema_version", 10**30),
        ][int(rng.integers(0, 9))]
        doc[field_] = value
        desc += f" {field_} = {value!r}"
        refuse = True
    elif kind == "top level":
        text = str(rng.choice(["[]", "1", '"cal"', "null", "true", "{}", "", "[{}]"]))
        desc += f" {text!r}"
        refuse = True
    elif kind == "truncate":
        full = json.dumps(doc, indent=2)
        cut = int(rng.integers(0, len(full)))
        text = full[:cut]
        desc += f" at char {cut}"
        refuse = True
    elif kind == "bytes":
        full = bytearray(json.dumps(doc).encode())
        for _ in range(int(rng.integers(1, 5))):
            full[int(rng.integers(0, len(full)))] = int(rng.integers(0, 256))
        text = full.decode("utf-8", errors="replace")
    elif kind == "wrap":
        key = str(rng.choice(["accel", "mag", "verdict", "diagnostics", "covariance"]))
        if key in doc:
            doc[key] = [doc[key]]
            desc += f" {key} in a list"
            refuse = key in ("accel", "mag")
    elif kind == "big":
        num = str(rng.choice(["1e400", "-1e400", "1" + "0" * 400, "NaN", "Infinity", "1e308"]))
        part = str(rng.choice(["gain", "bias"]))
        if part == "gain":
            doc[sensor][part][0][0] = "__BIG__"
        else:
            doc[sensor][part][0] = "__BIG__"
        text = json.dumps(doc).replace('"__BIG__"', num)
        desc += f" {sensor}.{part} first entry = {num[:12]}"
        refuse = num != "1e308"
    elif kind == "number text":
        doc[sensor]["bias"] = [str(v) for v in doc[sensor]["bias"]]
        desc += f" {sensor}.bias as strings"
        refuse = True
    elif kind == "negative noise":
        doc[sensor]["noise_cov"] = (-np.eye(3)).tolist()
        desc += f" {sensor}.noise_cov negative definite"
    if text is None:
        text = json.dumps(doc, indent=1, allow_nan=True)
    return desc, text, refuse


def _downstream(cal: Calibration) -> str:
    """What reads a calibration must work on any calibration from_json accepts."""
    from fieldcal.output import exports

    raw = np.array([[0.1, -0.2, 0.98], [1.0, 0.5, -0.3]])
    for name in ("accel", "mag"):
        sensor = getattr(cal, name)
        if sensor is None:
            continue
        for m in (sensor.gain, sensor.bias):
            if not np.all(np.isfinite(m)):
                return f"nonsense: {name} has a non-finite gain or bias"
        fixed = cal.correct_accel(raw) if name == "accel" else cal.correct_mag(raw)
        if not np.all(np.isfinite(fixed)):
            return f"nonsense: correct_{name} gave non-finite values"
    for fmt in exports.FORMATS:
        with contextlib.suppress(ValueError):  # a format may refuse what it cannot state
            exports.export(cal, fmt)
    again = Calibration.from_json(cal.to_json())
    if again != cal:
        return "the JSON round trip changed the calibration"
    repr(cal)
    return ""


def calibration_cases(base: Base, n: int, seed: int) -> list[Case]:
    cases = []
    for k in range(n):
        rng = np.random.default_rng([seed, 3, k])
        desc, text, refuse = _cal_mutation(base, rng)
        via = str(
            rng.choice(
                ["library", "library", "export", "apply", "report"], p=[0.45, 0.2, 0.2, 0.1, 0.05]
            )
        )
        cases.append(_cal_case(f"#{k} {desc} via {via}", text, refuse, via))
    return cases


def _cal_case(name: str, text: str, refuse: bool, via: str) -> Case:
    def run(folder: Path) -> tuple[str, str]:
        if via == "library":
            return (
                library_outcome(
                    lambda: Calibration.from_json(text), check=_downstream, nonsense=False
                )
                if not refuse
                else _refused(lambda: Calibration.from_json(text))
            )
        path = folder / "cal.json"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        if via == "export":
            fmt = ["c-header", "matlab", "magneto", "json"][len(text) % 4]
            outcome = cli_outcome(["export", path, "--format", fmt])
        elif via == "apply":
            outcome = cli_outcome(
                ["apply", path, folder.parent / "small.csv", "-o", folder / "out.csv", "-q"]
            )
        else:
            outcome = cli_outcome(
                ["report", path, folder.parent / "small.csv", "-o", folder / "r.html"]
            )
        if refuse and outcome[0] == "ok":
            return "nonsense", "a malformed calibration file was used"
        return outcome

    return Case("calibration files", name, run, 60.0 if via == "report" else 20.0)


def _refused(call: Callable[[], object]) -> tuple[str, str]:
    outcome, detail = library_outcome(call, check=_downstream)
    if outcome == "ok":
        return "nonsense", "a malformed calibration file was read"
    return outcome, detail


# ============================================================================ library calls
def _poses_mutation(poses: list[np.ndarray], rng: np.random.Generator) -> tuple[str, Any]:
    kinds = [
        "as is",
        "strings",
        "object",
        "bool",
        "complex",
        "complex zero",
        "float16",
        "float32",
        "int",
        "uint8",
        "lists",
        "ragged pose",
        "flat pose",
        "transposed pose",
        "empty pose",
        "no poses",
        "None in list",
        "scalar",
        "text",
        "dict",
        "nan",
        "inf",
        "scale",
        "constant",
        "collinear",
        "few",
        "drop one",
        "continuous",
        "3-d",
        "single sample",
        "generator",
        "nested too deep",
        "tuple",
        "masked",
        "huge count",
        "bytes",
    ]
    kind = str(rng.choice(kinds))
    p = [np.array(x) for x in poses]
    i = int(rng.integers(0, len(p)))
    if any(x.ndim != 2 for x in p) and kind in ("ragged pose", "transposed pose", "nan", "inf"):
        kind = "flat pose"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out: Any
        if kind == "as is":
            out = p
        elif kind == "strings":
            out = [x.astype(str) for x in p]
            if rng.random() < 0.5:
                out[i] = np.full(p[i].shape, "abc")
        elif kind == "object":
            out = np.empty(len(p), dtype=object)
            for k, x in enumerate(p):
                out[k] = x
        elif kind == "bool":
            out = [x > x.mean() for x in p]
        elif kind == "complex":
            out = [x + 1j * 0.01 for x in p]
        elif kind == "complex zero":
            out = [x.astype(complex) for x in p]
        elif kind in ("float16", "float32", "uint8"):
            out = [x.astype(kind) for x in p]
        elif kind == "int":
            out = [np.round(x * 1000).astype(np.int64) for x in p]
        elif kind == "lists":
            out = [x.tolist() for x in p]
        elif kind == "ragged pose":
            p[i] = p[i][:, :2]
            out = p
        elif kind == "flat pose":
            p[i] = p[i].ravel()
            out = p
        elif kind == "transposed pose":
            p[i] = p[i].T
            out = p
        elif kind == "empty pose":
            p[i] = np.zeros((0, 3))
            out = p
        elif kind == "no poses":
            out = []
        elif kind == "None in list":
            out = [*p[:i], None, *p[i + 1 :]]
        elif kind == "scalar":
            out = float(rng.choice([5.0, NAN]))
        elif kind == "text":
            out = "accel.csv"
        elif kind == "dict":
            out = {"pose0": p[0]}
        elif kind in ("nan", "inf"):
            p[i] = p[i].copy()
            p[i][0, int(rng.integers(0, 3))] = NAN if kind == "nan" else INF
            out = p
        elif kind == "scale":
            f = float(rng.choice([1e-30, 1e30, 1e150, 1e151, 1e300, 1e-300, 1e-310, 2.0**1000]))
            out = [x * f for x in p]
            kind += f" x{f:g}"
        elif kind == "constant":
            out = [np.repeat(p[0][:1], len(x), axis=0) for x in p]
        elif kind == "collinear":
            d = p[0].mean(axis=0)
            out = [np.outer(np.full(len(x), k + 1.0), d) + 1e-3 * x for k, x in enumerate(p)]
        elif kind == "few":
            k = int(rng.integers(0, 9))
            out = p[:k]
            kind += f" ({k})"
        elif kind == "drop one":
            out = p[:-1]
        elif kind == "continuous":
            out = np.concatenate(p)
        elif kind == "3-d":
            m = min(len(x) for x in p)
            out = np.stack([x[:m] for x in p])
        elif kind == "single sample":
            out = [x[:1] for x in p]
        elif kind == "generator":
            out = (x for x in p)
        elif kind == "nested too deep":
            out = [[x] for x in p]
        elif kind == "tuple":
            out = tuple(p)
        elif kind == "masked":
            out = [np.ma.masked_array(x, mask=x > 1e9) for x in p]
        elif kind == "huge count":
            out = [np.repeat(x, 50, axis=0) for x in p]
        elif kind == "bytes":
            out = [x.tobytes() for x in p]
    return kind, out


#: Odd values of fieldcal.calibrate's own options.
CALIBRATE_OPTIONS: dict[str, list[Any]] = {
    "gravity": [
        9.80665,
        "9.8",
        -1,
        0,
        NAN,
        INF,
        True,
        1e308,
        1e-308,
        np.float32(9.8),
        np.array(9.8),
        [9.8],
        complex(9.8),
        np.float16(9.8),
        1e150,
    ],
    "field_strength": [48.5, "48", -5, NAN, INF, 1e-320, np.int8(3), [1, 2], 1e-150],
    "noise": [
        0.01,
        -1,
        0,
        NAN,
        INF,
        "0.01",
        [0.01, 0.02, 0.03],
        [0.01, 0.02],
        np.eye(3) * 1e-4,
        -np.eye(3),
        np.ones((3, 3)),
        {"accel": 0.01},
        {"gyro": 1},
        {"accel": "x"},
        1e200,
        True,
        complex(1, 1),
        np.float16(0.01),
        [[1e-4, 0, 0], [0, 1e-4, 0], [0, 0, NAN]],
        np.eye(3, dtype=complex),
        1e-200,
    ],
    "pose_noise": [
        "auto",
        "none",
        "AUTO",
        0,
        0.01,
        -1,
        NAN,
        INF,
        "0.01",
        {"accel": "none", "mag": 0.1},
        {"x": 1},
        None,
        True,
        [0.1],
        1e300,
    ],
    "robust": [True, False, "yes", 1, 0, None, np.bool_(True)],
    "false_alarm": [0.01, 0, 1, -0.1, NAN, "0.01", True, 1e-300, 0.999999, np.float16(0.1)],
    "cut_unsteady": [None, True, False, "no", 1],
    "body_frame": ["accel", "mag", "gyro", None, 1],
    "mag_mirrored": [False, True, "yes", 1, np.bool_(False), None, "false"],
    "on_progress": [None, 1, "x", (lambda line: None)],
}
#: Odd values of each method's options.
METHOD_OPTIONS: dict[str, dict[str, list[Any]]] = {
    "mle": {
        "max_iter": [0, -1, 1, 1.5, True, "200", NAN, 10**20, np.int64(5)],
        "tol": [0, -1, NAN, INF, "1e-9", 1e-300, 1.0, True, np.float32(1e-6)],
        "initial": ["cal.json", {}, 5, "accel only", "ellipsoid", "mle", "mag only"],
    },
    "greedy": {
        "gamma": [0, -1, NAN, INF, "1e-4", 1.0, True],
        "max_iterations": [0, -1, 1, 1.5, True, "10", 50],
        "rotation_tol": [0, NAN, -1, "1e-9"],
        "rotation_max_iterations": [0, 1.5, True, 3],
    },
    "ellipsoid": {
        "faithful": ["yes", 1, True, False, None],
        "inclination_deg": [91, NAN, "60", 60, -90, INF, True],
        "fit_on": ["pose_means", "x", None],
    },
}


def _option_mutation(rng: np.random.Generator, base: Base) -> tuple[str, dict[str, Any]]:
    """Options for fieldcal.calibrate: its own, then the method's (now and then one that no
    method has)."""
    opts: dict[str, Any] = {}
    pools = dict(CALIBRATE_OPTIONS)
    method = str(rng.choice(["mle", "mle", "greedy", "ellipsoid", "odd"]))
    if method == "odd":
        opts["method"] = [None, 1, "", "MLE", "nope"][int(rng.integers(0, 5))]
    else:
        opts["method"] = method
        pools.update(METHOD_OPTIONS[method])
    if rng.random() < 0.05:
        pools["wobble"] = [1]
    for key in rng.choice(list(pools), int(rng.integers(1, 4)), replace=False):
        pool = pools[str(key)]
        value = pool[int(rng.integers(0, len(pool)))]
        if key == "initial" and isinstance(value, str) and value in base.calibrations:
            value = base.calibrations[value]
        opts[str(key)] = value
    if opts.get("method") == "greedy":
        opts.setdefault("max_iterations", 50)  # keeps greedy's minutes out of the timeout
    return ", ".join(f"{k}={_short(v)}" for k, v in opts.items()), opts


def _short(value: object) -> str:
    if isinstance(value, Calibration):
        return f"<Calibration {value.method}>"
    if isinstance(value, np.ndarray):
        return f"array{value.shape}"
    return repr(value)[:40]


def _calibrate_check(cal: object) -> str:
    if not isinstance(cal, Calibration):
        return f"calibrate returned {type(cal).__name__}"
    try:
        cal.check_values()
    except ValueError as exc:
        return f"nonsense: calibrate returned an invalid calibration ({exc})"
    again = Calibration.from_json(cal.to_json())
    if again != cal:
        return "the JSON round trip changed the calibration"
    return ""


def library_cases(base: Base, n: int, seed: int, *, slow: bool = True) -> list[Case]:
    """``n`` library calls; without ``slow``, none runs the greedy method (seconds each)."""
    cases = []
    for k in range(n):
        rng = np.random.default_rng([seed, 4, k])
        session = base.sessions[int(rng.integers(0, len(base.sessions)))]
        which = str(
            rng.choice(
                [
                    "calibrate",
                    "calibrate",
                    "calibrate",
                    "calibrate",
                    "nonsense",
                    "summarize",
                    "stats_from_means",
                    "fit_ellipsoid",
                    "align",
                    "correct",
                    "field magnitudes",
                    "detect_still",
                    "poses_from_log",
                    "load_log",
                ],
            )
        )
        cases.append(_library_case(k, which, session, base, rng, slow))
    return cases


def _library_case(
    k: int,
    which: str,
    session: fieldcal.Session,
    base: Base,
    rng: np.random.Generator,
    slow: bool = True,
) -> Case:
    accel, mag = list(session.accel), list(session.mag)
    name = f"#{k} {which}"
    call: Callable[[], object]
    check: Callable[[Any], str] | None = None
    nonsense = False
    if which == "calibrate":
        target = str(rng.choice(["accel", "mag", "both", "none"]))
        a_desc, a = _poses_mutation(accel, rng) if target in ("accel", "both") else ("", accel)
        m_desc, m = _poses_mutation(mag, rng) if target in ("mag", "both") else ("", mag)
        if rng.random() < 0.1:
            a, a_desc = None, "None"
        o_desc, opts = _option_mutation(rng, base) if rng.random() < 0.6 else ("", {})
        if not slow and opts.get("method") == "greedy":
            o_desc, opts = o_desc.replace("'greedy'", "'mle'"), {"method": "mle"}
        name += f" accel[{a_desc}] mag[{m_desc}] {o_desc}"
        call = _calibrate_call(a, m, opts)
        check = _calibrate_check
    elif which == "nonsense":
        nonsense = True
        how = str(rng.choice(["same data", "mag shuffled", "labels shuffled", "accel twice"]))
        method = str(rng.choice(["mle", "mle", "ellipsoid", "greedy" if slow else "mle"]))
        if how == "same data":
            m = accel
        elif how == "mag shuffled":
            # a derangement of the 14-pose session's poses, fitted jointly by "mle" (with 10
            # poses a random pairing can still fit: the certificate has 8 degrees of freedom)
            accel, mag = list(base.sessions[-1].accel), list(base.sessions[-1].mag)
            order = rng.permutation(len(mag))
            while np.any(order == np.arange(len(mag))):
                order = rng.permutation(len(mag))
            m = [mag[i] for i in order]
            method = "mle"
        elif how == "labels shuffled":
            stacked_a, stacked_m = np.concatenate(accel), np.concatenate(mag)
            labels = rng.permutation(np.repeat(np.arange(len(accel)), [len(x) for x in accel]))
            accel = [stacked_a[labels == i] for i in range(len(accel))]
            m = [stacked_m[labels == i] for i in range(len(mag))]
        else:
            m = [x * 1.5 + 0.2 for x in accel]
        name += f" ({how}, method={method})"
        opts = (
            {"method": method} if method != "greedy" else {"method": method, "max_iterations": 100}
        )
        call = _calibrate_call(accel, m, opts)
        check = _calibrate_check
    elif which == "summarize":
        desc, a = _poses_mutation(accel, rng)
        trim = [True, False, "yes", None][int(rng.integers(0, 4))]
        name += f" accel[{desc}] trim={trim!r}"
        call = lambda: fieldcal.summarize(a, mag, trim=trim)  # noqa: E731
    elif which == "stats_from_means":
        desc, a = _poses_mutation([np.array([x.mean(axis=0) for x in accel])], rng)
        a = a[0] if isinstance(a, list) and a and rng.random() < 0.8 else a
        counts = [None, [1] * len(accel), [0] * len(accel), [-1] * len(accel), "x", [1.5] * 3][
            int(rng.integers(0, 6))
        ]
        name += f" means[{desc}] counts={counts!r}"[:200]
        call = lambda: fieldcal.stats_from_means(a, None, counts)  # noqa: E731
    elif which == "fit_ellipsoid":
        desc, x = _poses_mutation([np.concatenate(mag)], rng)
        x = x[0] if isinstance(x, list) and x and rng.random() < 0.8 else x
        faithful = [False, True, "yes"][int(rng.integers(0, 3))]
        name += f" samples[{desc}] faithful={faithful!r}"
        call = lambda: fieldcal.fit_ellipsoid(x, faithful=faithful)  # noqa: E731
    elif which == "align":
        desc, x = _poses_mutation([np.concatenate(accel)], rng)
        x = x[0] if isinstance(x, list) and x else x
        m_all = np.concatenate(mag)
        incl = [None, 60.0, 91, NAN, "x"][int(rng.integers(0, 5))]
        name += f" accel[{desc}] inclination_deg={incl!r}"
        call = lambda: fieldcal.align(x, m_all, inclination_deg=incl)  # noqa: E731
    elif which == "correct":
        cal = base.calibrations[str(rng.choice(list(base.calibrations)))]
        desc, x = _poses_mutation([np.concatenate(accel)[:20]], rng)
        x = x[0] if isinstance(x, list) and x else x
        sensor = str(rng.choice(["accel", "mag"]))
        name += f" {cal.method} correct_{sensor}[{desc}]"
        call = lambda: (cal.correct_accel if sensor == "accel" else cal.correct_mag)(x)  # noqa: E731
    elif which == "field magnitudes":
        cal = base.calibrations["mle"]
        g = [9.8, "9.8", NAN, -1, 0, INF, None, True, 1e-320, 1e308][int(rng.integers(0, 10))]
        h = [48.0, None, NAN, [1.0]][int(rng.integers(0, 4))]
        name += f" gravity={g!r} field_strength={h!r}"
        call = lambda: cal.with_field_magnitudes(g, h)  # noqa: E731
    elif which == "detect_still":
        from fieldcal.logs.stillness import detect_still

        cols = base.arrays["continuous"]
        x = np.column_stack([cols["ax"], cols["ay"], cols["az"]])
        desc, x2 = _poses_mutation([x], rng)
        x2 = x2[0] if isinstance(x2, list) and x2 else x2
        opts = {}
        for key in rng.choice(["window", "min_samples", "trim", "factor", "threshold",
                               "floor_quantile", "max_gap", "merge_sigma"],
                              int(rng.integers(0, 3)), replace=False):  # fmt: skip
            pool = [INF, NAN, 0, -1, 1e300, 1.5, "5", None, True, 10**30, 3]
            opts[str(key)] = pool[int(rng.integers(0, len(pool)))]
        name += f" accel[{desc}] {opts!r}"[:200]
        call = lambda: detect_still(x2, **opts)  # noqa: E731
    elif which == "poses_from_log":
        from fieldcal.logs import load_log, poses_from_log

        opts = {}
        for key in rng.choice(["rate", "window", "min_still", "trim", "threshold", "factor"],
                              int(rng.integers(1, 3)), replace=False):  # fmt: skip
            pool = [INF, NAN, 0, -1, 1e300, 1e-300, 0.5, "5", None, True, 10**30, 3]
            opts[str(key)] = pool[int(rng.integers(0, len(pool)))]
        name += f" {opts!r}"

        def call() -> object:
            path = base.folder / "continuous.csv"
            if not path.exists():
                path.write_text(base.texts["continuous"])
            return poses_from_log(load_log(path), **opts)

    else:  # load_log
        from fieldcal.logs import load_log

        opts = {}
        pools: dict[str, list[Any]] = {
            "accel_cols": ["ax,ay,az", ["ax", "ay"], "x", 5, ["ax", "ay", 3], ("mx", "my", "mz")],
            "mag_cols": [None, "mx,my,mz", "ax,ay,az", ""],
            "time_col": [None, "t", "ax", 5, ""],
            "pose_col": [None, "pose", "t", "ax"],
            "drop_nan": [True, "yes"],
            "need": [("accel",), "accel", (), ("gyro",)],
        }
        for key in rng.choice(list(pools), int(rng.integers(1, 3)), replace=False):
            pool = pools[str(key)]
            opts[str(key)] = pool[int(rng.integers(0, len(pool)))]
        name += f" {opts!r}"

        def call() -> object:
            path = base.folder / "continuous.csv"
            if not path.exists():
                path.write_text(base.texts["continuous"])
            return load_log(path, **opts)

    return Case(
        "library calls",
        name[:300],
        lambda folder: library_outcome(call, nonsense=nonsense, check=check),
    )


def outside_cases(base: Base, n: int, seed: int) -> list[Case]:
    """``fieldcal.simulate`` and ``fieldcal.metrics.reconstruction_error`` with odd arguments:
    simulation/ and metrics.py are outside this work, so their row of the table is apart."""
    pools: dict[str, list[Any]] = {
        "preset": ["paper", "nope", None, 1],
        "seed": [0, -1, "x", 1.5, None, 2**70],
        "n_poses": [0, 1, -3, 2.5, "10", 12, None],
        "samples": [(1, 1), (0, 0), (5, 2), (-1, 3), "x", (2.5, 4), (10,)],
        "noise_alpha": [(0.0, 0.0), (-1.0, 1.0), (NAN, 1.0), 0.1],
        "pose_noise": [0.0, -1.0, NAN, (0.1, 0.01), "x"],
        "dip_deg": [(10.0, 20.0), (91.0, 95.0), None, "x"],
        "gain_spread": [0.0, -1.0, 10.0, NAN],
        "pose_distribution": ["uniform", "handheld", "nope"],
    }
    cases = []
    for k in range(n):
        rng = np.random.default_rng([seed, 5, k])
        if k % 2:
            cases.append(_metrics_case(k, base, rng))
            continue
        opts: dict[str, Any] = {}
        for key in rng.choice(list(pools), int(rng.integers(1, 4)), replace=False):
            pool = pools[str(key)]
            opts[str(key)] = pool[int(rng.integers(0, len(pool)))]
        cases.append(Case(OUTSIDE, f"#{k} simulate {opts!r}", _simulate_run(opts)))
    return cases


def _simulate_run(opts: dict[str, Any]) -> Callable[[Path], tuple[str, str]]:
    return lambda folder: library_outcome(lambda: fieldcal.simulate(**opts))


def _metrics_case(k: int, base: Base, rng: np.random.Generator) -> Case:
    accel = base.sessions[int(rng.integers(0, len(base.sessions)))].accel
    true = np.array([x.mean(axis=0) for x in accel])
    desc, est = _poses_mutation([true + 1e-3], rng)
    est = est[0] if isinstance(est, list) and est and rng.random() < 0.8 else est
    cov = [np.eye(3) * 1e-4, np.zeros((3, 3)), -np.eye(3), np.eye(2), "x"][int(rng.integers(0, 5))]
    counts = [None, [0] * len(true), [1] * len(true), "x"][int(rng.integers(0, 4))]
    name = f"#{k} metrics.reconstruction_error estimate[{desc}] cov={_short(cov)} counts={counts!r}"

    def call() -> object:
        return fieldcal.metrics.reconstruction_error(true, est, cov, counts)

    return Case(OUTSIDE, name[:200], lambda folder: library_outcome(call))


def _calibrate_call(a: Any, m: Any, opts: dict[str, Any]) -> Callable[[], object]:
    return lambda: fieldcal.calibrate(a, m, **opts)


# ============================================================================ running
def build(base: Base, counts: dict[str, int], seed: int, *, slow: bool = True) -> list[Case]:
    """The cases of each category (``counts``), seeded; without ``slow``, no greedy fits."""
    BASE_TEXTS.update(base.texts)
    cases: list[Case] = []
    for category, n in counts.items():
        if category == "log files":
            cases += log_cases(base, n, seed)
        elif category == "options":
            cases += option_cases(base, n, seed, slow=slow)
        elif category == "calibration files":
            cases += calibration_cases(base, n, seed)
        elif category == OUTSIDE:
            cases += outside_cases(base, n, seed)
        elif category == RESIDUE:
            cases += residue_cases(
                base.documents["mle"], base.calibrations["mle"], cli_outcome, library_outcome, Case
            )
        else:
            cases += library_cases(base, n, seed, slow=slow)
    return cases


def run_cases(
    cases: Sequence[Case],
    folder: Path,
    *,
    keep: Path | None = None,
    timeout_scale: float = 1.0,
    progress: Callable[[int, Result], None] | None = None,
) -> list[Result]:
    results = []
    for k, case in enumerate(cases):
        work = folder / f"case{k}"
        work.mkdir(parents=True, exist_ok=True)
        started = time.perf_counter()
        try:
            with _alarm(case.timeout * timeout_scale):
                outcome, detail = case.run(work)
        except _Timeout:
            outcome, detail = "hang", f"no answer within {case.timeout * timeout_scale:g} s"
        result = Result(case.category, case.name, outcome, detail, time.perf_counter() - started)
        results.append(result)
        if outcome in BUGS and keep is not None:
            dest = keep / f"{case.category.replace(' ', '-')}-{k}"
            shutil.rmtree(dest, ignore_errors=True)
            shutil.copytree(
                work,
                dest,
                symlinks=True,
                ignore_dangling_symlinks=True,
                ignore=lambda d, names: [n for n in names if _special(Path(d) / n)],
            )
            (dest / "CASE.txt").write_text(f"{case.name}\n{outcome}: {detail}\n")
        shutil.rmtree(work, ignore_errors=True)
        if progress is not None:
            progress(k, result)
    return results


def _special(path: Path) -> bool:
    try:
        return not stat.S_ISREG(path.lstat().st_mode) and not path.is_dir()
    except OSError:
        return True


def table(results: Sequence[Result]) -> str:
    counts = Counter((r.category, r.outcome) for r in results)
    head = "| category | cases | " + " | ".join(OUTCOMES) + " |"
    rows = [head, "|---|" + "---:|" * (len(OUTCOMES) + 1)]
    for category in CATEGORIES:
        n = sum(counts[(category, o)] for o in OUTCOMES)
        if n:
            cells = " | ".join(str(counts[(category, o)]) for o in OUTCOMES)
            rows.append(f"| {category} | {n} | {cells} |")
    total = " | ".join(str(sum(counts[(c, o)] for c in CATEGORIES)) for o in OUTCOMES)
    rows.append(f"| **all** | {len(results)} | {total} |")
    return "\n".join(rows)


def bugs(results: Sequence[Result]) -> list[Result]:
    return [r for r in results if r.outcome in BUGS]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a small corpus, no docs update")
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--keep", type=Path, help="keep the inputs of failing cases here")
    parser.add_argument("--only", choices=CATEGORIES, action="append")
    parser.add_argument("--dump", type=Path, help="write every result as JSON lines here")
    parser.add_argument(
        "--fraction", type=float, default=1.0, help="this share of the full corpus (a busy machine)"
    )
    parser.add_argument(
        "--timeout-scale", type=float, default=1.0, help="every case's timeout times this"
    )
    args = parser.parse_args()
    counts = dict(QUICK if args.quick else FULL)
    if args.fraction != 1.0:
        counts = {k: max(1, round(v * args.fraction)) for k, v in counts.items()}
    if args.only:
        counts = {k: v for k, v in counts.items() if k in args.only}
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fieldcal-fuzz-") as tmp:
        folder = Path(tmp)
        base = make_base(folder, args.seed)
        cases = build(base, counts, args.seed)
        print(f"{len(cases)} cases", flush=True)

        def progress(k: int, result: Result) -> None:
            if result.outcome in BUGS:
                print(
                    f"[{result.outcome}] {result.category} {result.name}\n    {result.detail}",
                    flush=True,
                )
            if (k + 1) % 200 == 0:
                print(f"  {k + 1} cases, {time.perf_counter() - started:.0f} s", flush=True)

        if args.keep:
            args.keep.mkdir(parents=True, exist_ok=True)
        results = run_cases(
            cases,
            folder / "cases",
            keep=args.keep,
            progress=progress,
            timeout_scale=args.timeout_scale,
        )
    elapsed = time.perf_counter() - started
    if args.dump:
        with args.dump.open("w") as handle:
            for r in results:
                handle.write(json.dumps(r.__dict__) + "\n")
    print(table(results))
    slow = sorted(results, key=lambda r: -r.seconds)[:5]
    print("slowest:", "; ".join(f"{r.seconds:.1f} s {r.name[:60]}" for r in slow))
    print(f"{elapsed:.0f} s")
    if not args.quick and not args.only:
        extra = "".join(
            f" --{name.replace('_', '-')} {value:g}"
            for name, value in (("fraction", args.fraction), ("timeout_scale", args.timeout_scale))
            if value != 1.0
        )
        write(results, elapsed, args.seed, extra, args.timeout_scale)


def write(
    results: Sequence[Result], elapsed: float, seed: int, extra: str = "", scale: float = 1.0
) -> None:
    """The fuzz section of docs/benchmarks.md: the table and every bug found."""
    from _report import stamp, write_section

    ours = [r for r in bugs(results) if r.category != OUTSIDE]
    outside = [r for r in bugs(results) if r.category == OUTSIDE]
    per = ", ".join(f"{n:,} {c}" for c, n in Counter(r.category for r in results).items())
    lines = [
        "## Fuzz: malformed logs, options, calibration files and library calls",
        "",
        stamp(f"nice python benchmarks/fuzz.py --seed {seed}{extra}"),
        f"Seeded generators of malformed input ({per}); each case runs in this process with "
        f"a timeout ({20 * scale:g} s; {60 * scale:g} s for a report"
        + (f", {scale:g}x the usual: a machine shared with other jobs" if scale != 1 else "")
        + "), the command line through click's test runner.",
        "",
        "- **log files**: CSV text truncated, garbage bytes (NUL, non-UTF-8, quotes), fields "
        "over 131,072 characters, odd cells (NaN, inf, 1e300, 1e400, text, empty), scaled by "
        "1e-300 ... 1e300, duplicated, missing or empty header names, preambles, ragged rows, "
        "other delimiters, BOM, CRLF, 20,000 columns, time columns reversed, constant or beyond "
        "the float range, pose columns with a label per row; NPZ files truncated, with flipped "
        "bytes, empty, a bare `.npy`, pickled, float16/int/bool/complex/text/date arrays, "
        "(3, n) and other shapes, arrays of different lengths; Parquet files damaged or with "
        "text, null and list columns; a FIFO, a folder, `/dev/null`, `/dev/zero`, a broken "
        "link. Through `fieldcal calibrate` (a fifth through `apply` and `report`).",
        "- **options**: `calibrate` option sets on valid logs: inf, nan, 0, -1, 1e300, 1e999, "
        "text for every number; bad `--noise`, `--pose-noise`, `--mag-axes`, column choices.",
        "- **calibration files**: JSON with values replaced by other types, keys deleted, "
        "wrong shapes, NaN/inf, singular gains, booleans as strings, nesting 10 to 100,000 "
        "deep, damaged text and bytes, future versions; through `Calibration.from_json` and "
        "everything that reads it (corrections, every export, JSON round trip) or `fieldcal "
        "export`, `apply`, `report`.",
        "- **library calls**: `fieldcal.calibrate` with poses as text, objects, booleans, "
        "complex, float16, ragged, transposed, empty, NaN/inf, scaled 1e-310 ... 1e301, "
        "constant or collinear, too few, and odd options (every method's); `summarize`, "
        "`stats_from_means`, `fit_ellipsoid`, `align`, `correct_*`, `with_field_magnitudes`, "
        "`load_log`, `detect_still`, `poses_from_log`.",
        "- **residue**: issue 22's list, one case each (`benchmarks/fuzz_residue.py`): "
        "`capture` onto a full file system, `batch --scheduler bogus` (10 s), the greedy "
        "method on 1,200 rows scaled by 1e-30 (60 s), `plan_poses(cal, 10**6)`, a capture "
        "with a fifth of its lines NaN (must warn `dropped_lines`), a board whose header came "
        "before the port opened, a log without its `ax` or `mz` column (and with `--sensors`), "
        "gains of 1e300 and 1e-300 and a bias of 1e308 in a calibration file (refused naming "
        "the key), `１２`, `١٢` and `1_000` as numbers, `apply` on 10,000 NUL bytes, `store "
        "list` across different `--gravity`.",
        "",
        "Outcomes: **ok** a result (exit code 0, or 3 for a fail verdict); **error** one "
        "line, `Error: ...` with exit code 2 or a one-line `ValueError`; **usage** click's "
        "own three-line block for an option value of the wrong type. Bugs: **traceback** any "
        "other exception or exit code (and numpy's own words, e.g. `Singular matrix`), "
        "**hang** the timeout, **noisy** a multi-line or over-long (400 characters) error or "
        "numpy warnings printed, **nonsense** a result other than verdict fail for input that "
        "has none: the same columns for both sensors, the magnetometer's columns a (scaled) "
        "copy of the accelerometer's, pose labels shuffled across rows, magnetometer rows or "
        "poses shuffled against the accelerometer's, a singular or non-finite gain in a "
        "calibration file.",
        "",
        table(results),
        "",
        f"{len(results):,} cases in {elapsed:.0f} s; {len(ours)} bug(s) in every row but the "
        f"last, {len(outside)} in the last (`fieldcal.simulate` and "
        "`fieldcal.metrics.reconstruction_error`, the test helpers).",
    ]
    found = ours + outside
    if found:
        lines += ["", "Bugs found (the first 30):", ""]
        lines += [
            f"- {r.category}: `{r.name[:110]}` — {r.outcome}: {r.detail[:150]}" for r in found[:30]
        ]
    write_section("fuzz", "\n".join(lines))


if __name__ == "__main__":
    main()
