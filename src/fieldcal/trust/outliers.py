"""Per-pose, per-sensor tests: is this pose's reading explained by the model?

Statistic. For sensor ``s`` in pose ``i`` the whitened residual ``e_si`` has, in the linearised
model, covariance ``I − H_ii,ss`` (``H`` the hat matrix: the fit absorbs part of each residual,
most of all for poses of high leverage). The pose's own rotation absorbs whole directions (a
turn about the field ``h`` moves only the accelerometer's reading, one about gravity only the
magnetometer's), so the test uses the ``r`` directions the fit leaves at least
:data:`MIN_SHARE` of their variance:

    t_si = Σ_k (v_kᵀ e_si)² / λ_k  ~  χ²(r),    I − H_ii,ss = Σ_k λ_k v_k v_kᵀ.

When the pose-level variance was estimated, the statistic is externally studentised, as in
regression diagnostics: deleting pose ``i`` lowers the sensor's cost by exactly ``t_si`` and its
degrees of freedom by ``r`` (linear model), so the variance estimated without the pose is
``(J_s − t_si)/(ν_s − r)`` of the current one, and ``t`` is divided by that (for the estimated
share ``w`` of the pose mean's variance only). One disturbed pose can then not hide by inflating
``q²`` for everyone, nor by dragging the fit so that every pose's residual grows. ``t/r``
follows ``F(r, ν_eff)`` with ``ν_eff = c (ν_s − r) / w²`` (Satterthwaite; ``c`` =
:func:`~fieldcal.trust.pose_noise.dof_factor`, the estimate's measured share of its nominal
degrees of freedom; ``ν_eff → ∞`` and the χ²(r) law when nothing was estimated).

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

from ..stats.pose_stats import PoseStats
from .evaluate import Evaluation
from .pose_noise import PoseNoise, dof_factor, estimated_share

__all__ = ["REASONS", "PoseTests", "pose_tests"]

Array = NDArray[np.float64]

#: One line per kind of rejection, naming the cause and the fix.
REASONS = {
    "mag": "magnetic disturbance: the magnetometer disagrees and the accelerometer does not; "
    "take this pose away from steel, magnets and electronics",
    "accel": "moved or bumped: the accelerometer disagrees with every other pose; hold the "
    "device still against a fixed support",
    "both": "moved or bumped: both sensors disagree with every other pose; hold the device "
    "still against a fixed support",
    "turned": "moved during the pose: the magnetometer's readings swing within it while the "
    "accelerometer's stay (a turn about the vertical); hold the device still",
    "angle": "the angle between gravity and the magnetic field in this pose disagrees with the "
    "other poses: a magnetic disturbance or the device moved (one pose cannot tell which); take "
    "this pose again, still and away from iron",
}

#: A failing residual with less than this share of its square along the sensor's own field is
#: "across": the pose's rotation spreads such an error over both sensors, so the sensor to
#: blame cannot be told.
RADIAL = 0.5

#: A pose whose own scatter exceeds this multiple of the typical pose's moved within it.
SWING = 10.0

_EYE = np.eye(3)
_EYE.setflags(write=False)


@dataclass(frozen=True)
class PoseTests:
    """Statistics (N, #sensors), p-values (N, #sensors) and the sensors' names."""

    sensors: tuple[str, ...]
    statistic: Array
    p_value: Array
    radial: Array  # (N, #sensors): share of each residual's square along the sensor's field

    def flagged(self, alpha: float) -> NDArray[np.bool_]:
        """Poses any sensor of which fails at family-wise rate ``alpha`` (Bonferroni)."""
        n, k = self.p_value.shape
        return np.asarray(np.any(self.p_value < alpha / (n * k), axis=1))

    def kind(self, i: int, alpha: float, stats: PoseStats) -> tuple[str, str]:
        """Which sensors fail in pose ``i`` (``"mag"``, ``"accel"`` or ``"both"``) and the
        reason's key in :data:`REASONS`: a failing magnetometer whose readings swung within the
        pose turned with the device, otherwise it met a disturbed field."""
        n, k = self.p_value.shape
        failing = [s for j, s in enumerate(self.sensors) if self.p_value[i, j] < alpha / (n * k)]
        if len(failing) == 2:
            return "both", "angle" if self.radial[i].max() < RADIAL else "both"
        sensor = failing[0] if failing else self.sensors[int(np.argmin(self.p_value[i]))]
        scatter = stats.sensor(sensor).scatter
        if sensor == "mag" and scatter is not None and scatter[i] > SWING * np.median(scatter):
            return "mag", "turned"
        if len(self.sensors) == 2 and self.radial[i, self.sensors.index(sensor)] < RADIAL:
            return sensor, "angle"
        return sensor, sensor


#: A sensor whose estimated variance keeps fewer degrees of freedom than this once a pose is
#: deleted is studentised with the whole pose's deletion (both sensors): one-reading-per-pose
#: sets of 8–16 poses (measured: ``benchmarks/trust.py``, part 6, small sets).
MIN_OWN_DOF = 8.0

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
    radial = np.ones((n, len(sensors)))
    joint: Array | None = None  # the joint deletion identity, computed when first needed
    joint_made = False
    # every sensor's own test at once: its whitened residuals and leverage blocks, stacked
    blocks = [ev.block(s) for s in sensors]
    own = np.concatenate([lev[:, b, b] for b in blocks]) if len(blocks) > 1 else lev
    t_all, r_all = _studentised(
        ev.whitened.reshape(n, len(sensors), 3).transpose(1, 0, 2).reshape(-1, 3), _EYE - own
    )
    for j, s in enumerate(sensors):
        along = np.einsum("ni,ni->n", ev.raw[s], ev.directions[s]) ** 2
        radial[:, j] = along / np.maximum(np.einsum("ni,ni->n", ev.raw[s], ev.raw[s]), 1e-300)
        t, r = t_all[j * n : (j + 1) * n], r_all[j * n : (j + 1) * n]
        w = _estimated_share(stats, noise, s)
        if w > 0:
            # delete pose i: J_s loses exactly t_i (linear model), the degrees of freedom r_i;
            # only the estimated share w of each pose mean's variance rescales with it
            J, nu = ev.sensor_cost(s), shares[s]
            ratio = (J - t) / np.maximum(nu - r, 1.0) / max(J / nu, 1e-300)
            # the poses' rotations couple the sensors, so one sensor's deletion identity is
            # only approximate; with few degrees of freedom of its own a pose can seem to hold
            # all of a sensor's cost (J_s − t_s ≤ 0, the variance left 0, every test
            # significant): there the pose's joint identity, exact, stands in. With enough
            # degrees of freedom for every pose (30 poses or more, measured) it is not needed,
            # and its eigen-decompositions of the (N, 6, 6) blocks are not made.
            few = (nu - r) < MIN_OWN_DOF
            if few.any():
                if not joint_made:
                    joint, joint_made = _joint_deletion(ev, lev), True
                if joint is not None:
                    ratio = np.where(few, np.maximum(ratio, joint), ratio)
            scale = np.maximum(1.0 - w + w * np.maximum(ratio, 0.0), max(1.0 - w, 1e-6))
            t = t / scale
            c = dof_factor(stats.sensor(s))
            nu_eff = np.minimum(c * np.maximum(nu - r, 1.0) / (w * w), 1e7)
        else:
            nu_eff = np.full(n, 1e7)
        stat[:, j] = t
        pval[:, j] = fdtrc(r, nu_eff, np.maximum(t, 0.0) / r)
    return PoseTests(sensors, stat, pval, radial)


def _joint_deletion(ev: Evaluation, lev: Array) -> Array | None:
    """Per pose, the variance left without it relative to the current one, from the whole
    pose (both sensors): ``(J − t_i) / (ν − r_i) / (J / ν)`` with ``t_i`` the pose's
    studentised cost over all its readings (exact deletion identity of the linear model);
    ``None`` with one sensor (the sensor's own identity is then the joint one)."""
    if len(ev.problem.sensors) < 2:
        return None
    m = ev.whitened.shape[1]
    t, r = _studentised(ev.whitened, np.eye(m) - lev)
    J = float(ev.pose_cost.sum())
    nu = float(sum(ev.dof_share().values()))
    if not (J > 0 and nu > 0):
        return None
    return np.asarray(np.maximum(J - t, 0.0) / np.maximum(nu - r, 1.0) / (J / nu))


def _estimated_share(stats: PoseStats, noise: PoseNoise, sensor: str) -> float:
    """The estimated pose-level variance's share of a pose mean's variance (0 when fixed)."""
    if sensor not in noise.estimated or not noise.variance[sensor] > 0:
        return 0.0
    return estimated_share(stats.sensor(sensor), noise.variance[sensor])
