"""The gyroscope between epochs: the calibrated turn over each interval and its Jacobians.

Epochs are the samples: the interval ``[t_j, t_{j+1}]`` is one step, with the rate held at the
mean of its two readings (``hold="midpoint"``, exact for a rate changing linearly about a fixed
axis, as :mod:`fieldcal.gyro.integrate` does) or at the first one (``hold="previous"``, for a
gyroscope whose sample is the mean rate over the interval that follows it)::

    φ_j = K_g⁻¹ (r̄_j − b_g) Δt_j,   r̄_j = (r_j + r_{j+1}) / 2  or  r_j               (C4)
    e_j = Log(R_{j+1} R_jᵀ Exp(φ_j))                                                (C3)

With ``R ← Exp(δ) R`` (body frame, left) and ``e`` small (it is the gyroscope's noise)::

    ∂e/∂δ_{j+1} = I,   ∂e/∂δ_j = −Exp(φ_j)ᵀ,   ∂e/∂φ_j = J_r(φ_j)                      (C5)
    ∂φ/∂K_g[a,b] = −(K_g⁻¹)[:, a] ω̄_b Δt,    ∂φ/∂b_g = −K_g⁻¹ Δt

where ``J_r`` is the right Jacobian of SO(3). The noise of ``e_j`` per axis: ``σ_ω² Δt_j²``
(the midpoint's two halves share samples with the neighbouring intervals; over many steps the
sum has the variance of independent steps, which is what determines drift and gain).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...geometry.rotations import exp_so3, eye_plus, hat, log_so3

__all__ = [
    "HOLDS",
    "SAMPLINGS",
    "GyroFactors",
    "gyro_factors",
    "knot_factors",
    "right_jacobian",
    "sampling_evidence",
    "thermal_factors",
]

Array = NDArray[np.float64]


def right_jacobian(phi: Array) -> Array:
    """``J_r(φ)`` of SO(3), batched over leading axes (series near 0)."""
    theta2 = np.sum(phi * phi, axis=-1)
    theta = np.sqrt(theta2)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    b = np.where(small, 1.0 / 6.0 - theta2 / 120.0, (safe - np.sin(safe)) / safe**3)
    return eye_plus(phi, -a, b, theta2)


def _log_near_identity(M: Array) -> Array:
    """``Log`` of rotations close to the identity (the factors at a fit), vectorised; the
    general :func:`~fieldcal.geometry.rotations.log_so3` for any beyond 0.5 rad."""
    vee = 0.5 * np.stack(
        [M[:, 2, 1] - M[:, 1, 2], M[:, 0, 2] - M[:, 2, 0], M[:, 1, 0] - M[:, 0, 1]], axis=1
    )
    s = np.linalg.norm(vee, axis=1)  # sin θ
    theta = np.arcsin(np.minimum(s, 1.0))
    scale = np.where(s > 1e-12, theta / np.where(s > 1e-12, s, 1.0), 1.0)
    out: Array = vee * scale[:, None]
    far = (s > 0.479) | (np.trace(M, axis1=1, axis2=2) < 1.0)
    if np.any(far):
        out[far] = log_so3(M[far])
    return out


@dataclass
class GyroFactors:
    """The gyroscope's factors between consecutive epochs.

    Attributes
    ----------
    residual : (n − 1, 3) array
        ``−e_j`` (the factor's target is 0).
    previous : (n − 1, 3, 3) array
        ``∂e_j/∂δ_j = −Exp(φ_j)ᵀ`` (``∂e_j/∂δ_{j+1}`` is the identity).
    params : (n − 1, 3, 12) array
        ``∂e_j/∂(K_g, b_g)`` (gain row-major, then bias).
    rates : (n − 1, 3) array
        ``ω̄_j``, the calibrated rate over each interval (rad/s).
    dt : (n − 1,) array
    """

    residual: Array
    previous: Array
    params: Array
    rates: Array
    dt: Array


HOLDS = ("midpoint", "previous")
#: The gyroscope's sampling conventions by their user-facing names (``gyro_sampling=``,
#: ``--gyro-sampling``) and the hold each means: a reading of the rate at its instant, or the
#: mean rate over the interval that follows it (a gyroscope that reports the turn since its
#: last output).
SAMPLINGS = {"instant": "midpoint", "mean": "previous"}


def sampling_evidence(time: Array, gyro: Array, field: Array) -> tuple[float, float]:
    """Which sampling convention the readings follow, from the field's direction in the body.

    A fixed world direction seen from the body (``field`` (n, 3), unit vectors: the
    magnetometer calibrated by the start's ellipsoid) moves between samples as
    ``v_{k+1} ≈ Exp(−φ_k) v_k``; the two conventions' turns differ by
    ``δ_k = ½ (r_{k+1} − r_k) Δt × v̄_k``. With ``e_k = Δv_k + φ_k^mean × v̄_k`` (the interval
    mean's misfit), the least-squares share ``λ = −Σ e·δ / Σ |δ|²`` is about 1 for rates read
    at their instant and 0 for interval means. Returns ``(λ, its standard error)``; the error
    is large when the rate hardly changes between samples (then the conventions agree)."""
    dt = np.diff(time)[:, None]
    v = field
    mid = 0.5 * (v[1:] + v[:-1])
    e = (v[1:] - v[:-1]) + np.cross(gyro[:-1] * dt, mid)
    d = np.cross(0.5 * (gyro[1:] - gyro[:-1]) * dt, mid)
    dd = float(np.sum(d * d))
    if not np.isfinite(dd) or dd <= 0:
        return float("nan"), float("inf")
    lam = -float(np.sum(e * d)) / dd
    rest = np.sum((e + lam * d) * d, axis=1)
    return lam, float(np.sqrt(np.sum(rest**2))) / dd


def gyro_factors(
    rotations: Array, time: Array, raw: Array, gain: Array, bias: Array, hold: str = "midpoint"
) -> GyroFactors:
    """Eq. C3–C5 for every interval of the log."""
    dt = np.diff(time)
    Ginv = np.linalg.inv(gain)
    held = 0.5 * (raw[1:] + raw[:-1]) if hold == "midpoint" else raw[:-1]
    rates = (held - bias) @ Ginv.T
    phi = rates * dt[:, None]
    D = exp_so3(phi)
    A = rotations[1:] @ np.swapaxes(rotations[:-1], 1, 2)
    e = _log_near_identity(A @ D)
    Jr = right_jacobian(phi)
    JG = Jr @ Ginv  # ∂e/∂φ · K_g⁻¹
    n = len(dt)
    params = np.empty((n, 3, 12))
    # column 3a + b: −(J_r K_g⁻¹)[:, a] ω̄_b Δt
    params[:, :, :9] = -(JG[:, :, :, None] * phi[:, None, None, :]).reshape(n, 3, 9)
    params[:, :, 9:] = -JG * dt[:, None, None]
    return GyroFactors(-e, -np.swapaxes(D, 1, 2), params, rates, dt)


def thermal_factors(
    rotations: Array,
    time: Array,
    raw: Array,
    gain: Array,
    bias: Array,
    hold: str,
    coefficients: Array | None,
    temperature: Array | None,
) -> GyroFactors:
    """:func:`gyro_factors` with the bias following temperature: ``b + Σ_k c_k d_j^k``
    (``d_j = T_j − T_ref``, ``coefficients`` (K, 3)). The rate is linear in the bias, so the
    factor's Jacobian with respect to ``c_k`` is its bias column times the held ``d^k`` (the
    interval's mean of its two ends' with ``hold="midpoint"``, the first's otherwise);
    ``params`` gains those 3K columns. Without coefficients or temperature it is
    :func:`gyro_factors`."""
    if coefficients is None or temperature is None or len(coefficients) == 0:
        return gyro_factors(rotations, time, raw, gain, bias, hold)
    order = len(coefficients)
    P = temperature[:, None] ** np.arange(1, order + 1)[None, :]
    f = gyro_factors(rotations, time, raw - P @ coefficients, gain, bias, hold)
    held = 0.5 * (P[1:] + P[:-1]) if hold == "midpoint" else P[:-1]
    Jb = f.params[:, :, 9:12]
    extra = (held[:, None, :, None] * Jb[:, :, None, :]).reshape(len(held), 3, 3 * order)
    return GyroFactors(
        f.residual, f.previous, np.concatenate([f.params, extra], axis=2), f.rates, f.dt
    )


def knot_factors(rotations: Array, turn: Array, jacobian: Array, moved: Array) -> GyroFactors:
    """The gyroscope's factors between knots (:mod:`.knots`), pre-integrated at the anchor's
    gyroscope parameters and moved to the current ones to first order (Forster et al.'s bias
    update, here for the gain and the temperature terms too)::

        Γ_k(θ) = Γ̂_k Exp(ξ_k),  ξ_k = G_k (θ − θ̂)
        e_k = Log(R_{k+1} R_kᵀ Γ_k(θ))                                              (C3')
        ∂e/∂δ_{k+1} = I,   ∂e/∂δ_k = −Γ_kᵀ,   ∂e/∂θ = J_r(ξ_k) G_k ≈ (I − ½ [ξ_k]×) G_k

    ``turn`` ``Γ̂`` (m, 3, 3), ``jacobian`` ``G`` (m, 3, p) and ``moved`` ``θ − θ̂`` (p,); as a
    sample's factor (:func:`gyro_factors`) with ``Exp(φ)`` replaced by ``Γ``. ``rates`` and
    ``dt`` are left to the caller (the knots' ``dt`` is ``√ΣΔt²``, the noise's scale)."""
    xi = jacobian @ moved
    G = turn @ exp_so3(xi)
    A = rotations[1:] @ np.swapaxes(rotations[:-1], 1, 2)
    e = _log_near_identity(A @ G)
    # J_r(ξ) G, ξ the parameters' move since the anchor (a round's: thousandths of a radian)
    params = jacobian - 0.5 * (hat(xi) @ jacobian)
    m = len(turn)
    return GyroFactors(-e, -np.swapaxes(G, 1, 2), params, np.zeros((m, 3)), np.ones(m))
