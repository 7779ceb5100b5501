"""What the gyroscope's fit needs of a log: the still poses' rows, means, noise and drift, and
the motion segments between them (the intervals, their rates and bias interpolation weights)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import chdtrc, fdtrc

from ..errors import InputError
from .integrate import Hold, runs

Array = NDArray[np.float64]

#: Block length (seconds) of the still poses' block means that check the white-noise model.
BLOCK_SECONDS = 0.25


#: A gyroscope column flat at its extreme for this many consecutive motion rows saturates.
FLAT_ROWS = 4


@dataclass
class Segments:
    """The motion segments' intervals, concatenated: what the model needs of the log."""

    raw: Array  # (J, 3) the interval's raw rate (hold applied), scaled units
    dt: Array  # (J,)
    lam: Array  # (J,) interpolation weight of the later pose's bias
    seg: NDArray[np.int64]  # (J,) segment of each interval
    first: NDArray[np.int64]  # (M,) first interval of each segment
    last: NDArray[np.int64]  # (M,) last interval of each segment
    before: NDArray[np.int64]  # (M,) pose before each segment (the later one is before + 1)
    rows: tuple[tuple[int, int], ...]


def check_rows(poses: Sequence[Sequence[int]], n: int) -> NDArray[np.int64]:
    try:
        rows = np.array([[int(a), int(b)] for a, b in poses], dtype=np.int64)
    except (TypeError, ValueError):
        raise InputError(
            "poses must be a sequence of (start, stop) row pairs, one per still pose"
        ) from None
    if rows.ndim != 2 or len(rows) < 2:
        raise InputError(f"{len(rows)} still pose(s) given; the gyroscope needs at least 4")
    bad = (rows[:, 0] < 0) | (rows[:, 1] > n) | (rows[:, 1] - rows[:, 0] < 2)
    if np.any(bad):
        i = int(np.argmax(bad))
        raise InputError(
            f"pose {i} has rows {rows[i, 0]}..{rows[i, 1]}; each pose needs at least 2 rows "
            f"within the log's {n} (start inclusive, stop exclusive)"
        )
    overlap = rows[1:, 0] < rows[:-1, 1]
    if np.any(overlap):
        i = int(np.argmax(overlap)) + 1
        raise InputError(
            f"pose {i} starts at row {rows[i, 0]} before pose {i - 1} ends ({rows[i - 1, 1]}); "
            "give the still poses in time order, without overlap"
        )
    return rows


def check_saturation(
    raw: Array,
    rows: NDArray[np.int64],
    links: NDArray[np.int64],
    full_scale: float | None,
    bias: Array,
    sigma: Array,
) -> None:
    """Refuse a gyroscope that clips during the turns: its integral would be short."""
    # the rows of the turns: from the last row of pose k to the first of k + 1, inclusive
    edges = np.zeros(len(raw) + 1, dtype=np.int64)
    np.add.at(edges, rows[links, 1] - 1, 1)
    np.add.at(edges, rows[links + 1, 0] + 1, -1)
    motion = np.cumsum(edges[:-1]) > 0
    for j, axis in enumerate("xyz"):
        x = raw[:, j]
        if full_scale is not None:
            hit = motion & (np.abs(x) >= 0.999 * full_scale)
            if np.any(hit):
                r = int(np.argmax(hit))
                raise InputError(
                    f"the gyroscope saturates on axis {axis} at row {r} ({x[r]:.6g}, full scale "
                    f"{full_scale:.6g}): the turns are faster than its range; turn more slowly "
                    "or record with a larger full-scale range"
                )
            continue
        for extreme in (float(x.max()), float(x.min())):
            if abs(extreme - bias[j]) <= 20.0 * max(float(sigma[j]), 1e-300):
                continue
            flat = motion & (x == extreme)
            if np.count_nonzero(flat) < FLAT_ROWS:
                continue
            # a run of FLAT_ROWS consecutive rows at the extreme: clipped, not a peak
            run = np.convolve(flat.astype(np.int64), np.ones(FLAT_ROWS, dtype=np.int64), "valid")
            if np.any(run == FLAT_ROWS):
                r = int(np.argmax(run == FLAT_ROWS))
                raise InputError(
                    f"the gyroscope saturates on axis {axis}: {extreme:.6g} raw units held for "
                    f"{FLAT_ROWS}+ rows from row {r} during a turn; turn more slowly or record "
                    "with a larger full-scale range (or pass full_scale if this is not clipping)"
                )


def build_segments(
    t: Array,
    raw: Array,
    rows: NDArray[np.int64],
    links: NDArray[np.int64],
    pose_time: Array,
    hold: Hold,
) -> Segments:
    """The motion segments ``links`` (``k``: from pose ``k`` to ``k + 1``): every interval
    from the last row of pose ``k`` to the first of ``k + 1``, all segments at once."""
    k = np.asarray(links, dtype=np.int64)
    a, c = rows[k, 1] - 1, rows[k + 1, 0]  # last row of pose k, first of k + 1
    length = c - a  # intervals per segment
    last = np.cumsum(length) - 1
    first = last - length + 1
    seg = np.repeat(np.arange(len(k), dtype=np.int64), length)
    left = np.arange(len(seg), dtype=np.int64) + np.repeat(a - first, length)  # row before
    right = left + 1
    if hold == "midpoint":
        u = 0.5 * (raw[right] + raw[left])
        mid = 0.5 * (t[right] + t[left])
    else:
        u, mid = raw[left], t[left]
    before = pose_time[k][seg]
    lam = (mid - before) / (pose_time[k + 1][seg] - before)
    return Segments(
        u,
        t[right] - t[left],
        lam,
        seg,
        first,
        last,
        k,
        tuple(zip(a.tolist(), c.tolist(), strict=True)),
    )


