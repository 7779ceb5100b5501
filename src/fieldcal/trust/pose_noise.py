"""Pose-level noise ``Q_s = q_s² I``, estimated together with the calibration.

A pose mean's error is not only white noise averaged over ``Δ`` samples (Eq. 7): sensor
non-linearity, a field that changes across the desk, drift and flexing add an error per pose
that does not average away. Its covariance is ``C_si = Σ_s/Δ_si + q_s² I``.

Estimator (REML-type moment equation, ``docs/methods/pose-noise.md``). For each sensor ``q_s²``
solves

    J_s(q²) = ν_s(q²),     J_s = Σ_i r_siᵀ C_si⁻¹ r_si,     ν_s = 3N − tr(H_ss)

— the whitened residual sum of squares equals its expectation, the residual degrees of freedom
(the hat matrix ``H`` accounts for the parameters fitted, as REML does). ``J_s`` falls with
``q²``; when ``J_s(0) ≤ ν_s`` the data show no pose-level noise and ``q_s = 0``. The root is
found with the parameters held, then the calibration is refitted with the new weights (methods
that weigh poses by ``C_si``) and ``ν_s`` re-evaluated, until ``q_s`` settles.

One sample per pose (no Eq. 7) is the special case ``Σ_s = 0``: then ``q_s² = J_s(1)/ν_s``
is the noise from the residuals, reported as the sample noise.

Standard error: ``J_s`` is close to χ²(ν_s), so ``se(q²) = sqrt(2 ν_s) / |dJ_s/dq²|`` and
``se(q) = se(q²) / 2q``; at ``q = 0`` the reported value is ``sqrt(se(q²))``, the size of ``q``
the data could hide.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from math import sqrt

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from ..stats.pose_stats import PoseStats, SensorStats
from .evaluate import Evaluation, evaluate

__all__ = ["PoseNoise", "estimate", "estimated_share", "solve_pose_variance"]

Array = NDArray[np.float64]

#: Degrees of freedom of a q² estimated on top of Eq. 7's scatter, relative to ``ν_s``. Such a
#: q varies about 1.4 times more than ``χ²(ν_s)`` implies (``benchmarks/trust.py``: the SD of
#: ``(q̂ − q)/se`` is 1.15-1.4 at N = 20 and 1.7 at N = 11 with the nominal count, and the pose
#: tests raised 4 times their nominal false alarms), so it is worth about half its nominal
#: degrees of freedom; its standard error, the widening of the error bars and the pose tests'
#: reference distribution use this. With one sample per pose the estimate is the classical
#: residual variance and keeps its nominal count (sap6's split-half z is 0.4-1.0 with it).
EFFECTIVE_DOF = 0.5


def dof_factor(sensor: SensorStats) -> float:
    """The share of ``ν_s`` the estimated q² of this sensor is worth (see EFFECTIVE_DOF)."""
    return EFFECTIVE_DOF if sensor.cov is not None else 1.0


#: Relative change of every q below which the fixed point has settled (q's own standard
#: error is 10 % or more, so a finer root changes nothing that matters).
RTOL = 0.02
MAX_ROUNDS = 30


@dataclass(frozen=True)
class PoseNoise:
    """Each sensor's pose-level variance, its standard error and whether it was estimated."""

    variance: dict[str, float]
    std_se: dict[str, float | None]
    estimated: tuple[str, ...]
    rounds: int


def whitened_terms(sensor: SensorStats, raw: Array) -> tuple[Array, Array]:
    """``(Vᵀ r_i)²`` and ``λ_j / Δ_i`` per pose and axis, with ``Σ = V diag(λ) Vᵀ``, so that
    ``r_iᵀ C_i⁻¹ r_i = Σ_j proj_ij / (lam_ij + q²)`` for any ``q²``."""
    if sensor.cov is None:
        return raw * raw, np.zeros_like(raw)
    lam, V = _eigh(np.asarray(sensor.cov, dtype=np.float64).tobytes())
    proj = (raw @ V) ** 2
    return proj, np.maximum(lam, 0.0)[None, :] / sensor.counts[:, None]


