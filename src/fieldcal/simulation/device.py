"""A simulated IMU board: still samples at a rotation, motion samples between two rotations.

:class:`Device` draws its truth with :func:`fieldcal.simulate` (gains, biases, fields and noise
covariances of the preset) and then produces samples on demand, as a board held by a user
would: a time column at ``rate``, the raw accelerometer ``K_a R g + b_a + noise``, the raw
magnetometer ``K_m R h + b_m + noise`` and a gyroscope ``K_g ω + b_g(t) + noise`` with a drawn
truth (:class:`GyroTruth`, :func:`draw_gyro`: a realistic MEMS part by default, an ideal one on
request). Between two rotations the board turns along the geodesic of SO(3) with a
raised-cosine speed (at rest at both ends), shaken a little (a linear acceleration of up to
``shake`` |g|), and the gyroscope reads the body-frame turn rate.

Rotations are world (NED) to body, ``v_body = R v_world`` (docs/conventions.md), the body
being the frame the drawn gains act in (the sensors' raw axes). The gyroscope reads the
angular velocity ``ω`` of the body in the body frame: ``dR/dt = -[ω]× R``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Unpack

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._frozen import ArrayDataclass, frozen_array
from ..calibration import Calibration
from ..geometry.frames import orthogonal_polar_factor
from ..geometry.rotations import exp_so3, log_so3
from .session import Drawn, Preset, Session, simulate

__all__ = ["COLUMNS", "GYRO_STREAM", "Device", "GyroTruth", "Samples", "draw_gyro", "geodesic"]

Array = NDArray[np.float64]

#: Column names of :meth:`Samples.columns`, in order.
COLUMNS = ("t", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz")

#: The gyroscope's truth is drawn from ``default_rng([seed, GYRO_STREAM])``, a stream of its
#: own: the other sensors' samples of a seed do not change with it, and a seed gives the same
#: gyroscope in :func:`~fieldcal.simulation.continuous.simulate_continuous` and :class:`Device`.
GYRO_STREAM = 4

#: The realistic MEMS gyroscope :func:`draw_gyro` draws by default (each uniform in ±value):
#: scale error, cross-axis coupling, misalignment to the body frame (radians, per axis of a
#: small rotation), bias (rad/s); and the white noise of one sample at 100 Hz (rad/s).
MEMS = {"scale": 0.03, "cross_axis": 0.01, "misalignment": np.radians(1.0), "bias": 0.02}
MEMS_NOISE_100HZ = 0.005


@dataclass(frozen=True, eq=False)
class GyroTruth(ArrayDataclass):
    """A simulated gyroscope: ``raw = gain @ ω + bias + drift · t + noise``.

    ``ω`` is the body-frame angular rate in rad/s (``dR/dt = −[ω]× R``) in the frame named by
    ``frame``: ``"drawn"`` the frame the session's drawn gains act in (the sensors' own axes:
    the samples are made there), ``"gauge"`` fieldcal's body frame (the accelerometer's gain
    symmetric, :func:`fieldcal.geometry.gauge.canonical_gauge`), where an estimate from a
    calibration's rotations lives. The two differ by the rotation ``U`` of the accelerometer's
    polar decomposition: ``ω_gauge = U ω_drawn``, ``gain_gauge = gain_drawn Uᵀ``.

    Attributes
    ----------
    gain : (3, 3) array
        Raw units per rad/s (scale, cross-axis coupling, misalignment).
    bias : (3,) array
        Raw units, at ``t = 0``.
    noise_std : float
        Standard deviation of one sample's white noise, raw units, each axis.
    drift : (3,) array
        Change of the bias per second, raw units/s (zeros: a constant bias).
    frame : str
        ``"drawn"`` or ``"gauge"`` (above).
    """

    gain: Array
    bias: Array
    noise_std: float
    drift: Array
    frame: str = "drawn"

    def __post_init__(self) -> None:
        object.__setattr__(self, "gain", frozen_array(self.gain))
        object.__setattr__(self, "bias", frozen_array(self.bias))
        object.__setattr__(self, "drift", frozen_array(self.drift))
        object.__setattr__(self, "noise_std", float(self.noise_std))

    def bias_at(self, t: ArrayLike) -> Array:
        """The bias (..., 3) at times ``t`` (s)."""
        out: Array = self.bias + np.asarray(t, dtype=float)[..., None] * self.drift
        return out

    def read(self, t: ArrayLike, omega: ArrayLike, normals: ArrayLike) -> Array:
        """Raw readings (n, 3) of body-frame rates ``omega`` (n, 3) at times ``t``, with the
        noise made from standard normals (n, 3)."""
        w = np.asarray(omega, dtype=float)
        out: Array = w @ self.gain.T + self.bias_at(t) + self.noise_std * np.asarray(normals)
        return out

    def in_gauge(self, drawn: Drawn) -> GyroTruth:
        """This truth in fieldcal's body frame for a session drawn as ``drawn``."""
        if self.frame == "gauge":
            return self
        U = orthogonal_polar_factor(np.asarray(drawn["accel_gain"], dtype=float))
        return GyroTruth(self.gain @ U.T, self.bias, self.noise_std, self.drift, "gauge")


