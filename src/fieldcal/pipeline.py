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
from .calibration import Calibration, ParameterCovariance
from .errors import InputError
from .geometry.frames import ACCEL_SIGNS, parse_axes
from .geometry.rotations import hat, rotation_angle_deg
from .gyro.estimate import GyroFit, fit_gyro
from .gyro.gyro_temperature import with_bias_temperature
from .gyro.integrate import effective_time, segment_turns
from .likelihood.cramer_rao import pose_rotation_factors
from .logs import Log, PoseSet, poses_from_log, turns_slowly
from .logs.inputs import read_log
from .logs.log_temperature import pose_temperature_samples
from .logs.pose_finding import NO_STILL, POSE_SOURCES
from .logs.pose_hints import pose_advice
from .methods import get as get_method
from .methods.continuous import fit_continuous
from .settings import (
    OPTIONS,
    TARGET_OPTIONS,
    DetectSettings,
    FitSettings,
    ReadSettings,
    TrustSettings,
    changed,
    settings_of,
)
from .stats.pose_stats import check_spread, stats_from_means
from .trust.continuous_motion import trust_continuous
from .trust.targets import Targets

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
#: The still detector's warning that its "rests" move: with ``poses="auto"`` the log is then
#: calibrated from continuous motion when it can be.
MOVING_RESTS = "the still intervals found move"
#: Options of :func:`calibrate` the continuous estimator and its trust path use
#: (:func:`fieldcal.trust.continuous_motion.trust_continuous`); others are noted as unused.
CONTINUOUS_OPTIONS = (
    "gravity",
    "field_strength",
    "mag_mirrored",
    "location",
    "date",
    "dip_allowance_deg",
    "targets",
    "gyro_sampling",
    "gyro_noise",
    "hold",
    "prior",
    *TARGET_OPTIONS,
)
#: Fit options :func:`run_log` itself reads, whatever estimator it runs.
_LOG_OPTIONS = ("method", "mag_axes", "accel_sign", "gyro")

Array = NDArray[np.float64]


def _check_poses(
    poses: PoseSet,
    method: str,
    log: Log,
    rate: float | None,
    detection: dict[str, Any] | None = None,
) -> None:
    """Enough poses and orientations for ``method``, else an :class:`InputError` naming the
    fix. ``detection``: the settings the poses were found with in ``log`` (None: the poses were
    given): the message then says which other settings find how many
    (:func:`~fieldcal.logs.pose_hints.pose_advice`)."""
    n = poses.n
    sensors = [(name, getattr(poses, name)) for name in ("accel", "mag")]
    sensors = [(name, samples) for name, samples in sensors if samples is not None]
    need = get_method(method).min_poses_for(len(sensors))
    hints = None
    if detection is not None and poses.source in ("still", "column"):
        distinct = len({entry.get("orientation", i) for i, entry in enumerate(poses.entries)})
        if n < need or distinct < max(need, 8 if len(sensors) == 2 else 9):
            hints = pose_advice(log, found=poses, **detection)
    if n < need:
        advice = f"hold the device still in {need - n} or more further orientations"
        if hints is None and poses.source == "still" and turns_slowly(log, rate=rate):
            advice = "the log turns slowly without rests: use --poses windows (poses='windows')"
        why = " (the 6N readings must outnumber the 3N pose angles plus 22 sensor parameters)"
        raise InputError(
            f"{n} pose(s) found; the {method} method needs at least {need}"
            + (why if len(sensors) == 2 and hints is None else "")
            + (f": {hints}; or {advice}" if hints else f": {advice}")
        )
    means = {name: poses.means(name) for name, _ in sensors}
    try:
        check_spread(stats_from_means(means.get("accel"), means.get("mag")))
    except ValueError as exc:
        raise InputError(str(exc)) from None
    # one sensor alone: 9 unknowns (symmetric gain and bias), one constraint per orientation
    need = max(need, 8 if len(sensors) == 2 else 9)
    distinct = len({entry["orientation"] for entry in poses.entries})
    if distinct < need:
        raise InputError(
            f"the {n} poses show only {distinct} distinct orientations (closer than 3° count as "
            f"one); {'a joint' if len(sensors) == 2 else 'a single-sensor'} calibration needs at "
            f"least {need}: "
            + (f"{hints}; or add" if hints else "add")
            + " poses tilted between the axes (e.g. resting on the edges and corners of a box), "
            "not only with each axis up and down"
        )


