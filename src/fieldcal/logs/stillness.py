"""Still-pose detection in a continuous log.

Algorithm (all vectorised; cumulative sums give every moving-window statistic in O(n)); each
sensor's readings are first divided by an exact power of two (:func:`scale_of`), so the
result is the same in any unit, 1e-30 or 1e30:

1. Moving variance of the accelerometer over a centred window of ``window`` samples (the sum of
   the three axes' variances), and, when a gyroscope is present, the moving mean of
   ``|ω − ω_bias|²`` (variance plus squared mean rate, so a steady rotation that leaves the
   accelerometer quiet, as about a vertical axis, still counts as motion).
2. The noise floor is a low quantile (``floor_quantile``, 10 %) of those statistics: in a
   calibration log a good part of the time is spent still, so the quietest tenth of the windows
   shows the sensor's own noise. The threshold is ``factor²`` times that floor (``factor`` is
   a ratio of standard deviations, 3 by default).
3. Runs of windows under the threshold are still intervals; ``trim`` samples are cut at each
   end (the hand settles or starts to move there), and runs shorter than ``min_samples`` are
   dropped.
4. A run whose samples, taken together, exceed the threshold drifted slowly (quiet windows,
   but a slow turn): it is cut into pieces of ``min_samples`` and the still pieces are kept.
5. Adjacent intervals of one pose are merged: a short gap (at most ``max_gap`` samples, e.g.
   a tap on the table) between intervals whose mean readings agree within ``merge_sigma``
   per-sample noise standard deviations; the gap's samples are left out.

A log split at resets of its clock (``segment``, e.g. ``Log.segment``) is detected as one, with
one noise floor, but every moving window stops at a segment's boundary as it stops at the log's
ends, and no run or merge crosses one.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import SHORT_LOG, InputError
from ..limits import power_of_two

#: The message's words for a log shorter than one detection window (a few shots, one a row).

__all__ = ["SHORT_LOG", "Segment", "StillResult", "detect_still", "moving_variance", "scale_of"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Segment:
    """A still interval from ``start`` to ``stop`` (exclusive) of the log as given.

    ``pieces`` are the still runs it is made of (more than one when runs of one pose were
    merged across a short disturbance, whose samples are left out).
    """

    start: int
    stop: int
    std: float
    mean: tuple[float, float, float]
    pieces: tuple[tuple[int, int], ...] = ()

    @property
    def rows(self) -> NDArray[np.int64]:
        """Sample positions of the interval, without the samples of merged-over gaps."""
        pieces = self.pieces or ((self.start, self.stop),)
        return np.concatenate([np.arange(a, b) for a, b in pieces])

    @property
    def samples(self) -> int:
        return len(self.rows)


@dataclass(frozen=True)
class StillResult:
    """Detected segments and the parameters that found them (for the summary and the JSON)."""

    segments: tuple[Segment, ...]
    threshold: float
    noise_floor: float
    window: int
    min_samples: int
    trim: int

    @property
    def threshold_std(self) -> float:
        """The threshold as a standard deviation per axis (same units as the readings)."""
        return float(np.sqrt(self.threshold / 3.0))

    def to_dict(self) -> dict[str, float]:
        return {
            "count": len(self.segments),
            "threshold_var": self.threshold,
            "threshold_std": self.threshold_std,
            "noise_floor_var": self.noise_floor,
            "window": self.window,
            "min_samples": self.min_samples,
            "trim": self.trim,
        }


def _bounds(n: int, segment: NDArray[np.int64] | None) -> NDArray[np.int64]:
    """First rows of the segments after the first (where ``segment`` changes); empty for one."""
    if segment is None:
        return np.empty(0, dtype=np.int64)
    return np.flatnonzero(segment[1:] != segment[:-1]) + 1


def _windows(
    n: int, window: int, breaks: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]] | None:
    """Each row's centred window [lo, hi), truncated at the log's ends and at ``breaks`` (the
    first rows of segments); ``None`` when no window is truncated but at the log's ends (the
    sums then come from slices, without index arrays)."""
    if breaks.size == 0:
        return None
    half = window // 2
    centre = np.arange(n)
    edges = np.concatenate([[0], breaks, [n]])
    piece = np.searchsorted(breaks, centre, side="right")
    lo = np.maximum(centre - half, edges[piece])
    hi = np.minimum(centre + half + 1, edges[piece + 1])
    return lo, hi


def _cumulative(x: Array) -> Array:
    """Cumulative sums along the rows with a leading row of zeros (``c[b] - c[a]`` sums a:b)."""
    out = np.empty((len(x) + 1, *x.shape[1:]))
    out[0] = 0.0
    np.cumsum(x, axis=0, out=out[1:])
    return out


def _window_means(
    c: Array,
    window: int,
    bounds: tuple[NDArray[np.int64], NDArray[np.int64]] | None,
    out: Array | None = None,
) -> Array:
    """Means over each row's window from cumulative sums ``c`` (n + 1 rows): each window's sum
    divided by its count of rows (into ``out`` when given).

    Without ``bounds`` the window is centred and truncated at the log's ends: the middle rows
    are one subtraction of two slices and one division by the full window's count, no
    gathered copies.
    """
    n = len(c) - 1
    shape = (n,) + (1,) * (c.ndim - 1)
    if bounds is not None:
        lo, hi = bounds
        count = (hi - lo).astype(float).reshape(shape)
        return np.divide(np.subtract(c[hi], c[lo], out=out), count, out=out)
    half = window // 2
    a, b = min(half, n), max(min(half, n), n - half)  # rows a..b-1 have full windows
    ends = np.concatenate([np.arange(a), np.arange(b, n)])
    lo, hi = np.clip(ends - half, 0, n), np.clip(ends + half + 1, 0, n)
    means = np.empty((n, *c.shape[1:])) if out is None else out
    middle = np.subtract(c[a + half + 1 : b + half + 1], c[a - half : b - half], out=means[a:b])
    middle /= float(2 * half + 1)
    means[ends] = (c[hi] - c[lo]) / (hi - lo).astype(float).reshape((len(ends), *shape[1:]))
    return means


def moving_variance(x: Array, window: int, segment: NDArray[np.int64] | None = None) -> Array:
    """Sum over columns of the variance in a centred window (truncated at the ends and, when
    ``segment`` is given, where it changes), O(n)."""
    x = np.asarray(x, dtype=float)
    return _moving_variance(x, window, _windows(len(x), window, _bounds(len(x), segment)))


def _moving_variance(
    x: Array, window: int, bounds: tuple[NDArray[np.int64], NDArray[np.int64]] | None
) -> Array:
    return _variance(_sums(x), window, bounds)


def _variance(
    sums: tuple[Array, Array],
    window: int,
    bounds: tuple[NDArray[np.int64], NDArray[np.int64]] | None,
    work: Array | None = None,
) -> Array:
    """The moving variance from the cumulative sums of :func:`_sums`: every step writes into
    the window means (the same operations, in the same order, as with temporaries), the
    mean squares into ``work`` (n, k) when given."""
    mean = _window_means(sums[0], window, bounds)
    var = _window_means(sums[1], window, bounds, out=work)
    var -= np.square(mean, out=mean)
    np.maximum(var, 0.0, out=var)
    if var.shape[1] == 3:  # as .sum(axis=1) (same order), without a strided reduction
        return var[:, 0] + var[:, 1] + var[:, 2]
    return var.sum(axis=1)


def _moving_mean(
    x: Array, window: int, bounds: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None
) -> Array:
    return _window_means(_cumulative(x), window, bounds)


def scale_of(x: Array) -> float:
    """The power of two nearest the largest ``|x|`` (:func:`fieldcal.limits.power_of_two`; 1
    for zeros): dividing by it changes no digit, and the readings become of order one."""
    # the largest |x| as max(max, -min): no temporary array of |x|
    return power_of_two(max(float(np.max(x, initial=0.0)), -float(np.min(x, initial=0.0))))


def _real(value: object, name: str, *, minimum: float, inclusive: bool = True) -> float:
    """A finite real number ``>= minimum`` (``> minimum`` unless ``inclusive``)."""
    number = math.nan  # anything but a real number (a bool is not one here) fails below
    if not isinstance(value, (bool, np.bool_)) and isinstance(value, numbers.Real):
        number = float(value)
    if not (math.isfinite(number) and (number >= minimum if inclusive else number > minimum)):
        bound = f"at least {minimum:g}" if inclusive else f"above {minimum:g}"
        raise InputError(f"{name} must be a finite number {bound}, got {value!r}"[:200])
    return number


def _count(value: object, name: str, minimum: int, n: int) -> int:
    """A whole number of samples ``>= minimum``, capped at ``n + 1`` (no run is longer)."""
    return round(min(_real(value, name, minimum=minimum), n + 1.0))


def _readings(x: object, name: str) -> Array:
    array = np.asarray(x)
    if array.dtype.kind not in "fiu" or array.ndim != 2 or array.shape[1] != 3:
        raise InputError(
            f"{name}: expected an (n, 3) array of real numbers, got "
            f"{array.dtype.name} {list(array.shape)}"
        )
    array = array.astype(np.float64, copy=False)
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name}: NaN or inf readings; drop those rows before still detection")
    return array


def _segments(segment: object, n: int) -> NDArray[np.int64] | None:
    """``segment`` checked: one whole number per sample, or None."""
    if segment is None:
        return None
    array = np.asarray(segment)
    if array.dtype.kind not in "iu" or array.shape != (n,):
        raise InputError(
            f"segment: expected one whole number per sample ({n}), got "
            f"{array.dtype.name} {list(array.shape)}"
        )
    return array.astype(np.int64, copy=False)


def _floor(stat: Array, quantile: float, head: Array, readings: Callable[[], Array]) -> float:
    """``max(quantile of stat, 3 · step² / 12, 1e-300)``, ``step`` the resolution of the
    readings (``head`` their first rows, ``readings()`` all of them)."""
    floor = _quantile(stat, quantile)
    # quantised sensors can show exactly zero variance in a window; the floor is at least the
    # variance of rounding to the sensor's step (step² / 12 per axis). The smallest step of
    # the first rows bounds the step from above: when even that bound cannot win the max,
    # the scan of every row is not needed.
    bound = _smallest_step(head)
    if 3.0 * bound**2 / 12.0 < floor:
        return max(floor, 1e-300)
    return max(floor, 3.0 * _resolution(readings()) ** 2 / 12.0, 1e-300)


#: Rows whose smallest step is tried first as a bound of the readings' resolution.
_HEAD = 4096


def _smallest_step(x: Array) -> float:
    """The smallest non-zero change between successive rows (inf when none)."""
    steps = np.abs(np.diff(x, axis=0))
    return float(np.min(steps, where=steps > 0, initial=np.inf))


def _resolution(x: Array) -> float:
    smallest = _smallest_step(x)
    return smallest if math.isfinite(smallest) else 0.0


def _quantile(x: Array, q: float) -> float:
    """``np.quantile(x, q)`` of a 1-D float array (the default, linear method), the same
    number: the two order statistics around ``(n − 1) q`` by one partition (numpy's
    single-rank partition is a vectorised quickselect; ``np.quantile`` asks for several ranks
    at once and takes a slower one) and numpy's interpolation."""
    n = len(x)
    virtual = (n - 1) * q
    if n == 0 or not 0.0 <= virtual < n - 1:
        return float(np.quantile(x, q))
    below = math.floor(virtual)
    part = np.partition(x, below)
    a, b = float(part[below]), float(part[below + 1 :].min())
    t = virtual - below
    # numpy's _lerp: from the nearer end, so that t = 0 and t = 1 give the ends exactly
    return b - (b - a) * (1 - t) if t >= 0.5 else a + (b - a) * t


