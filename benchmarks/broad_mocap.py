"""BROAD trials against their motion capture: are fieldcal's error bars believable on real
hand-held motion? (issue 33, item 2)

Each trial (``../shared/data/broad``: a myon aktos-t IMU at 285.7 Hz, already calibrated by its
vendor, with an optical motion-capture orientation) is calibrated by
``fieldcal.calibrate_log`` in its default mode (``poses="auto"``), and the result is compared
with the motion capture and with the vendor's calibration (the identity: the logged values are
the vendor's calibrated m/s², rad/s and µT).

**How the comparison is made.**

1. *Samples compared*: the quasi-static ones — gyroscope rate below 0.5 rad/s and
   ``| |a| − 9.81 |`` below 0.3 m/s² (vendor units), motion capture present — where the
   accelerometer reads gravity to within a few hundredths of a degree of body acceleration.
2. *Frames*: the motion capture gives the rotation from its own marker frame to the lab
   (``q``, z up), so the lab's up direction in the marker frame is ``u = R(q)ᵀ e_z``. The
   marker frame is not the sensor frame: one constant rotation ``Q`` from the marker frame to
   the device's body frame is fitted by Wahba's problem between the gyroscope's rates (as
   logged: the vendor's axes) and the motion capture's body rates
   (``Log(R_kᵀ R_{k+1})/Δt``), ``Q = argmin Σ |ω_k − Q ω_mocap,k|²`` over the samples
   turning faster than 0.5 rad/s. The gyroscope is neither calibration's subject here, so
   the alignment favours neither; the vendor's frame and fieldcal's (the accelerometer's
   gain symmetric) coincide when the vendor's accelerometer is right, so a rotation of the
   vertical between the two calibrations is an error of one of them, not a choice of axes.
   (Fitting ``Q`` to each calibration's own accelerometer instead would absorb any error
   that looks like a constant rotation over the orientations the trial visits, as a bias
   does when the device is mostly upright: on trial 01 that hides 0.8° of the 0.9°.)
3. *Tilt error* of a calibration: RMS over the compared samples of the angle between ``â``
   (the calibrated accelerometer's direction) and ``Q u``. *Heading error*: the calibrated
   accelerometer and magnetometer give the rotation body → NED by TRIAD (down ``−â``, east
   ``down × m̂``); composed with the motion capture's body → lab (``R(q) Qᵀ``) it should be
   one constant rotation lab → NED (the lab's yaw and the declination); the RMS of its yaw
   about that yaw's circular mean is the heading error (tilt-compensated, as a compass is; a
   lab's non-uniform field is in it for both calibrations).
4. *Beyond the vendor's*: the vendor's calibration, measured the same way, sets the floor (the
   motion capture's own error, its alignment, the lab's field, body acceleration left in the
   samples, the vendor's residual errors). The **measured** error of fieldcal's calibration is
   the excess over that floor in quadrature, ``√max(e_fieldcal² − e_vendor², 0)``: the part
   the fieldcal calibration adds. *Ratio* = measured / predicted (the calibration's
   ``accuracy.tilt_deg`` and ``heading_deg``, 1σ RMS over orientations); target 0.5–2. When
   fieldcal is no worse than the vendor the excess is 0 and the ratio says only that the
   prediction is not too small.
5. *Two trials* (01 and 04, the same device on the same day): RMS over the parameters both fits
   have of ``(a − b)/√(σa² + σb²)`` (target ≤ 2). *Split halves*: each trial's halves
   calibrated alone, the same RMS per parameter group (target 0.5–2).
6. *Fast trial* (06): the accelerometer's gain against the vendor's (9.81·I in m/s² per |g|:
   the diagonal's relative error, %, and its z), and the gyroscope's misalignment (the rotation
   angle of its gain's orthogonal polar factor: the vendor's gyroscope is aligned with its
   accelerometer, which fieldcal's body frame follows) and scale errors.

    python benchmarks/broad_mocap.py                 # all four trials, splits, writes the docs
    python benchmarks/broad_mocap.py --trials 01 06 --no-split --no-docs
    python benchmarks/broad_mocap.py --step 3        # every third sample (95 Hz), faster
    python benchmarks/broad_mocap.py --allowances    # the continuous fits with Eq. C6a–C6b

``--allowances``: the continuous estimator's weights for what its model leaves out
(``fit_continuous(allowances=True)``, not reachable from ``calibrate_log``) switched on by
wrapping its rounds; ``cal.options["allowances"]`` records it.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import pin_blas_threads, stamp, write_section

import fieldcal
from fieldcal.errors import InputError
from fieldcal.geometry.frames import orthogonal_polar_factor
from fieldcal.geometry.rotations import (
    log_so3,
    quaternion_to_matrix,
    rotation_angle_deg,
    wahba,
)
from fieldcal.methods import continuous

Array = NDArray[np.float64]
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "broad"
TRIALS = {
    "01": "slow, no rests",
    "04": "slow, with breaks",
    "06": "fast",
    "33": "magnet attached",
}
G = 9.81  # the vendor's unit: the accelerometer reads about +9.81 up (README)
#: Parameter groups, by name prefix.
GROUPS = {
    "accel gain": "accel.gain",
    "accel bias": "accel.bias",
    "mag gain": "mag.gain",
    "mag bias": "mag.bias",
    "dip": "dip_deg",
    "gyro gain": "gyro.gain",
    "gyro bias": "gyro.bias",
    "lever arm": "lever_arm_m",
}
#: Quasi-static samples: gyroscope rate (rad/s) and |a| − g (m/s²) below these.
STILL_RATE, STILL_ACCEL = 0.5, 0.3


def load(trial: str, step: int = 1) -> tuple[dict[str, Array], Array] | None:
    """The trial's sensor columns and its motion-capture quaternions (NaN where unseen)."""
    path = next(DATA.glob(f"{trial}_*.csv"), None)
    if path is None:
        return None
    d = np.genfromtxt(path, delimiter=",", names=True)[::step]
    cols = {k: np.ascontiguousarray(d[k]) for k in ("t", *(p + a for p in "agm" for a in "xyz"))}
    quat = np.column_stack([d[k] for k in ("qw", "qx", "qy", "qz")])
    return cols, quat


