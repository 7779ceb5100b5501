"""Integration of a gyroscope's body-frame rate into a rotation, over the timestamps as given.

Convention (``docs/conventions.md``): ``R`` maps world (NED) vectors to the body frame and the
body turns at ``ω`` (rad/s, body frame), so ``dR/dt = −[ω]× R``. Over an interval of length
``h`` with a constant rate the exact step is ``R ← exp(−[ω h]×) R``; the rotation over a run of
samples is the ordered product of the steps, later steps on the left. :func:`integrate` returns
``R(t_end) R(t_0)ᵀ`` (or every ``R(t_k) R(t_0)ᵀ``), the turn that the fit compares with
``R_{i+1} R_iᵀ`` of two poses.

The rate over the interval ``[t_k, t_{k+1}]`` is

- ``hold="midpoint"`` (default): the mean of the two samples' rates, ``(ω_k + ω_{k+1}) / 2``
  (exact for a constant rate, and for a rate changing linearly about a fixed axis; second
  order in the step otherwise);
- ``hold="previous"``: the rate of sample ``k`` (exact when the rate is piecewise constant,
  each sample's value holding until the next timestamp).

Each step is a unit quaternion (scalar first), composed exactly; the ordered product of all
steps is a log-depth (Hillis-Steele) scan, ``log₂ n`` vectorised quaternion products, so a
10⁵-sample log integrates in a few milliseconds without a Python loop over samples.

Timestamps: bursts (several rows sharing one timestamp, then a gap, as loggers of two sensors
on one clock write them) keep the rows' order and share the interval to the next distinct
timestamp equally (:func:`effective_time`); time going backwards is refused.
"""

from __future__ import annotations

from typing import Literal, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError
from ..geometry.rotations import log_so3, quaternion_to_matrix

__all__ = [
    "HOLDS",
    "cumulative_quaternions",
    "effective_time",
    "integrate",
    "interval_rates",
    "quaternion_multiply",
    "rotation_vector",
    "step_quaternions",
]

Array = NDArray[np.float64]
Hold = Literal["midpoint", "previous"]

#: How the rate over an interval between two samples is taken (see the module docstring).
HOLDS: tuple[Hold, ...] = ("midpoint", "previous")


def effective_time(time: ArrayLike) -> Array:
    """Timestamps with bursts spread out: strictly increasing, in seconds.

    A run of rows sharing one timestamp keeps its order and shares the interval up to the
    next distinct timestamp equally (a run at the end of the log shares the median step).

    Parameters
    ----------
    time : (n,) array_like
        Seconds, non-decreasing.

    Returns
    -------
    (n,) array
        Strictly increasing times, equal to ``time`` wherever no timestamp repeats.

    Raises
    ------
    InputError
        When a timestamp is not finite or smaller than the one before.
    """
    t = np.asarray(time, dtype=float)
    if t.ndim != 1:
        raise InputError(f"time must be one column of seconds, got an array of shape {t.shape}")
    if not np.all(np.isfinite(t)):
        row = int(np.argmin(np.isfinite(t)))
        raise InputError(f"time has a NaN or inf value at row {row}; drop that row or fix it")
    step = np.diff(t)
    if np.any(step < 0):
        row = int(np.argmax(step < 0)) + 1
        raise InputError(
            f"time goes backwards at row {row} ({t[row - 1]:.6g} s, then {t[row]:.6g} s); "
            "split the log at the reset (split_on_reset=True) or sort it"
        )
    repeated = step == 0
    if not np.any(repeated):
        return t
    positive = step[step > 0]
    if positive.size == 0:
        raise InputError("every timestamp is the same; give the time column of the log")
    # each row's run: the first row of a run of equal timestamps and the run's length
    first = np.flatnonzero(np.concatenate([[True], ~repeated]))
    length = np.diff(np.concatenate([first, [len(t)]]))
    start_time = t[first]
    end_time = np.concatenate([t[first[1:]], [t[-1] + float(np.median(positive))]])
    width = (end_time - start_time) / length
    run = np.repeat(np.arange(len(first)), length)
    offset = np.arange(len(t)) - first[run]
    spread: Array = start_time[run] + offset * width[run]
    return spread


def interval_rates(
    time: ArrayLike, omega: ArrayLike, hold: Hold = "midpoint"
) -> tuple[Array, Array]:
    """The rate over each interval between consecutive samples and the interval's length.

    Parameters
    ----------
    time : (n,) array_like
        Seconds (bursts spread by :func:`effective_time`).
    omega : (n, 3) array_like
        Body-frame rates, rad/s.
    hold : {"midpoint", "previous"}
        How the rate over an interval is taken (module docstring).

    Returns
    -------
    rates : (n − 1, 3) array
    dt : (n − 1,) array
    """
    w = np.asarray(omega, dtype=float)
    if w.ndim != 2 or w.shape[1] != 3:
        raise InputError(f"omega must have shape (n, 3), got {w.shape}")
    t = effective_time(time)
    if len(t) != len(w):
        raise InputError(f"time has {len(t)} rows but omega has {len(w)}; pass equal rows")
    if hold not in HOLDS:
        raise InputError(f"hold must be one of {', '.join(HOLDS)}; got {hold!r}")
    dt = np.diff(t)
    rates = 0.5 * (w[1:] + w[:-1]) if hold == "midpoint" else w[:-1]
    return rates, dt