def fold_axes(cal: Calibration, P: Array, spec: str, sensor: str = "mag") -> Calibration:
    """Express a calibration fitted on ``P @ raw`` in terms of the raw columns.

    ``P @ raw = K v + b`` means ``raw = Pᵀ K v + Pᵀ b``: the gain becomes ``Pᵀ K`` and the bias
    ``Pᵀ b``, so firmware applies the result to the readings as logged. Used for the
    magnetometer's axis map (``spec`` recorded as ``options["mag_axes"]``) and for an
    accelerometer that reports gravity (``P = −I``, ``options["accel_sign"]``). The bias's
    temperature terms fold the same way, ``c_k → Pᵀ c_k`` (:mod:`fieldcal.thermal`).
    """
    fitted = getattr(cal, sensor)
    if fitted is None:
        return cal
    Pt, A = P.T, np.abs(P.T)
    new = dataclasses.replace(
        fitted,
        gain=Pt @ fitted.gain,
        bias=Pt @ fitted.bias,
        noise_cov=Pt @ fitted.noise_cov @ P,
        noise_cov_std=None if fitted.noise_cov_std is None else A @ fitted.noise_cov_std @ A.T,
        temperature=None
        if fitted.temperature is None
        else dataclasses.replace(
            fitted.temperature, coefficients=fitted.temperature.coefficients @ P, std=None
        ),
    )
    covariance = cal.covariance
    if covariance is not None:
        names = list(covariance.names)
        T = np.eye(len(names))
        # raw parameter (i, ...) = Σ_k Pᵀ[i, k] · fitted parameter (k, ...), per gain column
        triples = [[f"{sensor}.gain[{r},{j}]" for r in range(3)] for j in range(3)]
        triples.append([f"{sensor}.bias[{r}]" for r in range(3)])
        order = 0 if fitted.temperature is None else fitted.temperature.order
        triples += [[f"{sensor}.temp[{k},{r}]" for r in range(3)] for k in range(1, order + 1)]
        for triple in triples:
            if all(t in names for t in triple):
                idx = [names.index(t) for t in triple]
                T[np.ix_(idx, idx)] = Pt
        covariance = covariance.transformed(T)
    key = f"{sensor}_residual"
    poses = tuple(
        {**row, key: list(Pt @ np.asarray(row[key]))} if key in row else row for row in cal.poses
    )
    option = "mag_axes" if sensor == "mag" else "accel_sign"
    return dataclasses.replace(
        cal,
        **{sensor: new},
        covariance=covariance,
        options={**cal.options, option: spec},
        poses=poses,
    )


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
        keywords = {**(keywords or {}), **more}
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