@functools.lru_cache(maxsize=16)
def _eigh(cov: bytes) -> tuple[Array, Array]:
    """The eigen-decomposition of a 3x3 covariance given by its bytes: the same Σ of Eq. 7 in
    every round of the fixed point and in the standard error, decomposed once."""
    lam, V = np.linalg.eigh(np.frombuffer(cov).reshape(3, 3))
    lam.setflags(write=False)
    V.setflags(write=False)
    return lam, V


def solve_pose_variance(proj: Array, lam: Array, target: float) -> float:
    """The ``q² ≥ 0`` with ``J(q²) = Σ proj / (lam + q²) = target`` (0 when ``J(0)`` is
    below it).

    ``J`` is convex and falls monotonically in ``q²``, so Newton's method from the left of the
    root (where ``J > target``) climbs to it without overshooting; a few steps suffice.
    """
    if target <= 0:
        return 0.0
    proj, lam = proj.ravel(), lam.ravel()
    if not lam.any():  # one sample per pose: J = Σ proj / q², solved in closed form
        total = float(proj.sum())
        return total / target if total > 0 else 0.0
    positive = bool(lam.min() > 0)
    if positive and float(proj @ (1.0 / lam)) <= target:
        return 0.0
    # a start left of the root: below the smallest q² at which J could reach the target
    q2 = 0.0 if positive else 1e-12 * float(proj.sum()) / target
    for _ in range(100):
        inv = 1.0 / (lam + q2)
        weighted = proj * inv
        value = float(weighted.sum()) - target
        slope = float(weighted @ inv)
        if slope <= 0:
            return q2
        step = value / slope
        q2 += step
        if step <= 1e-12 * q2:
            break
    return float(q2)


def _std_error(proj: Array, lam: Array, q2: float, nu: float, factor: float) -> float:
    slope = float(np.sum(proj / (lam + q2) ** 2))
    if slope <= 0 or nu <= 0:
        return float("inf")
    # J varies like χ² with the estimate's effective degrees of freedom, scaled to mean ν
    se_var = nu * np.sqrt(2.0 / (factor * nu)) / slope
    if q2 > 0:
        return float(se_var / (2.0 * np.sqrt(q2)))
    return float(np.sqrt(se_var))


def _initial_variance(means: Array) -> float:
    # one sample per pose: only the ratio between the sensors matters for the first fit; 1e-3
    # of the spread is a typical MEMS noise-to-range ratio and the fixed point corrects it
    spread = float(np.sqrt(np.mean(np.sum((means - means.mean(axis=0)) ** 2, axis=1))))
    return (1e-3 * max(spread, 1e-300)) ** 2


def with_variances(stats: PoseStats, variance: dict[str, float]) -> PoseStats:
    """``stats`` with these pose-level variances (``stats`` itself when it has them already:
    the same object keeps what was built from it, the whitened problem among them)."""
    changed = {
        s: stats.sensor(s).with_pose_var(v)
        for s, v in variance.items()
        if s in stats.sensors and stats.sensor(s).pose_var != float(v)
    }
    return stats.replace(**changed) if changed else stats


def estimated_share(sensor: SensorStats, q2: float) -> float:
    """The share ``w`` of the estimated pose-level variance ``q2`` in a pose mean's variance,
    ``tr(Σ/Δ_i + q² I)/3`` averaged over the poses (in closed form: ``tr Σ`` times the mean of
    ``1/Δ_i``, not one 3x3 covariance per pose)."""
    within = 0.0
    if sensor.cov is not None:
        mean_inverse = float((1.0 / sensor.counts).sum()) / len(sensor.counts)
        within = float(np.trace(sensor.cov)) * mean_inverse / 3.0
    total = within + sensor.pose_var
    return min(q2 / total, 1.0) if total > 0 else 1.0


