"""Continuous estimator: whole-process CPU time and peak memory per sample (issue 33 item 6).

Each case is the user's whole process, run fresh: ``python -m fieldcal calibrate log.csv``
(import, read the CSV, fit, verdict, write the JSON), its CPU time (user + system, its own
``resource.getrusage``) and peak resident memory (``ru_maxrss``). Logs: hand-held logs from the
independent simulator (``fieldcal.simulation.handheld``: lever arm, translation) of 60 s, 600 s
and (``--long``) 3600 s at 100 Hz, written to CSV first (not timed), and BROAD trial 06 at its
full 285.7 Hz when ``../shared/data/broad`` is there. Medians over ``--repeat`` runs (the 600 s
and 3600 s logs, and every case before, once: the machine is shared). ``--before SRC`` runs
every case also with ``PYTHONPATH=SRC`` (an earlier version's ``src``, e.g. ``git archive
<commit> src | tar -x -C /tmp/before``), side by side in the same run (``--no-hour-before``
skips the hour before: the per-sample estimator needed 2.4 GB for it). The issue's goals:
≤ 20 µs CPU and ≤ 1 KB per sample; a 3-minute 285 Hz log ≤ 5 s CPU; an hour at 100 Hz ≤ 10 s
CPU and ≤ 500 MB.

    python benchmarks/continuous_speed.py                      # the table
    python benchmarks/continuous_speed.py --long --before /tmp/before/src
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "broad"

WRITE = """
import numpy as np
from fieldcal.simulation.handheld import simulate_handheld
log = simulate_handheld(1, seconds={seconds}, rate=100.0, internal_rate=200.0)
c = log.columns
names = ["t"] + [p + a for p in "agm" for a in "xyz"]
np.savetxt({path!r}, np.column_stack([c[n] for n in names]), delimiter=",",
           header=",".join(names), comments="", fmt="%.9g")
"""

# the user's whole process: the CLI in this interpreter, then its own resource use
RUN = """
import resource, runpy, sys
sys.argv = ["fieldcal", "calibrate", {path!r}, "-o", {out!r}, "--force", "--quiet"]
try:
    runpy.run_module("fieldcal", run_name="__main__")
except SystemExit as stop:
    if stop.code not in (0, 3, None):
        raise
r = resource.getrusage(resource.RUSAGE_SELF)
print(r.ru_utime + r.ru_stime, r.ru_maxrss / 1024.0)
"""


def _env(src: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(src)}


def measure(path: Path, src: Path, out: Path) -> tuple[float, float]:
    """CPU seconds and peak MB of ``fieldcal calibrate path`` in a fresh process."""
    done = subprocess.run(
        [sys.executable, "-c", RUN.format(path=str(path), out=str(out))],
        capture_output=True,
        text=True,
        check=True,
        env=_env(src),
    )
    cpu, mb = done.stdout.split()[-2:]
    return float(cpu), float(mb)


def rows(path: Path) -> int:
    with path.open() as f:
        return sum(1 for _ in f) - 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--long", action="store_true", help="Add an hour at 100 Hz.")
    parser.add_argument("--before", type=Path, help="An earlier version's src, run alongside.")
    parser.add_argument("--repeat", type=int, default=3, help="Runs per short case (median).")
    parser.add_argument(
        "--no-hour-before", action="store_true", help="Skip the hour with --before."
    )
    args = parser.parse_args()
    after = ROOT / "src"
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        cases: list[tuple[str, Path, int, bool]] = []
        for seconds in (60, 600, 3600) if args.long else (60, 600):
            path = folder / f"handheld_{seconds}s.csv"
            code = WRITE.format(seconds=float(seconds), path=str(path))
            subprocess.run([sys.executable, "-c", code], check=True, env=_env(after))
            repeat = args.repeat if seconds <= 60 else 1
            before = seconds < 3600 or not args.no_hour_before
            cases.append((f"hand-held, {seconds} s at 100 Hz", path, repeat, before))
        trial = next(DATA.glob("06_*.csv"), None) if DATA.is_dir() else None
        if trial is not None:
            cases.append(("BROAD 06, 197 s at 285.7 Hz", trial, args.repeat, True))
        versions = [("after", after)]
        if args.before is not None:
            versions.insert(0, ("before", args.before))
        print("| log | samples | version | CPU s | µs/sample | peak MB | KB/sample |")
        print("|---|---:|---|---:|---:|---:|---:|")
        for label, path, repeat, with_before in cases:
            n = rows(path)
            for name, src in versions:
                if name == "before" and not with_before:
                    continue
                times = repeat if name == "after" else 1
                runs = [measure(path, src, folder / "cal.json") for _ in range(times)]
                cpu = statistics.median(r[0] for r in runs)
                mb = statistics.median(r[1] for r in runs)
                print(
                    f"| {label} | {n} | {name} | {cpu:.2f} | {1e6 * cpu / n:.0f} | {mb:.0f} "
                    f"| {1024 * mb / n:.2f} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
