"""What an estimator measured that the verdict judges: typed findings, one frozen dataclass per
kind, carried by :attr:`fieldcal.Calibration.findings`.

An estimator (:mod:`fieldcal.methods`' registry: the pose methods, the continuous-motion
estimator, the gyroscope stage) never builds a :class:`~fieldcal.calibration.Reason` or a
:class:`~fieldcal.calibration.Verdict`: it fills in these, and the rules of
:mod:`fieldcal.trust.verdict` read them. Each is written to the calibration file under
``findings`` (``docs/json-schema.md``), so a report or a plan made from the file sees what the
fit saw.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypedDict

__all__ = [
    "Findings",
    "GyroFindings",
    "GyroSegment",
    "MotionFindings",
    "PoseCorrelation",
    "TemperatureIgnored",
    "TemperatureSpan",
]


class GyroSegment(TypedDict):
    """One motion segment the gyroscope was fitted on: an entry of
    :attr:`fieldcal.Calibration.gyro_segments` (the JSON's ``gyro_segments``, keys as here)."""

    start: int  # first data row of the segment in the file
    stop: int  # one past its last data row
    seconds: float
    angle_deg: float  # turned over the segment
    residual_deg: float  # the integrated turn against the poses', after calibration


@dataclass(frozen=True)
class GyroFindings:
    """The gyroscope stage's fit to the motion between the poses (:mod:`fieldcal.gyro`).

    Attributes
    ----------
    segments_used, segments_left_out : int
        Motion segments fitted, and left out because their integrated turn disagreed with
        the poses' (a bump, a gap in the log, time stamps that are not the samples' own).
    p_value : float
        The segments' misfit statistic against its χ² distribution.
    widening : float
        The factor its error bars were widened by for that misfit (1: none).
    """

    segments_used: int
    segments_left_out: int
    p_value: float
    widening: float


@dataclass(frozen=True)
class PoseCorrelation:
    """Poses cut from one continuous motion (``poses="windows"``/``"samples"``): their residuals'
    correlation between neighbours (:mod:`fieldcal.trust.correlation`).

    Attributes
    ----------
    tau : float
        Correlation time, in poses.
    effective_poses : float
        About how many independent poses the correlated ones are worth.
    poses : int
        Poses fitted.
    widening : float
        Factor the error bars were widened by.
    """

    tau: float
    effective_poses: float
    poses: int
    widening: float


@dataclass(frozen=True)
class MotionFindings:
    """The continuous-motion estimator's view of its log (:mod:`fieldcal.methods.continuous`).

    Attributes
    ----------
    undetermined : tuple of str
        For each group of parameters the motion leaves undetermined, the turns to add.
    lacking : str
        What the motion lacks when the fit did not settle ("" when nothing, or not asked).
    unsettled : tuple of str
        Parameters left undetermined although the log turned through them (the fit, not the
        recording).
    disturbed_seconds, duration_seconds : float
        Seconds down-weighted for body acceleration, of the log's duration.
    field_strength_rms : float
        The calibrated field's strength, RMS relative departure from 1 (a magnet that moves
        with the device but not rigidly, iron passed near it).
    dip_spread_deg : float
        The dip's spread over the estimator's stretches where the accelerometer reads gravity.
    gyro_units_ratio : float or None
        The raw rates' turning over the magnetometer direction's own (about 1 in rad/s, 57 in
        °/s); ``None`` when the field direction barely turned.
    turn_step_rad : float
        The largest turns per sample (99th percentile of ``|ω| Δt``).
    max_rate : float
        The largest rate, rad/s.
    clipped_axes : tuple of int
        Gyroscope axes at their range on more than 0.5 % of the samples.
    """

    undetermined: tuple[str, ...] = ()
    lacking: str = ""
    unsettled: tuple[str, ...] = ()
    disturbed_seconds: float = 0.0
    duration_seconds: float = 0.0
    field_strength_rms: float = 0.0
    dip_spread_deg: float = 0.0
    gyro_units_ratio: float | None = None
    turn_step_rad: float = 0.0
    max_rate: float = 0.0
    clipped_axes: tuple[int, ...] = ()


@dataclass(frozen=True)
class TemperatureSpan:
    """A temperature column whose span was too small for temperature terms: the calibration
    holds at the mean temperature (°C)."""

    low: float
    high: float
    mean: float


@dataclass(frozen=True)
class TemperatureIgnored:
    """A temperature column left out as unusable (``--ignore-bad-temp``): its name and why."""

    column: str
    why: str


@dataclass(frozen=True)
class Findings:
    """Every kind of finding an estimator reports; ``None`` where the path does not measure it.

    Attributes
    ----------
    gyro : GyroFindings or None
        The gyroscope stage of a pose calibration.
    pose_correlation : PoseCorrelation or None
        Correlated poses (windows, samples).
    motion : MotionFindings or None
        The continuous-motion estimator.
    temperature_span : TemperatureSpan or None
        The continuous estimator's refused temperature terms (the pose path reads its pose
        statistics).
    temperature_ignored : TemperatureIgnored or None
        The log's temperature column, left out as unusable.
    """

    gyro: GyroFindings | None = None
    pose_correlation: PoseCorrelation | None = None
    motion: MotionFindings | None = None
    temperature_span: TemperatureSpan | None = None
    temperature_ignored: TemperatureIgnored | None = None
