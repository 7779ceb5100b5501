"""The χ² certificate of Eq. 8 and the per-pose table, from the model's evaluation."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.special import chdtrc

from ..calibration import Diagnostics
from ..stats.pose_stats import PoseStats
from .evaluate import Evaluation

__all__ = ["certify", "pose_table"]


def certify(ev: Evaluation, status: str) -> Diagnostics:
    """At the ML optimum ``J`` (Eq. 8) ~ χ²(dof); ``p_value`` is its upper tail.

    When the pose-level noise was estimated, ``J`` equals its degrees of freedom by
    construction for that sensor and the test carries no information: ``status`` says so.
    """
    per_pose = ev.pose_cost
    statistic = float(per_pose.sum())
    dof = ev.dof
    p_value = float(chdtrc(dof, statistic)) if dof > 0 else float("nan")
    return Diagnostics(statistic, dof, p_value, per_pose, status)


def pose_table(
    ev: Evaluation, stats: PoseStats, index: NDArray[np.int64]
) -> list[dict[str, object]]:
    """One dict per pose in the fit: caller's index, samples (and trimmed), cost, share, the
    residual of each sensor in raw units (the pose mean minus the model) and, with a
    temperature column, the pose's mean temperature (°C)."""
    cost = ev.pose_cost
    total = float(cost.sum())
    rows = []
    for i in range(stats.n_poses):
        row: dict[str, object] = {"index": int(index[i])}
        for s in stats.sensors:
            sensor = stats.sensor(s)
            row[f"{s}_samples"] = int(sensor.counts[i])
            if sensor.trimmed is not None and sensor.trimmed[i]:
                row[f"{s}_trimmed"] = int(sensor.trimmed[i])
            row[f"{s}_residual"] = [float(-x) for x in ev.raw[s][i]]
        row["samples"] = max(int(stats.sensor(s).counts[i]) for s in stats.sensors)
        if stats.temperature is not None:  # the pose's mean temperature (°C): the report's
            row["temperature"] = float(stats.temperature.means[i])
        row["cost"] = float(cost[i])
        row["share"] = float(cost[i] / total) if total > 0 else 0.0
        rows.append(row)
    return rows
