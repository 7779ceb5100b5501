"""From a log to a calibration: its poses (still detection, windows or a pose column), the
checks a log needs, ``fieldcal.calibrate``, the magnetometer's axis map and the accelerometer's
sign folded back, and the JSON document the ``calibrate`` command writes.

:func:`calibrate_log` is the library's form of ``fieldcal calibrate``; :func:`run_log` is the
same on a :class:`~fieldcal.logs.log.Log` with the poses and notes the CLI prints.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .api import calibrate_with, check_targets, field_settings, targets_for
from .calibration import Calibration
from .errors import MOVING_RESTS, NO_STILL, WRONG_RATE, InputError, MovingRestsWarning
from .findings import TemperatureIgnored
from .folding import fold_axes
from .geometry.frames import ACCEL_SIGNS, parse_axes
from .gyro.integrate import effective_time
from .gyro.scale import gyro_factor, gyro_scale_problem
from .logs import Log, PoseSet, poses_from_log
from .logs.inputs import read_log
from .logs.log_temperature import pose_temperature_samples
from .logs.pose_finding import POSE_SOURCES, SHORT_LOG
from .logs.pose_hints import pose_advice
from .methods import estimator
from .methods.enough_poses import check_poses as _check_poses
from .reference import FieldReference
from .settings import (
    OPTIONS,
    DetectSettings,
    FitSettings,
    ReadSettings,
    TrustSettings,
    changed,
    renamed,
    settings_of,
)
from .trust.continuous_motion import trust_continuous
from .trust.interference_stage import flight_options, with_interference
from .trust.targets import Targets
from .trust.verdict import with_late_checks

__all__ = [
    "ACCEL_SIGNS",
    "POSE_MODES",
    "POSE_SOURCES",
    "LogCalibration",
    "LogSettings",
    "calibrate_log",
    "document",
    "fold_axes",
    "read_log",
    "run_log",
]

#: ``poses=``: the ways to cut a log into poses, the continuous-motion estimator
#: (:mod:`fieldcal.methods.continuous`: no rests, a gyroscope) and ``"auto"`` (still detection
#: when the log has enough rests, else continuous when it has a gyroscope and time).
POSE_MODES = ("auto", *POSE_SOURCES, "continuous")
Array = NDArray[np.float64]


@dataclass(frozen=True)
class LogSettings:
    """Everything a log's calibration is given, by stage, built once from the user's values.

    Attributes
    ----------
    read, detect, fit, trust : ReadSettings, DetectSettings, FitSettings, TrustSettings
        The option table's settings (:mod:`fieldcal.settings`): the reader's, the still
        detector's, the fit's (with the axis map, the accelerometer's sign and the gyroscope
        stage) and the check's.
    targets : Targets, optional
        ``targets=`` of :func:`fieldcal.calibrate`; the target options of ``trust``
        (``--target-tilt`` ...) replace its values.
    method_options : mapping
        The method's own options (``max_iter``, ``initial``, ...), checked by its registry entry
        when the fit starts.
    """

    read: ReadSettings = field(default_factory=ReadSettings)
    detect: DetectSettings = field(default_factory=DetectSettings)
    fit: FitSettings = field(default_factory=FitSettings)
    trust: TrustSettings = field(default_factory=TrustSettings)
    targets: Targets | None = None
    method_options: Mapping[str, object] = field(default_factory=dict)

    @classmethod
    def of(cls, keywords: Mapping[str, object] | None = None, /, **more: object) -> LogSettings:
        """The library's keywords (:func:`calibrate_log`'s, :func:`fieldcal.calibrate_many`'s)
        split by stage: an option of the table goes to its stage's settings, ``targets`` is
        checked, any other keyword is the method's own.

        Parameters
        ----------
        keywords : mapping, optional
            By library keyword; one left out takes the table's default.
        **more
            More of them (``LogSettings.of(poses="windows", gravity=9.81)``).

        Returns
        -------
        LogSettings
        """
        keywords = renamed({**(keywords or {}), **more}, stacklevel=4)
        own = {k: v for k, v in keywords.items() if k not in OPTIONS and k != "targets"}
        return cls(
            read=settings_of(ReadSettings, keywords),
            detect=settings_of(DetectSettings, keywords),
            fit=settings_of(FitSettings, keywords),
            trust=settings_of(TrustSettings, keywords),
            targets=check_targets(keywords.get("targets")),
            method_options=own,
        )

    def given(self) -> dict[str, object]:
        """The fit's and the check's options given values other than their defaults, by
        library keyword (for notes on what an estimator does not use)."""
        out = {**changed(self.fit), **changed(self.trust)}
        out.update(self.method_options)
        if self.targets is not None:
            out["targets"] = self.targets
        return out


_DEFAULT_SETTINGS = LogSettings()


@dataclass(frozen=True)
class LogCalibration:
    """A log's calibration with what the command line shows beside it.

    Attributes
    ----------
    calibration : Calibration
        The result; ``calibration.poses`` lists every pose found, with its rows in the log.
    poses : PoseSet
        The poses the log was cut into and how (still detection, windows or a pose column).
    notes : tuple of str
        Lines on the input: the columns used, how the poses were found, folded conventions.
    """

    calibration: Calibration
    poses: PoseSet
    notes: tuple[str, ...]

    def document(self) -> dict[str, Any]:
        """The calibration JSON the ``calibrate`` command writes."""
        return document(self.calibration, self.poses)


def _check_choice(name: str, value: object, choices: tuple[str, ...]) -> None:
    if not isinstance(value, str) or value not in choices:
        raise InputError(
            f"{name} must be one of {', '.join(repr(c) for c in choices)}; got {value!r}"[:200]
        )


@dataclass(frozen=True)
class _Job:
    """A log's calibration with its settings checked once, whatever the path: the mode chosen
    (``"continuous"``, a way to find poses, or ``"given"``: ``found``), what the continuous path
    lacks (``None``: nothing), the input notes, the magnetometer's axis map, and the World
    Magnetic Model's field, the magnitudes and the targets (checked before any long work)."""

    settings: LogSettings
    found: PoseSet | None
    mode: str
    why_not: str | None
    notes: tuple[str, ...]
    axes: Array | None
    reference: FieldReference | None
    magnitudes: dict[str, float | None]
    targets: Targets | None
    gyro_scale: float = 1.0
    gyro_problem: str | None = None

    @property
    def may_fall_back(self) -> bool:
        """``poses="auto"`` on a log the continuous path can take: a still detection that
        finds too little goes on to the continuous motion."""
        return self.mode == "auto" and self.why_not is None


