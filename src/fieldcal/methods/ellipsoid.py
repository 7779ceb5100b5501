"""CK-Explorer's calibration: an ellipsoid fit per sensor, then dot-product alignment.

The seed is ``../shared/seeds/004_bce6d316cac7a7b6.txt``; equation numbers below are its own.

1. Each sensor's samples are fitted with the quadric of Eq. 8 (:mod:`fieldcal.geometry.quadrics`),
   giving the centre (hard iron, offset) and ``M = LᵀL`` (Eq. 9-12); ``L`` is the reverse
   triangular factor of Eq. 13 and ``L (s − c)`` the corrected reading (Eq. 14).
2. The magnetometer's triad is rotated onto the accelerometer's by minimising Eq. 16,
   ``Σ (aᵀ R_mis m − |a||m| β)²``, over the stereographic parameters ``(X, Y, Z)`` of Eq. 18-24
   (pole at ``q1 = +1``, identity at ``(1, 0, 0)``) and ``β = cos θ``, by Levenberg-Marquardt.
   The magnetometer's correction is ``R_mis L (m − c)`` (Eq. 25).

``faithful=True`` does exactly that. The default (``faithful=False``) fixes the ways it breaks:
conditioned least squares instead of normal equations, an ellipsoid-specific fallback (Li &
Griffiths 2004) when the quadric is not an ellipsoid, unit vectors and ``|β| <= 1`` in Eq. 16,
a closed-form start (so a large misalignment does not trap the solver in a wrong minimum) and
an analytic Jacobian, and a solver that did not converge raises instead of returning.
``docs/methods/ellipsoid.md`` maps each function to its equation.

Conventions: ``fit_ellipsoid`` and ``align`` return the seed's own numbers (``L``, centre,
``R_mis``, ``β``); :func:`fit` (``fieldcal.calibrate(..., method="ellipsoid")``) turns them into
fieldcal's model, ``gain = (R_mis L)⁻¹``, ``bias = c``, and re-expresses the result in
fieldcal's gauge (:func:`fieldcal.geometry.gauge.canonical_gauge`). With ``a = (0, 0, −1)`` and
``m = (cos dip, 0, sin dip)``, ``β = a·m = −sin dip``: ``dip = θ − 90°``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration, SensorCalibration
from ..geometry.frames import GRAVITY, magnetic_reference
from ..geometry.gauge import canonical_gauge
from ..geometry.rotations import (
    exp_so3,
    wahba,
)
from ..stats.pose_stats import PoseStats, Samples, SensorStats, brief
from .dot_alignment import (
    Alignment,
    AlignmentError,
    _initial_beta,
    align,
    quaternion_to_stereographic,
    stereographic_to_quaternion,
)
from .ellipsoid_fit import (
    MIN_POSES,
    MIN_SAMPLES,
    EllipsoidFit,
    NotAnEllipsoidWarning,
    _check_samples,
    _ellipsoid_quadric,
    _ellipsoid_result,
    fit_ellipsoid,
)

__all__ = [
    "MIN_POSES",
    "MIN_SAMPLES",
    "Alignment",
    "AlignmentError",
    "EllipsoidFit",
    "NotAnEllipsoidWarning",
    "align",
    "fit",
    "fit_ellipsoid",
    "quaternion_to_stereographic",
    "stereographic_to_quaternion",
]

Array = NDArray[np.float64]


def _continuous(samples: Samples | None, name: str) -> Array | None:
    """One sensor's continuous input: an (n, 3) array, or per-pose arrays stacked."""
    if samples is None:
        return None
    if isinstance(samples, np.ndarray) and samples.ndim == 2:
        return _check_samples(samples, name)
    if isinstance(samples, (Sequence, np.ndarray)):
        try:
            stacked = np.concatenate([np.atleast_2d(np.asarray(p, float)) for p in samples])
        except ValueError:
            raise ValueError(f"{name}: expected an (n, 3) array of samples") from None
        return _check_samples(stacked, name)
    raise ValueError(f"{name}: expected an (n, 3) array of samples, got {type(samples).__name__}")


def _paired_pose_samples(raw_accel: Samples, raw_mag: Samples) -> tuple[Array, Array]:
    """Sample pairs pose by pose; a pose with unequal counts keeps the first min(n_a, n_m)."""
    pairs = [
        (np.asarray(a, float).reshape(-1, 3), np.asarray(m, float).reshape(-1, 3))
        for a, m in zip(raw_accel, raw_mag, strict=True)
    ]
    n = [min(len(a), len(m)) for a, m in pairs]
    return (
        np.concatenate([a[:k] for (a, _), k in zip(pairs, n, strict=True)]),
        np.concatenate([m[:k] for (_, m), k in zip(pairs, n, strict=True)]),
    )


