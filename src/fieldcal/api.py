"""``fieldcal.calibrate``: validate the input, summarise the poses, run the method through the
shared trust path, then express the result in the user's units and handedness.

This module names no method: :mod:`fieldcal.methods` validates and dispatches.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import functools
import importlib
import numbers
from collections.abc import Callable, Mapping, Sequence
from types import ModuleType
from typing import TYPE_CHECKING, TypeAlias

import numpy as np
from numpy.typing import ArrayLike

from .calibration import Calibration
from .errors import InputError
from .methods import Method
from .methods import get as get_method
from .reference import DIP_ALLOWANCE_DEG, FieldReference, expected_field
from .stats.noise import noise_covariance, per_sensor, pose_noise_value
from .stats.poses import PoseStats, Samples, brief, summarize_scaled
from .stats.scaling import normalise

if TYPE_CHECKING:
    from threadpoolctl import ThreadpoolController

__all__ = ["calibrate"]

#: ``noise=``: a standard deviation (scalar or per axis) or a 3x3 covariance, for both sensors
#: or per sensor (checked at run time by :func:`fieldcal.stats.noise.noise_covariance`).
NoiseSpec: TypeAlias = ArrayLike | Mapping[str, ArrayLike | None]
#: ``pose_noise=``: "auto", "none" or a standard deviation, for both sensors or per sensor.
PoseNoiseSpec: TypeAlias = str | float | Mapping[str, str | float]


@functools.cache
def _blas() -> ThreadpoolController:
    """One cached controller: limiting threads through it costs microseconds, not the
    milliseconds of re-scanning the loaded BLAS libraries on every call."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def _reference(location: object, date: object, allowance: object) -> FieldReference | None:
    if location is None:
        if date is not None:
            raise InputError("a date was given without a location; give --location LAT,LON too")
        return None
    if (
        isinstance(allowance, bool)
        or not isinstance(allowance, (int, float, np.floating, np.integer))
        or not 0 <= float(allowance) < 90
    ):
        raise InputError(f"dip_allowance_deg must be degrees from 0 to 90, got {brief(allowance)}")
    return expected_field(location, date)  # type: ignore[arg-type]  # validated there


def _field_strength(value: object, reference: FieldReference | None) -> float | None:
    """A number, or ``"wmm"``/``"wmm:uT"``/``"wmm:nT"``: the model's intensity at the site."""
    if not isinstance(value, str):
        return _magnitude(value, "field_strength")
    unit = {"wmm": "uT", "wmm:ut": "uT", "wmm:µt": "uT", "wmm:nt": "nT"}.get(value.lower())
    if unit is None:
        raise InputError(
            f"field_strength {value[:40]!r} is neither a number nor wmm, wmm:uT or wmm:nT"
        )
    if reference is None:
        raise InputError(
            "field strength 'wmm' takes the World Magnetic Model's intensity where the log was "
            "recorded: give --location LAT,LON too"
        )
    return reference.intensity_in(unit)


def _trust() -> ModuleType:
    """The shared trust path, imported on first use: it needs SciPy, which ``import fieldcal``
    does not load."""
    return importlib.import_module(".trust.fitting", __package__)


def _magnitude(value: object, name: str) -> float | None:
    """A reference field's magnitude: a real number from 1e-150 to 1e150 (the gains are raw
    units per unit of it, and their covariance must stay in floating-point range)."""
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a positive number, got {brief(value)}")
    if not 1e-150 <= float(value) <= 1e150:
        raise ValueError(
            f"{name} must be a positive number from 1e-150 to 1e150, got {brief(value)}"
        )
    return float(value)


