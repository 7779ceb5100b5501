"""CK-Explorer's step 1: the ellipsoid fit of one sensor's samples (seed
``../shared/seeds/004_bce6d316cac7a7b6.txt``, Eq. 8-14; :mod:`fieldcal.methods.ellipsoid` is
the method, which also runs step 2, :mod:`.dot_alignment`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..geometry.quadrics import (
    Quadric,
    algebraic_fit,
    ellipsoid_radii,
    li_griffiths_fit,
    reverse_triangular_factor,
)
from ..stats.pose_stats import LARGEST, as_readings, brief

Array = NDArray[np.float64]

__all__ = ["MIN_POSES", "MIN_SAMPLES", "EllipsoidFit", "NotAnEllipsoidWarning", "fit_ellipsoid"]

#: Continuous input: Eq. 8 has 9 free parameters; one more sample leaves a residual from
#: which the noise can be estimated. (The closed-form alignment start needs 9 pairs too.)
MIN_SAMPLES = 10
#: Pose input: 9 free parameters need 9 distinct orientations; fewer poses leave the fit
#: determined by the noise alone.
MIN_POSES = 9


class NotAnEllipsoidWarning(RuntimeWarning):
    """The algebraic fit of Eq. 8 gave a hyperboloid (poor coverage): Eq. 13 would be NaN."""


# =========================================================================== ellipsoid fit
@dataclass(frozen=True, eq=False)
class EllipsoidFit:
    """One sensor's ellipsoid calibration in the seed's terms (Sec. 2).

    ``corrected = correction @ (raw − center)`` (Eq. 14) lies on the unit sphere; in fieldcal's
    model terms ``raw = gain @ v + bias`` with ``gain = correction⁻¹`` and ``bias = center``.

    Attributes
    ----------
    center : (3,) array
        ``(x_o, y_o, z_o)``: offset or hard iron, raw units.
    correction : (3, 3) array
        ``L``, lower triangular with ``LᵀL = M`` (Eq. 13); NaN when the fit is no ellipsoid
        (only with ``faithful=True``).
    gain, bias : arrays
        ``L⁻¹`` and ``center``: the same calibration as fieldcal's forward model.
    shape : (3, 3) array
        ``M = LᵀL`` (Eq. 12).
    coefficients : (10,) array
        ``v0..v9`` of Eq. 8 with ``v0 + v1 + v2 = −3``.
    kappa : float
        ``κ`` of Eq. 11.
    radii : (3,) array
        Semi-axes of the ellipsoid, raw units, longest first.
    fit_method : str
        ``"algebraic"`` (Eq. 8) or ``"li-griffiths"`` (fallback).
    fallback_used, is_ellipsoid, faithful : bool
    residual_rms : float
        RMS of ``|L (s − c)| − 1`` (unit-sphere units).
    n_samples : int
    """

    center: Array
    correction: Array
    gain: Array
    bias: Array
    shape: Array
    coefficients: Array
    kappa: float
    radii: Array
    fit_method: str
    fallback_used: bool
    is_ellipsoid: bool
    faithful: bool
    residual_rms: float
    n_samples: int

    def correct(self, raw: ArrayLike) -> Array:
        """Eq. 14: ``L (raw − center)`` for readings (..., 3)."""
        return (np.asarray(raw, dtype=float) - self.center) @ self.correction.T


def _check_samples(
    samples: ArrayLike,
    name: str,
    minimum: int = MIN_SAMPLES,
    why: str = "the ellipsoid of Eq. 8 has 9 free parameters, and one more leaves a residual "
    "for the noise",
) -> Array:
    x = as_readings(samples, name)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"{name}: expected an (n, 3) array of x, y, z readings, got {x.shape}")
    if x.shape[0] < minimum:
        raise ValueError(
            f"{name}: {x.shape[0]} samples given; at least {minimum} are needed ({why})"
        )
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name}: NaN or inf readings; remove those samples before calibrating")
    if np.any(np.abs(x) > LARGEST):
        raise ValueError(
            f"{name}: readings up to {float(np.abs(x).max()):.3g} are too large to square in "
            "floating point; give them in a smaller unit"
        )
    return x


def _numerics(name: str, faithful: bool) -> Callable[[np.linalg.LinAlgError], ValueError]:
    """The one-line error for a fit that numpy's linear algebra could not finish."""

    def error(exc: np.linalg.LinAlgError) -> ValueError:
        hint = (
            "faithful=True computes on the raw numbers: give readings of order one, or use "
            "faithful=False"
            if faithful
            else "record more orientations, each axis up and down"
        )
        return ValueError(f"{name}: the fit failed in floating point ({exc}); {hint}")

    return error