def run_log(
    log: Log,
    settings: LogSettings = _DEFAULT_SETTINGS,
    *,
    found: PoseSet | None = None,
    on_progress: Callable[[str], None] | None = None,
) -> LogCalibration:
    """Find a log's poses and calibrate from them: the path of ``fieldcal calibrate``.

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
    detect, fit = settings.detect, settings.fit
    poses: str | PoseSet = detect.poses if found is None else found
    accel_sign, mag_axes, method, gyro = fit.accel_sign, fit.mag_axes, fit.method, fit.gyro
    rate = detect.rate
    if isinstance(poses, str):
        _check_choice("poses", poses, POSE_MODES)
    if gyro is True and log.gyro is None:  # before the long work
        raise InputError(
            "the gyroscope cannot be calibrated: the log has no gyroscope columns; name them "
            "with --gyro-cols"
        )
    _check_choice("accel_sign", accel_sign, ACCEL_SIGNS)
    notes, P = _input_notes(log, mag_axes, accel_sign)
    gravity_sign = accel_sign == "gravity"
    tuned = [
        name
        for name, value in (
            ("window", detect.window),
            ("min_still", detect.min_still),
            ("still_trim", detect.still_trim),
            ("still_threshold", detect.still_threshold),
        )
        if value is not None
    ]
    if poses == "auto" and tuned:  # the still detector's options given: the user wants rests
        poses = "still"
        notes.append(
            f"poses='auto': still detection, as its options were given ({', '.join(tuned)})"
        )
    why_not = _why_not_continuous(log, rate, gyro) if poses in ("auto", "continuous") else None
    if poses == "continuous" and why_not is not None:
        raise InputError(f"poses='continuous' (--poses continuous) needs {why_not}")
    if poses == "continuous":
        return _run_continuous(log, P, settings, notes, on_progress)
    # the settings the poses are looked for with (None: given), for the advice on too few
    detection: dict[str, Any] | None = None
    # True once these very poses passed _check_poses (poses='auto'): checking them again
    # would pass too, the detection settings only shape a failure's advice
    checked = False
    if isinstance(poses, PoseSet):
        found = poses
    else:
        if on_progress is not None:
            on_progress(f"finding the poses in {log.path}")
        # neither the map nor the sign moves a still interval: the poses are found in the
        # readings as logged and the samples of each are mapped below
        detection = detect.detector_keywords()
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                found = _find_poses(log, poses, detection, why_not)
            moving = [w for w in caught if MOVING_RESTS in str(w.message)]
            if poses == "auto" and why_not is None and moving:
                raise InputError(str(moving[0].message))
            for w in caught:  # the detector's own warnings, passed on
                warnings.warn(w.message, w.category, stacklevel=2)
            if poses == "auto":
                _check_poses(found, method, log, rate, None if why_not is None else detection)
                checked = True
        except InputError as exc:
            if poses != "auto" or why_not is not None:
                raise
            # what the rests lack, without their advice ("hold still"): the motion is used
            why = "its rests move" if MOVING_RESTS in str(exc) else str(exc).split(": ")[0]
            notes.append(
                "poses='auto': calibrated from continuous motion, not from rests (still "
                f"detection: {why}); the log has a gyroscope and time"
            )
            # a fit that did not converge is still written, its verdict fail with the causes
            # the continuous rules name (docs/methods/continuous.md)
            return _run_continuous(log, P, settings, notes, on_progress)
        if poses == "auto":
            notes.append(f"poses='auto': calibrated from {found.n} rests found by still detection")
    if P is not None and found.mag is not None:
        found = dataclasses.replace(found, mag=[m @ P.T for m in found.mag])
        checked = False
    if gravity_sign and found.accel is not None:
        found = dataclasses.replace(found, accel=[-a for a in found.accel])
        checked = False
    notes.append(_how_found(log, found))
    if not checked:
        _check_poses(found, method, log, rate, detection)
    if on_progress is not None:
        on_progress(f"calibrating {found.n} poses ({method})")
    temperature = pose_temperature_samples(log, found.entries)
    cal = calibrate_with(
        found.accel,
        found.mag,
        fit,
        settings.trust,
        targets=settings.targets,
        method_options=settings.method_options,
        on_progress=on_progress,
        time_ordered=found.time_ordered,  # samples, windows: error bars for correlated poses
        temperature=temperature,
    )
    if gyro is not False:
        # on the fit as made (before an axis map or sign is folded into it): the poses'
        # orientation covariance comes from its noise model and gauge
        if on_progress is not None and log.gyro is not None:
            on_progress("calibrating the gyroscope from the motion between the poses")
        cal = _gyro_stage(
            log, found, cal, required=gyro is True, rate=rate, notes=notes, on_progress=on_progress
        )
    if P is not None and mag_axes is not None:
        cal = fold_axes(cal, P, mag_axes)
    if gravity_sign:
        cal = fold_axes(cal, -np.eye(3), accel_sign, sensor="accel")
    return LogCalibration(_with_pose_rows(cal, found, log), found, tuple(notes))


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
    provenance: dict[str, Any] = {"log": log.path, "columns": log.used}
    if log.device is not None:  # the log names its device: fieldcal store add needs no --device
        provenance["device"] = log.device
    if found.rate is not None:  # the sample rate: noise densities (Kalibr) need it
        provenance["rate"] = float(found.rate)
    return dataclasses.replace(cal, poses=tuple(rows), options={**cal.options, **provenance})


def _find_poses(log: Log, poses: str, detection: dict[str, Any], why_not: str | None) -> PoseSet:
    """:func:`poses_from_log`; when still detection finds no rest, the error says which other
    settings find how many poses (not when ``poses='auto'`` goes on to continuous motion:
    ``why_not`` None)."""
    try:
        return poses_from_log(log, poses="still" if poses == "auto" else poses, **detection)
    except InputError as exc:
        text = str(exc)
        if NO_STILL not in text or (poses == "auto" and why_not is None):
            raise
        advice = pose_advice(log, **detection)
        if advice is None:
            raise
        raise InputError(f"{text.split('; try ', 1)[0]}; {advice}") from None


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


def _run_continuous(
    log: Log,
    P: Array | None,
    settings: LogSettings,
    notes: list[str],
    on_progress: Callable[[str], None] | None,
) -> LogCalibration:
    """The continuous-motion estimator on the whole log (:func:`fieldcal.methods.continuous.
    fit_continuous`) and the shared trust path (:func:`fieldcal.trust.continuous_motion.
    trust_continuous`: handedness, the reference, accuracy, verdict), the axis map and the
    accelerometer's sign folded back as for poses."""
    assert log.accel is not None and log.mag is not None and log.gyro is not None
    fit, rate = settings.fit, settings.detect.rate
    mag_axes, accel_sign = fit.mag_axes, fit.accel_sign
    # checked before the long work, as calibrate_with checks them
    reference, magnitudes = field_settings(fit, settings.trust)
    gravity, field_strength = magnitudes["accel"], magnitudes["mag"]
    targets = targets_for(settings.targets, settings.trust)
    if log.time is not None and rate is None:
        time = effective_time(log.time)
    else:
        time = np.arange(log.n) / float(rate or log.rate)  # type: ignore[arg-type]
    unused = sorted(
        k
        for k, v in settings.given().items()
        if k not in CONTINUOUS_OPTIONS
        and k not in _LOG_OPTIONS
        and v is not None
        and v is not False
        and v != "auto"
    )
    if unused:
        notes.append(f"not used by the continuous estimator: {', '.join(unused)}")
    accel = -log.accel if accel_sign == "gravity" else log.accel
    mag = log.mag if P is None else log.mag @ P.T
    if on_progress is not None:
        on_progress(f"calibrating from continuous motion ({log.n} samples)")
    try:
        cal = fit_continuous(
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
            prior=fit.prior,
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
        reference=reference,
        dip_allowance_deg=float(settings.trust.dip_allowance_deg),
        targets=targets,
        magnitudes=magnitudes,
    )
    if P is not None and mag_axes is not None:
        cal = fold_axes(cal, P, mag_axes)
    if accel_sign == "gravity":
        cal = fold_axes(cal, -np.eye(3), accel_sign, sensor="accel")
    traj = cal.options["trajectory"]
    notes.append(
        f"continuous motion: {traj['duration_s']:.4g} s, {traj['epochs']} epochs, "
        f"{100 * traj['gravity_coverage']:.0f} % of gravity directions visited, "
        f"{len(cal.options['downweighted'])} stretch(es) down-weighted for body acceleration"
    )
    provenance: dict[str, Any] = {"log": log.path, "columns": log.used}
    if log.device is not None:
        provenance["device"] = log.device
    hz = float(rate) if rate is not None else log.rate
    if hz is not None:
        provenance["rate"] = float(hz)
    cal = dataclasses.replace(cal, options={**cal.options, **provenance})
    found = PoseSet(None, None, [], None, hz, source="continuous")
    return LogCalibration(cal, found, tuple(notes))


