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
    "block_scan",
    "cumulative_columns",
    "cumulative_quaternions",
    "effective_time",
    "integrate",
    "interval_rates",
    "matrix_columns",
    "multiply_columns",
    "quaternion_multiply",
    "rotation_vector",
    "runs",
    "segment_turns",
    "step_columns",
    "step_parts",
    "step_quaternions",
]

Array = NDArray[np.float64]
Hold = Literal["midpoint", "previous"]

#: How the rate over an interval between two samples is taken (see the module docstring).
HOLDS: tuple[Hold, ...] = ("midpoint", "previous")


def effective_time(time: ArrayLike) -> Array:
    """Timestamps with bursts spread out: strictly increasing, in seconds.

    A run of rows sharing one timestamp keeps its order and shares the interval up to the
    next distinct timestamp equally (a run at the end of the log shares the median step). A
    step back of less than a typical step (jitter: samples written slightly out of order) makes
    the row share the latest time before it.

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
        When a timestamp is not finite or goes back by more than a typical step.
    """
    t = np.asarray(time, dtype=float)
    if t.ndim != 1:
        raise InputError(f"time must be one column of seconds, got an array of shape {t.shape}")
    if not np.all(np.isfinite(t)):
        row = int(np.argmin(np.isfinite(t)))
        raise InputError(f"time has a NaN or inf value at row {row}; drop that row or fix it")
    step = np.diff(t)
    if np.any(step < 0):
        positive = step[step > 0]
        typical = float(np.median(positive)) if positive.size else 0.0
        if np.all(step > -typical):
            # jitter (two sensors' samples written slightly out of order, as the reader keeps
            # it): such a row shares the time of the latest before it and is spread below
            t = np.maximum.accumulate(t)
            step = np.diff(t)
        else:
            row = int(np.argmax(step <= -typical)) + 1
            raise InputError(
                f"time goes backwards at row {row} ({t[row - 1]:.6g} s, then {t[row]:.6g} s); "
                "pass --split-on-reset (split_on_reset=True) to start a new segment at a reset "
                "of the clock, or sort the log by time"
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
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty(np.broadcast_shapes(p.shape, q.shape))
    out[..., 0] = pw * qw - px * qx - py * qy - pz * qz
    out[..., 1] = pw * qx + px * qw + py * qz - pz * qy
    out[..., 2] = pw * qy - px * qz + py * qw + pz * qx
    out[..., 3] = pw * qz + px * qy - py * qx + pz * qw
    return out


#: Steps composed one after another within a block of the scan (vectorised across blocks).
SCAN_BLOCK = 64

#: Scans of at most this many blocks are Hillis-Steele's (``log₂ m`` products of the whole
#: array): fewer numpy calls than so few blocks would take.
HILLIS_BLOCKS = 32


def multiply_columns(p: Array, q: Array, out: Array | None = None) -> Array:
    """:func:`quaternion_multiply` for quaternions stored by component, ``(4, ...)`` (each
    component a contiguous row: the products run at the memory's pace); ``out`` (not ``p`` or
    ``q``) receives them, each row summed in place in the order written."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    if out is None:
        out = np.empty(np.broadcast_shapes(p.shape, q.shape))
    o = np.multiply(pw, qw, out=out[0])
    o -= px * qx
    o -= py * qy
    o -= pz * qz
    o = np.multiply(pw, qx, out=out[1])
    o += px * qw
    o += py * qz
    o -= pz * qy
    o = np.multiply(pw, qy, out=out[2])
    o -= px * qz
    o += py * qw
    o += pz * qx
    o = np.multiply(pw, qz, out=out[3])
    o += px * qy
    o -= py * qx
    o += pz * qw
    return out


def cumulative_columns(steps: Array) -> Array:
    """:func:`cumulative_quaternions` for step quaternions stored by component, ``(4, m)``."""
    m = steps.shape[1]
    if m <= HILLIS_BLOCKS * SCAN_BLOCK:
        return _hillis_steele(steps)
    scan, before = _blocked(steps, SCAN_BLOCK)
    # each block carried by the product of the blocks before it
    blocks = np.empty_like(scan)
    blocks[:, :, 0] = scan[:, :, 0]
    multiply_columns(scan[:, :, 1:], before[:, None, 1:], out=blocks[:, :, 1:])
    c = blocks.transpose(0, 2, 1).reshape(4, -1)[:, :m]
    c /= np.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2] + c[3] * c[3])  # unit (round-off)
    return c


def block_scan(steps: Array, block: int = SCAN_BLOCK) -> tuple[Array, Array]:
    """:func:`cumulative_columns` left in two factors, without the pass that multiplies them
    out: the products within each block of ``block`` steps, in order (4, m), and the product
    of the whole blocks before each block (4, nb): the scan at step ``k`` is
    ``inner[k] ⊗ before[k // block]`` (for a caller that needs it at a few steps, or composes
    it with another product anyway)."""
    m = steps.shape[1]
    nb = -(-m // block)
    if m <= HILLIS_BLOCKS * block:
        before = np.zeros((4, nb))
        before[0] = 1.0
        return _hillis_steele(steps), before
    scan, before = _blocked(steps, block)
    inner = scan.transpose(0, 2, 1).reshape(4, -1)[:, :m]
    inner /= np.sqrt(
        inner[0] * inner[0] + inner[1] * inner[1] + inner[2] * inner[2] + inner[3] * inner[3]
    )
    return inner, before


def _blocked(steps: Array, block: int) -> tuple[Array, Array]:
    """The products within each block (4, block, nb), composed in order for every block at
    once, and the products of the whole blocks before each (4, nb), the identity first."""
    m = steps.shape[1]
    nb = -(-m // block)
    flat = np.empty((4, nb * block))
    flat[:, :m] = steps
    flat[:, m:] = np.array([1.0, 0.0, 0.0, 0.0])[:, None]
    # (4, position in block, block): each position's row contiguous across the blocks
    blocks = np.ascontiguousarray(flat.reshape(4, nb, block).transpose(0, 2, 1))
    scan = np.empty_like(blocks)
    scan[:, 0] = blocks[:, 0]
    for j in range(1, block):
        multiply_columns(blocks[:, j], scan[:, j - 1], out=scan[:, j])
    before = np.empty((4, nb))
    before[:, 0] = (1.0, 0.0, 0.0, 0.0)
    before[:, 1:] = cumulative_columns(scan[:, -1, :-1])  # products of the whole blocks
    return scan, before


def _hillis_steele(steps: Array) -> Array:
    """The inclusive scan by Hillis-Steele: after the pass with stride ``d`` each column holds
    the product of the ``2d`` steps ending at it."""
    c = np.array(steps, dtype=float)
    m = c.shape[1]
    d = 1
    while d < m:
        c[:, d:] = multiply_columns(c[:, d:], c[:, :-d])
        d *= 2
    c /= np.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2] + c[3] * c[3])  # unit (round-off)
    return c


def step_columns(h: Array) -> Array:
    """Step quaternions (4, J) of ``exp(−[h]×)`` for rotation vectors ``h = ω dt`` (3, J) by
    component (:func:`step_quaternions`)."""
    return step_parts(h)[0]


def step_parts(h: Array) -> tuple[Array, Array, Array]:
    """:func:`step_columns` with what it computed on the way: the quaternions (4, J), the
    squared angles ``θ²`` and ``sin(θ/2)/θ`` (J,) (the step's right Jacobian reuses them)."""
    theta2 = h[0] * h[0] + h[1] * h[1] + h[2] * h[2]
    theta = np.sqrt(theta2)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    half_sinc = np.where(small, 0.5 - theta2 / 48.0, np.sin(0.5 * safe) / safe)
    q = np.empty((4, h.shape[1]))
    q[0] = np.cos(0.5 * theta)
    q[1:] = -half_sinc * h
    return q, theta2, half_sinc


def matrix_columns(q: Array, *, unit: bool = False) -> Array:
    """Rotation matrices (3, 3, J) of quaternions (4, J) by component, normalised first
    (``unit=True``: already unit to round-off, taken as they are)."""
    if not unit:
        q = q / np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    w, x, y, z = q
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    R = np.empty((3, 3, q.shape[1]))
    R[0, 0], R[0, 1], R[0, 2] = 1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)
    R[1, 0], R[1, 1], R[1, 2] = 2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)
    R[2, 0], R[2, 1], R[2, 2] = 2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)
    return R


