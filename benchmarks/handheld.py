"""Hand-held motion with the physics of a turn: fieldcal's continuous calibration on logs of the
independent test bed (``fieldcal.simulation.handheld``), against its truth (issue 33, item 3).

Each log is 60 s at 100 Hz of a MEMS board turned in the hand: the sensor 3–15 cm from the
turning point (so it feels ``ω̇ × r + ω × (ω × r)``), the hand's own bounded translation, turning
rates up to ``max_rate``, rests or none. The configurations cycle over the logs:

- peak rate 5, 10 or 20 rad/s;
- translation 0.3, 0.6 or 1.0 m/s² RMS;
- no rests, or three rests of 3 s;

(18 combinations; log ``k`` has seed ``k`` and combination ``k mod 18``). Each is calibrated by
``fieldcal.calibrate_log(columns, poses=...)`` (``continuous`` by default, the estimator every
hand-held log with a gyroscope reaches) and compared with the truth in fieldcal's gauge:

- *gain error*: per sensor, the largest entry of ``|K̂ − K|`` over the mean of ``K``'s diagonal,
  % (targets: accelerometer ≤ 1 %, magnetometer and gyroscope ≤ 0.5 %);
- *bias error in se*: per sensor, the largest ``|b̂ − b| / σ̂`` over the three axes (target ≤ 4);
- *RMS z* per parameter group over all logs (target 0.5–2) and *coverage* of the 95 %
  intervals (±1.96σ̂; 0.95 when honest);
- refusals and FAIL verdicts are counted and left out (a user would not use them).

    python benchmarks/handheld.py                    # 200 logs, writes the docs section
    python benchmarks/handheld.py --logs 36 --no-docs
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import pin_blas_threads, stamp, write_section
from continuous import GROUPS, NAMES, _values

import fieldcal
from fieldcal.errors import InputError
from fieldcal.simulation.handheld import simulate_handheld

CONFIGS = list(
    itertools.product((5.0, 10.0, 20.0), (0.3, 0.6, 1.0), (0, 3))
)  # (max_rate, translation_rms, rests)
TARGET_GAIN = {"accel": 1.0, "mag": 0.5, "gyro": 0.5}
TARGET_BIAS_SE = 4.0
SENSORS = ("accel", "mag", "gyro")


def one_log(k: int, poses: str, seconds: float) -> dict[str, object]:
    """Calibrate log ``k`` and compare it with the truth."""
    max_rate, translation, rests = CONFIGS[k % len(CONFIGS)]
    log = simulate_handheld(
        k, seconds=seconds, max_rate=max_rate, translation_rms=translation, rests=rests
    )
    label = f"seed {k} ({max_rate:g} rad/s, {translation:g} m/s², {rests} rests)"
    start = time.process_time()
    try:
        cal = fieldcal.calibrate_log(log.columns, poses=poses)
    except InputError as exc:
        return {"label": label, "left out": f"refused: {exc}"}
    cpu = time.process_time() - start
    if cal.verdict.level == "fail":
        return {"label": label, "left out": f"FAIL ({', '.join(cal.verdict.codes)})"}
    est, true = _values(cal), _values(log.truth)
    present = [n for n in NAMES if cal.covariance is not None and n in cal.covariance.names]
    sd = dict(zip(present, cal.covariance.stds(present), strict=True)) if present else {}
    out: dict[str, object] = {"label": label, "cpu": cpu, "config": (max_rate, translation, rests)}
    out["z"] = {n: (est[n] - true[n]) / sd[n] for n in present if sd[n] > 0}
    for s in SENSORS:
        K_true = np.asarray(getattr(log.truth, s).gain)
        K_est = np.asarray(getattr(cal, s).gain) if getattr(cal, s) is not None else None
        if K_est is None:
            continue
        scale = float(np.mean(np.abs(np.diag(K_true))))
        out[f"{s} gain %"] = 100 * float(np.max(np.abs(K_est - K_true))) / scale
        zb = [abs(out["z"][f"{s}.bias[{i}]"]) for i in range(3) if f"{s}.bias[{i}]" in out["z"]]
        out[f"{s} bias se"] = max(zb) if zb else np.nan
    arm = cal.options.get("lever_arm")  # the continuous fit's lever arm (issue 33), if any
    if isinstance(arm, dict) and "metres" in arm:
        error = np.asarray(arm["metres"]) - log.lever_arm_gauge
        out["lever arm error cm"] = 100 * float(np.linalg.norm(error))
        sd = np.asarray(arm.get("std_m", [np.nan] * 3), dtype=float)
        out["z"].update({f"lever_arm_m[{i}]": error[i] / sd[i] for i in range(3) if sd[i] > 0})
    return out


def summarise(results: list[dict[str, object]]) -> list[str]:
    kept = [r for r in results if "left out" not in r]
    lines = [
        f"{len(kept)} of {len(results)} logs calibrated "
        f"(median CPU per fit {np.median([r['cpu'] for r in kept]):.2f} s)."
        if kept
        else f"0 of {len(results)} logs calibrated.",
        "",
        "| sensor | gain error % median | 95th pct | max | within target | "
        "bias |error|/se median | 95th pct | within 4 se |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for s in SENSORS:
        g = np.array([r[f"{s} gain %"] for r in kept if f"{s} gain %" in r])
        b = np.array([r[f"{s} bias se"] for r in kept if f"{s} bias se" in r])
        if not len(g):
            continue
        lines.append(
            f"| {s} (target {TARGET_GAIN[s]:g} %) | {np.median(g):.3f} | "
            f"{np.percentile(g, 95):.3f} | {g.max():.3f} | {np.mean(g <= TARGET_GAIN[s]):.0%} | "
            f"{np.median(b):.2f} | {np.percentile(b, 95):.2f} | "
            f"{np.mean(b <= TARGET_BIAS_SE):.0%} |"
        )
    lines += ["", "| group | RMS z | coverage of 95 % intervals |", "|---|---:|---:|"]
    everything: list[float] = []
    groups = {**GROUPS, "lever arm": [f"lever_arm_m[{i}]" for i in range(3)]}
    for group, names in groups.items():
        z = np.array([r["z"][n] for r in kept for n in names if n in r["z"]])  # type: ignore[index]
        if len(z):
            everything += list(z)
            lines.append(
                f"| {group} | {np.sqrt(np.mean(z**2)):.2f} | {np.mean(np.abs(z) < 1.96):.3f} |"
            )
    if everything:
        z = np.asarray(everything)
        lines.append(f"| all | {np.sqrt(np.mean(z**2)):.2f} | {np.mean(np.abs(z) < 1.96):.3f} |")
    lines += ["", *per_config(kept), ""]
    arms = [r["lever arm error cm"] for r in kept if "lever arm error cm" in r]
    if arms:
        lines += [f"Lever arm error: median {np.median(arms):.2f} cm, max {max(arms):.2f} cm.", ""]
    left = [r for r in results if "left out" in r]
    lines += [f"Left out (refused or FAIL): {len(left)}."]
    lines += [f"- {r['label']}: {r['left out']}" for r in left]
    return [*lines, ""]


def per_config(kept: list[dict[str, object]]) -> list[str]:
    """RMS z of all parameters and the worst gain error, per peak rate and per rests."""
    lines = [
        "| peak rate | rests | logs | RMS z (all) | accel gain % (max) | mag gain % (max) "
        "| gyro gain % (max) |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for rate in sorted({c[0] for c in CONFIGS}):
        for rests in sorted({c[2] for c in CONFIGS}):
            rs = [r for r in kept if r["config"][0] == rate and r["config"][2] == rests]  # type: ignore[index]
            if not rs:
                continue
            z = np.concatenate([list(r["z"].values()) for r in rs])  # type: ignore[union-attr]
            worst = [max(r.get(f"{s} gain %", np.nan) for r in rs) for s in SENSORS]  # type: ignore[type-var]
            lines.append(
                f"| {rate:g} rad/s | {rests} | {len(rs)} | {np.sqrt(np.mean(z**2)):.2f} | "
                + " | ".join(f"{w:.2f}" for w in worst)
                + " |"
            )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", type=int, default=200)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--poses", default="continuous", choices=["continuous", "auto"])
    parser.add_argument("--no-docs", action="store_true")
    parser.add_argument("--quiet", action="store_true", help="No per-log progress on stderr.")
    args = parser.parse_args()
    command = "python benchmarks/handheld.py" + "".join(
        f" --{k} {v}"
        for k, v in vars(args).items()
        if k not in ("no_docs", "quiet") and v != parser.get_default(k)
    )
    results = []
    with pin_blas_threads():
        for k in range(args.logs):
            results.append(one_log(k, args.poses, args.seconds))
            if not args.quiet:
                r = results[-1]
                note = r.get("left out") or ", ".join(
                    f"{s} {r[f'{s} gain %']:.2f} %" for s in SENSORS if f"{s} gain %" in r
                )
                print(f"{k + 1}/{args.logs} {r['label']}: {note}", file=sys.stderr, flush=True)
    lines = ["## Hand-held test bed (issue 33)", "", stamp(command), ""]
    lines += [
        f"{args.logs} simulated {args.seconds:g} s logs at 100 Hz "
        "(`fieldcal.simulation.handheld`): lever arm 3–15 cm, peak rate 5/10/20 rad/s, hand "
        "translation 0.3/0.6/1.0 m/s² RMS, no rests or three; calibrated by "
        f'`fieldcal.calibrate_log(columns, poses="{args.poses}")`. Gain error: largest entry '
        "of |K̂ − K| over K's mean diagonal; bias error: largest |b̂ − b|/σ̂ of the three axes.",
        "",
    ]
    lines += summarise(results)
    print("\n".join(lines))
    if not args.no_docs:
        write_section("handheld", "\n".join(lines))


if __name__ == "__main__":
    main()
