"""From a log to poses: rows grouped by a pose column, still intervals detected, or a slowly
turning log cut into short windows; each pose's orientation label (revisits of one orientation
share one).

Windows (``poses="windows"``) are for logs with no rests, collected the Magneto/MotionCal way:
the board is turned slowly by hand for a minute. Each window of :data:`WINDOW` (0.25 s) is one
pose; fieldcal's pose-level noise absorbs what moves inside a window, as long as that is small
against the field: the mean of readings spread over an arc lies inside the sphere by about
(arc)²/24 of its radius. Before cutting, the log is checked: the median over the windows of the
change of the mean across a window (second half against first half) and of the spread of the
readings about the mean (the sensor's white noise, from successive differences, taken out), each
against the field's norm, must stay under :data:`MOTION_LIMIT` (5 %) in all but the
fastest tenth of the windows (the 90th percentile, :data:`MOTION_PERCENTILE`: a median let a
log that is half rests pass at "0 %" however fast the other half turned). At that limit a steady
turn sweeps 0.1 rad per window, which shrinks the window mean by 0.04 % of |g|; a wobble of 5 %
spread shrinks it by about 0.1 %, the order of a good accelerometer's calibration accuracy.
0.25 s windows then allow about 23°/s, a slow turn by hand (a full turn in 16 s), and still hold
25 samples at 100 Hz. A log that turns too fast is refused with a window length that the
same check accepts on it: the direction's rate of change measured in the windows gives the
first guess, which is then measured and shortened until it passes.

Samples (``poses="samples"``) are for slow logs without a gyroscope, however sparse (Magneto's
examples: about 3 rows/s, no time column): each sample is its own pose and the pose-level noise
absorbs the motion; a dense log is grouped into short windows so that it gives at most
:data:`MAX_SAMPLE_POSES` poses, never longer than the motion check accepts. Neighbouring poses
share the motion: the fit widens its error bars for the correlation it measures between them
(:mod:`fieldcal.trust.correlation`).
"""

from __future__ import annotations

import math
import numbers
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import NO_STILL, InputError, MovingRestsWarning
from .log import Log
from .orientation_labels import orientation_labels, unit_directions
from .pose_set import MOTION_PERCENTILE, PoseEntry, PoseSet, WindowCut
from .stillness import SHORT_LOG, Segment, detect_still, scale_of

__all__ = [
    "MOTION_LIMIT",
    "NO_STILL",
    "POSE_SOURCES",
    "SHORT_LOG",
    "WINDOW",
    "PoseEntry",
    "PoseSet",
    "WindowCut",
    "orientation_labels",
    "poses_from_log",
    "poses_orientations",
    "turns_slowly",
]

Array = NDArray[np.float64]
Rows = NDArray[np.int64]

#: How a log without a pose column is cut into poses (``poses=``).
POSE_SOURCES = ("still", "windows", "samples")
#: Default window of ``poses="windows"``: seconds when the rate is known, else samples.
WINDOW = (0.25, 25)
#: Largest motion within a window, against the field's norm, for ``poses="windows"``.
MOTION_LIMIT = 0.05
#: ``poses="samples"``: a dense log is grouped into short windows beyond this many poses.
MAX_SAMPLE_POSES = 3000
#: A rate given and the time column's may differ by this much before a warning.
RATE_TOLERANCE = 0.05
#: Still intervals whose mean moves more than this (median, against the field's norm) come
#: from a log that turns without rests: a warning. Rests of real logs stay under 0.6 %.
REST_DRIFT = MOTION_LIMIT / 2
#: Fewest samples in a window (two per half for the change of the mean).
_FEWEST = 4


def _number(value: object) -> float:
    """``value`` as a float, NaN when it is not a real number (text, a bool, None)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        return math.nan
    return float(value)


def _rate(log: Log, rate: float | None) -> float | None:
    """The rate durations are converted with: ``rate`` when given (a warning when the time
    column disagrees by more than :data:`RATE_TOLERANCE`), else the time column's."""
    measured = log.rate if log.n > 1 else None
    if rate is None:
        return measured
    hz = _number(rate)
    if not (math.isfinite(hz) and hz > 0):
        raise InputError(
            f"--rate must be a positive number of samples per second, got {rate!r}"[:200]
        )
    if measured is not None and abs(hz / measured - 1.0) > RATE_TOLERANCE:
        warnings.warn(
            f"{log.path}: the rate given ({hz:g} Hz) and the time column's ({measured:.4g} Hz) "
            f"differ by {abs(hz / measured - 1.0):.0%}; durations in seconds use the rate given",
            UserWarning,
            stacklevel=3,
        )
    return hz


