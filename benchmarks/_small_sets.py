"""Part 6 of ``benchmarks/trust.py``: false alarms of the pose tests on small one-reading-per-pose
sets (issue 22: ≤ 1 % of clean 12-reading sessions may lose a pose).

Simulated: N single readings of a device with near-unit gains (accelerometer symmetric, 2 %
spread; magnetometer 5 %), a random dip of 20–70°, and pose-level noise only (the reading of an
averaged shot): ``q`` drawn log-uniformly from 10^-3.5 to 10^-2.5 of the field, independently
per sensor. Real: the sap6 instruments' 24-shot calibrations cut into two 12-shot halves
(even/odd shots, and random halves), each fitted alone.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import _real_sets as real
import numpy as np
from numpy.typing import NDArray

import fieldcal

Array = NDArray[np.float64]

#: Poses per simulated session, and sessions per size (the 12-pose row is the issue's).
SIZES = (8, 12, 16, 24)


def random_rotations(n: int, rng: np.random.Generator) -> Array:
    """``n`` rotations uniform on SO(3) (unit quaternions from a normal draw)."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def shots(n: int, seed: int) -> tuple[list[Array], list[Array]]:
    """One clean simulated set of ``n`` single readings (see the module docstring)."""
    rng = np.random.default_rng(seed)
    R = random_rotations(n, rng)
    dip = np.radians(rng.uniform(20, 70))
    g = np.array([0.0, 0.0, -1.0])
    h = np.array([np.cos(dip), 0.0, np.sin(dip)])
    Ka = np.eye(3) + 0.02 * rng.normal(size=(3, 3))
    Ka = (Ka + Ka.T) / 2
    Km = np.eye(3) + 0.05 * rng.normal(size=(3, 3))
    qa, qm = 10 ** rng.uniform(-3.5, -2.5, size=2)
    accel = [(Ka @ Ri @ g + 0.01 + qa * rng.normal(size=3))[None] for Ri in R]
    mag = [(Km @ Ri @ h + 0.2 + qm * rng.normal(size=3))[None] for Ri in R]
    return accel, mag


def _fit(accel: Any, mag: Any) -> fieldcal.Calibration | str:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return fieldcal.calibrate(accel, mag)
        except ValueError as exc:
            return str(exc)


def study_small_sets(sessions: int, seed: int, sizes: Sequence[int] = SIZES) -> dict[str, Any]:
    """Sessions that lose a pose, refusals and verdict codes, per size; and the sap6 halves."""
    rows = []
    for n in sizes:
        count = sessions if n == 12 else max(sessions // 2, 1)
        lost = refused = 0
        codes: dict[str, int] = {}
        for i in range(count):
            cal = _fit(*shots(n, seed + 1000 * n + i))
            if isinstance(cal, str):
                refused += 1
                continue
            lost += bool(cal.rejected)
            for code in set(cal.verdict.codes):
                codes[code] = codes.get(code, 0) + 1
        rows.append({"n": n, "sessions": count, "lost": lost, "refused": refused, "codes": codes})
        print(f"  {n} single readings: {lost}/{count} lost a pose, {refused} refused", flush=True)
    rng = np.random.default_rng(seed)
    real_rows = []
    for run in real.SAP6_RUNS:
        data = real.sap6(run)
        halves = [np.arange(0, 24, 2), np.arange(1, 24, 2)]
        for _ in range(10):
            p = rng.permutation(24)
            halves += [np.sort(p[:12]), np.sort(p[12:])]
        lost = refused = 0
        for half in halves:
            part = data.subset(half)
            cal = _fit(part.accel, part.mag)
            if isinstance(cal, str):
                refused += 1
            else:
                lost += bool(cal.rejected)
        whole = _fit(data.accel, data.mag)
        real_rows.append(
            {
                "run": run,
                "fits": len(halves),
                "lost": lost,
                "refused": refused,
                "whole": "refused" if isinstance(whole, str) else len(whole.rejected),
            }
        )
    return {"sim": rows, "real": real_rows}


def report_small_sets(res: dict[str, Any]) -> str:
    """The tables of :func:`study_small_sets` (Markdown)."""
    lines = [
        "| single readings N | sessions | lost a pose | refused | verdict codes (sessions) |",
        "|---|---|---|---|---|",
    ]
    for r in res["sim"]:
        codes = ", ".join(f"{k} {v}" for k, v in sorted(r["codes"].items())) or "none"
        share = 100 * r["lost"] / r["sessions"]
        lines.append(
            f"| {r['n']} | {r['sessions']} | {r['lost']} ({share:.1f} %) | {r['refused']} | "
            f"{codes} |"
        )
    lines += [
        "",
        "| sap6 run | 12-shot fits | lost a pose | refused | poses dropped in the 24-shot fit |",
        "|---|---|---|---|---|",
    ]
    for r in res["real"]:
        lines.append(f"| {r['run']} | {r['fits']} | {r['lost']} | {r['refused']} | {r['whole']} |")
    return "\n".join(lines)
