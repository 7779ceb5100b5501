"""Noise characterisation: recovery of N, K (and B) with the coverage of their intervals on
simulated records, speed at 10^6 and 10^7 samples, agreement with allantools, and real logs
against their datasheets. Writes the "noise" section of docs/benchmarks.md.

    python benchmarks/noise.py            # the full run (about a minute on 2 cores)
    python benchmarks/noise.py --quick    # small sizes, nothing written

allantools (https://pypi.org/project/allantools/) is compared when it is installed
(``pip install allantools``); it is not a dependency of fieldcal.
"""

from __future__ import annotations

import argparse
import importlib
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _real_sets
from _report import pin_blas_threads, stamp, write_section

import fieldcal
from fieldcal.noise import characterise_noise
from fieldcal.stats.allan import allan_deviation, fit_noise_model

RATE = 100.0
DATA = _real_sets.DATA
ROOT = Path(__file__).resolve().parents[1]


# ----------------------------------------------------------------------------- simulation
def white(rng: np.random.Generator, n: int, density: float) -> np.ndarray:
    """White rate noise of density N (unit/√Hz): σ per sample = N √rate."""
    return rng.normal(0.0, density * math.sqrt(RATE), (n, 3))


def walk(rng: np.random.Generator, n: int, k: float) -> np.ndarray:
    """Rate random walk K (unit/s/√Hz): steps of K / √rate."""
    return np.cumsum(rng.normal(0.0, k / math.sqrt(RATE), (n, 3)), axis=0)


def flicker(rng: np.random.Generator, n: int, b: float) -> np.ndarray:
    """Flicker rate noise whose Allan deviation is flat at 0.664 B: one-sided spectrum
    B² / (π f) (the IEEE Std 952 two-sided B² / (2π f)), shaped in the frequency domain."""
    f = np.fft.rfftfreq(n, 1.0 / RATE)
    spectrum = np.zeros_like(f)
    spectrum[1:] = b**2 / (math.pi * f[1:])
    out = np.empty((n, 3))
    for j in range(3):
        z = rng.normal(size=f.size) + 1j * rng.normal(size=f.size)
        out[:, j] = np.fft.irfft(np.sqrt(n * RATE * spectrum / 2.0) * z / math.sqrt(2.0), n)
    return out


CASES = [
    # name, samples, records, N, B, K
    ("white, 1000 s", 100_000, 100, 0.01, 0.0, 0.0),
    ("white + walk, 1000 s (crossing 17 s)", 100_000, 100, 0.01, 0.0, 1e-3),
    ("white + walk, 2.8 h", 1_000_000, 30, 0.01, 0.0, 1e-3),
    ("white + flicker + walk, 2.8 h", 1_000_000, 20, 0.01, 3e-3, 2e-4),
]


def recovery(quick: bool) -> tuple[str, list[str]]:
    rows = [
        "| record | records × axes | parameter | truth | mean estimate / truth − 1 | "
        "median σ / truth | within 1σ | within 2σ |",
        "|---|---|---|---|---|---|---|---|",
    ]
    notes = []
    for name, n, records, N, B, K in CASES:
        if quick:
            n, records = min(n, 100_000), 4
        rng = np.random.default_rng(abs(hash(name)) % 2**32)
        est: dict[str, list[np.ndarray]] = {"N": [], "B": [], "K": []}
        std: dict[str, list[np.ndarray]] = {"N": [], "B": [], "K": []}
        t0 = time.perf_counter()
        for _ in range(records):
            y = white(rng, n, N)
            if K:
                y += walk(rng, n, K)
            if B:
                y += flicker(rng, n, B)
            model = fit_noise_model(allan_deviation(y, RATE))
            for key, attr in (
                ("N", "noise_density"),
                ("B", "bias_instability"),
                ("K", "random_walk"),
            ):
                est[key].append(getattr(model, attr))
                std[key].append(getattr(model, attr + "_std"))
        seconds = time.perf_counter() - t0
        for key, truth in (("N", N), ("B", B), ("K", K)):
            e, s = np.concatenate(est[key]), np.concatenate(std[key])
            z = (e - truth) / s
            within1, within2 = np.mean(np.abs(z) < 1), np.mean(np.abs(z) < 2)
            if truth > 0:
                bias = f"{np.mean(e) / truth - 1:+.1%}"
                spread = f"{np.median(s) / truth:.2%}"
            else:
                detected = np.mean(e > 2 * s)
                bias = f"0 truth: resolved (> 2σ) in {detected:.0%}"
                spread = "—"
            rows.append(
                f"| {name} | {records} × 3 | {key} | {truth:g} | {bias} | {spread} | "
                f"{within1:.0%} | {within2:.0%} |"
            )
        notes.append(f"{name}: {seconds:.1f} s for {records} records")
    return "\n".join(rows), notes


