"""What a continuous log's fit says about the gyroscope, the field and the turns, as numbers.

The estimator records these in ``cal.options`` (``gyro_check``, ``field_check``,
``turn_check``); the verdict's rules (:mod:`fieldcal.trust.continuous_motion`, codes in
``docs/trust.md``) read them. Each is measured, never assumed:

- **the gyroscope's gain** (``gyro_check``): its scale (the cube root of ``|det K_g|``), the
  axes whose gain came out negative (a sign flipped in the axis mapping), and each axis's
  misalignment, the angle between the row ``K_g[i, :]`` (the direction that axis senses, in the
  accelerometer's body frame) and the body axis ``e_i``, with its standard error by the delta
  method (``∂θ_i/∂K_g[i, j] ≈ K_g[i, j] / (K_g[i, i] |K_g[i, :]| sin θ_i)`` off the diagonal,
  taken as ``σ(off-diagonal row) / |K_g[i, i]|`` near zero);
- **the gyroscope's units before the fit** (:func:`gyro_units_ratio`): the magnetometer's
  direction turns at ``|ω × m̂|``, so the raw rates' ``Σ |r × m̂|`` over the direction's own
  ``Σ |d m̂/dt|`` is about 1 for rad/s and about 57 for °/s (soft iron distorts the direction
  by far less than that factor);
- **the field's consistency** (``field_check``): after calibration the field's strength is 1 and
  its dip constant; a magnet that moves with the device but not rigidly, or iron passed near
  it, shows as the calibrated strength's RMS departure from 1 and the dip's spread over
  :data:`~.weights.STRETCH`-second stretches (BROAD: 2.5–3.7 % and 0.8–4° undisturbed, 15 % and
  5.6° with a magnet 2 cm from the sensor);
- **the turns** (``turn_check``): the largest turn per sample (the 99th percentile of
  ``|ω| Δt``) and the share of samples at an axis's extreme reading (a gyroscope at its range).
"""

from __future__ import annotations

from typing import TypedDict

import numpy as np
from numpy.typing import NDArray

from ...calibration import ParameterCovariance
from .model import Data, State

__all__ = [
    "UNITS_STEP",
    "FieldCheck",
    "GyroCheck",
    "TurnCheck",
    "field_check",
    "gyro_check",
    "gyro_units_ratio",
    "turn_check",
]

Array = NDArray[np.float64]

#: Seconds per step of the gyroscope's units check (:func:`gyro_units_ratio`).
UNITS_STEP = 0.1


class GyroCheck(TypedDict):
    """:func:`gyro_check`'s record (``options["gyro_check"]``)."""

    scale: float
    diagonal: list[float]
    diagonal_std: list[float]
    negative_axes: list[int]
    misalignment_deg: list[float]
    misalignment_std_deg: list[float]


class FieldCheck(TypedDict):
    """:func:`field_check`'s record (``options["field_check"]``)."""

    strength_rms: float
    strength_worst_stretch: float
    dip_spread_deg: float


class TurnCheck(TypedDict):
    """:func:`turn_check`'s record (``options["turn_check"]``)."""

    step_rad_p99: float
    max_rate: float
    clipped_axes: list[int]


def gyro_check(gain: Array, cov: ParameterCovariance) -> GyroCheck:
    """The gyroscope gain's scale, negative axes and misalignment per axis (module docstring)."""
    K = np.asarray(gain, dtype=float)
    names = [f"gyro.gain[{i},{j}]" for i in range(3) for j in range(3)]
    std = cov.stds(names).reshape(3, 3)
    rows = np.linalg.norm(K, axis=1)
    cos = np.abs(np.diag(K)) / np.maximum(rows, 1e-300)
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    off = ~np.eye(3, dtype=bool)
    off_std = np.sqrt(np.sum(np.where(off, std, 0.0) ** 2, axis=1))
    angle_std = np.degrees(off_std / np.maximum(np.abs(np.diag(K)), 1e-300))
    return {
        "scale": float(np.abs(np.linalg.det(K)) ** (1.0 / 3.0)),
        "diagonal": [float(x) for x in np.diag(K)],
        "diagonal_std": [float(x) for x in np.diag(std)],
        "negative_axes": [int(i) for i in range(3) if K[i, i] < 0],
        "misalignment_deg": [float(x) for x in angle],
        "misalignment_std_deg": [float(x) for x in angle_std],
    }