def _ellipsoid_quadric(
    x: Array, faithful: bool, name: str, weights: Array | None = None
) -> tuple[Quadric, bool]:
    """Eq. 8-12 on all samples; hardened: conditioned, with the Li & Griffiths fallback."""
    quadric = algebraic_fit(x, weights, conditioned=not faithful)
    if quadric.is_ellipsoid:
        return quadric, False
    if faithful:
        warnings.warn(
            f"{name}: the quadric of Eq. 8 is not an ellipsoid (poor coverage), so L (Eq. 13) "
            "is NaN; use faithful=False for the ellipsoid-specific fallback",
            NotAnEllipsoidWarning,
            stacklevel=3,
        )
        return quadric, False
    warnings.warn(
        f"{name}: the quadric of Eq. 8 is not an ellipsoid (the samples cover too few "
        "orientations); fell back to the Li & Griffiths ellipsoid-specific fit",
        NotAnEllipsoidWarning,
        stacklevel=3,
    )
    quadric = li_griffiths_fit(x, weights)
    if not quadric.is_ellipsoid:  # pragma: no cover - 4J − I² = 1 admits only ellipsoids
        raise ValueError(f"{name}: no ellipsoid fits these samples; record more orientations")
    return quadric, True


def fit_ellipsoid(samples: ArrayLike, *, faithful: bool = False) -> EllipsoidFit:
    """Calibrate one sensor alone (Sec. 2): offset/hard iron, scale, cross-axis/soft iron.

    Parameters
    ----------
    samples : (n, 3) array
        Raw readings of an accelerometer at rest or a magnetometer, in as many orientations as
        possible (n >= 10).
    faithful : bool
        ``True``: the seed's computation (normal equations on raw numbers; a hyperboloid gives
        a NaN ``L`` with a :class:`NotAnEllipsoidWarning`). ``False`` (default): conditioned
        least squares, and the Li & Griffiths fit (with the warning) when Eq. 8 is no ellipsoid.

    Returns
    -------
    EllipsoidFit
        The seed's ``L`` and centre; ``correct(raw)`` applies Eq. 14.
    """
    if not isinstance(faithful, (bool, np.bool_)):
        raise ValueError(f"faithful must be True or False, got {brief(faithful)}")
    x = _check_samples(samples, "samples")
    try:
        with np.errstate(all="ignore"):  # a failed fit shows as NaN (faithful) or an error
            quadric, fallback = _ellipsoid_quadric(x, bool(faithful), "samples")
            return _ellipsoid_result(x, quadric, fallback, bool(faithful))
    except np.linalg.LinAlgError as exc:
        raise _numerics("samples", bool(faithful))(exc) from None


def _ellipsoid_result(x: Array, quadric: Quadric, fallback: bool, faithful: bool) -> EllipsoidFit:
    L = reverse_triangular_factor(quadric.shape)  # Eq. 13
    finite = bool(np.all(np.isfinite(L)))
    gain = cast(Array, np.linalg.inv(L)) if finite else np.full((3, 3), np.nan)
    with np.errstate(invalid="ignore"):
        norms = np.linalg.norm((x - quadric.center) @ L.T, axis=1)  # Eq. 14
    return EllipsoidFit(
        center=quadric.center,
        correction=L,
        gain=gain,
        bias=quadric.center,
        shape=quadric.shape,
        coefficients=quadric.coefficients,
        kappa=quadric.kappa,
        radii=ellipsoid_radii(quadric.shape),
        fit_method="li-griffiths" if fallback else "algebraic",
        fallback_used=fallback,
        is_ellipsoid=quadric.is_ellipsoid and finite,
        faithful=faithful,
        residual_rms=float(np.sqrt(np.mean((norms - 1.0) ** 2))),
        n_samples=int(x.shape[0]),
    )


# =========================================================================== stereographic
