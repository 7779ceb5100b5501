"""The run-time monitor of the C library (``fieldcal_monitor_update``): how early it alarms on
a growing hard iron, and how often on a clean field (issue 35 item 2; docs/microcontroller.md).

The device: the simulated IMU of ``tests/output/test_c_library.py`` (20 poses calibrated, noise
about 0.5 % of the field per sample, a pose-level error of 0.1 %, dip about 60°), moved as a hand
does (roll and pitch within ±30°, the heading wandering; 100 Hz). Its readings are corrected in
Python (float32, as ``fieldcal_accel``/``fieldcal_mag``) and fed to the compiled library's
monitor by a small C driver.

- *ramps*: a hard iron growing linearly from 0 to ``s`` (uniform in 0.5-5 % of the field, a
  random direction) over 160 s (16,000 samples); the worst-case heading error at the first
  alarm is ``asin(|β|/H)`` (``β`` the shift then, ``H`` the field's horizontal part: the
  heading error ``β`` makes when it is horizontal and across the field); a ramp that never
  alarms counts with the heading error at its end.
- *clean*: the same motion with no shift (false alarms per block), and the device at rest in
  random orientations (the blocks of one rest share its pose-level error: the monitor's
  worst case for false alarms).

    python benchmarks/monitor_alarm.py                 # 200 ramps, 20 clean runs, 200 rests
    python benchmarks/monitor_alarm.py --ramps 40 --clean 4 --rests 40
"""

from __future__ import annotations

import argparse
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from _clib import hand_motion, hand_session, hand_stream

import fieldcal
from fieldcal.output.exports import c_library, export_files

DRIVER = r"""
#include "fieldcal_cal.h"
#include <stdio.h>
#include <stdlib.h>
int main(int argc, char **argv)
{
    fieldcal_monitor_t mon;
    fieldcal_cal_t cal = FIELDCAL_FACTORY;
    float s[6];
    long i = 0;
    if (argc > 1) {
        cal.monitor_threshold = (float)atof(argv[1]);
    }
    fieldcal_monitor_init(&mon);
    while (fread(s, sizeof(float), 6, stdin) == 6) {
        const int st = fieldcal_monitor_update(&mon, &cal, s, s + 3);
        if (st == FIELDCAL_MONITOR_OK || st == FIELDCAL_MONITOR_ALARM) {
            printf("%ld %d %g\n", i, st, mon.statistic);
        }
        i++;
    }
    return 0;
}
"""


class Monitor:
    def __init__(
        self, cal, folder: Path, window: int | None = None, threshold: float | None = None
    ) -> None:
        self.threshold = [] if threshold is None else [repr(threshold)]
        for name, text in export_files(cal, "c-library").items():
            (folder / name).write_bytes(text)
        (folder / "drive.c").write_text(DRIVER)
        self.exe = folder / "drive"
        flags = [] if window is None else [f"-DFIELDCAL_MONITOR_WINDOW={window}"]
        cc = shutil.which("cc") or "cc"
        subprocess.run(
            [
                cc,
                "-std=c99",
                "-O2",
                *flags,
                f"-I{folder}",
                str(folder / "drive.c"),
                str(folder / "fieldcal_cal.c"),
                "-o",
                str(self.exe),
                "-lm",
            ],
            check=True,
        )
        self.cal = cal

    def run(self, raw_a, raw_m) -> np.ndarray:
        """(blocks, 3): sample index, status, statistic."""
        a = self.cal.correct_accel(raw_a)
        m = self.cal.correct_mag(raw_m)
        data = np.column_stack([a, m]).astype("<f4").tobytes()
        cmd = [str(self.exe), *self.threshold]
        out = subprocess.run(cmd, input=data, capture_output=True, check=True)
        return np.array([[float(x) for x in line.split()] for line in out.stdout.splitlines()])


