"""Samples within a pose that are not still (a bump, a tap) are cut before Eq. 5 and Eq. 7.

Each sample is compared with its pose's median, per axis, in units of the sensor's robust
within-pose scatter: ``d² = Σ_axes ((x − median_i) / s)²`` with ``s = 1.4826 · MAD`` pooled over
the poses (the median of the poses' MADs, so one shaken pose does not set its own scale). For a
Gaussian sample ``d²`` follows χ²(3) closely; samples with ``d²`` beyond the
``1 − 10⁻⁵`` quantile are cut (about one false cut per 100,000 samples, far too few to bias
Eq. 7). Poses with fewer than :data:`MIN_SAMPLES` samples are left as they are. A sensor whose
readings do not vary within poses (scale 0, e.g. a coarse quantiser) is not trimmed.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["CUT", "MIN_SAMPLES", "Unsteady", "trim_unsteady", "unsteady"]

Array = NDArray[np.float64]

#: χ²(3) quantile at 1 − 1e-5: the squared robust distance beyond which a sample is cut.
CUT = 25.9
#: Fewest samples in a pose for a robust median.
MIN_SAMPLES = 10
#: Poses with at least this many samples have their order statistics selected one pose at a
#: time (linear-time partitions); the smaller ones between them share one sort, which costs
#: less than a few numpy calls per pose.
SELECT = 2048


def trim_unsteady(
    stacked: Array, counts: NDArray[np.int64]
) -> tuple[Array, NDArray[np.int64], NDArray[np.int64]]:
    """Cut unsteady samples from concatenated poses.

    Parameters
    ----------
    stacked : (ΣΔ, 3) array
        The poses' samples, one pose after the other.
    counts : (N,) int array
        Samples per pose.

    Returns
    -------
    kept : (ΣΔ', 3) array
        The samples kept, in order (``stacked`` itself when none is cut).
    kept_counts, trimmed : (N,) int arrays
        Samples kept and cut per pose. A pose never loses more than half its samples: the
        median stays inside what is kept.
    """
    x = np.array(
        stacked.T, order="C"
    )  # a copy (even of an F-ordered array): unsteady overwrites it
    found = unsteady(x, counts, np.empty((4, x.shape[1])))
    if found.cut is None:
        return stacked, counts, found.trimmed
    return stacked[~found.cut], counts - found.trimmed, found.trimmed


@dataclass
class Unsteady:
    """What :func:`unsteady` found, and what it computed on the way that Eq. 5 and 7 reuse.

    Attributes
    ----------
    cut : (ΣΔ,) bool array or None
        The samples to cut (``None``: none).
    trimmed : (N,) int array
        Samples cut per pose.
    medians : (3, N) array
        Each pose's median per axis.
    deviations, squares : (3, ΣΔ) arrays
        Each sample minus its pose's median, and its square (views into the work space).
    """

    cut: NDArray[np.bool_] | None
    trimmed: NDArray[np.int64]
    medians: Array
    deviations: Array
    squares: Array


def unsteady(
    x: Array,
    counts: NDArray[np.int64],
    work: Array,
    *,
    extremes: tuple[Array, Array] | None = None,
) -> Unsteady:
    """The samples to cut, for concatenated poses with the axes as rows.

    Parameters
    ----------
    x : (3, ΣΔ) array
        The poses' samples, one pose after the other; overwritten by their squared
        deviations from their pose's median (``Unsteady.squares``).
    counts : (N,) int array
        Samples per pose.
    work : (4, ΣΔ) array
        Work space (overwritten; more rows are allowed and left alone): the steps write into
        it rather than into temporaries of the data's size; the deviations returned live in
        its rows 0 to 2.
    extremes : ((3,), (3,)) arrays, optional
        The smallest and largest sample of each axis, when already known (else computed).

    A large pose is worked through one axis at a time while its samples are in the CPU's
    cache (copy, order statistics, deviations, squares), its copy in one small array reused
    by every pose; runs of small poses share one sort.
    """
    n = len(counts)
    trimmed = np.zeros(n, dtype=np.int64)
    deviations, row = work[:3], work[3]
    starts = np.cumsum(counts) - counts
    eligible = counts >= MIN_SAMPLES
    # beside the medians, two order statistics per pose that bound its MAD from below
    lo = (counts - 1) // 2
    a = lo // 2
    ranks = np.column_stack([a, lo, counts // 2, a + lo + 1])
    ranks[~eligible, 0] = ranks[~eligible, 3] = -1  # not needed: no MAD bound for them
    low, high = (x.min(axis=1), x.max(axis=1)) if extremes is None else extremes
    span = _span(low, high)
    stats = np.full((4, 3, n), np.nan)
    copy = np.empty(_largest(counts, counts >= SELECT))  # the selection reorders its input
    for i, s, e, distinct, back, wanted in _large(starts, counts, ranks):
        for axis in range(3):
            part = copy[: e - s]
            np.copyto(part, x[axis, s:e])
            picked = np.array(_select(part, distinct))[back]
            stats[wanted, axis, i] = _keyed(picked, i, float(low[axis]), float(span[axis]))
            median = 0.5 * (stats[1, axis, i] + stats[2, axis, i])
            d = np.subtract(x[axis, s:e], median, out=deviations[axis, s:e])
            np.multiply(d, d, out=x[axis, s:e])  # the samples are not needed again
    runs = list(_small(starts, counts))
    # each run's keys sorted (the MADs read the readings back from them), side by side
    ordered = np.empty((3, _largest(counts, counts < SELECT, total=True)))
    done = 0
    for p0, p1, c0, c1 in runs:
        block = ordered[:, done : done + c1 - c0]
        done += c1 - c0
        stats[:, :, p0:p1] = _sorted(x[:, c0:c1], block, p0, counts[p0:p1], ranks[p0:p1], low, span)
        median = 0.5 * (stats[1, :, p0:p1] + stats[2, :, p0:p1])
        d = deviations[:, c0:c1]
        np.subtract(x[:, c0:c1], np.repeat(median, counts[p0:p1], axis=1), out=d)
        np.multiply(d, d, out=x[:, c0:c1])
    medians = 0.5 * (stats[1] + stats[2])
    squares = x
    found = Unsteady(None, trimmed, medians, deviations, squares)
    if not eligible.any():
        return found
    y_a, y_b = stats[0][:, eligible], stats[3][:, eligible]
    if _none_cut(squares, medians[:, eligible], y_a, y_b, row):
        return found
    done = 0
    for p0, p1, c0, c1 in runs:  # the runs' sorted keys back to readings
        _readings(ordered[:, done : done + c1 - c0], p0, counts[p0:p1], low, span)
        done += c1 - c0
    mads = _mads(deviations, starts, counts, ranks[:, 1:3], ordered, runs, medians)
    scale = 1.4826 * _median(mads[:, eligible])
    usable = scale > 0
    if not usable.any():
        return found
    where = _beyond(deviations, squares, scale, usable, row)
    if where.size == 0:
        return found
    pose = np.searchsorted(starts, where, side="right") - 1
    where, pose = where[eligible[pose]], pose[eligible[pose]]
    trimmed = np.bincount(pose, minlength=n).astype(np.int64)
    too_many = trimmed > counts // 2  # a pose mostly "unsteady": keep it whole, let tests judge it
    if too_many.any():
        where = where[~too_many[pose]]
        trimmed[too_many] = 0
    if where.size == 0:
        return found
    cut = np.zeros(x.shape[1], dtype=bool)
    cut[where] = True
    return Unsteady(cut, trimmed, medians, deviations, squares)


def _mads(
    deviations: Array,
    starts: NDArray[np.int64],
    counts: NDArray[np.int64],
    ranks: NDArray[np.int64],
    ordered: Array,
    runs: list[tuple[int, int, int, int]],
    medians: Array,
) -> Array:
    """(3, N): each pose's median absolute deviation per axis, the mean of the absolute
    deviations of ranks ``ranks`` (N, 2).

    A large pose selects them from its absolute deviations (partitions); the small poses read
    them from their sorted readings ``ordered`` (the runs side by side, as :func:`unsteady`
    sorted them), without a second sort: :func:`_window_order`."""
    n = len(counts)
    stats = np.full((2, 3, n), np.nan)
    part_of = np.empty(_largest(counts, counts >= SELECT))
    for i, s, e, distinct, back, wanted in _large(starts, counts, ranks):
        for axis in range(3):
            part = np.abs(deviations[axis, s:e], out=part_of[: e - s])
            stats[wanted, axis, i] = np.array(_select(part, distinct))[back]
    done = 0
    for p0, p1, c0, c1 in runs:
        y = ordered[:, done : done + c1 - c0]
        done += c1 - c0
        stats[:, :, p0:p1] = _window_order(y, counts[p0:p1], ranks[p0:p1], medians[:, p0:p1])
    return np.asarray(0.5 * (stats[0] + stats[1]))


def _window_order(y: Array, counts: NDArray[np.int64], ranks: NDArray[np.int64], m: Array) -> Array:
    """(r, 3, k): the absolute deviations ``|y − m|`` of ranks ``ranks`` (k, r) of consecutive
    poses whose readings ``y`` (3, Σ counts) are sorted within each pose, ``m`` (3, k) their
    medians.

    The ``q + 1`` readings nearest the median are ``q + 1`` consecutive sorted ones, a window
    ``y[p .. p + q]``, and the absolute deviation of rank ``q`` is the smallest over the
    windows of their farther end, ``min_p max(m − y[p], y[p + q] − m)``: the first term falls
    and the second rises with ``p``, so the best window is where they cross, found by a
    binary search over ``p`` for every pose, axis and rank at once (``log₂ n`` vectorised
    steps, no sort). The readings are those the key sort gives back (:func:`_sorted`), so the
    deviations are those of the sorted keys' values, as the medians are."""
    k = len(counts)
    L = y.shape[1]
    starts = np.cumsum(counts) - counts
    flat = y.reshape(-1)
    # (3, k, r): the first sample of each pose in ``flat``, each rank, each median
    base = (np.arange(3)[:, None] * L + starts[None, :])[:, :, None]
    q = np.broadcast_to(ranks[None, :, :], (3, k, ranks.shape[1]))
    mid_value = m[:, :, None]
    top = np.broadcast_to((counts[:, None] - ranks)[None], q.shape)  # windows p in [0, top)
    # the search runs on positions in ``flat`` (base + p): fewer numpy calls per step, each a
    # few µs on these small arrays. The first crossed window is in [lo, hi]; where none is
    # (hi = top) lo may pass hi, hence min(lo, hi) after the loop.
    lo = base + np.zeros_like(q)
    hi = base + top
    last = hi - 1
    for _ in range(int(top.max()).bit_length()):
        p = (lo + hi) >> 1
        at = np.minimum(p, last)
        crossed = (flat[at + q] - mid_value) >= (mid_value - flat[at])
        hi = np.where(crossed, p, hi)
        lo = np.where(crossed, lo, p + 1)
    lo = np.minimum(lo, hi) - base
    # the best window is the first crossed one (its far end) or the one before (its near end)
    after = np.where(lo < top, flat[base + np.minimum(lo, top - 1) + q] - mid_value, np.inf)
    before = np.where(lo > 0, mid_value - flat[base + np.maximum(lo - 1, 0)], np.inf)
    return np.moveaxis(np.minimum(after, before), 2, 0)


def _beyond(
    deviations: Array, squares: Array, scale: Array, usable: NDArray[np.bool_], work: Array
) -> NDArray[np.intp]:
    """Positions of the samples whose ``d² = (3 / axes) Σ (deviation / scale)²`` (over the
    usable axes) exceeds :data:`CUT`.

    ``d²`` is written plainly, ``(z₀² + z₁²) + z₂²`` with ``z = deviation / scale``: the
    numbers ``np.einsum("ij,ij->j", z, z)`` gives for a (3, ΣΔ) array. It is computed only
    for the few candidates that ``squares`` weighted by ``1 / scale²`` (one product, no
    division of every sample) does not rule out; that weighted sum and ``d²`` differ by a few
    roundings, far inside the margin of 10⁻⁹.
    """
    factor = 3.0 / usable.sum()
    with np.errstate(divide="ignore"):
        weights = np.where(usable, 1.0 / (scale * scale), 0.0)
    np.matmul(weights, squares, out=work)
    candidates = np.flatnonzero(work > CUT * (1.0 - 1e-9) / factor)
    if candidates.size == 0:
        return candidates
    rows = np.flatnonzero(usable)
    z = deviations[np.ix_(rows, candidates)] / scale[rows, None]
    d2 = z[0] * z[0]
    for row in z[1:]:
        d2 += row * row
    d2 *= factor
    return candidates[d2 > CUT]


def _none_cut(squares: Array, medians: Array, y_a: Array, y_b: Array, d2: Array) -> bool:
    """True when no sample can be cut, proven without the MADs (which take a second pass of
    selection).

    In a pose's sorted samples ``y``, take positions ``a`` and ``b = a + lo + 1`` around the
    median ``m`` (``lo = (n − 1) // 2``). A deviation ``|y − m|`` below
    ``L = min(m − y_a, y_b − m)`` puts ``y`` strictly between ``y_a`` and ``y_b``: at most
    ``lo`` samples, so the MAD (the mean of the deviations ranked ``lo`` and ``lo + 1``) is at
    least ``L``. The scale from these ``L`` (the same median over the poses) is then at most
    the true scale, and every ``d²`` it gives at least the true one: if none of these reaches
    :data:`CUT` (with a margin far above rounding), none of the true ones does. Usually the
    case for a still session; ``squares`` holds the squared deviations from the medians.
    """
    bound = 1.4826 * _median(np.minimum(medians - y_a, y_b - medians)) * (1.0 - 1e-6)
    if not np.all(bound > 0):
        return False
    np.matmul(1.0 / (bound * bound), squares, out=d2)
    return bool(d2.max() <= CUT * (1.0 - 1e-6))


def _median(x: Array) -> Array:
    """``np.median(x, axis=1)`` (the same numbers) without its fixed cost: sort, mean of the
    middle pair."""
    ranked = np.sort(x, axis=1)
    k = x.shape[1]
    return np.asarray((ranked[:, (k - 1) // 2] + ranked[:, k // 2]) / 2.0)


def _largest(counts: NDArray[np.int64], which: NDArray[np.bool_], *, total: bool = False) -> int:
    """The most samples of the poses ``which`` (their sum with ``total``); 0 for none."""
    chosen = counts[which]
    return int(chosen.sum() if total else chosen.max(initial=0))


def _span(low: Array, high: Array) -> Array:
    """Twice each axis's range, 1 where it is 0: the keys' spacing between poses (relative to
    the data's own range: readings may be 1e-30 or 1e30)."""
    span = 2.0 * (high - low)
    span[span == 0] = 1.0
    return np.asarray(span)


def _large(
    starts: NDArray[np.int64], counts: NDArray[np.int64], ranks: NDArray[np.int64]
) -> Iterator[tuple[int, int, int, list[int], NDArray[np.intp], NDArray[np.bool_]]]:
    """For each pose of at least :data:`SELECT` samples: its index, first and last + 1
    sample, its distinct ranks wanted (increasing), where each wanted rank is among them, and
    which of the ranks are wanted (``-1``: not)."""
    for i in np.flatnonzero(counts >= SELECT).tolist():
        wanted = ranks[i] >= 0
        distinct, back = np.unique(ranks[i][wanted], return_inverse=True)
        s = int(starts[i])
        yield i, s, s + int(counts[i]), distinct.tolist(), back, wanted


def _small(
    starts: NDArray[np.int64], counts: NDArray[np.int64]
) -> Iterator[tuple[int, int, int, int]]:
    """Runs of consecutive poses of fewer than :data:`SELECT` samples: first pose, last + 1,
    first sample, last + 1."""
    if counts.max() < SELECT:  # the usual case: one run of every pose
        yield 0, len(counts), 0, int(starts[-1] + counts[-1])
        return
    small = (counts < SELECT).view(np.int8)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], small, [0]])))
    for p0, p1 in zip(edges[0::2].tolist(), edges[1::2].tolist(), strict=True):
        yield p0, p1, int(starts[p0]), int(starts[p1 - 1] + counts[p1 - 1])


