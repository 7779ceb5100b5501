"""Slow continuous logs without a gyroscope: ``poses="samples"`` and ``poses="windows"``.

A board turned slowly by hand with no rests (the Magneto / MotionCal way), accelerometer and
magnetometer only, with the hand's acceleration as a smooth random disturbance (an AR(1)
process per world axis, correlation time ``shake_s``), so neighbouring poses share it. For
each seeded log with a known truth: the 95 % intervals of every gain, bias and the dip, with
the error bars as fitted (``pose_correlation`` applied) and as they were before (divided by
the recorded widening), at 100 Hz (samples grouped into short windows, and 0.25 s windows)
and Magneto-like at 3 rows/s with no time column. Second, the calibrated magnetometer norm
spread against an independent ellipsoid fit (``fieldcal.fit_ellipsoid``) on the same logs
and on ``../shared/data/ck-explorer/acc_mag_log.csv``.

    python benchmarks/slow_turns.py              # 100 logs per case, writes docs/benchmarks.md
    python benchmarks/slow_turns.py --logs 20 --no-docs

Everything is seeded; BLAS is pinned to one thread.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from numpy.typing import NDArray

import fieldcal
from fieldcal.calibration import Calibration, SensorCalibration
from fieldcal.geometry.frames import GRAVITY, magnetic_reference
from fieldcal.geometry.gauge import canonical_gauge
from fieldcal.geometry.rotations import exp_so3, random_rotations
from fieldcal.logs.inputs import read_log
from fieldcal.pipeline import LogSettings, run_log

Array = NDArray[np.float64]

HERE = Path(__file__).resolve().parent
DATA = HERE.parent.parent / "shared" / "data"


def slow_turn_log(
    seed: int,
    *,
    seconds: float = 60.0,
    rate: float = 100.0,
    speed_deg: float = 20.0,
    shake: float = 0.01,
    shake_s: float = 0.5,
    accel_noise: float = 0.003,
    mag_noise: float = 0.01,
    gravity: float = 9.80665,
    field_strength: float = 48.0,
) -> tuple[dict[str, Array], Calibration]:
    """A slowly turned acc+mag log with a known truth.

    The body turns at ``speed_deg`` °/s about a body axis that wanders smoothly (random knots
    every 2 s). The accelerometer reads the specific force (the hand's acceleration, an AR(1)
    process of RMS ``shake`` |g| per world axis and correlation time ``shake_s`` seconds, plus
    gravity), the magnetometer a field of dip drawn in 50–70°, each through a gain (a few % /
    10 % off identity) and a bias, with white noise (fractions of |g|, |h| per sample).

    Returns the columns ``t, ax, ay, az, mx, my, mz`` and the truth in fieldcal's gauge
    (unit-less gains in raw units per unit field times the magnitudes given).
    """
    rng = np.random.default_rng(seed)
    n = max(2, round(seconds * rate))
    dt = 1.0 / rate
    knots = rng.normal(size=(int(seconds / 2) + 3, 3))
    at = np.arange(n) * dt / 2.0
    axis = np.column_stack([np.interp(at, np.arange(len(knots)), knots[:, j]) for j in range(3)])
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    steps = exp_so3(-axis * np.radians(speed_deg) * dt)  # dR/dt = −[ω]× R
    R = np.empty((n, 3, 3))
    R[0] = random_rotations(1, rng)[0]
    for k in range(1, n):
        R[k] = steps[k - 1] @ R[k - 1]
    phi = np.exp(-dt / shake_s)
    drive = rng.normal(0.0, shake * np.sqrt(1.0 - phi * phi), (n, 3))
    hand = np.empty((n, 3))
    hand[0] = rng.normal(0.0, shake, 3)
    for k in range(1, n):
        hand[k] = phi * hand[k - 1] + drive[k]
    Ka = np.eye(3) + rng.uniform(-0.03, 0.03, (3, 3))
    Km = np.eye(3) + rng.uniform(-0.1, 0.1, (3, 3))
    ba = rng.uniform(-0.05, 0.05, 3) * gravity
    bm = rng.uniform(-0.5, 0.5, 3) * field_strength
    dip = np.radians(rng.uniform(50.0, 70.0))
    g_world = GRAVITY * gravity
    h_world = magnetic_reference(dip) * field_strength
    f_body = np.einsum("nij,nj->ni", R, hand * gravity + g_world)
    h_body = np.einsum("nij,j->ni", R, h_world)
    accel = f_body @ Ka.T + ba + accel_noise * gravity * rng.standard_normal((n, 3))
    mag = h_body @ Km.T + bm + mag_noise * field_strength * rng.standard_normal((n, 3))
    columns = {"t": np.arange(n) * dt}
    for prefix, data in (("a", accel), ("m", mag)):
        for letter, column in zip("xyz", data.T, strict=True):
            columns[prefix + letter] = column
    # the gauge folds the magnitudes into the gains: back to raw units per m/s² and per µT,
    # as a calibration with gravity= and field_strength= given reports them
    Rc, Ka_c, Km_c, g_c, h_c = canonical_gauge(R, Ka, Km, g_world, h_world)
    Ka_c, Km_c, g_c, h_c = (
        Ka_c / gravity,
        Km_c / field_strength,
        g_c * gravity,
        h_c * field_strength,
    )
    truth = Calibration(
        accel=SensorCalibration(
            gain=Ka_c, bias=ba, noise_cov=(accel_noise * gravity) ** 2 * np.eye(3)
        ),
        mag=SensorCalibration(
            gain=Km_c, bias=bm, noise_cov=(mag_noise * field_strength) ** 2 * np.eye(3)
        ),
        gravity=g_c,
        magnetic=h_c,
        rotations=Rc,
        method="truth",
    )
    return columns, truth


def z_scores(cal: Calibration, truth: Calibration, *, unwiden: bool = False) -> Array:
    """(estimate − truth) / standard error for every gain and bias entry in the covariance and
    the dip; ``unwiden``: with the error bars before the correlation correction."""
    cov = cal.covariance
    assert cov is not None
    factor = 1.0
    record = cal.options.get("pose_correlation")
    if unwiden and isinstance(record, dict):
        factor = float(record["widening"])
    out = []
    for s in ("accel", "mag"):
        est, tr = cal.sensor(s), truth.sensor(s)
        for i in range(3):
            for j in range(3):
                name = f"{s}.gain[{i},{j}]"
                if name in cov.names and cov.std(name) > 0:
                    out.append((est.gain[i, j] - tr.gain[i, j]) / cov.std(name) * factor)
            out.append((est.bias[i] - tr.bias[i]) / cov.std(f"{s}.bias[{i}]") * factor)
    if truth.dip_deg is not None and cal.dip_deg is not None and cal.dip_std_deg:
        out.append((cal.dip_deg - truth.dip_deg) / cal.dip_std_deg * factor)
    return np.array(out)


def calibrate_columns(
    columns: dict[str, Array], poses: str, *, time_column: bool = True, **options: Any
) -> Any:
    """``run_log`` on the columns (without ``t`` when ``time_column`` is False)."""
    used = {k: v for k, v in columns.items() if k != "t" or time_column}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_log(read_log(used), LogSettings.of(options, poses=poses, gyro=False))


def norm_spread(mag: Array, cal_gain: Array, cal_bias: Array) -> float:
    """Standard deviation of |K⁻¹ (m − b)| relative to its mean."""
    v = np.linalg.solve(cal_gain, (mag - cal_bias).T).T
    norms = np.linalg.norm(v, axis=1)
    return float(np.std(norms) / np.mean(norms))


CASES = {
    # name: (simulation options, run_log poses, keep the time column)
    "100 Hz, samples": ({"rate": 100.0}, "samples", True),
    "100 Hz, windows 0.25 s": ({"rate": 100.0}, "windows", True),
    "3 rows/s, samples, no time": ({"rate": 3.0, "seconds": 120.0}, "samples", False),
}


def coverage(logs: int, seed: int) -> list[dict[str, Any]]:
    rows = []
    for name, (sim, poses, timed) in CASES.items():
        z_fit, z_raw, taus, times, levels = [], [], [], [], []
        for k in range(logs):
            columns, truth = slow_turn_log(seed + k, **sim)
            t0 = time.perf_counter()
            lc = calibrate_columns(columns, poses, time_column=timed, gravity=9.80665,
                                   field_strength=48.0)  # fmt: skip
            times.append(time.perf_counter() - t0)
            cal = lc.calibration
            z_fit.append(z_scores(cal, truth))
            z_raw.append(z_scores(cal, truth, unwiden=True))
            taus.append(float(cal.options.get("pose_correlation", {}).get("tau", 1.0)))
            levels.append(cal.verdict.level if cal.verdict else "?")
        zf, zr = np.concatenate(z_fit), np.concatenate(z_raw)
        rows.append(
            {
                "case": name,
                "logs": logs,
                "cover": float(np.mean(np.abs(zf) < 1.96)),
                "cover_before": float(np.mean(np.abs(zr) < 1.96)),
                "rms_z": float(np.sqrt(np.mean(zf**2))),
                "rms_z_before": float(np.sqrt(np.mean(zr**2))),
                "tau": float(np.median(taus)),
                "time": float(np.median(times)),
                "levels": {v: levels.count(v) for v in sorted(set(levels))},
            }
        )
        print(rows[-1], flush=True)
    return rows


def spreads(logs: int, seed: int) -> list[dict[str, Any]]:
    """Calibrated |m| spread: fieldcal samples vs an independent ellipsoid fit (and the truth)."""
    out = []
    for k in range(logs):
        columns, truth = slow_turn_log(seed + k, rate=3.0, seconds=120.0)
        mag = np.column_stack([columns[c] for c in ("mx", "my", "mz")])
        cal = calibrate_columns(columns, "samples", time_column=False).calibration
        ell = fieldcal.fit_ellipsoid(mag)
        assert truth.mag is not None and cal.mag is not None
        out.append(
            (
                norm_spread(mag, cal.mag.gain, cal.mag.bias),
                norm_spread(mag, ell.gain, ell.bias),
                norm_spread(mag, truth.mag.gain, truth.mag.bias),
            )
        )
    a = np.array(out)
    row = {"case": "simulated 3 rows/s", "logs": logs}
    row.update(
        dict(zip(("fieldcal", "ellipsoid", "truth"), np.median(a, axis=0).tolist(), strict=True))
    )
    rows = [row]
    path = DATA / "ck-explorer" / "acc_mag_log.csv"
    if path.exists():
        lc = calibrate_columns_path(path)
        log = fieldcal.read_log(str(path))
        assert log.mag is not None and lc.calibration.mag is not None
        ell = fieldcal.fit_ellipsoid(log.mag)
        rows.append(
            {
                "case": "ck-explorer acc_mag_log.csv",
                "logs": 1,
                "fieldcal": norm_spread(log.mag, lc.calibration.mag.gain, lc.calibration.mag.bias),
                "ellipsoid": norm_spread(log.mag, ell.gain, ell.bias),
                "truth": None,
                "poses": lc.poses.n,
                "verdict": lc.calibration.verdict.level if lc.calibration.verdict else None,
            }
        )
    for r in rows:
        print(r, flush=True)
    return rows


def calibrate_columns_path(path: Path) -> Any:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_log(read_log(str(path)), LogSettings.of(poses="samples", gyro=False))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", type=int, default=100)
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--no-docs", action="store_true")
    args = parser.parse_args(argv)
    cover = coverage(args.logs, args.seed)
    spread = spreads(min(args.logs, 20), args.seed)
    if not args.no_docs:
        write_docs(cover, spread, args)
    return 0


def write_docs(cover: list[dict[str, Any]], spread: list[dict[str, Any]], args: Any) -> None:
    lines = [
        "## Slow continuous logs without a gyroscope",
        "",
        f"`python benchmarks/slow_turns.py --logs {args.logs} --seed {args.seed}`: seeded slow "
        "turns (20°/s about a wandering axis, the hand's acceleration 0.01 |g| RMS with a 0.5 s "
        "correlation), accelerometer and magnetometer only; every gain, bias and the dip.",
        "",
        "| case | logs | 95 % coverage | before the correction | RMS z | before | median τ "
        "| median time | verdicts |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in cover:
        lines.append(
            f"| {r['case']} | {r['logs']} | {r['cover']:.1%} | {r['cover_before']:.1%} | "
            f"{r['rms_z']:.2f} | {r['rms_z_before']:.2f} | {r['tau']:.2g} | {r['time']:.2f} s "
            f"| {r['levels']} |"
        )
    lines += [
        "",
        "Calibrated magnetometer norm spread (std / mean of |K⁻¹(m − b)|, median over logs):",
        "",
        "| data | logs | fieldcal `--poses samples` | ellipsoid fit | truth |",
        "|---|---|---|---|---|",
    ]
    for r in spread:
        truth = "—" if r.get("truth") is None else f"{r['truth']:.3%}"
        lines.append(
            f"| {r['case']} | {r['logs']} | {r['fieldcal']:.3%} | {r['ellipsoid']:.3%} | {truth} |"
        )
    section = "\n".join(lines) + "\n"
    docs = HERE.parent / "docs" / "benchmarks.md"
    text = docs.read_text(encoding="utf-8")
    start = text.find("## Slow continuous logs without a gyroscope")
    if start >= 0:
        end = text.find("\n## ", start + 3)
        text = text[:start] + section + ("" if end < 0 else text[end + 1 :])
    else:
        text = text.rstrip("\n") + "\n\n" + section
    docs.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    sys.exit(main())
