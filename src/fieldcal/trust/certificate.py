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
    sensors = stats.sensors
    # each column as Python numbers in one call, then the rows (no numpy scalar per entry)
    counts = {s: stats.sensor(s).counts.tolist() for s in sensors}
    cut = {s: t.tolist() for s in sensors if (t := stats.sensor(s).trimmed) is not None}
    residual = {s: (-ev.raw[s]).tolist() for s in sensors}
    means = None if stats.temperature is None else stats.temperature.means.tolist()
    shares = (cost / total).tolist() if total > 0 else [0.0] * len(cost)
    samples = [max(n) for n in zip(*counts.values(), strict=True)]
    keys = [(s, f"{s}_samples", f"{s}_trimmed", f"{s}_residual") for s in sensors]
    rows = []
    for i, (pose, c) in enumerate(zip(index.tolist(), cost.tolist(), strict=True)):
        row: dict[str, object] = {"index": int(pose)}
        for s, n_key, cut_key, residual_key in keys:
            row[n_key] = counts[s][i]
            if s in cut and cut[s][i]:
                row[cut_key] = cut[s][i]
            row[residual_key] = residual[s][i]
        row["samples"] = samples[i]
        if means is not None:  # the pose's mean temperature (°C): the report's
            row["temperature"] = float(means[i])
        row["cost"] = c
        row["share"] = shares[i]
        rows.append(row)
    return rows
