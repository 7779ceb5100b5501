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

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import OptimizeResult, least_squares
from scipy.spatial.transform import Rotation

from ..calibration import Calibration, SensorCalibration
from ..geometry.alignment import constant_angle
from ..geometry.frames import GRAVITY, magnetic_reference
from ..geometry.gauge import canonical_gauge
from ..geometry.quadrics import (
    Quadric,
    algebraic_fit,
    ellipsoid_radii,
    li_griffiths_fit,
    reverse_triangular_factor,
)
from ..geometry.rotations import (
    exp_so3,
    quaternion_to_matrix,
    rotation_angle_deg,
    wahba,
)
from ..stats.pose_stats import LARGEST, PoseStats, Samples, SensorStats, as_readings, brief

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

#: Continuous input: Eq. 8 has 9 free parameters; one more sample leaves a residual from
#: which the noise can be estimated. (The closed-form alignment start needs 9 pairs too.)
MIN_SAMPLES = 10
#: Pose input: 9 free parameters need 9 distinct orientations; fewer poses leave the fit
#: determined by the noise alone.
MIN_POSES = 9


class NotAnEllipsoidWarning(RuntimeWarning):
    """The algebraic fit of Eq. 8 gave a hyperboloid (poor coverage): Eq. 13 would be NaN."""


class AlignmentError(ValueError):
    """The Levenberg-Marquardt minimisation of Eq. 16 did not converge."""


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
def stereographic_to_quaternion(p: ArrayLike) -> Array:
    """Eq. 21-24: ``(X, Y, Z)`` -> unit quaternion ``(q0, q1, q2, q3)``, q0 scalar.

    The projection's pole is ``q1 = +1``, so the identity ``q = (1, 0, 0, 0)`` is
    ``(X, Y, Z) = (1, 0, 0)``.
    """
    X, Y, Z = np.moveaxis(np.asarray(p, dtype=float), -1, 0)
    S = 1.0 + X * X + Y * Y + Z * Z
    return np.stack([2 * X / S, (S - 2.0) / S, 2 * Y / S, 2 * Z / S], axis=-1)


def quaternion_to_stereographic(q: ArrayLike) -> Array:
    """Eq. 18-20: ``X = q0/(1 − q1)``, ``Y = q2/(1 − q1)``, ``Z = q3/(1 − q1)``."""
    q = np.asarray(q, dtype=float)
    return np.stack([q[..., 0], q[..., 2], q[..., 3]], axis=-1) / (1.0 - q[..., 1:2])


def _quaternion_jacobian(p: Array) -> Array:
    """``∂q/∂(X, Y, Z)`` (4 x 3) of Eq. 21-24."""
    S = 1.0 + p @ p
    J = np.empty((4, 3))
    J[[0, 2, 3]] = 2.0 * np.eye(3) / S - 4.0 * np.outer(p, p) / S**2
    J[1] = 4.0 * p / S**2
    return J


def _rotation_derivatives(q: Array) -> Array:
    """``∂R/∂q_k`` (4 x 3 x 3) of the polynomial Eq. 17."""
    q0, q1, q2, q3 = q
    return 2.0 * np.array(
        [
            [[0, -q3, q2], [q3, 0, -q1], [-q2, q1, 0]],
            [[0, q2, q3], [q2, -2 * q1, -q0], [q3, q0, -2 * q1]],
            [[-2 * q2, q1, q0], [q1, 0, q3], [-q0, q3, -2 * q2]],
            [[-2 * q3, -q0, q1], [q0, -2 * q3, q2], [q1, q2, 0]],
        ]
    )


# =========================================================================== alignment
@dataclass(frozen=True, eq=False)
class Alignment:
    """The magnetometer-to-accelerometer rotation of Sec. 3 and the angle between the fields.

    ``rotation @ m`` expresses a calibrated magnetometer vector in the accelerometer's axes
    (Eq. 25); ``beta = cos θ`` with θ the angle between the accelerometer's reading (the
    specific force, "up") and the magnetic field. In fieldcal's NED convention the dip is
    ``θ − 90°`` (positive when the field points below the horizon).

    Attributes
    ----------
    rotation : (3, 3) array
        ``R_mis`` (Eq. 17).
    beta, theta_deg, dip_deg : float
        ``β``, ``θ = acos β`` (NaN when ``|β| > 1``, possible only with ``faithful=True``) and
        the dip.
    misalignment_deg : float
        Rotation angle of ``R_mis``.
    quaternion : (4,) array
        ``(q0, q1, q2, q3)``, scalar first, ``q0 >= 0``.
    stereographic : (3,) array
        ``(X, Y, Z)`` of Eq. 18-20 for that quaternion.
    iterations, nfev : int
        Levenberg-Marquardt iterations (Jacobian evaluations, analytic or, with
        ``faithful=True``, by forward differences) and residual evaluations.
    status : int
        MINPACK's status (``scipy.optimize.least_squares``): > 0 converged, 0 iteration limit.
    message : str
    converged : bool
    cost : float
        Sum of squared residuals of Eq. 16 (unit vectors unless ``faithful``).
    residual_rms : float
    start : str
        Which start gave the result: ``"identity"``, ``"closed-form"`` or ``"inclination"``.
    faithful : bool
    """

    rotation: Array
    beta: float
    theta_deg: float
    dip_deg: float
    misalignment_deg: float
    quaternion: Array
    stereographic: Array
    iterations: int
    nfev: int
    status: int
    message: str
    converged: bool
    cost: float
    residual_rms: float
    start: str
    faithful: bool


