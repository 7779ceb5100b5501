"""A synthetic continuous log: still poses from :func:`fieldcal.simulate` joined by motion.

Each pose's samples are the simulated ones, unchanged, so the truth and the per-pose statistics
are those of the underlying :class:`~fieldcal.simulate.Session`. Between poses the device turns
smoothly (geodesic on SO(3) with a raised-cosine speed profile) while being shaken a little,
and a gyroscope reads the turn rate, as a hand-held recording would show: ``raw = K_g ω +
b_g(t) + noise`` with ``ω`` the body-frame angular velocity (``dR/dt = −[ω]× R``) and a drawn
truth (:func:`~fieldcal.simulation.device.draw_gyro`: a realistic MEMS part by default, from a
stream of its own so the other columns of a seed do not depend on it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Unpack

import numpy as np
from numpy.typing import NDArray

from .device import GYRO_STREAM, GyroTruth, _cholesky, draw_gyro, geodesic
from .session import Preset, Session, simulate

__all__ = ["ContinuousLog", "simulate_continuous"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ContinuousLog:
    """Columns ``t, ax..az, gx..gz, mx..mz`` plus the session and each pose's sample range.

    ``gyro_drawn`` is the gyroscope's truth as drawn (the frame the samples are made in, that
    of ``session.drawn``); :attr:`gyro_truth` is the same in fieldcal's gauge, to compare with
    an estimate made from a calibration's rotations.
    """

    columns: dict[str, Array]
    session: Session
    segments: tuple[tuple[int, int], ...]
    rate: float
    gyro_drawn: GyroTruth | None = None

    @property
    def gyro_truth(self) -> GyroTruth | None:
        """The gyroscope's truth in fieldcal's body frame (``None`` if none was drawn)."""
        return None if self.gyro_drawn is None else self.gyro_drawn.in_gauge(self.session.drawn)

    def write_csv(self, path: str) -> None:
        names = list(self.columns)
        data = np.column_stack([self.columns[k] for k in names])
        np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.9g")


def simulate_continuous(
    preset: str = "paper",
    *,
    seed: int | None = None,
    rate: float = 100.0,
    move_seconds: tuple[float, float] = (1.0, 2.0),
    shake: float = 0.05,
    gyro_noise: float | None = None,
    ideal_gyro: bool = False,
    gyro_drift: float = 0.0,
    **options: Unpack[Preset],
) -> ContinuousLog:
    """Simulate a time-stamped log with still poses separated by motion.

    Parameters
    ----------
    preset, seed, **options
        Passed to :func:`fieldcal.simulate` (e.g. ``n_poses``, ``pose_distribution``).
    rate : float
        Sample rate in Hz (the pose sample counts of the preset become durations).
    move_seconds : (min, max)
        Duration of each transition, drawn uniformly.
    shake : float
        Amplitude of the hand's linear acceleration during transitions, in units of |g|.
    gyro_noise : float, optional
        Standard deviation of one gyroscope sample's white noise, rad/s (default: the MEMS
        part's 0.005 rad/s at 100 Hz, the same density at other rates).
    ideal_gyro : bool
        An ideal gyroscope (identity gain, zero bias) instead of the drawn MEMS part (scale
        ±3 %, cross-axis ±1 %, misalignment ±1°, bias ±0.02 rad/s).
    gyro_drift : float
        Half-range of the gyroscope's bias drift per axis, rad/s per second (default none).
    """
    session = simulate(preset, seed=seed, **options)
    drawn = session.drawn
    # a separate stream, so the still samples are exactly those of simulate(seed)
    rng = np.random.default_rng(None if seed is None else [seed, 1])
    gyro = draw_gyro(
        np.random.default_rng(None if seed is None else [seed, GYRO_STREAM]),
        rate=rate,
        ideal=ideal_gyro,
        noise=gyro_noise,
        drift=gyro_drift,
    )
    R = np.asarray(drawn["rotations"])
    Ka, Km = drawn["accel_gain"], drawn["mag_gain"]
    ba, bm = drawn["accel_bias"], drawn["mag_bias"]
    g, h = drawn["gravity"], drawn["magnetic"]
    chol_a = _cholesky(np.asarray(drawn["accel_cov"]))
    chol_m = _cholesky(np.asarray(drawn["mag_cov"]))

    accel_parts, mag_parts, gyro_parts, segments = [], [], [], []
    normal_parts: list[Array] = []  # the gyroscope's noise, drawn where it always was in the stream
    position = 0
    for i in range(len(R)):
        n_still = len(session.accel[i])
        accel_parts.append(session.accel[i])
        mag_parts.append(session.mag[i])
        gyro_parts.append(np.zeros((n_still, 3)))
        normal_parts.append(rng.standard_normal((n_still, 3)))
        segments.append((position, position + n_still))
        position += n_still
        if i + 1 == len(R):
            break
        m = max(2, round(rng.uniform(*move_seconds) * rate))
        # omega: the body-frame angular velocity, dR/dt = −[ω]× R (as Device reads it)
        Rt, omega = geodesic(R[i], R[i + 1], m, rate)
        u = (np.arange(m) + 0.5) / m
        lin = shake * np.sin(np.pi * u)[:, None] * rng.standard_normal((m, 3))
        body_g = np.einsum("nij,j->ni", Rt, g) + lin * np.linalg.norm(g)
        body_h = np.einsum("nij,j->ni", Rt, h)
        accel_parts.append(body_g @ Ka.T + ba + rng.standard_normal((m, 3)) @ chol_a.T)
        mag_parts.append(body_h @ Km.T + bm + rng.standard_normal((m, 3)) @ chol_m.T)
        gyro_parts.append(omega)
        normal_parts.append(rng.standard_normal((m, 3)))
        position += m
    accel = np.concatenate(accel_parts)
    mag = np.concatenate(mag_parts)
    t = np.arange(len(accel)) / rate
    rates = gyro.read(t, np.concatenate(gyro_parts), np.concatenate(normal_parts))
    columns = {"t": t}
    for prefix, data in (("a", accel), ("g", rates), ("m", mag)):
        for axis, column in zip("xyz", data.T, strict=True):
            columns[f"{prefix}{axis}"] = column
    return ContinuousLog(columns, session, tuple(segments), float(rate), gyro)