def _minimal_rotations(body: Array, reference: Array) -> Array:
    """Per pose, the smallest rotation taking the world ``reference`` onto ``body`` (unit).

    With one sensor the rotation about its field is unobservable; this fixes it to zero.
    """
    b = body / np.linalg.norm(body, axis=1, keepdims=True)
    axis = np.cross(reference, b)
    sin, cos = np.linalg.norm(axis, axis=1), b @ reference
    helper = np.cross(reference, np.eye(3)[int(np.argmin(np.abs(reference)))])
    axis = np.where((sin < 1e-12)[:, None], helper / np.linalg.norm(helper), axis)
    unit = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    return exp_so3(unit * np.arctan2(sin, cos)[:, None])


def _noise(stats_sensor: SensorStats | None, x: Array, fit_: EllipsoidFit) -> tuple[Array, str]:
    """Eq. 7 when the poses give it; otherwise isotropic from the radial residuals.

    For isotropic noise the radial component of a sample's error has the full variance σ²;
    ``|L(s − c)| − 1`` times the mean radius is that component in raw units, and the fit used
    9 degrees of freedom.
    """
    if stats_sensor is not None and stats_sensor.cov is not None:
        return np.asarray(stats_sensor.cov, float), "scatter"
    norms = np.linalg.norm(fit_.correct(x), axis=1)
    radius = float(np.exp(np.mean(np.log(fit_.radii))))
    var = float(np.sum((norms - 1.0) ** 2) * radius**2 / max(len(x) - 9, 1))
    return np.eye(3) * var, "residuals"


def _validate_options(
    faithful: object,
    inclination_deg: float | None,
    fit_on: str,
    continuous: bool,
) -> None:
    if not isinstance(faithful, (bool, np.bool_)):
        raise ValueError(f"faithful must be True or False, got {brief(faithful)}")
    if inclination_deg is not None:
        try:
            _initial_beta(float(inclination_deg))
        except (TypeError, ValueError):
            raise ValueError(
                f"inclination_deg must be a number in [-90, 90], got {brief(inclination_deg)}"
            ) from None
    if fit_on not in ("samples", "pose_means"):
        raise ValueError(f"fit_on must be 'samples' or 'pose_means', got {brief(fit_on)}")
    if fit_on == "pose_means" and continuous:
        raise ValueError("fit_on='pose_means' needs per-pose input; got continuous (n, 3) arrays")


@dataclass(frozen=True)
class _Inputs:
    """What the fits need: points (and weights) per sensor, and the pairs for Eq. 16."""

    samples: dict[str, Array | None]  # all raw samples (residual noise)
    points: dict[str, Array | None]  # what the ellipsoid is fitted on
    weights: dict[str, Array | None]
    pairs: tuple[Array, Array] | None


def _continuous_inputs(raw_accel: Samples | None, raw_mag: Samples | None) -> _Inputs:
    xa, xm = _continuous(raw_accel, "accel"), _continuous(raw_mag, "mag")
    if xa is None and xm is None:
        raise ValueError("no data: pass accelerometer samples, magnetometer samples, or both")
    if xa is not None and xm is not None and len(xa) != len(xm):
        raise ValueError(
            f"accel has {len(xa)} samples but mag has {len(xm)}; continuous input must pair "
            "the two sensors' samples one to one (same length, same instants)"
        )
    pairs = None if xa is None or xm is None else (xa, xm)
    samples = {"accel": xa, "mag": xm}
    return _Inputs(samples, samples, {"accel": None, "mag": None}, pairs)


def _pose_inputs(
    stats: PoseStats, raw_accel: Samples | None, raw_mag: Samples | None, fit_on: str
) -> _Inputs:
    if stats.n_poses < MIN_POSES:
        raise ValueError(
            f"{stats.n_poses} poses given; the ellipsoid of Eq. 8 has 9 free parameters, so "
            f"method='ellipsoid' (--method ellipsoid) needs at least {MIN_POSES} distinct poses"
        )
    raw = {"accel": raw_accel, "mag": raw_mag}
    samples = {
        k: None if v is None else np.concatenate([np.reshape(p, (-1, 3)) for p in v])
        for k, v in raw.items()
    }
    if fit_on == "pose_means":
        # Eq. 5 means weighted by Δ_i: the noise no longer inflates the fitted radii
        points = {k: None if v is None else stats.sensor(k).means for k, v in raw.items()}
        weights = {
            k: None if v is None else stats.sensor(k).counts.astype(float) for k, v in raw.items()
        }
        a, m = stats.accel, stats.mag
        return _Inputs(
            samples, points, weights, None if a is None or m is None else (a.means, m.means)
        )
    pairs = None
    if raw_accel is not None and raw_mag is not None:
        pairs = _paired_pose_samples(raw_accel, raw_mag)
    return _Inputs(samples, samples, {"accel": None, "mag": None}, pairs)