def run_log(
    log: Log,
    settings: LogSettings = _DEFAULT_SETTINGS,
    *,
    found: PoseSet | None = None,
    on_progress: Callable[[str], None] | None = None,
) -> LogCalibration:
    """Find a log's poses and calibrate from them, or from its continuous motion: the path of
    ``fieldcal calibrate``. A flight log's GPS position is the ``location`` when none is
    given; a log with battery current or throttle gets the magnetometer's interference term
    (:func:`fieldcal.trust.interference_stage.with_interference`).

    Parameters
    ----------
    log : Log
        As :func:`fieldcal.read_log` gives it; not modified (the axis map and the
        accelerometer's sign apply to copies of its arrays).
    settings : LogSettings
        The detection, fit and trust settings (see :func:`calibrate_log` for each option;
        ``settings.read`` is not used: the log is read).
    found : PoseSet, optional
        The poses, already found (``settings.detect.poses`` is then not used).
    on_progress : callable, optional
        Called with one line of text at each step.

    Returns
    -------
    LogCalibration
    """
    job, log = _prepare(log, settings, found)
    notes = list(job.notes)
    if job.mode == "continuous":
        return _run_continuous(log, job, notes, on_progress)
    try:
        poses, detection = _poses(log, job, job.found, notes, on_progress)
    except InputError as exc:
        if not job.may_fall_back:
            raise
        # the finding only: its advice (hold still in more orientations...) is the rests'
        why = "its rests move" if exc.code == MOVING_RESTS else _finding(str(exc))
        if job.gyro_problem is not None:
            raise InputError(
                f"{job.gyro_problem}; the continuous estimator needs it right, as the log "
                f"cannot be calibrated from rests (still detection: {why})"
            ) from None
        notes.append(
            "poses='auto': calibrated from continuous motion, not from rests (still "
            f"detection: {why}); the log has a gyroscope and time"
        )
        return _run_continuous(log, job, notes, on_progress)
    return _run_poses(log, job, poses, detection, notes, on_progress)


