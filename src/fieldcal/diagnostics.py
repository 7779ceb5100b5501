"""The likelihood of Eq. 8 evaluated per pose, and the fit certificate built from it."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import stats as _stats

from .model import Calibration, Diagnostics
from .poses import PoseStats

__all__ = ["certify", "pose_costs"]

Array = NDArray[np.float64]


def pose_costs(cal: Calibration, stats: PoseStats) -> Array:
    """Each pose's term of Eq. 8, ``Σ_s Δ_s[i] rᵀ Σ̂_s⁻¹ r`` with ``r = K_s R_i f_s + b_s − μ̂_s[i]``.

    Uses the noise covariances stored in ``cal`` (``noise_cov``), which are Eq. 7's estimate
    unless the noise was given or estimated from residuals.
    """
    predicted = cal.predicted_means()
    total = np.zeros(stats.n_poses)
    for sensor_stats, sensor_cal, mean in (
        (stats.accel, cal.accel, predicted[0]),
        (stats.mag, cal.mag, predicted[1]),
    ):
        if sensor_stats is None or sensor_cal is None:
            continue
        r = mean - sensor_stats.means
        whitened = np.linalg.solve(sensor_cal.noise_cov, r.T).T
        total += sensor_stats.counts * np.einsum("ni,ni->n", r, whitened)
    return total


def certify(cal: Calibration, stats: PoseStats, dof: int, status: str = "") -> Diagnostics:
    """χ² certificate: at the ML optimum ``J`` (Eq. 8) ~ χ²(dof); ``p_value`` is its upper tail."""
    per_pose = pose_costs(cal, stats)
    statistic = float(per_pose.sum())
    p_value = float(_stats.chi2.sf(statistic, dof)) if dof > 0 else float("nan")
    return Diagnostics(
        statistic=statistic, dof=int(dof), p_value=p_value, pose_cost=per_pose, status=status
    )


def pose_table(diagnostics: Diagnostics, stats: PoseStats) -> tuple[dict, ...]:
    """One dict per pose for ``Calibration.poses``: samples, cost and share of the total."""
    share = diagnostics.pose_share
    rows = []
    for i in range(stats.n_poses):
        row: dict = {"index": i}
        if stats.accel is not None:
            row["accel_samples"] = int(stats.accel.counts[i])
        if stats.mag is not None:
            row["mag_samples"] = int(stats.mag.counts[i])
        row["samples"] = max(row.get("accel_samples", 0), row.get("mag_samples", 0))
        row["cost"] = float(diagnostics.pose_cost[i])
        row["share"] = float(share[i])
        rows.append(row)
    return tuple(rows)