def _xyz(cols: dict[str, Array], prefix: str) -> Array:
    return np.column_stack([cols[prefix + a] for a in "xyz"])


def _unit(v: Array) -> Array:
    return np.asarray(v / np.linalg.norm(v, axis=-1, keepdims=True))


def compared_samples(cols: dict[str, Array], quat: Array) -> Array:
    """Indices of the quasi-static samples with motion capture (docstring, 1)."""
    rate = np.linalg.norm(_xyz(cols, "g"), axis=1)
    norm = np.linalg.norm(_xyz(cols, "a"), axis=1)
    seen = np.all(np.isfinite(quat), axis=1)
    return np.flatnonzero((rate < STILL_RATE) & (np.abs(norm - G) < STILL_ACCEL) & seen)


def _rotations(quat: Array) -> Array:
    """Marker → lab rotations; NaN where the markers were not seen."""
    seen = np.all(np.isfinite(quat), axis=1)
    q = np.where(seen[:, None], quat, np.array([1.0, 0.0, 0.0, 0.0]))
    R = quaternion_to_matrix(q / np.linalg.norm(q, axis=1, keepdims=True))
    R[~seen] = np.nan
    return R


def alignment(cols: dict[str, Array], quat: Array) -> tuple[Array, float]:
    """The marker → body rotation ``Q`` from the gyroscope's and the motion capture's rates
    (docstring, 2), and the RMS of the rate residual (rad/s)."""
    R = _rotations(quat)
    ok = np.all(np.isfinite(R[:-1]), axis=(1, 2)) & np.all(np.isfinite(R[1:]), axis=(1, 2))
    step = np.transpose(R[:-1][ok], (0, 2, 1)) @ R[1:][ok]
    mocap = log_so3(step) / np.diff(cols["t"])[ok][:, None]
    gyro = _xyz(cols, "g")
    mid = 0.5 * (gyro[1:] + gyro[:-1])[ok]
    turning = np.linalg.norm(mid, axis=1) > STILL_RATE
    Q = wahba(mid[turning], mocap[turning])
    residual = mid[turning] - mocap[turning] @ Q.T
    return Q, float(np.sqrt(np.mean(residual**2)))


