"""Reproduce the seed paper's Monte Carlo experiment (Miranda & Ferreira, Table 1, Fig. 1-3).

For each run (seed ``s``): ``fieldcal.simulate("paper", seed=s)`` (Table 1, N = 15) is
calibrated by every available method through ``fieldcal.calibrate``; the greedy method's δ
(Eq. 19) versus γ comes from one run with γ = 1e-6 and a per-iteration history (the algorithm
is deterministic and only its stopping rule depends on γ, so the first iteration ``k`` with
``J[k-1] − J[k] <= γ`` is exactly where a run with that γ stops). δ versus N follows Sec. 6.2:
one N = 30 session per run, the first ``n`` poses re-summarised for N = n.

A run is "stuck in a poor local minimum" when the greedy cost exceeds the oracle's (least
squares on Eq. 8 started at the truth, ``benchmarks/_oracle.py``) by more than the 99 %
quantile of χ²(3N + 22): the greedy fit is then significantly worse than the true parameters
themselves would be. Runs that hit the iteration cap are counted separately.

    nice -n 5 python benchmarks/paper_montecarlo.py            # full: 100 runs
    python benchmarks/paper_montecarlo.py --quick               # smoke run
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy import stats as sps

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _oracle import oracle
from _report import FIGURES, pin_blas_threads, stamp, write_section

import fieldcal
from fieldcal.methods.greedy import run_greedy
from fieldcal.metrics import reconstruction_error

GAMMAS = (10.0, 1.0, 1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6)
TABLE1_GAMMA = 1e-4


def deltas(truth, counts, predicted, n=None):
    """δ_a, δ_m of Eq. 19 against the truth's first ``n`` poses."""
    ta, tm = truth.predicted_means()
    n = len(ta) if n is None else n
    return (
        reconstruction_error(ta[:n], predicted[0], truth.accel.noise_cov, counts[:n]),
        reconstruction_error(tm[:n], predicted[1], truth.mag.noise_cov, counts[:n]),
    )


def stop_index(costs, gamma):
    """First k >= 1 with J[k-1] − J[k] <= γ (Sec. 5, step 7), or the last k (cap reached)."""
    drops = costs[:-1] - costs[1:]
    hit = np.flatnonzero(drops <= gamma)
    return (int(hit[0]) + 1, True) if hit.size else (len(costs) - 1, False)


def stuck(cost, oracle_cost, n_poses):
    return cost - oracle_cost > sps.chi2.ppf(0.99, 3 * n_poses + 22)


def greedy_history(stats, cap):
    """One γ = 1e-6 run; the history (J[k], state, seconds) gives every larger γ exactly."""
    history = []
    result = run_greedy(
        stats, 1e-6, cap, callback=lambda k, J, state, t: history.append((J, state, t))
    )
    return result, history


def table1_run(seed, methods, cap):
    session = fieldcal.simulate("paper", seed=seed)
    counts = session.counts
    t0 = time.perf_counter()
    stats = fieldcal.summarize(session.accel, session.mag)
    t_summary = time.perf_counter() - t0
    row = {"seed": seed}
    result, history = greedy_history(stats, cap)
    costs = np.array([h[0] for h in history])
    row["gamma"] = {}
    for gamma in GAMMAS:
        k, converged = stop_index(costs, gamma)
        J, state, seconds = history[k]
        row["gamma"][gamma] = {
            "delta": deltas(session.truth, counts, state.predicted_means()),
            "seconds": seconds + t_summary,
            "iterations": k,
            "converged": converged,
            "cost": J,
        }
    pa, pm, res = oracle(stats, session.truth)
    row["oracle"] = {"delta": deltas(session.truth, counts, (pa, pm)), "cost": 2 * res.cost}
    row["cost_increases"] = result.cost_increases
    row["sign_fixes"] = result.sign_fixes
    row["methods"] = {}
    for method in methods:
        if method == "greedy":
            g = row["gamma"][TABLE1_GAMMA]
            row["methods"]["greedy"] = {"delta": g["delta"], "seconds": g["seconds"], "ok": True}
            continue
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                cal = fieldcal.calibrate(session.accel, session.mag, method=method)
            seconds = time.perf_counter() - t0
            row["methods"][method] = {
                "delta": deltas(session.truth, counts, cal.predicted_means()),
                "seconds": seconds,
                "ok": bool(cal.converged),
            }
        except Exception as exc:  # a failing method is a result, not a crash of the benchmark
            row["methods"][method] = {"delta": (np.nan, np.nan), "seconds": np.nan, "ok": False}
            print(f"  {method} failed on seed {seed}: {exc}", file=sys.stderr)
    return row


