"""Still poses of a growing stream: the offline detector, rerun as samples arrive.

The offline detector (:func:`fieldcal.logs.pose_finding.poses_from_log`) sets its threshold from the
noise floor of the whole log, so no pose it finds is final until the log ends. The live form
runs that same detector on everything received so far, and calls a pose *settled* once the
device has moved away from it for longer than the detector looks around a sample (a window and
the trim) and the run before found the same pose (each edge within the trim): a window whose
motion statistic sits at the threshold can cut a pose short in one run and not in the next,
as the threshold follows the noise floor of the samples so far. From then on its rows do not
change unless the noise floor itself moves. When the
stream ends, one last run on all the data gives exactly the offline answer, so a capture and
``fieldcal calibrate`` on its recorded log agree by construction.

A pose still being held is *captured* once it is longer than the detector's shortest pose
plus a window: the user can be told to move on while still holding it, and its mean is
already well determined (its rows grow until it settles).

Each run is O(n) in the samples received. A run waits for new samples worth ``every`` seconds
and for the wall-clock time since the last run to reach ``load`` times what that run took, so
the detector takes at most about ``1 / (1 + load)`` of the time however fast the stream
comes (a file replayed at full speed, a long capture).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import InputError
from .log import Log
from .pose_finding import PoseSet, poses_from_log

__all__ = ["LiveDetector", "LiveState", "leading_poses"]


@dataclass(frozen=True)
class LiveState:
    """What the detector knows after a run.

    Attributes
    ----------
    poses : PoseSet or None
        Every pose found so far, as the offline detector finds them in the samples received;
        ``None`` before the first pose (see ``message``).
    settled : int
        How many of ``poses`` (the first ones) are settled: the device has since moved on.
    captured : int
        ``settled``, plus one when the pose being held is long enough to count.
    still_seconds : float or None
        How long the device has been still at the end of the stream (the pose being held),
        ``None`` while it moves.
    rows : int
        Samples the run saw.
    message : str
        Why no pose is found yet, when none is.
    warnings : tuple of str
        The detector's warnings on this run (rests that move ...).
    """

    poses: PoseSet | None
    settled: int
    captured: int
    still_seconds: float | None
    rows: int
    message: str = ""
    warnings: tuple[str, ...] = ()

    def captured_poses(self) -> PoseSet | None:
        """The captured poses (None when there are none)."""
        if self.poses is None or self.captured == 0:
            return None
        return leading_poses(self.poses, self.captured)


def leading_poses(poses: PoseSet, k: int) -> PoseSet:
    """The first ``k`` poses of ``poses`` (the same samples and entries)."""
    return dataclasses.replace(
        poses,
        accel=None if poses.accel is None else poses.accel[:k],
        mag=None if poses.mag is None else poses.mag[:k],
        entries=poses.entries[:k],
    )


class LiveDetector:
    """Runs :func:`~fieldcal.logs.pose_finding.poses_from_log` on a growing log.

    Parameters
    ----------
    detection : mapping
        Options of ``poses_from_log`` (``rate``, ``window``, ``min_still``, ``trim``,
        ``threshold``), as the offline command takes them.
    every : float
        Seconds of new samples between runs (samples when the log has no rate).
    load : float
        Wall-clock time between runs, as a multiple of the last run's duration.
    """

    def __init__(
        self,
        detection: Mapping[str, Any] | None = None,
        *,
        every: float = 0.25,
        load: float = 4.0,
    ) -> None:
        self.detection = {k: v for k, v in (detection or {}).items() if v is not None}
        self.every = float(every)
        self.load = float(load)
        self.rows = 0
        self._finished = -math.inf
        self._took = 0.0
        self._held: tuple[int, int] | None = None  # rows of the held pose once captured
        self._seen: list[tuple[int, int]] = []  # the last run's poses (start, stop)
        self._settled = 0  # poses settled so far
        self.state = LiveState(None, 0, 0, None, 0, "waiting for samples")

    def due(self, rows: int, rate: float | None) -> bool:
        """Whether ``rows`` samples (at ``rate`` Hz) warrant another run now."""
        if rows - self.rows < max(self.every * (rate or 1.0), 1.0):
            return False
        return time.monotonic() - self._finished >= self.load * self._took

    def update(self, log: Log, *, final: bool = False) -> LiveState:
        """Run the detector on ``log`` (all samples so far) and return what it found.

        With ``final`` every pose counts as settled, the last one included: the answer the
        offline detector gives on the whole log.
        """
        began = time.monotonic()
        self.rows = log.n
        try:
            self.state = self._update(log, final)
        finally:
            self._finished = time.monotonic()
            self._took = self._finished - began
        return self.state

    def _update(self, log: Log, final: bool) -> LiveState:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                poses = poses_from_log(log, poses="still", **self.detection)
            except InputError as exc:
                return LiveState(None, 0, 0, None, log.n, str(exc))
        said = tuple(str(w.message) for w in caught if issubclass(w.category, UserWarning))
        detection = poses.detection
        n = log.n
        if final or detection is None:
            return LiveState(poses, poses.n, poses.n, None, n, "", said)
        # a pose is passed when the samples after it reach beyond what its last windows
        # looked at (half a window) plus the trim, and the device is not still there; it is
        # settled once passed and found by the run before too (a pose settled stays so)
        margin = detection.window + detection.trim
        passed = sum(1 for s in detection.segments if s.stop + margin <= n)
        seen, self._seen = self._seen, [(s.start, s.stop) for s in detection.segments]
        settled = min(self._settled, passed)
        for s in detection.segments[settled:passed]:
            if not any(
                abs(s.start - a) <= detection.trim and abs(s.stop - b) <= detection.trim
                for a, b in seen
            ):
                break
            settled += 1
        self._settled = settled
        still = None
        captured = passed  # what the user is told was captured never waits for the check
        if detection.segments and passed < poses.n:
            last = detection.segments[-1]
            held = n - last.start
            still = held / poses.rate if poses.rate else float(held)
            # once captured, a held pose stays so: when the device starts to move, the
            # window's edge shortens the interval for a moment before the pose settles
            again = (
                self._held is not None and self._held[0] < last.stop and last.start < self._held[1]
            )
            if again or last.samples >= detection.min_samples + detection.window:
                captured = poses.n
                self._held = (last.start, last.stop)
        return LiveState(poses, settled, captured, still, n, "", said)
