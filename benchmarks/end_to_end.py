"""A large log end to end: ``fieldcal calibrate``, ``apply`` and ``report`` against a process
that only reads (and writes) the same file with pyarrow, each in its own process; then the
in-process breakdown of ``calibrate`` (import, read, columns, detection, calibration).

The log is the seed paper's Table 1 session as a continuous 100 Hz log
(``fieldcal simulate --continuous``) with its 15 rests lengthened to make about ``--rows`` rows
(10 columns: t, ax..az, gx..gz, mx..mz). Wall time and peak resident memory (``wait4``) of each
process, medians over ``--repeat`` runs taken in turn (one run of each command, then the next
round: an A/B loop, so a busy machine slows every command alike). The rows "(numpy parser)"
run the same command with pyarrow's CSV reader and bulk formatting switched off
(``ARROW_MIN_BYTES`` / ``ARROW_MIN_ROWS``): the default path as it was before them.
``--cpu K`` pins every process to CPU K (pyarrow's threads then share one core, as fieldcal's
own work does). Every process runs with Python's bytecode cache on (in a temporary folder,
filled before the first round): an installed fieldcal has its modules compiled, as pyarrow
has (a checkout with ``PYTHONDONTWRITEBYTECODE`` set compiles them in every process).

    python benchmarks/end_to_end.py                   # 10^6 rows, 5 rounds, docs updated
    python benchmarks/end_to_end.py --rows 10000000 --repeat 1 --no-docs
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import stamp, write_section

COLUMNS = ["t", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz"]

PYARROW_READ = "import pyarrow.csv as c, sys; c.read_csv(sys.argv[1])"
PYARROW_READ_WRITE = (
    "import pyarrow.csv as c, sys; t = c.read_csv(sys.argv[1]); c.write_csv(t, sys.argv[2])"
)


MAKE_LOG = """
import sys
from fieldcal.simulation.continuous import simulate_continuous
per_pose = max(int(sys.argv[2]) // 15, 50)
sim = simulate_continuous("paper", seed=1, samples=(int(0.97 * per_pose), per_pose))
sim.write_csv(sys.argv[1])
print(len(sim.columns["t"]))
"""

#: The default path with pyarrow's reader and bulk formatting off: ``python -c NUMPY_ONLY ...``
#: takes the command line's arguments.
NUMPY_ONLY = (
    "import fieldcal.logs.text as t, fieldcal.logs.streamed_text as s; "
    "t.ARROW_MIN_BYTES = t.ARROW_MIN_BYTES_LOADED = 1 << 62; "
    "s.ARROW_MIN_ROWS = 1 << 62; from fieldcal.cli import main; main()"
)


def make_log(path: Path, rows: int) -> int:
    """The Table 1 session as a continuous 100 Hz log of about ``rows`` rows: 15 still poses
    each about ``rows / 15`` samples long, with motion between them (as the issue's enlarged
    ``simulate --continuous`` log: still detection finds 15 poses). Made in a process of its
    own (a child forked from a large parent reports the parent's peak memory as its own).
    Returns the rows written."""
    argv = [sys.executable, "-c", MAKE_LOG, str(path), str(rows)]
    return int(subprocess.run(argv, capture_output=True, text=True, check=True).stdout)


def run(argv: list[str], cpu: int | None = None) -> tuple[float, float]:
    """Wall seconds and peak RSS (MB) of one process (on CPU ``cpu`` alone if given)."""
    pin = None if cpu is None else (lambda: os.sched_setaffinity(0, {cpu}))
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, preexec_fn=pin)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if proc.returncode not in (0, 3):
        raise SystemExit(f"{' '.join(argv)} failed ({proc.returncode}): {err.strip()}")
    return wall, usage.ru_maxrss / 1024


READ_AB = """
import json, sys, time
import numpy as np, pyarrow.csv
import fieldcal.logs.text as text
from fieldcal.logs.readers import read_table
def fieldcal_read(arrow):
    text.ARROW_MIN_BYTES = text.ARROW_MIN_BYTES_LOADED = 0 if arrow else 1 << 62
    read_table(sys.argv[1])
calls = {
    "pyarrow.csv.read_csv": lambda: pyarrow.csv.read_csv(sys.argv[1]),
    "fieldcal read_table": lambda: fieldcal_read(True),
    "fieldcal read_table (numpy parser)": lambda: fieldcal_read(False),
}
times = {name: [] for name in calls}
for _ in range(int(sys.argv[2])):
    for name, call in calls.items():
        start = time.perf_counter()
        call()
        times[name].append(time.perf_counter() - start)
print(json.dumps({name: float(np.median(t)) for name, t in times.items()}))
"""


def read_ab(path: Path, repeat: int, cpu: int | None) -> dict[str, float]:
    """Median seconds of pyarrow's read and fieldcal's (either parser), taken in turn in one
    process (imports done before the first round)."""
    pin = None if cpu is None else (lambda: os.sched_setaffinity(0, {cpu}))
    argv = [sys.executable, "-c", READ_AB, str(path), str(repeat)]
    out = subprocess.run(argv, capture_output=True, text=True, check=True, preexec_fn=pin)
    return json.loads(out.stdout)


def breakdown(path: Path) -> dict[str, float]:
    """Seconds of each step of ``calibrate`` in a fresh process."""
    code = f"""
import time, json
t0 = time.perf_counter()
import fieldcal
from fieldcal.logs import load_log, poses_from_log
from fieldcal.logs.readers import read_table
t1 = time.perf_counter()
read_table({str(path)!r})
t2 = time.perf_counter()
log = load_log({str(path)!r})
t3 = time.perf_counter()
poses = poses_from_log(log)
t4 = time.perf_counter()
fieldcal.calibrate(poses.accel, poses.mag)
t5 = time.perf_counter()
fieldcal.calibrate(poses.accel, poses.mag)
t6 = time.perf_counter()
print(json.dumps({{"import fieldcal": t1 - t0, "read_table": t2 - t1,
    "load_log (read + columns)": t3 - t2, "poses_from_log (still detection)": t4 - t3,
    "calibrate (first call: imports SciPy)": t5 - t4, "calibrate (again)": t6 - t5}}))
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    return json.loads(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--cpu", type=int, default=None, help="pin every process to this CPU")
    parser.add_argument("--log", type=Path, default=None, help="keep the log here (made once)")
    parser.add_argument("--no-docs", action="store_true", help="print only")
    args = parser.parse_args()
    fieldcal_cmd = [sys.executable, "-m", "fieldcal"]
    numpy_cmd = [sys.executable, "-c", NUMPY_ONLY]
    with tempfile.TemporaryDirectory(prefix="fieldcal-e2e-") as folder:
        tmp = Path(folder)
        # the bytecode cache on for every child, filled now (not in the first round)
        os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
        os.environ["PYTHONPYCACHEPREFIX"] = str(tmp / "pycache")
        spec = importlib.util.find_spec("fieldcal")
        assert spec is not None and spec.origin is not None
        package = str(Path(spec.origin).parent)
        subprocess.run([sys.executable, "-m", "compileall", "-q", package], check=True)
        log = args.log or tmp / "big.csv"
        # (a log made by an earlier run with the same --rows is read again)
        rows = sum(1 for _ in log.open("rb")) - 1 if log.exists() else make_log(log, args.rows)
        size_mb = log.stat().st_size / 1e6
        arrays_mb = rows * len(COLUMNS) * 8 / 1e6
        cal = tmp / "cal.json"
        subprocess.run([*fieldcal_cmd, "calibrate", str(log), "-o", str(cal), "-q"], check=True)
        commands = {
            "pyarrow.csv.read_csv": [sys.executable, "-c", PYARROW_READ, str(log)],
            "fieldcal calibrate": [
                *fieldcal_cmd, "calibrate", str(log), "-o", str(tmp / "c.json"), "-q", "--force"
            ],
            "fieldcal calibrate (numpy parser)": [
                *numpy_cmd, "calibrate", str(log), "-o", str(tmp / "c.json"), "-q", "--force"
            ],
            "pyarrow read + write_csv": [
                sys.executable, "-c", PYARROW_READ_WRITE, str(log), str(tmp / "pa.csv")
            ],
            "fieldcal apply": [
                *fieldcal_cmd, "apply", str(cal), str(log), "-o", str(tmp / "out.csv"), "-q",
                "--force",
            ],
            "fieldcal apply (numpy parser, repr)": [
                *numpy_cmd, "apply", str(cal), str(log), "-o", str(tmp / "out.csv"), "-q",
                "--force",
            ],
        }  # fmt: skip
        if importlib.util.find_spec("matplotlib") is not None:
            commands["fieldcal report"] = [
                *fieldcal_cmd, "report", str(cal), str(log), "-o", str(tmp / "r.html"), "-q",
                "--force",
            ]  # fmt: skip
        times: dict[str, list[tuple[float, float]]] = {name: [] for name in commands}
        loads = [os.getloadavg()[0]]
        for _ in range(args.repeat):
            for name, argv in commands.items():
                times[name].append(run(argv, args.cpu))
            loads.append(os.getloadavg()[0])
        steps = breakdown(log)
        reads = read_ab(log, args.repeat, args.cpu)

    def median(name: str, k: int) -> float:
        return float(np.median([t[k] for t in times[name]]))

    read = median("pyarrow.csv.read_csv", 0)
    read_write = median("pyarrow read + write_csv", 0)
    baseline = {
        "fieldcal calibrate": ("pyarrow.csv.read_csv", read),
        "fieldcal calibrate (numpy parser)": ("pyarrow.csv.read_csv", read),
        "fieldcal apply": ("pyarrow read + write_csv", read_write),
        "fieldcal apply (numpy parser, repr)": ("pyarrow read + write_csv", read_write),
        "fieldcal report": ("pyarrow.csv.read_csv", read),
    }
    pinned = "every process pinned to one CPU" if args.cpu is not None else "not pinned"
    lines = [
        f"A {rows:,}-row, {len(COLUMNS)}-column CSV with 15 still poses ({size_mb:.0f} MB; "
        f"the parsed float64 arrays are {arrays_mb:.0f} MB), each command in its own process, "
        f"medians of {args.repeat} rounds ({pinned}; 1-minute load average "
        f"{min(loads):.1f}-{max(loads):.1f} over the rounds on this 2-core machine):",
        "",
        "| process | wall (s) | peak RSS (MB) | wall / its pyarrow baseline |",
        "|---|---|---|---|",
    ]
    for name in commands:
        ratio = ""
        if name in baseline:
            ratio = f"{median(name, 0) / baseline[name][1]:.2f}x ({baseline[name][0]})"
        lines.append(f"| {name} | {median(name, 0):.2f} | {median(name, 1):.0f} | {ratio} |")
    lines += [
        "",
        "pyarrow's CSV reader and bulk formatting against numpy's parser and `repr` in the same "
        "rounds: `calibrate` "
        f"{median('fieldcal calibrate (numpy parser)', 0) / median('fieldcal calibrate', 0):.2f}x"
        " as fast, `apply` "
        f"{median('fieldcal apply (numpy parser, repr)', 0) / median('fieldcal apply', 0):.2f}x"
        " as fast. pyarrow is a main dependency for this (loaded on first use, in "
        "`logs/arrow_parser.py`: `import fieldcal` and `fieldcal --version` do not load it; "
        "files under 4 MiB keep numpy's parser, whose import is cheaper than pyarrow's). "
        "`apply` hands each block of about 100,000 lines with nothing unusual in it to pyarrow "
        "whole (it reads the sensors' fields, formats the calibrated values as `repr` would and "
        "joins them to the lines: `logs/streamed_text.py`, `_arrow_block`), the bytes the "
        "line-by-line path writes. Every process runs with the bytecode cache on (filled before "
        "the first round), as an installed fieldcal has it.",
    ]
    first = reads["pyarrow.csv.read_csv"]
    lines += [
        "",
        f"Reading alone, in one process, the three readers in turn for {args.repeat} rounds "
        "(medians):",
        "",
        "| reader | seconds | / pyarrow.csv.read_csv |",
        "|---|---|---|",
        *(f"| {name} | {t:.3f} | {t / first:.2f}x |" for name, t in reads.items()),
    ]
    lines += [
        "",
        "Where `calibrate`'s time goes (one fresh process; `load_log` reads the file again):",
        "",
        "| step | seconds |",
        "|---|---|",
    ]
    lines += [f"| {step} | {seconds:.3f} |" for step, seconds in steps.items()]
    text = "\n".join(lines)
    print(text)
    if not args.no_docs:
        command = " ".join(["python benchmarks/end_to_end.py", *sys.argv[1:]])
        write_section("end-to-end", f"## A large log end to end\n\n{stamp(command)}\n{text}")


if __name__ == "__main__":
    main()
