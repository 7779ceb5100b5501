"""An independent hand-held test bed: a rigid body turned in the hand, with the physics of a turn.

The continuous estimator is checked against logs it did not make: this module shares nothing
with :mod:`fieldcal.methods.continuous` (only the frame conventions of
:mod:`fieldcal.geometry.frames` and the rotation helpers). A hand-held device

- **turns** with a smooth random body-frame angular velocity ``ω(t)`` (a sum of sinusoids per
  axis, 0.1–1.5 Hz, scaled so its largest norm over the log is ``max_rate``, up to 20 rad/s as
  on BROAD's fast trials), with its analytic derivative ``ω̇(t)``;
- about a **turning point** (the wrist) at ``p(t)``, a bounded smooth random position (sum of
  sinusoids, 0.1–1 Hz, scaled to ``translation_rms`` m/s² of acceleration, shrunk if it would
  leave a ball of ``max_excursion`` m), the hand's own translation;
- carrying the sensors at the **lever arm** ``r`` (body frame, metres) from that point;
- optionally **resting**: the rate and the translation faded to zero with raised cosines.

Frames (docs/conventions.md): world North-East-Down, ``R`` maps world to body, the body turns as
``dR/dt = −[ω]× R``. The sensor sits at ``p + Rᵀ r``; differentiating twice
(``d(Rᵀ)/dt = Rᵀ [ω]×``) its acceleration is ``p̈ + Rᵀ (ω̇ × r + ω × (ω × r))``, so the specific
force in the body frame is::

    f = R (p̈ − g_w) + ω̇ × r + ω × (ω × r),      −g_w = GRAVITY |g| = (0, 0, −|g|)

(at rest the accelerometer reads "up"). The readings, raw units::

    accel = K_a f + b_a + noise                  (m/s² scale)
    mag   = K_m R |h| (cos dip, 0, sin dip) + b_m + noise   (µT scale; soft and hard iron)
    gyro  = K_g ω̃ + b_g + noise                  (rad/s scale)

``ω̃`` is the rate at the sample instant (``gyro_sampling="instant"``) or its mean over the
interval that follows the sample, ``[t_k, t_k + 1/rate)`` (``"mean"``, the convention of a
gyroscope that reports the turn since its last output, fieldcal's ``hold="previous"``).

The orientation is integrated on a fine grid (``internal_rate``, 1 kHz by default, a whole
multiple of the sample rate) with the fourth-order Magnus step of two Gauss points, so the
trajectory is the integral of the rate to far below the gyroscope's noise; the samples are the
fine grid's every ``k``-th point. Everything the readings are made from is returned.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration, SensorCalibration
from ..geometry.frames import GRAVITY, magnetic_reference, orthogonal_polar_factor
from ..geometry.gauge import canonical_gauge
from ..geometry.rotations import exp_so3, ordered_products, random_rotations
from .device import MEMS, MEMS_NOISE_100HZ
from .handwave import MEMS_FIELD

__all__ = ["GYRO_SAMPLING", "HandheldLog", "simulate_handheld"]

Array = NDArray[np.float64]

#: The gyroscope sampling conventions :func:`simulate_handheld` can make.
GYRO_SAMPLING = ("instant", "mean")

#: Frequency bands (Hz) of the turning rate and of the hand's translation.
_TURN_BAND = (0.1, 1.5)
_MOVE_BAND = (0.1, 1.0)
_TERMS = 6
#: Raised-cosine ramp (s) into and out of a rest.
_RAMP = 0.5


@dataclass(frozen=True)
class HandheldLog:
    """A simulated hand-held log and everything it was made from.

    Attributes
    ----------
    columns : dict of str to (n,) arrays
        ``t, ax, ay, az, gx, gy, gz, mx, my, mz`` (s, m/s², rad/s, µT scale), plus ``temp``
        (°C) when a warm-up was asked for. :func:`fieldcal.calibrate_log` takes it as is.
    truth : Calibration
        Accelerometer, magnetometer and gyroscope in fieldcal's gauge (unit fields, the
        accelerometer's gain symmetric; ``rotations`` the trajectory at every sample in that
        gauge; ``gyro.gain`` moved into the gauge's body frame; noise covariances per sample).
    accel_gain, accel_bias, mag_gain, mag_bias, gyro_gain, gyro_bias : arrays
        The sensors as drawn, acting on the drawn body frame (raw units per m/s², µT, rad/s).
    dip_deg : float
        The field's dip (positive below the horizon).
    lever_arm : (3,) array
        ``r``, the sensor's offset from the turning point in the drawn body frame, metres.
    lever_arm_gauge : (3,) array
        The same in fieldcal's body frame (``U r``, ``U`` the accelerometer gain's polar factor).
    rotations : (n, 3, 3) array
        World → drawn body frame at each sample.
    position, velocity, acceleration : (n, 3) arrays
        The turning point in the world frame (m, m/s, m/s²).
    omega, omega_dot : (n, 3) arrays
        Body-frame angular rate (rad/s) at each sample instant and its derivative (rad/s²).
    omega_read : (n, 3) array
        What the gyroscope was given before gain, bias and noise (instant or interval mean).
    specific_force : (n, 3) array
        ``f`` above (m/s², drawn body frame), before gain, bias and noise.
    rests : tuple of (start, stop)
        Sample ranges where the device is still.
    rate, gravity, field_strength : float
        Hz, ``|g|`` (m/s²), ``|h|`` (µT).
    options : dict
        The arguments the log was made with.
    """

    columns: dict[str, Array]
    truth: Calibration
    accel_gain: Array
    accel_bias: Array
    mag_gain: Array
    mag_bias: Array
    gyro_gain: Array
    gyro_bias: Array
    dip_deg: float
    lever_arm: Array
    lever_arm_gauge: Array
    rotations: Array
    position: Array
    velocity: Array
    acceleration: Array
    omega: Array
    omega_dot: Array
    omega_read: Array
    specific_force: Array
    rests: tuple[tuple[int, int], ...]
    rate: float
    gravity: float
    field_strength: float
    options: dict[str, object] = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of samples."""
        return len(self.columns["t"])


