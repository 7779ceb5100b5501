"""Why is fieldcal's vertical ~1° from the vendor's on BROAD? Experiments on the candidate
causes (issue 33, items 1–2).

Each variant refits a BROAD trial (every ``--step``-th sample) in the default mode and measures
it as ``broad_mocap.py`` does: the tilt beyond the vendor's calibration against the motion
capture ("measured"), the predicted tilt, and "Δ vendor", the RMS angle between fieldcal's and
the vendor's verticals on the quasi-static samples (no motion capture in it). The variants
change one thing each:

- ``mag ×k``: the magnetometer's per-stretch variances multiplied by ``k`` — candidate (a), the
  lab's non-uniform field pulling the trajectory's tilt during motion (the magnetometer's
  direction error is absorbed by the rotation, so its residual does not show it);
- ``accel moving ×k``: the accelerometer's variances multiplied by ``k`` in the stretches where
  it is more than :data:`MOVING` times its quietest tenth's — its gravity taken from the
  quiet stretches only (with ``mag ×k``: and the magnetometer kept out of the tilt);
- ``accel +k``: the accelerometer read ``k`` samples later (its reading at ``t_{j+k}`` taken as
  the force at ``t_j``) — candidate (c), a delay between accelerometer and gyroscope;
- ``allowances``: the estimator's experimental weights (Eq. C6a–C6b,
  ``fit_continuous(allowances=True)``, :mod:`fieldcal.methods.continuous.motion_noise`);
- ``batch 20 s``: the sandwich's long-run covariance over 20-s batches instead of 4 s — do the
  error bars grow when the residuals' correlation is taken over longer times?

The magnetometer and batch variants replace the estimator's weights or batch length in this
process only (:func:`fieldcal.methods.continuous.rounds.weights_at`, ``BATCH``): they are
experiments, not options.

    python benchmarks/broad_causes.py               # 01, 04, 06 at --step 3 (95 Hz)
    python benchmarks/broad_causes.py --trials 01 --no-docs
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import pin_blas_threads, stamp, write_section
from broad_mocap import TRIALS, calibrate, load, trial_row

import fieldcal.methods.continuous.rounds as rounds

#: name → (magnetometer variance factor, moving stretches' accelerometer variance factor,
#: accelerometer shift in samples, batch seconds)
VARIANTS: dict[str, tuple[float, float, int, float]] = {
    "as released": (1.0, 1.0, 0, rounds.BATCH),
    "mag ×10": (10.0, 1.0, 0, rounds.BATCH),
    "mag ×100": (100.0, 1.0, 0, rounds.BATCH),
    "accel moving ×100": (1.0, 100.0, 0, rounds.BATCH),
    "accel moving ×100, mag ×100": (100.0, 100.0, 0, rounds.BATCH),
    "accel +3": (1.0, 1.0, 3, rounds.BATCH),
    "batch 20 s": (1.0, 1.0, 0, 20.0),
    # the estimator's own experimental weights, Eq. C6a–C6b (fit_continuous(allowances=True))
    "allowances (C6a–C6b)": (1.0, 1.0, 0, rounds.BATCH),
}
ALLOWANCES = "allowances (C6a–C6b)"
#: A stretch is "moving" when its accelerometer variance exceeds this many times the quietest
#: tenth's (the white noise).
MOVING = 4.0


@contextmanager
def patched(mag_factor: float, moving: float, batch: float, allow: bool = False) -> Iterator[None]:
    """The estimator with its magnetometer's variances times ``mag_factor``, the moving
    stretches' accelerometer variances times ``moving`` and its sandwich's batch ``batch``
    seconds, restored afterwards."""
    original: Callable[..., Any] = rounds.weights_at
    original_batch = rounds.BATCH

    def weights(*args: Any, **kwargs: Any) -> Any:
        if allow:
            args = (*args[:5], True, *args[6:])
        w, levels = original(*args, **kwargs)
        w.mag = w.mag / mag_factor
        variance = 1.0 / w.accel
        quiet = np.quantile(variance, 0.1)
        w.accel = np.where(variance > MOVING * quiet, w.accel / moving, w.accel)
        return w, levels

    rounds.weights_at = weights  # type: ignore[assignment]
    rounds.BATCH = batch
    try:
        yield
    finally:
        rounds.weights_at = original  # type: ignore[assignment]
        rounds.BATCH = original_batch


def run(trial: str, step: int, variant: str) -> dict[str, object] | None:
    loaded = load(trial, step)
    if loaded is None:
        return None
    cols, quat = loaded
    mag_factor, moving, shift, batch = VARIANTS[variant]
    fitted = dict(cols)
    if shift:
        for axis in "xyz":  # a reading k samples later stands for this sample's force
            fitted["a" + axis] = np.roll(cols["a" + axis], -shift)
    start = time.process_time()
    with patched(mag_factor, moving, batch, variant == ALLOWANCES):
        cal = calibrate(fitted)
    cpu = time.process_time() - start
    if isinstance(cal, str):
        return {"trial": trial, "variant": variant, "refused": cal}
    row = trial_row(trial, cal, cols, quat)  # measured on the readings as logged
    scaled = cal.with_field_magnitudes(9.81, None)
    lever = cal.options.get("lever_arm", {}).get("metres", [np.nan] * 3)
    return {
        "trial": trial,
        "variant": variant,
        "tilt": row["tilt"],
        "heading": row["heading"],
        "bias": np.asarray(scaled.accel.bias) if scaled.accel is not None else np.full(3, np.nan),
        "lever_cm": 100 * float(np.linalg.norm(lever)),
        "cpu": cpu,
    }


def table(rows: list[dict[str, object]]) -> list[str]:
    lines = [
        "| trial | variant | tilt measured | tilt predicted | Δ vendor tilt | heading Δ vendor "
        "| accel bias (m/s²) | lever arm (cm) |",
        "|---|---|---:|---:|---:|---:|---|---:|",
    ]
    for r in rows:
        if "refused" in r:
            lines.append(f"| {r['trial']} | {r['variant']} | {r['refused']} ||||||")
            continue
        t, h = r["tilt"], r["heading"]
        assert isinstance(t, dict) and isinstance(h, dict)
        bias = ", ".join(f"{x:+.3f}" for x in np.asarray(r["bias"]))
        lines.append(
            f"| {r['trial']} | {r['variant']} | {t['measured']:.2f} | {t['predicted']:.2f} "
            f"| {t['delta']:.2f} | {h['delta']:.2f} | {bias} | {r['lever_cm']:.1f} |"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", nargs="+", default=["01", "04", "06"], choices=list(TRIALS))
    parser.add_argument("--step", type=int, default=3)
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--no-docs", action="store_true")
    args = parser.parse_args()
    rows = []
    with pin_blas_threads():
        for trial in args.trials:
            for variant in args.variants:
                row = run(trial, args.step, variant)
                if row is not None:
                    rows.append(row)
                    print(f"{trial} {variant}: done", file=sys.stderr, flush=True)
    command = f"python benchmarks/broad_causes.py --trials {' '.join(args.trials)}"
    command += f" --step {args.step}"
    if args.variants != list(VARIANTS):
        command += " --variants " + " ".join(f"'{v}'" for v in args.variants)
    lines = [
        "## BROAD: the causes of the vertical's error (issue 33)",
        "",
        stamp(command),
        "",
        *table(rows),
        "",
    ]
    print("\n".join(lines))
    if not args.no_docs:
        write_section("broad_causes", "\n".join(lines))


if __name__ == "__main__":
    main()
