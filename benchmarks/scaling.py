"""No quadratic stage: ``fieldcal calibrate`` and each of its stages against the number of poses
(10, 100, 1,000, 10,000), side by side with a pyarrow read of the same CSV.

The log is a continuous 100 Hz session drawn as Table 1 of the seed paper with ``N`` still poses
of 2 s each and 0.5-1 s of motion between them (about 275 rows a pose, 10 columns: t, ax..az,
gx..gz, mx..mz). For each ``N``:

- **processes** (wall and peak memory, ``wait4``): ``fieldcal calibrate log.csv`` and a process
  that only reads the file with ``pyarrow.csv.read_csv`` (the anchor), taken in turn for
  ``--repeat`` rounds (an A/B loop: a busy machine slows both alike); medians and ratios;
- **stages** (one fresh process, the anchor read first in it): fieldcal's reader, still
  detection, trimming + pose statistics + fit + trust (``run_log`` without the gyroscope), the
  gyroscope stage (``run_log`` with it, less the run without), the document (JSON) and the
  terminal summary, the HTML report (with matplotlib). A stage linear in poses has a constant
  time per pose down each column.

The gyroscope stage above ``--gyro-max`` poses is left out (of the process too, with
``--no-gyro``) and the table says so: measure it with a larger ``--gyro-max``.

Then the issue's row (``--issue-row``, on by default): 1,200 poses of about 830 rows each and
turn (Table 1's rests lengthened, 1-2 s of motion), about 10⁶ rows, ``calibrate`` with its
gyroscope against the pyarrow read in the same A/B loop; goals ≤ 5x the read's wall time and
≤ 1.5x its peak memory.

Every child process runs with Python's bytecode cache on (in a temporary folder,
``PYTHONPYCACHEPREFIX``) and one untimed run first: an installed fieldcal has its modules
compiled, as pyarrow has; a checkout run with ``PYTHONDONTWRITEBYTECODE`` would compile all of
fieldcal's in every process (about half a second of CPU).

``--cpu K`` pins every measured process to CPU K (as the issue's A/B pairs: pyarrow's reader
then has one core, as fieldcal's own work has).

    python benchmarks/scaling.py --cpu 1                   # docs/benchmarks.md updated
    python benchmarks/scaling.py --poses 10 100 --repeat 1 --no-issue-row --no-docs
    python benchmarks/scaling.py --poses --repeat 5 --cpu 1  # the issue's row alone, printed
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
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import stamp, write_section

PYARROW_READ = "import pyarrow.csv as c, sys; c.read_csv(sys.argv[1])"

STAGES = """
import io, json, sys, time
path, gyro, report = sys.argv[1], sys.argv[2] == "1", sys.argv[3] == "1"
out = {}
t = time.perf_counter()
import pyarrow.csv
pyarrow.csv.read_csv(path)
out["pyarrow.csv.read_csv (anchor)"] = time.perf_counter() - t
from rich.console import Console
import fieldcal
from fieldcal.logs import load_log, poses_from_log
from fieldcal.output.terminal import print_summary
from fieldcal.pipeline import LogSettings, run_log
def fit(gyro):
    return run_log(log, LogSettings.of({"gyro": gyro}), found=poses)
def timed(name, call):
    start = time.perf_counter()
    value = call()
    out[name] = time.perf_counter() - start
    return value
log = timed("read (load_log)", lambda: load_log(path))
poses = timed("still detection", lambda: poses_from_log(log))
run = timed("trim + pose statistics + fit + trust", lambda: fit(False))
if gyro:
    both = timed("gyro", lambda: fit(True))
    out["gyro"] -= out["trim + pose statistics + fit + trust"]
    run = both
doc = timed("document (JSON)", lambda: json.dumps(run.document()))
console = Console(file=io.StringIO(), width=120)
timed("terminal summary", lambda: print_summary(console, run.calibration, run.document(), []))
if report:
    from fieldcal.output.report import write_report
    timed("HTML report", lambda: write_report(run.calibration, log, sys.argv[4]))
out["poses found"] = len(run.calibration.poses)
print(json.dumps(out))
"""


MAKE_LOG = """
import sys, numpy as np, pyarrow as pa, pyarrow.csv as pa_csv
from fieldcal.simulation.continuous import simulate_continuous
if sys.argv[3] == "issue":  # about 10^6 rows at 1,200 poses: rests of 650-700 rows, 1-2 s turns
    options = dict(samples=(650, 700), move_seconds=(1.0, 2.0))
else:
    options = dict(samples=(200, 200), move_seconds=(0.5, 1.0))