def runs(first: NDArray[np.int64], last: NDArray[np.int64], size: int) -> list[slice]:
    """Consecutive segments (``first``/``last`` their intervals) in runs of about ``size``
    intervals, at least one segment each."""
    ends = last + 1
    out: list[slice] = []
    s0, m = 0, len(first)
    while s0 < m:
        s1 = max(int(np.searchsorted(ends, int(first[s0]) + size, side="right")), s0 + 1)
        out.append(slice(s0, s1))
        s0 = s1
    return out


def cumulative_quaternions(steps: Array) -> Array:
    """Inclusive ordered products ``c_k = s_k ⊗ … ⊗ s_0`` of step quaternions (m, 4).

    A blocked scan, linear work: the steps in blocks of :data:`SCAN_BLOCK`, composed in order
    within every block at once (one vectorised product per position), the blocks' totals
    scanned (Hillis-Steele: after the pass with stride ``d`` each holds the product of the
    ``2d`` totals ending at it), then each block carried by the product of those before it;
    computed by component (:func:`cumulative_columns`)."""
    out: Array = np.ascontiguousarray(cumulative_columns(np.asarray(steps, dtype=float).T).T)
    return out


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


#: Intervals integrated at a time by :func:`segment_turns` (a few MB of work arrays).
TURN_CHUNK = 1 << 16