def _median_columns(x: Array, rows: NDArray[np.bool_] | None) -> Array:
    """``np.median(x[rows], axis=0)`` (all rows for ``None``), the same numbers: the middle
    pair of each column by one partition, and their mean as numpy takes it."""
    out = np.empty(x.shape[1])
    for j in range(x.shape[1]):
        column = x[:, j] if rows is None else x[:, j][rows]
        m = len(column)
        if m == 0:
            return np.asarray(np.median(x if rows is None else x[rows], axis=0))
        half = m // 2
        part = np.partition(column, half)
        upper = part[half]
        out[j] = upper if m % 2 else np.mean([part[:half].max(), upper])
    return out


#: Samples per block of the gyroscope's drifting-bias track, in detection windows (at least
#: :data:`_BIAS_BLOCK_MIN`), and the still samples each block's median is taken over (at most).
_BIAS_BLOCK_WINDOWS = 20
_BIAS_BLOCK_MIN = 500
_BIAS_SAMPLES = 64


def _local_bias(
    rates: Array, still: NDArray[np.bool_], window: int, overall: Array
) -> tuple[Array, float] | None:
    """The gyroscope's bias as it drifts: the median of the still samples of each block of
    :data:`_BIAS_BLOCK_WINDOWS` windows, interpolated to every sample (n, 3), and the largest
    squared departure of a block's median from the log's, ``overall`` (``None`` with fewer
    than two blocks of still samples). The biases of MEMS gyroscopes move with temperature
    while a board warms up; a constant bias then makes the cold poses read as turning."""
    n = len(rates)
    block = max(_BIAS_BLOCK_WINDOWS * window, _BIAS_BLOCK_MIN)
    positions = np.flatnonzero(still)
    if positions.size == 0 or n < 2 * block:
        return None
    _, starts, counts = np.unique(positions // block, return_index=True, return_counts=True)
    enough = counts >= window
    if np.count_nonzero(enough) < 2:
        return None
    starts, counts = starts[enough], counts[enough]
    k = min(_BIAS_SAMPLES, int(counts.min()))
    picks = positions[starts[:, None] + (np.arange(k)[None, :] * counts[:, None]) // k]
    medians = np.median(rates[picks], axis=1)  # (blocks, 3)
    centres = positions[starts + counts // 2].astype(float)
    everywhere = np.arange(n, dtype=float)
    track = np.column_stack([np.interp(everywhere, centres, medians[:, j]) for j in range(3)])
    departure = float(np.max(np.sum((medians - overall) ** 2, axis=1)))
    return track, departure


def _runs(mask: NDArray[np.bool_], breaks: NDArray[np.int64]) -> NDArray[np.int64]:
    """(k, 2) start/stop (exclusive) of the runs of True, cut at ``breaks`` (segment starts)."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    if breaks.size:
        across = breaks[mask[breaks] & mask[breaks - 1]]  # a run across a segment's start
        starts = np.sort(np.concatenate([starts, across]))
        stops = np.sort(np.concatenate([stops, across]))
    return np.column_stack([starts, stops])


def detect_still(
    accel: Array,
    gyro: Array | None = None,
    *,
    window: float = 25,
    min_samples: float = 50,
    trim: float | None = None,
    factor: float = 3.0,
    threshold: float | None = None,
    floor_quantile: float = 0.1,
    max_gap: float | None = None,
    merge_sigma: float = 5.0,
    segment: NDArray[np.int64] | None = None,
) -> StillResult:
    """Find the intervals in which the device rests.

    Parameters
    ----------
    accel : (n, 3) array
        Accelerometer samples (any units).
    gyro : (n, 3) array, optional
        Gyroscope samples; when given, a window must also be quiet in rotation.
    window : int
        Moving-window length in samples (made odd).
    min_samples : int
        Shortest still interval kept, after trimming.
    trim : int, optional
        Samples cut at each end of an interval (default a quarter window).
    factor : float
        Threshold as a multiple of the noise floor's standard deviation.
    threshold : float, optional
        Accelerometer threshold given directly, as a per-axis standard deviation in the
        readings' units (overrides ``factor`` for the accelerometer).
    floor_quantile : float
        Quantile of the window statistics taken as the noise floor.
    max_gap : int, optional
        Longest gap bridged when merging adjacent intervals of one pose (default one window).
    merge_sigma : float
        Two intervals are one pose when their means differ by less than this many per-sample
        noise standard deviations.
    segment : (n,) array of int, optional
        Segment of each sample (e.g. ``Log.segment``, the log split at resets of its clock):
        no moving window, still interval or merge spans a change of segment.

    Numbers of samples may be given as floats (rounded); every parameter is checked (finite,
    in range) with a one-line :class:`~fieldcal.errors.InputError`.
    """
    raw = _readings(accel, "accel")
    n = len(raw)
    counts = _sample_counts(window, min_samples, trim, max_gap, n)
    trim, min_samples, window, max_gap = counts
    factor = _real(factor, "factor", minimum=0.0, inclusive=False)
    floor_quantile = _real(floor_quantile, "floor_quantile", minimum=0.0)
    if floor_quantile > 1:
        raise InputError(f"floor_quantile must be in [0, 1], got {floor_quantile!r}")
    merge_sigma = _real(merge_sigma, "merge_sigma", minimum=0.0)
    if threshold is not None:
        threshold = _real(threshold, "threshold", minimum=0.0, inclusive=False)
    breaks = _bounds(n, _segments(segment, n))
    bounds = _windows(n, window, breaks)
    # readings of order one in any unit: every statistic below is in these scaled units
    scale = scale_of(raw)
    accel = raw / scale

    with np.errstate(over="ignore", under="ignore"):  # a threshold beyond range is refused below
        # the cumulative sums serve the moving variance here and the runs' statistics below
        work = np.empty_like(accel)  # the centred readings, then the windows' mean squares
        sums = _sums(accel, work)
        var_a = _variance(sums, window, bounds, work)
        del work
        floor_a = _floor(var_a, floor_quantile, accel[: _HEAD + 1], lambda: accel)
        thr_a = np.float64(factor) ** 2 * floor_a
        if threshold is not None:
            thr_a = 3.0 * (np.float64(threshold) / scale) ** 2
        reported = (float(thr_a) * scale * scale, float(floor_a) * scale * scale)
    if not (np.isfinite(thr_a) and thr_a > 0 and all(map(math.isfinite, reported))):
        raise InputError(
            f"the still threshold ({'factor' if threshold is None else 'threshold'}) is out of "
            "the range floating point can hold; give a value nearer the readings' noise"
        )
    still = var_a < thr_a
    if gyro is not None:
        still &= _turns_little(gyro, still, window, bounds, floor_quantile, factor)

    segments = _still_segments(raw, accel, sums, still, breaks, counts, thr_a, floor_a, merge_sigma)
    return StillResult(
        segments=tuple(segments),
        threshold=reported[0],
        noise_floor=reported[1],
        window=window,
        min_samples=int(min_samples),
        trim=trim,
    )


def _sample_counts(
    window: float, min_samples: float, trim: float | None, max_gap: float | None, n: int
) -> tuple[int, int, int, int]:
    """The detector's numbers of samples checked and rounded (the window made odd, the trim a
    quarter window and the gap one window by default): ``(trim, min_samples, window,
    max_gap)``; a log shorter than one window is refused (``SHORT_LOG``)."""
    length = _real(window, "window", minimum=1.0)
    window = max(3, _count(length, "window", 1, n) | 1)
    min_samples = _count(min_samples, "min_samples", 1, n)
    trim = window // 4 if trim is None else _count(trim, "trim", 0, n)
    max_gap = window if max_gap is None else _count(max_gap, "max_gap", 0, n)
    if n < window:
        raise InputError(
            f"the log has {n} samples, fewer than one detection window "
            f"({max(window, length):.6g}); record longer or give a shorter window",
            code=SHORT_LOG,
        )
    return trim, min_samples, window, max_gap


def _still_segments(
    raw: Array,
    accel: Array,
    sums: tuple[Array, Array],
    still: NDArray[np.bool_],
    breaks: NDArray[np.int64],
    counts: tuple[int, int, int, int],
    thr_a: float,
    floor_a: float,
    merge_sigma: float,
) -> list[Segment]:
    """The still windows as rests: runs trimmed (``counts``: trim, min_samples, window,
    max_gap), a slowly drifting run cut into pieces that are still as a whole, the runs of
    one pose merged across a short disturbance, the rests of at least ``min_samples`` kept."""
    trim, min_samples, window, max_gap = counts
    runs = _runs(still, breaks)
    runs[:, 0] += trim
    runs[:, 1] -= trim
    runs = runs[runs[:, 1] - runs[:, 0] >= max(1, min(min_samples, 3))]
    # quiet windows can still drift slowly (a slow turn): such a run is cut into pieces of
    # min_samples and only the pieces that are still as a whole are kept
    runs = _split_drifting(sums, runs, thr_a, max(min_samples, window))
    piece = np.searchsorted(breaks, runs[:, 0], side="right")  # each run's segment
    tol = merge_sigma * np.sqrt(floor_a / 3.0)
    groups = _merge(accel, sums, runs, piece, max_gap, tol, thr_a)
    longest = max((int(np.sum(runs[g, 1] - runs[g, 0])) for g in groups), default=0)
    work = np.empty(9 * longest)  # reused by every segment's statistics: no new pages each
    segments = [
        s for s in (_segment(raw, runs[g], work) for g in groups) if s.samples >= min_samples
    ]
    return segments


def _turns_little(
    gyro: Array,
    still: NDArray[np.bool_],
    window: int,
    bounds: tuple[NDArray[np.int64], NDArray[np.int64]] | None,
    floor_quantile: float,
    factor: float,
) -> NDArray[np.bool_]:
    """The windows quiet in rotation: the gyroscope's energy about its bias (its median over
    the samples the accelerometer calls ``still``, or the bias of the time when it drifts)
    under ``factor``² times its noise floor."""
    n = len(still)
    rates = _readings(gyro, "gyro")
    if len(rates) != n:
        raise InputError(f"gyro has {len(rates)} samples but accel has {n}; pass equal rows")
    unit = scale_of(rates)
    rates = rates / unit
    head = rates[: _HEAD + 1].copy()
    # the gyro's bias is its median over the samples the accelerometer calls still
    bias = _median_columns(rates, still if np.any(still) else None)
    local = _local_bias(rates, still, window, bias)
    d = np.subtract(rates, bias, out=rates)  # the scaled rates are made again if needed
    np.multiply(d, d, out=d)  # as ** 2; the axes summed as .sum(axis=1) sums them
    energy = _moving_mean(d[:, 0] + d[:, 1] + d[:, 2], window, bounds)
    del rates, d
    gyro_readings = gyro
    floor_g = _floor(energy, floor_quantile, head, lambda: _readings(gyro_readings, "gyro") / unit)
    if local is not None and local[1] > (np.float64(factor) ** 2 - 1.0) * floor_g:
        # the bias drifts (a board warming up) by enough to push a resting window past the
        # threshold on its own: measure the rotation against the bias of the time, or the
        # cold poses read as turning. A smaller departure cannot hide a pose, and on
        # hand-held logs it is mostly the hand's motion in the block medians (measured: 4x
        # the floor on the ICM-20948 session 3; 12-13x on a simulated 20 K warm-up).
        d = _readings(gyro, "gyro") / unit - local[0]
        energy = _moving_mean(np.einsum("ij,ij->i", d, d), window, bounds)
        floor_g = _floor(energy, floor_quantile, head, lambda: d)
        del d
    with np.errstate(over="ignore"):
        return np.asarray(energy < np.float64(factor) ** 2 * floor_g)


def _var(c1: Array, c2: Array, runs: NDArray[np.int64]) -> tuple[Array, Array]:
    """Means (k, 3) and total variances (k,) of runs, from cumulative sums."""
    n = (runs[:, 1] - runs[:, 0])[:, None]
    mean = (c1[runs[:, 1]] - c1[runs[:, 0]]) / n
    var = ((c2[runs[:, 1]] - c2[runs[:, 0]]) / n - mean**2).sum(axis=1)
    return mean, var


def _sums(x: Array, work: Array | None = None) -> tuple[Array, Array]:
    """Cumulative sums of the centred readings and of their squares (computed once, for the
    moving variance and for the runs' statistics); ``work``, like ``x``, is written into."""
    centred = np.empty_like(x, order="C") if work is None else work
    # centring keeps the cumulative sums from losing precision; the mean's running sums go
    # through the centred copy's memory before it is written
    mean = _column_sums(x, centred) / len(x)
    np.subtract(x, mean, out=centred)
    c1 = _cumulative(centred)
    return c1, _cumulative(np.multiply(centred, centred, out=centred))


def _column_sums(x: Array, work: Array | None = None) -> Array:
    """``x.sum(axis=0)`` of an (n, k) array, the same numbers: numpy adds the rows of a
    C-ordered array one after the other, which is what a running sum does (faster, as its
    inner loop runs along each column rather than across one row at a time). ``work``, of
    at least ``x.size`` floats, takes the running sums."""
    if x.ndim != 2 or len(x) == 0 or not x.flags.c_contiguous:
        return np.asarray(x.sum(axis=0))
    out = None if work is None else work.reshape(-1)[: x.size].reshape(x.shape[::-1])
    return np.add.accumulate(x.T, axis=1, out=out)[:, -1].copy()


def _mean_var(x: Array, work: Array | None = None) -> tuple[Array, Array]:
    """``x.mean(axis=0)`` and ``x.var(axis=0)`` of an (n, k) C-ordered array, the same numbers
    (numpy's two passes: the mean, then the mean square of the deviations from it) with one
    sum of the rows for both. ``work``, of at least ``2 x.size`` floats, is written into
    instead of new arrays."""
    n = len(x)
    if work is None:
        work = np.empty(2 * x.size)
    d = work.reshape(-1)[: x.size].reshape(x.shape)
    spare = work.reshape(-1)[x.size : 2 * x.size]
    mean = _column_sums(x, spare) / n
    np.subtract(x, mean, out=d)
    return mean, _column_sums(np.multiply(d, d, out=d), spare) / n


def _split_drifting(
    sums: tuple[Array, Array] | None, runs: NDArray[np.int64], threshold: float, length: int
) -> NDArray[np.int64]:
    if len(runs) == 0 or sums is None:
        return runs
    c1, c2 = sums
    _, var = _var(c1, c2, runs)
    pieces = [runs[var < threshold]]
    for a, b in runs[var >= threshold]:  # a loop over runs, not samples
        edges = np.arange(a, b + 1, length)
        if len(edges) < 2:
            continue
        edges[-1] = b
        chunks = np.column_stack([edges[:-1], edges[1:]])
        pieces.append(chunks[_var(c1, c2, chunks)[1] < threshold])
    runs = np.concatenate(pieces)
    return runs[np.argsort(runs[:, 0])]


def _merge(
    accel: Array,
    sums: tuple[Array, Array] | None,
    runs: NDArray[np.int64],
    piece: NDArray[np.int64],
    max_gap: int,
    tol: float,
    threshold: float,
) -> list[NDArray[np.int64]]:
    """Group consecutive runs of one segment (``piece``) separated by a short gap and agreeing
    in their mean reading.

    A group whose pooled samples are not still as a whole (slow drift across the pieces) falls
    back to its pieces.
    """
    if len(runs) == 0 or sums is None:
        return []
    means, _ = _var(*sums, runs)
    gap = runs[1:, 0] - runs[:-1, 1]
    same = (gap <= max_gap) & (np.linalg.norm(np.diff(means, axis=0), axis=1) < tol)
    same &= piece[1:] == piece[:-1]
    starts = np.flatnonzero(np.concatenate([[True], ~same]))
    groups = np.split(np.arange(len(runs)), starts[1:])
    out: list[NDArray[np.int64]] = []
    for group in groups:
        if len(group) == 1:  # most groups: nothing pooled, nothing to check
            out.append(group)
            continue
        rows = np.concatenate([np.arange(a, b) for a, b in runs[group]])
        if accel[rows].var(axis=0).sum() >= threshold:
            out.extend(g[None] for g in group)
        else:
            out.append(group)
    return out


def _segment(raw: Array, runs: NDArray[np.int64], work: Array | None = None) -> Segment:
    """The segment of ``runs`` of the readings ``raw``; its statistics are computed on the
    readings over the power of two nearest their largest value, as
    :func:`fieldcal.logs.pose_finding.poses_from_log` reports a pose's spread (the same numbers, so
    it takes them from here). ``work``, of at least 9 floats per sample, is written into."""
    pieces = tuple((int(a), int(b)) for a, b in runs)
    if len(pieces) == 1:
        part = raw[pieces[0][0] : pieces[0][1]]  # a view: one run needs no gathered copy
    else:
        part = raw[np.concatenate([np.arange(a, b) for a, b in pieces])]
    scale = scale_of(part)
    if work is None:
        work = np.empty(9 * len(part))
    scaled = np.divide(part, scale, out=work[: part.size].reshape(part.shape))
    mean, var = _mean_var(scaled, work[part.size :])
    std = float(np.sqrt(np.mean(var))) * scale
    mean = mean * scale
    return Segment(
        pieces[0][0],
        pieces[-1][1],
        std,
        (float(mean[0]), float(mean[1]), float(mean[2])),
        pieces if len(pieces) > 1 else (),
    )