def _prepare(log: Log, settings: LogSettings, found: PoseSet | None) -> tuple[_Job, Log]:
    """Every setting a log's calibration needs checked once, before the long work, and the
    mode chosen: the still detector's options given with ``poses="auto"`` ask for rests. The
    log comes back with its gyroscope in rad/s (``--gyro-unit``)."""
    settings, located = _located(log, settings)
    detect, fit = settings.detect, settings.fit
    if found is None and isinstance(detect.poses, PoseSet):  # poses= given found poses
        found = detect.poses
    mode = "given" if found is not None else detect.poses
    if found is None:
        _check_choice("poses (--poses)", mode, POSE_MODES)
    if fit.gyro is True and log.gyro is None:
        raise InputError(
            "the gyroscope cannot be calibrated: the log has no gyroscope columns; name them "
            "with --gyro-cols"
        )
    _check_choice("accel_sign (--accel-sign)", fit.accel_sign, ACCEL_SIGNS)
    notes, P = _input_notes(log, fit.mag_axes, fit.accel_sign)
    log, gyro_scale, problem = _gyro_in_rad_s(log, fit.gyro_unit, detect.rate, fit.gyro, notes)
    # a wrong rate misleads every path; a unit only the continuous one (the poses' gyroscope
    # fit absorbs it into the gain)
    if problem is not None and (problem.code == WRONG_RATE or mode == "continuous"):
        raise problem
    notes = [*located, *notes]
    tuned = [name for name in _STILL_OPTIONS if getattr(detect, name) is not None]
    if mode == "auto" and tuned:
        mode = "still"
        notes.append(
            f"poses='auto': still detection, as its options were given ({', '.join(tuned)})"
        )
    why_not = None
    if mode in ("auto", "continuous"):
        why_not = _why_not_continuous(log, detect.rate, fit.gyro)
    if mode == "continuous" and why_not is not None:
        raise InputError(f"poses='continuous' (--poses continuous) needs {why_not}")
    reference, magnitudes = field_settings(fit, settings.trust)
    targets = targets_for(settings.targets, settings.trust)
    job = _Job(settings, found, mode, why_not, tuple(notes), P, reference, magnitudes, targets)
    gyro_problem = None if problem is None else str(problem)
    return dataclasses.replace(job, gyro_scale=gyro_scale, gyro_problem=gyro_problem), log


def _gyro_in_rad_s(
    log: Log, unit: str | None, rate: float | None, gyro: bool | None, notes: list[str]
) -> tuple[Log, float, InputError | None]:
    """The log with its gyroscope in rad/s (``--gyro-unit``), the factor applied, and what
    the gyroscope's integrated turn against the other sensors' says is wrong (a unit or a rate
    that contradicts the log; :func:`~fieldcal.gyro.scale.gyro_scale_problem`)."""
    factor = gyro_factor(unit)
    if log.gyro is None:
        return log, factor, None
    readings: Array = log.gyro * factor
    if factor != 1.0:
        log = dataclasses.replace(log, gyro=readings)
        notes.append(
            f"gyroscope read in {unit} (--gyro-unit), fitted in rad/s and folded back into its "
            "gain: the result applies to the raw columns as logged"
        )
    if gyro is False or log.accel is None or (log.time is None and not rate):
        return log, factor, None
    time = np.arange(log.n) / rate if rate else effective_time(log.time)  # type: ignore[arg-type]
    has_time = log.time is not None
    problem = gyro_scale_problem(
        time, log.accel, log.mag, readings, rate=rate, has_time=has_time, unit=unit
    )
    return log, factor, problem


def _finding(message: str) -> str:
    """A refusal's finding without its advice (what follows the reason: the fix for rests)."""
    for cut in (" (the 6N", ": hold", ": other settings", ": for a log", "; try ", "; or "):
        message = message.split(cut, 1)[0]
    return message


