"""A multirotor's flight with a known truth, for the interference term (issue 36).

Independent of the estimator: it knows nothing of :mod:`fieldcal.trust.interference_fit`.
The flight alternates hover (small tilts), forward legs (pitched 8–20° down, turning), turns
(yaw rates to 60°/s) and climbs/descents (throttle steps). Throttle follows the climb and the
tilt (``thrust ∝ 1/cos tilt``) with its own flicker; the battery current is
``2 + 58·throttle^1.5`` A (2–60 A), the interference ``K · current`` with ``|K|·60 A`` between
5 and 40 µT in a random direction. The magnetometer (µT) reads ``K_m R h + b + K u + noise``
with a random gain (±5 %, small cross-axis terms) and bias (±20 µT); the accelerometer reads
gravity and the body's acceleration (m/s², FRD: at rest ``(0, 0, −9.81)``); the gyroscope the
body rate (rad/s). The autopilot's attitude estimate is the truth turned by a slowly
wandering error (``attitude_error_deg``, independent of the current).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

__all__ = ["Flight", "simulate_flight"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Flight:
    """A simulated flight: readings, inputs and the truth."""

    time: Array
    accel: Array
    gyro: Array
    mag: Array
    current: Array
    throttle: Array
    attitude: Array  # the autopilot's estimate, body -> NED quaternions (w, x, y, z)
    true_attitude: Array
    gain: Array
    bias: Array
    coefficients: Array  # (3,) µT per A
    field: Array  # NED, µT

    def columns(self) -> dict[str, Array]:
        """The flight as a log's columns (what a flight log's reader gives)."""
        out = {"t": self.time}
        for name, values in (("a", self.accel), ("g", self.gyro), ("m", self.mag)):
            for j, axis in enumerate("xyz"):
                out[f"{name}{axis}"] = values[:, j]
        out["current"] = self.current
        out["throttle"] = self.throttle
        for j, part in enumerate("wxyz"):
            out[f"attitude_q{part}"] = self.attitude[:, j]
        return out


def _smooth(rng: np.random.Generator, n: int, rate: float, seconds: float, scale: float) -> Array:
    """A smooth random signal: random knots every ``seconds``, interpolated."""
    knots = rng.normal(0.0, scale, size=int(n / rate / seconds) + 3)
    at = np.arange(n) / rate / seconds
    return np.interp(at, np.arange(len(knots)), knots)


def simulate_flight(
    seed: int,
    *,
    seconds: float = 180.0,
    rate: float = 50.0,
    interference_ut: float | None = None,
    mag_noise: float = 0.3,
    attitude_error_deg: float = 0.5,
    current_varies: bool = True,
) -> Flight:
    """A flight (the module docstring says what it holds).

    ``interference_ut``: ``|K|`` at 60 A (default: drawn from 5–40 µT). ``current_varies``:
    False holds the throttle at hover (the current within ±0.3 A): the term is then not
    identifiable.
    """
    rng = np.random.default_rng(seed)
    n = round(seconds * rate)
    t = np.arange(n) / rate
    yaw_rate = np.radians(_smooth(rng, n, rate, 4.0, 35.0))
    yaw = np.cumsum(yaw_rate) / rate + rng.uniform(0, 2 * np.pi)
    legs = (_smooth(rng, n, rate, 6.0, 1.0) > 0.3).astype(float)  # forward legs
    pitch = np.radians(-legs * (8 + 12 * np.abs(_smooth(rng, n, rate, 5.0, 1.0))))
    pitch += np.radians(_smooth(rng, n, rate, 1.5, 3.0))
    roll = np.radians(_smooth(rng, n, rate, 1.5, 6.0))
    # smooth the legs' edges (a multirotor tilts in about a second)
    kernel = np.ones(int(rate)) / int(rate)
    pitch = np.convolve(pitch, kernel, mode="same")
    truth = Rotation.from_euler("ZYX", np.column_stack([yaw, pitch, roll]))
    tilt = np.arccos(np.clip(np.cos(pitch) * np.cos(roll), 0.5, 1.0))
    climb = np.clip(_smooth(rng, n, rate, 8.0, 0.25), -0.25, 0.35)
    if current_varies:
        throttle = (0.45 + climb) / np.cos(tilt) + 0.02 * _smooth(rng, n, rate, 0.3, 1.0)
    else:
        throttle = 0.45 + 0.002 * _smooth(rng, n, rate, 0.3, 1.0)
    throttle = np.clip(throttle, 0.0, 1.0)
    current = np.clip(2.0 + 58.0 * throttle**1.5, 2.0, 60.0)
    size = interference_ut if interference_ut is not None else rng.uniform(5.0, 40.0)
    direction = rng.normal(size=3)
    coefficients = size / 60.0 * direction / np.linalg.norm(direction)
    dip, dec = np.radians(rng.uniform(40, 70)), np.radians(rng.uniform(-15, 15))
    field = 50.0 * np.array([np.cos(dip) * np.cos(dec), np.cos(dip) * np.sin(dec), np.sin(dip)])
    gain = np.eye(3) + rng.uniform(-0.05, 0.05, (3, 3)) * np.array(
        [[1, 0.2, 0.2], [0.2, 1, 0.2], [0.2, 0.2, 1]]
    )
    bias = rng.uniform(-20, 20, 3)
    world_to_body = truth.inv()
    body_field = world_to_body.apply(field)
    mag = body_field @ gain.T + bias + current[:, None] * coefficients
    mag += rng.normal(0, mag_noise, (n, 3))
    # the body rate that carries each attitude to the next: R_{k+1} = R_k Exp(ω dt)
    steps = (truth[:-1].inv() * truth[1:]).as_rotvec() * rate
    body_rate = np.vstack([steps, steps[-1:]])
    gyro = body_rate + rng.normal(0, 0.003, (n, 3))
    accel = world_to_body.apply(np.array([0.0, 0.0, -9.81])) + rng.normal(0, 0.05, (n, 3))
    wander = np.column_stack([_smooth(rng, n, rate, 10.0, 1.0) for _ in range(3)])
    error = Rotation.from_rotvec(np.radians(attitude_error_deg) * wander)
    estimate = truth * error
    quat = estimate.as_quat(scalar_first=True)
    return Flight(
        t,
        accel,
        gyro,
        mag,
        current,
        throttle,
        quat,
        truth.as_quat(scalar_first=True),
        gain,
        bias,
        coefficients,
        field,
    )