class _Sinusoids:
    """A smooth random 3-vector signal ``Σ_k a_k sin(2π f_k t + φ_k)`` per axis, with exact
    derivatives (order 0, 1, 2)."""

    def __init__(self, rng: np.random.Generator, band: tuple[float, float]) -> None:
        self.f = rng.uniform(*band, (_TERMS, 3))
        self.phase = rng.uniform(0.0, 2.0 * np.pi, (_TERMS, 3))
        self.amp = rng.normal(0.0, 1.0, (_TERMS, 3)) * np.sqrt(2.0 / _TERMS)

    def __call__(self, t: Array, order: int = 0) -> Array:
        w = 2.0 * np.pi * self.f
        arg = w[None] * t[:, None, None] + self.phase[None] + order * np.pi / 2
        return np.asarray(np.sum(self.amp * w**order * np.sin(arg), axis=1))


class _Envelope:
    """1 while moving, 0 in each rest, raised-cosine ramps of ``_RAMP`` s; value and the first
    two derivatives (the ramps are ``½ − ½ cos(π d/ramp)`` in the distance ``d`` to the rest)."""

    def __init__(self, rests: list[tuple[float, float]]) -> None:
        self.rests = rests

    def __call__(self, t: Array) -> tuple[Array, Array, Array]:
        value, first, second = np.ones_like(t), np.zeros_like(t), np.zeros_like(t)
        k = np.pi / _RAMP
        for start, stop in self.rests:
            before, after = start - t, t - stop
            d = np.maximum(before, after)  # >0 outside, ≤0 inside the rest
            dd = np.where(before > after, -1.0, 1.0)  # d's derivative in t
            inside, ramp = d <= 0, (d > 0) & (d < _RAMP)
            v = np.where(inside, 0.0, np.where(ramp, 0.5 - 0.5 * np.cos(k * d), 1.0))
            v1 = np.where(ramp, 0.5 * k * np.sin(k * d) * dd, 0.0)
            v2 = np.where(ramp, 0.5 * k * k * np.cos(k * d), 0.0)
            lower = v < value  # rests do not overlap: the smaller factor wins
            value = np.where(lower, v, value)
            first = np.where(lower, v1, first)
            second = np.where(lower, v2, second)
        return value, first, second


