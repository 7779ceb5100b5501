"""Continuous-motion calibration (fieldcal.methods.continuous): accuracy against the static-pose
Cramér–Rao bound, coverage of the 95 % intervals, time and its linearity, and the simulation
configuration of Huang, Hendeby & Skog (arXiv:2505.16662, Huang-Chuan/Mag-IMU-JointCalibration).

- *accuracy* (issue 23 item 3): hand-waved 60 s logs at 100 Hz with MEMS-grade noise and no
  rests (``simulate_handwave``); the RMS error of each parameter group divided by the RMS
  Cramér–Rao standard error of a 15-pose static session of the same duration (400 samples per
  pose), the same sensors and the same noise, calibrated by ``fieldcal.calibrate`` (its own
  covariance). Run with the hand's acceleration (0.05 g RMS per axis) and without (pure turns).
- *coverage*: the share of the 37 parameters' 95 % intervals (±1.96σ of the fit's covariance)
  that hold the truth, over many logs.
- *time*: CPU and wall time of one fit at 60 s and 600 s (100 Hz), best of three.
- *split halves* (issue 23 item 2): each half of each real session calibrated alone; the RMS
  over the 37 parameters of ``(a − b)/sqrt(σa² + σb²)`` (1 when the error bars are honest and
  the halves differ only by noise). BROAD trials 01, 04, 06, 33 (every third sample, 95 Hz)
  and the ICM-20948 sessions 1 and 3 (no time stamps: at the nominal 28 Hz of their 30 ms
  loop; the magnetometer's axes mapped as their README says).
- *hhs*: their configuration ported: 80 Hz; rotations at 0.1 rad/s about x, y, z, x+y, x+z,
  y+z, one full turn each, with 0.05 rad/s of white rate noise per step; noise densities
  0.02 m/s²/√Hz (accelerometer), 8.7e-4 rad/s/√Hz (gyroscope), 0.003 µT/√Hz (magnetometer);
  accelerometer bias ±0.5 m/s²; magnetometer D = 27·scale(±10 %)·skew(±10°)·rotation(±5°),
  bias ±2 µT, dip 72 ± 5°; gyroscope bias 0.01 ± 0.1°/s; identity accelerometer and gyroscope
  gains; no body acceleration. RMSE by their definition (compute_stat.m: the root of the mean
  over datasets of each parameter's squared error norm, Frobenius for D) and per entry.

    python benchmarks/continuous.py                      # everything, writes the docs section
    python benchmarks/continuous.py --coverage-logs 40 --accuracy-logs 10 --no-docs
    python benchmarks/continuous.py --only split --no-docs   # the real sessions only
    python benchmarks/continuous.py --only hhs --hhs-sets 20 # their configuration only
    python benchmarks/continuous.py --only hhs --hhs-sets 20 --hold-gyro-gain  # gain held
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import pin_blas_threads, stamp, write_section

import fieldcal
from fieldcal.errors import InputError
from fieldcal.geometry.frames import GRAVITY
from fieldcal.geometry.rotations import exp_so3, random_rotations
from fieldcal.methods.continuous import fit_continuous
from fieldcal.methods.continuous.uncertainty import NAMES
from fieldcal.simulation.handwave import simulate_handwave

Array = NDArray[np.float64]
GROUPS = {
    "accel gain": [n for n in NAMES if n.startswith("accel.gain")],
    "accel bias": [n for n in NAMES if n.startswith("accel.bias")],
    "mag gain": [n for n in NAMES if n.startswith("mag.gain")],
    "mag bias": [n for n in NAMES if n.startswith("mag.bias")],
    "dip": ["dip_deg"],
    "gyro gain": [n for n in NAMES if n.startswith("gyro.gain")],
    "gyro bias": [n for n in NAMES if n.startswith("gyro.bias")],
}


def _cols(log, prefix: str) -> Array:
    return np.column_stack([log.columns[prefix + axis] for axis in "xyz"])


REFUSED: list[str] = []


def _fit(log):
    return fit_continuous(log.columns["t"], _cols(log, "a"), _cols(log, "m"), _cols(log, "g"))


def _fit_or_none(log, label: str):
    """The fit, or ``None`` (recorded in REFUSED) when the motion check refuses the log or the
    verdict fails (a user would not use that result)."""
    try:
        cal = _fit(log)
    except InputError as exc:
        REFUSED.append(f"{label}: refused: {exc}")
        return None
    if cal.verdict.level == "fail":
        REFUSED.append(f"{label}: verdict fail ({', '.join(cal.verdict.codes)})")
        return None
    return cal


def _values(cal) -> dict[str, float]:
    out: dict[str, float] = {}
    for s in ("accel", "mag", "gyro"):
        sensor = getattr(cal, s)
        for i in range(3):
            out[f"{s}.bias[{i}]"] = float(sensor.bias[i])
            for j in range(3):
                out[f"{s}.gain[{i},{j}]"] = float(sensor.gain[i, j])
    out["dip_deg"] = float(cal.dip_deg)
    return out


def _errors(cal, truth) -> dict[str, float]:
    est, true = _values(cal), _values(truth)
    return {k: est[k] - true[k] for k in NAMES}


def _static_crb(log, rng: np.random.Generator, poses: int = 15) -> dict[str, float]:
    """Standard errors of a static session of the same duration, sensors and noise."""
    t = log.truth
    per = log.n // poses
    R = random_rotations(poses, rng)
    accel, mag = [], []
    for Ri in R:
        a = t.accel.gain @ Ri @ GRAVITY + t.accel.bias
        m = t.mag.gain @ Ri @ t.magnetic + t.mag.bias
        accel.append(a + rng.standard_normal((per, 3)) * np.sqrt(t.accel.noise_cov[0, 0]))
        mag.append(m + rng.standard_normal((per, 3)) * np.sqrt(t.mag.noise_cov[0, 0]))
    cal = fieldcal.calibrate(accel, mag, pose_noise="none")
    names = [n for n in NAMES if not n.startswith("gyro")]
    return dict(zip(names, cal.covariance.stds(names), strict=True))


def accuracy(n_logs: int, shake: float) -> dict[str, float]:
    """RMS error / RMS static CRB per group (no gyroscope in the static session)."""
    rng = np.random.default_rng(12345)
    err2: dict[str, list[float]] = {g: [] for g in GROUPS}
    crb2: dict[str, list[float]] = {g: [] for g in GROUPS}
    gyro_rel = []
    for k in range(n_logs):
        log = simulate_handwave(seed=1000 + k, seconds=60.0, shake=shake)
        cal = _fit_or_none(log, f"accuracy seed {1000 + k}")
        if cal is None:
            continue
        e = _errors(cal, log.truth)
        s = _static_crb(log, rng)
        for g, names in GROUPS.items():
            err2[g] += [e[n] ** 2 for n in names]
            crb2[g] += [s[n] ** 2 for n in names if n in s]
        G = np.asarray(log.truth.gyro.gain)
        gyro_rel.append(np.linalg.norm(cal.gyro.gain - G) / np.linalg.norm(G))
    out = {g: float(np.sqrt(np.mean(err2[g]) / np.mean(crb2[g]))) for g in GROUPS if crb2[g]}
    out["gyro gain rel. error (max over logs, %)"] = 100 * float(np.max(gyro_rel))
    return out


def coverage(n_logs: int) -> tuple[dict[str, float], dict[str, float], float]:
    inside: dict[str, list[bool]] = {g: [] for g in GROUPS}
    zs: dict[str, list[float]] = {g: [] for g in GROUPS}
    cpu = []
    for k in range(n_logs):
        log = simulate_handwave(seed=5000 + k, seconds=60.0)
        start = time.process_time()
        cal = _fit_or_none(log, f"coverage seed {5000 + k}")
        if cal is None:
            continue
        cpu.append(time.process_time() - start)
        e = _errors(cal, log.truth)
        sd = dict(zip(NAMES, cal.covariance.stds(list(NAMES)), strict=True))
        for g, names in GROUPS.items():
            z = [e[n] / sd[n] for n in names]
            zs[g] += z
            inside[g] += [abs(v) < 1.96 for v in z]
    cov = {g: float(np.mean(v)) for g, v in inside.items()}
    rms = {g: float(np.sqrt(np.mean(np.square(v)))) for g, v in zs.items()}
    cov["all"] = float(np.mean([x for v in inside.values() for x in v]))
    return cov, rms, float(np.median(cpu))


def timing() -> list[tuple[float, int, float, float, int]]:
    rows = []
    for seconds in (60.0, 600.0):
        log = simulate_handwave(seed=1, seconds=seconds)
        best_cpu = best_wall = np.inf
        for _ in range(3):
            c, w = time.process_time(), time.perf_counter()
            cal = _fit(log)
            best_cpu = min(best_cpu, time.process_time() - c)
            best_wall = min(best_wall, time.perf_counter() - w)
        rows.append((seconds, log.n, best_cpu, best_wall, cal.iterations))
    return rows


# ------------------------------------------------------------------------- split halves
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def _broad(name: str):
    path = next((DATA / "broad").glob(f"{name}_*.csv"), None)
    if path is None:
        return None
    d = np.genfromtxt(path, delimiter=",", names=True)[::3]
    cols = [np.column_stack([d[p + a] for a in "xyz"]) for p in "amg"]
    return d["t"], *cols, 9.81


def _icm(session: str):
    path = DATA / "icm20948-deadtomgc" / "derived" / f"session{session}.csv"
    if not path.is_file():
        return None
    d = np.genfromtxt(path, delimiter=",", names=True)
    accel = np.column_stack([d["ax_g"], d["ay_g"], d["az_g"]])
    gyro = np.radians(np.column_stack([d["gx_dps"], d["gy_dps"], d["gz_dps"]]))
    mag = np.column_stack([d["mx_rawdiv10"], -d["my_rawdiv10"], -d["mz_rawdiv10"]])
    return np.arange(len(d)) / 28.0, accel, mag, gyro, 1.0


SPLIT_SETS = {
    "BROAD 01 slow, no rests": lambda: _broad("01"),
    "BROAD 04 slow, with breaks": lambda: _broad("04"),
    "BROAD 06 fast": lambda: _broad("06"),
    "BROAD 33 magnet attached": lambda: _broad("33"),
    "ICM-20948 session 1 (28 Hz nominal)": lambda: _icm("1"),
    "ICM-20948 session 3 (28 Hz nominal)": lambda: _icm("3"),
}


def split_halves() -> list[dict[str, object]]:
    """Per real session: each half's verdict and the RMS z of the halves' difference, overall
    and per group."""
    rows = []
    for label, load in SPLIT_SETS.items():
        data = load()
        if data is None:
            continue
        t, a, m, g, gravity = data
        half = len(t) // 2
        cals, verdicts = [], []
        for part in (slice(0, half), slice(half, len(t))):
            try:
                cal = fit_continuous(t[part], a[part], m[part], g[part], gravity=gravity)
            except InputError as exc:
                verdicts.append(f"refused ({exc})"[:80])
                continue
            cals.append(cal)
            verdicts.append(
                cal.verdict.level
                + (f" ({', '.join(cal.verdict.codes)})" if cal.verdict.codes else "")
            )
        row: dict[str, object] = {
            "set": label,
            "verdicts": verdicts,
            "seconds": float(t[-1] - t[0]),
        }
        if len(cals) == 2:
            sd = np.hypot(
                cals[0].covariance.stds(list(NAMES)), cals[1].covariance.stds(list(NAMES))
            )
            va, vb = _values(cals[0]), _values(cals[1])
            z = np.array([(va[n] - vb[n]) for n in NAMES]) / sd
            row["all"] = float(np.sqrt(np.mean(z**2)))
            for group, names in GROUPS.items():
                idx = [NAMES.index(n) for n in names]
                row[group] = float(np.sqrt(np.mean(z[idx] ** 2)))
        rows.append(row)
    return rows


def split_lines(rows: list[dict[str, object]]) -> list[str]:
    part = [
        "### Split halves on real sessions (issue 23 item 2)",
        "",
        "Each half calibrated alone; RMS over the parameters of (a − b)/√(σa² + σb²) "
        "(target 0.5–2). Verdicts of the two halves in the last column.",
        "",
        "| session | duration | all 37 | " + " | ".join(GROUPS) + " | halves' verdicts |",
        "|---|---:|---:|" + "---:|" * len(GROUPS) + "---|",
    ]
    for r in rows:
        cells = [f"{r[g]:.2f}" if g in r else "–" for g in ("all", *GROUPS)]
        verdicts = "; ".join(str(v) for v in r["verdicts"])  # type: ignore[attr-defined]
        part.append(
            f"| {r['set']} | {r['seconds']:.0f} s | " + " | ".join(cells) + f" | {verdicts} |"
        )
    return [*part, ""]


# ------------------------------------------------------------------------- Huang et al.
def _hhs_log(rng: np.random.Generator, rate: float = 80.0):
    """One dataset of their simulate.m, in fieldcal's conventions (R world → body)."""
    dt = 1.0 / rate
    axes = 0.1 * np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, 1]])
    steps = []
    for v in axes:
        n = int(np.ceil(2 * np.pi / np.linalg.norm(v) / dt))
        steps.append(v + 0.05 * rng.standard_normal((n, 3)))
    omega = np.concatenate(steps)  # body rate over each step
    # body → world B_{k+1} = B_k Exp(ω dt); ours R = Bᵀ: R_{k+1} = Exp(−ω dt) R_k
    R = [np.eye(3)]
    for step in exp_so3(-omega * dt):
        R.append(step @ R[-1])
    R = np.array(R)
    n = len(R)
    acc_bias = rng.uniform(-0.5, 0.5, 3)
    mag_bias = rng.uniform(-2, 2, 3)
    scale = np.diag(1 + rng.uniform(-0.1, 0.1, 3))
    sk = rng.uniform(-1, 1, 3) * np.radians(10)
    skew = np.array(
        [
            [1, 0, 0],
            [np.sin(sk[0]), np.cos(sk[0]), 0],
            [-np.sin(sk[1]), np.cos(sk[1]) * np.sin(sk[2]), np.cos(sk[1]) * np.cos(sk[2])],
        ]
    )
    mis = rng.uniform(-1, 1, 3) * np.radians(5)
    D = 27 * scale @ skew @ exp_so3(mis)
    dip = np.radians(72 + rng.uniform(-5, 5))
    gyro_bias = 0.01 + rng.uniform(-1, 1, 3) * np.radians(0.1)
    sa, sm, sg = 0.02 * np.sqrt(rate), 0.003 * np.sqrt(rate), 8.7e-4 * np.sqrt(rate)
    g = 9.8
    h = np.array([np.cos(dip), 0.0, np.sin(dip)])  # NED, north and down
    accel = (R @ GRAVITY) * g + acc_bias + sa * rng.standard_normal((n, 3))
    mag = (R @ h) @ D.T + mag_bias + sm * rng.standard_normal((n, 3))
    # their gyroscope sample k is the turn from k to k+1 over dt: hold="previous" in the fit
    gyro = np.vstack([omega, omega[-1:]]) + gyro_bias + sg * rng.standard_normal((n, 3))
    truth = {"D": D, "mag_bias": mag_bias, "acc_bias": acc_bias, "gyro_bias": gyro_bias}
    truth["dip_deg"] = np.degrees(dip)
    return np.arange(n) * dt, accel, mag, gyro, truth


