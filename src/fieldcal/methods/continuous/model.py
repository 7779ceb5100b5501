"""The continuous-motion model: parameters, residuals and their analytic Jacobians.

One epoch per sample ``j`` with its rotation ``R_j`` (world NED → body, the body frame fixed by
the accelerometer's symmetric gain, fieldcal's gauge). Readings (``docs/methods/continuous.md``,
Eq. C1–C3)::

    a_j = K_a R_j g + b_a + ε_a,j            g = GRAVITY = (0, 0, −1)              (C1)
    m_j = K_m R_j h(δ) + b_m + ε_m,j         h = (cos δ, 0, sin δ)                 (C2)
    Log(R_{j+1} R_jᵀ Exp(ω̄_j Δt_j)) = ε_g,j  ω̄_j = K_g⁻¹ (r̄_j − b_g)              (C3)

``ε_a`` holds the sensor's noise and the body's acceleration (a per-stretch variance,
:mod:`.weights`), ``ε_m`` the magnetometer's noise, ``ε_g`` the gyroscope's noise integrated
over the interval (:mod:`.preintegration`). Rotations are perturbed on the left, in the body
frame: ``R ← Exp(δ) R``.

Parameter vector (34): accelerometer gain (6, symmetric: xx, yy, zz, xy, xz, yz), bias (3);
magnetometer gain (9, row-major), bias (3); dip (1, radians); gyroscope gain (9), bias (3).

Temperature (issue 26, ``docs/methods/temperature.md``): when the log has a temperature, each
sensor's bias may be ``b + Σ_k c_k d_j^k`` with ``d_j = T_j − T_ref`` (``State.temps``, (K, 3)
per sensor, :data:`TEMP_SENSORS` order); the coefficients follow the 34 in the vector, and
``∂f_j/∂c_k = d_j^k I`` (the gyroscope's: its bias column times the held ``d^k``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ...geometry.frames import GRAVITY, magnetic_derivative, magnetic_reference
from ...geometry.rotations import exp_so3, hat

__all__ = [
    "N_PARAMS",
    "SLICES",
    "TEMP_SENSORS",
    "Blocks",
    "Data",
    "State",
    "accel_block",
    "columns",
    "mag_block",
    "powers",
]

Array = NDArray[np.float64]

#: Where each group of parameters sits in the parameter vector.
SLICES = {
    "accel": slice(0, 9),
    "mag": slice(9, 22),
    "gyro": slice(22, 34),
}
N_PARAMS = 34
#: The sensors whose bias may carry temperature terms, in the parameter vector's order.
TEMP_SENSORS = ("accel", "mag", "gyro")
#: (row, column) of the accelerometer's six symmetric gain parameters.
SYM = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


@dataclass
class Data:
    """The readings as logged (raw units), the times (s) and how the gyroscope's rate is
    held over an interval (:mod:`.preintegration`)."""

    time: Array
    accel: Array
    mag: Array
    gyro: Array
    hold: str = "midpoint"
    #: ``T_j − T_ref`` per sample (K), when the log has a temperature.
    temperature: Array | None = None


@dataclass
class State:
    """Parameters and trajectory being fitted."""

    accel_gain: Array
    accel_bias: Array
    mag_gain: Array
    mag_bias: Array
    dip: float
    gyro_gain: Array
    gyro_bias: Array
    rotations: Array
    #: Temperature coefficients per sensor, (K, 3) (raw units per K^k); absent: none.
    temps: dict[str, Array] = field(default_factory=dict)

    def copy(self) -> State:
        return State(
            self.accel_gain.copy(),
            self.accel_bias.copy(),
            self.mag_gain.copy(),
            self.mag_bias.copy(),
            float(self.dip),
            self.gyro_gain.copy(),
            self.gyro_bias.copy(),
            self.rotations.copy(),
            {s: c.copy() for s, c in self.temps.items()},
        )

    def vector(self) -> Array:
        """The 34 parameters in the order of :data:`SLICES`, then the temperature
        coefficients (:data:`TEMP_SENSORS` order, each ``(K, 3)`` row-major)."""
        Ka = self.accel_gain
        return np.concatenate(
            [
                [Ka[r, c] for r, c in SYM],
                self.accel_bias,
                self.mag_gain.ravel(),
                self.mag_bias,
                [self.dip],
                self.gyro_gain.ravel(),
                self.gyro_bias,
                *(self.temps[s].ravel() for s in TEMP_SENSORS if s in self.temps),
            ]
        )

    def updated(self, dp: Array, dR: Array) -> State:
        """The state moved by ``dp`` and the rotations by ``Exp(dR_j) R_j``."""
        from_vec = self.vector() + dp
        Ka = np.zeros((3, 3))
        for k, (r, c) in enumerate(SYM):
            Ka[r, c] = Ka[c, r] = from_vec[k]
        temps, at = {}, N_PARAMS
        for s in TEMP_SENSORS:
            if s in self.temps:
                size = self.temps[s].size
                temps[s] = from_vec[at : at + size].reshape(-1, 3)
                at += size
        return State(
            Ka,
            from_vec[6:9],
            from_vec[9:18].reshape(3, 3),
            from_vec[18:21],
            float(from_vec[21]),
            from_vec[22:31].reshape(3, 3),
            from_vec[31:34],
            exp_so3(dR) @ self.rotations,
            temps,
        )


def columns(state: State, sensor: str) -> NDArray[np.intp]:
    """Indices in the parameter vector of ``sensor``'s parameters: its slice of
    :data:`SLICES`, then its temperature coefficients (if any)."""
    sl = SLICES[sensor]
    base = np.arange(sl.start, sl.stop)
    at = N_PARAMS
    for s in TEMP_SENSORS:
        if s not in state.temps:
            continue
        size = state.temps[s].size
        if s == sensor:
            return np.concatenate([base, np.arange(at, at + size)])
        at += size
    return base


def powers(d: Array, order: int) -> Array:
    """``d^k`` for ``k = 1..order``: (n, order)."""
    return np.asarray(d[:, None] ** np.arange(1, order + 1)[None, :], dtype=np.float64)


def _thermal(state: State, sensor: str, reading: Array, d: Array | None) -> tuple[Array, Array]:
    """The reading less its temperature shift ``Σ c_k d^k`` and the shift's Jacobian
    (n, 3, 3K) with respect to the coefficients (``d^k I`` per order)."""
    coef = state.temps.get(sensor)
    n = len(reading)
    if coef is None or d is None or len(coef) == 0:
        return reading, np.zeros((n, 3, 0))
    P = powers(d, len(coef))
    J = (P[:, None, :, None] * np.eye(3)[None, :, None, :]).reshape(n, 3, 3 * len(coef))
    return reading - P @ coef, J


@dataclass
class Blocks:
    """One sensor's whitening-free residuals ``r = y − f`` (n, 3), the Jacobian of ``f`` with
    respect to the sample's rotation (n, 3, 3) and to the sensor's parameter slice (n, 3, p)."""

    residual: Array
    rotation: Array
    params: Array


def accel_block(state: State, accel: Array, temperature: Array | None = None) -> Blocks:
    """Eq. C1: residuals and Jacobians of the accelerometer at every sample; with
    ``temperature`` (``T_j − T_ref``) and terms in ``state.temps``, the bias follows it."""
    accel, Jc = _thermal(state, "accel", accel, temperature)
    u = state.rotations @ GRAVITY  # (n, 3) body-frame "up"
    Ka = state.accel_gain
    pred = u @ Ka.T + state.accel_bias
    n = len(u)
    Jp = np.zeros((n, 3, 9))
    for k, (r, c) in enumerate(SYM):
        Jp[:, r, k] = u[:, c]
        if r != c:
            Jp[:, c, k] = u[:, r]
    Jp[:, :, 6:9] = np.eye(3)
    Jt = -Ka @ hat(u)  # d(K R g)/dδ = −K [R g]×
    if Jc.shape[2]:
        Jp = np.concatenate([Jp, Jc], axis=2)
    return Blocks(accel - pred, Jt, Jp)


def mag_block(state: State, mag: Array, temperature: Array | None = None) -> Blocks:
    """Eq. C2: residuals and Jacobians of the magnetometer at every sample (temperature as
    in :func:`accel_block`)."""
    mag, Jc = _thermal(state, "mag", mag, temperature)
    v = state.rotations @ magnetic_reference(state.dip)
    Km = state.mag_gain
    pred = v @ Km.T + state.mag_bias
    n = len(v)
    Jp = np.zeros((n, 3, 13))
    for r in range(3):
        Jp[:, r, 3 * r : 3 * r + 3] = v
    Jp[:, :, 9:12] = np.eye(3)
    Jp[:, :, 12] = (state.rotations @ magnetic_derivative(state.dip)) @ Km.T
    Jt = -Km @ hat(v)
    if Jc.shape[2]:
        Jp = np.concatenate([Jp, Jc], axis=2)
    return Blocks(mag - pred, Jt, Jp)