def _located(log: Log, settings: LogSettings) -> tuple[LogSettings, list[str]]:
    """``settings`` with a flight log's GPS position (:mod:`fieldcal.logs.flight`) as the
    ``location`` when none is given, and the note saying so."""
    where = log.metadata.get("gps_location")
    if settings.trust.location is not None or not where:
        return settings, []
    date = settings.trust.date or log.metadata.get("date")
    trust = dataclasses.replace(settings.trust, location=where, date=date)
    note = f"location {where} from the log's GPS (the World Magnetic Model there)"
    settings = dataclasses.replace(settings, trust=trust)
    # the log states its magnetometer's unit: scale to the model's intensity in it, so the
    # gains export to the autopilot (its parameters are in that unit)
    unit = _WMM_UNIT_OF.get(str(log.metadata.get("mag_unit", "")).lower())
    if unit is None or settings.fit.field_strength is not None:
        return settings, [note]
    fit = dataclasses.replace(settings.fit, field_strength=f"wmm:{unit}")
    note += f", its intensity the field strength in the log's {unit}"
    return dataclasses.replace(settings, fit=fit), [note]


#: A flight log's magnetometer unit (:mod:`fieldcal.logs.flight`) → the ``wmm:`` unit.
_WMM_UNIT_OF = {"gauss": "gauss", "mgauss": "mgauss", "ut": "uT", "nt": "nT"}


#: The still detector's own options (given with ``poses="auto"``, they choose rests).
_STILL_OPTIONS = ("window", "min_still", "still_trim", "still_threshold")


def _poses(
    log: Log,
    job: _Job,
    found: PoseSet | None,
    notes: list[str],
    on_progress: Callable[[str], None] | None,
) -> tuple[PoseSet, dict[str, Any] | None]:
    """The poses (given, or found in ``log`` as ``job.mode`` says) and the settings they were
    found with (``None``: given). With ``poses="auto"`` they are checked here, so that too few
    can go on to the continuous motion; a log whose rests move raises ``MOVING_RESTS``."""
    if found is not None:
        return found, None
    if on_progress is not None:
        on_progress(f"finding the poses in {log.path}")
    # neither the map nor the sign moves a still interval: the poses are found in the
    # readings as logged and the samples of each are mapped later
    detection = job.settings.detect.detector_keywords()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        poses = _find_poses(log, job.mode, detection, job.why_not)
    moving = [w for w in caught if issubclass(w.category, MovingRestsWarning)]
    if moving and job.may_fall_back:
        raise InputError(str(moving[0].message), code=MOVING_RESTS)
    timed = log.time is not None or job.settings.detect.rate is not None  # else samples
    if moving and job.mode == "auto" and log.gyro is None and timed:
        # a hand-waved log: its motion can calibrate only with a gyroscope beside it
        raise InputError(
            f"{str(moving[0].message).split('; hold', 1)[0]}; a log waved by hand without "
            "rests is calibrated from its motion only with a gyroscope and time, and "
            "this log has no gyroscope columns (name them with --gyro-cols); without "
            "one, record rests (hold still in 8 or more orientations, e.g. on the faces "
            "and edges of a box) or turn slowly and use --poses windows"
        )
    for w in caught:  # the detector's own warnings, passed on
        warnings.warn(w.message, w.category, stacklevel=3)
    if job.mode == "auto":
        fit, rate = job.settings.fit, job.settings.detect.rate
        advice = None if job.why_not is None else detection
        _check_poses(poses, fit.method, log, rate, advice)
        notes.append(f"poses='auto': calibrated from {poses.n} rests found by still detection")
    return poses, detection


