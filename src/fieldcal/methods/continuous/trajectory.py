"""What the fitted trajectory and residuals say about the recording: the summary the JSON keeps.

- ``trajectory``: duration, epochs, the share of gravity directions through the body the log
  visited (of :data:`DIRECTIONS` evenly spread directions, one counts when the body's "up" came
  within :data:`COVERAGE_DEG` of it), and the total turn about each body axis.
- ``motion``: RMS body acceleration (the accelerometer's calibrated residual), RMS and peak
  angular rate.
- ``downweighted``: stretches whose accelerometer variance exceeds :data:`DISTURBED` times the
  log's quiet level, merged, each with its reason.
"""

from __future__ import annotations

from typing import Any, TypedDict

import numpy as np
from numpy.typing import NDArray

from ...geometry.frames import GRAVITY
from .observability import motion_advice

__all__ = [
    "COVERAGE_DEG",
    "DIRECTIONS",
    "DISTURBED",
    "RawMotion",
    "coverage",
    "downweighted",
    "raw_motion",
    "summary",
    "visited",
]

Array = NDArray[np.float64]


class RawMotion(TypedDict):
    """:func:`raw_motion`'s account of a log's motion before any calibration."""

    seconds: float
    gravity_coverage: float
    visited: Array
    turned_deg: dict[str, float]
    advice: str | None


DIRECTIONS = 64
COVERAGE_DEG = 25.0
#: A stretch is down-weighted when its accelerometer variance exceeds this many times the
#: quietest tenth of the log's stretches.
DISTURBED = 25.0


def _sphere(n: int) -> Array:
    """``n`` near-uniform unit vectors (Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = np.pi * (1.0 + 5.0**0.5) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def visited(up: Array) -> Array:
    """The :data:`DIRECTIONS` evenly spread unit directions (rows) that ``up`` (n, 3), the
    body's "up" direction per sample (any length), came within :data:`COVERAGE_DEG` of."""
    u = up / np.maximum(np.linalg.norm(up, axis=1, keepdims=True), 1e-300)
    dirs = _sphere(DIRECTIONS)
    step = max(1, len(u) // 20000)
    close = (u[::step] @ dirs.T) > np.cos(np.radians(COVERAGE_DEG))
    out: Array = dirs[np.any(close, axis=0)]
    return out


def coverage(rotations: Array) -> float:
    """Share of :data:`DIRECTIONS` directions the body's "up" came within
    :data:`COVERAGE_DEG` of."""
    return len(visited(rotations @ GRAVITY)) / DIRECTIONS


def raw_motion(time: Array, accel: Array, gyro: Array) -> RawMotion:
    """The motion of a log so far from its raw readings, before any calibration (a live
    capture's coverage): ``seconds``, ``gravity_coverage`` (of the raw accelerometer's
    directions, :func:`visited`), ``visited`` (those directions, rows), ``turned_deg`` (the
    raw gyroscope's total turn about each axis, rad/s nominal) and ``advice`` (what the motion
    still lacks, :func:`.observability.motion_advice`; ``None`` when nothing)."""
    t = np.asarray(time, dtype=float)
    dt = np.diff(t)[:, None] if len(t) > 1 else np.zeros((0, 1))
    g = np.asarray(gyro, dtype=float)
    turned = (
        np.degrees(np.sum(np.abs(0.5 * (g[1:] + g[:-1])) * dt, axis=0))
        if len(g) > 1
        else np.zeros(3)
    )
    up = np.asarray(accel, dtype=float)
    seen = visited(up)
    return RawMotion(
        seconds=float(t[-1] - t[0]) if len(t) else 0.0,
        gravity_coverage=len(seen) / DIRECTIONS,
        visited=seen,
        turned_deg={axis: float(v) for axis, v in zip("xyz", turned, strict=True)},
        advice=motion_advice(up, turned) if len(up) else None,
    )


def summary(
    time: Array, rotations: Array, rates: Array, body_accel: Array, gravity: float | None
) -> tuple[dict[str, Any], dict[str, float]]:
    """``(trajectory, motion)`` dictionaries (module docstring); ``rates`` (n − 1, 3) rad/s
    over the intervals, ``body_accel`` (n, 3) in units of |g|."""
    dt = np.diff(time)
    turned = np.degrees(np.sum(np.abs(rates) * dt[:, None], axis=0))
    trajectory = {
        "duration_s": float(time[-1] - time[0]),
        "epochs": len(time),
        "gravity_coverage": coverage(rotations),
        "turned_deg": {axis: float(v) for axis, v in zip("xyz", turned, strict=True)},
    }
    norm = np.linalg.norm(rates, axis=1)
    rms_acc = float(np.sqrt(np.mean(np.sum(body_accel**2, axis=1))))
    motion: dict[str, float] = {
        "body_accel_rms_g": rms_acc,
        "angular_rate_rms_deg_s": float(np.degrees(np.sqrt(np.mean(norm**2)))),
        "angular_rate_max_deg_s": float(np.degrees(np.max(norm))) if len(norm) else 0.0,
    }
    if gravity is not None:
        motion["body_accel_rms"] = rms_acc * float(gravity)
    return trajectory, motion


def downweighted(
    per_stretch: Array, length: int, time: Array, body_accel: Array, rows: NDArray[np.int_]
) -> list[dict[str, float | str]]:
    """The disturbed stretches (merged runs), each with rows, seconds and a reason."""
    quiet = float(np.quantile(per_stretch, 0.1))
    flagged = per_stretch > DISTURBED * quiet
    out: list[dict[str, float | str]] = []
    n = len(time)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flagged.astype(int), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        first, stop = int(a) * length, min(int(b) * length, n)
        rms = float(np.sqrt(np.mean(np.sum(body_accel[first:stop] ** 2, axis=1))))
        out.append(
            {
                "start": int(rows[first]),
                "stop": int(rows[stop - 1]) + 1,
                "seconds": float(time[stop - 1] - time[first]),
                "weight": float(quiet / np.max(per_stretch[a:b])),
                "reason": f"body acceleration {rms:.2g} g RMS (hand motion): accelerometer "
                "down-weighted",
            }
        )
    return out