# ----------------------------------------------------------------------------- speed
def best_of(repeat: int, work) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        work()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def speed(quick: bool) -> tuple[str, str]:
    rng = np.random.default_rng(1)
    rows = [
        "| samples × axes | τ points | allan_deviation (s) | fit_noise_model (s) | "
        "allantools oadev (s) |",
        "|---|---|---|---|---|",
    ]
    agreement = "allantools not installed: no comparison"
    try:
        allantools = importlib.import_module("allantools")
    except ImportError:
        allantools = None
    for n in (10**5,) if quick else (10**6, 10**7):
        y = white(rng, n, 0.01) + walk(rng, n, 1e-3)
        curve = allan_deviation(y, RATE)
        t_allan = best_of(1 if n >= 10**7 else 3, lambda y=y: allan_deviation(y, RATE))
        t_fit = best_of(3, lambda curve=curve: fit_noise_model(curve))
        t_ref = "—"
        if allantools is not None:
            column = np.ascontiguousarray(y[:, 0])
            start = time.perf_counter()
            taus, adev, _, _ = allantools.oadev(
                column, rate=RATE, data_type="freq", taus=curve.taus
            )
            t_ref = f"{3 * (time.perf_counter() - start):.2f} (3 axes, one call each)"
            mine = {
                round(float(t), 9): a for t, a in zip(curve.taus, curve.adev[:, 0], strict=True)
            }
            diffs = [abs(a / mine[round(float(t), 9)] - 1) for t, a in zip(taus, adev, strict=True)]
            agreement = (
                f"allantools {allantools.__version__} `oadev(data_type='freq')` on the same "
                f"{n:,}-sample record, at the {len(taus)} τ it computes (of our {len(curve.taus)}; "
                f"it stops short of m = n/2): largest relative difference {max(diffs):.1e}"
            )
        rows.append(f"| {n:,} × 3 | {len(curve.taus)} | {t_allan:.2f} | {t_fit:.3f} | {t_ref} |")
    # the whole path on a log: still detection, three sensors' worth of columns
    n = 10**5 if quick else 10**6
    log = {"t": np.arange(n) / RATE}
    for prefix, y in (("a", white(rng, n, 2e-4)), ("g", white(rng, n, 0.005) + walk(rng, n, 1e-4))):
        for j, axis in enumerate("xyz"):
            log[prefix + axis] = y[:, j]
    t_all = best_of(1, lambda: characterise_noise(log, accel_unit="g", gyro_unit="rad/s"))
    rows.append(
        f"| characterise_noise on a {n:,}-row log (accel + gyro, still detection) | | "
        f"{t_all:.2f} (total) | | |"
    )
    return "\n".join(rows), agreement


# ----------------------------------------------------------------------------- real logs
def _fmt(values: np.ndarray, scale: float, digits: int = 3) -> str:
    return ", ".join(f"{v * scale:.{digits}g}" for v in values)


