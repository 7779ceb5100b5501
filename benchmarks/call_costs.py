"""What the per-call goals of issue 24 are up against: numpy's fixed cost per operation on the
arrays a Table 1 call handles, the work that call does for five sessions and a set of shots,
and what writing a batch log's files costs.

One process, one BLAS thread, pinned to one CPU (``--cpu``, default 1):

- **operations**: single numpy/scipy operations on arrays of a Table 1 call's size (15 poses:
  (15, 3) vectors, (15, 3, 3) blocks, the 22x22 reduced system of Levenberg-Marquardt), each
  the median over rounds of the mean of many calls; the JSON text of a Table 1 calibration
  (``json.dumps``, the json module's C encoder, and ``fieldcal.serialize.dumps``, the
  ``cal.json`` layout) and its atomic write (temporary file, fsync, rename, fsync of the
  folder: ``fieldcal._files.write_text``);
- **sessions**: the default ``fieldcal.calibrate`` of ``simulate("paper", seed=k)``, k = 0-4,
  and of 24 single-reading shots (``_small_sets.shots(24, 0)``, as in ``speed.py``): its
  time, Python-level function calls (``cProfile``'s count), Levenberg-Marquardt runs and
  iterations (the cold starts, a doubtful set's extra starts and the pose-level noise's refits;
  results must not change beyond 1e-9, so this work is fixed), evaluations of the model, and
  the time per iteration.

The last paragraph turns them into the budget the issue's 2.5 ms leaves. Its lean iteration is
an estimate, the fewest numpy operations one iteration of the joint problem needs as the model
is written (rotation update ~10, residuals and cost ~7, Jacobian ~9, ``JᵀJ`` ~3, damped 3x3
inverses ~12, Schur complement ~6, reduced solve 1, step and predicted decrease ~6: about 55).

    python benchmarks/call_costs.py            # docs/benchmarks.md section call_costs
    python benchmarks/call_costs.py --quick    # fewer repetitions, printed only
"""

from __future__ import annotations

import argparse
import cProfile
import importlib
import importlib.util
import json
import os
import pstats
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from scipy.linalg.lapack import dgesv

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import pin_blas_threads, rebind, stamp, write_section
from _small_sets import shots

import fieldcal
from fieldcal import _files
from fieldcal.likelihood import levenberg
from fieldcal.serialize import dumps

#: The issue's goal for the default call on a Table 1 session (ms).
GOAL_MS = 2.5
#: The shot sets' anchor, when circuitpython-mag-cal is installed.
ANCHOR = "circuitpython-mag-cal's ellipsoid fit of the 24 shots below (the anchor)"
#: Numpy operations one lean iteration of the joint problem needs (see the module docstring).
LEAN_OPS = 55


def per_call(fn: Callable[[], object], rounds: int, budget: float = 0.02) -> float:
    """Seconds per call of ``fn``: the median over ``rounds`` of the mean over a batch of calls
    sized to take about ``budget`` seconds."""
    fn()
    start = time.perf_counter()
    fn()
    once = max(time.perf_counter() - start, 1e-7)
    n = max(1, int(budget / once))
    means = []
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(n):
            fn()
        means.append((time.perf_counter() - start) / n)
    return statistics.median(means)


