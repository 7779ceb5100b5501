"""Reading logs: fieldcal's text reader and ``fieldcal apply`` against pyarrow, pandas and numpy.

Every row runs in its own process on one generated CSV (N rows x 10 columns ``t, ax..mz``, a
simulated continuous session written with 9 significant digits), so interpreter start and
imports are paid as a user's command pays them. The rows are run in turn, round after round,
so that the load of a shared machine falls on all of them alike; wall times are medians over
the rounds, peak memory the process's maximum resident set (``VmHWM`` of
``/proc/self/status`` at exit: the rusage of a forked child would count its parent's pages).

Rows: ``python -c "import numpy"`` (the fixed cost), ``pyarrow.csv.read_csv`` with one thread
and with its default threads, ``pandas.read_csv``, ``numpy.loadtxt``, fieldcal's
``read_table`` (the fast path) and ``read_careful`` (the csv-module reader it falls back on:
what ``read_table`` did before), ``fieldcal calibrate`` end to end, ``apply_to_file`` (CSV in,
CSV out) and its baseline, pyarrow reading the CSV, computing six columns and writing it all.

    python benchmarks/readers.py                      # 10^6 rows, 5 rounds, docs section
    python benchmarks/readers.py --rows 100000 --rounds 3 --quick
    python benchmarks/readers.py --large 10000000     # and read a 10^7-row copy (~1.2 GB)
    python benchmarks/readers.py --file /tmp/big/big.csv --quick   # a CSV of your own
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import stamp, write_section

import fieldcal
from fieldcal.simulation.continuous import simulate_continuous

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ["t", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz"]

#: name -> (python code run with P = the log, N = its rows, C = a calibration, O = an output,
#: J = a calibration output; or None for the calibrate command), optional module it needs.
CASES: dict[str, tuple[str | None, str | None]] = {
    "python + import numpy": ("import numpy", None),
    "pyarrow.csv.read_csv, 1 thread": (
        "import pyarrow.csv as pc\n"
        "t = pc.read_csv(P, read_options=pc.ReadOptions(use_threads=False))\n"
        "assert t.num_rows == N",
        "pyarrow",
    ),
    "pyarrow.csv.read_csv": (
        "import pyarrow.csv as pc\nassert pc.read_csv(P).num_rows == N",
        "pyarrow",
    ),
    "pandas.read_csv": ("import pandas as pd\nassert len(pd.read_csv(P)) == N", "pandas"),
    "numpy.loadtxt": (
        "import numpy as np\nassert len(np.loadtxt(P, delimiter=',', skiprows=1)) == N",
        None,
    ),
    "fieldcal read_table": (
        "from fieldcal.logs.readers import read_table\nassert read_table(P).n_rows == N",
        None,
    ),
    "fieldcal read_careful (before)": (
        "from fieldcal.logs.text import read_careful\nassert read_careful(P).n_rows == N",
        None,
    ),
    "fieldcal calibrate (CLI)": (None, None),
    "fieldcal apply_to_file": (
        "from fieldcal.calibration import Calibration\n"
        "from fieldcal.logs import apply_to_file\n"
        "apply_to_file(Calibration.from_json(open(C).read()), P, O)",
        None,
    ),
    "pyarrow read + 6 columns + write": (
        "import pyarrow.csv as pc, pyarrow.compute as pcm\n"
        "t = pc.read_csv(P)\n"
        "for c in ['ax', 'ay', 'az', 'mx', 'my', 'mz']:\n"
        "    t = t.append_column(c + '_cal', pcm.multiply(t.column(c), 2.0))\n"
        "pc.write_csv(t, O)",
        "pyarrow",
    ),
}
READER_ROWS = [
    "pyarrow.csv.read_csv, 1 thread",
    "pyarrow.csv.read_csv",
    "pandas.read_csv",
    "numpy.loadtxt",
    "fieldcal read_table",
    "fieldcal read_careful (before)",
    "fieldcal calibrate (CLI)",
]


def make_log(path: Path, rows: int, seed: int = 1) -> int:
    """A simulated continuous session of ``rows`` rows (still poses and moves) as CSV."""
    n_poses = int(np.clip(rows // 6700, 15, 400))
    per_pose = max(rows / n_poses - 150, 60)  # a move between poses is ~150 rows at 100 Hz
    while True:
        low, high = int(0.92 * per_pose), int(per_pose)
        sim = simulate_continuous("paper", seed=seed, n_poses=n_poses, samples=(low, high))
        got = len(sim.columns["t"])
        if got >= rows:
            break
        per_pose *= 1.05 * rows / got
    data = np.column_stack([sim.columns[c] for c in COLUMNS])[:rows]
    fmt = ["%.2f"] + ["%.9g"] * (len(COLUMNS) - 1)
    np.savetxt(path, data, delimiter=",", header=",".join(COLUMNS), comments="", fmt=fmt)
    return len(data)


def make_calibration(path: Path) -> None:
    s = fieldcal.simulate("paper", seed=2)
    path.write_text(fieldcal.calibrate(s.accel, s.mag).to_json())


#: Run first in every process: report the peak resident set at exit (VmHWM belongs to the
#: process's own memory map; the rusage of a forked child would include the parent's pages).
PEAK = (
    "import atexit, sys\n"
    "def _peak():\n"
    "    status = open('/proc/self/status').read()\n"
    "    print('peak-kB', status.split('VmHWM:')[1].split()[0], file=sys.stderr)\n"
    "atexit.register(_peak)\n"
)


def run(argv: list[str], env: dict[str, str]) -> tuple[float, float]:
    """Wall seconds and peak resident MiB of one process."""
    start = time.perf_counter()
    proc = subprocess.run(
        argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"{argv[-1][-80:]!r} failed: {proc.stderr.strip()[-300:]}")
    peak = [line.split()[1] for line in proc.stderr.splitlines() if line.startswith("peak-kB")]
    return wall, int(peak[-1]) / 1024


def argv_for(name: str, log: Path, rows: int, folder: Path) -> list[str]:
    code, _ = CASES[name]
    if code is None:  # the calibrate command as a user runs it
        command = ["fieldcal", "calibrate", str(log), "-o", str(folder / "cal-out.json"), "--force"]
        code = (
            f"import runpy\nsys.argv = {command!r}\n"
            "runpy.run_module('fieldcal.cli', run_name='__main__')"
        )
    prelude = (
        f"P = {str(log)!r}\nN = {rows}\nC = {str(folder / 'cal.json')!r}\n"
        f"O = {str(folder / 'out.csv')!r}\n"
    )
    return [sys.executable, "-c", PEAK + prelude + code]


def measure(
    names: list[str], log: Path, rows: int, folder: Path, rounds: int
) -> dict[str, tuple[float, float, float]]:
    """name -> (median wall s, min wall s, median peak MiB), the rows run in turn each round."""
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    times: dict[str, list[float]] = {n: [] for n in names}
    peaks: dict[str, list[float]] = {n: [] for n in names}
    for r in range(rounds):
        order = names[r % len(names) :] + names[: r % len(names)]  # rotate: no row always first
        for name in order:
            wall, peak = run(argv_for(name, log, rows, folder), env)
            times[name].append(wall)
            peaks[name].append(peak)
            print(f"  round {r + 1}: {name:34s} {wall:6.2f} s {peak:7.0f} MiB", flush=True)
    return {
        n: (float(np.median(times[n])), float(np.min(times[n])), float(np.median(peaks[n])))
        for n in names
    }


def table(results: dict[str, tuple[float, float, float]], rows: int, ratios: bool = True) -> str:
    """The results as a markdown table, with the wall-time ratios to the pyarrow rows."""
    arrays = rows * len(COLUMNS) * 8 / 2**20
    base = {
        "pyarrow, 1 thread": "pyarrow.csv.read_csv, 1 thread",
        "pyarrow": "pyarrow.csv.read_csv",
        "pyarrow read+write": "pyarrow read + 6 columns + write",
    }
    ratios = ratios and all(name in results for name in base.values())
    head = "| process | median wall (s) | min (s) | peak RSS (MiB) |"
    if ratios:
        head += "".join(f" / {b} |" for b in base)
    lines = [head, "|---" * (head.count("|") - 1) + "|"]
    for name, (median, low, peak) in results.items():
        line = f"| {name} | {median:.2f} | {low:.2f} | {peak:.0f} |"
        if ratios:
            line += "".join(f" {median / results[b][0]:.2f} |" for b in base.values())
        lines.append(line)
    lines += ["", f"Parsed numbers: {arrays:.0f} MiB of float64 ({rows:,} rows x {len(COLUMNS)})."]
    return "\n".join(lines)


def targets(
    results: dict[str, tuple[float, float, float]],
    rows: int,
    large: dict[str, tuple[float, float, float]] | None,
    large_rows: int,
) -> str:
    """The brief's targets against this run (process wall-time ratios, whole-process RSS)."""

    def ratio(a: str, b: str) -> float:
        return results[a][0] / results[b][0] if a in results and b in results else np.nan

    arrays = rows * len(COLUMNS) * 8 / 2**20
    peak = results["fieldcal read_table"][2]
    checks = [
        (
            "`read_table` within ~1.5x `pyarrow.csv.read_csv`",
            ratio("fieldcal read_table", "pyarrow.csv.read_csv"),
            1.5,
        ),
        (
            "`fieldcal calibrate` end to end within 3x `pyarrow.csv.read_csv`",
            ratio("fieldcal calibrate (CLI)", "pyarrow.csv.read_csv"),
            3.0,
        ),
        (
            "`apply_to_file` within 3x pyarrow read + write",
            ratio("fieldcal apply_to_file", "pyarrow read + 6 columns + write"),
            3.0,
        ),
        (f"`read_table` peak RSS within ~2x the arrays ({arrays:.0f} MiB)", peak / arrays, 2.0),
    ]
    if large:
        big = large["fieldcal read_table"][2]
        big_arrays = large_rows * len(COLUMNS) * 8 / 2**20
        checks.append(
            (
                f"{large_rows:,} rows: peak RSS in proportion to the arrays ({big_arrays:.0f} MiB)",
                big / big_arrays,
                2.0,
            )
        )
    lines = ["| target | measured | met |", "|---|---|---|"]
    for what, value, limit in checks:
        met = "yes" if value <= limit else "no"
        lines.append(f"| {what} | {value:.2f}x | {met} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=1_000_000, help="rows of the generated log")
    parser.add_argument("--rounds", type=int, default=5, help="runs of every row")
    parser.add_argument(
        "--large", type=int, default=0, help="also read a copy of this many rows (0: no)"
    )
    parser.add_argument("--file", type=Path, help="read this CSV instead of a generated one")
    parser.add_argument("--quick", action="store_true", help="no docs update")
    args = parser.parse_args()

    folder = Path(tempfile.mkdtemp(prefix="fieldcal-readers-"))
    try:
        log = folder / "log.csv"
        if args.file is not None:
            shutil.copyfile(args.file, log)  # (the --large copy is made beside it)
            with log.open("rb") as handle:
                rows = sum(block.count(b"\n") for block in iter(lambda: handle.read(1 << 24), b""))
            rows -= 1  # the header line
        else:
            rows = make_log(log, args.rows)
        make_calibration(folder / "cal.json")
        size = log.stat().st_size / 1e6
        print(f"{log}: {rows:,} rows, {size:.0f} MB")
        names = [
            n for n, (_, needs) in CASES.items() if needs is None or importlib.util.find_spec(needs)
        ]
        results = measure(names, log, rows, folder, args.rounds)
        text = table(results, rows)
        print(text)
        large = ""
        big_results: dict[str, tuple[float, float, float]] | None = None
        big_rows = 0
        if args.large:
            big = folder / "large.csv"
            copies = -(-args.large // rows)
            with log.open("rb") as src, big.open("wb") as dst:
                dst.write(src.readline())
                body = src.read()
                for _ in range(copies):
                    dst.write(body)
            log.unlink()  # room on the disk; the large copy is what is read now
            big_rows = rows * copies
            print(f"{big}: {big_rows:,} rows, {big.stat().st_size / 1e6:.0f} MB")
            big_names = ["python + import numpy", "numpy.loadtxt", "fieldcal read_table"]
            big_results = measure(big_names, big, big_rows, folder, max(1, args.rounds // 2))
            large = table(big_results, big_rows, ratios=False)
            print(large)
            big.unlink()
        goal = targets(results, rows, big_results, big_rows)
        print(goal)
        if not args.quick:
            parts = [
                "## Reading logs",
                "",
                stamp(" ".join(["python benchmarks/readers.py", *sys.argv[1:]])),
                (
                    f"The file `{args.file.name}`, {rows:,} rows"
                    if args.file is not None
                    else f"A simulated continuous session, {rows:,} rows x {len(COLUMNS)} columns"
                )
                + f" ({size:.0f} MB of CSV, 9 significant digits). Each row of the table is a "
                f"separate process (interpreter start and imports included), run in turn for "
                f"{args.rounds} rounds on a 2-core machine shared with other work; medians of "
                "the rounds. `read_table` is the fast path (numpy's C parser in blocks); "
                "`read_careful` is the csv-module reader it falls back on to explain a "
                "failure, which is what `read_table` was before. `apply_to_file` writes CSV "
                "(every input field byte for byte, six calibrated columns appended); its "
                "baseline reads with pyarrow, computes six columns and writes the whole table.",
                "",
                text,
            ]
            parts += ["", "### Targets", "", goal]
            if large:
                parts += [
                    "",
                    f"### {big_rows:,} rows ({copies} copies of the file above)",
                    "",
                    large,
                ]
            write_section("readers", "\n".join(parts))
            print("docs/benchmarks.md: section 'readers' written")
    finally:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