def fit(
    stats: PoseStats | None,
    *,
    raw_accel: Samples | None,
    raw_mag: Samples | None,
    body_frame: str = "accel",
    progress: Callable[[str], None] | None = None,
    faithful: bool = False,
    inclination_deg: float | None = None,
    fit_on: str = "samples",
) -> Calibration:
    """``fieldcal.calibrate(..., method="ellipsoid")``: Sec. 2 per sensor, Sec. 3 jointly.

    ``stats`` is ``None`` for continuous (n, 3) input, else the pose statistics. By default
    (``fit_on="samples"``, the seed's way) the ellipsoids are fitted on all raw samples and the
    alignment on all sample pairs, so pose boundaries only serve the report: the per-pose
    rotations (two-vector Wahba on the calibrated pose means), Eq. 7's noise and Eq. 8's cost.
    ``fit_on="pose_means"`` (per-pose input only) fits the count-weighted pose means instead,
    which removes the bias the sample noise puts into an algebraic fit. Continuous input gives
    ``rotations`` of shape (0, 3, 3), isotropic residual noise and ``cost = NaN``.

    Options: ``faithful`` (bool), ``inclination_deg`` (float, the expected dip), ``fit_on``.
    """
    _validate_options(faithful, inclination_deg, fit_on, stats is None)
    faithful = bool(faithful)
    inputs = (
        _continuous_inputs(raw_accel, raw_mag)
        if stats is None
        else _pose_inputs(stats, raw_accel, raw_mag, fit_on)
    )
    fits: dict[str, EllipsoidFit | None] = {}
    for name in ("accel", "mag"):
        points = inputs.points[name]
        fits[name] = (
            None if points is None else _sensor_fit(points, faithful, name, inputs.weights[name])
        )
    fit_a, fit_m = fits["accel"], fits["mag"]
    alignment = None
    # pairs exist only when both sensors were fitted
    if inputs.pairs is not None and fit_a is not None and fit_m is not None:
        alignment = align(
            fit_a.correct(inputs.pairs[0]),
            fit_m.correct(inputs.pairs[1]),
            faithful=faithful,
            inclination_deg=inclination_deg,
        )
        if not np.isfinite(alignment.theta_deg):
            raise ValueError(
                f"the faithful alignment gave beta = {alignment.beta:.6g} (|beta| > 1, no angle); "
                "use faithful=False, which keeps |beta| <= 1"
            )
    options_used: dict[str, object] = {
        "faithful": faithful,
        "inclination_deg": None if inclination_deg is None else float(inclination_deg),
        "fit_on": fit_on,
        "body_frame": body_frame,
        "input": "continuous" if stats is None else "poses",
    }
    return _calibration(stats, fits, alignment, inputs.samples, body_frame, options_used)


def _sensor_fit(x: Array, faithful: bool, name: str, weights: Array | None) -> EllipsoidFit:
    quadric, fallback = _ellipsoid_quadric(x, faithful, name, weights)
    result = _ellipsoid_result(x, quadric, fallback, faithful)
    if not result.is_ellipsoid:
        raise ValueError(
            f"{name}: the faithful fit (Eq. 8) is not an ellipsoid, so L of Eq. 13 is NaN; "
            "record more orientations or use faithful=False"
        )
    return result


def _body_maps(
    fits: dict[str, EllipsoidFit | None], alignment: Alignment | None
) -> dict[str, Array | None]:
    """Each sensor's correction to the common (accelerometer) axes: ``L`` and ``R_mis L``."""
    maps = {k: None if f is None else f.correction for k, f in fits.items()}
    if alignment is not None and maps["mag"] is not None:
        maps["mag"] = alignment.rotation @ maps["mag"]  # Eq. 25
    return maps