def _log_rows(log: Log, entry: Mapping[str, Any]) -> tuple[int, int]:
    """A pose's first and stop positions among the log's kept rows (``start``/``stop`` are
    data-row numbers)."""
    first = int(np.searchsorted(log.index, int(entry["start"])))
    stop = int(np.searchsorted(log.index, int(entry["stop"]) - 1)) + 1
    return first, stop


def _gyro_stage(
    log: Log,
    found: PoseSet,
    cal: Calibration,
    *,
    required: bool,
    rate: float | None,
    notes: list[str],
    on_progress: Callable[[str], None] | None = None,
) -> Calibration:
    """The gyroscope, fitted to the motion between the fitted poses (:func:`fieldcal.gyro.
    fit_gyro`): with both field sensors, to the rotations the joint fit found; with the
    accelerometer alone, to the gravity directions. ``required`` (``gyro=True``) turns every
    reason not to into an error; otherwise the reason is a note and the result has no gyro."""

    def skip(reason: str) -> Calibration:
        if required:
            raise InputError(f"the gyroscope cannot be calibrated: {reason}")
        if log.gyro is not None:
            notes.append(f"gyroscope not calibrated: {reason}")
        return cal

    if log.gyro is None:
        return skip("the log has no gyroscope columns; name them with --gyro-cols")
    if found.source == "samples":
        return skip(
            "poses='samples' leaves no motion between the poses to integrate; use "
            "poses='continuous' (--poses continuous) for a log with a gyroscope"
        )
    if cal.accel is None:
        return skip("it needs the accelerometer (the gravity directions) to be calibrated")
    if log.time is not None and rate is None:
        time = log.time
    elif rate is not None or log.rate is not None:
        time = np.arange(log.n) / float(rate or log.rate)  # type: ignore[arg-type]
    else:
        return skip("the log has no time column; give one or the sample rate (--rate)")
    dropped = {r.index for r in cal.rejected}
    kept = [i for i in range(found.n) if i not in dropped]
    if any("start" not in found.entries[i] or "stop" not in found.entries[i] for i in kept):
        return skip("the poses are not intervals of the log in time order (a pose column)")
    rows = [_log_rows(log, found.entries[i]) for i in kept]
    try:
        # the poses' rotation covariance in its structure: linear in the number of poses
        C = pose_rotation_factors(cal)
        if cal.mag is not None and cal.magnetic is not None:
            fit = fit_gyro(
                time,
                log.gyro,
                rows,
                cal.rotations,
                rotation_cov=C,
                on_progress=on_progress,
            )
        else:
            gravity = cal.correct_accel(found.means("accel")[kept])
            # the directions' errors from the poses' tilts: blockdiag(−[g_i]×) C blockdiag(...)ᵀ
            fit = fit_gyro(
                time,
                log.gyro,
                rows,
                gravity_body=gravity,
                gravity_cov=C.transformed(hat(gravity)),
                on_progress=on_progress,
            )
        # the still poses' temperatures: the bias a polynomial in them, about the others' T_ref
        temps = pose_temperature_samples(log, [found.entries[i] for i in kept])
        if temps is not None:
            refs = [s.temperature.reference for s in (cal.accel, cal.mag) if s and s.temperature]
            means = [float(np.mean(t)) for t in temps]
            fit = with_bias_temperature(fit, means, refs[0] if refs else None)
    except InputError as exc:
        return skip(str(exc))
    except (np.linalg.LinAlgError, FloatingPointError, OverflowError):
        return skip(
            "its fit failed in floating point; check that the time column is in seconds "
            "(or give --time-col / --rate)"
        )
    used = len(fit.segments)
    if fit.rejected:
        notes.append(
            f"gyroscope: {len(fit.rejected)} of {used + len(fit.rejected)} motion segments left "
            "out: their integrated turn disagrees with the poses' (a bump, a gap in the log, or "
            "timestamps that are not the samples' own)"
        )
    if fit.p_value < 0.01:
        notes.append(
            f"gyroscope: the motion segments disagree with the model beyond their noise "
            f"(p = {fit.p_value:.2g}); its error bars are widened by {fit.widening:.3g}"
        )
    return with_gyro(cal, fit, log, time)


