"""From a log to poses: rows grouped by a pose column, or still intervals detected; each
pose's orientation label (revisits of one orientation share one)."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import TypedDict

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .log import Log
from .stillness import StillResult, detect_still, power_of_two

__all__ = ["PoseEntry", "PoseSet", "orientation_labels", "poses_from_log", "poses_orientations"]

Array = NDArray[np.float64]


class PoseEntry(TypedDict, total=False):
    """One pose found in a log, as written to the JSON's ``poses`` list and the summary."""

    label: str  # the pose column's value (grouped logs)
    start: int  # first data row of the pose in the file
    stop: int  # one past its last data row
    pieces: list[list[int]]  # [start, stop) runs merged across a short disturbance
    samples: int
    std: float | None  # RMS per-axis standard deviation of its readings (None: one sample)
    orientation: int  # revisits of one orientation share a label


@dataclass
class PoseSet:
    """Per-pose samples of each sensor and one entry per pose for the JSON and the summary."""

    accel: list[Array] | None
    mag: list[Array] | None
    entries: list[PoseEntry]
    detection: StillResult | None
    rate: float | None

    @property
    def n(self) -> int:
        return len(self.entries)


def _number(value: object) -> float:
    """``value`` as a float, NaN when it is not a real number (text, a bool, None)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        return math.nan
    return float(value)


def _rate(log: Log, rate: float | None) -> float | None:
    if rate is not None:
        hz = _number(rate)
        if not (math.isfinite(hz) and hz > 0):
            raise InputError(
                f"--rate must be a positive number of samples per second, got {rate!r}"[:200]
            )
        return hz
    if log.time is not None and log.n > 1:
        step = float(np.median(np.diff(log.time)))
        if step > 0 and math.isfinite(1.0 / step):
            return 1.0 / step
    return None


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
    scale = power_of_two(x)
    return float(np.sqrt(np.mean((x / scale).var(axis=0)))) * scale


def _label(value: object) -> str:
    if isinstance(value, (float, np.floating)) and float(value).is_integer():
        return str(int(value))
    return str(value)


def _grouped(log: Log) -> tuple[list[NDArray[np.int64]], list[str]]:
    labels = np.asarray(log.pose)
    if labels.dtype.kind == "f":
        keep = np.isfinite(labels)
    else:
        text = np.char.strip(labels.astype(str))
        keep = (text != "") & (np.char.lower(text) != "nan")
        labels = text
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
    groups = np.split(rows[sort], np.cumsum(counts)[:-1])
    return groups, [_label(values[i]) for i in order]


def _check_row_labels(log: Log, rows: NDArray[np.int64]) -> None:
    """Every row its own label: fine for shots (one averaged reading per pose, each in a new
    orientation), a wrong column when neighbouring rows are far closer to each other than
    rows half the log apart (the samples of a continuous log, labelled by a counter, the time
    or a reading)."""
    sensors = [x[rows] for x in (log.accel, log.mag) if x is not None]
    d = np.hstack([_unit_directions(x) for x in sensors])
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


def poses_from_log(
    log: Log,
    *,
    rate: float | None = None,
    window: float | None = None,
    min_still: float | None = None,
    trim: float | None = None,
    threshold: float | None = None,
    factor: float = 3.0,
) -> PoseSet:
    """Group the log's rows by its pose column, or detect still intervals.

    ``window``, ``min_still`` and ``trim`` are seconds when the rate is known (``rate`` or the
    time column), otherwise samples; defaults 0.5 s / 25, 1 s / 50, a quarter window.
    """
    hz = _rate(log, rate)
    if threshold is not None and not (math.isfinite(_number(threshold)) and threshold > 0):
        raise InputError(
            f"--still-threshold must be a positive per-axis standard deviation in the "
            f"readings' units, got {threshold!r}"[:200]
        )
    factor_value = _number(factor)
    if not (math.isfinite(factor_value) and factor_value > 0):
        raise InputError(f"factor must be a positive number, got {factor!r}"[:200])
    detection = None
    entries: list[PoseEntry] = []
    ref = log.accel if log.accel is not None else log.mag
    if ref is None:
        raise InputError(f"{log.path}: the log has neither accelerometer nor magnetometer data")
    if log.pose is not None:
        groups, labels = _grouped(log)
        for rows, label in zip(groups, labels, strict=True):
            entries.append(
                {
                    "label": label,
                    "start": int(log.index[rows[0]]),
                    "stop": int(log.index[rows[-1]]) + 1,
                }
            )
    else:
        w = _samples(window, "window", (0.5, 25), hz, log.n)
        min_samples = _samples(min_still, "min-still", (1.0, 50), hz, log.n)
        cut = None if trim is None else _samples(trim, "trim", (0.0, 0), hz, log.n, zero=True)
        detection = detect_still(
            ref,
            log.gyro,
            window=w,
            min_samples=min_samples,
            trim=cut,
            threshold=threshold,
            factor=factor_value,
        )
        if not detection.segments:
            unit = f"{min_samples / hz:g} s" if hz else f"{min_samples} samples"
            raise InputError(
                f"{log.path}: no still interval of at least {unit} found (threshold "
                f"{detection.threshold_std:.3g} per-axis std); try --still-threshold "
                f"{3 * detection.threshold_std:.3g} or a shorter --min-still, or label poses with "
                "--pose-col"
            )
        groups = [s.rows for s in detection.segments]
        for s in detection.segments:
            entry: PoseEntry = {
                "start": int(log.index[s.start]),
                "stop": int(log.index[s.stop - 1]) + 1,
            }
            if s.pieces:  # runs of one pose merged across a short disturbance, left out
                entry["pieces"] = [
                    [int(log.index[a]), int(log.index[b - 1]) + 1] for a, b in s.pieces
                ]
            entries.append(entry)
    for entry, rows in zip(entries, groups, strict=True):
        entry["samples"] = len(rows)
        entry["std"] = _std(ref[rows])
    poses = PoseSet(
        accel=None if log.accel is None else [log.accel[r] for r in groups],
        mag=None if log.mag is None else [log.mag[r] for r in groups],
        entries=entries,
        detection=detection,
        rate=hz,
    )
    # revisits of one orientation (e.g. before and after a rotation) share a label
    for entry, label in zip(entries, poses_orientations(poses), strict=True):
        entry["orientation"] = int(label)
    return poses


def poses_orientations(poses: PoseSet) -> NDArray[np.int64]:
    """Orientation label of each pose (revisits of one orientation share a label)."""
    sensors = [s for s in (poses.accel, poses.mag) if s is not None]
    return orientation_labels([_directions(s) for s in sensors])


def _directions(samples: list[Array]) -> Array:
    """Unit directions of the pose means about the mid-range point (a rough centre)."""
    return _unit_directions(np.array([p.mean(axis=0) for p in samples]))


def _unit_directions(points: Array) -> Array:
    """Unit directions of ``points`` (n, 3) about their mid-range point; zero where a point is
    the centre."""
    scaled = points / power_of_two(points)
    centred = scaled - 0.5 * (scaled.max(axis=0) + scaled.min(axis=0))
    norm = np.linalg.norm(centred, axis=1, keepdims=True)
    return np.divide(centred, norm, out=np.zeros_like(centred), where=norm > 0)


def orientation_labels(directions: list[Array], tol_deg: float = 3.0) -> NDArray[np.int64]:
    """Label each pose with its orientation: poses closer than ``tol_deg`` in every sensor's
    field direction share a label (0, 1, ... in order of first appearance).

    Greedy in the order of the poses: the first pose not yet labelled takes every later
    unlabelled pose within ``tol_deg`` of it. Candidates come from a grid of cells as wide as
    the chord of ``tol_deg`` over the first sensor's directions (the 27 cells around a pose
    hold every direction within the tolerance), so N poses take O(N) work, not an N x N table.
    """
    n = len(directions[0])
    cos_tol = np.cos(np.radians(tol_deg))
    chord = 2.0 * np.sin(np.radians(tol_deg) / 2.0)
    cells = np.floor(directions[0] / chord).astype(np.int64)
    members: dict[tuple[int, int, int], list[int]] = {}
    for i, cell in enumerate(map(tuple, cells.tolist())):
        members.setdefault(cell, []).append(i)
    offsets = [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)]
    label = np.full(n, -1, dtype=np.int64)
    count = 0
    for i in range(n):  # a loop over leaders; each compares against its neighbourhood at once
        if label[i] >= 0:
            continue
        x, y, z = cells[i]
        near = [members.get((x + a, y + b, z + c), ()) for a, b, c in offsets]
        candidates = np.fromiter((j for cell in near for j in cell), dtype=np.int64)
        candidates = candidates[label[candidates] < 0]
        same = np.ones(len(candidates), dtype=bool)
        for d in directions:
            same &= d[candidates] @ d[i] > cos_tol
        label[candidates[same]] = count
        label[i] = count
        count += 1
    return label
