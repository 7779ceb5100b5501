"""Every reading, detection, fitting and trust option, declared once.

Each option is one field of one of four small frozen dataclasses, by the stage that uses it —
:class:`ReadSettings` (the reader), :class:`DetectSettings` (cutting a log into poses),
:class:`FitSettings` (the calibration) and :class:`TrustSettings` (the reference and the
verdict) — with its default, and in the field's metadata an :class:`Option`: its flag on the
command line (and column in a batch manifest), its unit, its valid values and its help text.
:data:`OPTIONS` walks the four classes; from it come the command line's options
(``fieldcal.cli.options``), the manifest's per-log columns (``fieldcal.batch.manifest``) and
the split of the library's keyword arguments by stage (:func:`settings_of`,
:meth:`fieldcal.pipeline.LogSettings.of`; the readers' :data:`READ_OPTIONS`). :func:`parse`
turns an option's text (a command-line value, a manifest cell) into its value, or raises
``ValueError`` with the one-line reason.

Adding an option is one field here: a name (the library's keyword), a type and default, and
``meta(flag, help, ...)`` with its unit and ``valid`` values (a :class:`Range`, choices, or a
parser of its text). The command line picks it up for every command that takes its stage, the
manifest as a column; the stage's code reads it from its settings object. An option of the
library alone (``false_alarm``, ``body_frame``, ``cut_unsteady``) has no flag: no command-line
option, no manifest column.

The settings objects hold the values as the user gave them; each stage checks its own once,
with a one-line error (:func:`fieldcal.api.calibrate_with` the fit's and the trust's,
:func:`fieldcal.pipeline.run_log` the detection's choices, the reader the columns), and no
stage re-lists the defaults: the library's keyword defaults are these fields' defaults.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeAlias, TypeVar

from numpy.typing import ArrayLike

from .errors import InputError
from .geometry.frames import ACCEL_SIGNS
from .option_text import (
    WMM_UNITS,
    parse_field_strength,
    parse_flag,
    parse_noise,
    parse_pose_noise,
    wmm_unit,
)
from .option_types import (
    MAGNITUDE,
    NON_NEGATIVE,
    POSITIVE,
    Option,
    Range,
    Stage,
    library_only,
    meta,
)
from .reference import DIP_ALLOWANCE_DEG

__all__ = [
    "BODY_FRAMES",
    "CONTINUOUS_ONLY",
    "DEFAULT_METHOD",
    "ESTIMATION_PATHS",
    "MAGNITUDE",
    "NON_NEGATIVE",
    "OPTIONS",
    "POSES_ONLY",
    "POSE_CHOICES",
    "POSITIVE",
    "READ_OPTIONS",
    "RENAMED_KEYWORDS",
    "STAGES",
    "TARGET_OPTIONS",
    "WMM_UNITS",
    "DateSpec",
    "DetectSettings",
    "FitSettings",
    "LocationSpec",
    "NoiseSpec",
    "Option",
    "PoseNoiseSpec",
    "Range",
    "ReadSettings",
    "Stage",
    "TrustSettings",
    "changed",
    "parse",
    "parse_field_strength",
    "parse_noise",
    "parse_pose_noise",
    "renamed",
    "settings_of",
    "wmm_unit",
]

#: The calibration method when none is named (a name in :data:`fieldcal.methods.METHODS`).
DEFAULT_METHOD = "mle"
#: How a log without a pose column is calibrated: ``auto`` (still detection when the log has
#: enough rests, else the continuous-motion estimator when it has a gyroscope and time), still
#: detection, windows, one pose per sample (a slow log without a gyroscope;
#: ``fieldcal.logs.pose_finding.POSE_SOURCES``), or continuous motion
#: (``fieldcal.pipeline.POSE_MODES``, :mod:`fieldcal.methods.continuous`).
#: The estimation paths of a log (:mod:`fieldcal.methods`' registry): static poses, and
#: continuous motion with the gyroscope.
ESTIMATION_PATHS = ("poses", "continuous")
#: ``Option.paths`` of an option that only the pose methods read.
POSES_ONLY = ("poses",)
#: ``Option.paths`` of an option that only the continuous-motion estimator reads.
CONTINUOUS_ONLY = ("continuous",)
POSE_CHOICES = ("auto", "still", "windows", "samples", "continuous")
#: ``body_frame``: the sensor whose gain is made symmetric (Sec. 4.3).
BODY_FRAMES = ("accel", "mag")


#: ``noise=``: a standard deviation (scalar or per axis) or a 3x3 covariance, for both sensors
#: or per sensor (checked by :func:`fieldcal.stats.noise_models.noise_covariance`).
NoiseSpec: TypeAlias = ArrayLike | Mapping[str, ArrayLike | None]
#: ``pose_noise=``: "auto", "none" or a standard deviation, for both sensors or per sensor.
PoseNoiseSpec: TypeAlias = str | float | Mapping[str, str | float]
#: ``location=``: ``"LAT,LON[,ALT_M]"`` or ``(lat, lon[, alt_m])``.
LocationSpec: TypeAlias = str | Sequence[float]
#: ``date=``: ``"YYYY-MM-DD"`` or a date.
DateSpec: TypeAlias = str | _dt.date


#: Degrees of dip allowed for a local anomaly.
_DIP_ALLOWANCE = Range(0.0, 89.0, low_open=False)
#: A probability strictly between 0 and 1.
_PROBABILITY = Range(0.0, 1.0 - 1e-12)
#: A flight log's sensor instance (``--mag N``, ``--imu N``).
_INSTANCE = Range(0.0, 255.0, low_open=False)


# ----------------------------------------------------------------------------- the table
@dataclass(frozen=True)
class ReadSettings:
    """How a log is read: its columns and its text (:func:`fieldcal.read_log`)."""

    accel_cols: str | Sequence[str] | None = field(
        default=None,
        metadata=meta("--accel-cols", "Accelerometer columns x,y,z (default: recognised)."),
    )
    mag_cols: str | Sequence[str] | None = field(
        default=None,
        metadata=meta("--mag-cols", "Magnetometer columns x,y,z (default: recognised)."),
    )
    gyro_cols: str | Sequence[str] | None = field(
        default=None,
        metadata=meta("--gyro-cols", "Gyroscope columns x,y,z (helps still detection)."),
    )
    time_col: str | None = field(
        default=None, metadata=meta("--time-col", "Time column (s; ms/us/ns recognised).")
    )
    pose_col: str | None = field(
        default=None, metadata=meta("--pose-col", "Pose-label column: rows are grouped by it.")
    )
    temp_col: str | None = field(
        default=None,
        metadata=meta(
            "--temp-col",
            "Temperature column, °C (default: recognised: temp, temperature, t_degc ...).",
        ),
    )
    drop_nan: bool = field(
        default=False,
        metadata=meta("--drop-nan", "Drop rows with NaN/inf instead of failing.", valid="flag"),
    )
    ignore_bad_temp: bool = field(
        default=False,
        metadata=meta(
            "--ignore-bad-temp",
            "Calibrate without temperature terms when the --temp-col values are unusable (NaN, "
            "inf, not °C) instead of failing; cal.json then has the reason temperature_ignored.",
            valid="flag",
        ),
    )
    decimal: str | None = field(
        default=None,
        metadata=meta(
            "--decimal",
            "Decimal mark of a text log (default: '.', or ',' when the file shows it).",
            valid=(".", ","),
        ),
    )
    split_on_reset: bool = field(
        default=False,
        metadata=meta(
            "--split-on-reset",
            "Time going backwards starts a new segment instead of being an error.",
            valid="flag",
        ),
    )
    imu_topic: str | None = field(
        default=None,
        metadata=meta("--imu-topic", "ROS bag: the sensor_msgs/Imu topic (default: the one)."),
    )
    mag_topic: str | None = field(
        default=None,
        metadata=meta(
            "--mag-topic", "ROS bag: the sensor_msgs/MagneticField topic (default: the one)."
        ),
    )
    mag_instance: int | None = field(
        default=None,
        metadata=meta(
            "--mag",
            "Flight log (.ulg, .bin): the magnetometer instance (default: the primary; "
            "'fieldcal info LOG' lists them).",
            valid=_INSTANCE,
            metavar="N",
        ),
    )
    imu_instance: int | None = field(
        default=None,
        metadata=meta(
            "--imu",
            "Flight log (.ulg, .bin): the IMU instance (default: the primary).",
            valid=_INSTANCE,
            metavar="N",
        ),
    )
    current_col: str | None = field(
        default=None,
        metadata=meta(
            "--current-col",
            "Battery-current column (A) for the magnetometer's interference term (default: "
            "recognised: current, curr, battery_current).",
        ),
    )
    throttle_col: str | None = field(
        default=None,
        metadata=meta(
            "--throttle-col",
            "Throttle column (0-1) for the interference term when no current is logged "
            "(default: recognised: throttle).",
        ),
    )
    sensors: str | None = field(
        default=None,
        metadata=meta(
            "--sensors",
            "Which sensors to calibrate: accel or mag alone (the other's columns left out), "
            "or both (default: those recognised; a sensor with an axis missing is an error).",
            valid=("accel", "mag", "both"),
        ),
    )

    def keywords(self) -> dict[str, Any]:
        """The reader's keywords that are set (a value other than ``None`` or ``False``): the
        reader's own defaults stand for the rest (:func:`fieldcal.logs.load_log`)."""
        return {
            f.name: value
            for f in dataclasses.fields(self)
            if (value := getattr(self, f.name)) is not None and value is not False
        }