#: Huang–Hendeby–Skog's parameters and how many entries each has (their compute_stat.m).
HHS_PARAMETERS = {"D": 9, "mag_bias": 3, "acc_bias": 3, "gyro_bias": 3, "dip_deg": 1}


def identity_gyro_prior() -> fieldcal.Calibration:
    """A calibration whose gyroscope gain is their simulator's (the identity, rad/s): the
    earlier calibration ``hold="gyro.gain"`` takes the gain from."""
    from fieldcal.calibration import Calibration, SensorCalibration

    gyro = SensorCalibration(gain=np.eye(3), bias=np.zeros(3), noise_cov=np.eye(3))
    return Calibration(None, None, None, None, np.empty((0, 3, 3)), "prior", gyro=gyro)


def hhs(n_sets: int, **fit_options: object) -> dict[str, dict[str, float]]:
    """RMSE of each of their parameters over ``n_sets`` datasets, by their definition
    (compute_stat.m: ``sqrt(mean over datasets of |error vector|²)``, the Frobenius norm for
    ``D``) and per entry (that divided by √entries: what this table showed before issue 33);
    ``fit_options`` go to ``fit_continuous`` (e.g. a held gyroscope gain)."""
    rng = np.random.default_rng(1)
    err: dict[str, list[float]] = {k: [] for k in HHS_PARAMETERS}
    times, samples = [], 0
    for _ in range(n_sets):
        t, a, m, g, truth = _hhs_log(rng)
        samples = len(t)
        start = time.process_time()
        options = {"hold": "previous", "gyro_noise": 8.7e-4 * np.sqrt(80.0), **fit_options}
        cal = fit_continuous(t, a, m, g, **options)  # type: ignore[arg-type]
        times.append(time.process_time() - start)
        cal = cal.with_field_magnitudes(9.8, None)
        found = {
            "D": np.asarray(cal.mag.gain),
            "mag_bias": cal.mag.bias,
            "acc_bias": cal.accel.bias,
            "gyro_bias": cal.gyro.bias,
            "dip_deg": cal.dip_deg,
        }
        for k in HHS_PARAMETERS:
            err[k].append(float(np.sum(np.square(np.asarray(found[k]) - truth[k]))))
    out = {
        k: {
            "theirs": float(np.sqrt(np.mean(v))),
            "per entry": float(np.sqrt(np.mean(v) / HHS_PARAMETERS[k])),
        }
        for k, v in err.items()
    }
    out["time"] = {"CPU seconds per dataset (median)": float(np.median(times))}
    out["time"]["samples per dataset"] = float(samples)
    return out