def _run_poses(
    log: Log,
    job: _Job,
    found: PoseSet,
    detection: dict[str, Any] | None,
    notes: list[str],
    on_progress: Callable[[str], None] | None,
) -> LogCalibration:
    """The pose path: the axis map and sign applied to the poses' samples, the poses checked
    (unless ``poses="auto"`` checked these very ones), :func:`fieldcal.api.calibrate_with`,
    the gyroscope stage, the conventions folded back."""
    settings, fit, rate = job.settings, job.settings.fit, job.settings.detect.rate
    checked = job.mode == "auto"
    if job.axes is not None and found.mag is not None:
        found = dataclasses.replace(found, mag=[m @ job.axes.T for m in found.mag])
        checked = False
    if fit.accel_sign == "gravity" and found.accel is not None:
        found = dataclasses.replace(found, accel=[-a for a in found.accel])
        checked = False
    notes.append(_how_found(log, found))
    unused = _unused(settings, "poses")
    if unused:
        notes.append(f"not used by a fit from poses: {', '.join(unused)}")
    if not checked:
        _check_poses(found, fit.method, log, rate, detection)
    if on_progress is not None:
        on_progress(f"calibrating {found.n} poses ({fit.method})")
    cal = calibrate_with(
        found.accel,
        found.mag,
        fit,
        settings.trust,
        targets=settings.targets,
        method_options=settings.method_options,
        on_progress=on_progress,
        time_ordered=found.time_ordered,  # samples, windows: error bars for correlated poses
        temperature=pose_temperature_samples(log, found.entries),
    )
    if fit.gyro is not False:
        # on the fit as made (before an axis map or sign is folded into it): the poses'
        # orientation covariance comes from its noise model and gauge
        if on_progress is not None and log.gyro is not None:
            on_progress("calibrating the gyroscope from the motion between the poses")
        cal = estimator("gyro").fit(
            log,
            found,
            cal,
            required=fit.gyro is True,
            rate=rate,
            notes=notes,
            on_progress=on_progress,
        )
    cal = _in_logged_units(_late(_fold_back(cal, job), log, notes), job)
    return LogCalibration(_with_pose_rows(cal, found, log), found, tuple(notes))


def _late(cal: Calibration, log: Log, notes: list[str]) -> Calibration:
    """The stages after the fit on the calibration in the user's units (the magnetometer's
    interference term, :func:`fieldcal.trust.interference_stage.with_interference`), and the
    rules on what the stages and the input added (:data:`fieldcal.trust.verdict.LATE_CHECKS`:
    the gyroscope's gain and segments, a gain no unit explains, a temperature column left out,
    the interference), for every path."""
    cal, note = with_interference(cal, log)
    if note:
        notes.append(note)
    if log.temperature_ignored is not None:
        column, why = log.temperature_ignored
        ignored = TemperatureIgnored(column, why)
        cal = dataclasses.replace(
            cal, findings=dataclasses.replace(cal.findings, temperature_ignored=ignored)
        )
    return with_late_checks(cal)


def _fold_back(cal: Calibration, job: _Job) -> Calibration:
    """The magnetometer's axis map and the accelerometer's sign folded into the result, so it
    applies to the raw columns as logged (every path)."""
    fit = job.settings.fit
    if job.axes is not None and fit.mag_axes is not None:
        cal = fold_axes(cal, job.axes, fit.mag_axes)
    if fit.accel_sign == "gravity":
        cal = fold_axes(cal, -np.eye(3), fit.accel_sign, sensor="accel")
    return cal


def _in_logged_units(cal: Calibration, job: _Job) -> Calibration:
    """The gyroscope's gain in the unit it was logged in (``--gyro-unit``), after the rules
    judged it in rad/s: ``raw = gain·ω + bias`` in that unit is ``(gain, bias) / factor``."""
    if job.gyro_scale == 1.0 or cal.gyro is None:
        return cal
    unit = str(job.settings.fit.gyro_unit)
    return fold_axes(cal, np.eye(3) / job.gyro_scale, unit, "gyro", "gyro_unit")


def _find_poses(log: Log, poses: str, detection: dict[str, Any], why_not: str | None) -> PoseSet:
    """:func:`poses_from_log`; when still detection finds no rest, the error says which other
    settings find how many poses (not when ``poses='auto'`` goes on to continuous motion:
    ``why_not`` None)."""
    try:
        return poses_from_log(log, poses="still" if poses == "auto" else poses, **detection)
    except InputError as exc:
        if exc.code not in (NO_STILL, SHORT_LOG) or (poses == "auto" and why_not is None):
            raise
        advice = pose_advice(log, **detection)
        if advice is None:
            raise
        text = str(exc)  # its finding, with the advice for this log in place of the generic
        head = text.split("; ", 1)[0] if exc.code == SHORT_LOG else text.split("; try ", 1)[0]
        raise InputError(f"{head}; {advice}", code=exc.code) from None


