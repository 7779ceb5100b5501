"""Accuracy of method="mle" against an oracle, over Table 1 and harder simulated settings.

For every session the oracle is ``scipy.optimize.least_squares`` on the same likelihood (Eq. 8,
same pose statistics) started at the true parameters: the best any method can do on that data.
Reported per setting: δ/δ_oracle (δ = the two sensors' Eq. 19 errors combined in quadrature),
the failure share (δ > 1.5 δ_oracle), how often fieldcal's J is at or below the oracle's, and
the certificate's p-values (uniform at the ML optimum) — for the solver on the seed paper's
likelihood (``pose_noise="none", robust=False``), and for the default call (pose-level noise
estimated, robust fit), whose δ should stay at the oracle on these clean sessions.

    python benchmarks/accuracy.py                 # 1050 sessions (about 5 minutes)
    python benchmarks/accuracy.py --quick         # 70 sessions, no docs update
    python benchmarks/accuracy.py --sessions 300  # per-setting count = 300 / 7
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _oracle import oracle
from _report import pin_blas_threads, stamp, write_section

import fieldcal
from fieldcal.metrics import reconstruction_error

SETTINGS = {
    "paper": ("Table 1: N = 15, Δ ~ U{400..600}, gains ±10 %, biases ±1", {}),
    "few_poses": ("N = 8-10 poses of 30-60 samples", {}),
    "soft_iron": ("gains ±35 % (soft iron, cross-axis), biases ±3", {}),
    "steep_dip": ("dip 75-85°", {}),
    "handheld": ("hand-held: tilts mostly < 60°, two upside down", {}),
    "noisy": ("noise α ~ U[0.01, 0.05] (Eq. 18)", {}),
    "hard": ("all of the above at once, N = 10", {}),
}


def delta(truth, cal_means, counts):
    ta, tm = truth.predicted_means()
    return float(
        np.hypot(
            reconstruction_error(ta, cal_means[0], truth.accel.noise_cov, counts),
            reconstruction_error(tm, cal_means[1], truth.mag.noise_cov, counts),
        )
    )


def run_setting(preset: str, sessions: int, seed0: int) -> dict:
    ratios, below, pvals, iters, times = [], [], [], [], []
    default_ratios, default_times, q_positive, rejected, verdicts = [], [], [], [], []
    for k in range(sessions):
        seed = seed0 + k
        n_poses = 8 + seed % 3 if preset == "few_poses" else None
        s = fieldcal.simulate(preset, seed=seed, n_poses=n_poses)
        stats = fieldcal.summarize(s.accel, s.mag)
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cal = fieldcal.calibrate(s.accel, s.mag, pose_noise="none", robust=False)
            times.append(time.perf_counter() - t)
            t = time.perf_counter()
            default = fieldcal.calibrate(s.accel, s.mag)
            default_times.append(time.perf_counter() - t)
        pa, pm, res = oracle(stats, s.truth)
        d_or = delta(s.truth, (pa, pm), s.counts)
        ratios.append(delta(s.truth, cal.predicted_means(), s.counts) / d_or)
        if not default.rejected:  # δ is over all poses: compare when every pose was kept
            default_ratios.append(delta(s.truth, default.predicted_means(), s.counts) / d_or)
        q_positive.append(default.accel.pose_noise_std > 0 or default.mag.pose_noise_std > 0)
        rejected.append(len(default.rejected) > 0)
        verdicts.append(default.verdict.level)
        below.append(cal.cost <= 2 * res.cost * (1 + 1e-7) + 1e-9)
        pvals.append(cal.diagnostics.p_value)
        iters.append(cal.iterations)
    r = np.array(ratios)
    return {
        "sessions": sessions,
        "median": float(np.median(r)),
        "p99": float(np.quantile(r, 0.99)),
        "max": float(r.max()),
        "fail": float(np.mean(r > 1.5)),
        "within1": float(np.mean(r <= 1.01)),
        "below": float(np.mean(below)),
        "p_small": float(np.mean(np.array(pvals) < 0.05)),
        "iters": float(np.median(iters)),
        "ms": 1e3 * float(np.median(times)),
        "d_median": float(np.median(default_ratios)),
        "d_max": float(np.max(default_ratios)),
        "d_fail": float(np.mean(np.array(default_ratios) > 1.5)),
        "q_positive": float(np.mean(q_positive)),
        "rejected": float(np.mean(rejected)),
        "verdicts": {v: verdicts.count(v) for v in ("pass", "warn", "fail")},
        "d_ms": 1e3 * float(np.median(default_times)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=1050, help="total sessions (all settings)")
    parser.add_argument("--quick", action="store_true", help="70 sessions, no docs update")
    args = parser.parse_args()
    total = 70 if args.quick else args.sessions
    per = max(1, total // len(SETTINGS))
    rows = []
    with pin_blas_threads():
        for i, (preset, (label, _)) in enumerate(SETTINGS.items()):
            res = run_setting(preset, per, 10_000 * (i + 1))
            rows.append((preset, label, res))
            print(
                f"{preset:10s} n={res['sessions']} median={res['median']:.6f} "
                f"max={res['max']:.4f} fail={res['fail']:.3%} J<=oracle={res['below']:.1%}",
                flush=True,
            )
    lines = [
        "| setting | sessions | median δ/δ_oracle | 99th pct | max | failures (δ > 1.5 δ_oracle) "
        "| δ within 1 % | J ≤ oracle's J | p < 0.05 | median LM iterations | median ms |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    default_lines = [
        "| setting | median δ/δ_oracle | max | failures | q > 0 | any pose dropped "
        "| verdicts pass / warn / fail | median ms |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for preset, _, r in rows:
        v = r["verdicts"]
        default_lines.append(
            f"| `{preset}` | {r['d_median']:.5f} | {r['d_max']:.4f} | {r['d_fail']:.1%} | "
            f"{r['q_positive']:.0%} | {r['rejected']:.1%} | {v['pass']} / {v['warn']} / "
            f"{v['fail']} | {r['d_ms']:.1f} |"
        )
    allr = {k: [] for k in ("fail", "sessions")}
    for preset, label, r in rows:
        lines.append(
            f"| `{preset}`: {label} | {r['sessions']} | {r['median']:.5f} | {r['p99']:.4f} | "
            f"{r['max']:.4f} | {r['fail']:.1%} | {r['within1']:.1%} | {r['below']:.1%} | "
            f"{r['p_small']:.1%} | {r['iters']:.0f} | {r['ms']:.1f} |"
        )
        allr["fail"].append(r["fail"] * r["sessions"])
        allr["sessions"].append(r["sessions"])
    n_all = int(sum(allr["sessions"]))
    n_fail = round(sum(allr["fail"]))
    text = (
        '## Accuracy of method="mle" against the oracle\n\n'
        + stamp("python benchmarks/accuracy.py" + (f" --sessions {total}" if total != 1050 else ""))
        + "\nOracle: `scipy.optimize.least_squares` (trf, finite differences) on the same "
        "likelihood started at the true parameters. δ: the two sensors' Eq. 19 errors combined "
        "in quadrature. 'J ≤ oracle's J': fieldcal's optimum is at least as good as the one "
        "found from the truth (δ/δ_oracle > 1 with J below the oracle's is the data's optimum "
        "lying further from the truth, not a failure of the solver). Median ms: "
        "`fieldcal.calibrate` from raw samples, one BLAS thread.\n\n"
        '**The solver on the seed paper\'s likelihood** (`pose_noise="none", robust=False`: '
        "Eq. 7's noise only, every pose kept; the oracle's likelihood):\n\n"
        + "\n".join(lines)
        + f"\n\nAll settings: {n_fail} failures in {n_all} sessions.\n\n"
        "**The default call** (pose-level noise estimated, robust fit) on the same clean "
        "sessions: δ/δ_oracle over the sessions where no pose was dropped (δ is over all "
        "poses); 'q > 0': sessions where either sensor's pose-level noise came out above zero "
        "(about half, as for any variance estimate at its boundary); 'any pose dropped': false "
        "alarms (1 % family-wise by design).\n\n" + "\n".join(default_lines) + "\n"
    )
    print(text)
    if not args.quick:
        write_section("accuracy-mle", text)


if __name__ == "__main__":
    main()