def hhs_lines(n_sets: int, h: dict[str, dict[str, float]], note: str = "") -> list[str]:
    units = {"D": "µT", "mag_bias": "µT", "acc_bias": "m/s²", "gyro_bias": "rad/s", "dip_deg": "°"}
    part = [
        f"### Huang–Hendeby–Skog simulation configuration ({n_sets} datasets)",
        "",
        "RMSE by their definition (their compute_stat.m): the root of the mean over datasets "
        "of each parameter's squared error norm (the Frobenius norm for the 3×3 D, the "
        "Euclidean for a bias), so √9 = 3 times the per-entry RMSE for D and √3 for a bias; "
        "the per-entry RMSE beside it. No JointMAP figure is quoted here: their paper gives "
        "its RMSE as plots, not numbers, and JointMAP (MATLAB) was not run beside this."
        + (f" {note}" if note else ""),
        "",
        "| parameter | RMSE, their definition | RMSE per entry |",
        "|---|---:|---:|",
    ]
    for k in HHS_PARAMETERS:
        part.append(f"| {k} ({units[k]}) | {h[k]['theirs']:.4g} | {h[k]['per entry']:.4g} |")
    part += [
        "",
        f"Median {h['time']['CPU seconds per dataset (median)']:.2f} s CPU per dataset of "
        f"{h['time']['samples per dataset']:.0f} samples.",
    ]
    return part