def _why_not_continuous(log: Log, rate: float | None, gyro: bool | None) -> str | None:
    """What the continuous estimator lacks in this log (``None``: nothing)."""
    missing = [
        what
        for what, absent in (
            ("accelerometer", log.accel is None),
            ("magnetometer", log.mag is None),
            ("gyroscope (--gyro-cols)", log.gyro is None),
        )
        if absent
    ]
    if missing:
        return f"{' and '.join(missing)} columns"
    if log.time is None and rate is None:
        return "a time column (--time-col) or the sample rate (--rate)"
    if gyro is False:
        return "the gyroscope, but gyro=False (--no-gyro) was given"
    return None


def _unused(settings: LogSettings, path: str) -> list[str]:
    """The options given that the estimation ``path`` does not read (``Option.paths``), and
    for the continuous path the pose method's own options."""
    given = {**changed(settings.fit), **changed(settings.trust)}
    unused = [k for k in given if path not in OPTIONS[k].paths]
    if path == "continuous":
        own = settings.method_options.items()
        unused += [k for k, v in own if v is not None and v is not False]
    return sorted(unused)


def _run_continuous(
    log: Log,
    job: _Job,
    notes: list[str],
    on_progress: Callable[[str], None] | None,
) -> LogCalibration:
    """The continuous-motion estimator on the whole log (:func:`fieldcal.methods.continuous.
    fit_continuous`) and the shared trust path (:func:`fieldcal.trust.continuous_motion.
    trust_continuous`: handedness, the reference, accuracy, verdict), the axis map and the
    accelerometer's sign folded back as for poses."""
    assert log.accel is not None and log.mag is not None and log.gyro is not None
    settings = job.settings
    fit, rate = settings.fit, settings.detect.rate
    gravity, field_strength = job.magnitudes["accel"], job.magnitudes["mag"]
    if log.time is not None and rate is None:
        time = effective_time(log.time)
    else:
        time = np.arange(log.n) / float(rate or log.rate)  # type: ignore[arg-type]
    unused = _unused(settings, "continuous")
    if unused:
        notes.append(f"not used by the continuous estimator: {', '.join(unused)}")
    accel = -log.accel if fit.accel_sign == "gravity" else log.accel
    mag = log.mag if job.axes is None else log.mag @ job.axes.T
    if on_progress is not None:
        on_progress(f"calibrating from continuous motion ({log.n} samples)")
    flight, more = flight_options(log, fit.hold)  # the interference jointly; a flight log's
    notes += more  # autopilot (:func:`fieldcal.trust.interference_stage.flight_options`)
    try:
        cal = estimator("continuous").fit(
            time,
            accel,
            mag,
            log.gyro,
            rows=log.index,
            gravity=gravity,
            on_progress=on_progress,
            temperature=log.temperature,
            gyro_sampling=fit.gyro_sampling,
            gyro_noise=fit.gyro_noise,
            hold=fit.hold,
            prior=flight.pop("prior", fit.prior),
            **flight,
        )
    except (np.linalg.LinAlgError, FloatingPointError, OverflowError):
        raise InputError(
            "the continuous fit failed in floating point; check that the time column is in "
            "seconds (or give --rate) and the gyroscope in rad/s"
        ) from None
    cal = cal.with_field_magnitudes(gravity, field_strength)
    cal = trust_continuous(
        cal,
        mag_mirrored=bool(fit.mag_mirrored),
        reference=job.reference,
        dip_allowance_deg=float(settings.trust.dip_allowance_deg),
        targets=job.targets,
        magnitudes=job.magnitudes,
    )
    cal = _in_logged_units(_late(_fold_back(cal, job), log, notes), job)
    traj = cal.options["trajectory"]
    notes.append(
        f"continuous motion: {traj['duration_s']:.4g} s, {traj['epochs']} epochs, "
        f"{100 * traj['gravity_coverage']:.0f} % of gravity directions visited, "
        f"{len(cal.options['downweighted'])} stretch(es) down-weighted for body acceleration"
    )
    provenance: dict[str, object] = {"log": log.path, "columns": log.used}
    if log.device is not None:
        provenance["device"] = log.device
    hz = float(rate) if rate is not None else log.rate
    if hz is not None:
        provenance["rate"] = float(hz)
    cal = dataclasses.replace(cal, options={**cal.options, **provenance})
    found = PoseSet(None, None, [], None, hz, source="continuous")
    return LogCalibration(cal, found, tuple(notes))