def n_sweep_run(seed, n_values, cap):
    session = fieldcal.simulate("paper", seed=seed, n_poses=max(n_values))
    rows = {}
    for n in n_values:
        t0 = time.perf_counter()
        stats = fieldcal.summarize(session.accel[:n], session.mag[:n])
        result = run_greedy(stats, TABLE1_GAMMA, cap)
        seconds = time.perf_counter() - t0
        pa, pm, res = oracle(stats, _first(session.truth, n))
        rows[n] = {
            "delta": deltas(session.truth, session.counts, result.state.predicted_means(), n),
            "oracle_delta": deltas(session.truth, session.counts, (pa, pm), n),
            "seconds": seconds,
            "iterations": result.iterations,
            "converged": result.converged,
            "stuck": stuck(result.costs[-1], 2 * res.cost, n),
        }
    return rows


def _first(truth, n):
    """The truth restricted to its first n poses (what the oracle starts from)."""
    import dataclasses

    return dataclasses.replace(truth, rotations=truth.rotations[:n], poses=())


def available(methods):
    out, notes = [], []
    for m in methods:
        if importlib.util.find_spec(f"fieldcal.methods.{m}") is None:
            notes.append(f"`{m}` skipped: `fieldcal/methods/{m}.py` does not exist yet.")
        else:
            out.append(m)
    return out, notes


def q(values, p):
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    return float(np.percentile(values, p)) if values.size else float("nan")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=100, help="Monte Carlo runs (Table 1: 100)")
    parser.add_argument("--sweep-runs", type=int, default=None, help="runs for the N sweep")
    parser.add_argument("--n-values", default="6,7,8,10,12,15,20,25,30")
    parser.add_argument("--methods", default="greedy,ellipsoid,mle")
    parser.add_argument("--max-iterations", type=int, default=1000, help="greedy iteration cap")
    parser.add_argument("--quick", action="store_true", help="smoke run: 3 runs, 3 values of N")
    parser.add_argument("--no-write", action="store_true", help="print, do not touch docs/")
    args = parser.parse_args(argv)
    if args.quick:
        args.runs, args.sweep_runs, args.n_values, args.max_iterations = 3, 2, "6,15,30", 300
    sweep_runs = args.runs if args.sweep_runs is None else args.sweep_runs
    n_values = [int(v) for v in args.n_values.split(",")]
    methods, notes = available([m.strip() for m in args.methods.split(",") if m.strip()])
    command = "python benchmarks/paper_montecarlo.py " + " ".join(
        sys.argv[1:] if argv is None else argv
    )
    limiter = pin_blas_threads()
    start = time.perf_counter()
    table = []
    for seed in range(args.runs):
        table.append(table1_run(seed, methods, args.max_iterations))
        print(f"table1 run {seed}: {time.perf_counter() - start:.0f} s", file=sys.stderr)
    sweep = []
    for seed in range(sweep_runs):
        sweep.append(n_sweep_run(seed, n_values, args.max_iterations))
        print(f"N sweep run {seed}: {time.perf_counter() - start:.0f} s", file=sys.stderr)
    wall = time.perf_counter() - start
    limiter.restore_original_limits()
    markdown = report(stamp(command.strip()), table, sweep, n_values, methods, notes, args, wall)
    figures = make_figures(table, sweep, n_values)
    if figures:
        markdown += "\n" + "\n".join(f"![{name}](figures/{name})" for name in figures) + "\n"
    print(markdown)
    if not args.no_write:
        write_section("paper_montecarlo", markdown)