def _hhs_options(pairs: list[str]) -> dict[str, object]:
    out: dict[str, object] = {}
    for pair in pairs:
        name, _, value = pair.partition("=")
        out[name.strip()] = json.loads(value)
    if "gyro.gain" in str(out.get("hold", "")) and "prior" not in out:
        out["prior"] = identity_gyro_prior()  # their gyroscope gain: the identity
    return out


def _hhs_note(pairs: list[str]) -> str:
    return f"Fitted with {', '.join(pairs)}." if pairs else ""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--coverage-logs", type=int, default=200)
    parser.add_argument("--accuracy-logs", type=int, default=20)
    parser.add_argument("--hhs-sets", type=int, default=10)
    parser.add_argument("--no-docs", action="store_true")
    parser.add_argument(
        "--only", choices=["split", "hhs"], help="Only the split halves or the HHS configuration."
    )
    parser.add_argument(
        "--hhs-option",
        action="append",
        default=[],
        metavar="NAME=JSON",
        help="A keyword for fit_continuous in the HHS runs (JSON value), e.g. to hold a block.",
    )
    parser.add_argument(
        "--hold-gyro-gain",
        action="store_true",
        help="HHS runs: hold the gyroscope's gain at their simulator's (the identity).",
    )
    args = parser.parse_args()
    if args.hold_gyro_gain:
        args.hhs_option.append('hold="gyro.gain"')
    if args.only == "split":
        with pin_blas_threads():
            print("\n".join(split_lines(split_halves())), flush=True)
        return
    if args.only == "hhs":
        with pin_blas_threads():
            h = hhs(args.hhs_sets, **_hhs_options(args.hhs_option))
        print("\n".join(hhs_lines(args.hhs_sets, h, _hhs_note(args.hhs_option))), flush=True)
        return
    command = (
        "python benchmarks/continuous.py"
        + "".join(
            f" --{k.replace('_', '-')} {v}"
            for k, v in vars(args).items()
            if k not in ("no_docs", "only", "hhs_option", "hold_gyro_gain")
            and v != parser.get_default(k)
        )
        + "".join(f" --hhs-option '{o}'" for o in args.hhs_option)
    )
    lines = ["## Continuous motion (issue 23)", "", stamp(command), ""]
    with pin_blas_threads():
        rows = timing()
        lines += [
            "### Time (one fit, best of 3; 100 Hz hand-waved log)",
            "",
            "| duration | samples | CPU s | wall s | LM iterations |",
            "|---:|---:|---:|---:|---:|",
        ]
        lines += [f"| {s:g} s | {n} | {c:.3f} | {w:.3f} | {i} |" for s, n, c, w, i in rows]
        lines += ["", f"10× the samples: {rows[1][2] / rows[0][2]:.1f}× the CPU time.", ""]
        print("\n".join(lines), flush=True)
        part = ["### Accuracy against the static-pose Cramér–Rao bound", ""]
        part += [
            f"RMS error of each group over {args.accuracy_logs} 60 s logs ÷ RMS standard error "
            "of a 15-pose static session of the same duration, sensors and noise "
            "(target: ≤ 1.5).",
            "",
            "| group | hand shaking 0.05 g | pure turns |",
            "|---|---:|---:|",
        ]
        shaken = accuracy(args.accuracy_logs, 0.05)
        still = accuracy(args.accuracy_logs, 0.0)
        for g in shaken:
            part.append(f"| {g} | {shaken[g]:.2f} | {still[g]:.2f} |")
        lines += [*part, ""]
        print("\n".join(part), flush=True)
        cov, rms, cpu = coverage(args.coverage_logs)
        part = [
            f"### Coverage of the 95 % intervals ({args.coverage_logs} logs of 60 s)",
            "",
            "| group | coverage | RMS z |",
            "|---|---:|---:|",
        ]
        part += [f"| {g} | {cov[g]:.3f} | {rms[g]:.2f} |" for g in GROUPS]
        part += [f"| all 37 | {cov['all']:.3f} | |", "", f"Median CPU per fit: {cpu:.2f} s.", ""]
        lines += part
        print("\n".join(part), flush=True)
        part = split_lines(split_halves())
        lines += part
        print("\n".join(part), flush=True)
        h = hhs(args.hhs_sets, **_hhs_options(args.hhs_option))
        part = hhs_lines(args.hhs_sets, h, _hhs_note(args.hhs_option))
        lines += [*part, ""]
        print("\n".join(part), flush=True)
        part = [f"Logs left out (refused, or the verdict failed): {len(REFUSED)}.", ""]
        part += [f"- {r}" for r in REFUSED]
        lines += [*part, ""]
        print("\n".join(part), flush=True)
    if not args.no_docs:
        write_section("continuous", "\n".join(lines))


if __name__ == "__main__":
    main()