def draw_gyro(
    rng: np.random.Generator,
    *,
    rate: float = 100.0,
    ideal: bool = False,
    noise: float | None = None,
    drift: float = 0.0,
) -> GyroTruth:
    """Draw a gyroscope's truth (in the drawn frame, :class:`GyroTruth`).

    Parameters
    ----------
    rng : numpy.random.Generator
        The gyroscope's own stream (``default_rng([seed, GYRO_STREAM])``).
    rate : float
        Samples per second: the default noise keeps the density of :data:`MEMS_NOISE_100HZ`
        at 100 Hz (``0.005 · sqrt(rate / 100)`` rad/s per sample).
    ideal : bool
        Identity gain and zero bias (and no drift); the noise as given or the default.
    noise : float, optional
        Standard deviation of one sample's white noise (rad/s) instead of the default.
    drift : float
        Half-range of the bias drift drawn per axis, rad/s per second (0: constant bias).

    Returns
    -------
    GyroTruth
        Default (realistic MEMS): ``gain = (I + S + C) exp([m]×)`` with the scale errors ``S``
        (diagonal, ±3 %), cross-axis couplings ``C`` (off-diagonal, ±1 %) and a misalignment
        ``m`` (±1° per axis); bias ±0.02 rad/s per axis.
    """
    # every draw is made (ideal or not) so a seed gives the same noise stream either way
    scale = rng.uniform(-MEMS["scale"], MEMS["scale"], 3)
    cross = rng.uniform(-MEMS["cross_axis"], MEMS["cross_axis"], (3, 3))
    angles = rng.uniform(-MEMS["misalignment"], MEMS["misalignment"], 3)
    bias = rng.uniform(-MEMS["bias"], MEMS["bias"], 3)
    slope = rng.uniform(-1.0, 1.0, 3) * float(drift)
    std = MEMS_NOISE_100HZ * np.sqrt(float(rate) / 100.0) if noise is None else float(noise)
    if ideal:
        return GyroTruth(np.eye(3), np.zeros(3), std, np.zeros(3))
    np.fill_diagonal(cross, 0.0)
    gain = (np.eye(3) + np.diag(scale) + cross) @ exp_so3(angles)
    return GyroTruth(gain, bias, std, slope)