def report(header, table, sweep, n_values, methods, notes, args, wall):
    runs, cap = len(table), args.max_iterations
    floor = np.sqrt(3 * 15 / np.mean([500 * 15]))
    lines = [
        "## Paper reproduction: Monte Carlo of Table 1 (Miranda & Ferreira)",
        "",
        header,
        f"{runs} runs (seeds 0..{runs - 1}, `fieldcal.simulate('paper', seed=s)`), N = 15, "
        f"γ = 1e-4; greedy iteration cap {cap}; N sweep over {len(sweep)} runs "
        f"(`simulate('paper', seed=s, n_poses={max(n_values)})`, first n poses re-summarised). "
        f"Total wall time {wall / 60:.1f} min, one process, BLAS pinned to one thread. "
        f"δ (Eq. 19) is in sample standard deviations; averaging alone gives δ ≈ "
        f"√(3N/ΣΔ) ≈ {floor:.3f}.",
        "",
        *[f"- {n}" for n in notes],
        "",
        "### All methods, Table 1 setting (N = 15, γ = 1e-4)",
        "",
        "| method | median δ_a | 90th pct δ_a | median δ_m | 90th pct δ_m | median time (s) | "
        "90th pct time (s) | converged |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for m in methods:
        rows = [r["methods"][m] for r in table]
        da = [r["delta"][0] for r in rows]
        dm = [r["delta"][1] for r in rows]
        t = [r["seconds"] for r in rows]
        ok = (
            sum(r["ok"] for r in rows)
            if m != "greedy"
            else sum(r["gamma"][TABLE1_GAMMA]["converged"] for r in table)
        )
        lines.append(
            f"| {m} | {q(da, 50):.3f} | {q(da, 90):.3f} | {q(dm, 50):.3f} | {q(dm, 90):.3f} | "
            f"{q(t, 50):.3f} | {q(t, 90):.3f} | {ok}/{runs} |"
        )
    oa = [r["oracle"]["delta"][0] for r in table]
    om = [r["oracle"]["delta"][1] for r in table]
    lines += [
        f"| oracle (least squares from the truth) | {q(oa, 50):.3f} | {q(oa, 90):.3f} | "
        f"{q(om, 50):.3f} | {q(om, 90):.3f} | | | |",
        "",
        "Greedy times are the cumulative time at the stopping iteration of the γ = 1e-6 run "
        "(plus `summarize`), which is what a run with γ = 1e-4 takes; `converged` for greedy "
        "counts runs that met the γ rule before the cap.",
        "",
        "### Greedy: δ and time versus γ (the paper's Fig. 1 and Fig. 3a)",
        "",
        "| γ | median δ_a | 90th pct δ_a | median δ_m | 90th pct δ_m | median iterations | "
        "median time (s) | 90th pct time (s) | capped |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for gamma in GAMMAS:
        rows = [r["gamma"][gamma] for r in table]
        da = [r["delta"][0] for r in rows]
        dm = [r["delta"][1] for r in rows]
        lines.append(
            f"| {gamma:g} | {q(da, 50):.3f} | {q(da, 90):.3f} | {q(dm, 50):.3f} | "
            f"{q(dm, 90):.3f} | {q([r['iterations'] for r in rows], 50):.0f} | "
            f"{q([r['seconds'] for r in rows], 50):.3f} | {q([r['seconds'] for r in rows], 90):.3f}"
            f" | {sum(not r['converged'] for r in rows)}/{runs} |"
        )
    claim = [
        gamma
        for gamma in GAMMAS
        if gamma <= 1e-2
        and max(
            q([r["gamma"][gamma]["delta"][0] for r in table], 50),
            q([r["gamma"][gamma]["delta"][1] for r in table], 50),
        )
        >= 0.1
    ]
    lines += [
        "",
        "**Paper's claim (median δ < 0.1 at N = 15 for γ <= 1e-2):** "
        + ("holds for every γ <= 1e-2." if not claim else f"fails for γ = {claim}."),
        "",
        "### Greedy: δ and time versus N (the paper's Fig. 2 and Fig. 3b), γ = 1e-4",
        "",
        "N = 6 and 7 have 3N − 22 <= 0 (more unknowns than readings); `fieldcal.calibrate` "
        "refuses them, so the benchmark calls the internal `run_greedy` for every N.",
        "",
        "| N | median δ_a | 90th pct δ_a | median δ_m | 90th pct δ_m | oracle median δ_a | "
        "oracle median δ_m | median time (s) | capped | stuck |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n in n_values:
        rows = [r[n] for r in sweep]
        da = [r["delta"][0] for r in rows]
        dm = [r["delta"][1] for r in rows]
        lines.append(
            f"| {n} | {q(da, 50):.3f} | {q(da, 90):.3f} | {q(dm, 50):.3f} | {q(dm, 90):.3f} | "
            f"{q([r['oracle_delta'][0] for r in rows], 50):.3f} | "
            f"{q([r['oracle_delta'][1] for r in rows], 50):.3f} | "
            f"{q([r['seconds'] for r in rows], 50):.3f} | "
            f"{sum(not r['converged'] for r in rows)}/{len(rows)} | "
            f"{sum(r['stuck'] for r in rows)}/{len(rows)} |"
        )
    g = [r["gamma"][TABLE1_GAMMA] for r in table]
    is_stuck = [stuck(x["cost"], r["oracle"]["cost"], 15) for x, r in zip(g, table, strict=True)]
    stuck_conv = sum(s and x["converged"] for s, x in zip(is_stuck, g, strict=True))
    stuck_cap = sum(s and not x["converged"] for s, x in zip(is_stuck, g, strict=True))
    same = sum(x["cost"] - r["oracle"]["cost"] <= 1.0 for x, r in zip(g, table, strict=True))
    lines += [
        "",
        "### Poor local minima (N = 15, γ = 1e-4)",
        "",
        f"Stuck (J_greedy − J_oracle > χ²₀.₉₉(3N + 22) = {sps.chi2.ppf(0.99, 67):.1f}): "
        f"{sum(is_stuck)}/{runs} runs, of which {stuck_conv} stopped by the γ rule (a poor "
        f"minimum or a plateau where J falls by less than γ per iteration) and {stuck_cap} "
        f"were still descending at the cap of {cap} iterations. Within 1 χ² unit of the "
        f"oracle's cost: {same}/{runs}. Runs with a sign fix (Sec. 4.2): "
        f"{sum(r['sign_fixes'] > 0 for r in table)}/{runs}; runs where one raised J: "
        f"{sum(r['cost_increases'] > 0 for r in table)}/{runs}.",
        "",
    ]
    return "\n".join(lines)


def make_figures(table, sweep, n_values):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return []
    FIGURES.mkdir(parents=True, exist_ok=True)
    names = []

    def band(ax, x, rows, key, label):
        for s, color in ((0, "C0"), (1, "C1")):
            values = [[r[key][s] for r in col] for col in rows]
            ax.plot(x, [q(v, 50) for v in values], "o-", color=color, label=f"median {label[s]}")
            ax.plot(x, [q(v, 90) for v in values], "--", color=color, label=f"90th pct {label[s]}")

    fig, ax = plt.subplots(figsize=(6, 4))
    band(ax, GAMMAS, [[r["gamma"][g] for r in table] for g in GAMMAS], "delta", ("δ_a", "δ_m"))
    ax.set(xscale="log", yscale="log", xlabel="γ", ylabel="δ (Eq. 19)", title="Fig. 1: δ vs γ")
    ax.invert_xaxis()
    ax.legend()
    names.append(_save(fig, "paper_fig1_delta_vs_gamma.png"))

    fig, ax = plt.subplots(figsize=(6, 4))
    band(ax, n_values, [[r[n] for r in sweep] for n in n_values], "delta", ("δ_a", "δ_m"))
    ax.set(yscale="log", xlabel="N", ylabel="δ (Eq. 19)", title="Fig. 2: δ vs N (γ = 1e-4)")
    ax.legend()
    names.append(_save(fig, "paper_fig2_delta_vs_n.png"))

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    t_gamma = [[r["gamma"][g]["seconds"] for r in table] for g in GAMMAS]
    a1.plot(GAMMAS, [q(t, 50) for t in t_gamma], "o-", label="median")
    a1.plot(GAMMAS, [q(t, 90) for t in t_gamma], "--", label="90th pct")
    a1.set(xscale="log", yscale="log", xlabel="γ", ylabel="time (s)", title="Fig. 3a")
    a1.invert_xaxis()
    a1.legend()
    t_n = [[r[n]["seconds"] for r in sweep] for n in n_values]
    a2.plot(n_values, [q(t, 50) for t in t_n], "o-", label="median")
    a2.plot(n_values, [q(t, 90) for t in t_n], "--", label="90th pct")
    a2.set(yscale="log", xlabel="N", ylabel="time (s)", title="Fig. 3b (γ = 1e-4)")
    a2.legend()
    names.append(_save(fig, "paper_fig3_time.png"))
    return names


def _save(fig, name):
    fig.tight_layout()
    fig.savefig(FIGURES / name, dpi=100)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return name


if __name__ == "__main__":
    main()