def gyro_units_ratio(time: Array, mag: Array, gyro: Array) -> float | None:
    """``Σ |r̄ × m̂| Δ / Σ ∠(m̂_k, m̂_{k+1})`` over steps of :data:`UNITS_STEP` seconds (module
    docstring; the step long enough that the magnetometer's noise does not add turns): about
    1 for a gyroscope in rad/s, 57 in °/s; ``None`` when the field direction barely turned."""
    n = len(time)
    if n < 3:
        return None
    k = max(1, round(UNITS_STEP / float(np.median(np.diff(time)))))
    at = np.arange(0, n, k)
    if len(at) < 3:
        return None
    norm = np.linalg.norm(mag[at], axis=1)
    if np.any(norm <= 0):
        return None
    # as logged: the hard iron is not known yet, and it only shrinks the direction's turns
    u = mag[at] / norm[:, None]
    moved = np.arccos(np.clip(np.sum(u[1:] * u[:-1], axis=1), -1.0, 1.0))
    c = np.concatenate([np.zeros((1, 3)), np.cumsum(gyro[:-1] * np.diff(time)[:, None], 0)])
    turned = c[at[1:]] - c[at[:-1]]  # the raw rates integrated over each step
    sensed = np.linalg.norm(np.cross(turned, 0.5 * (u[1:] + u[:-1])), axis=1)
    total = float(np.sum(moved))
    if total <= 1e-3 * len(moved) or not np.isfinite(total):
        return None
    return float(np.sum(sensed) / total)


def field_check(state: State, data: Data, length: int) -> FieldCheck:
    """The calibrated field's strength (RMS relative departure from 1, largest stretch mean)
    and dip (RMS over stretches of ``length`` samples of the stretch's mean departure from the
    median, degrees, where the accelerometer reads gravity within 5 %) (module docstring)."""
    m = np.linalg.solve(state.mag_gain, (data.mag - state.mag_bias).T).T
    strength = np.linalg.norm(m, axis=1)
    # the dip from the calibrated accelerometer where it reads gravity alone (within 5 %): the
    # fitted trajectory would follow a disturbed field part of the way
    a = np.linalg.solve(state.accel_gain, (data.accel - state.accel_bias).T).T
    quiet = np.abs(np.linalg.norm(a, axis=1) - 1.0) < 0.05
    down = -a / np.maximum(np.linalg.norm(a, axis=1), 1e-300)[:, None]
    dip = np.degrees(np.arcsin(np.clip(np.sum(down * m, 1) / np.maximum(strength, 1e-300), -1, 1)))
    k = max(1, int(length))
    count = len(strength) // k
    out: FieldCheck = {
        "strength_rms": float(np.sqrt(np.mean((strength - 1.0) ** 2))),
        "strength_worst_stretch": 0.0,
        "dip_spread_deg": 0.0,
    }
    if count >= 1:
        means = strength[: count * k].reshape(count, k).mean(axis=1)
        out["strength_worst_stretch"] = float(np.max(np.abs(means - 1.0)))
        sel = quiet[: count * k].reshape(count, k)
        d = dip[: count * k].reshape(count, k)
        n_sel = sel.sum(axis=1)
        ok = n_sel >= max(1, k // 10)
        if np.sum(ok) >= 2:
            per = np.sum(np.where(sel, d, 0.0), axis=1)[ok] / n_sel[ok]
            out["dip_spread_deg"] = float(np.sqrt(np.mean((per - np.median(per)) ** 2)))
    return out


def turn_check(time: Array, rates: Array, raw: Array) -> TurnCheck:
    """The largest turns per sample (99th percentile of ``|ω| Δt``, radians), the largest rate
    (rad/s) and the share of samples at an axis's extreme reading (a gyroscope at its range:
    the same extreme on more than 0.5 % of the samples)."""
    dt = np.diff(time)
    step = np.linalg.norm(rates, axis=1) * dt
    peak = np.max(np.abs(raw), axis=0)
    at_extreme = np.abs(raw) >= peak[None, :] * (1.0 - 1e-6)
    share = at_extreme.mean(axis=0)
    clipped = [int(i) for i in range(3) if share[i] > 0.005 and peak[i] > 0]
    return {
        "step_rad_p99": float(np.quantile(step, 0.99)) if len(step) else 0.0,
        "max_rate": float(np.max(np.linalg.norm(rates, axis=1))) if len(rates) else 0.0,
        "clipped_axes": clipped,
    }