def geodesic(start: Array, stop: Array, m: int, rate: float) -> tuple[Array, Array]:
    """A turn from ``start`` to ``stop`` in ``m`` samples at ``rate`` Hz: geodesic on SO(3),
    raised-cosine speed (at rest at both ends), sampled at the middle of each step.

    Parameters
    ----------
    start, stop : (3, 3) arrays
        World-to-body rotations.
    m : int
        Samples.
    rate : float
        Samples per second.

    Returns
    -------
    rotations : (m, 3, 3) array
        World-to-body rotation at each sample.
    omega : (m, 3) array
        Body-frame angular velocity (rad/s) at each sample, the gyroscope's noise-free
        reading: ``dR/dt = -[ω]× R``.
    """
    u = (np.arange(m) + 0.5) / m
    s = 0.5 - 0.5 * np.cos(np.pi * u)  # raised cosine: starts and stops at rest
    phi = log_so3(stop @ start.T)  # the turn from start to stop, about body-frame axes
    rotations = exp_so3(s[:, None] * phi) @ start
    duration = m / rate
    # R(t) = exp(s(t) φ) R_0, so dR/dt = ṡ [φ]× R and ω = -ṡ φ
    omega = -((0.5 * np.pi * np.sin(np.pi * u) / duration)[:, None] * phi)
    return rotations, omega


@dataclass(frozen=True)
class Samples:
    """Rows of a simulated board: time (s), raw accelerometer, gyroscope (rad/s), raw
    magnetometer, and the true world-to-body rotation of each row."""

    t: Array
    accel: Array
    gyro: Array
    mag: Array
    rotations: Array

    @property
    def n(self) -> int:
        """Rows."""
        return len(self.t)

    def columns(self) -> dict[str, Array]:
        """Columns ``t, ax, ay, az, gx, gy, gz, mx, my, mz`` (:data:`COLUMNS`)."""
        out = {"t": self.t}
        for prefix, data in (("a", self.accel), ("g", self.gyro), ("m", self.mag)):
            for axis, column in zip("xyz", data.T, strict=True):
                out[prefix + axis] = column
        return out