def errors_against_mocap(accel: Array, mag: Array, quat: Array, Q: Array) -> dict[str, Array]:
    """Per-sample tilt and heading errors (degrees) of calibrated readings against the motion
    capture, the marker frame aligned by ``Q`` (docstring, 2–3); the heading's about its
    circular mean (the lab's yaw and the declination)."""
    a_hat, m_hat = _unit(accel), _unit(mag)
    R_lab = _rotations(quat)
    up = np.einsum("nji,j->ni", R_lab, np.array([0.0, 0.0, 1.0])) @ Q.T  # lab up, body frame
    tilt = np.degrees(np.arccos(np.clip(np.sum(a_hat * up, axis=1), -1.0, 1.0)))
    down = -a_hat
    east = _unit(np.cross(down, m_hat))
    north = np.cross(east, down)
    to_ned = np.stack([north, east, down], axis=1)  # rows: body → NED
    lab_to_ned = to_ned @ Q @ np.transpose(R_lab, (0, 2, 1))  # lab → marker → body → NED
    x = lab_to_ned[:, :, 0]  # the lab's x axis in NED
    yaw = np.arctan2(x[:, 1], x[:, 0])
    mean = np.angle(np.mean(np.exp(1j * yaw)))
    return {"tilt": tilt, "heading": np.degrees(np.angle(np.exp(1j * (yaw - mean))))}


def _rms(x: Array) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def calibrate(cols: dict[str, Array], allowances: bool = False) -> fieldcal.Calibration | str:
    """``fieldcal.calibrate_log`` in its default mode (with ``allowances``, the continuous
    fit's Eq. C6a–C6b on); the refusal's message if it refuses."""
    original = continuous.run_rounds

    def with_allowances(state: Any, plan: Any, prior: Any) -> Any:
        plan.options.allowances = True
        return original(state, plan, prior)

    if allowances:
        continuous.run_rounds = with_allowances  # type: ignore[assignment]
    try:
        return fieldcal.calibrate_log(cols)
    except InputError as exc:
        return f"refused: {exc}"
    finally:
        continuous.run_rounds = original  # type: ignore[assignment]


def values(cal: fieldcal.Calibration) -> dict[str, tuple[float, float]]:
    """Every parameter the covariance names: (value, standard error)."""
    cov = cal.covariance
    if cov is None:
        return {}
    out = {}
    for name, sd in zip(cov.names, cov.stds(list(cov.names)), strict=True):
        if name == "dip_deg":
            out[name] = (float(cal.dip_deg or 0.0), float(sd))
            continue
        if name.startswith("lever_arm_m["):  # the continuous fit's lever arm (issue 33)
            arm = cal.options.get("lever_arm")
            if isinstance(arm, dict) and "metres" in arm:
                out[name] = (float(arm["metres"][int(name[-2])]), float(sd))
            continue
        if "." not in name:
            continue
        sensor, rest = name.split(".", 1)
        block = getattr(cal, sensor, None)
        if block is None or not rest.startswith(("gain", "bias")):
            continue
        index = tuple(int(i) for i in rest[rest.index("[") + 1 : -1].split(","))
        array = block.gain if rest.startswith("gain") else block.bias
        out[name] = (float(array[index]), float(sd))
    return out


def agreement(a: fieldcal.Calibration, b: fieldcal.Calibration) -> dict[str, float]:
    """RMS z of the difference, over all shared parameters and per group."""
    va, vb = values(a), values(b)
    shared = [n for n in va if n in vb and np.hypot(va[n][1], vb[n][1]) > 0]
    z = {n: (va[n][0] - vb[n][0]) / np.hypot(va[n][1], vb[n][1]) for n in shared}
    out = {"all": float(np.sqrt(np.mean(np.square(list(z.values()))))) if z else np.nan}
    for group, prefix in GROUPS.items():
        zs = [v for n, v in z.items() if n.startswith(prefix)]
        out[group] = float(np.sqrt(np.mean(np.square(zs)))) if zs else np.nan
    out["n"] = float(len(z))
    return out


def _mode(cal: fieldcal.Calibration) -> str:
    return f"{cal.options.get('mode', '?')}, {cal.verdict.summary}"