def _magnus(t: Array, omega: _Sinusoids, envelope: _Envelope, scale: float) -> Array:
    """Rotation vectors ``φ_k`` with ``R(t_{k+1}) = Exp(−φ_k) R(t_k)`` for ``dR/dt = −[ω]× R``:
    the fourth-order Magnus step with two Gauss points ``ω₁, ω₂``:
    ``φ = h/2 (ω₁ + ω₂) − (√3 h²/12) ω₂ × ω₁`` (``[−[ω₂]×, −[ω₁]×] = [ω₂ × ω₁]×``)."""
    h = np.diff(t)
    c = np.sqrt(3.0) / 6.0
    t1, t2 = t[:-1] + (0.5 - c) * h, t[:-1] + (0.5 + c) * h
    w1 = omega(t1) * envelope(t1)[0][:, None] * scale
    w2 = omega(t2) * envelope(t2)[0][:, None] * scale
    return np.asarray(
        0.5 * h[:, None] * (w1 + w2) - np.sqrt(3.0) / 12.0 * h[:, None] ** 2 * np.cross(w2, w1)
    )


def _draw_sensors(
    rng: np.random.Generator, gravity: float, field_strength: float
) -> dict[str, Array]:
    """MEMS-grade gains and biases (:data:`~fieldcal.simulation.handwave.MEMS_FIELD`,
    :data:`~fieldcal.simulation.device.MEMS`), drawn body frame, raw units."""
    p = MEMS_FIELD
    scale = rng.uniform(-MEMS["scale"], MEMS["scale"], 3)
    cross = rng.uniform(-MEMS["cross_axis"], MEMS["cross_axis"], (3, 3))
    np.fill_diagonal(cross, 0.0)
    mis = rng.uniform(-MEMS["misalignment"], MEMS["misalignment"], 3)
    return {
        "Ka": np.eye(3) + rng.uniform(-p["accel_gain"], p["accel_gain"], (3, 3)),
        "ba": rng.uniform(-p["accel_bias"], p["accel_bias"], 3) * gravity,
        "Km": np.eye(3) + rng.uniform(-p["mag_gain"], p["mag_gain"], (3, 3)),
        "bm": rng.uniform(-p["mag_bias"], p["mag_bias"], 3) * field_strength,
        "Kg": (np.eye(3) + np.diag(scale) + cross) @ exp_so3(mis),
        "bg": rng.uniform(-MEMS["bias"], MEMS["bias"], 3),
    }


def _lever(rng: np.random.Generator, lever_arm: float | tuple[float, float] | Array) -> Array:
    """A lever arm (m): a given vector, or a random direction with a length given or drawn
    uniformly from a (min, max) range."""
    arm = np.asarray(lever_arm, dtype=float)
    if arm.shape == (3,):
        return arm
    length = float(rng.uniform(*arm)) if arm.shape == (2,) else float(arm)
    direction = rng.standard_normal(3)
    return np.asarray(length * direction / np.linalg.norm(direction))


def _rest_intervals(seconds: float, rests: int, rest_seconds: float) -> list[tuple[float, float]]:
    if rests <= 0:
        return []
    centres = (np.arange(rests) + 0.5) * seconds / rests
    return [(c - rest_seconds / 2, c + rest_seconds / 2) for c in centres]


def _turning(
    t: Array,
    rate: float,
    fine_k: int,
    turn: _Sinusoids,
    envelope: _Envelope,
    max_rate: float,
    R0: Array,
    gyro_sampling: str,
) -> tuple[Array, Array, Array, Array]:
    """The trajectory at the samples ``t``, the rate and its derivative there, and what the
    gyroscope reads of the rate (instant, or the mean over the interval that follows)."""
    n = len(t)
    fine = np.arange((n - 1) * fine_k + 1) / (rate * fine_k)
    # scaled so the peak norm is max_rate, found on a 1 kHz grid of its own so that the scale,
    # and with it the motion, does not depend on the integration grid
    grid = np.linspace(0.0, fine[-1], max(2, round(fine[-1] * 1000.0) + 1))
    peak = float(np.max(np.linalg.norm(turn(grid) * envelope(grid)[0][:, None], axis=1)))
    w_scale = max_rate / peak if peak > 0 else 0.0
    steps = exp_so3(-_magnus(fine, turn, envelope, w_scale))
    R = np.concatenate([R0[None], ordered_products(steps) @ R0])[::fine_k]
    env, env1, _ = envelope(t)
    omega = turn(t) * env[:, None] * w_scale
    omega_dot = (turn(t, 1) * env[:, None] + turn(t) * env1[:, None]) * w_scale
    if gyro_sampling == "instant":
        return R, omega, omega_dot, omega
    # the mean over [t_k, t_{k+1}): trapezoid on the fine grid (the last sample: instant)
    w_f = turn(fine) * envelope(fine)[0][:, None] * w_scale
    seg = 0.5 * (w_f[1:] + w_f[:-1])
    means = seg.reshape(n - 1, fine_k, 3).mean(axis=1)
    return R, omega, omega_dot, np.vstack([means, omega[-1:]])


