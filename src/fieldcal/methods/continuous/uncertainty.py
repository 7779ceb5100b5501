"""Covariance of the continuous fit, the trajectory marginalised: Cramér–Rao and sandwich.

The Fisher information of the 34 parameters with the trajectory eliminated is the Schur
complement ``S = H_pp − H_pt H_tt⁻¹ H_tp`` of the Gauss–Newton matrix at the optimum
(:func:`.solver.schur`, one banded factorisation); its inverse is the Cramér–Rao bound when the
residuals are independent with the variances the weights say (Eq. C8 of
``docs/methods/continuous.md``).

They are not: the hand's acceleration is smooth, a magnetic disturbance passes over seconds,
the lab's field changes with the device's position. The reported covariance is therefore the
sandwich (Eq. C9)::

    Cov = S⁻¹ (Ω + P) S⁻¹,     Ω = long-run covariance of the per-epoch scores ψ_j

where ``ψ_j = J̃_jᵀ W_j r_j`` is epoch ``j``'s share of the gradient with the trajectory
profiled out (``J̃ = J_p − J_t H_tt⁻¹ H_tp``: a residual's effect on the parameters once the
trajectory has moved to absorb what it can; the gyroscope's factor between ``j`` and ``j + 1``
counts at ``j``), ``Ω`` the overlapping-batch-means estimate of ``Σ_l Cov(ψ_j, ψ_{j+l})``
over batches of :data:`BATCH` seconds (a Bartlett-window HAC estimate, Newey–West), and ``P``
the prior's precision (a parameter only the prior determines keeps the prior's variance).
Each parameter gets its own widening: a correlated disturbance of the accelerometer widens the
parameters it reaches, not every parameter by one factor per sensor. With independent
residuals of the variances assumed, ``Ω → S − P`` and the sandwich is the Cramér–Rao bound.
``S⁻¹`` is mapped to fieldcal's named parameters (``accel.gain[i,j]`` from the six symmetric
entries, ``dip_deg`` in degrees) by the delta method.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.lapack import dtbtrs

from ...calibration import ParameterCovariance
from ...likelihood.information import sandwich as sandwich_form
from ...likelihood.information import scaled_inverse
from ...thermal import temperature_names
from .covariates import interference_labels
from .model import (
    N_PARAMS,
    SYM,
    TEMP_SENSORS,
    Blocks,
    Data,
    State,
    accel_columns,
    accel_of,
    columns,
    mag_columns,
    mag_of,
)
from .preintegration import GyroFactors
from .solver import Normal, Weights, add_columns, normal_equations, schur, state_factors

__all__ = [
    "BATCH",
    "LEVER_NAMES",
    "NAMES",
    "covariance",
    "information",
    "kept_shares",
    "sandwich",
    "scores",
    "temperature_labels",
]

Array = NDArray[np.float64]

#: Seconds per batch of the long-run covariance of the scores (Eq. C9): several times the
#: time over which a hand's acceleration or a passing disturbance stays correlated.
BATCH = 4.0
#: Fewest batches the log must hold for the long-run covariance; shorter logs use batches of
#: a ``1/MIN_BATCHES`` of the log.
MIN_BATCHES = 8


def _names(sensor: str) -> list[str]:
    gain = [f"{sensor}.gain[{i},{j}]" for i in range(3) for j in range(3)]
    return gain + [f"{sensor}.bias[{i}]" for i in range(3)]


#: Names of the covariance's rows, in the order of fieldcal's other methods (gyro last).
NAMES: tuple[str, ...] = (*_names("accel"), *_names("mag"), "dip_deg", *_names("gyro"))


#: Covariance names of the lever arm (metres, :data:`.model.LEVER`), after :data:`NAMES`.
LEVER_NAMES: tuple[str, ...] = tuple(f"lever_arm_m[{i}]" for i in range(3))


def _extra(state: State) -> tuple[str, ...]:
    """The covariance's names past :data:`NAMES`: the lever arm's, then the temperature
    coefficients' (the parameter vector's order)."""
    return (
        *LEVER_NAMES,
        *temperature_labels(state),
        *interference_labels(len(state.interference)),  # :mod:`.covariates`
    )


def temperature_labels(state: State) -> list[str]:
    """Covariance names of the temperature coefficients, in the parameter vector's order
    (``<sensor>.temp[k,j]``, :func:`fieldcal.thermal.temperature_names`)."""
    return [
        f"{s}.{name}"
        for s in TEMP_SENSORS
        if s in state.temps
        for name in temperature_names(len(state.temps[s]))
    ]


def _to_names(extra: int = 0) -> Array:
    """``T`` with ``named = T @ p`` (37 × 34, plus ``extra`` parameters — the lever arm, the
    temperature coefficients — mapped to themselves) for the perturbations of the parameters."""
    T = np.zeros((len(NAMES) + extra, N_PARAMS + extra))
    T[len(NAMES) :, N_PARAMS:] = np.eye(extra)
    for k, (r, c) in enumerate(SYM):
        T[3 * r + c, k] = 1.0
        T[3 * c + r, k] = 1.0
    T[9:12, 6:9] = np.eye(3)
    T[12:24, 9:21] = np.eye(12)
    T[24, 21] = np.degrees(1.0)
    T[25:37, 22:34] = np.eye(12)
    return T


def information(state: State, data: Data, w: Weights) -> Array:
    """The Fisher information of the 34 parameters, the trajectory marginalised (34×34)."""
    S, *_ = schur(normal_equations(state, data, w))
    return S


def _invert(S: Array, free: NDArray[np.bool_] | None = None) -> Array:
    """``S⁻¹`` over the ``free`` parameters (all by default; held ones' rows and columns 0), a
    pseudo-inverse (a prior may hold directions the data leave free)."""
    if free is not None and not np.all(free):
        out = np.zeros_like(S)
        out[np.ix_(free, free)] = _invert(S[np.ix_(free, free)])
        return out
    return scaled_inverse(S, pseudo=True)


def _free(w: Weights, size: int) -> NDArray[np.bool_] | None:
    return None if w.prior is None else w.prior.free(size)


def _named(C: Array, extra: tuple[str, ...] = ()) -> ParameterCovariance:
    T = _to_names(len(extra))
    return ParameterCovariance((*NAMES, *extra), T @ C @ T.T)


def covariance(state: State, data: Data, w: Weights) -> tuple[ParameterCovariance, Array]:
    """The named Cramér–Rao covariance (``NAMES``, Eq. C8) and the information it inverts."""
    S = information(state, data, w)
    return _named(_invert(S, _free(w, len(S))), _extra(state)), S


@dataclass
class _Jacobians:
    """The residuals' Jacobians at the optimum, computed once for the scores and replicates."""

    accel: Blocks
    mag: Blocks
    gyro: GyroFactors
    #: Each sensor's columns in the parameter vector (:func:`.model.columns`).
    cols: dict[str, NDArray[np.intp]]
    size: int


def _jacobians(state: State, data: Data) -> _Jacobians:
    f = state_factors(state, data)
    cols = {"mag": mag_columns(state, data), "gyro": columns(state, "gyro")}
    cols["accel"] = accel_columns(state)
    return _Jacobians(
        accel_of(state, data),
        mag_of(state, data),
        f,
        cols,
        len(state.vector()),
    )


def _pushes(
    jac: _Jacobians, w: Weights, ra: Array, rm: Array, rg: Array
) -> tuple[Array, Array, Array, Array]:
    """Of given residuals, per epoch: ``J_pᵀ W r`` (n, 34) and the field sensors' ``J_tᵀ W r``
    (n, 3); per gyroscope factor ``j`` its pushes on the rotations it joins, ``(∂e/∂δ_j)ᵀ W r``
    on ``j`` and ``W r`` on ``j + 1`` (each (n − 1, 3))."""
    n = len(ra)
    own = np.zeros((n, jac.size))
    push = np.zeros((n, 3))
    for block, weight, r, sl in (
        (jac.accel, w.accel, ra, jac.cols["accel"]),
        (jac.mag, w.mag, rm, jac.cols["mag"]),
    ):
        wr = (r * weight[:, None])[:, None, :]
        add_columns(own, sl, (wr @ block.params)[:, 0])
        push += (wr @ block.rotation)[:, 0]
    wr = (rg * w.gyro[:, None])[:, None, :]
    add_columns(own[:-1], jac.cols["gyro"], (wr @ jac.gyro.params)[:, 0])
    return own, push, (wr @ jac.gyro.previous)[:, 0], wr[:, 0]


def _scores(jac: _Jacobians, w: Weights, X: Array, ra: Array, rm: Array, rg: Array) -> Array:
    """``ψ_j`` (n, 34) of given residuals: ``J̃ᵀ W r = J_pᵀ W r − X_jᵀ J_tᵀ W r``. The
    gyroscope's factor between ``j`` and ``j + 1`` counts whole at ``j``: its two pushes
    nearly cancel (``∂e/∂δ_j ≈ −I``), and split over two epochs they would not within a batch."""
    own, push, prev, nxt = _pushes(jac, w, ra, rm, rg)
    out: Array = own - (push[:, None, :] @ X)[:, 0]
    out[:-1] -= (prev[:, None, :] @ X[:-1])[:, 0] + (nxt[:, None, :] @ X[1:])[:, 0]
    return out


def _profile(normal: Normal, W: Array) -> Array:
    """``X = H_tt⁻¹ H_tp = L⁻ᵀ W`` (n, 3, 34), ``W = L⁻¹ H_tp`` from :func:`.solver.schur`."""
    assert normal.factor is not None
    X, info = dtbtrs(normal.factor, W, uplo="L", trans="T")
    if info != 0:
        raise np.linalg.LinAlgError(f"banded triangular solve failed (info {info})")
    out: Array = X.reshape(-1, 3, W.shape[1])
    return out


def scores(state: State, data: Data, w: Weights, normal: Normal, W: Array) -> Array:
    """``ψ_j`` (n, 34): each epoch's share of the gradient with the trajectory profiled out.

    ``W = L⁻¹ H_tp`` from :func:`.solver.schur` (whose factor ``L`` ``normal`` keeps);
    ``X = H_tt⁻¹ H_tp = L⁻ᵀ W`` maps a push on the trajectory to the parameters' share of it.
    For a residual ``r`` at epoch ``j`` with Jacobians ``J_t`` (rotation) and ``J_p``,
    ``J̃ᵀ W r = J_pᵀ W r − X_jᵀ J_tᵀ W r``: no array of ``J̃`` is formed.
    """
    jac = _jacobians(state, data)
    X = _profile(normal, W)
    return _scores(jac, w, X, jac.accel.residual, jac.mag.residual, jac.gyro.residual)


def _fitted(
    jac: _Jacobians, w: Weights, normal: Normal, Sinv: Array, W: Array, eps: tuple[Array, ...]
) -> tuple[Array, ...]:
    """The residuals the linearised fit leaves of errors ``eps`` (accel, mag, gyro):
    ``r̂ = ε − J H⁻¹ Jᵀ W ε``, by the factorisation already made (``Sinv``: the Schur
    complement's inverse over the free parameters, :func:`_invert`)."""
    own, rhs_t, prev, nxt = _pushes(jac, w, *eps)
    rhs_t[:-1] += prev
    rhs_t[1:] += nxt
    rhs_p = own.sum(axis=0)
    z, info = dtbtrs(normal.factor, rhs_t.reshape(-1, 1), uplo="L")
    dp = Sinv @ (rhs_p - W.T @ z[:, 0])
    x, info2 = dtbtrs(normal.factor, z - (W @ dp)[:, None], uplo="L", trans="T")
    if info or info2:
        raise np.linalg.LinAlgError("banded triangular solve failed")
    d = x[:, 0].reshape(-1, 3)
    ra, rm, rg = eps
    fa = (jac.accel.rotation @ d[:, :, None])[:, :, 0] + jac.accel.params @ dp[jac.cols["accel"]]
    fm = (jac.mag.rotation @ d[:, :, None])[:, :, 0] + jac.mag.params @ dp[jac.cols["mag"]]
    fg = (jac.gyro.previous @ d[:-1, :, None])[:, :, 0] + d[1:]
    fg += jac.gyro.params @ dp[jac.cols["gyro"]]
    return ra - fa, rm - fm, rg - fg


def _draw(rng: np.random.Generator, w: Weights) -> tuple[Array, Array, Array]:
    """Independent errors with the variances the weights say."""
    n = len(w.accel)
    return (
        rng.standard_normal((n, 3)) / np.sqrt(w.accel)[:, None],
        rng.standard_normal((n, 3)) / np.sqrt(w.mag)[:, None],
        rng.standard_normal((n - 1, 3)) / np.sqrt(w.gyro)[:, None],
    )


def kept_shares(state: State, data: Data, w: Weights, replicates: int = 2) -> Array:
    """Per sensor (accelerometer, magnetometer, gyroscope), the share of its errors' weighted
    sum of squares the fit leaves in its residuals, ``E[r̂ᵀ W r̂] / E[εᵀ W ε]`` (3,), measured on
    ``replicates`` seeded draws of independent errors passed through the linearised fit.

    The trajectory absorbs part of every error (3 unknowns per epoch among 9 readings; most of
    the gyroscope's, which it follows between the field sensors' readings): a variance taken
    from the residuals is that share of the true one. Dividing by it is the restricted
    (REML-type) moment estimate of the noise levels (Eq. C6)."""
    normal = normal_equations(state, data, w)
    S, _, W, _ = _eliminated(normal)
    Sinv = _invert(S, _free(w, len(S)))
    jac = _jacobians(state, data)
    data_w = dataclasses.replace(w, prior=None)
    rng = np.random.default_rng(1)
    kept = np.zeros(3)
    total = np.zeros(3)
    weights = (w.accel, w.mag, w.gyro)
    for _ in range(replicates):
        eps = _draw(rng, data_w)
        fitted = _fitted(jac, data_w, normal, Sinv, W, eps)
        for k in range(3):
            total[k] += float(np.sum(weights[k] * np.sum(eps[k] ** 2, axis=1)))
            kept[k] += float(np.sum(weights[k] * np.sum(fitted[k] ** 2, axis=1)))
    share: Array = np.clip(kept / np.maximum(total, 1e-300), 1e-6, 1.0)
    return share


def _eliminated(normal: Normal) -> tuple[Array, Array, Array, Array]:
    """:func:`.solver.schur` undamped, the border ``H_tp`` let go after it (``W`` replaces it;
    on an hour's log it is tens of megabytes)."""
    out = schur(normal)
    normal.border = np.empty((0, out[2].shape[1]))
    return out


def long_run(psi: Array, batch: int) -> Array:
    """``Ω``: the long-run covariance of the centred scores, summed over the log (34×34), by
    overlapping batch means over ``batch`` samples (Eq. C9)."""
    n = len(psi)
    b = int(min(max(batch, 1), max(n // MIN_BATCHES, 1)))
    x = psi - psi.mean(axis=0)
    c = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    sums = c[b:] - c[:-b]  # (n − b + 1, 34): every batch of b consecutive epochs
    omega: Array = (sums.T @ sums) * (n / (b * (n - b + 1)))
    return omega


def attenuation(
    jac: _Jacobians,
    w: Weights,
    normal: Normal,
    S: Array,
    W: Array,
    X: Array,
    batch: int,
    replicates: int = 4,
    free: NDArray[np.bool_] | None = None,
) -> Array:
    """Per parameter, the share of the long-run variance that the fitted residuals keep (34,).

    The trajectory absorbs part of every error (most of the gyroscope's): a batch's scores then
    lose what the trajectory carried across the batch's ends, over the trajectory's own
    correlation length (seconds, for the heading a magnetometer fixes against a precise
    gyroscope). Measured on ``replicates`` draws of independent errors with the weights' variances
    passed through the linearised fit (seeded: the result is deterministic): the sandwich's
    diagonal from the fitted residuals over the one from the errors themselves."""
    rng = np.random.default_rng(0)
    Sinv = _invert(S, free)
    kept = np.zeros(len(S))
    total = np.zeros(len(S))
    for _ in range(replicates):
        eps = _draw(rng, w)
        fitted = _fitted(jac, w, normal, Sinv, W, eps)
        for out, r in ((total, eps), (kept, fitted)):
            om = long_run(_scores(jac, w, X, *r), batch)
            out += np.einsum("ij,jk,ki->i", Sinv, om, Sinv)
    share: Array = np.clip(kept / np.maximum(total, 1e-300), 0.05, 1.0)
    return share


def sandwich(
    state: State, data: Data, w: Weights, batch: int
) -> tuple[ParameterCovariance, ParameterCovariance, Array]:
    """The named sandwich covariance (Eq. C9), the Cramér–Rao one (Eq. C8) and the information.

    ``batch``: samples per batch of the long-run covariance (:data:`BATCH` seconds)."""
    normal = normal_equations(state, data, w)
    S, _, W, _ = _eliminated(normal)
    data_w = dataclasses.replace(w, prior=None)
    jac = _jacobians(state, data)
    X = _profile(normal, W)
    psi = _scores(jac, data_w, X, jac.accel.residual, jac.mag.residual, jac.gyro.residual)
    omega = long_run(psi, batch)
    free = _free(w, len(S))
    share = attenuation(jac, data_w, normal, S, W, X, batch, free=free)
    Sinv = _invert(S, free)
    C = sandwich_form(Sinv, omega)
    C /= np.sqrt(np.outer(share, share))
    if w.prior is not None:
        m = len(w.prior.precision)
        C += Sinv[:, :m] @ np.diag(w.prior.precision) @ Sinv[:m, :]
    extra = _extra(state)
    return _named(0.5 * (C + C.T), extra), _named(Sinv, extra), S