sim = simulate_continuous("paper", seed=1, n_poses=int(sys.argv[2]), **options)
columns = {k: np.round(v, 2 if k == "t" else 6) for k, v in sim.columns.items()}
options = pa_csv.WriteOptions(include_header=False, quoting_style="none")  # (it quotes names)
with open(sys.argv[1], "wb") as handle:
    handle.write((",".join(columns) + "\\n").encode())
    pa_csv.write_csv(pa.table(columns), handle, write_options=options)
print(len(columns["t"]))
"""


def make_log(path: Path, n_poses: int, kind: str = "scaling") -> int:
    """The continuous log with ``n_poses`` poses, written with pyarrow (numpy's savetxt would
    take minutes at 10,000 poses); readings rounded to 6 decimals as a logger writes them.
    Made in a process of its own: a child forked from a large parent would report the parent's
    peak memory as its own. ``kind="issue"``: the issue's longer rests and turns. Returns the
    rows written."""
    argv = [sys.executable, "-c", MAKE_LOG, str(path), str(n_poses), kind]
    return int(subprocess.run(argv, capture_output=True, text=True, check=True, env=ENV).stdout)


def child_env(cache: Path) -> dict[str, str]:
    """The environment of the measured processes: Python's bytecode cache on, in ``cache``."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = str(cache)
    return env


ENV: dict[str, str] = dict(os.environ)


#: The CPU every measured process is pinned to (``--cpu``), or None.
CPU: int | None = None


def _pin() -> None:
    if CPU is not None:
        os.sched_setaffinity(0, {CPU})


