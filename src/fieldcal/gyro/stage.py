"""The gyroscope stage of a pose calibration: the gyroscope fitted to the motion between the
fitted poses of a log (:func:`fieldcal.gyro.fit_gyro`), attached to the calibration with its
findings (:class:`fieldcal.findings.GyroFindings`: segments left out, misfit) for the verdict's
rules (``gyro_segments``, ``gyro_misfit``, ``gyro_gain`` in :mod:`fieldcal.trust.verdict`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TypedDict

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration, ParameterCovariance
from ..errors import InputError
from ..findings import GyroFindings, GyroSegment
from ..geometry.rotations import hat, rotation_angle_deg
from ..likelihood.cramer_rao import pose_rotation_factors
from ..logs import Log, PoseSet
from ..logs.log_temperature import pose_temperature_samples
from ..logs.pose_finding import PoseEntry
from .estimate import GyroFit, fit_gyro
from .integrate import segment_turns
from .temperature import with_bias_temperature

__all__ = ["GyroRecord", "gyro_stage", "with_gyro"]


class GyroRecord(TypedDict, total=False):
    """How the gyroscope was fitted: ``Calibration.options["gyro"]`` (the JSON's
    ``options.gyro``), read by the report and by a person checking the fit."""

    method: str
    drift: float | None
    drift_p_value: float | None
    bias_wander: float
    pose_time: list[float]  # seconds, each pose's middle
    pose_bias: list[list[float]]  # each pose's mean rate, rad/s
    observable: list[str]
    statistic: float
    dof: int
    p_value: float
    widening: float
    temperature: dict[str, object]  # the bias against temperature, with one


def _log_rows(log: Log, entry: PoseEntry) -> tuple[int, int]:
    """A pose's first and stop positions among the log's kept rows (``start``/``stop`` are
    data-row numbers)."""
    first = int(np.searchsorted(log.index, int(entry["start"])))
    stop = int(np.searchsorted(log.index, int(entry["stop"]) - 1)) + 1
    return first, stop


def gyro_stage(
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
    elif (hz := rate or log.rate) is not None:
        time = np.arange(log.n) / float(hz)
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
        GyroSegment(
            start=int(log.index[first]),
            stop=int(log.index[last]) + 1,
            seconds=float(time[last] - time[first]),
            angle_deg=float(angle),
            residual_deg=float(residual),
        )
        for (first, last), angle, residual in zip(
            fit.segments, angles, fit.segment_residual_deg, strict=True
        )
    ]
    how: GyroRecord = {
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
    found = GyroFindings(
        segments_used=len(fit.segments),
        segments_left_out=len(fit.rejected),
        p_value=float(fit.p_value),
        widening=float(fit.widening),
    )
    return dataclasses.replace(
        cal,
        gyro=sensor,
        covariance=covariance,
        gyro_segments=tuple(segments),
        options={**cal.options, "gyro": how},
        findings=dataclasses.replace(cal.findings, gyro=found),
    )
