"""A synthetic hand-waved log: accelerometer, magnetometer and gyroscope in continuous motion.

The device tumbles the way a person waves a board to calibrate it (the figure-eight dance of
MotionCal and ArduPilot): a smooth random body-frame angular velocity (a sum of sinusoids per
axis, 0.1–1 Hz), with the hand's linear acceleration (a smooth random position, 0.3–2 Hz) and
optional rests (the rate faded to zero with a raised cosine). Every parameter and the whole
trajectory are known.

Conventions (:mod:`fieldcal.geometry.frames`): world NED, ``R`` maps world to body, the body
turns as ``dR/dt = −[ω]× R``. Readings (raw units)::

    accel = K_a R (a_w / |g| + GRAVITY) |g| + b_a + noise     (specific force)
    mag   = K_m R |h| (cos dip, 0, sin dip) + b_m + noise
    gyro  = K_g ω + b_g + noise                                (rad/s in, raw out)

With ``warmup`` the board warms along ``T(t) = T₀ + (T₁ − T₀)(1 − e^{−3t/seconds})`` (a
``temp`` column, °C) and each sensor's bias given in ``drift`` follows
``b + Σ_k c_k (T − T_ref)^k``, ``T_ref`` the log's mean temperature (:mod:`fieldcal.thermal`).

``K_a``, ``K_m``, ``K_g`` act on the drawn body frame; :attr:`HandwaveLog.truth` is the same in
fieldcal's gauge (:func:`fieldcal.geometry.gauge.canonical_gauge`), with the gyroscope's gain
moved into that frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..calibration import Calibration, SensorCalibration
from ..geometry.frames import GRAVITY, magnetic_reference, orthogonal_polar_factor
from ..geometry.gauge import canonical_gauge
from ..geometry.rotations import exp_so3, ordered_products, random_rotations
from ..thermal import TemperatureModel
from .device import MEMS, MEMS_NOISE_100HZ

__all__ = ["MEMS_FIELD", "HandwaveLog", "simulate_handwave"]

Array = NDArray[np.float64]

#: MEMS-grade field sensors (each uniform in ±value unless a range): accelerometer gain error
#: (scale and cross-axis), bias in |g|, white noise per sample at 100 Hz in |g|; magnetometer
#: gain error (soft iron), bias (hard iron) in |h|, white noise per sample in |h|.
MEMS_FIELD = {
    "accel_gain": 0.03,
    "accel_bias": 0.05,
    "accel_noise": 0.003,
    "mag_gain": 0.10,
    "mag_bias": 0.5,
    "mag_noise": 0.01,
}
#: Oversampling of the true motion between samples (the gyroscope reads the rate at the samples).
_FINE = 8


@dataclass(frozen=True)
class HandwaveLog:
    """A simulated continuous log and its truth.

    Attributes
    ----------
    columns : dict of str to (n,) arrays
        ``t, ax, ay, az, gx, gy, gz, mx, my, mz`` (seconds, raw units).
    truth : Calibration
        Accelerometer, magnetometer and gyroscope truth in fieldcal's gauge (unit fields;
        ``rotations`` is the trajectory at every sample in that gauge; ``gyro`` the
        gyroscope's gain and bias in the gauge's body frame, ``gyro.noise_cov`` its
        per-sample noise).
    rotations : (n, 3, 3) array
        The trajectory as drawn (world to drawn body frame) at each sample.
    body_acceleration : (n, 3) array
        The hand's acceleration in the world frame, units of |g|.
    omega : (n, 3) array
        The true body-frame angular rate (rad/s) in the drawn frame.
    rests : tuple of (start, stop)
        Sample ranges where the device is still.
    rate : float
    gravity, field_strength : float
        ``|g|`` in accelerometer units and ``|h|`` in magnetometer units.
    """

    columns: dict[str, Array]
    truth: Calibration
    rotations: Array
    body_acceleration: Array
    omega: Array
    rests: tuple[tuple[int, int], ...]
    rate: float
    gravity: float
    field_strength: float
    options: dict[str, object] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.columns["t"])

    def write_csv(self, path: str) -> None:
        names = list(self.columns)
        data = np.column_stack([self.columns[k] for k in names])
        np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.9g")


def _smooth(
    rng: np.random.Generator, t: Array, n_terms: int, band: tuple[float, float], rms: float
) -> tuple[Array, Array]:
    """A smooth random 3-vector signal (sum of sinusoids, frequencies in ``band`` Hz) with the
    given RMS per axis, and its second time derivative."""
    f = rng.uniform(*band, (n_terms, 3))
    phase = rng.uniform(0.0, 2.0 * np.pi, (n_terms, 3))
    amp = rng.normal(0.0, 1.0, (n_terms, 3)) * rms * np.sqrt(2.0 / n_terms)
    arg = 2.0 * np.pi * f[None] * t[:, None, None] + phase[None]
    value = np.sum(amp * np.sin(arg), axis=1)
    second = np.sum(-amp * (2.0 * np.pi * f) ** 2 * np.sin(arg), axis=1)
    return value, second


def _envelope(t: Array, rests: list[tuple[float, float]], ramp: float) -> Array:
    """1 while moving, 0 during each rest, raised-cosine ramps of ``ramp`` seconds between."""
    env = np.ones_like(t)
    for start, stop in rests:
        d = np.maximum(start - t, t - stop)  # >0 outside, <0 inside the rest
        part = np.where(d <= 0, 0.0, np.where(d >= ramp, 1.0, 0.5 - 0.5 * np.cos(np.pi * d / ramp)))
        env = np.minimum(env, part)
    return env


def _warmup(
    t: Array,
    warmup: tuple[float, float] | None,
    drift: dict[str, ArrayLike] | None,
    readings: dict[str, Array],
) -> tuple[Array | None, dict[str, TemperatureModel]]:
    """The warm-up's temperatures (module docstring) and each drifting sensor's model; adds
    the drift to ``readings`` in place."""
    if drift and warmup is None:
        raise ValueError("drift needs warmup (the temperatures it follows)")
    if warmup is None:
        return None, {}
    temp = warmup[0] + (warmup[1] - warmup[0]) * (1.0 - np.exp(-3.0 * (t - t[0]) / np.ptp(t)))
    ref, span = float(np.mean(temp)), np.array([temp.min(), temp.max()])
    models: dict[str, TemperatureModel] = {}
    for sensor, coef in (drift or {}).items():
        models[sensor] = TemperatureModel(ref, np.asarray(coef, dtype=float), span)
        readings[sensor] += models[sensor].shift(temp)
    return temp, models


def simulate_handwave(
    *,
    seed: int | None = None,
    seconds: float = 60.0,
    rate: float = 100.0,
    turn_rate: float = 1.5,
    shake: float = 0.05,
    rests: int = 0,
    rest_seconds: float = 3.0,
    axes: tuple[float, float, float] = (1.0, 1.0, 1.0),
    gravity: float = 9.80665,
    field_strength: float = 48.0,
    dip_deg: tuple[float, float] = (-75.0, 75.0),
    noise_scale: float = 1.0,
    gyro_noise: float | None = None,
    warmup: tuple[float, float] | None = None,
    drift: dict[str, ArrayLike] | None = None,
) -> HandwaveLog:
    """Simulate a hand-waved log with known truth.

    Parameters
    ----------
    seed : int, optional
        Seed of every draw.
    seconds, rate : float
        Duration (s) and sample rate (Hz).
    turn_rate : float
        RMS angular rate per axis while moving, rad/s.
    shake : float
        RMS linear acceleration of the hand per axis, units of |g| (0: pure rotation).
    rests : int
        Number of still stretches of ``rest_seconds`` spread over the log.
    axes : (3,) floats
        Scale of the turn rate about each body axis (``(0, 0, 1)``: turns about z only).
    gravity, field_strength : float
        ``|g|`` in the accelerometer's raw units (m/s²), ``|h|`` in the magnetometer's (µT).
    dip_deg : (min, max)
        Range the dip is drawn from.
    noise_scale : float
        Multiplies every white-noise level of :data:`MEMS_FIELD` and the gyroscope's.
    gyro_noise : float, optional
        Gyroscope white noise per sample, rad/s (default: the MEMS part's density at ``rate``).
    warmup : (T₀, T₁), optional
        The die temperature at the start and the one it tends to (°C): adds a ``temp`` column
        (see the module docstring). The other draws are unchanged.
    drift : dict of str to (K, 3) array_like, optional
        Per sensor (``accel``, ``mag``, ``gyro``) the bias's temperature coefficients ``c_k``
        (raw units per K^k) about the log's mean temperature; needs ``warmup``. The truth's
        ``<sensor>.temperature`` holds them.

    Returns
    -------
    HandwaveLog
    """
    if seconds <= 0 or rate <= 0:
        raise ValueError("seconds and rate must be positive")
    rng = np.random.default_rng(seed)
    n = max(2, round(seconds * rate))
    t = np.arange(n) / rate
    fine = np.arange((n - 1) * _FINE + 1) / (rate * _FINE)
    # drawn sensors
    d = _draw_sensors(rng, rate, gravity, field_strength, dip_deg, noise_scale, gyro_noise)
    Ka, ba, Km, bm, dip, sa, sm, Kg, bg, sg = d
    R, omega, env = _motion(rng, fine, seconds, rests, rest_seconds, turn_rate, axes)
    _, acc = _smooth(rng, t, 6, (0.3, 2.0), 1.0)
    # position amplitude chosen so the acceleration has the requested RMS per axis
    acc = acc / max(float(np.sqrt(np.mean(acc**2))), 1e-12) * shake * env[:, None]
    g_world = GRAVITY * gravity
    h_world = magnetic_reference(dip) * field_strength
    f_body = np.einsum("nij,nj->ni", R, acc * gravity + g_world)
    h_body = np.einsum("nij,j->ni", R, h_world)
    accel = f_body @ Ka.T + ba + sa * rng.standard_normal((n, 3))
    mag = h_body @ Km.T + bm + sm * rng.standard_normal((n, 3))
    gyro = omega @ Kg.T + bg + sg * rng.standard_normal((n, 3))
    temp, models = _warmup(t, warmup, drift, {"accel": accel, "mag": mag, "gyro": gyro})
    columns = {"t": t}
    for prefix, data in (("a", accel), ("g", gyro), ("m", mag)):
        for axis, column in zip("xyz", data.T, strict=True):
            columns[f"{prefix}{axis}"] = column
    if temp is not None:
        columns["temp"] = temp
    provenance = {"seed": seed, "seconds": seconds, "rate": rate, "shake": shake}
    truth = _truth(d, R, g_world, h_world, models, provenance)
    return HandwaveLog(
        columns=columns,
        truth=truth,
        rotations=R,
        body_acceleration=acc,
        omega=omega,
        rests=_rest_rows(env),
        rate=float(rate),
        gravity=float(gravity),
        field_strength=float(field_strength),
        options={"turn_rate": turn_rate, "rests": rests, "axes": tuple(axes)},
    )


class _Drawn(NamedTuple):
    """A drawn device: each sensor's gain, bias and noise (std), and the dip (radians)."""

    Ka: Array
    ba: Array
    Km: Array
    bm: Array
    dip: float
    sa: float
    sm: float
    Kg: Array
    bg: Array
    sg: float


def _motion(
    rng: np.random.Generator,
    fine: Array,
    seconds: float,
    rests: int,
    rest_seconds: float,
    turn_rate: float,
    axes: tuple[float, float, float],
) -> tuple[Array, Array, Array]:
    """The hand's turning on the fine time grid, sampled at the log's rate: the rotations
    world → body, the body rates and the envelope (0 at the ``rests`` evenly spaced rests)."""
    stretches: list[tuple[float, float]] = []
    if rests > 0:
        centres = (np.arange(rests) + 0.5) * seconds / rests
        stretches = [(c - rest_seconds / 2, c + rest_seconds / 2) for c in centres]
    env_fine = _envelope(fine, stretches, ramp=0.5)
    w_fine, _ = _smooth(rng, fine, 6, (0.1, 1.0), turn_rate)
    w_fine = w_fine * np.asarray(axes, dtype=float) * env_fine[:, None]
    R0 = random_rotations(1, rng)[0]
    # dR/dt = −[ω]× R, the rate held at the middle of each fine step
    mid = 0.5 * (w_fine[1:] + w_fine[:-1]) * np.diff(fine)[:, None]
    rel = ordered_products(exp_so3(-mid))
    R = np.concatenate([R0[None], rel @ R0])[::_FINE]
    omega = w_fine[::_FINE]
    env = env_fine[::_FINE]
    return R, omega, env


def _rest_rows(env: Array) -> tuple[tuple[int, int], ...]:
    """The rows [start, stop) where the envelope is zero: the rests."""
    still = env < 1e-9
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
    return tuple((int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True))


def _draw_sensors(
    rng: np.random.Generator,
    rate: float,
    gravity: float,
    field_strength: float,
    dip_deg: tuple[float, float],
    noise_scale: float,
    gyro_noise: float | None,
) -> _Drawn:
    """The MEMS device of a hand-waved log (``MEMS_FIELD``, ``MEMS``), drawn in this order."""
    p = MEMS_FIELD
    Ka = np.eye(3) + rng.uniform(-p["accel_gain"], p["accel_gain"], (3, 3))
    ba = rng.uniform(-p["accel_bias"], p["accel_bias"], 3) * gravity
    Km = np.eye(3) + rng.uniform(-p["mag_gain"], p["mag_gain"], (3, 3))
    bm = rng.uniform(-p["mag_bias"], p["mag_bias"], 3) * field_strength
    dip = float(np.radians(rng.uniform(*dip_deg)))
    sa = p["accel_noise"] * np.sqrt(rate / 100.0) * noise_scale * gravity
    sm = p["mag_noise"] * np.sqrt(rate / 100.0) * noise_scale * field_strength
    scale = rng.uniform(-MEMS["scale"], MEMS["scale"], 3)
    cross = rng.uniform(-MEMS["cross_axis"], MEMS["cross_axis"], (3, 3))
    np.fill_diagonal(cross, 0.0)
    mis = rng.uniform(-MEMS["misalignment"], MEMS["misalignment"], 3)
    Kg = (np.eye(3) + np.diag(scale) + cross) @ exp_so3(mis)
    bg = rng.uniform(-MEMS["bias"], MEMS["bias"], 3)
    sg = (MEMS_NOISE_100HZ * np.sqrt(rate / 100.0) if gyro_noise is None else gyro_noise) * (
        noise_scale if gyro_noise is None else 1.0
    )
    return _Drawn(Ka, ba, Km, bm, dip, float(sa), float(sm), Kg, bg, float(sg))


def _truth(
    d: _Drawn,
    R: Array,
    g_world: Array,
    h_world: Array,
    models: dict[str, TemperatureModel],
    options: dict[str, Any],
) -> Calibration:
    """The drawn device in fieldcal's gauge (:func:`fieldcal.geometry.gauge.canonical_gauge`):
    what a calibration of the log should find."""
    Rc, Ka_c, Km_c, g_c, h_c = canonical_gauge(R, d.Ka, d.Km, g_world, h_world)
    U = orthogonal_polar_factor(d.Ka)  # ω_gauge = U ω_drawn
    return Calibration(
        accel=SensorCalibration(
            gain=Ka_c, bias=d.ba, noise_cov=d.sa**2 * np.eye(3), temperature=models.get("accel")
        ),
        mag=SensorCalibration(
            gain=Km_c, bias=d.bm, noise_cov=d.sm**2 * np.eye(3), temperature=models.get("mag")
        ),
        gravity=g_c,
        magnetic=h_c,
        rotations=Rc,
        method="truth",
        gyro=SensorCalibration(
            gain=d.Kg @ U.T,
            bias=d.bg,
            noise_cov=d.sg**2 * np.eye(3),
            temperature=models.get("gyro"),
        ),
        options=options,
    )
