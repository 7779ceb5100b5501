"""Whether a log's poses can calibrate: enough of them for the method, spread over enough
distinct orientations, with the message that says how to get more (moved from
``fieldcal.pipeline``, which calls it before every pose fit)."""

from __future__ import annotations

from typing import Any

from ..errors import InputError
from ..logs import Log, PoseSet, turns_slowly
from ..logs.pose_hints import SEPARATE_READINGS, pose_advice
from ..stats.pose_stats import check_spread, stats_from_means
from . import get as get_method

__all__ = ["check_poses"]


def check_poses(
    poses: PoseSet,
    method: str,
    log: Log,
    rate: float | None,
    detection: dict[str, Any] | None = None,
) -> None:
    """Enough poses and orientations for ``method``, else an :class:`InputError` naming the
    fix. ``detection``: the settings the poses were found with in ``log`` (None: the poses were
    given): the message then says which other settings find how many
    (:func:`~fieldcal.logs.pose_hints.pose_advice`)."""
    n = poses.n
    sensors = [(name, getattr(poses, name)) for name in ("accel", "mag")]
    sensors = [(name, samples) for name, samples in sensors if samples is not None]
    need = get_method(method).min_poses_for(len(sensors))
    hints = None
    if detection is not None and poses.source in ("still", "column"):
        distinct = len({entry.get("orientation", i) for i, entry in enumerate(poses.entries)})
        if n < need or distinct < max(need, 8 if len(sensors) == 2 else 9):
            hints = pose_advice(log, found=poses, **detection)
    if n < need:
        advice = f"hold the device still in {need - n} or more further orientations"
        if hints is None and poses.source == "still" and turns_slowly(log, rate=rate):
            advice = "the log turns slowly without rests: use --poses windows (poses='windows')"
        separate = poses.source == "still" and log.time is None and rate is None
        if separate and log.gyro is None and "--poses samples" not in (hints or ""):
            advice = f"{SEPARATE_READINGS}; or {advice}"  # Magneto-style: a reading now and then
        why = " (the 6N readings must outnumber the 3N pose angles plus 22 sensor parameters)"
        raise InputError(
            f"{n} pose(s) found; the {method} method needs at least {need}"
            + (why if len(sensors) == 2 and hints is None else "")
            + (f": {hints}; or {advice}" if hints else f": {advice}")
        )
    means = {name: poses.means(name) for name, _ in sensors}
    try:
        check_spread(stats_from_means(means.get("accel"), means.get("mag")))
    except ValueError as exc:
        raise InputError(str(exc)) from None
    # one sensor alone: 9 unknowns (symmetric gain and bias), one constraint per orientation
    need = max(need, 8 if len(sensors) == 2 else 9)
    distinct = len({entry["orientation"] for entry in poses.entries})
    if distinct < need:
        raise InputError(
            f"the {n} poses show only {distinct} distinct orientations (closer than 3° count as "
            f"one); {'a joint' if len(sensors) == 2 else 'a single-sensor'} calibration needs at "
            f"least {need}: "
            + (f"{hints}; or add" if hints else "add")
            + " poses tilted between the axes (e.g. resting on the edges and corners of a box), "
            "not only with each axis up and down"
        )
