"""Error bars widened for the correlation between neighbouring poses of one continuous motion.

A log cut into samples or short windows (``poses="samples"``, ``"windows"``) gives poses that
are consecutive pieces of one motion: the hand's acceleration, the arc swept inside a window
and a slow magnetic disturbance are shared by neighbours, so their residuals are correlated
and the Cramér–Rao covariance, which treats the poses as independent, is too small. The
correction is measured, not assumed: the autocorrelation ``ρ_k`` of the poses' residuals
along time (each sensor's residuals divided by their RMS, summed over the axes) gives the
integrated autocorrelation time

    τ = 1 + 2 Σ_{k=1}^{M} ρ_k,

the variance of a mean of ``N`` correlated terms being ``τ`` times that of ``N`` independent
ones (Newey & West 1987 give the matching long-run covariance of the score; here one scalar
for every parameter, the scores being the residuals weighed by slowly turning directions).
The window ``M`` is chosen automatically as the smallest with ``M ≥ c τ(M)`` (Sokal's
rule, ``c`` = :data:`WINDOW_FACTOR`): long enough to hold the correlation, short enough that
the noise of the far lags does not swamp it. τ is measured per sensor, on its own residuals
(summed over the axes), and the covariance is multiplied by the larger ``max(τ, 1)`` (the
sensors share the rotations, so one sensor's correlated disturbance reaches the other's
parameters); ``N/τ`` is the effective number of independent poses. Independent poses (still
detection) are never touched.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration, ParameterCovariance
from ..findings import PoseCorrelation as Correlated

__all__ = ["WINDOW_FACTOR", "PoseCorrelation", "measure_correlation", "widen_for_correlation"]

Array = NDArray[np.float64]

#: Sokal's automatic window: the lags summed reach ``WINDOW_FACTOR`` times the estimated τ.
WINDOW_FACTOR = 5.0
#: Fewest poses for a measured correlation (fewer: none is claimed, the error bars stay).
FEWEST_POSES = 20
#: The status the fit certificate takes when the correction applies (not a test then).
STATUS = "correlated poses"


@dataclass(frozen=True)
class PoseCorrelation:
    """The correlation measured between neighbouring poses of a time-ordered log.

    Attributes
    ----------
    tau : float
        Integrated autocorrelation time of the residuals, in poses (1: independent).
    lags : int
        The window ``M`` of lags summed (Sokal's rule).
    poses : int
        Poses in the series.
    widening : float
        ``sqrt(max(tau, 1))``: the factor every standard error was multiplied by.
    reached : bool
        Whether the window rule was met before a quarter of the series (False: the
        correlation is longer than the log can measure, ``tau`` is a lower bound).
    """

    tau: float
    lags: int
    poses: int
    reached: bool = True

    @property
    def widening(self) -> float:
        return float(np.sqrt(max(self.tau, 1.0)))

    @property
    def effective(self) -> float:
        """The effective number of independent poses, ``N / max(τ, 1)``."""
        return self.poses / max(self.tau, 1.0)

    def to_dict(self) -> dict[str, object]:
        return {
            "tau": self.tau,
            "lags": self.lags,
            "poses": self.poses,
            "effective_poses": self.effective,
            "widening": self.widening,
            "window_reached": self.reached,
        }


def measure_correlation(residuals: Array, *, factor: float = WINDOW_FACTOR) -> PoseCorrelation:
    """τ of a multivariate series of residuals (N, d), rows in time order.

    Each column is centred; the autocovariances of the columns (by FFT, O(N log N)) are
    summed, normalised by lag 0 and summed up to Sokal's window (see the module's text).
    Columns should be on comparable scales (e.g. each sensor divided by its RMS).
    """
    x = np.asarray(residuals, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    n = len(x)
    x = x - x.mean(axis=0)
    size = 1 << int(2 * n - 1).bit_length()
    spectrum = np.fft.rfft(x, size, axis=0)
    acov = np.fft.irfft(np.sum(np.abs(spectrum) ** 2, axis=1), size)[:n]
    if not acov[0] > 0:
        return PoseCorrelation(tau=1.0, lags=0, poses=n)
    rho = acov / acov[0]
    tau_m = 1.0 + 2.0 * np.cumsum(rho[1:])  # τ(M) for M = 1, 2, ...
    last = max(1, n // 4)
    m = np.arange(1, len(tau_m) + 1)
    ok = np.flatnonzero(m[:last] >= factor * tau_m[:last])
    if ok.size:
        lags = int(ok[0]) + 1
        return PoseCorrelation(tau=float(tau_m[lags - 1]), lags=lags, poses=n)
    lags = min(last, len(tau_m))
    return PoseCorrelation(tau=float(tau_m[lags - 1]), lags=lags, poses=n, reached=False)


def _residual_series(cal: Calibration) -> dict[str, Array]:
    """Each sensor's residuals of the fitted poses in the order of the poses (their
    ``index``), (N, 3) in raw units; empty when the pose table has none."""
    rows = sorted(
        (p for p in cal.poses if "index" in p and not p.get("rejected")),
        key=lambda p: int(p["index"]),
    )
    out = {}
    for sensor in ("accel", "mag"):
        key = f"{sensor}_residual"
        if rows and all(key in p for p in rows):
            out[sensor] = np.array([p[key] for p in rows], dtype=float).reshape(-1, 3)
    return out


def widen_for_correlation(cal: Calibration) -> Calibration:
    """``cal`` with its covariance multiplied by τ measured on its pose residuals.

    For poses that are consecutive pieces of one continuous motion, in time order (the pose
    table's ``index``). τ is measured per sensor on its own residuals and the larger is
    applied to every parameter: the sensors share the poses' rotations, so a hand's
    acceleration correlates the magnetometer's parameters too though its own residuals look
    nearly white. Records ``options["pose_correlation"]`` (the larger τ, its lags, effective
    number of poses and widening, and each sensor's :meth:`PoseCorrelation.to_dict`) and
    sets the certificate's status to ``"correlated poses"``: its χ² treats the poses as
    independent, so it is not a test of the model here. A calibration with fewer than
    :data:`FEWEST_POSES` poses is returned as it is.
    """
    series = _residual_series(cal)
    if not series or min(len(r) for r in series.values()) < FEWEST_POSES:
        return cal
    found = {s: measure_correlation(r) for s, r in series.items()}
    worst = max(found.values(), key=lambda c: c.tau)
    covariance = cal.covariance
    if covariance is not None:
        covariance = ParameterCovariance(covariance.names, covariance.matrix * max(worst.tau, 1.0))
    diagnostics = cal.diagnostics
    if diagnostics is not None:
        diagnostics = dataclasses.replace(diagnostics, status=STATUS)
    record = {**worst.to_dict(), "sensors": {s: c.to_dict() for s, c in found.items()}}
    finding = Correlated(
        tau=float(worst.tau),
        effective_poses=float(worst.effective),
        poses=int(worst.poses),
        widening=float(worst.widening),
    )
    return dataclasses.replace(
        cal,
        covariance=covariance,
        diagnostics=diagnostics,
        # the record stays in options: the file's documented key (docs/cli.md)
        options={**cal.options, "pose_correlation": record},
        findings=dataclasses.replace(cal.findings, pose_correlation=finding),
    )
