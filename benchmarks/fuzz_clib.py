"""Fuzz the generated C library (issue 35 item 5): random and adversarial operation scripts
driven through ``tests/_clib_fuzz.py``'s driver, built with AddressSanitizer and
UndefinedBehaviorSanitizer, the invariants checked after every call (the estimator's and the
monitor's state finite; ``fieldcal_save`` writes exactly what ``fieldcal_check`` accepts and
what it writes loads back bit for bit; a refused ``fieldcal_load`` leaves the calibration as it
was; an apply is finite or NaN with an error code).

Inputs per call, drawn from a seeded generator: clean body-frame samples of a simulated IMU in
many orientations; the same with one axis replaced by NaN, ±inf, ±1e20, ±1e30, ±FLT_MAX, a
denormal, 0 or any float32 bit pattern; scaled by 1e-30 … 1e30; shifted (a hard iron); blobs
with bit flips (CRC re-sealed or not), absurd floats or flags re-sealed with a valid CRC,
truncated; widen with any float; a float of the calibration in RAM overwritten (then save must
refuse what check refuses). Prints the table row for docs/benchmarks.md.

    python benchmarks/fuzz_clib.py                  # 40 scripts x 2,500 calls
    python benchmarks/fuzz_clib.py --scripts 4 --calls 500
"""

from __future__ import annotations

import argparse
import platform
import shutil
import struct
import sys
import tempfile
import time
import zlib
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import _clib_fuzz as fz

import fieldcal
from fieldcal.output.exports import c_library

BAD = np.array(
    [np.nan, np.inf, -np.inf, 1e20, -1e20, 1e30, -1e30, 3.4e38, -3.4e38, 1e-40, -1e-45, 0.0],
    dtype=np.float32,
)


def _float(rng: np.random.Generator) -> float:
    if rng.random() < 0.5:
        return float(BAD[rng.integers(len(BAD))])
    return float(np.frombuffer(struct.pack("<I", int(rng.integers(2**32))), "<f4")[0])


def _vector(rng, base: np.ndarray) -> np.ndarray:
    kind = rng.integers(6)
    v = base.astype(float).copy()
    if kind == 1:
        v[rng.integers(3)] = _float(rng)
    elif kind == 2:
        v *= float(10.0 ** rng.choice([-30, -3, 0, 1, 3, 30])) * rng.uniform(0.3, 2.0)
    elif kind == 3:
        v = np.array([_float(rng) for _ in range(3)])
    elif kind == 4:
        v += rng.uniform(-0.08, 0.08, size=3)
    return v


def _reseal(blob: bytes) -> bytes:
    return blob[:-4] + struct.pack("<I", zlib.crc32(blob[:-4]))


