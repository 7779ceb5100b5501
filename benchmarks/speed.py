"""Speed of fieldcal.calibrate from raw samples to the full result, one BLAS thread.

Rows, measured side by side in one process on the same simulated data:

- ``mle`` — the default call: raw samples to the result with the pose-level noise estimated, the
  robust fit (trimming, pose tests), uncertainty, certificate, verdict and predicted accuracy;
- ``mle, seed's model`` — the same with ``pose_noise="none", robust=False`` (the seed paper's
  likelihood, Eq. 7 noise only: what fieldcal 0.1 computed);
- ``least_squares from truth`` — ``scipy.optimize.least_squares`` on the same likelihood started
  at the true parameters (from the pose statistics, so it does not pay for Eq. 5/7; dense
  finite differences for N = 15, the Jacobian's sparsity pattern for N = 2000);
- ``greedy`` and ``ellipsoid`` via ``fieldcal.calibrate(method=...)`` when those modules exist.

    python benchmarks/speed.py            # medians over repeated runs (about 5 minutes)
    python benchmarks/speed.py --quick    # fewer repetitions, no docs update
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _oracle import oracle
from _report import pin_blas_threads, stamp, write_section

import fieldcal

CASES = {
    "N = 15, Δ ~ U{400..600} (Table 1)": {"n_poses": 15, "samples": (400, 600)},
    "N = 2000, Δ ~ U{20..40}": {"n_poses": 2000, "samples": (20, 40)},
}
TARGET_MS = {"N = 15, Δ ~ U{400..600} (Table 1)": 5.0, "N = 2000, Δ ~ U{20..40}": 100.0}


def timed(fn, reps: int, budget: float, warm: bool = True) -> tuple[float, int]:
    """Median seconds of ``fn`` over up to ``reps`` runs (fewer when over ``budget`` seconds)."""
    if warm:
        fn()  # warm-up: imports, caches
    times = []
    start = time.perf_counter()
    while len(times) < reps and (time.perf_counter() - start < budget or len(times) < min(3, reps)):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times)), len(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions, no docs update")
    parser.add_argument("--sessions", type=int, default=5, help="simulated sessions per case")
    args = parser.parse_args()
    reps, budget = (10, 2.0) if args.quick else (60, 20.0)
    sessions = 2 if args.quick else args.sessions
    plain = {"pose_noise": "none", "robust": False}
    methods: list[tuple[str, str, dict[str, object]]] = [
        ("mle", "mle", {}),
        ("mle, seed's model", "mle", plain),
    ] + [
        (m, m, {})
        for m in ("greedy", "ellipsoid")
        if importlib.util.find_spec(f"fieldcal.methods.{m}") is not None
    ]
    rows = []
    with pin_blas_threads(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for case, kw in CASES.items():
            big = kw["n_poses"] > 100
            results: dict[str, list[float]] = {}
            for seed in range(sessions):
                s = fieldcal.simulate("paper", seed=seed, **kw)
                stats = fieldcal.summarize(s.accel, s.mag)
                for label, method, options in methods:
                    slow = method == "greedy"  # tens of seconds per run: one run, first session
                    if slow and seed > 0:
                        continue
                    med, _ = timed(
                        lambda m=method, s=s, o=options: fieldcal.calibrate(
                            s.accel, s.mag, method=m, **o
                        ),
                        1 if slow else reps,
                        budget,
                        warm=not slow,
                    )
                    results.setdefault(label, []).append(med)
                med, _ = timed(
                    lambda st=stats, s=s, b=big: oracle(st, s.truth, sparse=b),
                    3 if big else reps,
                    budget,
                )
                results.setdefault("least_squares from truth", []).append(med)
                print(
                    case, seed, {k: f"{1e3 * v[-1]:.2f} ms" for k, v in results.items()}, flush=True
                )
            for name, values in results.items():
                rows.append((case, name, 1e3 * float(np.median(values))))
    lines = [
        "| case | method | median ms | × mle | target |",
        "|---|---|---|---|---|",
    ]
    for case, name, ms in rows:
        mle_ms = next(m for c, n, m in rows if c == case and n == "mle")
        target = f"≤ {TARGET_MS[case]:g} ms" if name == "mle" else ""
        lines.append(f"| {case} | {name} | {ms:.2f} | {ms / mle_ms:.1f} | {target} |")
    text = (
        '## Speed of method="mle"\n\n'
        + stamp("python benchmarks/speed.py" + (" --quick" if args.quick else ""))
        + f"\nMedian over repeated runs per session, then median over {sessions} simulated "
        "sessions; one BLAS thread (`threadpoolctl`). `mle`, `greedy`, `ellipsoid`: "
        "`fieldcal.calibrate` from raw samples (Eq. 5/7 included) to the full result with "
        "the default trust path (pose-level noise, robust fit, verdict, accuracy); "
        '`mle, seed\'s model`: the same call with `pose_noise="none", robust=False`, what '
        "fieldcal 0.1 computed; "
        "`least_squares from truth`: scipy on the pose statistics, started at the true "
        "parameters. `greedy` takes tens of seconds: a single run on the first session only.\n\n"
        + "\n".join(lines)
        + "\n"
    )
    print(text)
    if not args.quick:
        write_section("speed-mle", text)


if __name__ == "__main__":
    main()
