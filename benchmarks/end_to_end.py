"""A large log end to end: ``fieldcal calibrate``, ``apply`` and ``report`` against a process
that only reads (and writes) the same file with pyarrow, each in its own process; then the
in-process breakdown of ``calibrate`` (import, read, columns, detection, calibration).

The log is the seed paper's Table 1 session as a continuous 100 Hz log
(``fieldcal simulate --continuous``) with its 15 rests lengthened to make about ``--rows`` rows
(10 columns: t, ax..az, gx..gz, mx..mz). Wall time and peak resident memory (``wait4``) of each
process, medians over ``--repeat`` runs taken in turn (one run of each command, then the next
round), so a busy machine slows every command alike.

    python benchmarks/end_to_end.py                   # 10^6 rows, 5 rounds, docs updated
    python benchmarks/end_to_end.py --rows 10000000 --repeat 1 --no-docs
"""

from __future__ import annotations

import argparse
import importlib.util
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


def make_log(path: Path, rows: int) -> int:
    """The Table 1 session as a continuous 100 Hz log of about ``rows`` rows: 15 still poses
    each about ``rows / 15`` samples long, with motion between them (as the issue's enlarged
    ``simulate --continuous`` log: still detection finds 15 poses). Returns the rows written."""
    from fieldcal.simulation.continuous import simulate_continuous

    per_pose = max(rows // 15, 50)
    sim = simulate_continuous("paper", seed=1, samples=(int(0.97 * per_pose), per_pose))
    sim.write_csv(str(path))
    return len(sim.columns["t"])


def run(argv: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (MB) of one process."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if proc.returncode not in (0, 3):
        raise SystemExit(f"{' '.join(argv)} failed ({proc.returncode}): {err.strip()}")
    return wall, usage.ru_maxrss / 1024


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
    import json

    return json.loads(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--no-docs", action="store_true", help="print only")
    args = parser.parse_args()
    fieldcal_cmd = [sys.executable, "-m", "fieldcal.cli"]
    with tempfile.TemporaryDirectory(prefix="fieldcal-e2e-") as folder:
        tmp = Path(folder)
        log = tmp / "big.csv"
        rows = make_log(log, args.rows)
        size_mb = log.stat().st_size / 1e6
        arrays_mb = rows * len(COLUMNS) * 8 / 1e6
        cal = tmp / "cal.json"
        subprocess.run([*fieldcal_cmd, "calibrate", str(log), "-o", str(cal), "-q"], check=True)
        commands = {
            "pyarrow.csv.read_csv": [sys.executable, "-c", PYARROW_READ, str(log)],
            "fieldcal calibrate": [
                *fieldcal_cmd, "calibrate", str(log), "-o", str(tmp / "c.json"), "-q", "--force"
            ],
            "pyarrow read + write_csv": [
                sys.executable, "-c", PYARROW_READ_WRITE, str(log), str(tmp / "pa.csv")
            ],
            "fieldcal apply": [
                *fieldcal_cmd, "apply", str(cal), str(log), "-o", str(tmp / "out.csv"), "-q",
                "--force",
            ],
        }  # fmt: skip
        if importlib.util.find_spec("matplotlib") is not None:
            commands["fieldcal report"] = [
                *fieldcal_cmd, "report", str(cal), str(log), "-o", str(tmp / "r.html"), "-q",
                "--force",
            ]  # fmt: skip
        times: dict[str, list[tuple[float, float]]] = {name: [] for name in commands}
        for _ in range(args.repeat):
            for name, argv in commands.items():
                times[name].append(run(argv))
        steps = breakdown(log)

    def median(name: str, k: int) -> float:
        return float(np.median([t[k] for t in times[name]]))

    read = median("pyarrow.csv.read_csv", 0)
    read_write = median("pyarrow read + write_csv", 0)
    baseline = {
        "fieldcal calibrate": ("pyarrow.csv.read_csv", read),
        "fieldcal apply": ("pyarrow read + write_csv", read_write),
        "fieldcal report": ("pyarrow.csv.read_csv", read),
    }
    lines = [
        f"A {rows:,}-row, {len(COLUMNS)}-column CSV with 15 still poses ({size_mb:.0f} MB; "
        f"the parsed float64 arrays are {arrays_mb:.0f} MB), each command in its own process, "
        f"medians of {args.repeat} rounds:",
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
        "Where `calibrate`'s time goes (one fresh process; `load_log` reads the file again):",
        "",
        "| step | seconds |",
        "|---|---|",
    ]
    lines += [f"| {step} | {seconds:.3f} |" for step, seconds in steps.items()]
    text = "\n".join(lines)
    print(text)
    if not args.no_docs:
        command = "python benchmarks/end_to_end.py" + (
            f" --rows {args.rows}" if args.rows != 1_000_000 else ""
        )
        write_section("end-to-end", f"## A large log end to end\n\n{stamp(command)}\n{text}")


if __name__ == "__main__":
    main()
