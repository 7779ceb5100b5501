"""From a log to a calibration: its poses (still detection, windows or a pose column), the
checks a log needs, ``fieldcal.calibrate``, the magnetometer's axis map and the accelerometer's
sign folded back, and the JSON document the ``calibrate`` command writes.

:func:`calibrate_log` is the library's form of ``fieldcal calibrate``; :func:`run_log` is the
same on a :class:`~fieldcal.logs.log.Log` with the poses and notes the CLI prints.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .api import calibrate
from .calibration import Calibration, ParameterCovariance
from .errors import InputError
from .geometry.frames import ACCEL_SIGNS, parse_axes
from .geometry.rotations import hat, rotation_angle_deg
from .gyro.estimate import GyroFit, fit_gyro
from .gyro.integrate import integrate
from .logs import Log, PoseSet, poses_from_log, turns_slowly
from .logs.poses import POSE_SOURCES
from .logs.sources import read_log
from .methods import get as get_method
from .methods.mle.uncertainty import pose_rotation_covariance
from .stats.poses import check_spread, stats_from_means

__all__ = [
    "ACCEL_SIGNS",
    "POSE_SOURCES",
    "LogCalibration",
    "calibrate_log",
    "document",
    "fold_axes",
    "read_log",
    "run_log",
]

#: Options of :func:`calibrate_log` that go to the reader, not to the calibration.
READ_OPTIONS = ("decimal", "split_on_reset", "imu_topic", "mag_topic")

Array = NDArray[np.float64]


def _check_poses(poses: PoseSet, method: str, log: Log, rate: float | None) -> None:
    n = poses.n
    sensors = [(name, getattr(poses, name)) for name in ("accel", "mag")]
    sensors = [(name, samples) for name, samples in sensors if samples is not None]
    need = get_method(method).min_poses_for(len(sensors))
    if n < need:
        advice = f"hold the device still in {need - n} or more further orientations"
        if poses.source == "still" and turns_slowly(log, rate=rate):
            advice = "the log turns slowly without rests: use --poses windows (poses='windows')"
        raise InputError(
            f"{n} pose(s) found; the {method} method needs at least {need}"
            + (
                " (the 6N readings must outnumber the 3N pose angles plus 22 sensor parameters)"
                if len(sensors) == 2
                else ""
            )
            + f": {advice}"
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
            f"least {need}: add poses tilted between the axes (e.g. resting on the edges and "
            "corners of a box), not only with each axis up and down"
        )


def fold_axes(cal: Calibration, P: Array, spec: str, sensor: str = "mag") -> Calibration:
    """Express a calibration fitted on ``P @ raw`` in terms of the raw columns.

    ``P @ raw = K v + b`` means ``raw = Pᵀ K v + Pᵀ b``: the gain becomes ``Pᵀ K`` and the bias
    ``Pᵀ b``, so firmware applies the result to the readings as logged. Used for the
    magnetometer's axis map (``spec`` recorded as ``options["mag_axes"]``) and for an
    accelerometer that reports gravity (``P = −I``, ``options["accel_sign"]``).
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
    )
    covariance = cal.covariance
    if covariance is not None:
        names = list(covariance.names)
        T = np.eye(len(names))
        # raw parameter (i, ...) = Σ_k Pᵀ[i, k] · fitted parameter (k, ...), per gain column
        triples = [[f"{sensor}.gain[{r},{j}]" for r in range(3)] for j in range(3)]
        triples.append([f"{sensor}.bias[{r}]" for r in range(3)])
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
    *,
    poses: str | PoseSet = "still",
    accel_sign: str = "specific-force",
    mag_axes: str | None = None,
    rate: float | None = None,
    window: float | None = None,
    min_still: float | None = None,
    still_trim: float | None = None,
    still_threshold: float | None = None,
    method: str = "mle",
    gyro: bool | None = None,
    on_progress: Callable[[str], None] | None = None,
    **options: Any,
) -> LogCalibration:
    """Find a log's poses and calibrate from them: the path of ``fieldcal calibrate``.

    See :func:`calibrate_log` for the parameters. ``log`` is not modified: the axis map and the
    accelerometer's sign apply to copies of its arrays.
    """
    if isinstance(poses, str):
        _check_choice("poses", poses, POSE_SOURCES)
    if gyro is True and log.gyro is None:  # before the long work
        raise InputError(
            "the gyroscope cannot be calibrated: the log has no gyroscope columns; name them "
            "with --gyro-cols"
        )
    _check_choice("accel_sign", accel_sign, ACCEL_SIGNS)
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
    gravity_sign = accel_sign == "gravity"
    if gravity_sign:
        if log.accel is None:
            raise InputError("--accel-sign gravity given but the log has no accelerometer columns")
        notes.append(
            "accelerometer read as reporting gravity (−1 g on the up axis): fitted on the "
            "negated readings and folded back into its gain, so the correction gives the "
            "specific force (+1 g up) from the raw columns as logged"
        )
    if isinstance(poses, PoseSet):
        found = poses
    else:
        if on_progress is not None:
            on_progress(f"finding the poses in {log.path}")
        # neither the map nor the sign moves a still interval: the poses are found in the
        # readings as logged and the samples of each are mapped below
        found = poses_from_log(
            log,
            poses=poses,
            rate=rate,
            window=window,
            min_still=min_still,
            trim=still_trim,
            threshold=still_threshold,
        )
    if P is not None and found.mag is not None:
        found = dataclasses.replace(found, mag=[m @ P.T for m in found.mag])
    if gravity_sign and found.accel is not None:
        found = dataclasses.replace(found, accel=[-a for a in found.accel])
    notes.append(_how_found(log, found))
    _check_poses(found, method, log, rate)
    if on_progress is not None:
        on_progress(f"calibrating {found.n} poses ({method})")
    cal = calibrate(found.accel, found.mag, method=method, on_progress=on_progress, **options)
    if gyro is not False:
        # on the fit as made (before an axis map or sign is folded into it): the poses'
        # orientation covariance comes from its noise model and gauge
        if on_progress is not None and log.gyro is not None:
            on_progress("calibrating the gyroscope from the motion between the poses")
        cal = _gyro_stage(log, found, cal, required=gyro is True, rate=rate, notes=notes)
    if P is not None and mag_axes is not None:
        cal = fold_axes(cal, P, mag_axes)
    if gravity_sign:
        cal = fold_axes(cal, -np.eye(3), accel_sign, sensor="accel")
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
    cal = dataclasses.replace(cal, poses=tuple(rows), options={**cal.options, **provenance})
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
        C = pose_rotation_covariance(cal)
        if cal.mag is not None and cal.magnetic is not None:
            fit = fit_gyro(time, log.gyro, rows, cal.rotations, rotation_cov=C)
        else:
            gravity = cal.correct_accel(found.means("accel")[kept])
            # the directions' errors from the poses' tilts: blockdiag(−[g_i]×) C blockdiag(...)ᵀ
            H = hat(gravity)
            n = len(kept)
            cov = np.einsum("iab,ibjc,jdc->iajd", H, C.reshape(n, 3, n, 3), H)
            fit = fit_gyro(
                time, log.gyro, rows, gravity_body=gravity, gravity_cov=cov.reshape(3 * n, 3 * n)
            )
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
    segments = []
    for (first, last), residual in zip(fit.segments, fit.segment_residual_deg, strict=True):
        # the turn the calibrated gyroscope integrates over the segment
        turn = integrate(time[first : last + 1], sensor.correct(log.gyro[first : last + 1]))
        segments.append(
            {
                "start": int(log.index[first]),
                "stop": int(log.index[last]) + 1,
                "seconds": float(time[last] - time[first]),
                "angle_deg": float(rotation_angle_deg(turn)),
                "residual_deg": float(residual),
            }
        )
    how = {
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
    return dataclasses.replace(
        cal,
        gyro=sensor,
        covariance=covariance,
        gyro_segments=tuple(segments),
        options={**cal.options, "gyro": how},
    )


def _how_found(log: Log, poses: PoseSet) -> str:
    at = f" at {poses.rate:.4g} Hz" if poses.rate else ""
    if poses.windows is not None:
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
    **options: Any,
) -> Calibration:
    """Calibrate from a log: read it, find its poses, fit, as ``fieldcal calibrate`` does.

    Parameters
    ----------
    source : Log, path, DataFrame, pyarrow Table or mapping of columns
        The log (see :func:`fieldcal.read_log`).
    accel_cols, mag_cols, gyro_cols, time_col, pose_col, drop_nan
        Columns and missing values, as in :func:`fieldcal.read_log` (ignored for a ``Log``).
    poses : {"still", "windows"}
        How the log is cut into poses when it has no pose column: still detection (default),
        or consecutive windows of ``window`` seconds for a log turned slowly with no rests.
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
    **options
        Everything :func:`fieldcal.calibrate` takes: ``method``, ``gravity``,
        ``field_strength``, ``noise``, ``pose_noise``, ``robust``, ``mag_mirrored``, ...

    Returns
    -------
    Calibration
        ``cal.poses`` lists every pose found, with its rows in the log and, for a pose the
        robust fit dropped, ``rejected``.
    """
    reading = {k: options.pop(k) for k in READ_OPTIONS if k in options}
    if options.get("on_progress") is not None:
        reading["on_progress"] = options["on_progress"]
    log = read_log(
        source,
        accel_cols=accel_cols,
        mag_cols=mag_cols,
        gyro_cols=gyro_cols,
        time_col=time_col,
        pose_col=pose_col,
        drop_nan=drop_nan,
        **reading,
    )
    return run_log(log, **options).calibration


def document(cal: Calibration, poses: PoseSet) -> dict[str, Any]:
    """The calibration JSON with how the poses were found: ``still_detection`` (the
    detector's parameters) or ``pose_windows`` (the windows and the motion measured in them)."""
    doc = cal.to_dict()
    if poses.detection is not None:
        doc["still_detection"] = poses.record()
    elif poses.windows is not None:
        doc["pose_windows"] = poses.record()
    return doc
