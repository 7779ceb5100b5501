"""Noise levels and disturbances of the continuous fit, estimated from its residuals.

- **Stretches** (``STRETCH`` seconds): each field sensor's variance per stretch, the mean of its
  squared residuals there (at least a floor). The accelerometer's residual holds its noise and
  the body's acceleration, which a hand makes in bursts: a stretch where the hand accelerates
  the device weighs by its own larger variance, rests weigh most. This is the maximum of the
  likelihood over one variance per stretch (Eq. C6 of ``docs/methods/continuous.md``).
- **Gyroscope**: one variance of the rate, ``σ_ω²``, measured from the raw rates' second
  differences (``Var(r_{j+1} − 2 r_j + r_{j−1}) = 6 σ²`` for white noise; the median absolute
  deviation ignores the motion's own changes); a factor's variance is ``σ_ω² Δt²``. Not from
  the factors' residuals alone: with a rotation per epoch the trajectory absorbs most of them
  (see below).
- **What the fit keeps**: the trajectory absorbs part of every error, so variances taken from
  the residuals are divided by the share of its errors each sensor keeps
  (:func:`.uncertainty.kept_shares`, the REML-type correction); the gyroscope's rate
  variance is the raw rates' white noise unless its factors misfit far beyond it
  (:func:`.rounds.gyro_variance`).
- **Correlation in time** (body acceleration is smooth, a disturbance passes over seconds) is
  not a weight: the sandwich covariance (:mod:`.uncertainty`, Eq. C9) widens each parameter's
  error bar by what the correlated residuals do to it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["STRETCH", "gyro_rate_variance", "stretch_variance"]

Array = NDArray[np.float64]

#: Seconds over which a field sensor's variance is taken as constant.
STRETCH = 2.0


def stretch_variance(residual: Array, length: int, floor: float) -> tuple[Array, Array]:
    """Per-sample variance (n,) of a sensor's residuals (n, 3), constant over stretches of
    ``length`` samples, at least ``floor``; and the stretches' own variances."""
    n = len(residual)
    k = max(1, int(length))
    m = -(-n // k)
    sq = np.zeros(m * k)
    sq[:n] = np.sum(residual**2, axis=1) / 3.0
    counts = np.minimum(k, n - np.arange(m) * k)
    per = sq.reshape(m, k).sum(axis=1) / counts
    per = np.maximum(per, floor)
    return np.repeat(per, k)[:n], per


def gyro_rate_variance(raw: Array, gain: Array) -> float:
    """``σ_ω²`` (rad²/s², per axis) of the gyroscope's white noise (module docstring)."""
    d2 = raw[2:] - 2.0 * raw[1:-1] + raw[:-2]
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
    raw_var = (1.4826 * mad) ** 2 / 6.0
    Ginv = np.linalg.inv(gain)
    return float(max(np.trace(Ginv @ np.diag(raw_var) @ Ginv.T) / 3.0, 1e-20))