def ramps(mon: Monitor, s, count: int, seed: int) -> dict[str, object]:
    F = float(np.linalg.norm(mon.cal.magnetic))
    H = F * np.cos(np.radians(mon.cal.dip_deg))
    n = 16_000
    worst, alarmed, sizes = [], 0, []
    for k in range(count):
        rng = np.random.default_rng([seed, k])
        size = rng.uniform(0.005, 0.05) * F
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        shift = np.linspace(0.0, size, n)[:, None] * direction
        raw_a, raw_m = hand_stream(s, hand_motion(n, rng), rng, shift)
        blocks = mon.run(raw_a, raw_m)
        alarm = blocks[blocks[:, 1] == 2]
        at = int(alarm[0, 0]) if len(alarm) else n - 1
        alarmed += bool(len(alarm))
        worst.append(np.degrees(np.arcsin(min(np.linalg.norm(shift[at]) / H, 1.0))))
        sizes.append(size / F)
    worst_a = np.array(worst)
    return {
        "ramps": count,
        "alarmed": alarmed,
        "worst_deg": float(worst_a.max()),
        "median_deg": float(np.median(worst_a)),
        "over_2deg": int((worst_a > 2.0).sum()),
        "sizes": (float(min(sizes)), float(max(sizes))),
    }


def clean(mon: Monitor, s, runs: int, rests: int, seed: int) -> dict[str, int]:
    blocks = alarms = 0
    for k in range(runs):
        rng = np.random.default_rng([seed, 1, k])
        raw_a, raw_m = hand_stream(s, hand_motion(16_000, rng), rng)
        out = mon.run(raw_a, raw_m)
        blocks += len(out)
        alarms += int((out[:, 1] == 2).sum())
    rest_blocks = rest_alarms = 0
    truth = s.truth
    for k in range(rests):
        rng = np.random.default_rng([seed, 2, k])
        R = Rotation.random(random_state=int(rng.integers(2**31)))
        n = 1600  # 16 s at rest: 100 blocks of one pose
        rot = Rotation.from_matrix(np.repeat(R.as_matrix()[None], n, axis=0))
        raw_a, raw_m = hand_stream(s, rot, rng)
        # the pose-level error of this rest: one offset for the whole rest, as the truth's
        for name, raw in (("accel", raw_a), ("mag", raw_m)):
            q = truth.sensor(name).pose_noise_std
            raw += rng.normal(scale=q, size=3) if q else 0.0
        out = mon.run(raw_a, raw_m)
        rest_blocks += len(out)
        rest_alarms += int((out[:, 1] == 2).sum())
    return {
        "blocks": blocks,
        "alarms": alarms,
        "rest_blocks": rest_blocks,
        "rest_alarms": rest_alarms,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ramps", type=int, default=200)
    parser.add_argument("--clean", type=int, default=20)
    parser.add_argument("--rests", type=int, default=200)
    parser.add_argument("--seed", type=int, default=35)
    parser.add_argument("--window", type=int, default=None, help="override W (experiments)")
    parser.add_argument("--threshold", type=float, default=None, help="override (experiments)")
    args = parser.parse_args()
    s = hand_session()
    cal = fieldcal.calibrate(s.accel, s.mag)
    _, _, fields = c_library.factory(cal)
    started = time.process_time()
    with tempfile.TemporaryDirectory() as folder:
        mon = Monitor(cal, Path(folder), args.window, args.threshold)
        r = ramps(mon, s, args.ramps, args.seed)
        c = clean(mon, s, args.clean, args.rests, args.seed)
    print(
        f"# {platform.node()} {platform.machine()} python {sys.version.split()[0]}, "
        f"{time.strftime('%Y-%m-%d')}, CPU {time.process_time() - started:.0f} s"
    )
    threshold = args.threshold or float(fields["monitor_threshold"][0])
    print(f"threshold {threshold:.3f}, window {args.window or 8} blocks of 16")
    print(
        f"ramps: {r['alarmed']}/{r['ramps']} alarmed; worst-case heading at the alarm: max "
        f"{r['worst_deg']:.2f} deg, median {r['median_deg']:.2f} deg, {r['over_2deg']} over 2 deg"
    )
    print(
        f"clean motion: {c['alarms']} alarms in {c['blocks']} blocks; at rest: "
        f"{c['rest_alarms']} alarms in {c['rest_blocks']} blocks"
    )


if __name__ == "__main__":
    main()
