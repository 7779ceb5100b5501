"""The poses found in a log (:class:`PoseSet`): each pose's samples per sensor, one entry per
pose for the JSON and the summary (:class:`PoseEntry`), and how they were made (still
detection, a pose column, windows with the motion measured in them, :class:`WindowCut`, or
samples). :mod:`fieldcal.logs.pose_finding` makes them and exports these names as before."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TypedDict

import numpy as np
from numpy.typing import NDArray

from .stillness import StillResult, _column_sums

__all__ = ["MOTION_PERCENTILE", "PoseEntry", "PoseSet", "WindowCut", "pose_mean"]

Array = NDArray[np.float64]


#: The percentile over the windows of the motion that must stay under :data:`MOTION_LIMIT`.
MOTION_PERCENTILE = 90.0


class PoseEntry(TypedDict, total=False):
    """One pose found in a log, as written to the JSON's ``poses`` list and the summary."""

    label: str  # the pose column's value (grouped logs)
    start: int  # first data row of the pose in the file
    stop: int  # one past its last data row
    pieces: list[list[int]]  # [start, stop) runs merged across a short disturbance
    samples: int
    std: float | None  # RMS per-axis standard deviation of its readings (None: one sample)
    orientation: int  # revisits of one orientation share a label


@dataclass(frozen=True)
class WindowCut:
    """How a slowly turning log was cut into windows, and the motion measured in them.

    ``drift`` and ``spread`` are the :data:`MOTION_PERCENTILE` th percentiles over the
    windows, as fractions of the field's norm (|g| for the accelerometer, the field for a
    magnetometer-only log): the change of the mean across a window and the spread of the
    readings about it, white noise taken out. ``turn`` is the rate of change of the field's
    direction at the same percentile, radians per sample (the change of the mean across half
    a window over its length).
    """

    window: int  # samples per window
    seconds: float | None  # the same in seconds (None without a rate)
    count: int
    sensor: str  # "accel" or "mag": the sensor checked
    drift: float
    spread: float
    limit: float
    turn: float = 0.0

    @property
    def motion(self) -> float:
        """The larger of ``drift`` and ``spread``: what must stay under ``limit``."""
        return max(self.drift, self.spread)

    def to_dict(self) -> dict[str, object]:
        per_s = None if not self.seconds else math.degrees(self.turn) * self.window / self.seconds
        return {
            "window": self.window,
            "window_s": self.seconds,
            "count": self.count,
            "sensor": self.sensor,
            "drift": self.drift,
            "spread": self.spread,
            "motion": self.motion,
            "limit": self.limit,
            "percentile": MOTION_PERCENTILE,
            "turn_deg_per_sample": math.degrees(self.turn),
            "turn_deg_s": per_s,
        }


@dataclass
class PoseSet:
    """Per-pose samples of each sensor and one entry per pose for the JSON and the summary.

    ``source`` says how the poses were made: ``"column"`` (the pose column), ``"still"``
    (still detection, ``detection``), ``"windows"`` (``windows``) or ``"samples"`` (one pose
    per sample, or per ``windows`` when the log is dense); :meth:`record` is that for the
    JSON. ``time_ordered``: the poses are consecutive pieces of one motion (windows, samples).
    """

    accel: list[Array] | None
    mag: list[Array] | None
    entries: list[PoseEntry]
    detection: StillResult | None
    rate: float | None
    source: str = "still"
    windows: WindowCut | None = None
    _means: dict[str, Array] = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def n(self) -> int:
        return len(self.entries)

    def means(self, sensor: str) -> Array:
        """(N, 3): each pose's mean reading of ``sensor`` (``"accel"`` or ``"mag"``), the
        numbers ``p.mean(axis=0)`` gives for each pose ``p``, computed once (by running sums
        along each column: numpy adds the rows in the same order, more slowly)."""
        if sensor not in ("accel", "mag"):
            raise ValueError(f"sensor must be 'accel' or 'mag', got {sensor!r}")
        if sensor not in self._means:
            samples: list[Array] | None = getattr(self, sensor)
            if samples is None:
                raise ValueError(f"no {sensor} poses")
            self._means[sensor] = np.array([pose_mean(p) for p in samples]).reshape(-1, 3)
        return self._means[sensor]

    def record(self) -> dict[str, object]:
        """How the poses were made, for the JSON: the source, its parameters, the rate."""
        out: dict[str, object] = {"source": self.source}
        if self.detection is not None:
            out.update(self.detection.to_dict())
        if self.windows is not None:
            out.update(self.windows.to_dict())
        if self.source == "samples":
            out["samples_per_pose"] = max((e.get("samples", 1) for e in self.entries), default=1)
        out["rate_hz"] = self.rate
        return out

    @property
    def time_ordered(self) -> bool:
        return self.source in ("windows", "samples")


def pose_mean(x: Array) -> Array:
    """``x.mean(axis=0)``, the same numbers, faster (:func:`~.stillness._column_sums`)."""
    return _column_sums(x) / len(x)