def trial_row(trial: str, cal: fieldcal.Calibration, cols: dict[str, Array], quat: Array) -> dict:
    """Predicted against measured tilt and heading for one trial (docstring, 4)."""
    Q, rate_residual = alignment(cols, quat)
    idx = compared_samples(cols, quat)
    a, m, q = _xyz(cols, "a")[idx], _xyz(cols, "m")[idx], quat[idx]
    vendor = errors_against_mocap(a, m, q, Q)
    ours = errors_against_mocap(cal.correct_accel(a), cal.correct_mag(m), q, Q)
    row: dict[str, object] = {
        "trial": trial,
        "mode": _mode(cal),
        "samples": len(idx),
        "rate residual": rate_residual,
    }
    acc = cal.accuracy
    for key, predicted in (
        ("tilt", None if acc is None else acc.tilt_deg),
        ("heading", None if acc is None else acc.heading_deg),
    ):
        e_vendor, e_ours = _rms(vendor[key]), _rms(ours[key])
        excess = float(np.sqrt(max(e_ours**2 - e_vendor**2, 0.0)))
        if key == "tilt":  # the angle between the two calibrations' verticals
            a_v, a_f = _unit(a), _unit(cal.correct_accel(a))
            delta = np.degrees(np.arccos(np.clip(np.sum(a_v * a_f, axis=1), -1.0, 1.0)))
        else:  # the two headings' difference about its mean
            d = np.radians(ours[key] - vendor[key])
            delta = np.degrees(np.angle(np.exp(1j * (d - np.angle(np.mean(np.exp(1j * d)))))))
        row[key] = {
            "vendor": e_vendor,
            "fieldcal": e_ours,
            "measured": excess,
            "predicted": predicted,
            "ratio": None if not predicted else excess / predicted,
            "delta": _rms(delta),
        }
    return row


def fast_trial(cal: fieldcal.Calibration) -> dict[str, object]:
    """The accelerometer's gain against the vendor's, the gyroscope's misalignment (6)."""
    scaled = cal.with_field_magnitudes(G, None)
    K = np.asarray(scaled.accel.gain) if scaled.accel is not None else np.eye(3)
    names = [f"accel.gain[{i},{i}]" for i in range(3)]
    sd = scaled.covariance.stds(names) if scaled.covariance is not None else np.zeros(3)
    out: dict[str, object] = {
        "accel gain diag error %": [100 * (K[i, i] - 1.0) for i in range(3)],
        "accel gain diag z": [(K[i, i] - 1.0) / s if s > 0 else np.nan for i, s in enumerate(sd)],
        "accel bias m/s²": list(np.asarray(scaled.accel.bias)) if scaled.accel else [],
    }
    if cal.gyro is not None:
        Kg = np.asarray(cal.gyro.gain)
        out["gyro misalignment deg"] = float(rotation_angle_deg(orthogonal_polar_factor(Kg)))
        out["gyro scale error %"] = list(100 * (np.linalg.svd(Kg, compute_uv=False) - 1.0))
        # each row's off-diagonal terms as angles: how far an axis leans towards another
        rows = Kg / np.linalg.norm(Kg, axis=1, keepdims=True)
        lean = np.degrees(np.arcsin(np.abs(rows - np.diag(np.diag(rows)))))
        out["gyro largest cross-axis term deg"] = float(lean.max())
    return out


def _cell(x: object, fmt: str = "{:.2f}") -> str:
    return "–" if x is None or (isinstance(x, float) and not np.isfinite(x)) else fmt.format(x)