def operations(rounds: int, folder: Path) -> list[tuple[str, float]]:
    """(what, µs per call) of single operations of a Table 1 call's size."""
    rng = np.random.default_rng(0)
    x, y = rng.standard_normal((2, 15, 3))
    blocks = rng.standard_normal((15, 3, 3))
    spd = blocks @ blocks.transpose(0, 2, 1) + 3 * np.eye(3)
    reduced = rng.standard_normal((22, 22)) + 22 * np.eye(22)
    rhs = rng.standard_normal(22)
    index = rng.permutation(15)
    angles = rng.standard_normal(15)
    s = fieldcal.simulate("paper", seed=1)
    doc = fieldcal.calibrate(s.accel, s.mag).to_dict()
    text = dumps(doc)
    target = folder / "cal.json"
    cases: list[tuple[str, Callable[[], object]]] = [
        ("`x + y`, (15, 3)", lambda: x + y),
        ("`x[index]`, (15, 3) gathered by 15 indices", lambda: x[index]),
        ("`x.sum()`, (15, 3)", lambda: x.sum()),
        ("`np.sin(a)`, (15,)", lambda: np.sin(angles)),
        ("`A @ B`, (15, 3, 3) blocks", lambda: blocks @ blocks),
        ("`np.linalg.inv`, (15, 3, 3)", lambda: np.linalg.inv(spd)),
        ("`np.linalg.eigh`, one 3x3", lambda: np.linalg.eigh(spd[0])),
        ("`np.linalg.eigh`, (15, 3, 3)", lambda: np.linalg.eigh(spd)),
        ("`np.linalg.svd`, one 3x3", lambda: np.linalg.svd(blocks[0])),
        ("LAPACK `dgesv`, 22x22 (the reduced system)", lambda: dgesv(reduced, rhs)),
        (f"`json.dumps`, Table 1 calibration ({len(text) // 1000} kB)", lambda: json.dumps(doc)),
        ("`serialize.dumps` (the cal.json layout), same", lambda: dumps(doc)),
        (
            "atomic write with fsync (`_files.write_text`), same",
            lambda: _files.write_text(target, text),
        ),
    ]
    if importlib.util.find_spec("mag_cal") is not None:  # the shot sets' anchor (speed.py)
        mag_cal = importlib.import_module("mag_cal.calibration")
        accel, mag = (np.vstack(x) for x in shots(24, 0))
        cases.append(
            (
                ANCHOR,
                lambda: mag_cal.Calibration().calibrate(
                    mag, accel, routine=mag_cal.Calibration.ELLIPSOID
                ),
            )
        )
    return [(what, 1e6 * per_call(fn, rounds)) for what, fn in cases]


def sessions(calls: int) -> list[dict[str, Any]]:
    """The default call's time and work for Table 1 sessions of seeds 0-4 and 24 shots."""
    lm = {"runs": 0, "iterations": 0, "seconds": 0.0}
    evaluations = [0]

    def count_lm(fn: Callable[..., levenberg.Result]) -> Callable[..., levenberg.Result]:
        def run(*args: Any, **kwargs: Any) -> levenberg.Result:
            start = time.perf_counter()
            result = fn(*args, **kwargs)
            lm["seconds"] += time.perf_counter() - start
            lm["runs"] += 1
            lm["iterations"] += result.iterations
            return result

        return run

    def count_batch(fn: Callable[..., list[Any]]) -> Callable[..., list[Any]]:
        """Starts stepped together (a doubtful set's extra starts): each a run."""

        def run(*args: Any, **kwargs: Any) -> list[Any]:
            start = time.perf_counter()
            results = fn(*args, **kwargs)
            lm["seconds"] += time.perf_counter() - start
            lm["runs"] += len(results)
            lm["iterations"] += sum(getattr(r, "iterations", 0) for r in results)
            return results

        return run

    def count_evaluate(fn: Callable[..., Any]) -> Callable[..., Any]:
        def run(*args: Any, **kwargs: Any) -> Any:
            evaluations[0] += 1
            return fn(*args, **kwargs)

        return run

    sets: list[tuple[str, Any, Any]] = []
    for seed in range(5):
        s = fieldcal.simulate("paper", seed=seed)
        sets.append((f"Table 1, seed {seed}", s.accel, s.mag))
    sets.append(("24 shots, seed 0", *shots(24, 0)))
    rows = []
    for name, accel, mag in sets:
        seconds = per_call(lambda a=accel, m=mag: fieldcal.calibrate(a, m), 5, budget=0.2)
        profile = cProfile.Profile()
        profile.enable()
        fieldcal.calibrate(accel, mag)
        profile.disable()
        python_calls = pstats.Stats(profile).total_calls
        undo = rebind("fieldcal.likelihood.levenberg", "solve_alone", count_lm)
        undo += rebind("fieldcal.likelihood.lockstep", "lockstep", count_batch)
        undo += rebind("fieldcal.trust.evaluate", "evaluate", count_evaluate)
        lm.update(runs=0, iterations=0, seconds=0.0)
        evaluations[0] = 0
        try:
            for _ in range(calls):
                fieldcal.calibrate(accel, mag)
        finally:
            for holder, attr, fn in undo:
                setattr(holder, attr, fn)
        rows.append(
            {
                "set": name,
                "ms": 1e3 * seconds,
                "python_calls": python_calls,
                "runs": lm["runs"] / calls,
                "iterations": lm["iterations"] / calls,
                "evaluations": evaluations[0] / calls,
                "lm_ms": 1e3 * lm["seconds"] / calls,
                "us_per_iteration": 1e6 * lm["seconds"] / max(lm["iterations"], 1),
            }
        )
        print(rows[-1], flush=True)
    return rows