@dataclass(frozen=True)
class DetectSettings:
    """How a log is cut into poses (:func:`fieldcal.logs.poses_from_log`)."""

    poses: str = field(
        default=POSE_CHOICES[0],
        metadata=meta(
            "--poses",
            "Without a pose column: auto (rests when the log has enough, else continuous "
            "motion when it has a gyroscope and time), detect still intervals, cut the log "
            "into windows of --window seconds (turned slowly with no rests), samples, or "
            "continuous (every sample, the gyroscope tying the orientations together).",
            valid=POSE_CHOICES,
            show_default=True,
        ),
    )
    rate: float | None = field(
        default=None,
        metadata=meta(
            "--rate", "Sample rate in Hz when there is no time column.", unit="Hz", valid=POSITIVE
        ),
    )
    min_still: float | None = field(
        default=None,
        metadata=meta(
            "--min-still",
            "Shortest still interval: seconds (samples without time/rate). Default 1 s / 50.",
            unit="s",
            valid=POSITIVE,
        ),
    )
    window: float | None = field(
        default=None,
        metadata=meta(
            "--window",
            "Moving-variance window: seconds (samples without time/rate). Default 0.5 s / 25.",
            unit="s",
            valid=POSITIVE,
        ),
    )
    still_trim: float | None = field(
        default=None,
        metadata=meta(
            "--still-trim",
            "Cut at each end of an interval (s or samples).",
            unit="s",
            valid=NON_NEGATIVE,
            old_flag="--trim",
        ),
    )
    still_threshold: float | None = field(
        default=None,
        metadata=meta(
            "--still-threshold",
            "Accelerometer threshold, per-axis std in raw units (default: 3x noise floor).",
            unit="raw",
            valid=MAGNITUDE,
        ),
    )

    def detector_keywords(self) -> dict[str, float | None]:
        """The still detector's keywords (:func:`fieldcal.logs.poses_from_log`,
        :class:`fieldcal.logs.live.LiveDetector`): ``rate``, ``window``, ``min_still``,
        ``trim`` (``still_trim``) and ``threshold`` (``still_threshold``)."""
        return {
            "rate": self.rate,
            "window": self.window,
            "min_still": self.min_still,
            "trim": self.still_trim,
            "threshold": self.still_threshold,
        }