def report(
    rows: list[dict], pair: dict[str, float] | None, splits: dict[str, dict], fast: dict | None
) -> list[str]:
    lines = [
        "### Predicted against measured error (motion capture, beyond the vendor's calibration)",
        "",
        "Measured = √max(e_fieldcal² − e_vendor², 0) on the quasi-static samples (rate "
        f"< {STILL_RATE} rad/s, ||a| − g| < {STILL_ACCEL} m/s²), the motion capture's marker "
        "frame aligned to the device's by one Wahba rotation fitted to the gyroscope's rates; "
        "ratio = measured / predicted (target 0.5–2; 0 when fieldcal is no worse than the "
        "vendor's calibration). Degrees.",
        "",
        "| trial | mode, verdict | samples | tilt vendor | tilt fieldcal | tilt measured "
        "| tilt predicted | ratio | tilt Δ vendor | heading vendor | heading fieldcal "
        "| heading measured | heading predicted | ratio | heading Δ vendor |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        cells = [r["trial"] + " " + TRIALS[r["trial"]], r["mode"], str(r["samples"])]
        for key in ("tilt", "heading"):
            d = r[key]
            cells += [_cell(d["vendor"]), _cell(d["fieldcal"]), _cell(d["measured"])]
            cells += [_cell(d["predicted"]), _cell(d["ratio"]), _cell(d["delta"])]
        lines.append("| " + " | ".join(cells) + " |")
    lines += [
        "",
        "Δ vendor: RMS of the per-sample difference between fieldcal's and the vendor's "
        "calibration (the angle between their verticals; their headings' difference about its "
        "mean) — no motion capture in it, so free of the lab's floor; it is fieldcal's error "
        "where the vendor's calibration is right. Gyroscope-to-motion-capture rate residual "
        "(alignment quality): "
        + ", ".join(f"{r['trial']} {r['rate residual']:.3f} rad/s" for r in rows)
        + ".",
        "",
    ]
    groups = ["all", *GROUPS]
    if pair is not None:
        lines += [
            "### The same device from two trials (01 and 04, full logs)",
            "",
            "RMS of (a − b)/√(σa² + σb²) over the parameters both fits have (target ≤ 2).",
            "",
            "| " + " | ".join(groups) + " |",
            "|" + "---:|" * len(groups),
            "| " + " | ".join(_cell(pair.get(g)) for g in groups) + " |",
            "",
        ]
    if splits:
        lines += [
            "### Split halves (each half calibrated alone; target 0.5–2 per group)",
            "",
            "| trial | " + " | ".join(groups) + " | halves |",
            "|---|" + "---:|" * len(groups) + "---|",
        ]
        for trial, s in splits.items():
            cells = [_cell(s.get(g)) for g in groups]
            lines.append(f"| {trial} | " + " | ".join(cells) + f" | {s['halves']} |")
        lines.append("")
    if fast is not None:
        lines += ["### Fast trial 06 against the vendor's calibration", ""]
        lines += ["| quantity | value |", "|---|---|"]
        for k, v in fast.items():
            text = ", ".join(f"{x:.2f}" for x in v) if isinstance(v, list) else f"{v:.2f}"
            lines.append(f"| {k} | {text} |")
        lines += [
            "",
            "Targets: accelerometer gain within 2 % of the vendor's, gyroscope "
            "misalignment under 1°, or a verdict saying the log cannot determine them.",
            "",
        ]
    return lines


def split_halves(cols: dict[str, Array], allowances: bool = False) -> dict[str, object]:
    half = len(cols["t"]) // 2
    fits = []
    for part in (slice(0, half), slice(half, None)):
        fits.append(calibrate({k: v[part] for k, v in cols.items()}, allowances))
    labels = [f if isinstance(f, str) else _mode(f) for f in fits]
    out: dict[str, object] = {"halves": "; ".join(labels)}
    if all(not isinstance(f, str) for f in fits):
        out.update(agreement(fits[0], fits[1]))  # type: ignore[arg-type]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", nargs="+", default=list(TRIALS), choices=list(TRIALS))
    parser.add_argument("--step", type=int, default=1, help="Keep every step-th sample.")
    parser.add_argument("--no-split", action="store_true", help="Skip the split halves.")
    parser.add_argument("--no-docs", action="store_true")
    parser.add_argument(
        "--allowances", action="store_true", help="The continuous fits with Eq. C6a-C6b."
    )
    args = parser.parse_args()
    command = (
        "python benchmarks/broad_mocap.py"
        + "".join(
            f" --{k.replace('_', '-')} {' '.join(v) if isinstance(v, list) else v}"
            for k, v in vars(args).items()
            if k not in ("no_docs", "no_split", "allowances") and v != parser.get_default(k)
        )
        + (" --no-split" if args.no_split else "")
        + (" --allowances" if args.allowances else "")
    )
    rows, fits, splits, cpu = [], {}, {}, {}
    with pin_blas_threads():
        for trial in args.trials:
            loaded = load(trial, args.step)
            if loaded is None:
                print(f"trial {trial}: not in {DATA}, skipped", file=sys.stderr)
                continue
            cols, quat = loaded
            start = time.process_time()
            cal = calibrate(cols, args.allowances)
            cpu[trial] = time.process_time() - start
            if isinstance(cal, str):
                print(f"trial {trial}: {cal}", file=sys.stderr)
                continue
            fits[trial] = cal
            rows.append(trial_row(trial, cal, cols, quat))
            print(f"trial {trial}: {_mode(cal)}, {cpu[trial]:.1f} s CPU", file=sys.stderr)
            if not args.no_split:
                splits[trial] = split_halves(cols, args.allowances)
    pair = agreement(fits["01"], fits["04"]) if {"01", "04"} <= fits.keys() else None
    fast = fast_trial(fits["06"]) if "06" in fits else None
    lines = ["## BROAD against motion capture (issue 33)", "", stamp(command), ""]
    lines += report(rows, pair, splits, fast)
    lines += ["CPU per full-log fit (s): " + ", ".join(f"{k}: {v:.1f}" for k, v in cpu.items()), ""]
    print("\n".join(lines))
    if not args.no_docs:
        write_section("broad_mocap", "\n".join(lines))


if __name__ == "__main__":
    main()
