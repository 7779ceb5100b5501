"""Logs built from a known answer, shared by the rooms' tests: a CSV writer and a board
turned slowly by hand with no rests."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def _csv(path, columns: dict[str, np.ndarray]):
    names = list(columns)
    data = np.column_stack([np.asarray(columns[k], float) for k in names])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return path


def _turning(
    seed: int,
    *,
    seconds: float = 60.0,
    rate: float = 100.0,
    speed_deg: float = 12.0,
    accel_noise: float = 0.004,
    mag_noise: float = 0.3,
    mag_bias: float = 30.0,
):
    """A board turned slowly by hand with no rests, through a known calibration.

    The turn is about a body-frame axis that wanders smoothly (random knots each second),
    at ``speed_deg`` per second. Gravity (specific force, 1 up) and a 50 µT field with a 60°
    dip are read through a gain and a bias, with white noise.
    """
    rng = np.random.default_rng(seed)
    n, chunk = round(seconds * rate), 10
    k = -(-n // chunk)
    knots = rng.normal(size=(int(seconds) + 2, 3))
    at = np.arange(k) * chunk / rate
    axis = np.column_stack([np.interp(at, np.arange(len(knots)), knots[:, j]) for j in range(3)])
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    omega = np.radians(speed_deg)
    turn = Rotation.from_rotvec(axis * omega * chunk / rate)  # each chunk's turn
    starts = [Rotation.from_rotvec(rng.normal(size=3))]
    for i in range(k - 1):
        starts.append(starts[-1] * turn[i])
    within = np.arange(chunk) / rate
    steps = Rotation.from_rotvec((axis[:, None, :] * omega * within[None, :, None]).reshape(-1, 3))
    R = (Rotation.concatenate(starts)[np.repeat(np.arange(k), chunk)] * steps)[:n]
    dip = np.radians(60.0)
    g, h = np.array([0.0, 0.0, 1.0]), 50.0 * np.array([np.cos(dip), 0.0, -np.sin(dip)])
    Ka = 1000.0 * np.array([[1.02, 0.01, -0.02], [0.0, 0.98, 0.015], [0.0, 0.0, 1.01]])
    ba = np.array([20.0, -15.0, 30.0])
    Km = np.array([[1.1, 0.05, 0.02], [0.0, 0.9, -0.03], [0.0, 0.0, 1.05]])
    bm = mag_bias * np.array([1.0, -0.7, 0.3])
    accel = R.inv().apply(g) @ Ka.T + ba + rng.normal(0.0, 1000.0 * accel_noise, (n, 3))
    mag = R.inv().apply(h) @ Km.T + bm + rng.normal(0.0, mag_noise, (n, 3))
    columns = {"t": np.arange(n) / rate}
    for prefix, values in (("a", accel), ("m", mag)):
        for j, letter in enumerate("xyz"):
            columns[prefix + letter] = values[:, j]
    return columns, (Ka, ba, Km, bm)


class _Sensor:
    """A sensor stand-in without temperature terms."""

    temperature = None  # no temperature terms


class _Double:
    """A calibration stand-in: correct_* doubles the reading."""

    accel = mag = _Sensor()

    @staticmethod
    def correct_accel(raw, temperature=None):
        with np.errstate(over="ignore"):  # 2 x 1e308 is inf, as a calibration would give
            return 2 * np.asarray(raw)

    correct_mag = correct_accel
