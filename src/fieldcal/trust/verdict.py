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

import dataclasses
import math
from collections.abc import Iterator, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from ..calibration import Accuracy, Calibration, Reason, Verdict
from ..findings import MotionFindings, TemperatureSpan
from ..likelihood.temperature import MIN_SPAN_K
from ..methods.continuous.motion_checks import gyro_check
from ..stats.pose_stats import PoseStats
from ..verdicts import VerdictLevel
from .interference_fit import interference_reasons
from .rule_case import (
    OWNER,
    Case,
    Check,
    Findings,
    Fired,
    PoseFindings,
    ReferenceCheck,
)
from .rule_case import owns as _owns
from .rule_table import RULES
from .targets import DEFAULT_TARGETS, Targets

__all__ = [
    "CHECKS",
    "LATE_CHECKS",
    "OWNER",
    "RULES",
    "Case",
    "Findings",
    "PoseFindings",
    "ReferenceCheck",
    "judge",
    "reason",
    "with_dropped_lines",
    "with_late_checks",
]

Array = NDArray[np.float64]


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
@_owns("not_converged")
def _converged(case: Case) -> Iterator[Fired]:
    if not case.cal.converged:
        yield "not_converged", {"detail": case.cal.message or f"{case.cal.iterations} iterations"}


@_owns("degenerate")
def _degenerate(case: Case) -> Iterator[Fired]:
    if case.stats is None or case.found is None:  # continuous: its identifiability check
        return
    if case.found.condition > CONDITION_LIMIT:
        axis = _axis(case.body_directions(case.stats.sensors[0]))
        yield "degenerate", {"condition": case.found.condition, "axis": axis}


@_owns("too_many_rejected", "unidentifiable")
def _rejections(case: Case) -> Iterator[Fired]:
    found = case.found
    if found is None:  # continuous: stretches are down-weighted, not dropped
        return
    if 4 * len(found.rejected) > found.n_total:
        yield "too_many_rejected", {"rejected": len(found.rejected), "total": found.n_total}
    if found.unflagged_left:
        yield "unidentifiable", {"flagged": found.unflagged_left}


@_owns("same_sensor")
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


@_owns("not_rigid", "pose_noise")
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


@_owns("trimmed")
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


#: What to record for a better calibration, by mode (the rule that fires chooses the advice):
#: still poses, or (``Case.stats`` None) more continuous motion.
_MORE = {
    False: "record more poses, still and away from iron, covering every axis up and down",
    True: "record the motion longer and through more orientations (every axis up and down, "
    "turns about each axis), away from iron; fieldcal plan on this calibration names the turns",
}


@_owns("unusable", "accuracy")
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
            "record": _MORE[case.stats is None],
        }
        if not value <= UNUSABLE_FACTOR * target:
            yield "unusable", {**numbers, "factor": UNUSABLE_FACTOR}
            return
        worse.append(numbers)
    for numbers in worse:
        yield "accuracy", numbers


@_owns("untested")
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


@_owns("implausible_gain")
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


@_owns("rejected", "coverage")
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


@_owns(
    "negative_dip",
    "reference_undecided",
    "reference_mirrored",
    "reference_unmirrored",
    "reference_dip",
)
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


@_owns("not_ml", "implausible")
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
        and case.cal.findings.pose_correlation is None  # then the χ² is no test
    ):
        yield "implausible", {"cost": diag.statistic, "dof": diag.dof, "p": diag.p_value}


@_owns("correlated_poses")
def _correlated(case: Case) -> Iterator[Fired]:
    """Poses cut from one continuous motion (:mod:`.correlation` measured and applied τ)."""
    found = case.cal.findings.pose_correlation
    if found is not None:
        yield (
            "correlated_poses",
            {
                "tau": found.tau,
                "effective": found.effective_poses,
                "poses": found.poses,
                "widening": found.widening,
            },
        )


#: Gains (raw units per calibrated unit: g, the field's strength, rad/s) that some physical unit
#: explains, per sensor: from the largest unit (g, tesla, rev/s) to the finest counts (20-bit
#: ADCs, nT), with a decade of room either side.
SCALE_RANGE = {"accel": (1e-4, 1e8), "mag": (1e-8, 1e8), "gyro": (1e-4, 1e8)}
SCALE_UNIT = {"accel": "unit of gravity", "mag": "unit of the field's strength", "gyro": "rad/s"}


