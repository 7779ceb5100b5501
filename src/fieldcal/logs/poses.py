"""From a log to poses: rows grouped by a pose column, or still intervals detected; each
pose's orientation label (revisits of one orientation share one)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypedDict

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .log import Log
from .stillness import StillResult, detect_still

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


def _rate(log: Log, rate: float | None) -> float | None:
    if rate is not None:
        if not (np.isfinite(rate) and rate > 0):
            raise InputError(f"--rate must be a positive number of samples per second, got {rate}")
        return float(rate)
    if log.time is not None and log.n > 1:
        step = float(np.median(np.diff(log.time)))
        if step > 0:
            return 1.0 / step
    return None


def _samples(
    value: float | None, default_seconds: float, default_samples: int, rate: float | None
) -> int:
    """A duration in seconds when the rate is known, else a number of samples."""
    if value is None:
        return round(default_seconds * rate) if rate else default_samples
    return round(value * rate) if rate else round(value)


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
    order = np.argsort(first)  # poses in the order they first appear in the log
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    pose_of_row = rank[inverse]
    sort = np.argsort(pose_of_row, kind="stable")
    counts = np.bincount(pose_of_row, minlength=len(order))
    groups = np.split(rows[sort], np.cumsum(counts)[:-1])
    return groups, [_label(values[i]) for i in order]


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
        w = _samples(window, 0.5, 25, hz)
        min_samples = _samples(min_still, 1.0, 50, hz)
        detection = detect_still(
            ref,
            log.gyro,
            window=w,
            min_samples=min_samples,
            trim=None if trim is None else _samples(trim, 0.0, 0, hz),
            threshold=threshold,
            factor=factor,
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
        entry["std"] = float(np.sqrt(np.mean(ref[rows].var(axis=0)))) if len(rows) > 1 else None
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
    means = np.array([p.mean(axis=0) for p in samples])
    centred = means - 0.5 * (means.max(axis=0) + means.min(axis=0))
    return centred / np.maximum(np.linalg.norm(centred, axis=1, keepdims=True), 1e-300)


def orientation_labels(directions: list[Array], tol_deg: float = 3.0) -> NDArray[np.int64]:
    """Label each pose with its orientation: poses closer than ``tol_deg`` in every sensor's
    field direction share a label (0, 1, ... in order of first appearance)."""
    cos_tol = np.cos(np.radians(tol_deg))
    same = np.ones((len(directions[0]),) * 2, dtype=bool)
    for d in directions:
        same &= d @ d.T > cos_tol
    label = np.full(len(same), -1)
    for i in range(len(same)):  # a loop over poses (tens), not samples
        if label[i] < 0:
            label[same[i] & (label < 0)] = i
    return np.unique(label, return_inverse=True)[1]