@dataclass(frozen=True)
class FitSettings:
    """How the calibration is fitted (:func:`fieldcal.calibrate`)."""

    method: str = field(
        default=DEFAULT_METHOD,
        metadata=meta(
            "--method",
            "Calibration method",
            valid=None,
            show_default=True,
            paths=POSES_ONLY,
        ),
    )
    gravity: float | None = field(
        default=None,
        metadata=meta(
            "--gravity", "|g| for calibrated accel units (e.g. 9.80665).", valid=MAGNITUDE
        ),
    )
    field_strength: float | str | None = field(
        default=None,
        metadata=meta(
            "--field-strength",
            "|h| for calibrated mag units (e.g. 48.5), or wmm: the World Magnetic Model's "
            "intensity at --location in µT (wmm:nT for nT).",
            valid=parse_field_strength,
            metavar="NUMBER|WMM",
        ),
    )
    noise: NoiseSpec | None = field(
        default=None,
        metadata=meta(
            "--noise",
            "Noise std of one raw sample: one value, or accel=0.01,mag=0.2 (default: estimated).",
            unit="raw",
            valid=parse_noise,
            paths=POSES_ONLY,
        ),
    )
    pose_noise: PoseNoiseSpec = field(
        default="auto",
        metadata=meta(
            "--pose-noise",
            "Pose-level noise std of each pose mean, raw units: auto (estimated), none "
            "(zero, the seed paper's model), one value, or accel=0.01,mag=0.2.",
            unit="raw",
            valid=parse_pose_noise,
            show_default=True,
            paths=POSES_ONLY,
        ),
    )
    robust: bool = field(
        default=True,
        metadata=meta(
            "--no-robust",
            "Keep every pose and every sample: no rejection of disturbed poses, no "
            "trimming of bumps inside a pose.",
            valid="flag",
            inverted=True,
            paths=POSES_ONLY,
        ),
    )
    cut_unsteady: bool | None = field(
        default=None,
        metadata=library_only(
            "Cut samples that are not still inside each pose before Eq. 5/7 (default: as "
            "robust; --no-robust turns both off).",
            paths=POSES_ONLY,
        ),
    )
    body_frame: str = field(
        default=BODY_FRAMES[0],
        metadata=library_only(
            "The sensor whose gain is made symmetric, fixing the common body frame (Sec. 4.3).",
            valid=BODY_FRAMES,
            paths=POSES_ONLY,
        ),
    )
    mag_axes: str | None = field(
        default=None,
        metadata=meta("--mag-axes", "Magnetometer axis map onto the accelerometer's, e.g. +y+x-z."),
    )
    accel_sign: str = field(
        default=ACCEL_SIGNS[0],
        metadata=meta(
            "--accel-sign",
            "What the accelerometer reports at rest: specific force (+1 g up) or gravity "
            "(-1 g up, some loggers); the result corrects to specific force either way.",
            valid=ACCEL_SIGNS,
            show_default=True,
        ),
    )
    gyro: bool | None = field(
        default=None,
        metadata=meta(
            "--gyro/--no-gyro",
            "Calibrate the gyroscope from the motion between the poses: by default when "
            "the log has one and it can be (a note says why not); --gyro makes that an error.",
            valid="switch",
        ),
    )
    gyro_unit: str | None = field(
        default=None,
        metadata=meta(
            "--gyro-unit",
            "The gyroscope's raw unit: rad/s (default), deg/s, or a number (rad/s per raw "
            "unit); folded back into its gain, so the result applies to the columns as logged.",
        ),
    )
    mag_mirrored: bool = field(
        default=False,
        metadata=meta(
            "--mag-mirrored",
            "The magnetometer's axes (after --mag-axes) are left-handed relative to the "
            "accelerometer's; static data cannot tell this from the dip's sign.",
            valid="flag",
        ),
    )
    gyro_sampling: str = field(
        default="auto",
        metadata=meta(
            "--gyro-sampling",
            "Continuous motion: a gyroscope reading is the rate at its instant, or the mean "
            "rate over the interval that follows it; auto detects it from the data (noted).",
            valid=("auto", "instant", "mean"),
            show_default=True,
            paths=CONTINUOUS_ONLY,
        ),
    )
    gyro_noise: float | None = field(
        default=None,
        metadata=meta(
            "--gyro-noise",
            "Continuous motion: the gyroscope's white noise per sample, rad/s (default: "
            "estimated from the rates' quietest stretches; give it when the rate jitters at every "
            "sample).",
            unit="rad/s",
            valid=MAGNITUDE,
            paths=CONTINUOUS_ONLY,
        ),
    )
    hold: str | None = field(
        default=None,
        metadata=meta(
            "--hold",
            "Continuous motion: blocks held at --prior's values, comma-separated: gyro.gain, "
            "gyro.bias, accel.bias, mag.bias.",
            metavar="BLOCKS",
            paths=CONTINUOUS_ONLY,
        ),
    )
    prior: str | None = field(
        default=None,
        metadata=meta(
            "--prior",
            "The earlier calibration file (cal.json) that --hold takes its values from.",
            metavar="CAL.JSON",
            paths=CONTINUOUS_ONLY,
        ),
    )