def _samples(
    value: float | None,
    option: str,
    defaults: tuple[float, int],
    rate: float | None,
    n: int,
    *,
    zero: bool = False,
) -> int:
    """A duration in seconds when the rate is known, else a number of samples; checked to be
    a finite positive number (``zero``: or 0) and at most the log's ``n`` samples."""
    if value is None:
        return max(1, round(defaults[0] * rate)) if rate else defaults[1]
    number = _number(value)
    unit = "seconds" if rate else "samples (no time column or --rate)"
    if not (math.isfinite(number) and (number >= 0 if zero else number > 0)):
        sign = "a non-negative" if zero else "a positive"
        raise InputError(f"--{option} must be {sign} number of {unit}, got {value!r}"[:200])
    samples = number * rate if rate else number
    if samples > n:
        at = f" ({samples:.6g} samples at {rate:g} Hz)" if rate else ""
        raise InputError(
            f"--{option} {number:g}{at} is longer than the log ({n} samples); give a shorter one"
        )
    return round(samples) if zero else max(1, round(samples))


def _std(x: Array) -> float | None:
    """RMS per-axis standard deviation (in any unit: computed on ``x`` over a power of two)."""
    if len(x) < 2:
        return None
    scale = scale_of(x)
    return float(np.sqrt(np.mean((x / scale).var(axis=0)))) * scale


def _label(value: object) -> str:
    if isinstance(value, (float, np.floating)) and float(value).is_integer():
        return str(int(value))
    return str(value)


def _run_stats(y: Array, starts: Rows, stops: Rows) -> tuple[Array, Array, Rows]:
    """Means (k, 3), per-axis variances (k, 3) and counts of the runs ``y[start:stop]`` (in
    order, not overlapping, gaps between them left out), by two passes of ``add.reduceat``:
    O(n), no loop over the runs. ``y`` should be of order one (divided by a power of two)."""
    k, n = len(starts), len(y)
    count = stops - starts
    mean, edges, cut = _run_means(y, starts, stops)
    # each run's rows less its mean (the gaps' rows are not summed): two passes, no cancelling
    fill = np.zeros((2 * k + 1, y.shape[1]))
    fill[1::2] = mean
    dev = y - np.repeat(fill, np.diff(np.concatenate([[0], edges, [n]])), axis=0)
    np.square(dev, out=dev)
    var = np.add.reduceat(dev, cut, axis=0)[0::2] / count[:, None]
    return mean, var, count


def _run_means(y: Array, starts: Rows, stops: Rows) -> tuple[Array, Rows, Rows]:
    """Means (k, 3) of the runs ``y[start:stop]`` (:func:`_run_stats`' first pass, where the
    spread is not wanted), the runs' edges and the indices ``add.reduceat`` summed at."""
    edges = np.column_stack([starts, stops]).ravel()
    cut = edges[:-1] if edges[-1] >= len(y) else edges  # reduceat's indices stay below n
    mean = np.add.reduceat(y, cut, axis=0)[0::2] / (stops - starts)[:, None]
    return mean, edges, cut


def _rms_std(var: Array, count: Rows, scale: float) -> list[float | None]:
    """Each pose's RMS per-axis standard deviation (None for a single sample), as :func:`_std`."""
    std = np.sqrt(var.mean(axis=1)) * scale
    return [float(s) if c > 1 else None for s, c in zip(std.tolist(), count.tolist(), strict=True)]


def _grouped(log: Log) -> tuple[Rows | None, Rows, list[str]]:
    """Rows of each label, concatenated in the order the labels first appear (None: every
    row, in order), the count of each label, and the labels."""
    labels = np.asarray(log.pose)
    if labels.dtype.kind == "f":
        keep = np.isfinite(labels)
    elif labels.dtype.kind in "iu":  # whole numbers: every row labelled, no text to compare
        keep = np.ones(len(labels), dtype=bool)
    else:
        text = np.char.strip(labels.astype(str))
        keep = (text != "") & (np.char.lower(text) != "nan")
        labels = text
    if keep.all():
        runs = _label_runs(log, labels)
        if runs is not None:
            return None, *runs
    rows = np.flatnonzero(keep)
    if rows.size == 0:
        raise InputError(f"{log.path}: the pose column {log.used['pose'][0]!r} has no labels")
    values, first, inverse = np.unique(labels[rows], return_index=True, return_inverse=True)
    if len(values) == rows.size > 1:
        _check_row_labels(log, rows)
    order = np.argsort(first)  # poses in the order they first appear in the log
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    pose_of_row = rank[inverse]
    sort = np.argsort(pose_of_row, kind="stable")
    counts = np.bincount(pose_of_row, minlength=len(order))
    return rows[sort], counts, [_label(v) for v in values[order].tolist()]


