"""CK-Explorer's step 2: the dot-product alignment of the magnetometer's triad onto the
accelerometer's (seed ``../shared/seeds/004_bce6d316cac7a7b6.txt``, Eq. 16-25), faithful or
hardened (:mod:`fieldcal.methods.ellipsoid` is the method).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import OptimizeResult, least_squares
from scipy.spatial.transform import Rotation

from ..geometry.alignment import constant_angle
from ..geometry.rotations import (
    quaternion_to_matrix,
    rotation_angle_deg,
)
from ..stats.pose_stats import brief
from .ellipsoid_fit import _check_samples, _numerics

Array = NDArray[np.float64]

__all__ = [
    "Alignment",
    "AlignmentError",
    "align",
    "quaternion_to_stereographic",
    "stereographic_to_quaternion",
]


class AlignmentError(ValueError):
    """The Levenberg-Marquardt minimisation of Eq. 16 did not converge."""


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