@_owns("unexplained_scale")
def _unexplained_scale(case: Case) -> Iterator[Fired]:
    """Each sensor whose gain's scale (the geometric mean of its singular values, raw units
    per calibrated unit) is outside :data:`SCALE_RANGE`: judged on the calibration in the
    user's units (a late check: the fit itself sees normalised readings)."""
    for s in ("accel", "mag", "gyro"):
        sensor = getattr(case.cal, s, None)
        if sensor is None:
            continue
        with np.errstate(all="ignore"):
            sigma = np.linalg.svd(np.asarray(sensor.gain, dtype=float), compute_uv=False)
            scale = float(np.exp(np.mean(np.log(sigma))))
        low, high = SCALE_RANGE[s]
        if np.isfinite(scale) and not low <= scale <= high:
            name = SENSOR_NAME.get(s, "gyroscope")
            numbers = {"sensor": name, "scale": scale, "unit": SCALE_UNIT[s]}
            yield "unexplained_scale", {**numbers, "low": low, "high": high}


@_owns("temperature_ignored")
def _temperature_ignored(case: Case) -> Iterator[Fired]:
    """A temperature column left out as unusable (``--ignore-bad-temp``)."""
    found = case.cal.findings.temperature_ignored
    if found is not None:
        yield "temperature_ignored", {"column": found.column, "why": found.why}


@_owns("temperature_span")
def _temperature_span(case: Case) -> Iterator[Fired]:
    """A temperature column whose span was too small for temperature terms
    (:mod:`fieldcal.likelihood.temperature`): the calibration holds at the mean temperature."""
    t = None if case.stats is None else case.stats.temperature
    span = case.cal.findings.temperature_span  # the continuous estimator's
    if t is not None and t.refused:
        low, high = (float(x) for x in t.span)
        span = TemperatureSpan(low, high, float(t.reference))
    if span is not None:
        values = {"span": span.high - span.low, "low": span.low, "high": span.high}
        yield "temperature_span", {**values, "mean": span.mean, "need": MIN_SPAN_K}


#: A pose calibration's gyroscope: its plausible gain, scale within this share of 1 (MEMS
#: datasheets: ±3 %; deg/s for rad/s is 57x), axis scales and cross-axis terms within it, and
#: its axes within :data:`GYRO_AXES_DEG` of the accelerometer's (a swapped or reversed pair
#: turns the triad by 90° or 180°; separate chips may be mounted a few degrees apart).
GYRO_SCALE = 0.1
GYRO_AXES_DEG = 15.0


@_owns("gyro_gain")
def _gyro_gain(case: Case) -> Iterator[Fired]:
    """The gyroscope's gain (raw rad/s per rad/s, in the accelerometer's body frame): its scale,
    a reversed axis, its shape (axis scales, cross-axis) and its axes' angle to the
    accelerometer's."""
    sensor = case.cal.gyro
    if sensor is None or case.cal.findings.motion is not None:  # continuous: _motion_gyro
        return
    if not np.all(np.isfinite(sensor.gain)):
        return
    W, sigma, Vt = np.linalg.svd(sensor.gain)
    if not sigma[-1] > 0:
        return
    scale = float(np.exp(np.mean(np.log(sigma))))
    rotation = W @ Vt
    shape = Vt.T @ np.diag(sigma / scale) @ Vt
    off = np.abs(shape - _EYE)
    angle = math.degrees(math.acos(min(1.0, max(-1.0, (float(np.trace(rotation)) - 1) / 2))))
    if abs(scale - 1.0) > GYRO_SCALE:
        yield "gyro_gain", {"what": "scale", "value": f"{scale:.3g}", "limit": "±10 %"}
    elif np.linalg.det(rotation) < 0:
        yield "gyro_gain", {"what": "a reversed axis: determinant", "value": "< 0", "limit": "> 0"}
    elif off.max() > GYRO_SCALE:
        yield (
            "gyro_gain",
            {"what": "axis scale or cross-axis term", "value": f"{off.max():.3g}", "limit": "±0.1"},
        )
    elif angle > GYRO_AXES_DEG:
        numbers = {"value": f"{angle:.1f}°", "limit": f"{GYRO_AXES_DEG:g}°"}
        yield "gyro_gain", {"what": "angle to the accelerometer's axes", **numbers}


#: A gyroscope fit whose segments misfit below this p-value has its error bars widened.
GYRO_MISFIT_P = 0.01


@_owns("gyro_segments", "gyro_misfit")
def _gyro_segments(case: Case) -> Iterator[Fired]:
    """The gyroscope stage's findings (:class:`fieldcal.findings.GyroFindings`)."""
    found = case.cal.findings.gyro
    if found is None:
        return
    if found.segments_left_out:
        total = found.segments_used + found.segments_left_out
        yield "gyro_segments", {"left_out": found.segments_left_out, "total": total}
    if found.p_value < GYRO_MISFIT_P:
        yield "gyro_misfit", {"p": found.p_value, "widening": found.widening}


