"""One verdict from fixed rules: ``pass``, ``warn`` or ``fail``, with one :class:`Reason` per
finding.

A rule of level ``note`` adds its reason without raising the level (a fact the user should
know that the data cannot settle, such as the sign of the dip).

Every rule is a code with a fixed level and message in :data:`RULES` (filled with numbers; the
table in ``docs/trust.md``) and a small check in :data:`CHECKS` that says, for one
:class:`Case`, which codes fire and with what numbers. :func:`judge` runs the list. Nothing here
builds prose that is parsed later: scripts, tests and the batch table read ``Reason.code``.

Adding a rule: its entry in :data:`RULES`, a check function appended to :data:`CHECKS`, a row
in ``docs/trust.md`` and a test.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..calibration import Accuracy, Calibration, Reason, Verdict
from ..likelihood.temperature import MIN_SPAN_K
from ..reference import FieldReference
from ..stats.pose_stats import PoseStats
from .targets import DEFAULT_TARGETS, Targets

__all__ = [
    "CHECKS",
    "RULES",
    "Case",
    "Findings",
    "ReferenceCheck",
    "judge",
    "reason",
    "with_dropped_lines",
]

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
        "the calibration is too uncertain to use (predicted {what} error {value}, more than "
        "{factor:g}x the {target} target); record more poses, still and away from iron, "
        "covering every axis up and down",
    ),
    "accuracy": (
        "warn",
        "the predicted {what} error {value} is worse than the {target} target; record more "
        "poses, still and away from iron, covering every axis up and down (or set the target "
        "with --target-{option})",
    ),
    "untested": (
        "warn",
        "the fit certificate has {dof} degree(s) of freedom, too few ({minimum} or more) to "
        "test the model or find a disturbed pose; record {more} more pose(s) ({needed} in all)",
    ),
    "implausible_gain": (
        "warn",
        "the {sensor}'s gain is implausible for its sensor class ({what} {value:.3g}, more than "
        "{limit:.0%} off {expected}); check the columns, the units (--{option}) and that the "
        "device was still and rigid in every pose",
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
    "correlated_poses": (
        "note",
        "the poses are consecutive pieces of one continuous motion: neighbouring poses' "
        "residuals are correlated (τ = {tau:.3g} poses, about {effective:.0f} independent of "
        "{poses}), so the error bars are widened {widening:.2g}x and the fit certificate is "
        "not a test of the model; rests (still detection) give a real test",
    ),
    "temperature_span": (
        "note",
        "the poses' temperatures span {span:.1f} K ({low:.1f} to {high:.1f} °C): temperature "
        "terms need at least {need:g} K (power the board on cold and record poses while it "
        "warms); calibrated at the mean temperature {mean:.1f} °C",
    ),
    "implausible": (
        "warn",
        "the fit is implausible under the stated noise (J = {cost:.4g} for χ²({dof}), p = "
        "{p:.2g}); let fieldcal estimate the pose-level noise (pose noise auto)",
    ),
    "dropped_lines": (
        "warn",
        "{dropped} of {total} data lines ({share:.1%}) were dropped as unreadable ({which}); "
        "the samples between are missing: check the cable, the baud rate and that the device "
        "writes whole lines",
    ),  # continuous logs (fieldcal.trust.continuous_motion): gyroscope, field, turns
    "continuous_field_disturbed": (
        "fail",
        "the calibrated magnetic field's strength varies by {strength:.1%} RMS over the log "
        "(more than {limit:.0%}; dip spread {dip:.1f}° over {stretch:g}-s stretches): a "
        "magnet or iron that moves relative to the sensor, or a disturbed site; move away from "
        "the magnet (fix it rigidly or remove it) and record again",
    ),
    "gyro_units": (
        "fail",
        "the gyroscope's rates are {ratio:.3g}x the turning the magnetometer's direction shows "
        "(about 1 for rad/s, 57 for °/s): give the gyroscope in rad/s (°/s x 0.01745)",
    ),
    "gyro_gain_sign": (
        "fail",
        "the gyroscope's {axes} ax{plural} turned against the field sensors (gain {values}): "
        "an axis sign or mapping is wrong; check the gyroscope's columns and axis signs",
    ),
    "gyro_gain_scale": (
        "fail",
        "the gyroscope's scale came out {scale:.3g} (more than {limit:.0%} off 1 for rates in "
        "rad/s): check its units (rad/s) and columns",
    ),
    "gyro_misalignment": (
        "warn",
        "the gyroscope's {axis} axis is {angle:.2g} ± {std:.2g}° off the accelerometer's (more "
        "than {limit:g}°): mounted askew or a cross-axis error; check the axis mapping, or "
        "apply the fitted gain",
    ),
    "gyro_undetermined": (
        "note",
        "the log cannot determine the gyroscope's {axis} axis alignment to better than "
        "{std:.2g}° (1σ): turn about {axis} at a steady rate, then about the other axes",
    ),
    "continuous_fast_turns": (
        "warn",
        "the turns reach {rate:.3g} rad/s ({step:.2g} rad per sample{clipped}): the lever arm "
        "and the hand's translation grow with the rate and a sampled turn loses accuracy; "
        "slower turns",
    ),
}

#: Condition number of the Jacobi-scaled reduced system above which the poses are degenerate.
CONDITION_LIMIT = 1e10
#: A pose-level error this many times the per-sample noise draws a warning.
POSE_NOISE_RATIO = 3.0
#: A predicted error this many times its target fails the verdict (``unusable``); beyond the
#: target alone it warns (``accuracy``).
UNUSABLE_FACTOR = 5.0
#: Share of a sensor's samples cut as not still above which the verdict warns.
TRIMMED = 0.05
#: Share of a stream's data lines dropped as unreadable above which the verdict warns.
DROPPED_LINES = 0.01
#: Pose-level noise, relative to the field, that no rigid device at rest shows.
NOT_RIGID = 0.05
#: Smallest eigenvalue of the mean of ``u uᵀ`` over gravity directions for good coverage
#: (1/3 for directions spread evenly over the sphere).
COVERAGE = 0.04
#: Fewest certificate degrees of freedom that test the model (``untested`` below).
MIN_TEST_DOF = 10
#: Plausible gains, per sensor: the largest departure of the gain's scale from 1 (judged only
#: when the field's magnitude was given in the readings' unit) and of its shape (the symmetric
#: factor divided by its scale: axis scales and cross terms) from the identity. MEMS
#: accelerometers are within a few percent; magnetometers carry soft iron, so more is allowed.
GAIN_SCALE = {"accel": 0.2, "mag": 0.3}
GAIN_SHAPE = {"accel": 0.2, "mag": 0.5}
#: A gain scale inside this range (raw units per unit of the given magnitude) means the
#: readings are in the magnitude's unit (other units differ by 9.8 or more: g vs m/s², µT vs
#: gauss 100, LSB thousands); only then is the scale judged.
UNIT_RANGE = (0.5, 2.0)
#: The option that sets each field's magnitude, and each sensor's name in the gain messages.
MAGNITUDE_OPTION = {"accel": "gravity", "mag": "field-strength"}
SENSOR_NAME = {"accel": "accelerometer", "mag": "magnetometer"}


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


@dataclass(frozen=True)
class Case:
    """Everything the rules read: the finished calibration (in the fit's units), the pose
    statistics it was fitted to, the trust path's findings, the predicted accuracy, the Earth's
    field check, the targets, and ``magnitudes``: for each sensor whose field magnitude the user
    gave, ``(factor, given)`` — the factor that takes the fitted gain to the user's units
    (raw units per unit of the given magnitude) and the magnitude as given.

    ``stats`` and ``found`` are ``None`` for a calibration from continuous motion
    (:func:`fieldcal.trust.continuous_motion.trust_continuous`): the pose-level rules then do
    not apply, the others read the trajectory (``cal.rotations``) where they read poses."""

    cal: Calibration
    stats: PoseStats | None
    found: Findings | None
    accuracy: Accuracy | None = None
    reference: ReferenceCheck | None = None
    targets: Targets = DEFAULT_TARGETS
    magnitudes: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def sensors(self) -> tuple[str, ...]:
        """The sensors calibrated: the pose statistics', else the calibration's."""
        if self.stats is not None:
            return tuple(self.stats.sensors)
        return tuple(s for s in ("accel", "mag") if getattr(self.cal, s) is not None)

    def body_directions(self, sensor: str) -> Array:
        """The unit field directions in the body frame, per pose (continuous motion: per kept
        epoch of the trajectory, ``R_j`` applied to the sensor's reference field)."""
        if self.stats is None:
            x = np.asarray(self.cal.rotations) @ self.cal.reference(sensor)
        else:
            x = self.stats.sensor(sensor).means - self.cal.sensor(sensor).bias
        return np.asarray(x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300))


#: What a check yields: a code of :data:`RULES` and the numbers its message needs.
Fired = tuple[str, dict[str, object]]
Check = Callable[[Case], Iterator[Fired]]

#: A predicted error that a check compares with a target: (Accuracy attribute, what the
#: message calls it, Targets attribute, --target-* option, is it relative).
_ACCURACY = (
    ("tilt_deg", "tilt", "tilt_deg", "tilt", False),
    ("heading_deg", "heading", "heading_deg", "heading", False),
    ("accel_norm_rel", "|a|", "norm_pct", "norm", True),
    ("mag_norm_rel", "|m|", "norm_pct", "norm", True),
)


def _axis(directions: Array) -> str:
    _, V = np.linalg.eigh(directions.T @ directions / max(len(directions), 1))
    return "xyz"[int(np.argmax(np.abs(V[:, 0])))]


# ----------------------------------------------------------------------------- the checks
def _converged(case: Case) -> Iterator[Fired]:
    if not case.cal.converged:
        yield "not_converged", {"detail": case.cal.message or f"{case.cal.iterations} iterations"}


def _degenerate(case: Case) -> Iterator[Fired]:
    if case.stats is None or case.found is None:  # continuous: its identifiability check
        return
    if case.found.condition > CONDITION_LIMIT:
        axis = _axis(case.body_directions(case.stats.sensors[0]))
        yield "degenerate", {"condition": case.found.condition, "axis": axis}


def _rejections(case: Case) -> Iterator[Fired]:
    found = case.found
    if found is None:  # continuous: stretches are down-weighted, not dropped
        return
    if 4 * len(found.rejected) > found.n_total:
        yield "too_many_rejected", {"rejected": len(found.rejected), "total": found.n_total}
    if found.unflagged_left:
        yield "unidentifiable", {"flagged": found.unflagged_left}


def _same_sensor(case: Case) -> Iterator[Fired]:
    stats = case.stats
    if stats is None or not (
        "accel" in stats.sensors and "mag" in stats.sensors and stats.n_poses >= 5
    ):
        return
    # the affine least-squares fit of the magnetometer's means by the accelerometer's, centred
    # (the intercept is the means' difference): normal equations of a 3x3 system
    A = stats.sensor("accel").means
    Y = stats.sensor("mag").means
    A = A - A.sum(axis=0) / len(A)  # np.mean's numbers, without its wrapper
    Y = Y - Y.sum(axis=0) / len(Y)
    try:
        coef = np.linalg.solve(A.T @ A, A.T @ Y)
    except np.linalg.LinAlgError:  # accelerometer means on a plane: the general solver
        coef = np.linalg.lstsq(A, Y, rcond=None)[0]
    spread = float(np.sqrt(np.vdot(Y, Y)))
    residual = float(np.linalg.norm(Y - A @ coef) / spread) if spread > 0 else 0.0
    if residual < 0.02:
        yield "same_sensor", {"residual": residual}


def _pose_noise(case: Case) -> Iterator[Fired]:
    if case.stats is None:  # no poses: no pose-level noise
        return
    for s in case.stats.sensors:
        sc = case.cal.sensor(s)
        field = sc.gain @ case.cal.reference(s)
        radius = math.sqrt(float(field @ field))  # np.linalg.norm's number
        if not radius > 0:
            continue
        if sc.pose_noise_std > NOT_RIGID * radius:
            yield "not_rigid", {"sensor": s, "ratio": sc.pose_noise_std / radius}
            continue
        cov = case.stats.sensor(s).cov
        sample = math.sqrt(max(float(np.trace(cov)), 0.0) / 3.0) if cov is not None else 0.0
        if sample > 0 and sc.pose_noise_std > POSE_NOISE_RATIO * sample:
            yield "pose_noise", {"sensor": s, "ratio": sc.pose_noise_std / sample}


def _trimmed(case: Case) -> Iterator[Fired]:
    if case.stats is None:  # no samples are cut from a continuous log
        return
    for s in case.stats.sensors:
        st = case.stats.sensor(s)
        trimmed = st.trimmed
        if trimmed is None:
            continue
        cut = trimmed.sum()
        if cut > 0:
            share = float(cut / (cut + st.counts.sum()))
            if share > TRIMMED:
                yield (
                    "trimmed",
                    {
                        "share": share,
                        "sensor": s,
                        "poses": int(np.count_nonzero(trimmed)),
                    },
                )


def _accuracy(case: Case) -> Iterator[Fired]:
    """``unusable`` for the first prediction beyond :data:`UNUSABLE_FACTOR` times its target
    (NaN counts), otherwise ``accuracy`` for each prediction beyond its target."""
    acc = case.accuracy if case.accuracy is not None else case.cal.accuracy
    if acc is None:
        return
    worse = []
    for attribute, what, target_name, option, relative in _ACCURACY:
        value = getattr(acc, attribute)
        if value is None:
            continue
        target = float(getattr(case.targets, target_name)) / (100.0 if relative else 1.0)
        if value <= target:  # NaN is not: it goes on to be unusable
            continue
        shown = f"{value:.1%}" if relative else f"{value:.3g}°"
        goal = f"{100 * target:g}%" if relative else f"{target:g}°"
        numbers: dict[str, object] = {
            "what": what,
            "value": shown,
            "target": goal,
            "option": option,
        }
        if not value <= UNUSABLE_FACTOR * target:
            yield "unusable", {**numbers, "factor": UNUSABLE_FACTOR}
            return
        worse.append(numbers)
    for numbers in worse:
        yield "accuracy", numbers


def _untested(case: Case) -> Iterator[Fired]:
    diag = case.cal.diagnostics
    if case.stats is None or diag is None or diag.dof >= MIN_TEST_DOF:
        return
    # each further pose adds its readings (3 per sensor) less its own rotation's angles
    # (3 with both sensors; 2 tilt angles for one)
    per_pose = 3 if len(case.stats.sensors) == 2 else 1
    more = math.ceil((MIN_TEST_DOF - max(diag.dof, 0)) / per_pose)
    yield (
        "untested",
        {
            "dof": diag.dof,
            "minimum": MIN_TEST_DOF,
            "more": more,
            "needed": case.stats.n_poses + more,
        },
    )


def _shapes(gains: Array) -> list[tuple[float, Array] | None]:
    """Each gain's scale (geometric mean of its singular values) and its symmetric factor
    (``K = U P``, ``P = V Σ Vᵀ``) divided by that scale: the axis scales and cross terms;
    ``None`` for a gain of rank below 3 (numpy's ``matrix_rank`` tolerance) or not finite.
    One SVD for all the gains (S, 3, 3)."""
    finite: NDArray[np.bool_] = np.asarray(np.isfinite(gains).all(axis=(1, 2)))
    if not finite.all():
        gains = np.where(finite[:, None, None], gains, _EYE)
    _, sigma, Vt = np.linalg.svd(gains)
    full = finite & (sigma[:, -1] > sigma[:, 0] * _RANK_TOL)
    with np.errstate(divide="ignore", invalid="ignore"):  # a singular gain: not used
        scale = np.exp(np.add.reduce(np.log(sigma), axis=1) / 3.0)  # np.mean's numbers
        shape = (Vt.transpose(0, 2, 1) * (sigma / scale[:, None])[:, None, :]) @ Vt
    return [(float(scale[k]), shape[k]) if full[k] else None for k in range(len(gains))]


_EYE = np.eye(3)
_EYE.setflags(write=False)
_RANK_TOL = 3 * float(np.finfo(float).eps)


def _gains(case: Case) -> Iterator[Fired]:
    sensors = case.sensors
    shapes = _shapes(np.array([case.cal.sensor(s).gain for s in sensors]))
    for s, shaped in zip(sensors, shapes, strict=True):
        if shaped is None:
            continue
        scale, shape = shaped
        numbers: dict[str, object] = {"sensor": SENSOR_NAME[s], "option": MAGNITUDE_OPTION[s]}
        given = case.magnitudes.get(s)
        real = None if given is None else scale * given[0]
        # only within UNIT_RANGE are the readings in the magnitude's unit (LSB with --gravity
        # 9.80665 is a fine use: any scale is right then)
        in_unit = real is not None and UNIT_RANGE[0] <= real <= UNIT_RANGE[1]
        if in_unit and real is not None and abs(real - 1.0) > GAIN_SCALE[s]:
            yield (
                "implausible_gain",
                {
                    **numbers,
                    "what": "scale",
                    "value": real,
                    "limit": GAIN_SCALE[s],
                    "expected": "1",
                },
            )
            continue
        off = np.abs(shape - _EYE)
        if off.max() > GAIN_SHAPE[s]:
            i, j = np.unravel_index(int(np.argmax(off)), off.shape)
            yield (
                "implausible_gain",
                {
                    **numbers,
                    "what": "relative axis scale" if i == j else "cross-axis term",
                    "value": float(shape[i, j]),
                    "limit": GAIN_SHAPE[s],
                    "expected": "1" if i == j else "0",
                },
            )


def _coverage(case: Case) -> Iterator[Fired]:
    if case.found is not None and case.found.rejected:
        rejected = case.found.rejected
        which = ", ".join(f"pose {i} ({kind})" for i, kind in rejected[:6])
        more = "" if len(rejected) <= 6 else f" and {len(rejected) - 6} more"
        yield "rejected", {"count": len(rejected), "which": which + more}
    if case.stats is None and len(case.cal.rotations) == 0:
        return
    directions = case.body_directions(case.sensors[0])
    lowest = float(np.linalg.eigvalsh(directions.T @ directions / len(directions))[0])
    if lowest < COVERAGE:
        yield "coverage", {"axis": _axis(directions)}


#: A fitted dip further than this many combined standard errors (plus the allowance) from the
#: model's draws a warning.
REFERENCE_SIGMAS = 3.0


def _dip(case: Case) -> Iterator[Fired]:
    dip = case.cal.dip_deg
    if dip is None:
        return
    check = case.reference
    if check is None:
        if dip < 0:
            yield "negative_dip", {"dip": dip}
        return
    ref = check.field
    where = {"model": ref.model, "place": ref.place, "expected": ref.dip_deg}
    if check.decided_mirrored is None:
        yield "reference_undecided", {"dip": dip, **where}
    elif check.decided_mirrored and not check.stated_mirrored:
        yield "reference_mirrored", where
    elif not check.decided_mirrored and check.stated_mirrored:
        yield "reference_unmirrored", where
    std = case.cal.dip_std_deg or 0.0
    diff = abs(dip - ref.dip_deg)
    if diff > REFERENCE_SIGMAS * math.hypot(std, ref.dip_std_deg) + check.allowance_deg:
        yield (
            "reference_dip",
            {
                "dip": dip,
                "std": std,
                "ref_std": ref.dip_std_deg,
                "diff": diff,
                "date": ref.date,
                "allowance": check.allowance_deg,
                **where,
            },
        )


def _likelihood(case: Case) -> Iterator[Fired]:
    if case.stats is None or case.found is None:  # continuous: correlated, not a χ² test
        return
    if case.found.excess is not None:
        yield "not_ml", dict(case.found.excess)
    diag = case.cal.diagnostics
    if (
        diag is not None
        and diag.status == "ok"
        and diag.dof > 0
        and diag.p_value < 1e-4
        and not case.found.rejected
        and "pose_correlation" not in case.cal.options  # then the χ² is no test
    ):
        yield "implausible", {"cost": diag.statistic, "dof": diag.dof, "p": diag.p_value}


def _correlated(case: Case) -> Iterator[Fired]:
    """Poses cut from one continuous motion (:mod:`.correlation` measured and applied τ)."""
    found = case.cal.options.get("pose_correlation")
    if isinstance(found, Mapping):
        yield (
            "correlated_poses",
            {
                "tau": found["tau"],
                "effective": found["effective_poses"],
                "poses": found["poses"],
                "widening": found["widening"],
            },
        )


def _temperature_span(case: Case) -> Iterator[Fired]:
    """A temperature column whose span was too small for temperature terms
    (:mod:`fieldcal.likelihood.temperature`): the calibration holds at the mean temperature."""
    t = None if case.stats is None else case.stats.temperature
    if t is not None and t.refused:
        low, high = (float(x) for x in t.span)
        values = {"span": high - low, "low": low, "high": high, "mean": t.reference}
        yield "temperature_span", {**values, "need": MIN_SPAN_K}


#: The rules, run in this order by :func:`judge` (reasons of one level keep it).
CHECKS: tuple[Check, ...] = (
    _converged,
    _degenerate,
    _rejections,
    _same_sensor,
    _pose_noise,
    _trimmed,
    _accuracy,
    _untested,
    _gains,
    _coverage,
    _dip,
    _likelihood,
    _correlated,
    _temperature_span,
)

_ORDER = {"fail": 2, "warn": 1, "note": 0}


def reason(code: str, **values: object) -> Reason:
    """The :class:`Reason` of rule ``code`` with its message filled from ``values``."""
    level, template = RULES[code]
    return Reason(code, level, template.format(**values))


def judge(
    cal: Calibration,
    stats: PoseStats | None,
    found: Findings | None,
    accuracy: Accuracy | None = None,
    reference: ReferenceCheck | None = None,
    *,
    targets: Targets | None = None,
    magnitudes: Mapping[str, tuple[float, float]] | None = None,
    given: Sequence[Reason] = (),
) -> Verdict:
    """Run :data:`CHECKS` on a finished calibration; the worst level wins (``note`` never
    raises it), reasons most severe first.

    ``accuracy``, when given, stands for ``cal.accuracy`` (so both can be attached in one
    step); ``reference`` compares the dip with the World Magnetic Model's (its sign is then
    settled, so the negative-dip note is not given); ``targets`` (default :class:`Targets` ())
    are what the predicted accuracy is compared with; ``magnitudes`` see :class:`Case`.
    ``stats`` and ``found`` are ``None`` for a calibration from continuous motion (the
    pose-level rules do not apply); ``given`` are reasons its method found itself (the
    continuous estimator's stretch- and motion-level ones), kept in the verdict.
    """
    case = Case(
        cal,
        stats,
        found,
        accuracy,
        reference,
        DEFAULT_TARGETS if targets is None else targets,
        {} if magnitudes is None else magnitudes,
    )
    reasons = [reason(code, **values) for check in CHECKS for code, values in check(case)]
    reasons += list(given)
    worst = max((_ORDER[r.level] for r in reasons), default=0)
    level = {2: "fail", 1: "warn", 0: "pass"}[worst]
    return Verdict(level, tuple(sorted(reasons, key=lambda r: -_ORDER[r.level])))


def with_dropped_lines(verdict: Verdict, dropped: Mapping[str, int], rows: int) -> Verdict:
    """``verdict`` with the input rule ``dropped_lines`` applied: a stream's data lines dropped
    as unreadable (``dropped``: count by reason) against the ``rows`` kept; more than
    :data:`DROPPED_LINES` of them warns. Applied by ``fieldcal capture``, which sees the
    lines (the fit sees only the rows kept)."""
    count = sum(dropped.values())
    total = count + rows
    if total == 0 or count <= DROPPED_LINES * total:
        return verdict
    which = ", ".join(f"{k} {v}" for k, v in dropped.items() if v)
    added = reason("dropped_lines", dropped=count, total=total, share=count / total, which=which)
    reasons = sorted((*verdict.reasons, added), key=lambda r: -_ORDER[r.level])
    worst = max({"pass": 0, "warn": 1, "fail": 2}[verdict.level], _ORDER[added.level])
    return Verdict({2: "fail", 1: "warn", 0: "pass"}[worst], tuple(reasons))
