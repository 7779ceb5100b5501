"""Continuous estimator: whole-process CPU time and peak memory per sample (issue 33 item 6).

Each case runs in a fresh process (``python -c``: import, simulate or read, ``fit_continuous``)
so that the figures are what a user's process costs: CPU time (user + system, the child's
``resource.getrusage``) and its peak resident memory (``ru_maxrss``). Cases: hand-held logs from
the independent simulator (``fieldcal.simulation.handheld``, lever arm, translation) of 60 s and
600 s at 100 Hz, and BROAD trial 06 at its full 285.7 Hz when ``../shared/data/broad`` is there.
The issue's goals: ≤ 20 µs CPU and ≤ 1 KB per sample; a 3-minute 285 Hz log ≤ 5 s CPU; an hour
at 100 Hz ≤ 10 s CPU and ≤ 500 MB.

    python benchmarks/continuous_speed.py            # prints the table
    python benchmarks/continuous_speed.py --long     # adds an hour at 100 Hz (slow today)
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
from pathlib import Path

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "broad"

SIMULATED = """
import time
import numpy as np
from fieldcal.simulation.handheld import simulate_handheld
from fieldcal.methods.continuous import fit_continuous
t0 = time.process_time()
log = simulate_handheld(1, seconds={seconds}, rate=100.0, internal_rate=200.0)
c = log.columns
cols = [np.column_stack([c[p + a] for a in "xyz"]) for p in "amg"]
made = time.process_time() - t0
fit_continuous(c["t"], *cols, gravity=log.gravity)
print(len(c["t"]), made)
"""

BROAD = """
import numpy as np
from fieldcal.methods.continuous import fit_continuous
d = np.genfromtxt({path!r}, delimiter=",", names=True)
cols = [np.column_stack([d[p + a] for a in "xyz"]) for p in "amg"]
fit_continuous(d["t"], *cols, gravity=9.81)
print(len(d), 0.0)
"""


def run(code: str) -> tuple[int, float, float]:
    """Samples, CPU seconds (less the simulation's, which a user does not run) and peak MB of
    a fresh process running ``code``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    n, made = out.split()[-2:]
    return int(n), cpu - float(made), after.ru_maxrss / 1024.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--long", action="store_true", help="Add an hour at 100 Hz.")
    args = parser.parse_args()
    cases = [("hand-held, 60 s at 100 Hz", SIMULATED.format(seconds=60.0))]
    cases.append(("hand-held, 600 s at 100 Hz", SIMULATED.format(seconds=600.0)))
    if args.long:
        cases.append(("hand-held, 3600 s at 100 Hz", SIMULATED.format(seconds=3600.0)))
    trial = next(DATA.glob("06_*.csv"), None) if DATA.is_dir() else None
    if trial is not None:
        cases.append(("BROAD 06, 197 s at 285.7 Hz", BROAD.format(path=str(trial))))
    print("| log | samples | CPU s | µs/sample | peak MB | KB/sample |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, code in cases:
        n, cpu, mb = run(code)
        # ru_maxrss of the children is the largest child's: the cases run largest last
        print(
            f"| {label} | {n} | {cpu:.1f} | {1e6 * cpu / n:.0f} | {mb:.0f} | {1024 * mb / n:.1f} |"
        )


if __name__ == "__main__":
    main()
