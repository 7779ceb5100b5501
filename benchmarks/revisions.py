"""Two revisions of fieldcal side by side in one process: the Table 1 call, the seed's model
and 24 single-reading shots, timed call by call in alternation.

On a shared machine (this one: 2 cores of a host whose speed drifts by tens of percent within
seconds) two processes run one after the other can differ by 1.4x with the same code; two
copies of the package in one process, called in turn, see the same drift. Each revision is
taken from git (``git archive``) into a temporary folder and imported under its own name
(``fieldcal_a``, ``fieldcal_b``: the package's own absolute module names rewritten, so the two
never share a module). Per round, each case runs ``--calls`` times per revision, the order
alternating between rounds; the figure is the median over rounds of the per-call median, and
the ratio the median of the rounds' paired ratios (with its interquartile range). The results
of the two revisions are compared first (largest relative difference of the gains, verdicts).

    python benchmarks/revisions.py 8b9efb7 HEAD            # 30 rounds, pinned to CPU 1
    python benchmarks/revisions.py 8b9efb7 HEAD --docs     # and write the docs section
"""

from __future__ import annotations

import argparse
import importlib
import io
import os
import re
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import ROOT, pin_blas_threads, stamp, write_section
from _small_sets import shots

#: A quoted module name of the package: ``"fieldcal"`` or ``"fieldcal.x.y"`` (lazy imports).
_QUOTED = re.compile(r"""(["'])fieldcal([."'])""")


def export(rev: str, name: str, into: Path) -> None:
    """Revision ``rev``'s ``src/fieldcal`` as the package ``name`` in ``into``."""
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", rev, "src/fieldcal"],
        check=True,
        capture_output=True,
    ).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(into / "_tmp", filter="data")
    (into / "_tmp" / "src" / "fieldcal").rename(into / name)
    for path in (into / name).rglob("*.py"):
        text = path.read_text(encoding="utf-8")
        path.write_text(_QUOTED.sub(rf"\1{name}\2", text), encoding="utf-8")


def cases(fc: Any) -> dict[str, Callable[[], Any]]:
    """The three calls of one revision, on the same inputs."""
    s = fc.simulate("paper", seed=1)
    a, m = shots(24, 0)
    return {
        "calibrate, default (Table 1)": lambda: fc.calibrate(s.accel, s.mag),
        "calibrate, seed's model (Table 1)": lambda: fc.calibrate(
            s.accel, s.mag, pose_noise="none", robust=False
        ),
        "calibrate, 24 single-reading shots": lambda: fc.calibrate(a, m),
    }


def same_results(a: dict[str, Callable[[], Any]], b: dict[str, Callable[[], Any]]) -> str:
    """Largest relative difference of the two revisions' gains over the cases, and verdicts."""
    worst, verdicts = 0.0, []
    for name in a:
        x, y = a[name](), b[name]()
        for sensor in ("accel", "mag"):
            gx, gy = x.sensor(sensor).gain, y.sensor(sensor).gain
            worst = max(worst, float(np.abs(gx - gy).max() / np.abs(gx).max()))
        verdicts.append(x.verdict.level == y.verdict.level)
    same = "the same" if all(verdicts) else "DIFFERENT"
    return f"largest relative difference of the gains {worst:.1e}; verdicts {same}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", help="git revision (e.g. a commit)")
    parser.add_argument("after", help="git revision (e.g. HEAD)")
    parser.add_argument("--rounds", type=int, default=30)
    parser.add_argument("--calls", type=int, default=10, help="calls per case and round")
    parser.add_argument("--cpu", type=int, default=1, help="pin to this CPU (-1: do not pin)")
    parser.add_argument("--docs", action="store_true", help="write the docs section")
    args = parser.parse_args()
    if args.cpu >= 0 and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {args.cpu})
    warnings.simplefilter("ignore")  # the small sets' notes
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        export(args.before, "fieldcal_a", folder)
        export(args.after, "fieldcal_b", folder)
        sys.path.insert(0, str(folder))
        calls = {
            "a": cases(importlib.import_module("fieldcal_a")),
            "b": cases(importlib.import_module("fieldcal_b")),
        }
        check = same_results(calls["a"], calls["b"])
        times: dict[str, dict[str, list[float]]] = {name: {"a": [], "b": []} for name in calls["a"]}
        load = os.getloadavg()
        with pin_blas_threads():
            for fn in [*calls["a"].values(), *calls["b"].values()]:
                for _ in range(5):
                    fn()  # warm-up: imports, caches
            for r in range(args.rounds):
                for name in times:
                    for which in ("a", "b") if r % 2 == 0 else ("b", "a"):
                        fn = calls[which][name]
                        per_call = []
                        for _ in range(args.calls):
                            t = time.process_time()
                            fn()
                            per_call.append(time.process_time() - t)
                        times[name][which].append(1e3 * statistics.median(per_call))
    rows = [
        f"| call | {args.before} (ms) | {args.after} (ms) | ratio (IQR) |",
        "|---|---|---|---|",
    ]
    for name, t in times.items():
        ratios = [b / a for a, b in zip(t["a"], t["b"], strict=True)]
        q1, q3 = np.percentile(ratios, [25, 75])
        rows.append(
            f"| `{name}` | {statistics.median(t['a']):.2f} | {statistics.median(t['b']):.2f} | "
            f"{statistics.median(ratios):.2f} ({q1:.2f}-{q3:.2f}) |"
        )
    command = f"python benchmarks/revisions.py {args.before} {args.after}"
    text = (
        f"## Two revisions side by side (`benchmarks/revisions.py`)\n\n{stamp(command)}\n"
        f"Both revisions in one process, pinned to one CPU, one BLAS thread, {args.rounds} "
        f"rounds of {args.calls} calls per case and revision, the order alternating; process "
        f"CPU time; medians over rounds, ratio = median of the rounds' paired ratios. "
        f"Load average at the start: {load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f}. Results: "
        f"{check}.\n\n" + "\n".join(rows)
    )
    print(text)
    if args.docs:
        write_section("revisions", text)


if __name__ == "__main__":
    main()