def _keyed(values: Array, pose: int, low: float, span: float) -> Array:
    """Readings of ``pose`` as sorting the keys gives them back (see :func:`_sorted`):
    ``key = (x − low) + pose · span``, then ``key − pose · span + low``. The key is a
    non-decreasing function of the reading, so the key of a pose's reading of rank ``r`` is
    its key of rank ``r``: a large pose's readings are selected by partitions (linear time)
    and only the selected ones go through this arithmetic, the same numbers, bit for bit."""
    shift = pose * span
    keys = (values - low) + shift
    return (keys - shift) + low


def _sorted(
    x: Array,
    keys: Array,
    first: int,
    counts: NDArray[np.int64],
    ranks: NDArray[np.int64],
    low: Array,
    span: Array,
) -> Array:
    """Order statistics of consecutive poses ``first, first + 1, ...`` whose samples are ``x``
    (3, Σ counts): (r, 3, len(counts)), NaN where a rank is -1 (not wanted). ``keys`` (the
    shape of ``x``) receives their sorted keys (:func:`_readings` reads them back).

    One sort of ``key = pose · span + (x − low)`` (``low`` the smallest reading, ``span``
    twice the range, per axis) orders the samples by pose, then by value, with a rounding far
    below any sensor's resolution: each pose's ranks sit at fixed positions of the sorted
    keys, and ``key − pose · span + low`` gives back its readings.
    """
    k = len(counts)
    out = np.full((ranks.shape[1], x.shape[0], k), np.nan)
    starts = np.cumsum(counts) - counts
    np.subtract(x, low[:, None], out=keys)
    keys += _shifts(first, counts, span)
    keys.sort(axis=1)
    j, pose = np.nonzero((ranks >= 0).T)
    at = starts[pose] + ranks[pose, j]
    shift = np.multiply(pose + first, span[:, None])
    out[j, :, pose] = ((keys[:, at] - shift) + low[:, None]).T
    return out


