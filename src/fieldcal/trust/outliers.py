"""Per-pose, per-sensor tests: is this pose's reading explained by the model?

Statistic. For sensor ``s`` in pose ``i`` the whitened residual ``e_si`` has, in the linearised
model, covariance ``I − H_ii,ss`` (``H`` the hat matrix: the fit absorbs part of each residual,
most of all for poses of high leverage). The pose's own rotation absorbs whole directions (a
turn about the field ``h`` moves only the accelerometer's reading, one about gravity only the
magnetometer's), so the test uses the ``r`` directions the fit leaves at least
:data:`MIN_SHARE` of their variance:

    t_si = Σ_k (v_kᵀ e_si)² / λ_k  ~  χ²(r),    I − H_ii,ss = Σ_k λ_k v_k v_kᵀ.

The whitening uses the pose-level variance estimated *without* pose ``i`` (externally
studentised, as in regression diagnostics), so one disturbed pose cannot hide by inflating
``q²`` for everyone. With ``q²`` estimated from ``ν`` degrees of freedom, ``t/r`` follows
``F(r, ν_eff)`` with ``ν_eff = ν / w²`` (Satterthwaite; ``w`` is the estimated variance's share
of the pose mean's variance, so ``ν_eff → ∞`` and the χ² law when nothing was estimated).

Decision. A pose is flagged when a sensor's p-value is below ``α / (N · #sensors)``
(Bonferroni: family-wise false-alarm rate ``α`` per calibration, 1 % by default). A
magnetometer that fails with an accelerometer that passes is a magnetic disturbance (iron
nearby); a failing accelerometer means the device moved or was bumped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import fdtrc

from ..stats.poses import PoseStats
from .evaluate import Evaluation
from .pose_noise import PoseNoise, whitened_terms

__all__ = ["PoseTests", "REASONS", "pose_tests"]

Array = NDArray[np.float64]

#: One line per kind of rejection, naming the cause and the fix.
REASONS = {
    "mag": "magnetic disturbance: the magnetometer disagrees and the accelerometer does not; "
    "take this pose away from steel, magnets and electronics",
    "accel": "moved or bumped: the accelerometer disagrees with every other pose; hold the "
    "device still against a fixed support",
    "both": "moved or bumped: both sensors disagree with every other pose; hold the device "
    "still against a fixed support",
}

_GRID = 96


@dataclass(frozen=True)
class PoseTests:
    """Statistics (N, #sensors), p-values (N, #sensors) and the sensors' names."""

    sensors: tuple[str, ...]
    statistic: Array
    p_value: Array

    def flagged(self, alpha: float) -> NDArray[np.bool_]:
        """Poses any sensor of which fails at family-wise rate ``alpha`` (Bonferroni)."""
        n, k = self.p_value.shape
        return np.asarray(np.any(self.p_value < alpha / (n * k), axis=1))

    def kind(self, i: int, alpha: float) -> str:
        """``"mag"``, ``"accel"`` or ``"both"``: which sensors fail in pose ``i``."""
        n, k = self.p_value.shape
        failing = [s for j, s in enumerate(self.sensors) if self.p_value[i, j] < alpha / (n * k)]
        if len(failing) == 2:
            return "both"
        return failing[0] if failing else self.sensors[int(np.argmin(self.p_value[i]))]


def _external_variance(proj: Array, lam: Array, target: Array, q2_all: float) -> Array:
    """Per pose ``i``, the ``q²`` solving ``Σ_{k≠i} proj_k/(lam_k + q²) = target_i``.

    Evaluated on a log grid around the joint estimate (``J`` without pose ``i`` is ``J`` minus
    pose ``i``'s own term), then the root interpolated in ``log q²`` between grid points.
    """
    n = proj.shape[0]
    scale = max(q2_all, float(np.median(np.sum(proj, axis=1))) / 3.0, 1e-300)
    grid = scale * np.logspace(-8, 3, _GRID)
    terms = np.einsum("ij,gij->gi", proj, 1.0 / (lam[None] + grid[:, None, None]))  # (G, N)
    without = terms.sum(axis=1)[:, None] - terms  # (G, N): J_(−i)(q²) on the grid
    below = without <= target[None, :]
    first = np.where(below.any(axis=0), below.argmax(axis=0), _GRID - 1)
    out = np.zeros(n)
    positive = np.all(lam > 0)
    for i in range(n):  # N scalar interpolations; the heavy part above is vectorised
        g = first[i]
        if g == 0:
            out[i] = 0.0 if positive else grid[0]
            continue
        j0, j1 = without[g - 1, i], without[g, i]
        t = (np.log(j0) - np.log(target[i])) / max(np.log(j0) - np.log(j1), 1e-300)
        out[i] = float(np.exp(np.log(grid[g - 1]) + t * (np.log(grid[g]) - np.log(grid[g - 1]))))
    return out


#: Residual directions whose variance the fit leaves below this share carry no test: the pose's
#: own rotation absorbs them (a rotation about ``h`` moves only the accelerometer's reading).
MIN_SHARE = 0.02


def _studentised(e: Array, resid_cov: Array) -> tuple[Array, Array]:
    """``eᵀ (I − H)⁺ e`` over the directions the fit does not absorb, and their number."""
    lam, V = np.linalg.eigh(resid_cov)
    keep = lam > MIN_SHARE
    z = np.einsum("nij,ni->nj", V, e)
    t = np.sum(np.where(keep, z * z / np.where(keep, lam, 1.0), 0.0), axis=1)
    return t, np.maximum(keep.sum(axis=1), 1).astype(float)


def pose_tests(ev: Evaluation, stats: PoseStats, noise: PoseNoise) -> PoseTests:
    """The statistic and p-value of every pose and sensor (see the module docstring)."""
    sensors = ev.problem.sensors
    n = ev.problem.n
    shares = ev.dof_share()
    lev = ev.uncertainty.leverage
    stat = np.zeros((n, len(sensors)))
    pval = np.ones((n, len(sensors)))
    for j, s in enumerate(sensors):
        block = ev.block(s)
        H = lev[:, block, block]
        sensor = stats.sensor(s)
        raw = ev.raw[s]
        if s in noise.estimated:
            # whiten again with q² estimated without pose i
            proj, lam = whitened_terms(sensor, raw)
            target = shares[s] - (3.0 - np.einsum("nii->n", H))
            q2 = _external_variance(proj, lam, np.maximum(target, 1e-9), noise.variance[s])
            covs = sensor.with_pose_var(0.0).mean_covariances() + q2[:, None, None] * np.eye(3)
            total = np.trace(sensor.mean_covariances(), axis1=1, axis2=2).mean() / 3.0
            w = min(noise.variance[s] / total, 1.0) if total > 0 else 1.0
            nu_eff = min(shares[s] / max(w * w, 1e-12), 1e7)
        else:
            covs = sensor.mean_covariances()
            nu_eff = 1e7
        e = np.linalg.solve(np.linalg.cholesky(covs), raw[:, :, None])[:, :, 0]
        t, dof = _studentised(e, np.eye(3) - H)
        stat[:, j] = t
        pval[:, j] = fdtrc(dof, nu_eff, np.maximum(t, 0.0) / dof)
    return PoseTests(sensors, stat, pval)