def _input_notes(log: Log, mag_axes: str | None, accel_sign: str) -> tuple[list[str], Array | None]:
    """The notes on the input (columns, dropped rows, folded conventions) and the
    magnetometer's axis map (``None``: none), each convention checked against the log."""
    notes = [
        "columns used: "
        + "; ".join(f"{role} = {','.join(cols)}" for role, cols in log.used.items())
    ]
    notes += log.notes
    if log.dropped:
        notes.append(f"dropped {log.dropped} row(s) with NaN or inf values")
    P = None
    if mag_axes is not None:
        if log.mag is None:
            raise InputError("--mag-axes given but the log has no magnetometer columns")
        P = parse_axes(mag_axes)
        notes.append(
            f"magnetometer axes mapped {mag_axes} for the fit and folded back into its gain: "
            "apply the result to the raw columns as logged"
        )
    if accel_sign == "gravity":
        if log.accel is None:
            raise InputError("--accel-sign gravity given but the log has no accelerometer columns")
        notes.append(
            "accelerometer read as reporting gravity (−1 g on the up axis): fitted on the "
            "negated readings and folded back into its gain, so the correction gives the "
            "specific force (+1 g up) from the raw columns as logged"
        )
    return notes, P


def _with_pose_rows(cal: Calibration, found: PoseSet, log: Log) -> Calibration:
    """``cal`` with every pose found (its rows in the log; ``rejected`` for one the robust fit
    dropped) and the log's provenance (path, columns, device, rate)."""
    fitted = {int(row["index"]): row for row in cal.poses}
    dropped = {r.index: r for r in cal.rejected}
    rows = []
    for i, entry in enumerate(found.entries):
        row = {**fitted.get(i, {"index": i}), **entry}
        if i in dropped:
            row["rejected"] = f"{dropped[i].sensor}: {dropped[i].reason}"
        rows.append(row)
    provenance: dict[str, object] = {"log": log.path, "columns": log.used}
    if log.device is not None:  # the log names its device: fieldcal store add needs no --device
        provenance["device"] = log.device
    if found.rate is not None:  # the sample rate: noise densities (Kalibr) need it
        provenance["rate"] = float(found.rate)
    return dataclasses.replace(cal, poses=tuple(rows), options={**cal.options, **provenance})


def _how_found(log: Log, poses: PoseSet) -> str:
    at = f" at {poses.rate:.4g} Hz" if poses.rate else ""
    if poses.source == "samples":
        per = poses.record()["samples_per_pose"]
        how = f"one per sample{at}" if per == 1 else f"one per {per} samples{at}"
    elif poses.windows is not None:
        cut = poses.windows
        length = f"{cut.seconds:.3g} s" if cut.seconds else f"{cut.window}-sample"
        how = (
            f"cut into {length} windows{at} (motion {100 * cut.motion:.2g} % of the field, "
            f"limit {100 * cut.limit:.2g} %)"
        )
    elif poses.detection is not None:
        how = f"found by still detection{at}"
    elif "pose" in log.used:
        how = f"grouped by the pose column {log.used['pose'][0]!r}"
    else:
        how = "given"
    distinct = len({e["orientation"] for e in poses.entries})
    return f"{poses.n} poses {how} ({distinct} distinct orientations)"