@dataclass(frozen=True)
class TrustSettings:
    """What the result is checked against (:mod:`fieldcal.trust`, the World Magnetic Model)."""

    location: LocationSpec | None = field(
        default=None,
        metadata=meta(
            "--location",
            "Where the log was recorded (decimal degrees, metres above the WGS 84 "
            "ellipsoid): the World Magnetic Model's dip, intensity and declination there are "
            "the reference; its dip decides the magnetometer's handedness and is checked.",
            metavar="LAT,LON[,ALT_M]",
        ),
    )
    date: DateSpec | None = field(
        default=None,
        metadata=meta(
            "--date",
            "When the log was recorded, for --location (default: today).",
            metavar="YYYY-MM-DD",
        ),
    )
    dip_allowance_deg: float = field(
        default=DIP_ALLOWANCE_DEG,
        metadata=meta(
            "--dip-allowance",
            "Degrees of dip allowed for a local anomaly beyond the uncertainties before "
            f"the verdict warns (default {DIP_ALLOWANCE_DEG:g}).",
            unit="deg",
            valid=_DIP_ALLOWANCE,
        ),
    )
    false_alarm: float = field(
        default=0.01,
        metadata=library_only(
            "Family-wise false-alarm rate of the pose tests per calibration.",
            valid=_PROBABILITY,
            paths=POSES_ONLY,
        ),
    )
    target_tilt: float | None = field(
        default=None,
        metadata=meta(
            "--target-tilt",
            "Predicted tilt error (1σ, degrees) to reach: the verdict warns beyond it, fails "
            "beyond 5 times it; capture and plan aim at it.",
            unit="deg",
            valid=POSITIVE,
            target="tilt_deg",
        ),
    )
    target_heading: float | None = field(
        default=None,
        metadata=meta(
            "--target-heading",
            "Predicted heading error (1σ, degrees) to reach: the verdict warns beyond it, "
            "fails beyond 5 times it; capture and plan aim at it.",
            unit="deg",
            valid=POSITIVE,
            target="heading_deg",
        ),
    )
    target_norm: float | None = field(
        default=None,
        metadata=meta(
            "--target-norm",
            "Predicted error of |a| and |m| (1σ, percent) to reach: the verdict warns beyond "
            "it, fails beyond 5 times it.",
            unit="%",
            valid=POSITIVE,
            target="norm_pct",
        ),
    )


