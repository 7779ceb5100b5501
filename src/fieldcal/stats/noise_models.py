"""Noise values: the user's per-sample noise and pose-level noise as covariances, and the
standard error of Eq. 7's estimate.

Two noise terms make up the covariance of a pose mean (``docs/methods/pose-noise.md``)::

    C_si = Σ_s / Δ_si + Q_s

``Σ_s`` is one raw sample's covariance (Eq. 7, or the user's ``noise=``), ``Q_s = q_s² I`` the
pose-level noise (estimated, or the user's ``pose_noise=``).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from .pose_stats import as_readings, brief

__all__ = ["noise_covariance", "per_sensor", "pose_noise_value", "wishart_std"]

Array = NDArray[np.float64]


def per_sensor(value: object, what: str) -> dict[str, object]:
    """``value`` for both sensors, or the ``{"accel": ..., "mag": ...}`` the user gave."""
    if isinstance(value, Mapping):
        unknown = sorted(map(str, set(value) - {"accel", "mag"}))
        if unknown:
            raise ValueError(f"{what} keys must be 'accel' and/or 'mag', got {unknown}")
        return {k: value.get(k) for k in ("accel", "mag")}
    return {"accel": value, "mag": value}


def _finite_positive(array: Array, name: str, value: object) -> None:
    if array.dtype.kind not in "fiu" or not np.all(np.isfinite(array)) or not np.all(array > 0):
        raise ValueError(f"noise for {name} must be finite and positive, got {brief(value)}")


def noise_covariance(value: object, name: str) -> Array:
    """A user's per-sample noise: a standard deviation (scalar or per axis) or a 3x3 covariance."""
    if isinstance(value, (str, bytes, bool, np.bool_)):
        raise ValueError(f"noise for {name} must be a number or an array, got {brief(value)}")
    try:
        array = as_readings(value, f"noise for {name}")
    except ValueError:
        raise ValueError(
            f"noise for {name} must be a number or an array of real numbers, got {brief(value)}"
        ) from None
    if array.ndim == 0 or array.shape == (3,):
        _finite_positive(array, name, value)
        with np.errstate(over="ignore", invalid="ignore"):  # caught below, with its reason
            cov = np.eye(3) * np.square(array) if array.ndim == 0 else np.diag(np.square(array))
        if not (np.all(np.isfinite(cov)) and np.all(np.diag(cov) > 0)):
            size = "large" if np.any(array > 1) else "small"
            raise ValueError(
                f"noise for {name} is too {size} to square in floating point ({brief(value)}); "
                "give it in the readings' own units"
            )
        return cov
    if array.shape != (3, 3):
        raise ValueError(
            f"noise for {name} must be a standard deviation (scalar or 3 values) or a 3x3 "
            f"covariance, got shape {array.shape}"
        )
    cov = 0.5 * (array + array.T)
    if not np.all(np.isfinite(cov)) or np.any(np.linalg.eigvalsh(cov) <= 0):
        raise ValueError(f"noise for {name} must be a finite positive definite covariance")
    return cov


def pose_noise_value(value: object, name: str) -> float | None:
    """A user's pose-level noise: a standard deviation in raw units (0 allowed), as a variance.

    ``"auto"`` (estimate) gives ``None``; ``"none"`` gives 0.
    """
    if value is None or value == "auto":
        return None
    if value == "none":
        return 0.0
    if isinstance(value, (str, bytes, bool)):
        raise ValueError(
            f"pose_noise for {name} must be 'auto', 'none' or a standard deviation in raw "
            f"units, got {brief(value)}"
        )
    try:
        std = float(value)  # type: ignore[arg-type]  # float() itself is the check
    except (TypeError, ValueError):
        raise ValueError(
            f"pose_noise for {name} must be 'auto', 'none' or a standard deviation in raw "
            f"units, got {brief(value)}"
        ) from None
    if not (np.isfinite(std) and std >= 0):
        raise ValueError(
            f"pose_noise for {name} must be finite and not negative, got {brief(value)}"
        )
    return std * std


def wishart_std(cov: Array, dof: int) -> Array:
    """Standard error of Eq. 7's entries: ``Var Σ̂_ij = (Σ_ij² + Σ_ii Σ_jj)/ν``."""
    d = cov.diagonal()
    # Σ_ii Σ_jj by broadcasting: np.outer's numbers without its wrapper (called per fit)
    return np.asarray(np.sqrt((cov**2 + d[:, None] * d[None, :]) / max(dof, 1)))
