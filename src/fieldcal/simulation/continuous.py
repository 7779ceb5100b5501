"""A synthetic continuous log: still poses from :func:`fieldcal.simulate` joined by motion.

Each pose's samples are the simulated ones, unchanged, so the truth and the per-pose statistics
are those of the underlying :class:`~fieldcal.simulate.Session`. Between poses the device turns
smoothly (geodesic on SO(3) with a raised-cosine speed profile) while being shaken a little,
and a gyroscope reads the turn rate, as a hand-held recording would show.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Unpack

import numpy as np
from numpy.typing import NDArray

from .device import geodesic
from .session import Preset, Session, simulate

__all__ = ["ContinuousLog", "simulate_continuous"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ContinuousLog:
    """Columns ``t, ax..az, gx..gz, mx..mz`` plus the session and each pose's sample range."""

    columns: dict[str, Array]
    session: Session
    segments: tuple[tuple[int, int], ...]
    rate: float

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
    gyro_noise: float = 0.01,
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
    gyro_noise : float
        Standard deviation of the gyroscope's noise, rad/s.
    """
    session = simulate(preset, seed=seed, **options)
    drawn = session.drawn
    # a separate stream, so the still samples are exactly those of simulate(seed)
    rng = np.random.default_rng(None if seed is None else [seed, 1])
    R = np.asarray(drawn["rotations"])
    Ka, Km = drawn["accel_gain"], drawn["mag_gain"]
    ba, bm = drawn["accel_bias"], drawn["mag_bias"]
    g, h = drawn["gravity"], drawn["magnetic"]
    chol_a = (
        np.linalg.cholesky(drawn["accel_cov"]) if np.any(drawn["accel_cov"]) else np.zeros((3, 3))
    )
    chol_m = np.linalg.cholesky(drawn["mag_cov"]) if np.any(drawn["mag_cov"]) else np.zeros((3, 3))

    accel_parts, mag_parts, gyro_parts, segments = [], [], [], []
    position = 0
    for i in range(len(R)):
        n_still = len(session.accel[i])
        accel_parts.append(session.accel[i])
        mag_parts.append(session.mag[i])
        gyro_parts.append(rng.standard_normal((n_still, 3)) * gyro_noise)
        segments.append((position, position + n_still))
        position += n_still
        if i + 1 == len(R):
            break
        m = max(2, round(rng.uniform(*move_seconds) * rate))
        Rt, omega = geodesic(R[i], R[i + 1], m, rate)
        # these logs' gyroscope reads the turn rate with the opposite sign to the body-frame
        # angular velocity (Device's); kept, so the logs stay as they were
        omega = -omega
        u = (np.arange(m) + 0.5) / m
        lin = shake * np.sin(np.pi * u)[:, None] * rng.standard_normal((m, 3))
        body_g = np.einsum("nij,j->ni", Rt, g) + lin * np.linalg.norm(g)
        body_h = np.einsum("nij,j->ni", Rt, h)
        accel_parts.append(body_g @ Ka.T + ba + rng.standard_normal((m, 3)) @ chol_a.T)
        mag_parts.append(body_h @ Km.T + bm + rng.standard_normal((m, 3)) @ chol_m.T)
        gyro_parts.append(omega + rng.standard_normal((m, 3)) * gyro_noise)
        position += m
    accel = np.concatenate(accel_parts)
    mag = np.concatenate(mag_parts)
    gyro = np.concatenate(gyro_parts)
    columns = {"t": np.arange(len(accel)) / rate}
    for prefix, data in (("a", accel), ("g", gyro), ("m", mag)):
        for axis, column in zip("xyz", data.T, strict=True):
            columns[f"{prefix}{axis}"] = column
    return ContinuousLog(columns, session, tuple(segments), float(rate))