def with_gyro(cal: Calibration, fit: GyroFit, log: Log, time: NDArray[np.float64]) -> Calibration:
    """``cal`` with the gyroscope of ``fit``: its parameters, their covariance beside the
    others' (no correlation kept), the motion segments and how it was fitted."""
    assert log.gyro is not None  # the readings it was fitted to
    sensor = fit.sensor
    covariance = cal.covariance
    if covariance is not None:
        n, m = len(covariance.names), len(fit.covariance.names)
        matrix = np.zeros((n + m, n + m))
        matrix[:n, :n] = covariance.matrix
        matrix[n:, n:] = fit.covariance.matrix
        covariance = ParameterCovariance((*covariance.names, *fit.covariance.names), matrix)
    spans = np.array(fit.segments, dtype=np.int64).reshape(-1, 2)
    # the turn the calibrated gyroscope integrates over each segment, all at once: the
    # segments' rows gathered (only they are corrected)
    length = spans[:, 1] - spans[:, 0] + 1
    start = np.cumsum(length) - length
    rows = np.repeat(spans[:, 0] - start, length) + np.arange(int(length.sum()))
    turns = segment_turns(
        time[rows], sensor.correct(log.gyro[rows]), np.column_stack([start, start + length - 1])
    )
    angles = rotation_angle_deg(turns)
    segments = [
        {
            "start": int(log.index[first]),
            "stop": int(log.index[last]) + 1,
            "seconds": float(time[last] - time[first]),
            "angle_deg": float(angle),
            "residual_deg": float(residual),
        }
        for (first, last), angle, residual in zip(
            fit.segments, angles, fit.segment_residual_deg, strict=True
        )
    ]
    how: dict[str, Any] = {
        "method": fit.method,
        "drift": fit.drift,
        "drift_p_value": fit.drift_p_value,
        "bias_wander": fit.bias_wander,
        "pose_time": [float(t) for t in fit.pose_time],
        "pose_bias": [[float(v) for v in row] for row in fit.pose_bias],
        "observable": list(fit.observable),
        "statistic": fit.statistic,
        "dof": fit.dof,
        "p_value": fit.p_value,
        "widening": fit.widening,
    }
    if fit.temperature_record:
        how["temperature"] = fit.temperature_record
    return dataclasses.replace(
        cal,
        gyro=sensor,
        covariance=covariance,
        gyro_segments=tuple(segments),
        options={**cal.options, "gyro": how},
    )


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