def calibrate_log(
    source: Log | str | os.PathLike[str] | object,
    *,
    accel_cols: str | Sequence[str] | None = None,
    mag_cols: str | Sequence[str] | None = None,
    gyro_cols: str | Sequence[str] | None = None,
    time_col: str | None = None,
    pose_col: str | None = None,
    drop_nan: bool = False,
    on_progress: Callable[[str], None] | None = None,
    **options: object,
) -> Calibration:
    """Calibrate from a log: read it, find its poses, fit, as ``fieldcal calibrate`` does.

    Parameters
    ----------
    source : Log, path, DataFrame, pyarrow Table or mapping of columns
        The log (see :func:`fieldcal.read_log`).
    accel_cols, mag_cols, gyro_cols, time_col, pose_col, drop_nan
        Columns and missing values, as in :func:`fieldcal.read_log` (ignored for a ``Log``).
    poses : {"auto", "still", "windows", "samples", "continuous"}
        How the log is calibrated when it has no pose column: ``"still"`` detection of rests,
        consecutive ``"windows"`` of ``window`` seconds for a log turned slowly with no rests,
        every ``"samples"`` its own pose (a slow log without a gyroscope, however sparse; a
        dense one in short windows), the error bars of windows and samples widened for the
        correlation measured between neighbouring poses (``cal.options["pose_correlation"]``),
        ``"continuous"`` motion (:mod:`fieldcal.methods.continuous`: every sample, the
        gyroscope tying the orientations together; needs a gyroscope and time), or
        ``"auto"`` (default): still detection when the log has enough rests, else continuous
        when it has a gyroscope and time, with a note saying which and why.
    accel_sign : {"specific-force", "gravity"}
        What the accelerometer reports: the specific force (+1 g on the up axis at rest,
        default) or gravity (−1 g up, some loggers); the result corrects to the specific force.
    mag_axes : str, optional
        The magnetometer's axes onto the accelerometer's, e.g. ``"+y+x-z"``; folded back so
        the result applies to the raw columns.
    rate : float, optional
        Samples per second; overrides the time column's rate for the durations below (and
        the gyroscope's integration).
    gyro : bool, optional
        The gyroscope (``cal.gyro``, :mod:`fieldcal.gyro`), fitted to the motion between the
        poses when the log has one: by default when it can be (a note says why not otherwise),
        ``True`` to make any reason an error, ``False`` to skip it.
    window, min_still, still_trim, still_threshold : float, optional
        Still detection: moving-variance window, shortest still interval, the part cut at each
        end (seconds, samples without a rate) and the accelerometer threshold (raw units).
    on_progress : callable, optional
        Called with one line of text at each step.
    target_tilt, target_heading, target_norm : float, optional
        The verdict's accuracy targets (degrees, degrees, percent), in place of those of
        ``targets`` (default :class:`fieldcal.Targets`' values): ``--target-tilt`` ...
    **options
        Everything :func:`fieldcal.calibrate` takes: ``method``, ``gravity``,
        ``field_strength``, ``noise``, ``pose_noise``, ``robust``, ``mag_mirrored``,
        ``targets``, ..., and the reader's options (:data:`fieldcal.settings.READ_OPTIONS`).
        Each goes to its stage's settings object (:class:`LogSettings`); the defaults are the
        option table's (:mod:`fieldcal.settings`).

    Returns
    -------
    Calibration
        ``cal.poses`` lists every pose found, with its rows in the log and, for a pose the
        robust fit dropped, ``rejected``.
    """
    columns: dict[str, object] = {"accel_cols": accel_cols, "mag_cols": mag_cols}
    columns.update(gyro_cols=gyro_cols, time_col=time_col, pose_col=pose_col, drop_nan=drop_nan)
    settings = LogSettings.of({**columns, **options})
    reading = settings.read.keywords()
    if on_progress is not None:
        reading["on_progress"] = on_progress
    log = read_log(source, **reading)
    return run_log(log, settings, on_progress=on_progress).calibration


def document(cal: Calibration, poses: PoseSet) -> dict[str, Any]:
    """The calibration JSON with how the poses were found: ``still_detection`` (the
    detector's parameters) or ``pose_windows`` (the windows and the motion measured in them)."""
    doc = cal.to_dict()
    if poses.detection is not None:
        doc["still_detection"] = poses.record()
    elif poses.source == "samples":
        doc["pose_samples"] = poses.record()
    elif poses.windows is not None:
        doc["pose_windows"] = poses.record()
    elif poses.source == "continuous":
        doc["continuous"] = {
            **poses.record(),
            **{k: cal.options[k] for k in ("trajectory", "motion", "downweighted")},
        }
    return doc