def _translation(
    t: Array,
    rate: float,
    fine_k: int,
    move: _Sinusoids,
    envelope: _Envelope,
    translation_rms: float,
    max_excursion: float,
) -> tuple[Array, Array, Array]:
    """The turning point's position, velocity and acceleration at ``t`` (world, m):
    ``p = e(t) q(t)`` with ``q`` scaled to ``translation_rms`` while moving, shrunk to stay
    within ``max_excursion`` of its mean."""
    fine = np.arange((len(t) - 1) * fine_k + 1) / (rate * fine_k)
    env_f = envelope(fine)[0]
    moving = env_f > 0.999
    a_f = move(fine, 2)
    rms = float(np.sqrt(np.mean(np.sum(a_f[moving] ** 2, axis=1)))) if moving.any() else 1.0
    scale = translation_rms / rms
    q_f = move(fine) * env_f[:, None]
    centre = np.mean(q_f, axis=0)
    reach = float(np.max(np.linalg.norm(q_f - centre, axis=1))) * scale
    if reach > max_excursion:
        scale *= max_excursion / reach
    e0, e1, e2 = envelope(t)
    q0, q1, q2 = (move(t, k) * scale for k in range(3))
    position = e0[:, None] * q0 - centre * scale
    velocity = e1[:, None] * q0 + e0[:, None] * q1
    acceleration = e2[:, None] * q0 + 2.0 * e1[:, None] * q1 + e0[:, None] * q2
    return position, velocity, acceleration


def _truth(
    R: Array,
    s: dict[str, Array],
    g_world: Array,
    h_world: Array,
    noise: dict[str, float],
    options: dict[str, object],
) -> tuple[Calibration, Array]:
    """The drawn sensors in fieldcal's gauge, and the rotation ``U`` from the drawn body frame
    to the gauge's (``ω_gauge = U ω_drawn``)."""
    Rc, Ka_c, Km_c, g_c, h_c = canonical_gauge(R, s["Ka"], s["Km"], g_world, h_world)
    U = orthogonal_polar_factor(s["Ka"])
    eye = np.eye(3)
    truth = Calibration(
        accel=SensorCalibration(gain=Ka_c, bias=s["ba"], noise_cov=noise["accel"] ** 2 * eye),
        mag=SensorCalibration(gain=Km_c, bias=s["bm"], noise_cov=noise["mag"] ** 2 * eye),
        gravity=g_c,
        magnetic=h_c,
        rotations=Rc,
        method="truth",
        gyro=SensorCalibration(
            gain=s["Kg"] @ U.T, bias=s["bg"], noise_cov=noise["gyro"] ** 2 * eye
        ),
        options=options,
    )
    return truth, U


def _check(
    seconds: float,
    rate: float,
    internal_rate: float,
    gyro_sampling: str,
    max_rate: float,
    translation_rms: float,
    max_excursion: float,
) -> None:
    """:func:`simulate_handheld`'s arguments, or a ValueError naming the wrong one."""
    if seconds <= 0 or rate <= 0 or internal_rate <= 0:
        raise ValueError("seconds, rate and internal_rate must be positive")
    if gyro_sampling not in GYRO_SAMPLING:
        raise ValueError(f"gyro_sampling must be one of {', '.join(GYRO_SAMPLING)}")
    if max_rate < 0 or translation_rms < 0 or max_excursion <= 0:
        raise ValueError("max_rate and translation_rms must be ≥ 0, max_excursion > 0")


