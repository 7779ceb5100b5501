"""Knots: the trajectory at a lower rate, the samples between them reduced (issue 33 item 6).

A rotation per sample makes the fit's cost and memory grow with the sample rate, although the
gyroscope already says how the body turns between samples. The trajectory is therefore kept at
*knots*, every :func:`knot_step` samples (``R_k`` the rotation at the window's first sample), and
each window of samples ``i = s_k … s_{k+1} − 1`` is reduced to one row (JointMAP's epochs, Huang,
Hendeby & Skog; pre-integration as Forster et al.):

- **the turn within the window**, ``ΔR_i = Γ_{k,i}ᵀ``, ``Γ_{k,i} = Exp(φ_{s_k}) … Exp(φ_{i−1})``
  with ``φ_j`` the calibrated turn of interval ``j`` (Eq. C4), so ``R_i = ΔR_i R_k``;
- **the field sensors' means** with the rotation compensated: the mean of Eq. C1–C2 over the
  window is ``K_a (M_k R_k g + ⟨ℓ_i⟩ / g₀) + b_a`` and ``K_m M_k R_k h + b_m`` with
  ``M_k = ⟨ΔR_i⟩`` (3×3, a rotation shrunk by the window's spread of turns), exactly;
  ``⟨ℓ_i⟩`` follows from the raw rates' mean, mean outer product and mean slope
  (:func:`.model.lever_terms`), exactly; every other per-sample covariate (temperature's
  powers, any other column of :class:`.model.Data`) is averaged, exact for terms linear in it;
- **the gyroscope between knots**, ``Γ_k = Γ_{k,s_{k+1}}``, with its first-order change with the
  gyroscope's gain, bias and temperature terms, ``∂e/∂θ = −Γ_kᵀ Σ_i Γ_{k,i+1} J_r(φ_i) K_g⁻¹
  ∂(K_g φ_i)/∂θ`` (analytic), and the noise ``σ_ω² Σ Δt_i²`` per axis
  (:func:`.preintegration.knot_factors`).

``M_k`` and ``Γ̂_k`` are computed at the gyroscope parameters of the round's start (the *anchor*);
within a round the factor follows the parameters to first order and ``M_k`` is held (its change
is second order: a gain error times the window's turn). What is lost: the field sensors'
information *within* a window about the gyroscope (the knots keep every turn between windows)
and the body acceleration's frequencies above the knot rate (noise here). The knot rate is
chosen from the motion (:func:`knot_step`) and recorded.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...geometry.rotations import exp_so3
from ...likelihood.temperature import MAX_ORDER
from .model import Data, KnotFactors, State, powers
from .preintegration import right_jacobian

__all__ = [
    "KNOT_SECONDS",
    "KNOT_TURN",
    "gyro_vector",
    "knot_step",
    "reduce",
    "sample_rates",
    "sample_rotations",
]

Array = NDArray[np.float64]

#: Longest spacing of the knots, seconds (10 Hz): a hand's turns change over tenths of a second.
KNOT_SECONDS = 0.1
#: Largest turn within a window at the log's 99th-percentile rate, radians: ``M_k`` then stays
#: near a rotation (a turn ``α`` shrinks it by about ``α²/24``) and the first-order update of the
#: pre-integrated turn stays within its noise over a round.
KNOT_TURN = 0.5
#: Knots per pass of the reduction (bounds the memory of its per-sample temporaries).
KNOT_CHUNK = 8192


def knot_step(time: Array, gyro: Array) -> tuple[int, str]:
    """Samples per knot and the rule that chose it: the most whose window lasts at most
    :data:`KNOT_SECONDS` and turns at most :data:`KNOT_TURN` at the raw rates' 99th percentile
    (at least one sample: a slow log's knots are its samples)."""
    dt = float(np.median(np.diff(time)))
    fast = float(np.quantile(np.linalg.norm(gyro, axis=1), 0.99))
    span = min(KNOT_SECONDS, KNOT_TURN / max(fast, 1e-9))
    step = max(1, int(np.floor(span / dt + 1e-9)))
    rule = (
        f"every {step} samples ({step * dt:.3g} s): at most {KNOT_SECONDS:g} s and "
        f"{KNOT_TURN:g} rad at the 99th-percentile rate ({fast:.3g} rad/s)"
    )
    return step, rule


def _orders(data: Data) -> int:
    """Temperature orders the knots carry (all the thermal terms may select)."""
    return 0 if data.temperature is None else MAX_ORDER


def gyro_vector(state: State, orders: int) -> Array:
    """``θ``: the gyroscope's gain (row-major), bias and temperature coefficients padded to
    ``orders`` (the columns of :attr:`.model.KnotFactors.jacobian`)."""
    coef = np.zeros((orders, 3))
    own = state.temps.get("gyro")
    if own is not None and len(own):
        coef[: len(own)] = own
    return np.concatenate([state.gyro_gain.ravel(), state.gyro_bias, coef.ravel()])


def _held(data: Data, lo: int, stop: int, orders: int) -> tuple[Array, Array | None]:
    """Intervals ``lo..stop−2``: the held raw rate (Eq. C4) and the held temperature powers."""
    g = data.gyro[lo:stop]
    mid = data.hold == "midpoint"
    held = 0.5 * (g[1:] + g[:-1]) if mid else g[:-1]
    if not orders or data.temperature is None:
        return held, None
    P = powers(data.temperature[lo:stop], orders)
    return held, (0.5 * (P[1:] + P[:-1]) if mid else P[:-1])


def _grid(x: Array, knots: int, step: int) -> Array:
    """Rows of ``x`` padded with zeros to ``knots × step`` and shaped ``(knots, step, …)``."""
    out = np.zeros((knots * step, *x.shape[1:]))
    out[: len(x)] = x[: knots * step]
    return out.reshape(knots, step, *x.shape[1:])


def _phi(
    data: Data, state: State, lo: int, stop: int, orders: int
) -> tuple[Array, Array, Array | None]:
    """Intervals ``lo..stop−2``: the calibrated turns ``φ`` (Eq. C4), ``Δt`` and the held
    temperature powers."""
    held, P = _held(data, lo, stop, orders)
    bias = state.gyro_bias
    if P is not None:
        bias = bias + P @ gyro_vector(state, orders)[12:].reshape(orders, 3)
    dt = np.diff(data.time[lo:stop])
    Ginv = np.linalg.inv(state.gyro_gain)
    return (held - bias) @ Ginv.T * dt[:, None], dt, P


def _turned_cross(back: Array, acc: Array) -> Array:
    """``−B [e_c]× A`` for the three axes ``c`` (k, 3, 3, m), written out: ``[e_c]× A`` is
    the cross product of ``e_c`` with each column of ``A`` (a stacked 3×3 matmul is slower)."""
    out = np.empty((len(back), 3, 3, acc.shape[2]))
    b0, b1, b2 = back[:, :, 0, None], back[:, :, 1, None], back[:, :, 2, None]
    a0, a1, a2 = acc[:, None, 0], acc[:, None, 1], acc[:, None, 2]
    out[:, 0] = b1 * a2 - b2 * a1
    out[:, 1] = b2 * a0 - b0 * a2
    out[:, 2] = b0 * a1 - b1 * a0
    return out


def _walk(
    data: Data, state: State, lo: int, knots: int, step: int, orders: int, jacobians: bool
) -> dict[str, Array]:
    """Knots ``lo..lo+knots−1``: the turns ``ΔR`` to each sample of their windows, summed
    (``M``, or each one: ``each``), the pre-integrated turn ``Γ`` to the next knot and (with
    ``jacobians``) its Jacobian ``G`` and ``Σ Δt²``."""
    first = lo * step
    stop = min(len(data.time), first + knots * step + 1)
    phi, dt, P = _phi(data, state, first, stop, orders)
    phi_g, dt_g = _grid(phi, knots, step), _grid(dt[:, None], knots, step)[:, :, 0]
    count = np.minimum(step, len(data.time) - first - np.arange(knots) * step)
    Ginv = np.linalg.inv(state.gyro_gain)
    turn = np.broadcast_to(np.eye(3), (knots, 3, 3)).copy()
    mean = turn.copy()
    each = np.empty((knots, step, 3, 3)) if not jacobians else None
    if each is not None:
        each[:, 0] = turn
    width = 12 + 3 * orders
    acc = np.zeros((knots, 3, width)) if jacobians else None
    # ∂(M u)/∂θ = Σ_c u_c D_c, D_c = −⟨ΔR_i [e_c]× acc_i⟩ (module docstring)
    spread = np.zeros((knots, 3, 3, 12)) if jacobians else None
    P_g = None if P is None else _grid(P, knots, step)
    for p in range(step):
        ph = phi_g[:, p]
        turn = turn @ exp_so3(ph)
        if acc is not None:
            A = turn @ right_jacobian(ph) @ Ginv  # Γ_{k,i+1} J_r(φ_i) K_g⁻¹
            acc[:, :, :9] += (A[:, :, :, None] * ph[:, None, None, :]).reshape(knots, 3, 9)
            Ab = A * dt_g[:, p, None, None]
            acc[:, :, 9:12] += Ab
            if P_g is not None:
                extra = Ab[:, :, None, :] * P_g[:, p, None, :, None]
                acc[:, :, 12:] += extra.reshape(knots, 3, 3 * orders)
        if p + 1 < step:
            # only a log's last window can be short: mask only when it is
            inside = None if p + 1 < count[-1] else (p + 1 < count)[:, None, None]
            back = np.swapaxes(turn, 1, 2)
            mean += back if inside is None else np.where(inside, back, 0.0)
            if spread is not None and acc is not None:
                term = _turned_cross(back, acc[:, :, :12])
                spread += term if inside is None else np.where(inside[:, None], term, 0.0)
            if each is not None:
                each[:, p + 1] = np.swapaxes(turn, 1, 2)
    out = {"mixing": mean / count[:, None, None], "turn": turn, "count": count}
    if spread is not None:
        out["spread"] = spread / count[:, None, None, None]
    if each is not None:
        out["each"] = each
    if acc is not None:
        out["jacobian"] = -np.swapaxes(turn, 1, 2) @ acc
        out["dt2"] = np.sum(dt_g**2, axis=1)
    return out


def _means(x: Array, starts: NDArray[np.intp], count: Array) -> Array:
    out: Array = np.add.reduceat(x, starts, axis=0) / count.reshape(-1, *([1] * (x.ndim - 1)))
    return out


def reduce(data: Data, state: State, step: int) -> Data:
    """The knots of ``data`` (every ``step`` samples) at ``state``'s gyroscope: one row per
    knot (module docstring), ``state.rotations`` not used."""
    n = len(data.time)
    K = -(-n // step)
    starts = np.arange(K) * step
    orders = _orders(data)
    parts = [
        _walk(data, state, lo, min(KNOT_CHUNK, K - lo), step, orders, True)
        for lo in range(0, K, KNOT_CHUNK)
    ]
    joined = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    count = joined["count"].astype(float)
    averaged: dict[str, Any] = {}
    for f in dataclasses.fields(data):
        value = getattr(data, f.name)
        if f.name in ("time", "temperature") or not isinstance(value, np.ndarray):
            continue
        if value.ndim >= 1 and len(value) == n:  # the readings and any per-sample covariate
            averaged[f.name] = _means(value, starts, count)
    if data.temperature is not None:
        averaged["temperature"] = _means(powers(data.temperature, orders), starts, count)
    g = data.gyro
    averaged["gyro_second"] = _means(g[:, :, None] * g[:, None, :], starts, count)
    averaged["mixing_jacobian"] = joined["spread"]
    factors = KnotFactors(
        joined["turn"][:-1],
        joined["jacobian"][:-1],
        joined["dt2"][:-1],
        gyro_vector(state, orders),
    )
    return dataclasses.replace(
        data, time=data.time[starts], mixing=joined["mixing"], factors=factors, **averaged
    )


def sample_rotations(data: Data, state: State, step: int) -> Array:
    """Every sample's rotation ``R_i = ΔR_i R_k`` (n, 3, 3) from the knots' (``state``) and the
    calibrated gyroscope."""
    n = len(data.time)
    K = len(state.rotations)
    orders = _orders(data)
    out = np.empty((n, 3, 3))
    for lo in range(0, K, KNOT_CHUNK):
        m = min(KNOT_CHUNK, K - lo)
        each = _walk(data, state, lo, m, step, orders, False)["each"]
        rows = (each @ state.rotations[lo : lo + m, None]).reshape(-1, 3, 3)
        first = lo * step
        out[first : first + len(rows)] = rows[: n - first]
    return out


def sample_rates(data: Data, state: State) -> Array:
    """The calibrated rate over every interval (n − 1, 3), rad/s (Eq. C4)."""
    phi, dt, _ = _phi(data, state, 0, len(data.time), _orders(data))
    out: Array = phi / dt[:, None]
    return out