def interval_bias(data: Segments, b: Array) -> Array:
    """The bias (J, 3) over each interval, linear in time between the poses' biases ``b``."""
    lam = data.lam[:, None]
    pose = data.before[data.seg]
    out: Array = (1.0 - lam) * b[pose] + lam * b[pose + 1]
    return out


def segment_sums(data: Segments, p: Array) -> Array:
    """``∫ (raw − b(t)) dt`` of each segment with the still poses' biases (scaled units·s)."""
    u = data.raw - interval_bias(data, p)
    out: Array = np.add.reduceat(u * data.dt[:, None], data.first, axis=0)
    return out


def pose_statistics(
    t: Array, raw: Array, rows: NDArray[np.int64]
) -> tuple[Array, Array, Array, Array, int, Array]:
    """Pose means, mean times, durations, pooled sample covariance (and its dof), and the
    block-mean check of the white-noise model (the rate noise density's factor)."""
    n_pose = len(rows)
    means = np.empty((n_pose, 3))
    times = np.empty(n_pose)
    steps = np.diff(t)
    typical = float(np.median(steps[steps > 0])) if np.any(steps > 0) else 1.0
    block_len = max(4, round(BLOCK_SECONDS / typical))
    a, b = rows[:, 0], rows[:, 1]
    durations = (t[b - 1] - t[a]) + typical
    count = (b - a) // block_len  # whole blocks per pose
    count[count < 2] = 0
    scatter = np.zeros((3, 3))
    block_scatter = np.zeros((3, 3))
    # the poses a run at a time (their rows gathered: a few MB whatever the log's length)
    for run in runs(a, b - 1, POSE_ROWS):
        length = b[run] - a[run]
        x = raw[_ranges(a[run], length)]
        starts = np.cumsum(length) - length
        means[run] = np.add.reduceat(x, starts, axis=0) / length[:, None]
        times[run] = np.add.reduceat(t[_ranges(a[run], length)], starts) / length
        d = x - np.repeat(means[run], length, axis=0)
        scatter += d.T @ d
        k = count[run]
        if np.any(k):
            blocks = raw[_ranges(a[run], k * block_len)].reshape(-1, block_len, 3).mean(axis=1)
            first = np.cumsum(k) - k
            some = k > 0
            centre = np.add.reduceat(blocks, first[some], axis=0) / k[some, None]
            d = blocks - np.repeat(centre, k[some], axis=0)
            block_scatter += d.T @ d
    dof = int(np.sum(b - a - 1))
    block_dof = int(np.sum(np.maximum(count - 1, 0)))
    cov = scatter / max(dof, 1)
    q_white = cov * typical
    factor = 1.0
    if block_dof >= 10 and np.trace(cov) > 0:
        q_block = block_scatter / block_dof * (block_len * typical)
        ratio = float(np.trace(np.linalg.solve(q_white, q_block))) / 3.0
        # a low-pass filter or a wandering bias: block means vary more than white noise says
        if ratio > 1.0 + 3.0 * math.sqrt(2.0 / block_dof):
            factor = ratio
    return means, times, durations, cov, dof, q_white * factor


#: Rows of still poses taken at a time by :func:`pose_statistics`.
POSE_ROWS = 1 << 16


def _ranges(start: NDArray[np.int64], length: NDArray[np.int64]) -> NDArray[np.int64]:
    """The rows ``start[i] … start[i] + length[i] − 1`` of every ``i``, concatenated."""
    offsets = np.cumsum(length) - length
    out: NDArray[np.int64] = np.arange(int(length.sum()), dtype=np.int64) + np.repeat(
        start - offsets, length
    )
    return out


def drift_line(
    means: Array, times: Array, durations: Array, Q: Array
) -> tuple[Array | None, float | None, float, Array]:
    """The bias line through the poses' means: slope, its p-value, the wander ``v`` (raw²)
    beyond white noise and the per-pose prior covariance ``Q/T_i + v I``."""
    n = len(means)
    base = Q[None] / durations[:, None, None]
    if n < 3:
        return None, None, 0.0, base
    tau = times - np.average(times, weights=durations)
    X = np.zeros((n, 3, 6))
    X[:, :, :3] = np.eye(3)
    X[:, :, 3:] = tau[:, None, None] * np.eye(3)

    def gls(cov: Array) -> tuple[Array, Array, float]:
        inv = np.linalg.inv(cov)
        A = np.einsum("nai,nab,nbj->ij", X, inv, X)
        rhs = np.einsum("nai,nab,nb->i", X, inv, means)
        C = np.linalg.inv(A)
        beta = C @ rhs
        res = means - np.einsum("nai,i->na", X, beta)
        chi2 = float(np.einsum("na,nab,nb->", res, inv, res))
        return beta, C, chi2

    dof = 3 * (n - 2)
    beta, C, chi2 = gls(base)
    v = 0.0
    if chdtrc(dof, chi2) < 0.01:
        # the poses' biases wander beyond white noise: v I added to each, χ² = dof
        lo, hi = 0.0, float(np.max(np.var(means, axis=0))) * 4.0 + 1e-300
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            if gls(base + mid * np.eye(3))[2] > dof:
                lo = mid
            else:
                hi = mid
        v = hi
        beta, C, chi2 = gls(base + v * np.eye(3))
    slope, Cs = beta[3:], C[3:, 3:]
    z2 = float(slope @ np.linalg.solve(Cs, slope))
    p = float(fdtrc(3, dof, z2 / 3.0)) if v > 0 else float(chdtrc(3, z2))
    return slope, p, v, base + v * np.eye(3)
