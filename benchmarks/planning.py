"""Planning benchmark: how many poses does a user need to reach a target when following the
planner (``fieldcal.planning.next_pose``), random orientations, or the classic six-face protocol?

For each simulated device (truth drawn as in Table 1 of the seed paper with a realistic dip,
noise and pose-level noise, below) and each strategy, poses are added one at a time; from the
8th on the session is calibrated (``fieldcal.calibrate``, default options) after every pose,
until the calibration reports ``cal.dip_std_deg ≤ 0.1°`` and ``cal.accuracy.heading_deg ≤
0.5°`` or the cap is reached. The user holds the device as told with an error of a few degrees
(``--hand`` per axis, 1σ). Strategies:

- planner: :func:`first_poses` (raw pose means, directions only) until 8 poses (and while the
  calibration fails its verdict), then :func:`plan_poses` (``k=1``) on the current calibration
  after every pose;
- random: rotations drawn uniformly on SO(3);
- six faces: the 6 faces at heading north, then again at east, south, west, and round again;
- starter, then random: :func:`first_poses` for the first 8 poses, random ones after (how much
  of the planner's gain is its first 8 poses).

Every strategy sees the same devices, the same sample noise and pose-level offsets (common
random numbers; the pose's own draws depend only on device and pose number).

    python benchmarks/planning.py                   # 200 devices, writes the planning section
    python benchmarks/planning.py --devices 20 --no-docs
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _report import pin_blas_threads, stamp, write_section

import fieldcal
from fieldcal.errors import InputError
from fieldcal.geometry.orientations import CANDIDATES
from fieldcal.geometry.rotations import exp_so3, random_rotations
from fieldcal.planning.next_pose import Targets, first_poses, floor, plan_poses

Array = NDArray[np.float64]

#: The target, as the calibration reports it.
DIP_TARGET = 0.1
HEADING_TARGET = 0.5
#: What the planner is asked for: the same (no tilt target in this study: 90°).
TARGETS = Targets(heading_deg=HEADING_TARGET, tilt_deg=90.0, dip_deg=DIP_TARGET)
MIN_POSES = 8
#: The pose-level noise is drawn relative to the white noise of a mean of this many samples.
WHITE_SAMPLES = 100
STRATEGIES = ("planner", "random", "six faces", "starter, then random")


@dataclass
class Device:
    """One simulated device: the truth (fieldcal's gauge) and its pose-level noise."""

    truth: fieldcal.Calibration
    q: dict[str, float]
    seed: int

    def with_true_pose_noise(self) -> fieldcal.Calibration:
        """The truth with its pose-level noise, for :func:`floor`."""
        sensors = {
            n: dataclasses.replace(self.truth.sensor(n), pose_noise_std=self.q[n])
            for n in ("accel", "mag")
        }
        return dataclasses.replace(self.truth, **sensors)


def draw_device(seed: int, q_factor: tuple[float, float]) -> Device:
    """Table 1 gains and magnetometer biases, accelerometer biases ±0.05, dip 40-75°,
    per-sample noise α ~ U[1e-5, 1e-4] (Eq. 18), and
    pose-level noise ``q`` of 0-``q_factor`` times the white level of a 100-sample mean."""
    s = fieldcal.simulate(
        "paper", seed=seed, n_poses=1, dip_deg=(40.0, 75.0), noise_alpha=(1e-5, 1e-4)
    )
    rng = np.random.default_rng([seed, 1])
    # Table 1's biases (±1 field unit) suit hard iron; an accelerometer's offset is a few
    # hundredths of g
    truth = s.truth
    accel = dataclasses.replace(truth.sensor("accel"), bias=rng.uniform(-0.05, 0.05, 3))
    truth = dataclasses.replace(truth, accel=accel)
    q = {}
    for name in ("accel", "mag"):
        white = float(np.sqrt(np.trace(s.truth.sensor(name).noise_cov) / 3 / WHITE_SAMPLES))
        q[name] = float(rng.uniform(*q_factor)) * white
    return Device(truth, q, seed)


def record(device: Device, R: Array, pose: int, samples: int) -> tuple[Array, Array]:
    """Raw samples of one still pose at rotation ``R`` (world → body)."""
    rng = np.random.default_rng([device.seed, 2, pose])
    out = []
    for name in ("accel", "mag"):
        sc = device.truth.sensor(name)
        mean = sc.predict(R[None], device.truth.reference(name))[0]
        offset = rng.standard_normal(3) * device.q[name]
        L = np.linalg.cholesky(sc.noise_cov)
        out.append(mean + offset + rng.standard_normal((samples, 3)) @ L.T)
    return out[0], out[1]


def held(device: Device, R: Array, pose: int, hand_deg: float) -> Array:
    """The rotation a person actually holds when told ``R``: a few degrees off."""
    rng = np.random.default_rng([device.seed, 3, pose])
    return exp_so3(np.radians(hand_deg) * rng.standard_normal(3)) @ R


def calibrate(accel: list[Array], mag: list[Array]) -> fieldcal.Calibration | None:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return fieldcal.calibrate(accel, mag)
    except ValueError:  # degenerate or too few poses so far: keep recording
        return None


def reached(cal: fieldcal.Calibration | None) -> bool:
    if cal is None or cal.accuracy is None or cal.accuracy.heading_deg is None:
        return False
    dip = cal.dip_std_deg
    return dip is not None and dip <= DIP_TARGET and cal.accuracy.heading_deg <= HEADING_TARGET


FACES = [c for c in CANDIDATES if c.kind == "face"]


def six_faces(n: int) -> Array:
    """The n-th pose of the classic protocol: 6 faces at north, then at east, south, west."""
    heading = 90.0 * ((n // 6) % 4)
    faces = [c for c in FACES if c.heading_deg == heading]
    return faces[n % 6].rotation


def run(
    device: Device, strategy: str, samples: int, cap: int, hand_deg: float
) -> tuple[int | None, float]:
    """Poses needed to reach the target (None: not within ``cap``) and seconds spent planning."""
    accel: list[Array] = []
    mag: list[Array] = []
    cal = None
    planning = 0.0
    rng = np.random.default_rng([device.seed, 4])
    for n in range(cap):
        if strategy == "random" or (strategy == "starter, then random" and n >= MIN_POSES):
            R = random_rotations(1, rng)[0]
        elif strategy == "starter, then random":
            means_a = np.array([a.mean(axis=0) for a in accel]).reshape(-1, 3)
            means_m = np.array([m.mean(axis=0) for m in mag]).reshape(-1, 3)
            R = first_poses(means_a, means_m)[0].rotation
        elif strategy == "six faces":
            R = six_faces(n)
        else:
            t0 = time.perf_counter()
            R = None
            if cal is not None and cal.verdict is not None and cal.verdict.level != "fail":
                try:
                    R = plan_poses(cal, targets=TARGETS, samples=samples)[0].rotation
                except InputError:
                    R = None
            if R is None:  # no usable calibration yet: the starter order
                means_a = np.array([a.mean(axis=0) for a in accel]).reshape(-1, 3)
                means_m = np.array([m.mean(axis=0) for m in mag]).reshape(-1, 3)
                R = first_poses(means_a, means_m)[0].rotation
            planning += time.perf_counter() - t0
        a, m = record(device, held(device, R, n, hand_deg), n, samples)
        accel.append(a)
        mag.append(m)
        if n + 1 >= MIN_POSES:
            cal = calibrate(accel, mag)
            if reached(cal):
                return n + 1, planning
    return None, planning


def summary(needed: list[int | None], cap: int) -> dict[str, float]:
    """Median and quartiles (never reached counted as above the cap), and the share never."""
    values = np.array([cap + 1 if v is None else v for v in needed], dtype=float)
    q1, med, q3 = np.percentile(values, [25, 50, 75])
    return {
        "q1": q1,
        "median": med,
        "q3": q3,
        "never": float(np.mean([v is None for v in needed])),
        "mean_reached": float(np.mean([v for v in needed if v is not None]))
        if any(v is not None for v in needed)
        else float("nan"),
    }


def fmt(value: float, cap: int) -> str:
    return f"> {cap}" if value > cap else f"{value:g}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--devices", type=int, default=200)
    parser.add_argument("--samples", type=int, default=50, help="samples per pose")
    parser.add_argument("--cap", type=int, default=30, help="most poses a user records")
    parser.add_argument("--hand", type=float, default=3.0, help="holding error, deg per axis")
    parser.add_argument("--q-factor", type=float, default=3.0, help="pose noise up to x white")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-docs", action="store_true", help="print only")
    args = parser.parse_args()
    pin_blas_threads()
    started = time.perf_counter()
    needed: dict[str, list[int | None]] = {s: [] for s in STRATEGIES}
    plan_time: list[float] = []
    plan_calls = 0
    floored = 0  # devices whose true pose-level noise alone exceeds the heading target
    for d in range(args.devices):
        device = draw_device(args.seed + d, (0.0, args.q_factor))
        floored += floor(device.with_true_pose_noise()).heading_deg > HEADING_TARGET
        for strategy in STRATEGIES:
            n, spent = run(device, strategy, args.samples, args.cap, args.hand)
            needed[strategy].append(n)
            if strategy == "planner":
                plan_time.append(spent)
                plan_calls += n if n is not None else args.cap
        if (d + 1) % 20 == 0:
            print(f"{d + 1} devices, {time.perf_counter() - started:.0f} s", file=sys.stderr)
    elapsed = time.perf_counter() - started
    stats = {s: summary(needed[s], args.cap) for s in STRATEGIES}
    paired = [
        (p, r)
        for p, r in zip(needed["planner"], needed["random"], strict=True)
        if p is not None and r is not None
    ]
    ratio = stats["planner"]["median"] / stats["random"]["median"]
    start = [
        (p, r)
        for p, r in zip(needed["planner"], needed["starter, then random"], strict=True)
        if p is not None and r is not None
    ]
    start_ratio = float(np.median([p / r for p, r in start])) if start else float("nan")
    paired_ratio = float(np.median([p / r for p, r in paired])) if paired else float("nan")
    rows = [
        f"| {s} | {fmt(stats[s]['q1'], args.cap)} | {fmt(stats[s]['median'], args.cap)} | "
        f"{fmt(stats[s]['q3'], args.cap)} | {stats[s]['mean_reached']:.1f} | "
        f"{stats[s]['never']:.1%} |"
        for s in STRATEGIES
    ]
    given = [
        f"--{name.replace('_', '-')} {value:g}"
        for name, value in vars(args).items()
        if name != "no_docs" and value != parser.get_default(name)
    ]
    command = " ".join(["python benchmarks/planning.py", *given])
    text = "\n".join(
        [
            "## Planning (`benchmarks/planning.py`)",
            "",
            stamp(command),
            f"{args.devices} simulated devices (Table 1 gains and magnetometer biases, "
            "accelerometer biases ±0.05 g, dip 40-75°, per-sample noise α ~ U[1e-5, 1e-4] of "
            "Eq. 18, pose-level noise 0-"
            f"{args.q_factor:g}× the white level of a {WHITE_SAMPLES}-sample mean), "
            f"{args.samples} samples per "
            f"pose, the device held {args.hand:g}° (1σ per axis) off the orientation asked for. "
            "After every pose from the 8th, `fieldcal.calibrate` (default options); the target "
            f"is reached when the calibration reports `dip_std_deg ≤ {DIP_TARGET}` and "
            f"`accuracy.heading_deg ≤ {HEADING_TARGET}`; at most {args.cap} poses "
            f"(never reached counts as > {args.cap} in the quartiles). Strategies: *planner* "
            "`first_poses` (raw means) until a calibration passes or warns, then `plan_poses` "
            "(k = 1) after every pose; *random* uniform on SO(3); *six faces* the faces at "
            "north, then east, south, west, round again; *starter, then random* `first_poses` "
            "for 8 poses, random after. Same devices, sample noise and pose offsets for all.",
            "",
            "| strategy | poses needed: 25 % | median | 75 % | mean (reached) | never reached |",
            "|---|---|---|---|---|---|",
            *rows,
            "",
            f"Planner / random, medians: {ratio:.2f} ({1 - ratio:.0%} fewer poses); median of the "
            f"per-device ratios where both reached: {paired_ratio:.2f} ({len(paired)} devices); "
            f"planner / (starter, then random), per device: {start_ratio:.2f} "
            f"({len(start)} devices). 'mean (reached)': mean over the devices that reached it. "
            f"Devices whose true pose-level noise alone gives a heading error above "
            f"{HEADING_TARGET}° (`floor`, unreachable by any strategy): {floored} "
            f"({floored / args.devices:.1%}). "
            f"Planning time per pose (first_poses or plan_poses): "
            f"{1e3 * sum(plan_time) / max(plan_calls, 1):.1f} ms mean. "
            f"Run time {elapsed / 60:.1f} min.",
        ]
    )
    print(text)
    if not args.no_docs:
        write_section("planning", text)


if __name__ == "__main__":
    main()