#: The continuous fit's rules (:class:`fieldcal.findings.MotionFindings`): the calibrated
#: field's strength beyond this RMS relative departure from 1 is disturbed (BROAD: 2.5–3.7 %
#: undisturbed in a lab, 15 % with a magnet 2 cm away).
FIELD_STRENGTH_LIMIT = 0.06
#: The gyroscope's rates over the magnetometer direction's turning outside this range: wrong
#: units (1 for rad/s; 57 for °/s). Wide: hard iron slows the raw direction's turns.
GYRO_UNITS_RANGE = (0.25, 8.0)
#: The gyroscope's scale (``|det K_g|^(1/3)``) beyond this share off 1: wrong units or columns.
GYRO_SCALE_LIMIT = 0.2
#: Degrees of misalignment of a gyroscope axis that draw a warning (when significant at 2σ).
GYRO_MISALIGNMENT_DEG = 3.0
#: A gyroscope axis's misalignment standard error (degrees) beyond which the log does not
#: determine it.
GYRO_UNDETERMINED_DEG = 1.0
#: Radians per sample (99th percentile of ``|ω| Δt``) beyond which the turns are too fast.
FAST_STEP_RAD = 0.25
_AXES = "xyz"


def _units_wrong(motion: MotionFindings) -> bool:
    ratio = motion.gyro_units_ratio
    low, high = GYRO_UNITS_RANGE
    return ratio is not None and not low <= ratio <= high


@_owns("gyro_units", "gyro_gain_sign", "gyro_gain_scale", "gyro_misalignment", "gyro_undetermined")
def _motion_gyro(case: Case) -> Iterator[Fired]:
    """A continuous fit's gyroscope: its units against the magnetometer's turning, the sign,
    scale (unless the units are blamed) and each axis's alignment with its standard error
    (:func:`fieldcal.methods.continuous.motion_checks.gyro_check`)."""
    motion, sensor, cov = case.cal.findings.motion, case.cal.gyro, case.cal.covariance
    if motion is None:
        return
    units_wrong = _units_wrong(motion)
    if units_wrong:
        yield "gyro_units", {"ratio": motion.gyro_units_ratio}
    if sensor is None or cov is None:
        return
    gyro = gyro_check(sensor.gain, cov)
    negative = gyro["negative_axes"]
    if negative:
        values = ", ".join(f"{_AXES[i]} {gyro['diagonal'][i]:+.3g}" for i in negative)
        plural = "es" if len(negative) > 1 else "is"
        axes = ", ".join(_AXES[i] for i in negative)
        yield "gyro_gain_sign", {"axes": axes, "plural": plural, "values": values}
    if not units_wrong and abs(gyro["scale"] - 1.0) > GYRO_SCALE_LIMIT:
        yield "gyro_gain_scale", {"scale": gyro["scale"], "limit": GYRO_SCALE_LIMIT}
    pairs = zip(gyro["misalignment_deg"], gyro["misalignment_std_deg"], strict=True)
    for i, (angle, std) in enumerate(pairs):
        if std > GYRO_UNDETERMINED_DEG:
            yield "gyro_undetermined", {"axis": _AXES[i], "std": std}
        elif angle - 2.0 * std > GYRO_MISALIGNMENT_DEG:
            numbers = {"angle": angle, "std": std, "limit": GYRO_MISALIGNMENT_DEG}
            yield "gyro_misalignment", {"axis": _AXES[i], **numbers}


@_owns(
    "continuous_undetermined",
    "continuous_unsettled",
    "continuous_disturbed",
    "continuous_field_disturbed",
    "continuous_fast_turns",
)
def _motion(case: Case) -> Iterator[Fired]:
    """The continuous-motion estimator's findings (:class:`fieldcal.findings.MotionFindings`):
    parameters the motion leaves undetermined (with the turns to add), a fit that did not
    settle, a log mostly down-weighted for body acceleration."""
    found = case.cal.findings.motion
    if found is None:
        return
    for advice in found.undetermined:
        yield "continuous_undetermined", {"advice": advice}
    if found.lacking:
        yield "continuous_undetermined", {"advice": found.lacking}
    elif found.unsettled:
        yield "continuous_unsettled", {"which": ", ".join(found.unsettled)}
    if found.disturbed_seconds > 0.5 * found.duration_seconds:
        yield (
            "continuous_disturbed",
            {"disturbed": found.disturbed_seconds, "duration": found.duration_seconds},
        )
    if found.field_strength_rms > FIELD_STRENGTH_LIMIT:
        numbers = {"limit": FIELD_STRENGTH_LIMIT, "dip": found.dip_spread_deg, "stretch": 2.0}
        yield "continuous_field_disturbed", {"strength": found.field_strength_rms, **numbers}
    if found.turn_step_rad > FAST_STEP_RAD or found.clipped_axes:
        clipped = found.clipped_axes
        where = ""
        if clipped:
            where = f"; the gyroscope's {', '.join(_AXES[i] for i in clipped)} at its range"
        turns: dict[str, object] = {"step": found.turn_step_rad, "clipped": where}
        yield "continuous_fast_turns", {"rate": found.max_rate, **turns}