def report(ops: list[tuple[str, float]], runs: list[dict[str, Any]], command: str) -> str:
    lines = [
        "## What a Table 1 call is made of (`benchmarks/call_costs.py`)",
        "",
        stamp(command),
        "One process pinned to one CPU, one BLAS thread. Load average at the start: "
        + ", ".join(f"{v:.2f}" for v in os.getloadavg())
        + ". Operations: median over rounds of the mean of many calls. Sessions: the default "
        '`fieldcal.calibrate(s.accel, s.mag)` for `s = fieldcal.simulate("paper", seed=k)`; '
        "Levenberg-Marquardt runs and iterations counted inside the solver, per call.",
        "",
        "| operation, on a Table 1 call's arrays | µs per call |",
        "|---|---|",
        *(f"| {what} | {us:.2f} |" for what, us in ops),
        "",
        "| set | ms per call | Python-level calls | LM runs | LM iterations | evaluations "
        "| LM ms | µs per LM iteration |",
        "|---|---|---|---|---|---|---|---|",
        *(
            f"| {r['set']} | {r['ms']:.2f} | {r['python_calls']:,} | {r['runs']:.0f} "
            f"| {r['iterations']:.0f} | {r['evaluations']:.0f} | {r['lm_ms']:.2f} "
            f"| {r['us_per_iteration']:.0f} |"
            for r in runs
        ),
    ]
    cheap = statistics.median(us for what, us in ops[:4])
    blocks = next(us for what, us in ops if what.startswith("`A @ B`"))
    per_op = statistics.median([cheap, blocks])
    table1 = [r for r in runs if r["set"].startswith("Table 1")]
    iterations = statistics.median(r["iterations"] for r in table1)
    lean_ms = iterations * LEAN_OPS * per_op / 1e3
    files = sum(us for what, us in ops if "cal.json" in what or "atomic" in what) / 1e3
    shot = next(r for r in runs if "shots" in r["set"])
    anchor = next((us for what, us in ops if what == ANCHOR), None)
    lines += [
        "",
        f"At {per_op:.1f} µs an operation (between an elementwise operation, a gather or a "
        f"reduction, {cheap:.1f} µs, and a batched 3x3 product, {blocks:.1f} µs), the issue's "
        f"{GOAL_MS} ms buys about {1e3 * GOAL_MS / per_op:,.0f} numpy operations for the "
        f"whole call. The median session takes {iterations:.0f} Levenberg-Marquardt "
        f"iterations (fixed: the results must not change beyond 1e-9); a lean iteration of "
        f"about {LEAN_OPS} operations would take {LEAN_OPS * per_op:.0f} µs, the "
        f"iterations alone {lean_ms:.2f} ms, before the pose statistics, the closed-form "
        f"starts (eigen-decompositions at tens of µs each), the pose-level noise's refits, "
        f"the evaluations and the verdict. In a batch, each log's `cal.json` (laid out and "
        f"written atomically) costs {files:.2f} ms on its own. The 24 shots take "
        f"{shot['runs']:.0f} Levenberg-Marquardt runs of {shot['iterations']:.0f} iterations "
        f"in all (a doubtful set's extra starts, the pose-level noise's refits): at the lean "
        f"iteration's cost {shot['iterations'] * LEAN_OPS * per_op / 1e3:.2f} ms"
        + ("." if anchor is None else f", against {anchor / 1e3:.2f} ms for the anchor's fit."),
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions, no docs")
    parser.add_argument("--cpu", type=int, default=1, help="the CPU to pin to (-1: none)")
    args = parser.parse_args()
    if args.cpu >= 0:
        os.sched_setaffinity(0, {args.cpu})
    rounds, calls = (5, 5) if args.quick else (21, 20)
    with pin_blas_threads(), tempfile.TemporaryDirectory() as tmp:
        ops = operations(rounds, Path(tmp))
        for what, us in ops:
            print(f"{what}: {us:.2f} µs", flush=True)
        runs = sessions(calls)
    text = report(ops, runs, "python benchmarks/call_costs.py")
    print(text)
    if not args.quick:
        write_section("call_costs", text)


if __name__ == "__main__":
    main()
