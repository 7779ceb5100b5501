"""Warm-up sessions: a board powered on cold, posed while it warms, biases drifting with T.

The die temperature follows a first-order warm-up, ``T(t) = T₀ + ΔT (1 − exp(−t/τ))``, and each
sensor's bias moves with it, ``b(T) = b + Σ_k a_k (T − T₀)^k`` (``a_k`` drawn per axis,
linear and quadratic by default): the model of ``docs/methods/temperature.md``. Samples are
those of :func:`fieldcal.simulate` (or :func:`fieldcal.simulation.continuous.
simulate_continuous` for a log with motion and a gyroscope) with the drift added, so the rest
of the truth is theirs.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np
from numpy.typing import NDArray

from .continuous import ContinuousLog, simulate_continuous
from .session import Session, simulate

__all__ = ["ThermalTruth", "WarmupLog", "WarmupSession", "simulate_warmup", "simulate_warmup_log"]

Array = NDArray[np.float64]

#: Default drift per axis, half-range of the drawn coefficient of each order (field units per
#: K^k): about 0.04 |g| and 0.08 |h| over 20 K (reports: 0.05–0.1 g over 45 K on a cheap
#: flight controller, ~10 µT of ~50 µT over 45 K on the IST8310), gyro ~1 °/s per 20 K.
DRIFT: dict[str, tuple[float, ...]] = {
    "accel": (2e-3, 3e-5),
    "mag": (4e-3, 5e-5),
    "gyro": (1e-3, 1e-5),
}


@dataclass(frozen=True)
class ThermalTruth:
    """The drawn drift: ``b(T) − b = Σ_k coefficients[s][k−1] (T − start)^k`` per sensor."""

    start: float
    coefficients: dict[str, Array]

    def drift(self, sensor: str, temperature: Array) -> Array:
        """(..., 3): the bias's drift of ``sensor`` at ``temperature`` (°C)."""
        d = np.asarray(temperature, dtype=float)[..., None] - self.start
        out = np.zeros((*d.shape[:-1], 3))
        for k, c in enumerate(self.coefficients[sensor], start=1):
            out = out + c * d**k
        return out

    def about(self, sensor: str, reference: float, order: int | None = None) -> Array:
        """(K, 3): the same polynomial in ``T − reference`` without its constant term (what
        a fit with ``T_ref = reference`` estimates), padded with zeros to ``order`` rows."""
        a = self.coefficients[sensor]
        K = len(a)
        delta = reference - self.start
        out = np.zeros((max(K, order or 0), 3))
        for j in range(1, K + 1):  # (u + δ)^j = Σ_k C(j, k) δ^(j−k) u^k
            for k in range(1, j + 1):
                out[k - 1] += comb(j, k) * delta ** (j - k) * a[j - 1]
        return out


@dataclass(frozen=True)
class WarmupSession:
    """Per-pose samples while the board warms: ``accel``, ``mag`` (lists of (n_i, 3)) and
    ``temperature`` (list of (n_i,), °C); ``session`` holds the rest of the truth."""

    accel: list[Array]
    mag: list[Array]
    temperature: list[Array]
    session: Session
    truth: ThermalTruth


@dataclass(frozen=True)
class WarmupLog:
    """A continuous warm-up log: ``columns`` with ``temp`` (°C) beside ``t, a*, g*, m*``."""

    columns: dict[str, Array]
    log: ContinuousLog
    truth: ThermalTruth

    def write_csv(self, path: str) -> None:
        names = list(self.columns)
        data = np.column_stack([self.columns[k] for k in names])
        np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.9g")


def _draw(
    rng: np.random.Generator, drift: dict[str, tuple[float, ...]], sensors: tuple[str, ...]
) -> dict[str, Array]:
    return {
        s: np.array([rng.uniform(-h, h, 3) for h in drift.get(s, ())]).reshape(-1, 3)
        for s in sensors
    }


def _warm(t: Array, start: float, span: float, tau: float) -> Array:
    return np.asarray(start + span * (1.0 - np.exp(-t / tau)), dtype=float)


def simulate_warmup(
    *,
    seed: int | None = None,
    n_poses: int = 24,
    span: float = 20.0,
    start: float = 20.0,
    tau: float = 120.0,
    pose_seconds: float = 12.0,
    rate: float = 100.0,
    drift: dict[str, tuple[float, ...]] | None = None,
    preset: str = "paper",
    noise_alpha: tuple[float, float] = (1e-6, 1e-5),
) -> WarmupSession:
    """Simulate per-pose samples of a warm-up session.

    Parameters
    ----------
    seed : int, optional
        Seeds everything (the poses are those of ``simulate(preset, seed=seed)``).
    n_poses : int
        Poses, one every ``pose_seconds``.
    span : float
        ``ΔT``: the warm-up's total rise, K (the log sees less when it ends before it settles).
    start : float
        ``T₀``, °C.
    tau : float
        Warm-up time constant, s.
    pose_seconds, rate : float
        Time from one pose's start to the next's, and the sample rate (Hz).
    drift : dict, optional
        Half-range of each order's coefficient per sensor (default :data:`DRIFT`); ``{}`` or
        zeros give a log with no temperature effect.
    preset : str
        :func:`fieldcal.simulate`'s preset.
    noise_alpha : (low, high)
        The range of Eq. 18's ``α`` (:func:`fieldcal.simulate`): by default a MEMS part's
        noise, about 0.1–0.3 % of the field per sample (the paper's Table 1 draws up to 10 %).
    """
    session = simulate(preset, seed=seed, n_poses=n_poses, noise_alpha=noise_alpha)
    rng = np.random.default_rng(None if seed is None else [seed, 26])
    truth = ThermalTruth(float(start), _draw(rng, DRIFT if drift is None else drift, SENSORS))
    accel, mag, temps = [], [], []
    for i in range(n_poses):
        n = len(session.accel[i])
        t = i * pose_seconds + np.arange(n) / rate
        temp = _warm(t, start, span, tau) + 0.02 * rng.standard_normal(n)  # sensor's LSB noise
        temps.append(temp)
        accel.append(session.accel[i] + truth.drift("accel", temp))
        mag.append(session.mag[i] + truth.drift("mag", temp))
    return WarmupSession(accel, mag, temps, session, truth)


SENSORS = ("accel", "mag", "gyro")


def simulate_warmup_log(
    *,
    seed: int | None = None,
    n_poses: int = 18,
    span: float = 20.0,
    start: float = 20.0,
    tau: float = 60.0,
    drift: dict[str, tuple[float, ...]] | None = None,
    rate: float = 100.0,
) -> WarmupLog:
    """A continuous warm-up log (still poses joined by motion, with a gyroscope) whose
    accelerometer, magnetometer and gyroscope biases drift with the temperature (column
    ``temp``), as :func:`simulate_warmup` draws them."""
    log = simulate_continuous("paper", seed=seed, n_poses=n_poses, rate=rate)
    rng = np.random.default_rng(None if seed is None else [seed, 26])
    truth = ThermalTruth(float(start), _draw(rng, DRIFT if drift is None else drift, SENSORS))
    t = log.columns["t"]
    temp = _warm(t, start, span, tau) + 0.02 * rng.standard_normal(len(t))
    columns = dict(log.columns)
    for prefix, sensor in (("a", "accel"), ("g", "gyro"), ("m", "mag")):
        d = truth.drift(sensor, temp)
        for j, axis in enumerate("xyz"):
            columns[f"{prefix}{axis}"] = columns[f"{prefix}{axis}"] + d[:, j]
    columns["temp"] = temp
    return WarmupLog(columns, log, truth)