def _shifts(first: int, counts: NDArray[np.int64], span: Array) -> Array:
    """(3, Σ counts): each sample's ``pose · span``, its pose's shift of the keys."""
    return np.repeat(np.multiply.outer(span, np.arange(first, first + len(counts))), counts, 1)


def _readings(keys: Array, first: int, counts: NDArray[np.int64], low: Array, span: Array) -> Array:
    """The sorted keys of :func:`_sorted` back to readings, in place: each pose's keys stay in
    its place, so ``key − pose · span + low`` gives its readings sorted (the numbers
    :func:`_sorted` gives at the ranks it reads)."""
    keys -= _shifts(first, counts, span)
    keys += low[:, None]
    return keys


def _select(row: Array, ranks: list[int]) -> list[float]:
    """The values of ``row`` (1-D, reordered in place) at the sorted positions ``ranks``
    (increasing, distinct), by partitions around one rank at a time: numpy's single-rank
    partition is a vectorised quickselect, several ranks at once fall back to a slower one."""
    if not ranks:
        return []
    m = len(row)
    if ranks[-1] == m - 1:  # the largest: no partition needed
        return [*_select(row, ranks[:-1]), float(row.max())]
    if ranks[0] == 0:
        return [float(row.min()), *_select(row, ranks[1:])]
    j = len(ranks) // 2
    r = ranks[j]
    row.partition(r)
    left = _select(row[:r], ranks[:j])
    right = _select(row[r + 1 :], [q - r - 1 for q in ranks[j + 1 :]])
    return [*left, float(row[r]), *right]