def _pose_rotations(
    stats: PoseStats,
    fits: dict[str, EllipsoidFit | None],
    maps: dict[str, Array | None],
    noise: dict[str, Array],
    fields: dict[str, Array | None],
) -> Array:
    """Two-vector Wahba per pose on the calibrated pose means (one sensor: minimal rotation).

    Each direction is weighted by its information, ``Δ_i`` over the noise variance in
    calibrated units, so a noisy magnetometer does not tilt the rotations.
    """
    body, world, weights = [], [], []
    for name in ("accel", "mag"):
        L, fit_, field_ = maps[name], fits[name], fields[name]
        if L is None or fit_ is None or field_ is None:
            continue
        sensor_stats = stats.sensor(name)
        v = (sensor_stats.means - fit_.center) @ L.T
        body.append(v / np.linalg.norm(v, axis=1, keepdims=True))
        world.append(np.broadcast_to(field_, v.shape))
        weights.append(sensor_stats.counts / (np.trace(L @ noise[name] @ L.T) / 3.0))
    if len(body) == 1:
        return _minimal_rotations(body[0], world[0][0])
    return wahba(np.stack(body, 1), np.stack(world, 1), np.stack(weights, 1))


def _fields(
    fits: dict[str, EllipsoidFit | None], alignment: Alignment | None
) -> dict[str, Array | None]:
    """``g = (0, 0, −1)``; ``h = (cos dip, 0, sin dip)`` with ``dip = θ − 90°`` (so that
    ``g·h = −sin dip = cos θ = β``, Eq. 15); ``(1, 0, 0)`` for a magnetometer alone."""
    gravity = None if fits["accel"] is None else GRAVITY
    magnetic = None
    if fits["mag"] is not None:
        dip = 0.0 if alignment is None else np.radians(alignment.dip_deg)
        magnetic = magnetic_reference(dip)
    return {"accel": gravity, "mag": magnetic}


def _calibration(
    stats: PoseStats | None,
    fits: dict[str, EllipsoidFit | None],
    alignment: Alignment | None,
    samples: dict[str, Array | None],
    body_frame: str,
    options: dict[str, object],
) -> Calibration:
    """The seed's numbers as fieldcal's model (``gain = (R_mis L)⁻¹``, ``bias = c``), in
    fieldcal's gauge, with rotations, noise and the Eq. 8 certificate when poses are given."""
    maps = _body_maps(fits, alignment)
    fields = _fields(fits, alignment)
    noise: dict[str, Array] = {}
    sources: dict[str, str] = {}
    for name, sensor_fit in fits.items():
        x = samples[name]
        if sensor_fit is not None and x is not None:  # a fit has its samples
            sensor_stats = None if stats is None else stats.sensor(name)
            noise[name], sources[name] = _noise(sensor_stats, x, sensor_fit)
    rotations = (
        np.zeros((0, 3, 3)) if stats is None else _pose_rotations(stats, fits, maps, noise, fields)
    )
    inverse = {k: None if L is None else cast(Array, np.linalg.inv(L)) for k, L in maps.items()}
    R, Ka, Km, gravity, magnetic = canonical_gauge(
        rotations, inverse["accel"], inverse["mag"], fields["accel"], fields["mag"], body_frame
    )
    sensors: dict[str, SensorCalibration | None] = {}
    for name, gain in (("accel", Ka), ("mag", Km)):
        sensor_fit = fits[name]
        sensors[name] = (
            None
            if sensor_fit is None or gain is None
            else SensorCalibration(gain, sensor_fit.center, noise[name], noise_source=sources[name])
        )
    cal = Calibration(
        accel=sensors["accel"],
        mag=sensors["mag"],
        gravity=gravity,
        magnetic=magnetic,
        rotations=R,
        method="ellipsoid",
        iterations=0 if alignment is None else alignment.iterations,
        converged=True if alignment is None else alignment.converged,
        options=options,
        message=_status(fits, alignment),
    )
    return cal


def _status(fits: dict[str, EllipsoidFit | None], alignment: Alignment | None) -> str:
    parts = [
        f"{name}: {f.fit_method} fit, residual rms {f.residual_rms:.3g}"
        for name, f in fits.items()
        if f is not None
    ]
    if fits["mag"] is not None and fits["accel"] is None:
        parts.append("dip not observable without an accelerometer (magnetic set to (1, 0, 0))")
    if alignment is not None:
        parts.append(
            f"alignment: {alignment.message} (status {alignment.status}, start "
            f"{alignment.start}); beta={alignment.beta:.6g} theta={alignment.theta_deg:.4f} deg "
            f"R_mis angle={alignment.misalignment_deg:.4f} deg"
        )
    return "; ".join(parts)