def _check_pairs(accel: ArrayLike, mag: ArrayLike, minimum: int) -> tuple[Array, Array]:
    why = f"Eq. 16 needs at least {minimum} pairs for its start and 4 unknowns"
    a = _check_samples(accel, "accel_cal", minimum, why)
    m = _check_samples(mag, "mag_cal", minimum, why)
    if a.shape != m.shape:
        raise ValueError(
            f"accel_cal has {a.shape[0]} samples but mag_cal has {m.shape[0]}; the alignment "
            "needs the two sensors' readings taken together, pair by pair"
        )
    return a, m


def _outer_rows(a: Array, m: Array) -> Array:
    """Rows ``vec(a mᵀ)`` (n x 9): ``aᵀ R m = vec(a mᵀ) · vec(R)``, so Eq. 16 is one matmul."""
    return np.einsum("ni,nj->nij", a, m).reshape(-1, 9)


def _forward_difference(fun: Callable[[Array], Array]) -> Callable[[Array], Array]:
    """Forward-difference Jacobian with lsqcurvefit's step ``√eps · max(|x|, 1)``.

    Given to MINPACK as a callable so that it reports its iteration count (``njev``).
    """

    def jacobian(x: Array) -> Array:
        f0 = fun(x)
        steps = np.sqrt(np.finfo(float).eps) * np.maximum(np.abs(x), 1.0)
        columns = [(fun(x + h * e) - f0) / h for h, e in zip(steps, np.eye(x.size), strict=True)]
        return np.column_stack(columns)

    return jacobian


def _residual_faithful(a: Array, m: Array) -> Callable[[Array], Array]:
    """Eq. 16 as in the seed: raw vectors, ``β`` unconstrained, R from Eq. 21-24 and 17."""
    rows = _outer_rows(a, m)
    scale = np.linalg.norm(a, axis=1) * np.linalg.norm(m, axis=1)

    def residual(params: Array) -> Array:
        R = quaternion_to_matrix(stereographic_to_quaternion(params[:3]))
        return rows @ R.ravel() - scale * params[3]

    return residual


def _residual_hardened(
    rows: Array, R0: Array
) -> tuple[Callable[[Array], Array], Callable[[Array], Array]]:
    """Eq. 16 on unit vectors with ``β = cos θ``, ``R_mis = R0 R(X, Y, Z)``; analytic Jacobian.

    ``rows`` are :func:`_outer_rows` of the unit vectors. The stereographic chart (Eq. 18-24)
    is centred on the start ``R0``, so its pole (a 180° rotation away) is never approached.
    """

    def residual(params: Array) -> Array:
        R = R0 @ quaternion_to_matrix(stereographic_to_quaternion(params[:3]))
        return rows @ R.ravel() - np.cos(params[3])

    def jacobian(params: Array) -> Array:
        q = stereographic_to_quaternion(params[:3])
        dR = R0 @ _rotation_derivatives(q)  # ∂(R0 R)/∂q_k, Eq. 17
        J = np.empty((rows.shape[0], 4))
        J[:, :3] = rows @ dR.reshape(4, 9).T @ _quaternion_jacobian(params[:3])
        J[:, 3] = np.sin(params[3])
        return J

    return residual, jacobian


def _closed_form_start(a: Array, m: Array) -> tuple[Array, float]:
    """``aᵀ R m = β`` is linear in R's nine entries and β: the SVD null vector, projected onto
    SO(3) (:func:`fieldcal.geometry.alignment.constant_angle`)."""
    return constant_angle(a, m, proper=True)


def _initial_beta(inclination_deg: float | None) -> float:
    """The seed's ``β_est = cos(90° + inclination)``, or 0 when no inclination is given."""
    if inclination_deg is None:
        return 0.0
    if (
        isinstance(inclination_deg, (bool, np.bool_))
        or not isinstance(inclination_deg, (int, float, np.integer, np.floating))
        or not (np.isfinite(inclination_deg) and -90.0 <= inclination_deg <= 90.0)
    ):
        raise ValueError(
            f"inclination_deg must be a number in [-90, 90], got {brief(inclination_deg)}"
        )
    return float(np.cos(np.radians(90.0 + inclination_deg)))