#: The rules, run in this order by :func:`judge` (reasons of one level keep it).
@_owns("interference", "interference_unusable", "interference_not_identifiable")
def _interference(case: Case) -> Iterator[Fired]:
    """The magnetometer's interference term (:mod:`.interference_fit`): not identifiable, or
    above ArduPilot's 30 % / 60 % of the Earth's field."""
    if case.cal.mag is not None:
        yield from interference_reasons(case.cal.mag.interference)


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
    _gyro_gain,
    _gyro_segments,
    _motion,
    _motion_gyro,
)
#: The rules judged on the finished calibration in the user's units, after every stage of a
#: path (the gyroscope of a pose calibration, the input's own findings), applied by
#: :func:`with_late_checks` to the verdict the fit was judged with (a reason already there is
#: not given twice).
LATE_CHECKS: tuple[Check, ...] = (
    _gyro_gain,
    _gyro_segments,
    _unexplained_scale,
    _temperature_ignored,
    _interference,
)

_ORDER = {"fail": 2, "warn": 1, "note": 0}
#: The verdict of a worst reason level (``_ORDER``'s number; a note leaves it at pass).
_VERDICT: dict[int, VerdictLevel] = {2: "fail", 1: "warn", 0: "pass"}


def reason(code: str, **values: object) -> Reason:
    """The :class:`Reason` of rule ``code`` with its message filled from ``values``."""
    level, template = RULES[code]
    return Reason(code, level, template.format(**values))


def judge(
    cal: Calibration,
    stats: PoseStats | None,
    found: PoseFindings | None,
    accuracy: Accuracy | None = None,
    reference: ReferenceCheck | None = None,
    *,
    targets: Targets | None = None,
    magnitudes: Mapping[str, tuple[float, float]] | None = None,
) -> Verdict:
    """Run :data:`CHECKS` on a finished calibration; the worst level wins (``note`` never
    raises it), reasons most severe first.

    ``accuracy``, when given, stands for ``cal.accuracy`` (so both can be attached in one
    step); ``reference`` compares the dip with the World Magnetic Model's (its sign is then
    settled, so the negative-dip note is not given); ``targets`` (default :class:`Targets` ())
    are what the predicted accuracy is compared with; ``magnitudes`` see :class:`Case`.
    ``stats`` and ``found`` are ``None`` for a calibration from continuous motion (the
    pose-level rules do not apply; the rules on its typed findings do).
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
    worst = max((_ORDER[r.level] for r in reasons), default=0)
    level = _VERDICT[worst]
    return Verdict(level, tuple(sorted(reasons, key=lambda r: -_ORDER[r.level])))


def _merged(verdict: Verdict, added: Sequence[Reason]) -> Verdict:
    """``verdict`` with ``added`` reasons, most severe first, its level raised as they say."""
    reasons = sorted((*verdict.reasons, *added), key=lambda r: -_ORDER[r.level])
    worst = max(
        [{"pass": 0, "warn": 1, "fail": 2}[verdict.level], *(_ORDER[r.level] for r in added)]
    )
    return Verdict(_VERDICT[worst], tuple(reasons))


def with_late_checks(cal: Calibration) -> Calibration:
    """``cal`` with :data:`LATE_CHECKS` applied to its verdict: the rules on what a stage after
    the fit added (the gyroscope of a pose calibration, :mod:`fieldcal.gyro.stage`)."""
    if cal.verdict is None:
        return cal
    case = Case(cal, None, None)
    added = [reason(code, **values) for check in LATE_CHECKS for code, values in check(case)]
    added = [r for r in added if r not in cal.verdict.reasons]  # judged already (continuous)
    if not added:
        return cal
    return dataclasses.replace(cal, verdict=_merged(cal.verdict, added))


OWNER["dropped_lines"] = "with_dropped_lines"


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
    return _merged(verdict, [added])