def initial_variances(stats: PoseStats, fixed: dict[str, float | None]) -> PoseStats:
    """The statistics for the first fit: the user's pose-level variances where given, 0 where
    estimated (one sample per pose: a first guess that :func:`estimate` corrects)."""
    variance = {}
    for s in stats.sensors:
        sensor = stats.sensor(s)
        given = fixed.get(s)
        if given is not None:
            variance[s] = given
        elif sensor.cov is None:
            variance[s] = _initial_variance(sensor.means)
        else:
            variance[s] = 0.0
        if sensor.cov is None and not variance[s] > 0:
            raise ValueError(
                f"{s}: one sample per pose gives no within-pose scatter (Eq. 7), so its noise "
                "must come from the residuals: use pose_noise='auto' (--pose-noise auto) or give "
                "noise=... (--noise)"
            )
    return with_variances(stats, variance)


def estimate(
    refit: Callable[[PoseStats, Calibration], Calibration],
    cal: Calibration,
    stats: PoseStats,
    body_frame: str,
    free: tuple[str, ...],
) -> tuple[Calibration, PoseStats, Evaluation, PoseNoise]:
    """Estimate the pose-level variance of the sensors in ``free``.

    ``cal`` was fitted to ``stats`` (:func:`initial_variances`); ``refit(stats, previous)``
    fits again with other weights. Returns the final calibration, the statistics with the
    variances set, the model evaluated there, and the estimates.
    """
    sensors = stats.sensors
    variance = {s: stats.sensor(s).pose_var for s in sensors}
    current = stats
    ev = evaluate(cal, current, body_frame)
    rounds = 0
    terms: dict[str, tuple[Array, Array]] = {}  # whitened_terms at ``current`` and ``ev``
    while free and rounds < MAX_ROUNDS:
        rounds += 1
        shares = ev.dof_share()
        new = dict(variance)
        terms = {s: whitened_terms(current.sensor(s), ev.raw[s]) for s in free}
        for s in free:
            new[s] = solve_pose_variance(*terms[s], shares[s])
        # settled: the fit made with the current q stands (a change below RTOL is far inside
        # q's own standard error), so no refit is spent on confirming it
        if all(abs(sqrt(new[s]) - sqrt(variance[s])) <= RTOL * sqrt(new[s]) for s in free):
            break
        variance = new
        current = with_variances(stats, variance)
        cal = refit(current, cal)
        ev = evaluate(cal, current, body_frame)
        terms = {}  # made at the previous point
    shares = ev.dof_share()
    std_se: dict[str, float | None] = {s: None for s in sensors}
    for s in free:
        proj, lam = terms[s] if s in terms else whitened_terms(current.sensor(s), ev.raw[s])
        std_se[s] = _std_error(proj, lam, variance[s], shares[s], dof_factor(current.sensor(s)))
    return cal, current, ev, PoseNoise(variance, std_se, free, rounds)


def widening(ev: Evaluation, noise: PoseNoise, stats: PoseStats) -> float:
    """Factor on every variance for the pose-level noise having been estimated.

    With a variance estimated from ``ν`` degrees of freedom a standardised error follows
    Student's t, of variance ``ν/(ν − 2)``; only the estimated part of each pose mean's
    variance carries that uncertainty, so the factor is weighted by its share ``w``.
    """
    shares = ev.dof_share()
    factor = 1.0
    for s in noise.estimated:
        q2 = noise.variance[s]
        if not q2 > 0:
            continue
        sensor = stats.sensor(s)
        w = estimated_share(sensor, q2)
        nu = dof_factor(sensor) * shares[s]
        # Student's t with 2 or fewer degrees of freedom has no variance: then be generous
        factor = max(factor, 1.0 + w * 2.0 / (nu - 2.0) if nu > 3 else 1.0 + w * 2.0)
    return factor


def noise_reported(sensor: SensorStats) -> Array:
    """The per-sample noise to report: Eq. 7's, or (one sample per pose) the pose variance."""
    if sensor.cov is not None:
        return np.asarray(sensor.cov)
    return np.eye(3) * sensor.pose_var