def _blob(rng, blob: bytes) -> bytes:
    out = bytearray(blob)
    kind = rng.integers(7)  # 5, 6: the factory's blob, intact
    if kind == 0:
        for _ in range(rng.integers(1, 5)):
            bit = int(rng.integers(8 * len(out)))
            out[bit // 8] ^= 1 << (bit % 8)
        return _reseal(bytes(out)) if rng.random() < 0.5 else bytes(out)
    if kind in (1, 2):
        for _ in range(rng.integers(1, 5)):
            i = int(rng.integers((len(blob) - 20) // 4))
            out[16 + 4 * i : 20 + 4 * i] = struct.pack("<f", _float(rng))
        return _reseal(bytes(out))
    if kind == 3:
        out[12:16] = struct.pack("<I", int(rng.integers(2**32)))
        return _reseal(bytes(out))
    if kind == 4:
        return bytes(out[: rng.integers(len(out))])
    return blob


def script(rng, a, m, blob: bytes, sid: int, calls: int) -> bytes:
    parts = []
    for _ in range(calls):
        k = int(rng.integers(13)) if rng.random() < 0.97 else 13  # RAM overwritten: rarely
        i = int(rng.integers(len(a)))
        if k <= 4:
            parts.append(fz.update(fz.UPDATE, _vector(rng, a[i]), _vector(rng, m[i])))
        elif k <= 6:
            parts.append(fz.update(fz.MONITOR, a[i], _vector(rng, m[i])))
        elif k == 7:
            parts.append(fz.widen(_float(rng) if rng.random() < 0.5 else rng.uniform(0, 0.1)))
        elif k == 8:
            parts.append(bytes([int(rng.choice([fz.FOLD, fz.SAVE, fz.INIT]))]))
        elif k == 9:
            parts.append(fz.load(_blob(rng, blob), sid if rng.random() < 0.9 else sid ^ 1))
        elif k == 10:
            parts.append(fz.apply(int(rng.integers(3)), _vector(rng, a[i])))
        elif k == 11:
            parts.append(fz.update(fz.HEADING, _vector(rng, a[i]), _vector(rng, m[i])))
        elif k == 12:
            parts.append(fz.three(int(rng.choice([fz.TILT, fz.HI_APPLY])), _vector(rng, m[i])))
        else:
            parts.append(
                fz.poke(int(rng.integers(256)), _float(rng))
                if rng.random() < 0.8
                else fz.flags(int(rng.integers(2**32)))
            )
    return b"".join(parts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scripts", type=int, default=40)
    parser.add_argument("--calls", type=int, default=2500)
    parser.add_argument("--seed", type=int, default=35)
    args = parser.parse_args()
    cc = shutil.which("cc")
    if cc is None:
        sys.exit("no C compiler (cc)")
    session = fieldcal.simulate("paper", seed=35, n_poses=24, dip_deg=(58.0, 62.0))
    cal = fieldcal.calibrate(session.accel, session.mag)
    a = cal.correct_accel(np.concatenate([p[::4] for p in session.accel]))
    m = cal.correct_mag(np.concatenate([p[::4] for p in session.mag]))
    blob = c_library.blob(cal)
    sid = c_library.sensor_id_of(cal)
    counts: Counter[str] = Counter()
    started = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp:
        reason = fz.sanitizers_missing(cc, Path(tmp))
        if reason is not None:
            sys.exit(reason)
        driver = fz.Driver(cal, Path(tmp) / "lib")
        for k in range(args.scripts):
            rng = np.random.default_rng([args.seed, k])
            (init_rc, check_rc), steps = driver.run(script(rng, a, m, blob, sid, args.calls))
            assert init_rc == 0 and check_rc == 0
            counts.update(fz.check(steps))
    calls = sum(counts.values())
    used = counts["hardiron_update -> 1"]
    loads = sum(v for k, v in counts.items() if k.startswith("load"))
    loaded = counts["load -> 0"]
    saves = sum(v for k, v in counts.items() if k.startswith("save"))
    refused_saves = counts["save -> -6"]
    folds = sum(v for k, v in counts.items() if k.startswith("hardiron_fold"))
    print(
        f"# {platform.node()} {platform.machine()}, {time.strftime('%Y-%m-%d')}, "
        f"wall {time.monotonic() - started:.0f} s, seed {args.seed}"
    )
    for key in sorted(counts):
        print(f"  {key}: {counts[key]}")
    print(
        f"| C library (`benchmarks/fuzz_clib.py --scripts {args.scripts} --calls {args.calls}`) "
        f"| {args.scripts} scripts, {calls:,} calls under ASan+UBSan: hard-iron updates "
        f"{sum(v for k, v in counts.items() if k.startswith('hardiron_update')):,} ({used:,} "
        f"used), loads {loads:,} ({loaded:,} accepted), saves {saves:,} ({refused_saves:,} "
        f"refused), folds {folds:,} | state finite after every call, save ⇒ load bit for bit, "
        "refused load ⇒ target unchanged, apply finite or NaN with an error code | 0 violations, "
        "0 sanitizer reports |"
    )


if __name__ == "__main__":
    main()