def run(argv: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (MB) of one process (pinned to :data:`CPU` if set)."""
    start = time.perf_counter()
    proc = subprocess.Popen(
        argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=ENV, preexec_fn=_pin
    )
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    code = os.waitstatus_to_exitcode(status)
    if code not in (0, 3):
        err = proc.stderr.read().decode() if proc.stderr else ""
        raise SystemExit(f"{' '.join(argv)} failed ({code}): {err.strip()[-400:]}")
    return wall, usage.ru_maxrss / 1024


def load() -> str:
    return "load average " + ", ".join(f"{x:.1f}" for x in os.getloadavg())


@dataclass
class Row:
    poses: int
    rows: int
    anchor: tuple[float, float]  # median wall (s), peak RSS (MB)
    calibrate: tuple[float, float]
    stages: dict[str, float]
    gyro: bool
    load: str


def measure(
    n_poses: int, repeat: int, gyro: bool, report: bool, tmp: Path, kind: str = "scaling"
) -> Row:
    log = tmp / f"poses{n_poses}-{kind}.csv"
    rows = make_log(log, n_poses, kind)
    calibrate = [sys.executable, "-m", "fieldcal", "calibrate", str(log), "-o",
                 str(tmp / "cal.json"), "-q", "--force"]  # fmt: skip
    if not gyro:
        calibrate.append("--no-gyro")
    anchor = [sys.executable, "-c", PYARROW_READ, str(log)]
    run(calibrate)  # untimed: the bytecode cache filled
    pairs: dict[str, list[tuple[float, float]]] = {"anchor": [], "calibrate": []}
    for _ in range(repeat):  # A/B in turn
        pairs["anchor"].append(run(anchor))
        pairs["calibrate"].append(run(calibrate))
    argv = [sys.executable, "-c", STAGES, str(log), str(int(gyro)), str(int(report)),
            str(tmp / "report.html")]  # fmt: skip
    stages = json.loads(
        subprocess.run(
            argv, capture_output=True, text=True, check=True, env=ENV, preexec_fn=_pin
        ).stdout
    )
    log.unlink()

    def median(name: str) -> tuple[float, float]:
        wall, rss = np.median(np.array(pairs[name]), axis=0)
        return float(wall), float(rss)

    return Row(n_poses, rows, median("anchor"), median("calibrate"), stages, gyro, load())


def tables(results: list[Row], repeat: int) -> str:
    pinned = f"every process pinned to CPU {CPU}" if CPU is not None else "not pinned"
    lines = [
        f"`fieldcal calibrate log.csv` and a process reading the same CSV with "
        f"`pyarrow.csv.read_csv`, in turn for {repeat} round(s), medians ({pinned}):",
        "",
        "| poses | rows | pyarrow read (s) | calibrate (s) | ratio | calibrate peak RSS (MB) "
        "| pyarrow peak RSS (MB) | memory ratio | calibrate ms / pose | gyroscope | load |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        (a, a_mb), (c, c_mb) = r.anchor, r.calibrate
        gyro = "fitted" if r.gyro else "left out (--no-gyro)"
        lines.append(
            f"| {r.poses:,} | {r.rows:,} | {a:.2f} | {c:.2f} | {c / a:.1f}x | {c_mb:.0f} "
            f"| {a_mb:.0f} | {c_mb / a_mb:.2f}x | {1e3 * c / r.poses:.2f} | {gyro} | {r.load} |"
        )
    names: list[str] = []
    for r in results:
        names += [k for k in r.stages if k not in names and k != "poses found"]
    head = " | ".join(f"{r.poses:,} poses" for r in results)
    lines += [
        "",
        "Each stage in one fresh process per pose count, the anchor read first in it: seconds "
        "(and µs per pose); a stage linear in poses keeps its time per pose down a column. The "
        "last column is the time per pose at the largest count the stage ran at over the one "
        "before (about 1 or less: linear; about 10 per decade: quadratic).",
        "",
        f"| stage | {head} | per pose, last / previous |",
        "|---|" + "---|" * (len(results) + 1),
    ]
    for name in names:
        cells = [
            f"{r.stages[name]:.3f} ({1e6 * r.stages[name] / r.poses:,.0f})"
            if name in r.stages
            else "left out"
            for r in results
        ]
        ran = [r.stages[name] / r.poses for r in results if name in r.stages]
        growth = f"{ran[-1] / ran[-2]:.2f}" if len(ran) > 1 else ""
        lines.append(f"| {name} | {' | '.join(cells)} | {growth} |")
    found = " | ".join(f"{r.stages['poses found']:,.0f}" for r in results)
    lines.append(f"| poses found | {found} | |")
    return "\n".join(lines)


def issue_table(row: Row, repeat: int) -> str:
    """The issue's row: 1,200 poses, about 10⁶ rows, against its goals."""
    (a, a_mb), (c, c_mb) = row.anchor, row.calibrate
    return "\n".join(
        [
            f"The issue's row ({row.poses:,} poses of about {row.rows // row.poses} rows each "
            f"and turn, {row.rows:,} rows, the gyroscope fitted), the same A/B loop, "
            f"{repeat} round(s), medians:",
            "",
            "| poses | rows | pyarrow read (s) | calibrate (s) | ratio (goal ≤ 5x) "
            "| pyarrow peak RSS (MB) | calibrate peak RSS (MB) | memory ratio (goal ≤ 1.5x) "
            "| gyroscope stage (s, in process) | load |",
            "|---|---|---|---|---|---|---|---|---|---|",
            f"| {row.poses:,} | {row.rows:,} | {a:.2f} | {c:.2f} | {c / a:.1f}x | {a_mb:.0f} "
            f"| {c_mb:.0f} | {c_mb / a_mb:.2f}x | {row.stages.get('gyro', float('nan')):.2f} "
            f"| {row.load} |",
        ]
    )


def main() -> None:
    global ENV, CPU
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, nargs="*", default=[10, 100, 1000, 10000],
                        help="pose counts; none (a bare --poses): the issue's row alone, "
                        "printed, docs not written")  # fmt: skip
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--gyro-max", type=int, default=10000,
                        help="poses above which the gyroscope stage is left out")  # fmt: skip
    parser.add_argument("--report-max", type=int, default=1000,
                        help="poses above which the HTML report is left out")  # fmt: skip
    parser.add_argument("--issue-row", action=argparse.BooleanOptionalAction, default=True,
                        help="the issue's 1,200 poses, 10^6 rows (default on)")  # fmt: skip
    parser.add_argument("--cpu", type=int, default=None,
                        help="pin every measured process to this CPU (pyarrow's threads "
                        "then share one core, as fieldcal's own work does)")  # fmt: skip
    parser.add_argument("--no-docs", action="store_true", help="print only")
    args = parser.parse_args()
    CPU = args.cpu
    report_ok = importlib.util.find_spec("matplotlib") is not None
    results = []
    issue = None
    with tempfile.TemporaryDirectory(prefix="fieldcal-scaling-") as folder:
        ENV = child_env(Path(folder) / "pycache")
        for n in args.poses:
            result = measure(
                n, args.repeat, n <= args.gyro_max, report_ok and n <= args.report_max,
                Path(folder),
            )  # fmt: skip
            print(result, flush=True)
            results.append(result)
        if args.issue_row:
            issue = measure(1200, args.repeat, True, False, Path(folder), "issue")
            print(issue, flush=True)
    text = tables(results, args.repeat) if results else ""
    if issue is not None:
        text += ("\n\n" if text else "") + issue_table(issue, args.repeat)
    print(text)
    if not args.no_docs and results:
        command = "python benchmarks/scaling.py " + " ".join(sys.argv[1:])
        write_section(
            "scaling", f"## Against the number of poses\n\n{stamp(command.strip())}\n{text}"
        )


if __name__ == "__main__":
    main()
