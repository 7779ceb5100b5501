"""``fieldcal.calibrate``: validate the input, summarise the poses, dispatch to a method.

A method is a function ``fit(stats, *, raw_accel, raw_mag, body_frame, **options)`` returning a
:class:`~fieldcal.model.Calibration` with unit fields (``|g| = |h| = 1``); this module then
applies the physical magnitudes the user asked for, so every method shares them.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
from collections.abc import Callable
from typing import Any

import numpy as np

from .model import Calibration
from .poses import PoseStats, SensorStats, summarize

__all__ = ["METHODS", "MIN_POSES", "calibrate"]

#: method name -> module in ``fieldcal.methods`` that defines ``fit``.
METHODS: dict[str, str] = {"mle": "mle", "greedy": "greedy", "ellipsoid": "ellipsoid"}

#: The joint problem has 6N observations and 3N + 22 unknowns: it needs 3N − 22 > 0.
MIN_POSES = 8


@functools.cache
def _blas() -> Any:
    """One cached controller: limiting threads through it costs microseconds, not the
    milliseconds of re-scanning the loaded BLAS libraries on every call."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def _method(name: str) -> Callable[..., Calibration]:
    module = importlib.import_module(f".methods.{METHODS[name]}", __package__)
    return module.fit


def _noise_cov(value: Any, name: str) -> np.ndarray:
    """A user's noise: a standard deviation (scalar or per axis) or a 3x3 covariance."""
    array = np.asarray(value, dtype=float)
    if array.ndim <= 1 and not np.all(array > 0):
        raise ValueError(f"noise for {name} must be finite and positive, got {value!r}")
    if array.ndim == 0:
        cov = np.eye(3) * float(array) ** 2
    elif array.shape == (3,):
        cov = np.diag(array**2)
    elif array.shape == (3, 3):
        cov = 0.5 * (array + array.T)
    else:
        raise ValueError(
            f"noise for {name} must be a standard deviation (scalar or 3 values) or a 3x3 "
            f"covariance, got shape {array.shape}"
        )
    if not np.all(np.isfinite(cov)) or np.any(np.linalg.eigvalsh(cov) <= 0):
        raise ValueError(f"noise for {name} must be finite and positive")
    return cov


def _with_user_noise(stats: PoseStats, noise: Any) -> tuple[PoseStats, dict[str, str]]:
    """Replace Eq. 7's covariance by the user's where given; report each sensor's source."""
    sources: dict[str, str] = {}
    per_sensor = noise if isinstance(noise, dict) else {"accel": noise, "mag": noise}
    unknown = set(per_sensor) - {"accel", "mag"}
    if unknown:
        raise ValueError(f"noise keys must be 'accel' and/or 'mag', got {sorted(unknown)}")
    updated: dict[str, SensorStats | None] = {}
    for name in ("accel", "mag"):
        sensor: SensorStats | None = getattr(stats, name)
        if sensor is None:
            updated[name] = None
            continue
        value = per_sensor.get(name)
        if value is not None:
            updated[name] = dataclasses.replace(sensor, cov=_noise_cov(value, name))
            sources[name] = "user"
        else:
            updated[name] = sensor
            sources[name] = "scatter" if sensor.cov is not None else "residuals"
    return PoseStats(updated["accel"], updated["mag"]), sources


def calibrate(
    accel: Any,
    mag: Any = None,
    method: str = "mle",
    *,
    gravity: float | None = None,
    field_strength: float | None = None,
    noise: Any = None,
    body_frame: str = "accel",
    mag_mirrored: bool = False,
    **options: Any,
) -> Calibration:
    """Calibrate an accelerometer and a magnetometer together from static poses.

    Parameters
    ----------
    accel, mag
        Each a sequence of N arrays of shape (n_i, 3): the raw samples taken while the device
        rested in pose i (same N and order for both sensors). Either may be ``None`` to
        calibrate one sensor alone. ``method="ellipsoid"`` also takes single (n, 3) arrays of
        continuous samples.
    method : {"mle", "greedy", "ellipsoid"}
        ``"mle"`` (default): joint maximum likelihood, globally initialised, with uncertainty.
        ``"greedy"``: the seed paper's algorithm (Miranda & Ferreira, Sec. 5), as published.
        ``"ellipsoid"``: per-sensor ellipsoid fits and dot-product alignment (CK-Explorer).
    gravity, field_strength : float, optional
        Magnitudes of the reference fields; the gains come out in raw units per unit of these.
        Default 1 (unit fields).
    noise : float, array, or dict, optional
        Noise of one raw sample, used instead of the within-pose scatter (Eq. 7): a standard
        deviation (scalar or per axis), a 3x3 covariance, or ``{"accel": ..., "mag": ...}``.
        When a sensor has one sample per pose and no noise is given, it is estimated from the
        fit's residuals.
    body_frame : {"accel", "mag"}
        Which sensor's gain is made symmetric, fixing the common body frame (Sec. 4.3).
    mag_mirrored : bool
        Whether the magnetometer's axes, as given, are mirrored relative to the
        accelerometer's (a left-handed triad, e.g. the LSM9DS1's). Static poses cannot tell
        this from a field in the opposite magnetic hemisphere (the dip's sign), so it is a
        prior: by default the magnetometer's gain comes out with a positive determinant.
        Remapping the axes to match the accelerometer beforehand is equivalent.
    **options
        Passed to the method (see its documentation), e.g. ``gamma`` for ``"greedy"``.

    Returns
    -------
    Calibration
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if body_frame not in ("accel", "mag"):
        raise ValueError(f"body_frame must be 'accel' or 'mag', got {body_frame!r}")
    continuous = method == "ellipsoid" and any(
        isinstance(x, np.ndarray) and x.ndim == 2 for x in (accel, mag) if x is not None
    )
    if continuous:
        if noise is not None:
            raise ValueError(
                "noise= needs per-pose input; with continuous samples the ellipsoid method "
                "estimates the noise from its fit residuals (pass per-pose arrays instead)"
            )
        stats, sources = None, {}
    else:
        stats = summarize(accel, mag)
        if method != "ellipsoid" and stats.n_poses < MIN_POSES:
            raise ValueError(
                f"{stats.n_poses} poses given; the {method} method needs at least {MIN_POSES} "
                f"(6N readings must outnumber the 3N rotation angles plus 22 sensor parameters)"
            )
        stats, sources = (
            _with_user_noise(stats, noise)
            if noise is not None
            else (
                stats,
                {
                    name: ("scatter" if getattr(stats, name).cov is not None else "residuals")
                    for name in ("accel", "mag")
                    if getattr(stats, name) is not None
                },
            )
        )
    fit = _method(method)
    kwargs = {"raw_accel": accel, "raw_mag": mag, "body_frame": body_frame, **options}
    # The problems are small (3x3 blocks, a 22x22 system): threaded BLAS only adds contention,
    # and two processes calibrating at once made a 5 ms fit take 0.7 s with default threading.
    with _blas().limit(limits=1):
        if method in ("mle", "greedy") and "residuals" in sources.values():
            # one sample per pose: no Eq. 7, the noise comes from the fit's residuals
            from .noise import fit_with_residual_noise

            cal = fit_with_residual_noise(fit, stats, sources, warm_start=method == "mle", **kwargs)
        else:
            cal = fit(stats, noise_sources=sources, **kwargs)
    cal = cal.with_mag_handedness(mag_mirrored)
    if gravity is not None or field_strength is not None:
        cal = cal.with_field_magnitudes(gravity, field_strength)
    return cal