def _alignment(
    R: Array, beta: float, result: OptimizeResult, faithful: bool, start: str
) -> Alignment:
    xyzw = Rotation.from_matrix(R).as_quat()
    q = np.array([xyzw[3], *xyzw[:3]])
    q = q if q[0] >= 0 else -q
    with np.errstate(invalid="ignore"):
        theta = float(np.degrees(np.arccos(beta))) if abs(beta) <= 1 else float("nan")
    return Alignment(
        rotation=R,
        beta=float(beta),
        theta_deg=theta,
        dip_deg=theta - 90.0,
        misalignment_deg=float(rotation_angle_deg(R)),
        quaternion=q,
        stereographic=quaternion_to_stereographic(q),
        iterations=int(result.njev),
        nfev=int(result.nfev),
        status=int(result.status),
        message=str(result.message),
        converged=bool(result.status > 0),
        cost=float(2.0 * result.cost),
        residual_rms=float(np.sqrt(np.mean(result.fun**2))),
        start=start,
        faithful=faithful,
    )


def _align_faithful(a: Array, m: Array, beta0: float) -> Alignment:
    """The seed's Algorithm 2: LM from ``q = identity``, finite-difference Jacobian."""
    residual = _residual_faithful(a, m)
    x0 = np.array([1.0, 0.0, 0.0, beta0])
    result = least_squares(residual, x0, jac=_forward_difference(residual), method="lm")
    R = quaternion_to_matrix(stereographic_to_quaternion(result.x[:3]))
    alignment = _alignment(R, float(result.x[3]), result, True, "identity")
    if not alignment.converged:
        warnings.warn(f"alignment (Eq. 16) did not converge: {alignment.message}", stacklevel=3)
    return alignment


def _align_hardened(a: Array, m: Array, inclination_deg: float | None) -> Alignment:
    """Eq. 16 on unit vectors from several starts (closed form, identity); keep the best."""
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    m = m / np.linalg.norm(m, axis=1, keepdims=True)
    R_cf, beta_cf = _closed_form_start(a, m)
    starts = [("closed-form", R_cf, beta_cf), ("identity", np.eye(3), 0.0)]
    if inclination_deg is not None:
        starts.append(("inclination", np.eye(3), _initial_beta(inclination_deg)))
    rows = _outer_rows(a, m)
    best: Alignment | None = None
    for name, R0, beta0 in starts:
        residual, jacobian = _residual_hardened(rows, R0)
        theta0 = float(np.arccos(np.clip(beta0, -1 + 1e-9, 1 - 1e-9)))
        x0 = np.array([1.0, 0.0, 0.0, theta0])
        result = least_squares(residual, x0, jac=jacobian, method="lm", xtol=1e-12, ftol=1e-12)
        R = R0 @ quaternion_to_matrix(stereographic_to_quaternion(result.x[:3]))
        candidate = _alignment(R, float(np.cos(result.x[3])), result, False, name)
        if best is None or (candidate.converged, -candidate.cost) > (best.converged, -best.cost):
            best = candidate
    assert best is not None
    if not best.converged:
        raise AlignmentError(
            f"the alignment (Eq. 16) did not converge ({best.message}); check that accel and mag "
            "samples are paired and cover many orientations"
        )
    return best


def align(
    accel_cal: ArrayLike,
    mag_cal: ArrayLike,
    *,
    faithful: bool = False,
    inclination_deg: float | None = None,
) -> Alignment:
    """Rotate the magnetometer's triad onto the accelerometer's (Sec. 3, Eq. 15-25).

    Parameters
    ----------
    accel_cal, mag_cal : (n, 3) arrays
        Calibrated accelerometer and magnetometer readings taken together (pair by pair),
        e.g. ``fit_ellipsoid(...).correct(raw)``.
    faithful : bool
        ``True``: the seed's Levenberg-Marquardt on Eq. 16 as written (raw norms, free ``β``)
        from ``q = identity``, finite-difference Jacobian; a run that did not converge is
        returned with ``converged=False`` and a warning. ``False`` (default): unit vectors,
        ``β = cos θ`` (so ``|β| <= 1``), analytic Jacobian, starts from the closed-form solution
        and from the identity, keeps the lowest cost; raises :class:`AlignmentError` (a
        ``ValueError``) when no start converged.
    inclination_deg : float, optional
        Expected magnetic inclination (dip), positive below the horizon; the seed's start
        ``β0 = cos(90° + inclination)`` (default ``β0 = 0``).

    Returns
    -------
    Alignment
    """
    if not isinstance(faithful, (bool, np.bool_)):
        raise ValueError(f"faithful must be True or False, got {brief(faithful)}")
    _initial_beta(inclination_deg)  # checked before any work
    faithful = bool(faithful)
    # 4 unknowns; the hardened closed-form start solves for 10 up to scale, so needs 9 pairs
    a, m = _check_pairs(accel_cal, mag_cal, 4 if faithful else 9)
    if np.any(np.linalg.norm(a, axis=1) == 0) or np.any(np.linalg.norm(m, axis=1) == 0):
        raise ValueError("zero-length calibrated vectors; calibrate both sensors first")
    try:
        with np.errstate(all="ignore"):
            if faithful:
                return _align_faithful(a, m, _initial_beta(inclination_deg))
            return _align_hardened(a, m, inclination_deg)
    except np.linalg.LinAlgError as exc:
        raise _numerics("align", faithful)(exc) from None


# =========================================================================== fieldcal method
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