def _label_runs(log: Log, labels: NDArray[np.generic]) -> tuple[Rows, list[str]] | None:
    """The counts and labels of every row labelled, each label in one run of rows (as a
    logger writes the poses one after the other): :func:`_grouped`'s answer without sorting
    the labels or gathering the rows; None when a label comes back after another."""
    n = len(labels)
    if n == 0:
        return None
    starts = np.concatenate([[0], np.flatnonzero(labels[1:] != labels[:-1]) + 1])
    values = labels[starts].tolist()  # (0.0 and -0.0 are one label, as for np.unique)
    if len(set(values)) != len(values):
        return None
    if len(values) == n > 1:
        _check_row_labels(log, np.arange(n))
    return np.diff(starts, append=n), [_label(v) for v in values]


def _check_row_labels(log: Log, rows: Rows) -> None:
    """Every row its own label: fine for shots (one averaged reading per pose, each in a new
    orientation), a wrong column when neighbouring rows are far closer to each other than
    rows half the log apart (the samples of a continuous log, labelled by a counter, the time
    or a reading)."""
    sensors = [x[rows] for x in (log.accel, log.mag) if x is not None]
    d = np.hstack([unit_directions(x) for x in sensors])
    if len(d) < 4:
        return
    neighbours = float(np.median(np.linalg.norm(d[1:] - d[:-1], axis=1)))
    apart = float(np.median(np.linalg.norm(d - np.roll(d, len(d) // 2, axis=0), axis=1)))
    if neighbours < 0.25 * apart:
        raise InputError(
            f"{log.path}: the pose column {log.used['pose'][0]!r} gives every row its own label "
            f"({rows.size} rows) though neighbouring rows read nearly the same: it does not label "
            "poses; give a column with one label per pose, or leave --pose-col out to detect "
            "the still intervals"
        )


def _segment_edges(log: Log) -> Rows:
    """Start of every segment of the log and its end: [0, ..., n]."""
    if log.segment is None:
        return np.array([0, log.n], dtype=np.int64)
    breaks = np.flatnonzero(log.segment[1:] != log.segment[:-1]) + 1
    return np.concatenate([[0], breaks, [log.n]]).astype(np.int64)


def _window_edges(log: Log, w: int) -> tuple[Rows, Rows]:
    """Consecutive windows of ``w`` samples in each segment; a segment's remainder is a
    window of its own when it holds at least half a window, else left out."""
    edges = _segment_edges(log)
    starts: list[Rows] = []
    stops: list[Rows] = []
    for a, b in zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True):
        k, rest = divmod(b - a, w)
        first = a + w * np.arange(k + (rest >= max(2, (w + 1) // 2)), dtype=np.int64)
        starts.append(first)
        stops.append(np.minimum(first + w, b))
    return np.concatenate(starts), np.concatenate(stops)


@dataclass(frozen=True)
class _Motion:
    cut: WindowCut
    means: Array  # window means, readings' units
    var: Array  # per-axis variances within each window, readings' units
    counts: Rows
    scale: float
    moving: bool  # the mean moves across most windows (beyond the noise)


def _field_norm(means: Array, sensor: str) -> float:
    """The field's norm in the units of ``means`` (pose or window means): |g| as their median
    norm for the accelerometer; for a magnetometer, whose offset can exceed its field, the
    radius of the sphere fitted to them (linear least squares, |x|² = 2 c·x + r² − |c|²), or
    half their range when the fit fails. ``inf`` for a log of zeros."""
    if sensor == "accel":
        norm = float(np.median(np.linalg.norm(means, axis=1)))
        return norm if norm > 0 else math.inf
    scale = scale_of(means)
    x = means / scale
    A = np.column_stack([2.0 * x, np.ones(len(x))])
    with np.errstate(all="ignore"):
        solution = np.linalg.lstsq(A, np.sum(x * x, axis=1), rcond=None)[0]
    r2 = float(solution[3] + solution[:3] @ solution[:3])
    if len(x) >= 4 and math.isfinite(r2) and r2 > 0:
        norm = math.sqrt(r2) * scale
    else:
        norm = float(np.mean(np.ptp(means, axis=0))) / 2.0
    return norm if norm > 0 else math.inf


def _still_drift(ref: Array, sensor: str, segments: Sequence[Segment]) -> float | None:
    """Median over the still intervals (those of one run) of the change of their mean from
    the first half to the second, the white noise of their own readings taken out, against
    the field's norm; None without such an interval.

    From one pass of sums over the halves; each interval's spread and mean are the
    detector's (:class:`Segment`), so its samples are not read again.
    """
    kept = [s for s in segments if not s.pieces and s.stop - s.start >= _FEWEST]
    if not kept:
        return None
    starts = np.array([s.start for s in kept], dtype=np.int64)
    stops = np.array([s.stop for s in kept], dtype=np.int64)
    mids = (starts + stops) // 2
    means = np.array([s.mean for s in kept])
    scale = scale_of(means)  # any power of two near the readings: exact, no overflow
    edges = np.column_stack([starts, mids, stops]).ravel()
    cut = edges[:-1] if edges[-1] >= len(ref) else edges  # reduceat's indices stay below n
    with np.errstate(over="ignore", invalid="ignore"):
        sums = np.add.reduceat(ref, cut, axis=0)
    if not np.isfinite(sums).all():  # readings near the float range: sum them scaled
        sums = np.add.reduceat(ref / scale, cut, axis=0) * scale
    n1, n2 = (mids - starts).astype(float), (stops - mids).astype(float)
    # in units of the power of two (exact), so that no square overflows
    first = sums[0::3] / n1[:, None] / scale
    second = sums[1::3] / n2[:, None] / scale
    total = 3.0 * (np.array([s.std for s in kept]) / scale) ** 2  # Σ of the axes' variances
    jump2 = np.sum((second - first) ** 2, axis=1)
    expected = total * (1.0 / n1 + 1.0 / n2)
    drift = np.sqrt(np.maximum(jump2 - expected, 0.0))
    return float(np.median(drift)) / _field_norm(means / scale, sensor)


def _measure(log: Log, hz: float | None, window: float | None) -> tuple[_Motion, Rows, Rows]:
    """Cut the log into windows and measure the motion within them (see the module's text)."""
    ref, sensor = (log.accel, "accel") if log.accel is not None else (log.mag, "mag")
    if ref is None:
        raise InputError(f"{log.path}: the log has neither accelerometer nor magnetometer data")
    w = _samples(window, "window", WINDOW, hz, log.n)
    if w < _FEWEST:
        given = f"{_number(window):g} s at {hz:g} Hz" if hz and window is not None else ""
        raise InputError(
            f"--window {given or w} gives {w} sample(s) per window; a window needs at least "
            f"{_FEWEST}: give a longer --window"
        )
    starts, stops = _window_edges(log, w)
    k = len(starts)
    if k == 0:
        raise InputError(
            f"{log.path}: the log ({log.n} samples) is shorter than one window ({w} samples); "
            "record longer or give a shorter --window"
        )
    scale = scale_of(ref)
    y = ref / scale
    mids = (starts + stops) // 2
    hmean, _, hcount = _run_stats(
        y, np.column_stack([starts, mids]).ravel(), np.column_stack([mids, stops]).ravel()
    )
    mean, var, count = _run_stats(y, starts, stops)
    # the sensor's white noise (total over the axes): half the mean square of the successive
    # differences inside the windows (a slow turn adds little to a difference of neighbours)
    dd = np.concatenate([[0.0], np.cumsum(np.square(np.diff(y, axis=0)).sum(axis=1))])
    pairs = int(np.sum(count - 1))
    noise = 0.5 * float(np.sum(dd[stops - 1] - dd[starts])) / pairs if pairs else 0.0
    n1, n2 = hcount[0::2].astype(float), hcount[1::2].astype(float)
    jump2 = np.sum((hmean[1::2] - hmean[0::2]) ** 2, axis=1)
    expected = noise * (1.0 / np.maximum(n1, 1) + 1.0 / np.maximum(n2, 1))
    drift = np.sqrt(np.maximum(jump2 - expected, 0.0))
    spread = np.sqrt(np.maximum(var.sum(axis=1) - noise * (count - 1) / count, 0.0))
    norm = _field_norm(mean, sensor)
    # the field's direction turns by drift/norm (radians) between the halves' centres
    turn = drift / norm / np.maximum(0.5 * (n1 + n2), 1.0)
    cut = WindowCut(
        window=w,
        seconds=w / hz if hz else None,
        count=k,
        sensor=sensor,
        drift=float(np.percentile(drift, MOTION_PERCENTILE)) / norm,
        spread=float(np.percentile(spread, MOTION_PERCENTILE)) / norm,
        limit=MOTION_LIMIT,
        turn=float(np.percentile(turn, MOTION_PERCENTILE)),
    )
    moving = bool(np.median(jump2) > 4.0 * float(np.median(expected)))
    motion = _Motion(cut, mean * scale, var * scale * scale, count, scale, moving)
    return motion, starts, stops


def _accepted_window(log: Log, hz: float | None, cut: WindowCut, fewest: int) -> int | None:
    """The longest window shorter than ``cut.window`` (and at least ``fewest`` samples) that
    the motion check accepts on this log, or None. The first guess comes from the direction's
    rate of change (``cut.turn``: a window sweeping 80 % of the limit); each guess is measured
    and shortened by a fifth until it passes (the spread of a shaking hand does not shrink
    with the window, so a guess alone is not enough)."""
    guess = cut.window - 1
    if cut.turn > 0:
        guess = min(guess, math.floor(2.0 * 0.8 * cut.limit / cut.turn))
    w = max(guess, fewest)
    while w >= max(fewest, _FEWEST):
        try:
            motion, _, _ = _measure(log, hz, w / hz if hz else w)
        except InputError:
            return None
        if motion.cut.motion <= MOTION_LIMIT:
            return w
        w = min(w - 1, math.floor(0.8 * w))
    return None


def _window_text(w: int, hz: float | None) -> str:
    """A window of ``w`` samples as ``--window`` takes it: seconds (enough digits to give
    back ``w``) with a rate, else samples."""
    return f"{w / hz:.4g} (seconds)" if hz else f"{w} (samples)"


def _too_fast(log: Log, hz: float | None, cut: WindowCut) -> InputError:
    what = "|g|" if cut.sensor == "accel" else "the field"
    name = "accelerometer" if cut.sensor == "accel" else "magnetometer"
    size = f"{cut.seconds:.3g} s" if cut.seconds is not None else f"{cut.window}-sample"
    rate = f"{math.degrees(cut.turn) * hz:.3g}°/s" if hz else f"{math.degrees(cut.turn):.3g}°"
    better = _accepted_window(log, hz, cut, _FEWEST)
    if better is not None:
        fix = f"give --window {_window_text(better, hz)} (checked on this log), or turn more slowly"
    else:
        fix = (
            "turn more slowly, or use --poses samples (each sample its own pose; shorter "
            "windows than the check accepts would hold too few samples)"
        )
    return InputError(
        f"{log.path}: the log moves too fast for {size} windows: the {name} moves "
        f"{cut.motion:.1%} of {what} within a window ({MOTION_PERCENTILE:.0f}th percentile over "
        f"{cut.count} windows; its direction turns up to {rate}{'' if hz else ' per sample'}; "
        f"the limit is {cut.limit:.0%}, which keeps the window means on the ellipsoid); {fix}"
    )


def turns_slowly(
    log: Log,
    *,
    rate: float | None = None,
    window: float | None = None,
    min_orientations: int = 12,
) -> bool:
    """Whether the log turns slowly without rests, so ``poses="windows"`` suits it.

    True when, cut into windows as ``poses="windows"`` would cut it, the mean reading moves
    (beyond the noise) across most windows, the motion stays under :data:`MOTION_LIMIT`, and
    the window means show at least ``min_orientations`` orientations 3° apart. For the
    message when still detection finds too few rests: "the log turns slowly without rests:
    use --poses windows". ``rate`` and ``window`` as for :func:`poses_from_log`.
    """
    return _turns_slowly(log, _rate(log, rate), window, min_orientations)


def _turns_slowly(log: Log, hz: float | None, window: float | None, least: int = 12) -> bool:
    """:func:`turns_slowly` with the rate already resolved."""
    try:
        motion, _, _ = _measure(log, hz, window)
    except InputError:
        if window is not None:
            raise  # a bad --window is the user's to fix
        return False  # a log shorter than one window does not turn slowly
    if not motion.moving or motion.cut.motion > MOTION_LIMIT or motion.cut.count < 2:
        return False
    # the checked sensor's directions: a turn about its field direction alone is not enough
    directions = unit_directions(motion.means)
    return len(set(orientation_labels([directions]).tolist())) >= least


def poses_from_log(
    log: Log,
    *,
    rate: float | None = None,
    window: float | None = None,
    min_still: float | None = None,
    trim: float | None = None,
    threshold: float | None = None,
    factor: float = 3.0,
    poses: str = "still",
) -> PoseSet:
    """Group the log's rows by its pose column, detect still intervals, or cut windows.

    Parameters
    ----------
    log : Log
        As :func:`~fieldcal.logs.log.load_log` returns it.
    rate : float, optional
        Samples per second. Durations (``window``, ``min_still``, ``trim``) are seconds when a
        rate is known, from ``rate`` or else from the time column
        (:func:`~fieldcal.logs.log.sample_rate`); otherwise numbers of samples. Given beside a
        time column, ``rate`` wins, with a warning when the two differ by more than 5 %.
    window : float, optional
        Still detection: the moving-variance window (default 0.5 s / 25 samples). Windows:
        the length of each pose window (default :data:`WINDOW`, 0.25 s / 25 samples).
    min_still, trim, threshold, factor
        Still detection: the shortest still interval (default 1 s / 50 samples), the samples
        cut at each end (default a quarter window), the accelerometer threshold as a per-axis
        standard deviation (default ``factor`` times the noise floor).
    poses : "still", "windows" or "samples"
        How a log without a pose column is cut: still intervals (a pose column, when present,
        groups the rows instead), or consecutive windows of a slowly turning log with no
        rests (this also overrides a pose column), or one pose per sample (a dense log:
        per short window; also overrides a pose column). Windows are refused with an
        :class:`InputError` naming the motion measured and a ``window`` that this log
        passes with when it turns too fast for them (:data:`MOTION_LIMIT`); they never span a
        reset of the clock (``log.segment``). ``window`` given with ``"samples"`` sets the
        samples per pose (no motion check: the pose-level noise absorbs the motion).

    Returns
    -------
    PoseSet
        The samples of each pose, one entry per pose (data rows, samples, spread,
        orientation) and how they were made (``source``, ``detection`` or ``windows``).
    """
    if poses not in POSE_SOURCES:
        raise InputError(f"poses must be one of {', '.join(POSE_SOURCES)}; got {poses!r}"[:200])
    hz = _rate(log, rate)
    if threshold is not None and not (math.isfinite(_number(threshold)) and threshold > 0):
        raise InputError(
            f"--still-threshold must be a positive per-axis standard deviation in the "
            f"readings' units, got {threshold!r}"[:200]
        )
    factor_value = _number(factor)
    if not (math.isfinite(factor_value) and factor_value > 0):
        raise InputError(f"factor must be a positive number, got {factor!r}"[:200])
    ref = log.accel if log.accel is not None else log.mag
    if ref is None:
        raise InputError(f"{log.path}: the log has neither accelerometer nor magnetometer data")
    if poses == "windows":
        return _windows(log, hz, window)
    if poses == "samples":
        return _sample_poses(log, hz, window)
    if log.pose is not None:
        return _by_column(log, hz)
    return _still_poses(log, hz, ref, window, min_still, trim, threshold, factor_value)


def _still_poses(
    log: Log,
    hz: float | None,
    ref: Array,
    window: float | None,
    min_still: float | None,
    trim: float | None,
    threshold: float | None,
    factor: float,
) -> PoseSet:
    """The still intervals of ``ref`` (the accelerometer, else the magnetometer) as poses;
    none found is an error saying what to change (``NO_STILL``), rests that move a warning
    (:class:`MovingRestsWarning`, stacklevel of :func:`poses_from_log`'s caller)."""
    w = _samples(window, "window", (0.5, 25), hz, log.n)
    min_samples = _samples(min_still, "min-still", (1.0, 50), hz, log.n)
    cut = None if trim is None else _samples(trim, "still-trim", (0.0, 0), hz, log.n, zero=True)
    detection = detect_still(
        ref,
        log.gyro,
        window=w,
        min_samples=min_samples,
        trim=cut,
        threshold=threshold,
        factor=factor,
        segment=log.segment,
    )
    if not detection.segments:
        unit = f"{min_samples / hz:g} s" if hz else f"{min_samples} samples"
        if _turns_slowly(log, hz, None):
            raise InputError(
                f"{log.path}: no still interval of at least {unit} found: the log turns slowly "
                "without rests; use --poses windows",
                code=NO_STILL,
            )
        raise InputError(
            f"{log.path}: no still interval of at least {unit} found (threshold "
            f"{detection.threshold_std:.3g} per-axis std); try --still-threshold "
            f"{3 * detection.threshold_std:.3g} or a shorter --min-still, or label poses with "
            "--pose-col",
            code=NO_STILL,
        )
    sensor = "accel" if log.accel is not None else "mag"
    drift = _still_drift(ref, sensor, detection.segments)
    if drift is not None and drift > REST_DRIFT:
        what = "|g|" if sensor == "accel" else "the field"
        advice = (
            "use --poses windows"
            if _turns_slowly(log, hz, None)
            else "hold the device still in each pose, or turn slowly and use --poses windows"
        )
        warnings.warn(
            f"{log.path}: the still intervals found move: their mean turns {drift:.1%} of "
            f"{what} across an interval (median; rests stay under {REST_DRIFT:.1%}), so the "
            f"log seems to turn without rests and its poses are means of moving readings; "
            f"{advice}",
            MovingRestsWarning,
            stacklevel=3,
        )
    entries: list[PoseEntry] = []
    groups: list[Rows | slice] = []
    for s in detection.segments:
        entry: PoseEntry = {
            "start": int(log.index[s.start]),
            "stop": int(log.index[s.stop - 1]) + 1,
        }
        if s.pieces:  # runs of one pose merged across a short disturbance, left out
            entry["pieces"] = [[int(log.index[a]), int(log.index[b - 1]) + 1] for a, b in s.pieces]
            groups.append(s.rows)
        else:
            groups.append(slice(s.start, s.stop))  # a view, not a copy
        entry["samples"] = s.samples
        # the detector computed the spread as _std(ref[rows]) does, on the same readings
        entry["std"] = s.std if s.samples > 1 else None
        entries.append(entry)
    found = PoseSet(
        accel=None if log.accel is None else [log.accel[g] for g in groups],
        mag=None if log.mag is None else [log.mag[g] for g in groups],
        entries=entries,
        detection=detection,
        rate=hz,
        source="still",
    )
    # the detection's means are the checked sensor's (accelerometer, else magnetometer)
    other = [found.means("mag")] if log.accel is not None and log.mag is not None else []
    _orient(found, [np.array([s.mean for s in detection.segments]), *other])
    return found


def _orient(found: PoseSet, means: list[Array]) -> None:
    """Each entry's orientation label from the pose means of each sensor."""
    labels = orientation_labels([unit_directions(m) for m in means])
    for entry, label in zip(found.entries, labels.tolist(), strict=True):
        entry["orientation"] = label


def _by_column(log: Log, hz: float | None) -> PoseSet:
    """Poses grouped by the pose column: one gathered copy per sensor, split into views, and
    the statistics of every pose at once (linear in the rows, whatever the number of labels)."""
    rows, counts, labels = _grouped(log)
    ends = np.cumsum(counts)
    # each label's rows are in increasing order: its first and last rows bound it
    if rows is None:  # every row, in order
        first_rows, lasts = ends - counts, ends - 1
    else:
        first_rows, lasts = rows[ends - counts], rows[ends - 1]
    samples: dict[str, list[Array]] = {}
    means: list[Array] = []
    std: list[float | None] = []
    spans = list(zip((ends - counts).tolist(), ends.tolist(), strict=True))
    for name in ("accel", "mag"):
        x = getattr(log, name)
        if x is None:
            continue
        gathered = x if rows is None else x[rows]
        samples[name] = [gathered[a:b] for a, b in spans]  # views (np.split's, without its cost)
        scale = scale_of(gathered)
        if not std:  # the spread of the first sensor (accelerometer, else magnetometer)
            mean, var, count = _run_stats(gathered / scale, ends - counts, ends)
            std = _rms_std(var, count, scale)
        else:
            mean = _run_means(gathered / scale, ends - counts, ends)[0]
        means.append(mean * scale)
    entries: list[PoseEntry] = [
        {
            "label": text,
            "start": int(log.index[a]),
            "stop": int(log.index[b]) + 1,
            "samples": int(c),
            "std": s,
        }
        for text, a, b, c, s in zip(
            labels, first_rows.tolist(), lasts.tolist(), counts.tolist(), std, strict=True
        )
    ]
    found = PoseSet(
        accel=samples.get("accel"),
        mag=samples.get("mag"),
        entries=entries,
        detection=None,
        rate=hz,
        source="column",
    )
    _orient(found, means)
    return found


def _windows(log: Log, hz: float | None, window: float | None) -> PoseSet:
    """Consecutive windows of a slowly turning log, each one pose (motion checked first)."""
    motion, starts, stops = _measure(log, hz, window)
    if motion.cut.motion > MOTION_LIMIT:
        raise _too_fast(log, hz, motion.cut)
    return _cut(log, hz, motion, starts, stops, "windows")


def _sample_poses(log: Log, hz: float | None, window: float | None) -> PoseSet:
    """Each sample its own pose; a dense log (more than :data:`MAX_SAMPLE_POSES` samples)
    grouped into consecutive windows of ``ceil(n / MAX_SAMPLE_POSES)`` samples, shortened until
    the motion check accepts them (``window``, when given, is taken as it is)."""
    if window is not None:
        w = _samples(window, "window", WINDOW, hz, log.n)
    else:
        w = max(1, -(-log.n // MAX_SAMPLE_POSES))
    if w >= _FEWEST:
        motion, starts, stops = _measure(log, hz, w / hz if hz else w)
        if window is None and motion.cut.motion > MOTION_LIMIT:
            shorter = _accepted_window(log, hz, motion.cut, _FEWEST)
            if shorter is None:
                w = 1
            else:
                motion, starts, stops = _measure(log, hz, shorter / hz if hz else shorter)
        if w >= _FEWEST:
            return _cut(log, hz, motion, starts, stops, "samples")
    starts, stops = _window_edges(log, w)
    if len(starts) == 0:
        raise InputError(f"{log.path}: the log has no samples")
    std: list[float | None] = [None] * len(starts)
    if w > 1:
        ref = log.accel if log.accel is not None else log.mag
        assert ref is not None
        scale = scale_of(ref)
        _, var, count = _run_stats(ref / scale, starts, stops)
        std = _rms_std(var, count, scale)
    found = _span_poses(log, hz, starts, stops, std, "samples")
    _orient(found, [found.means(s) for s in ("accel", "mag") if getattr(found, s) is not None])
    return found


def _span_poses(
    log: Log,
    hz: float | None,
    starts: Rows,
    stops: Rows,
    std: Sequence[float | None],
    source: str,
    windows: WindowCut | None = None,
) -> PoseSet:
    """The poses of consecutive spans ``[starts, stops)`` of the log's rows (unlabelled)."""
    first, last = log.index[starts], log.index[stops - 1] + 1
    entries: list[PoseEntry] = [
        {"start": a, "stop": b, "samples": c, "std": s}
        for a, b, c, s in zip(
            first.tolist(), last.tolist(), (stops - starts).tolist(), std, strict=True
        )
    ]
    spans = list(zip(starts.tolist(), stops.tolist(), strict=True))
    return PoseSet(
        accel=None if log.accel is None else [log.accel[a:b] for a, b in spans],
        mag=None if log.mag is None else [log.mag[a:b] for a, b in spans],
        entries=entries,
        detection=None,
        rate=hz,
        source=source,
        windows=windows,
    )


def _cut(
    log: Log, hz: float | None, motion: _Motion, starts: Rows, stops: Rows, source: str
) -> PoseSet:
    """The poses of windows measured by :func:`_measure`."""
    std = _rms_std(motion.var / motion.scale**2, motion.counts, motion.scale)
    found = _span_poses(log, hz, starts, stops, std, source, motion.cut)
    means = [motion.means]
    if log.accel is not None and log.mag is not None:  # the motion was measured on the accel
        scale = scale_of(log.mag)
        means.append(_run_means(log.mag / scale, starts, stops)[0] * scale)
    _orient(found, means)
    return found


def poses_orientations(poses: PoseSet) -> NDArray[np.int64]:
    """Orientation label of each pose (revisits of one orientation share a label)."""
    sensors = [s for s in (poses.accel, poses.mag) if s is not None]
    return orientation_labels([_directions(s) for s in sensors])


def _directions(samples: list[Array]) -> Array:
    """Unit directions of the pose means about the mid-range point (a rough centre)."""
    return unit_directions(np.array([p.mean(axis=0) for p in samples]))