def segment_turns(
    time: ArrayLike, omega: ArrayLike, spans: ArrayLike, *, hold: Hold = "midpoint"
) -> Array:
    """The rotation over each span of rows, as :func:`integrate` of that span alone, for every
    span at once (a blocked scan over their intervals together, linear in them).

    Parameters
    ----------
    time : (n,) array_like
        Seconds, non-decreasing within each span (bursts spread within it,
        :func:`effective_time`).
    omega : (n, 3) array_like
        Body-frame angular rate in rad/s.
    spans : (M, 2) array_like of int
        The first and the last row (inclusive) of each span.
    hold : {"midpoint", "previous"}
        How the rate over each interval is taken (module docstring).

    Returns
    -------
    (M, 3, 3) array
        ``R(t_last) R(t_first)ᵀ`` of each span (the identity for a span of one row).

    Raises
    ------
    InputError
        For a span outside the rows, or time going backwards within one.
    """
    t_all = np.asarray(time, dtype=float)
    w_all = np.asarray(omega, dtype=float)
    bounds = np.asarray(spans, dtype=np.int64).reshape(-1, 2)
    if w_all.ndim != 2 or w_all.shape[1] != 3 or t_all.shape != (len(w_all),):
        raise InputError(f"omega must have shape (n, 3) with n the rows of time, got {w_all.shape}")
    if hold not in HOLDS:
        raise InputError(f"hold must be one of {', '.join(HOLDS)}; got {hold!r}")
    first, last = bounds[:, 0], bounds[:, 1]
    if np.any(first < 0) or np.any(last >= len(t_all)) or np.any(last < first):
        raise InputError(f"spans must be (first, last) rows within the {len(t_all)} given")
    out = np.empty((len(bounds), 3, 3))
    steps = last - first  # intervals per span
    ends = np.cumsum(steps)
    for run in runs(ends - steps, ends - 1, TURN_CHUNK):
        out[run] = _turns(t_all, w_all, first[run], last[run], hold)
    return out


def _turns(
    t_all: Array, w_all: Array, first: NDArray[np.int64], last: NDArray[np.int64], hold: Hold
) -> Array:
    """:func:`segment_turns` of some spans (their intervals together)."""
    length = last - first + 1
    start = np.cumsum(length) - length  # each span's first position among the rows taken
    idx = np.repeat(first - start, length) + np.arange(int(length.sum()))
    t, w = t_all[idx], w_all[idx]
    inner = np.ones(len(t) - 1, dtype=bool)  # the pairs of rows within one span
    inner[(start + length - 1)[:-1]] = False
    step = np.diff(t)
    # spans of one row have no interval (and may start past the last one): left out here
    multi_start, multi_length = start[length > 1], length[length > 1]
    if len(multi_start):
        bursts = np.add.reduceat(inner & (step <= 0), multi_start) > 0
        for s0, n in zip(multi_start[bursts].tolist(), multi_length[bursts].tolist(), strict=True):
            t[s0 : s0 + n] = effective_time(t[s0 : s0 + n])  # bursts spread (or time refused)
    step = np.diff(t)[inner]
    rate = 0.5 * (w[1:] + w[:-1]) if hold == "midpoint" else w[:-1]
    # the scan in its two factors, multiplied out only where it is needed: before each span's
    # first interval and at its end
    inner_scan, before = block_scan(step_columns((rate[inner] * step[:, None]).T))
    ends = np.cumsum(length - 1)  # positions in the scan with the identity put first

    def scan_at(k: NDArray[np.int64]) -> Array:
        if inner_scan.shape[1] == 0:  # no interval at all: every span a single row
            return np.repeat(np.array([[1.0], [0.0], [0.0], [0.0]]), len(k), axis=1)
        at = np.maximum(k - 1, 0)
        out = multiply_columns(inner_scan[:, at], before[:, at // SCAN_BLOCK])
        out[:, k == 0] = np.array([1.0, 0.0, 0.0, 0.0])[:, None]
        return out

    base = scan_at(ends - (length - 1))
    base[1:] *= -1.0
    turn = matrix_columns(multiply_columns(scan_at(ends), base))
    out: Array = np.moveaxis(turn, 2, 0)
    return out


def rotation_vector(R: ArrayLike) -> Array:
    """Rotation vectors (..., 3) of rotation matrices (..., 3, 3), angle in [0, π]
    (:func:`fieldcal.geometry.rotations.log_so3`)."""
    out: Array = log_so3(np.asarray(R, dtype=float))
    return out