class Device:
    """A simulated board with a drawn truth (see the module's docstring).

    Parameters
    ----------
    preset : str
        A preset of :func:`fieldcal.simulate` (``"paper"``: Table 1), drawn with ``seed``.
    seed : int, optional
        Seeds the truth (as :func:`fieldcal.simulate`) and, through a separate stream, the
        samples: a seed and a sequence of calls give the same rows every time.
    rate : float
        Samples per second.
    shake : float
        Largest linear acceleration while moving, in units of |g|.
    gyro_noise : float, optional
        Standard deviation of the gyroscope's white noise, rad/s (default: the MEMS part's,
        0.005 rad/s at 100 Hz, :func:`draw_gyro`).
    ideal_gyro : bool
        An ideal gyroscope (identity gain, zero bias) instead of the drawn MEMS part.
    gyro_drift : float
        Half-range of the gyroscope's bias drift per axis, rad/s per second (default none).
    **options
        Other keywords of :func:`fieldcal.simulate` (``noise_alpha``, ``dip_deg`` ...).

    Attributes
    ----------
    session : Session
        The draw: ``session.truth`` is the truth in fieldcal's gauge (its ``rotations`` are
        the draw's poses, not the ones this device is put in); ``session.drawn`` the
        parameters as drawn, which the samples use.
    gyro_drawn : GyroTruth
        The gyroscope as drawn (the samples' frame); :attr:`gyro_truth` in fieldcal's gauge.
    """

    def __init__(
        self,
        preset: str = "paper",
        *,
        seed: int | None = None,
        rate: float = 100.0,
        shake: float = 0.05,
        gyro_noise: float | None = None,
        ideal_gyro: bool = False,
        gyro_drift: float = 0.0,
        **options: Unpack[Preset],
    ) -> None:
        if not rate > 0:
            raise ValueError(f"rate must be positive, got {rate!r}")
        self.session: Session = simulate(preset, seed=seed, **options)
        self.rate = float(rate)
        self.shake = float(shake)
        self.gyro_drawn = draw_gyro(
            np.random.default_rng(None if seed is None else [seed, GYRO_STREAM]),
            rate=self.rate,
            ideal=ideal_gyro,
            noise=gyro_noise,
            drift=gyro_drift,
        )
        self.gyro_noise = self.gyro_drawn.noise_std
        # a stream of its own: the truth is exactly simulate(preset, seed)'s
        self._rng = np.random.default_rng(None if seed is None else [seed, 2])
        self._count = 0
        d = self.drawn
        self._chol = {
            "accel": _cholesky(np.asarray(d["accel_cov"])),
            "mag": _cholesky(np.asarray(d["mag_cov"])),
        }

    @property
    def truth(self) -> Calibration:
        """The true calibration in fieldcal's gauge (compare estimates with it)."""
        return self.session.truth

    @property
    def gyro_truth(self) -> GyroTruth:
        """The gyroscope's truth in fieldcal's gauge (compare a gyroscope fit with it)."""
        return self.gyro_drawn.in_gauge(self.drawn)

    @property
    def drawn(self) -> Drawn:
        """The parameters as drawn: the gains and biases the raw samples are made with."""
        return self.session.drawn

    @property
    def time(self) -> float:
        """Time of the next sample, seconds."""
        return self._count / self.rate

    def _rows(self, m: int) -> Array:
        t = (self._count + np.arange(m)) / self.rate
        self._count += m
        return t

    def _readings(self, rotations: Array, linear: Array) -> tuple[Array, Array]:
        d = self.drawn
        g, h = np.asarray(d["gravity"]), np.asarray(d["magnetic"])
        m = len(rotations)
        body_g = np.einsum("nij,j->ni", rotations, g) + linear * np.linalg.norm(g)
        body_h = np.einsum("nij,j->ni", rotations, h)
        accel = body_g @ np.asarray(d["accel_gain"]).T + d["accel_bias"]
        mag = body_h @ np.asarray(d["mag_gain"]).T + d["mag_bias"]
        accel = accel + self._rng.standard_normal((m, 3)) @ self._chol["accel"].T
        mag = mag + self._rng.standard_normal((m, 3)) @ self._chol["mag"].T
        return accel, mag

    def still(self, rotation: ArrayLike, seconds: float) -> Samples:
        """Samples of the board resting at ``rotation`` for ``seconds`` (at least one).

        Parameters
        ----------
        rotation : (3, 3) array_like
            World-to-body rotation.
        seconds : float

        Returns
        -------
        Samples
        """
        R = _rotation(rotation)
        m = max(1, round(seconds * self.rate))
        t = self._rows(m)
        rotations = np.broadcast_to(R, (m, 3, 3)).copy()
        accel, mag = self._readings(rotations, np.zeros((m, 3)))
        gyro = self.gyro_drawn.read(t, np.zeros((m, 3)), self._rng.standard_normal((m, 3)))
        return Samples(t, accel, gyro, mag, rotations)

    def move(self, start: ArrayLike, stop: ArrayLike, seconds: float) -> Samples:
        """Samples of the board turning from ``start`` to ``stop`` in ``seconds`` (at least
        two samples): geodesic, raised-cosine speed, shaken, the gyroscope reading the turn.

        Parameters
        ----------
        start, stop : (3, 3) array_like
            World-to-body rotations.
        seconds : float

        Returns
        -------
        Samples
        """
        m = max(2, round(seconds * self.rate))
        rotations, omega = geodesic(_rotation(start), _rotation(stop), m, self.rate)
        u = (np.arange(m) + 0.5) / m
        linear = self.shake * np.sin(np.pi * u)[:, None] * self._rng.standard_normal((m, 3))
        t = self._rows(m)
        accel, mag = self._readings(rotations, linear)
        gyro = self.gyro_drawn.read(t, omega, self._rng.standard_normal((m, 3)))
        return Samples(t, accel, gyro, mag, rotations)


def _cholesky(cov: Array) -> Array:
    """The Cholesky factor of a covariance; zeros for noise-free samples."""
    if not np.any(cov):
        return np.zeros((3, 3))
    return np.asarray(np.linalg.cholesky(cov), dtype=np.float64)


def _rotation(value: ArrayLike) -> Array:
    R = np.asarray(value, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9):
        raise ValueError("a rotation must be a 3x3 orthogonal matrix")
    if np.linalg.det(R) < 0:
        raise ValueError("a rotation must have determinant +1")
    return R