#: The settings class of each stage, in the order a log goes through them.
STAGES: Mapping[Stage, type[Any]] = {
    "read": ReadSettings,
    "detect": DetectSettings,
    "fit": FitSettings,
    "trust": TrustSettings,
}


def _table() -> dict[str, Option]:
    table: dict[str, Option] = {}
    for stage, cls in STAGES.items():
        for f in dataclasses.fields(cls):
            option: Option = f.metadata["option"]
            table[f.name] = dataclasses.replace(option, name=f.name, stage=stage, default=f.default)
    return table


#: Every option by its library keyword, in the order of the stages.
OPTIONS: Mapping[str, Option] = _table()
#: The keywords that go to the reader (:func:`fieldcal.logs.load_log`).
READ_OPTIONS: tuple[str, ...] = tuple(n for n, o in OPTIONS.items() if o.stage == "read")
#: The options that set an attribute of :class:`fieldcal.Targets` (``--target-tilt`` ...).
TARGET_OPTIONS: tuple[str, ...] = tuple(n for n, o in OPTIONS.items() if o.target)

_Settings = TypeVar("_Settings", ReadSettings, DetectSettings, FitSettings, TrustSettings)


def changed(settings: object) -> dict[str, object]:
    """The fields of a settings object given values other than their defaults.

    Parameters
    ----------
    settings : ReadSettings, DetectSettings, FitSettings or TrustSettings

    Returns
    -------
    dict
        By library keyword.
    """
    out: dict[str, object] = {}
    for f in dataclasses.fields(settings):  # type: ignore[arg-type]  # a settings dataclass
        value = getattr(settings, f.name)
        plain = isinstance(value, (str, bool, int, float, type(None)))
        if value is not f.default and not (plain and value == f.default):
            out[f.name] = value
    return out


