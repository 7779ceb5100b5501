"""One verdict from fixed rules: ``pass``, ``warn`` or ``fail``, with one line per reason.

A rule of level ``note`` adds its line without raising the level (a fact the user should
know that the data cannot settle, such as the sign of the dip).

Every rule is a code, a level and a fixed message (filled with numbers), listed in
:data:`RULES` and in ``docs/trust.md``; nothing here builds prose that is parsed later.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..calibration import Accuracy, Calibration, Verdict
from ..reference import FieldReference
from ..stats.poses import PoseStats

__all__ = ["RULES", "Findings", "ReferenceCheck", "judge"]

Array = NDArray[np.float64]

#: code -> (level, message template). Each message names the cause and the fix.
RULES: dict[str, tuple[str, str]] = {
    "not_converged": (
        "fail",
        "the optimiser did not converge ({detail}); record more orientations or raise the "
        "iteration limit",
    ),
    "degenerate": (
        "fail",
        "the poses barely determine the calibration (condition number {condition:.2g}); add "
        "poses with the body's {axis} axis pointing up and down",
    ),
    "too_many_rejected": (
        "fail",
        "{rejected} of {total} poses had to be dropped (more than a quarter); record the session "
        "again, away from iron and with the device held still",
    ),
    "unidentifiable": (
        "fail",
        "{flagged} further pose(s) disagree with the model but dropping them would leave too "
        "few to calibrate; record the session again, away from iron, device held still",
    ),
    "same_sensor": (
        "fail",
        "the magnetometer readings are an affine copy of the accelerometer's (relative residual "
        "{residual:.2g}); check that the magnetometer columns are not the accelerometer's",
    ),
    "not_rigid": (
        "fail",
        "the {sensor}'s pose means scatter about the best fit by {ratio:.1%} of the field beyond "
        "their noise; no rigid device at rest does that (pose labels mixing orientations, "
        "wrong columns, or motion): check the pose grouping and the columns",
    ),
    "unusable": (
        "fail",
        "the calibration is too uncertain to use (predicted {what} error {value}); record more "
        "poses, still and away from iron, covering every axis up and down",
    ),
    "rejected": (
        "warn",
        "{count} pose(s) dropped as disturbed ({which}); see `rejected` for each and why",
    ),
    "trimmed": (
        "warn",
        "{share:.0%} of the {sensor}'s samples were cut as not still ({poses} poses); rows of "
        "another orientation inside a pose, or motion at the pose edges: check the pose "
        "labels or shorten the still intervals",
    ),
    "pose_noise": (
        "warn",
        "the {sensor}'s pose-to-pose error is {ratio:.1f}x its per-sample noise: "
        "poses not really still, or a magnetically busy site; rest the device on a firm "
        "support away from iron",
    ),
    "coverage": (
        "warn",
        "the poses cover the orientations poorly (the body's {axis} axis rarely points up or "
        "down); add such poses for a better calibration",
    ),
    "negative_dip": (
        "note",
        "the dip came out negative ({dip:.1f}°): right in the southern magnetic hemisphere; "
        "otherwise the magnetometer is mirrored (--mag-mirrored) or the accelerometer reports "
        "gravity instead of specific force (--accel-sign gravity)",
    ),
    "reference_mirrored": (
        "warn",
        "the magnetometer came out mirrored relative to the accelerometer to match the "
        "{model}'s dip at {place} ({expected:+.1f}°): if it is (as on an LSM9DS1), state "
        "--mag-mirrored; if it is not, the accelerometer reports gravity instead of specific "
        "force (--accel-sign gravity), or --location is in the wrong hemisphere",
    ),
    "reference_unmirrored": (
        "warn",
        "--mag-mirrored was stated, but the {model}'s dip at {place} ({expected:+.1f}°) makes "
        "the magnetometer right-handed relative to the accelerometer, and the reference decided: "
        "drop --mag-mirrored, or check --accel-sign and --location",
    ),
    "reference_undecided": (
        "note",
        "the dip at {place} ({expected:+.1f}° in the {model}, fitted {dip:+.1f}°) is too close "
        "to 0° to tell a mirrored magnetometer; its handedness follows --mag-mirrored",
    ),
    "reference_dip": (
        "warn",
        "the fitted dip {dip:.2f} ± {std:.2f}° differs from the {model}'s {expected:.2f} ± "
        "{ref_std:.2f}° at {place} on {date} by {diff:.1f}°, more than 3σ plus the "
        "{allowance:g}° allowed for local anomalies: a disturbed site (steel, magnets, "
        "electronics, reinforced concrete: calibrate outdoors away from them), a wrong "
        "--location or --date, an accelerometer reporting gravity (--accel-sign gravity) or a "
        "mirrored magnetometer (--mag-mirrored)",
    ),
    "not_ml": (
        "warn",
        "the {method} estimate's likelihood is far below the optimum (J exceeds the maximum "
        "likelihood fit's by {excess:.3g}, χ²({dof}) p = {p:.2g}); the mle method would be more "
        "accurate",
    ),
    "implausible": (
        "warn",
        "the fit is implausible under the stated noise (J = {cost:.4g} for χ²({dof}), p = "
        "{p:.2g}); let fieldcal estimate the pose-level noise (pose noise auto)",
    ),
}

#: Condition number of the Jacobi-scaled reduced system above which the poses are degenerate.
CONDITION_LIMIT = 1e10
#: A pose-level error this many times the per-sample noise draws a warning.
POSE_NOISE_RATIO = 3.0
#: Predicted errors beyond which a calibration is of no use (heading °, tilt °, relative norm).
UNUSABLE = {"heading_deg": 20.0, "tilt_deg": 10.0, "accel_norm_rel": 0.2, "mag_norm_rel": 0.2}
#: Share of a sensor's samples cut as not still above which the verdict warns.
TRIMMED = 0.05
#: Pose-level noise, relative to the field, that no rigid device at rest shows.
NOT_RIGID = 0.05
#: Smallest eigenvalue of the mean of ``u uᵀ`` over gravity directions for good coverage
#: (1/3 for directions spread evenly over the sphere).
COVERAGE = 0.04


@dataclass
class Findings:
    """What the trust path measured, for the rules."""

    n_total: int
    rejected: list[tuple[int, str]]
    unflagged_left: int
    condition: float
    excess: dict[str, object] | None


@dataclass(frozen=True)
class ReferenceCheck:
    """The World Magnetic Model's field for the verdict: the reference, the allowance for local
    anomalies (degrees of dip), the handedness the user stated and the one the reference decided
    (``None``: it could not)."""

    field: FieldReference
    allowance_deg: float
    stated_mirrored: bool
    decided_mirrored: bool | None


#: A fitted dip further than this many combined standard errors (plus the allowance) from the
#: model's draws a warning.
REFERENCE_SIGMAS = 3.0


def _reference_rules(
    add: Callable[..., None], dip: float, std: float | None, check: ReferenceCheck
) -> None:
    ref = check.field
    where = {"model": ref.model, "place": ref.place, "expected": ref.dip_deg}
    if check.decided_mirrored is None:
        add("reference_undecided", dip=dip, **where)
    elif check.decided_mirrored and not check.stated_mirrored:
        add("reference_mirrored", **where)
    elif not check.decided_mirrored and check.stated_mirrored:
        add("reference_unmirrored", **where)
    std = 0.0 if std is None else std
    diff = abs(dip - ref.dip_deg)
    if diff > REFERENCE_SIGMAS * math.hypot(std, ref.dip_std_deg) + check.allowance_deg:
        add(
            "reference_dip",
            dip=dip,
            std=std,
            ref_std=ref.dip_std_deg,
            diff=diff,
            date=ref.date,
            allowance=check.allowance_deg,
            **where,
        )


def _axis(directions: Array) -> str:
    _, V = np.linalg.eigh(directions.T @ directions / max(len(directions), 1))
    return "xyz"[int(np.argmax(np.abs(V[:, 0])))]


def _unit(x: Array) -> Array:
    return np.asarray(x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300))


def judge(
    cal: Calibration,
    stats: PoseStats,
    found: Findings,
    accuracy: Accuracy | None = None,
    reference: ReferenceCheck | None = None,
) -> Verdict:
    """Apply :data:`RULES` to a finished calibration; the worst level wins. ``accuracy``, when
    given, stands for ``cal.accuracy`` (so both can be attached in one step); ``reference``
    compares the dip with the World Magnetic Model's (its sign is then settled, so the
    negative-dip note is not given)."""
    reasons: list[tuple[str, str]] = []

    def add(code: str, **values: object) -> None:
        level, template = RULES[code]
        reasons.append((level, template.format(**values)))

    if not cal.converged:
        add("not_converged", detail=cal.message or f"{cal.iterations} iterations")
    sensors = stats.sensors
    first = sensors[0]
    body = {s: _unit(stats.sensor(s).means - cal.sensor(s).bias) for s in sensors}
    if found.condition > CONDITION_LIMIT:
        add("degenerate", condition=found.condition, axis=_axis(body[first]))
    if 4 * len(found.rejected) > found.n_total:
        add("too_many_rejected", rejected=len(found.rejected), total=found.n_total)
    if found.unflagged_left:
        add("unidentifiable", flagged=found.unflagged_left)
    if "accel" in sensors and "mag" in sensors and stats.n_poses >= 5:
        X = np.column_stack([stats.sensor("accel").means, np.ones(stats.n_poses)])
        Y = stats.sensor("mag").means
        coef, *_ = np.linalg.lstsq(X, Y, rcond=None)
        spread = np.linalg.norm(Y - Y.mean(axis=0))
        residual = float(np.linalg.norm(Y - X @ coef) / spread) if spread > 0 else 0.0
        if residual < 0.02:
            add("same_sensor", residual=residual)
    for s in sensors:
        sc = cal.sensor(s)
        radius = float(np.linalg.norm(sc.gain @ cal.reference(s)))
        if not radius > 0:
            continue
        if sc.pose_noise_std > NOT_RIGID * radius:
            add("not_rigid", sensor=s, ratio=sc.pose_noise_std / radius)
            continue
        cov = stats.sensor(s).cov
        sample = float(np.sqrt(np.trace(cov) / 3.0)) if cov is not None else 0.0
        if sample > 0 and sc.pose_noise_std > POSE_NOISE_RATIO * sample:
            add("pose_noise", sensor=s, ratio=sc.pose_noise_std / sample)
    for s in sensors:
        trimmed = stats.sensor(s).trimmed
        if trimmed is not None and trimmed.sum() > 0:
            share = float(trimmed.sum() / (trimmed.sum() + stats.sensor(s).counts.sum()))
            if share > TRIMMED:
                add("trimmed", share=share, sensor=s, poses=int(np.count_nonzero(trimmed)))
    accuracy = cal.accuracy if accuracy is None else accuracy
    if accuracy is not None:
        for what, limit in UNUSABLE.items():
            value = getattr(accuracy, what)
            if value is not None and not value <= limit:  # NaN counts as unusable
                shown = f"{value:.3g}°" if what.endswith("deg") else f"{value:.1%}"
                add("unusable", what=what.replace("_deg", "").replace("_rel", ""), value=shown)
                break
    if found.rejected:
        which = ", ".join(f"pose {i} ({kind})" for i, kind in found.rejected[:6])
        more = "" if len(found.rejected) <= 6 else f" and {len(found.rejected) - 6} more"
        add("rejected", count=len(found.rejected), which=which + more)
    directions = body[first]
    lowest = float(np.linalg.eigvalsh(directions.T @ directions / len(directions))[0])
    if lowest < COVERAGE:
        add("coverage", axis=_axis(directions))
    dip = cal.dip_deg
    if dip is not None and reference is not None:
        _reference_rules(add, dip, cal.dip_std_deg, reference)
    elif dip is not None and dip < 0:
        add("negative_dip", dip=dip)
    if found.excess is not None:
        add("not_ml", **found.excess)
    diag = cal.diagnostics
    if (
        diag is not None
        and diag.status == "ok"
        and diag.dof > 0
        and diag.p_value < 1e-4
        and not found.rejected
    ):
        add("implausible", cost=diag.statistic, dof=diag.dof, p=diag.p_value)
    order = {"fail": 2, "warn": 1, "note": 0}
    level = max((lv for lv, _ in reasons if lv != "note"), key=lambda lv: order[lv], default="pass")
    ranked = sorted(reasons, key=lambda r: -order[r[0]])
    return Verdict(level, tuple(text for _, text in ranked))