def _specific_force(R: Array, world: Array, omega: Array, omega_dot: Array, r: Array) -> Array:
    """The specific force in the body frame (module docstring): the turning point's
    acceleration less gravity (``world``, rotated in), tangential and centripetal terms."""
    out: Array = (
        np.einsum("nij,nj->ni", R, world)
        + np.cross(omega_dot, r)
        + np.cross(omega, np.cross(omega, r))
    )
    return out


def _noise_levels(
    rate: float, noise_scale: float, gravity: float, field_strength: float
) -> dict[str, float]:
    """White-noise standard deviations per sample: MEMS densities at 100 Hz, scaled to
    ``rate``."""
    root = np.sqrt(rate / 100.0) * noise_scale
    return {
        "accel": float(MEMS_FIELD["accel_noise"] * gravity * root),
        "mag": float(MEMS_FIELD["mag_noise"] * field_strength * root),
        "gyro": float(MEMS_NOISE_100HZ * root),
    }


def _readings(
    rng: np.random.Generator,
    s: dict[str, Array],
    noise: dict[str, float],
    force: Array,
    field: Array,
    omega_read: Array,
) -> dict[str, Array]:
    """Raw readings (``a``, ``m``, ``g``: (n, 3)) from the body-frame specific force, field and
    rates through the drawn sensors, with white noise."""
    n = len(force)
    return {
        "a": force @ s["Ka"].T + s["ba"] + noise["accel"] * rng.standard_normal((n, 3)),
        "m": field @ s["Km"].T + s["bm"] + noise["mag"] * rng.standard_normal((n, 3)),
        "g": omega_read @ s["Kg"].T + s["bg"] + noise["gyro"] * rng.standard_normal((n, 3)),
    }


def _columns(
    t: Array, readings: dict[str, Array], temperature: tuple[float, float] | None, seconds: float
) -> dict[str, Array]:
    """The log's columns (``t``, ``ax``…``mz``, and ``temp`` warming from T₀ towards T₁)."""
    columns: dict[str, Array] = {"t": t}
    for prefix in "agm":
        for axis, column in zip("xyz", readings[prefix].T, strict=True):
            columns[f"{prefix}{axis}"] = np.ascontiguousarray(column)
    if temperature is not None:
        t0, t1 = temperature
        columns["temp"] = t0 + (t1 - t0) * (1.0 - np.exp(-3.0 * t / max(seconds, 1e-9)))
    return columns