def real_logs() -> tuple[str, list[str]]:
    rows = [
        "| log | stretches (total / longest) | sensor | N per axis x, y, z | datasheet N | "
        "K per axis (± σ) | τ fitted |",
        "|---|---|---|---|---|---|---|",
    ]
    notes: list[str] = []
    deg = 180 / math.pi

    def add(label: str, report, sensor: str, unit: str, scale: float, sheet: str) -> None:
        fit = report.fits[sensor]
        k = [
            f"{kv * scale:.2g} ± {ks * scale:.1g}" if ok else f"< {(kv + 2 * ks) * scale:.2g}"
            for kv, ks, ok in zip(
                fit.random_walk, fit.random_walk_std, fit.random_walk_resolved, strict=True
            )
        ]
        rows.append(
            f"| {label} | {len(report.stretches)}: {report.seconds:.0f} s / {report.longest:.0f} s "
            f"| {sensor} | {_fmt(fit.noise_density, scale)} {unit}/√Hz | {sheet} | "
            f"{'; '.join(k)} {unit}/s/√Hz | {fit.tau_range[0]:.3g}–{fit.tau_range[1]:.3g} s |"
        )

    # Xsens (IMU-TK): raw counts at 100 Hz; gyro 1/6258 rad/s per count (IMU-TK's own start);
    # the accelerometer through fieldcal's own calibration of the same log (|g| = 9.81744 m/s²,
    # IMU-TK's value), so the counts become m/s² with this unit's gain, not a nominal one.
    acc = np.loadtxt(DATA / "imu_tk" / "xsens_acc.mat")
    gyr = np.loadtxt(DATA / "imu_tk" / "xsens_gyro.mat")
    source = {"t": acc[:, 0], "ax": acc[:, 1], "ay": acc[:, 2], "az": acc[:, 3]}
    source.update({"gx": gyr[:, 1], "gy": gyr[:, 2], "gz": gyr[:, 3]})
    poses = _real_sets.imu_tk()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = fieldcal.calibrate(poses.accel, None, gravity=9.81744)
    counts_per_ms2 = float(np.cbrt(abs(np.linalg.det(cal.accel.gain))))
    notes.append(
        f"Xsens accelerometer scale: fieldcal's calibration of the same log's {poses.n_poses} "
        f"still poses with |g| = 9.81744 m/s² (IMU-TK's value): {counts_per_ms2:.1f} counts "
        "per m/s² (cube root of the gain's determinant), applied with cal=; gyroscope 1/6258 "
        "rad/s per count (IMU-TK's starting value, not calibrated here)."
    )
    head = {key: value[acc[:, 0] < 50.0] for key, value in source.items()}
    first = characterise_noise(head, cal=cal, gyro_unit=1 / 6258, still="all")
    whole = characterise_noise(source, cal=cal, gyro_unit=1 / 6258)
    sheet_g = "0.05 °/s/√Hz (MTi, ±300 °/s; unverified: see below)"
    sheet_a = "0.002 m/s²/√Hz (MTi, ±5 g; unverified)"
    per_count = deg / 6258  # °/s per count
    add("Xsens (IMU-TK), first 50 s", first, "gyro", "°/s", per_count, sheet_g)
    add("Xsens (IMU-TK), first 50 s", first, "accel", "m/s²", 1.0, sheet_a)
    add("Xsens (IMU-TK), all still parts", whole, "gyro", "°/s", per_count, sheet_g)
    add("Xsens (IMU-TK), all still parts", whole, "accel", "m/s²", 1.0, sheet_a)

    # ICM-20948 (deadtomgc session 3): g and dps columns, no timestamps; the logging loop
    # sleeps 30 ms per sample, about 25-30 Hz: 27 Hz taken (as the other benchmarks)
    icm = characterise_noise(
        DATA / "icm20948-deadtomgc" / "derived" / "session3.csv",
        rate=27.0,
        sensors=("accel", "gyro"),
    )
    add("ICM-20948 session 3 (27 Hz assumed)", icm, "gyro", "°/s", 1.0, "0.015 °/s/√Hz")
    add("ICM-20948 session 3 (27 Hz assumed)", icm, "accel", "µg", 1e6, "230 µg/√Hz")

    # imucal's Ferraris session: m/s² and deg/s, 102.4 Hz, no timestamps
    imucal = characterise_noise(
        DATA / "imucal" / "example_ferraris_session.csv",
        rate=102.4,
        accel_unit="m/s^2",
        gyro_unit="deg/s",
    )
    add("imucal Ferraris session (102.4 Hz)", imucal, "gyro", "°/s", 1.0, "unknown IMU")
    add("imucal Ferraris session (102.4 Hz)", imucal, "accel", "m/s²", 1.0, "unknown IMU")
    for label, report in (
        ("Xsens first 50 s", first),
        ("Xsens", whole),
        ("ICM-20948", icm),
        ("imucal", imucal),
    ):
        notes.extend(f"{label}: {note}" for note in report.notes)
    return "\n".join(rows), notes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes; write nothing")
    args = parser.parse_args()
    started = time.perf_counter()
    with pin_blas_threads():
        table_recovery, recovery_notes = recovery(args.quick)
        print(table_recovery, *recovery_notes, sep="\n")
        table_speed, agreement = speed(args.quick)
        print(table_speed, agreement, sep="\n")
        table_real, real_notes = real_logs()
        print(table_real, *real_notes, sep="\n")
    minutes = (time.perf_counter() - started) / 60
    if args.quick:
        return
    markdown = f"""
## Noise (`benchmarks/noise.py`)

{stamp("python benchmarks/noise.py")}
`fieldcal.noise.characterise_noise` and `fieldcal.stats.allan` ([docs/noise.md](noise.md)):
the overlapping Allan deviation over the still stretches, and the fit of
σ²(τ) = N²/τ + B²·(2 ln 2/π) + K²τ/3 by weighted least squares, with sandwich standard errors
from the correlation of the estimates across τ. BLAS pinned to one thread. Run time
{minutes:.1f} min.

**Recovery and coverage** on simulated records at {RATE:g} Hz (independent axes; white noise of
density N, flicker whose Allan deviation is flat at 0.664 B, rate random walk K; units
arbitrary). "within kσ": the share of estimates within k of their own standard errors of the
truth (68 % and 95 % expected). For a zero truth the standard error is the detection scale
√σ(p²).

{table_recovery}

**Speed** (median of 3, one run at 10⁷):

{table_speed}

{agreement}.

**Real logs** (N: the white-noise density, the −½ line at τ = 1 s; K: the rate random walk,
"< x": not resolved, its 2σ upper bound; datasheet figures are typical values):

{table_real}

{chr(10).join("- " + n for n in real_notes)}
- Xsens datasheet: the IMU-TK data do not name the unit; raw 16-bit ADC counts are the legacy
  MTi/MTx output. Its manual (MT0100P) lists 0.04 °/s/√Hz (±150 °/s gyroscopes), 0.1 °/s/√Hz
  (±1200 °/s, MTx default), 0.004 m/s²/√Hz (±18 g); the default-range figures in its Table 1
  were not read here (0.05 °/s/√Hz and 0.002 m/s²/√Hz are the figures usually quoted).
- ICM-20948 session 3 is hand-held with pauses: its rests are short (seconds) and not
  perfectly still, so N is an upper bound of the chip's noise and no random walk can be
  resolved; N also scales with the assumed rate as 1/√rate (±5 % for 27 ± 3 Hz).
"""
    write_section("noise", markdown)
    print(f"wrote the noise section of docs/benchmarks.md ({minutes:.1f} min)")


if __name__ == "__main__":
    main()