def step_quaternions(rotvec: Array) -> Array:
    """Unit quaternions (..., 4), scalar first, of the steps ``exp(−[φ]×)`` for rotation
    vectors ``φ = ω h`` (..., 3): ``(cos(θ/2), −sin(θ/2) φ/θ)``, series near 0."""
    theta2 = np.einsum("...i,...i->...", rotvec, rotvec)
    theta = np.sqrt(theta2)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    half_sinc = np.where(small, 0.5 - theta2 / 48.0, np.sin(0.5 * safe) / safe)
    q = np.empty((*rotvec.shape[:-1], 4))
    q[..., 0] = np.cos(0.5 * theta)
    q[..., 1:] = -half_sinc[..., None] * rotvec
    return q


def quaternion_multiply(p: Array, q: Array) -> Array:
    """Hamilton products ``p ⊗ q`` (broadcast over leading axes), scalar first:
    ``R(p ⊗ q) = R(p) R(q)``."""
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


#: Steps composed one after another within a block of the scan (vectorised across blocks).
SCAN_BLOCK = 64


def cumulative_quaternions(steps: Array) -> Array:
    """Inclusive ordered products ``c_k = s_k ⊗ … ⊗ s_0`` of step quaternions (m, 4).

    A blocked scan, linear work: the steps in blocks of :data:`SCAN_BLOCK`, composed in order
    within every block at once (one vectorised product per position), the blocks' totals
    scanned (Hillis-Steele: after the pass with stride ``d`` each holds the product of the
    ``2d`` totals ending at it), then each block carried by the product of those before it."""
    c = np.array(steps, dtype=float)
    m = len(c)
    if m > 2 * SCAN_BLOCK:
        nb = -(-m // SCAN_BLOCK)
        flat = np.empty((nb * SCAN_BLOCK, 4))
        flat[:m] = c
        flat[m:] = (1.0, 0.0, 0.0, 0.0)
        blocks = flat.reshape(nb, SCAN_BLOCK, 4)
        for j in range(1, SCAN_BLOCK):
            blocks[:, j] = quaternion_multiply(blocks[:, j], blocks[:, j - 1])
        before = cumulative_quaternions(blocks[:-1, -1])  # products of the whole blocks
        blocks[1:] = quaternion_multiply(blocks[1:], before[:, None, :])
        c = blocks.reshape(-1, 4)[:m]
    else:
        d = 1
        while d < m:
            c[d:] = quaternion_multiply(c[d:], c[:-d])
            d *= 2
    # keep them unit (round-off of the products)
    c /= np.linalg.norm(c, axis=-1, keepdims=True)
    return c


@overload
def integrate(
    time: ArrayLike,
    omega: ArrayLike,
    *,
    cumulative: Literal[False] = ...,
    hold: Hold = ...,
) -> Array: ...


@overload
def integrate(
    time: ArrayLike, omega: ArrayLike, *, cumulative: Literal[True], hold: Hold = ...
) -> Array: ...


def integrate(
    time: ArrayLike,
    omega: ArrayLike,
    *,
    cumulative: bool = False,
    hold: Hold = "midpoint",
) -> Array:
    """The rotation a body-frame rate produces over the timestamps as given.

    Parameters
    ----------
    time : (n,) array_like
        Seconds, non-decreasing (repeated timestamps: see :func:`effective_time`).
    omega : (n, 3) array_like
        Body-frame angular rate in rad/s (a corrected gyroscope).
    cumulative : bool
        Return every ``R(t_k) R(t_0)ᵀ`` (n, 3, 3) instead of the last one.
    hold : {"midpoint", "previous"}
        How the rate over each interval is taken (module docstring).

    Returns
    -------
    (3, 3) or (n, 3, 3) array
        ``R(t_end) R(t_0)ᵀ`` in the world→body convention (``dR/dt = −[ω]× R``): a vector
        fixed in the world, expressed in the body frame at ``t_0``, maps to its expression
        at ``t_end``. The identity for a single sample.
    """
    rates, dt = interval_rates(time, omega, hold)
    if len(dt) == 0:
        eye = np.eye(3)
        return eye[None] if cumulative else eye
    steps = step_quaternions(rates * dt[:, None])
    if not cumulative:
        # the ordered product only: a pairwise tree reduction, log₂ n products of halves
        q = steps
        while len(q) > 1:
            if len(q) % 2:
                q = np.concatenate([q, [[1.0, 0.0, 0.0, 0.0]]])
            q = quaternion_multiply(q[1::2], q[0::2])
        total: Array = quaternion_to_matrix(q[0])
        return total
    c = cumulative_quaternions(steps)
    out = np.empty((len(dt) + 1, 3, 3))
    out[0] = np.eye(3)
    out[1:] = quaternion_to_matrix(c)
    return out


def rotation_vector(R: ArrayLike) -> Array:
    """Rotation vectors (..., 3) of rotation matrices (..., 3, 3), angle in [0, π]
    (:func:`fieldcal.geometry.rotations.log_so3`)."""
    out: Array = log_so3(np.asarray(R, dtype=float))
    return out