#: Library keywords renamed, old name to new: one word, one meaning (``trim`` was both the
#: still detector's cut at each end of an interval, ``still_trim``, and the fit's cut of
#: unsteady samples inside a pose, now ``cut_unsteady``). The old name is taken for one
#: release, with a ``DeprecationWarning``.
RENAMED_KEYWORDS = {"trim": "cut_unsteady"}


def renamed(keywords: Mapping[str, object], stacklevel: int = 3) -> dict[str, object]:
    """``keywords`` with each old name of :data:`RENAMED_KEYWORDS` under its new one (a
    ``DeprecationWarning`` for each; both given: an ``InputError``)."""
    out = dict(keywords)
    for old, new in RENAMED_KEYWORDS.items():
        if old not in out:
            continue
        if new in out:
            raise InputError(f"{old}= and {new}= were both given; {old}= is the old name of {new}=")
        warnings.warn(
            f"{old}= is now {new}= (the old name is taken until the next release)",
            DeprecationWarning,
            stacklevel=stacklevel,
        )
        out[new] = out.pop(old)
    return out


def settings_of(cls: type[_Settings], keywords: Mapping[str, object]) -> _Settings:
    """The settings object of ``cls`` (one of the four) from the library's keywords: those that
    are its fields, the others left (a keyword not given takes the field's default).

    Parameters
    ----------
    cls : type
        :class:`ReadSettings`, :class:`DetectSettings`, :class:`FitSettings` or
        :class:`TrustSettings`.
    keywords : mapping
        Keyword arguments of :func:`fieldcal.calibrate_log` (any stage's, a method's own).

    Returns
    -------
    settings : cls
        The values as given: the stage that reads them checks them.
    """
    names = {f.name for f in dataclasses.fields(cls)}
    given: dict[str, Any] = {k: v for k, v in keywords.items() if k in names}
    return cls(**given)


def parse(option: Option, text: str) -> object:
    """An option's value from its text (a command-line value, a manifest cell).

    Raises
    ------
    ValueError
        With the one-line reason (the caller names the option or the cell).
    """
    valid = option.valid
    if isinstance(valid, str):  # text, flag or switch
        if valid == "text":
            return text
        value = parse_flag(text)
        return not value if option.inverted else value
    if isinstance(valid, Range):
        return valid.check(text)
    if isinstance(valid, tuple):
        if text not in valid:
            raise ValueError(f"give one of {', '.join(valid)}")
        return text
    if valid is None:  # a registry's name: the registry checks it
        return text
    return valid(text)
