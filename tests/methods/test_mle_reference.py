"""The numbers of ``fieldcal.calibrate`` held fixed while its speed work goes on (issue 24,
item 3): Table 1 sessions (default path and the seed's model) and 24-shot sets, compared with
the numbers stored in ``tests/data/mle_reference.json`` before that work, to 1e-9 relative.

A speed change (fused fits, reused statistics, selection instead of sorting) must give the same
answer up to rounding: 1e-9 of a value's scale is ~10⁶ times double rounding, and ~10⁻⁶ of the
Table 1 standard errors (≈ 10⁻³ of the gains), so a real change of the estimate cannot hide in
it. The scale of each compared group is its largest magnitude (a bias of 10⁻⁵ next to one of
0.2 is compared at 0.2 · 10⁻⁹).

Regenerate (only when a result is meant to change, saying why in the commit)::

    python tests/methods/test_mle_reference.py --write
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import fieldcal

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = ROOT / "tests" / "data" / "mle_reference.json"
sys.path.insert(0, str(ROOT / "benchmarks"))

from _small_sets import shots  # noqa: E402

RTOL = 1e-9

#: case name → (session, calibrate's options)
CASES = {
    **{f"paper{seed}/default": ("paper", seed, {}) for seed in range(3)},
    **{
        f"paper{seed}/seed-model": ("paper", seed, {"pose_noise": "none", "robust": False})
        for seed in range(3)
    },
    **{f"shots{seed}/default": ("shots", seed, {}) for seed in range(2)},
}


def _calibrate(kind: str, seed: int, options: dict[str, object]) -> fieldcal.Calibration:
    if kind == "paper":
        s = fieldcal.simulate("paper", seed=seed)
        return fieldcal.calibrate(s.accel, s.mag, **options)  # type: ignore[arg-type]
    accel, mag = shots(24, seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # small-set notes are not what is compared here
        return fieldcal.calibrate(accel, mag, **options)  # type: ignore[arg-type]


def numbers(cal: fieldcal.Calibration) -> dict[str, object]:
    """The compared numbers: parameters, their variances, cost, predicted accuracy,
    and which poses were rejected and the verdict (compared exactly)."""
    out: dict[str, object] = {
        f"{s}_{p}": np.asarray(getattr(cal.sensor(s), p), dtype=float).ravel().tolist()
        for s in ("accel", "mag")
        for p in ("gain", "bias")
    }
    out["dip_deg"] = [float(cal.dip_deg or 0.0)]
    out["cost"] = [float(cal.cost)]
    if cal.covariance is not None:
        out["variances"] = np.diag(np.asarray(cal.covariance.matrix, dtype=float)).tolist()
    if cal.accuracy is not None:
        acc = cal.accuracy
        out["accuracy"] = [
            acc.tilt_deg,
            acc.heading_deg,
            acc.accel_norm_rel,
            acc.mag_norm_rel,
        ]
    out["rejected"] = sorted(int(r.index) for r in cal.rejected)
    out["verdict"] = cal.verdict.level if cal.verdict is not None else None
    return out


def _compare(got: dict[str, object], want: dict[str, object]) -> list[str]:
    problems = []
    for key, ref in want.items():
        value = got.get(key)
        if key in ("rejected", "verdict"):
            if value != ref:
                problems.append(f"{key}: {value} != {ref}")
            continue
        a, b = np.asarray(value, dtype=float), np.asarray(ref, dtype=float)
        if a.shape != b.shape:
            problems.append(f"{key}: shape {a.shape} != {b.shape}")
            continue
        scale = float(np.max(np.abs(b))) if b.size else 0.0
        worst = float(np.max(np.abs(a - b))) if b.size else 0.0
        if worst > RTOL * scale:
            problems.append(f"{key}: off by {worst:.3g} (allowed {RTOL * scale:.3g})")
    return problems


@pytest.fixture(scope="module")
def reference() -> dict[str, dict[str, object]]:
    data: dict[str, dict[str, object]] = json.loads(REFERENCE.read_text(encoding="utf-8"))
    return data


@pytest.mark.parametrize("case", list(CASES))
def test_the_numbers_stay_as_they_were(case, reference):
    kind, seed, options = CASES[case]
    assert _compare(numbers(_calibrate(kind, seed, options)), reference[case]) == []


def test_the_comparison_sees_a_change_of_1e_8(reference):
    """The check can fail: one gain nudged by 1e-8 relative is caught, rounding is not."""
    want = reference["paper0/default"]
    got = dict(want)
    gain = np.asarray(want["accel_gain"], dtype=float)
    got["accel_gain"] = (gain * (1 + 1e-8)).tolist()
    assert _compare(got, want) != []
    got["accel_gain"] = (gain * (1 + 1e-13)).tolist()
    assert _compare(got, want) == []


if __name__ == "__main__" and "--write" in sys.argv:
    table = {case: numbers(_calibrate(*CASES[case])) for case in CASES}
    lines = ",\n".join(f" {json.dumps(case)}: {json.dumps(table[case])}" for case in table)
    REFERENCE.write_text("{\n" + lines + "\n}\n", encoding="utf-8")
    print(f"wrote {REFERENCE}: {len(table)} cases")