def _probability(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a number in (0, 1), got {brief(value)}")
    if not 0 < float(value) < 1:
        raise ValueError(f"{name} must be in (0, 1), got {brief(value)}")
    return float(value)


def _user_noise(noise: object) -> dict[str, np.ndarray]:
    """The user's per-sample noise covariance per sensor (raw units), checked."""
    given = per_sensor(noise, "noise") if noise is not None else {}
    return {name: noise_covariance(v, name) for name, v in given.items() if v is not None}


def _with_user_noise(
    stats: PoseStats, given: Mapping[str, np.ndarray], scales: Mapping[str, float]
) -> tuple[PoseStats, dict[str, str]]:
    """Replace Eq. 7's covariance by the user's where given (in the readings' scaled units);
    report each sensor's source."""
    sources: dict[str, str] = {}
    for name in stats.sensors:
        value = given.get(name)
        if value is not None:
            stats = stats.replace(
                **{name: dataclasses.replace(stats.sensor(name), cov=value / scales[name] ** 2)}
            )
            sources[name] = "user"
        else:
            sources[name] = "scatter" if stats.sensor(name).cov is not None else "residuals"
    return stats, sources


def _scaled_variance(variance: float | None, scale: float) -> float | None:
    return None if variance is None else variance / scale**2


def _continuous(accel: object, mag: object) -> bool:
    return any(isinstance(x, np.ndarray) and x.ndim == 2 for x in (accel, mag) if x is not None)


def calibrate(
    accel: Samples | None,
    mag: Samples | None = None,
    method: str = "mle",
    *,
    gravity: float | None = None,
    field_strength: float | None = None,
    noise: NoiseSpec | None = None,
    pose_noise: PoseNoiseSpec = "auto",
    robust: bool = True,
    false_alarm: float = 0.01,
    trim: bool | None = None,
    body_frame: str = "accel",
    mag_mirrored: bool = False,
    location: str | Sequence[float] | None = None,
    date: str | _dt.date | None = None,
    dip_allowance_deg: float = DIP_ALLOWANCE_DEG,
    on_progress: Callable[[str], None] | None = None,
    **options: object,
) -> Calibration:
    """Calibrate an accelerometer and a magnetometer together from static poses.

    Parameters
    ----------
    accel, mag
        Each a sequence of N arrays of shape (n_i, 3): the raw samples taken while the device
        rested in pose i (same N and order for both sensors). Either may be ``None`` to
        calibrate one sensor alone. Methods registered as taking continuous input
        (``"ellipsoid"``) also take single (n, 3) arrays of samples.
    method : str
        A name in :data:`fieldcal.METHODS`: ``"mle"`` (default, joint maximum likelihood),
        ``"greedy"`` (the seed paper's algorithm), ``"ellipsoid"`` (CK-Explorer).
    gravity, field_strength : float, optional
        Magnitudes of the reference fields; the gains come out in raw units per unit of these.
        Default 1 (unit fields). ``field_strength="wmm"`` (or ``"wmm:uT"``, ``"wmm:nT"``)
        takes the World Magnetic Model's total intensity at ``location``, in µT (or nT).
    noise : float, array, or dict, optional
        Noise of one raw sample, used instead of the within-pose scatter (Eq. 7): a standard
        deviation (scalar or per axis), a 3x3 covariance, or ``{"accel": ..., "mag": ...}``.
    pose_noise : "auto", "none", float, or dict
        The pose-level noise ``q`` (raw units, per axis) of each pose mean, beyond
        ``noise / sqrt(samples)``: estimated with the calibration (``"auto"``, default), zero
        (``"none"``, the seed paper's model) or given; per sensor as
        ``{"accel": ..., "mag": ...}``. With one sample per pose it is the noise from the
        residuals.
    robust : bool
        Test every pose and drop disturbed ones, refitting (default True); each dropped pose
        is in ``cal.rejected``.
    false_alarm : float
        Family-wise false-alarm rate of the pose tests per calibration (default 0.01).
    trim : bool, optional
        Cut samples that are not still (a bump, a tap) inside each pose before Eq. 5/7.
        Default: the same as ``robust``.
    body_frame : {"accel", "mag"}
        Which sensor's gain is made symmetric, fixing the common body frame (Sec. 4.3).
    mag_mirrored : bool
        Whether the magnetometer's axes, as given, are mirrored relative to the
        accelerometer's (a left-handed triad, e.g. the LSM9DS1's). Static poses cannot tell
        this from a field in the opposite magnetic hemisphere (the dip's sign), so it is a
        prior: by default the magnetometer's gain comes out with a positive determinant. With a
        ``location`` the model's dip decides instead (the verdict warns when that contradicts
        what is stated here); ``cal.options["mag_handedness"]`` says which decided.
    location : str or sequence of float, optional
        Where the data were recorded, ``"LAT,LON[,ALT_M]"`` or ``(lat, lon[, alt_m])`` in
        decimal degrees and metres: the World Magnetic Model's field there
        (:func:`fieldcal.expected_field`) becomes ``cal.field_reference`` (JSON
        ``reference``), decides the handedness and is compared with the fitted dip.
    date : str or datetime.date, optional
        When (``"YYYY-MM-DD"``) for the model; default today. Needs ``location``.
    dip_allowance_deg : float
        The local anomaly allowed beyond the uncertainties before the verdict warns that the
        fitted dip differs from the model's (default :data:`fieldcal.reference.
        DIP_ALLOWANCE_DEG`, 2°).
    on_progress : callable, optional
        Called with one line of text at each step of the robust fit (for progress displays).
    **options
        The method's own options (keyword-only parameters of its ``fit``), e.g. ``gamma`` for
        ``"greedy"``; an unknown one is a ``ValueError`` listing the known ones.

    Returns
    -------
    Calibration
        With ``verdict``, ``rejected``, ``accuracy`` and each sensor's ``pose_noise_std``.
    """
    spec = get_method(method)
    if body_frame not in ("accel", "mag"):
        raise ValueError(f"body_frame must be 'accel' or 'mag', got {brief(body_frame)}")
    for flag, value in (("mag_mirrored", mag_mirrored), ("robust", robust)):
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{flag} must be True or False, got {brief(value)}")
    if on_progress is not None and not callable(on_progress):
        raise ValueError(
            f"on_progress must be a function taking one line of text, got {brief(on_progress)}"
        )
    if trim is None:
        trim = bool(robust)
    elif not isinstance(trim, (bool, np.bool_)):
        raise ValueError(f"trim must be True or False, got {brief(trim)}")
    alpha = _probability(false_alarm, "false_alarm")
    g = _magnitude(gravity, "gravity")
    reference = _reference(location, date, dip_allowance_deg)
    h = _field_strength(field_strength, reference)
    spec.check_options(options)
    fixed = {s: pose_noise_value(v, s) for s, v in per_sensor(pose_noise, "pose_noise").items()}
    user_noise = _user_noise(noise)
    provenance = {
        "body_frame": body_frame,
        "mag_mirrored": bool(mag_mirrored),
        "robust": bool(robust),
        "false_alarm": alpha,
        "trim": bool(trim),
    }

    try:
        # The problems are small (3x3 blocks, a 22x22 system): threaded BLAS only adds
        # contention, and two processes calibrating at once made a 5 ms fit take 0.7 s.
        # Floating-point trouble is not printed: the result is checked below and refused in
        # one line when anything a correction uses is not finite.
        with _blas().limit(limits=1), np.errstate(all="ignore"):
            cal, scales = _fit(
                spec, accel, mag, options, user_noise, fixed, body_frame,
                trim=bool(trim), robust=bool(robust), alpha=alpha,
                mag_mirrored=bool(mag_mirrored), reference=reference,
                dip_allowance_deg=dip_allowance_deg, on_progress=on_progress,
            )  # fmt: skip
            # the handedness: the fit's twins are equal but for it (the reference's when it
            # can decide, as the trust path did; the user's otherwise)
            decided = None
            if reference is not None:
                decided = _trust().reference_mirrored(cal, reference, dip_allowance_deg)
            mirrored = bool(mag_mirrored) if decided is None else decided
            provenance["mag_mirrored"] = mirrored
            provenance["mag_handedness"] = "stated" if decided is None else "reference"
            # back to the user's units with the provenance (one new Calibration, not two)
            cal = cal.with_raw_scale(scales, options=provenance)
            cal = cal.with_mag_handedness(mirrored)
            if reference is not None and cal.field_reference is None:  # the ellipsoid path
                cal = dataclasses.replace(cal, field_reference=reference)
            if g is not None or h is not None:
                cal = cal.with_field_magnitudes(g, h)
    except np.linalg.LinAlgError as exc:
        raise ValueError(
            f"the poses cannot determine the calibration (numpy: {' '.join(str(exc).split())}); "
            "record poses with each axis pointing up and down, and check the readings change "
            "from pose to pose"
        ) from None
    try:
        cal.check_values()
    except ValueError as exc:
        raise ValueError(
            f"the {method} fit gave no usable calibration ({str(exc).removeprefix('invalid ')}"
            "); check the readings (units, columns) and record poses with each axis up and down"
        ) from None
    return cal


def _fit(
    spec: Method,
    accel: Samples | None,
    mag: Samples | None,
    options: Mapping[str, object],
    user_noise: Mapping[str, np.ndarray],
    fixed: Mapping[str, float | None],
    body_frame: str,
    *,
    trim: bool,
    robust: bool,
    alpha: float,
    mag_mirrored: bool,
    reference: FieldReference | None,
    dip_allowance_deg: float,
    on_progress: Callable[[str], None] | None,
) -> tuple[Calibration, dict[str, float]]:
    """The method through the shared trust path, on readings divided by an exact power of two
    per sensor (the fit sees numbers of order one in any unit); returns the result and those
    divisors, by which :meth:`Calibration.with_raw_scale` scales it back."""
    if _continuous(accel, mag):
        accel, accel_scale = normalise(accel, "accel")
        mag, mag_scale = normalise(mag, "mag")
        if not spec.continuous:
            raise ValueError(
                f"method {spec.name!r} needs per-pose input: pass a list with one (n_i, 3) "
                "array per static pose (or use method='ellipsoid' for continuous samples)"
            )
        if user_noise:
            raise ValueError(
                "noise= needs per-pose input; with continuous samples the ellipsoid method "
                "estimates the noise from its fit residuals (pass per-pose arrays instead)"
            )
        cal = spec.load()(None, raw_accel=accel, raw_mag=mag, body_frame=body_frame, **options)
        return cal, {"accel": accel_scale, "mag": mag_scale}
    # one pass over the samples: checks, the divisors and Eq. 5/7 (the statistics are scaled,
    # not the samples; a method that reads the samples gets scaled copies)
    stats, scales, arrays = summarize_scaled(accel, mag, trim=trim)
    raw: dict[str, list[np.ndarray] | None] = {"accel": None, "mag": None}
    if spec.raw_samples:
        for s, poses in arrays.items():
            raw[s] = poses if poses is None or scales[s] == 1.0 else [p / scales[s] for p in poses]
    need = spec.min_poses_for(len(stats.sensors))
    if stats.n_poses < need:
        raise ValueError(
            f"{stats.n_poses} poses given; the {spec.name} method needs at least {need}"
            + (
                " (6N readings must outnumber the 3N rotation angles plus 22 sensor parameters)"
                if len(stats.sensors) == 2
                else " for one sensor (3N readings must outnumber 2N tilt angles plus "
                "9 sensor parameters)"
            )
        )
    stats, sources = _with_user_noise(stats, user_noise, scales)
    cal = _trust().fit_trusted(
        spec,
        stats,
        raw_accel=raw["accel"],
        raw_mag=raw["mag"],
        body_frame=body_frame,
        options=options,
        sources=sources,
        pose_noise={s: _scaled_variance(fixed[s], scales[s]) for s in stats.sensors},
        robust=robust,
        alpha=alpha,
        mag_mirrored=mag_mirrored,
        reference=reference,
        dip_allowance_deg=dip_allowance_deg,
        on_progress=on_progress,
    )
    return cal, scales