def _rest_rows(still: NDArray[np.bool_]) -> tuple[tuple[int, int], ...]:
    """The still stretches as (first row, row after the last)."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
    return tuple((int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True))


def simulate_handheld(
    seed: int | None = None,
    *,
    seconds: float = 60.0,
    rate: float = 100.0,
    lever_arm: float | tuple[float, float] | Array = (0.03, 0.15),
    max_rate: float = 10.0,
    translation_rms: float = 0.5,
    max_excursion: float = 1.0,
    rests: int = 0,
    rest_seconds: float = 3.0,
    gyro_sampling: str = "instant",
    internal_rate: float = 1000.0,
    gravity: float = 9.80665,
    field_strength: float = 48.0,
    dip_deg: tuple[float, float] = (-75.0, 75.0),
    noise_scale: float = 1.0,
    temperature: tuple[float, float] | None = None,
) -> HandheldLog:
    """Simulate a hand-held log with the physics of a turn (module docstring) and its truth.

    Parameters
    ----------
    seed : int, optional
        Seed of every draw.
    seconds, rate : float
        Duration (s) and sample rate (Hz).
    lever_arm : float, (min, max) or (3,) array
        The sensor's offset from the turning point, m: a length (random direction), a range
        the length is drawn from (default 3–15 cm), or the vector in the drawn body frame.
    max_rate : float
        The largest angular rate over the log, rad/s (the rate process is scaled to it).
    translation_rms : float
        RMS norm of the turning point's acceleration while moving, m/s² (0: the point is fixed).
    max_excursion : float
        The turning point stays within this distance (m) of its mean position.
    rests : int
        Number of still stretches of ``rest_seconds`` spread evenly over the log.
    gyro_sampling : {"instant", "mean"}
        The rate at the sample instant, or its mean over the interval that follows it.
    internal_rate : float
        Rate of the fine integration grid, Hz (rounded to a whole multiple of ``rate``).
    gravity, field_strength : float
        ``|g|`` (m/s²) and ``|h|`` (µT).
    dip_deg : (min, max)
        Range the dip is drawn from.
    noise_scale : float
        Multiplies every white-noise level (MEMS defaults at 100 Hz, the same densities at
        other rates).
    temperature : (T₀, T₁), optional
        Adds a ``temp`` column warming from T₀ towards T₁ (°C); the biases do not drift.

    Returns
    -------
    HandheldLog
    """
    _check(seconds, rate, internal_rate, gyro_sampling, max_rate, translation_rms, max_excursion)
    rng = np.random.default_rng(seed)
    fine_k = max(1, round(internal_rate / rate))
    n = max(2, round(seconds * rate))
    t = np.arange(n) / rate
    s = _draw_sensors(rng, gravity, field_strength)
    dip = float(rng.uniform(*dip_deg))
    r = _lever(rng, lever_arm)
    envelope = _Envelope(_rest_intervals(seconds, rests, rest_seconds))
    turn = _Sinusoids(rng, _TURN_BAND)
    move = _Sinusoids(rng, _MOVE_BAND)
    R0 = random_rotations(1, rng)[0]

    R, omega, omega_dot, omega_read = _turning(
        t, rate, fine_k, turn, envelope, max_rate, R0, gyro_sampling
    )
    position, velocity, acceleration = _translation(
        t, rate, fine_k, move, envelope, translation_rms, max_excursion
    )
    g_world = GRAVITY * gravity
    f = _specific_force(R, acceleration + g_world, omega, omega_dot, r)
    h_world = magnetic_reference(np.radians(dip)) * field_strength
    noise = _noise_levels(rate, noise_scale, gravity, field_strength)
    columns = _columns(
        t, _readings(rng, s, noise, f, R @ h_world, omega_read), temperature, seconds
    )
    truth, U = _truth(
        R, s, g_world, h_world, noise, {"seed": seed, "seconds": seconds, "rate": rate}
    )
    options: dict[str, object] = {
        "seed": seed,
        "seconds": seconds,
        "rate": rate,
        "max_rate": max_rate,
        "translation_rms": translation_rms,
        "rests": rests,
        "gyro_sampling": gyro_sampling,
        "internal_rate": rate * fine_k,
    }
    motion = (R, position, velocity, acceleration, omega, omega_dot, omega_read, f)
    still = envelope(t)[0] < 1e-12
    scales = (float(rate), float(gravity), float(field_strength))
    return _handheld_log(columns, truth, s, (dip, r, U), motion, still, scales, options)


def _handheld_log(
    columns: dict[str, Array],
    truth: Calibration,
    s: dict[str, Array],
    frame: tuple[float, Array, Array],
    motion: tuple[Array, ...],
    still: NDArray[np.bool_],
    scales: tuple[float, float, float],
    options: dict[str, object],
) -> HandheldLog:
    """The log and its truth: the sensors ``s``, the dip, lever arm and gauge rotation
    (``frame``), the motion (rotations, position, velocity, acceleration, rates, their
    derivative and readings, specific force), the still rows, the rate, ``|g|`` and ``|h|``."""
    dip, r, U = frame
    R, position, velocity, acceleration, omega, omega_dot, omega_read, f = motion
    return HandheldLog(
        columns=columns,
        truth=truth,
        accel_gain=s["Ka"],
        accel_bias=s["ba"],
        mag_gain=s["Km"],
        mag_bias=s["bm"],
        gyro_gain=s["Kg"],
        gyro_bias=s["bg"],
        dip_deg=dip,
        lever_arm=r,
        lever_arm_gauge=U @ r,
        rotations=R,
        position=position,
        velocity=velocity,
        acceleration=acceleration,
        omega=omega,
        omega_dot=omega_dot,
        omega_read=omega_read,
        specific_force=f,
        rests=_rest_rows(still),
        rate=scales[0],
        gravity=scales[1],
        field_strength=scales[2],
        options=options,
    )
