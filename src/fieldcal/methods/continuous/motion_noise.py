"""What the continuous model leaves out, as weights: body acceleration that does not average
down, and a field whose direction is not uniform (Eq. C6a–C6b of
``docs/methods/continuous.md``).

The per-stretch variances (:mod:`.weights`) measure how large the residuals are, not how much
of them is systematic. Two parts are, on real hand-held motion (BROAD against its motion
capture, ``benchmarks/broad_causes.py``):

- **Body acceleration** (C6a). The accelerometer's excess over its white noise in a stretch is
  what the model does not explain — the hand's travel, a turning point that moves, filter
  lags on fast turns. It is correlated with the orientation the hand is in, so it does not
  average down over the stretch's samples as noise would: counted as ``k`` independent draws
  it biases the accelerometer's bias and gain (BROAD 06: 4 % of gain, 3.9° of tilt at 4σ).
  It is counted once per stretch: each sample's variance is ``σ²_white + k (σ²_stretch −
  σ²_white − c)`` (``k`` samples per stretch, ``σ²_white`` the quietest tenth's, ``c``
  :data:`CHANCE` times the scatter of a white-noise stretch's variance, ``σ²_white √(2/(3k))``:
  chance):
  quiet stretches keep their weight, moving ones inform the gravity direction as one
  observation each. On the knots (:mod:`.knots`) the excess is read from the samples'
  residuals (:func:`sample_excess`): a knot is its window's mean and hides the part above the
  knot rate (BROAD 01: the knots' own excess gave a predicted tilt of 0.18°, the samples' 0.42°,
  for 1.28° measured), while a
  stretch's information about the gravity direction is ``1/excess`` whichever rows carry it.
- **The field's direction** (C6b). Indoors the field's direction varies by degrees over a
  metre (BROAD's lab: the vendor's own heading is 3–3.5° RMS from the motion capture). The
  rotation absorbs a direction error of the magnetometer, so its residuals do not show it; with
  the accelerometer weak during motion it then turns the trajectory's tilt, and the
  accelerometer's bias follows (BROAD 01, 04: 0.7–0.9° of tilt). Each magnetometer sample's
  variance gets ``(2/3) (σ_f |m|)²`` per axis (the two components a direction error moves, over
  three axes), ``σ_f`` = :data:`FIELD_DIRECTION_DEG`, an assumption, not a measurement.

Both widen the error bars by what they take away, through the weights the covariance uses.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "FIELD_DIRECTION_DEG",
    "field_direction_variance",
    "once_per_stretch",
    "sample_excess",
]

Array = NDArray[np.float64]

#: The field's direction is taken as uniform to this RMS angle over the log (degrees; Eq. C6b).
FIELD_DIRECTION_DEG = 3.0
#: Standard deviations of a white-noise stretch's scatter within which its excess over the
#: quietest tenth is chance: 1.3 of them from that tenth to the white stretches' mean, 3 beyond.
CHANCE = 4.5


def once_per_stretch(variance: Array, length: int) -> Array:
    """Eq. C6a: per-sample variances (n,) with each stretch's excess over the white noise (the
    quietest tenth's variance) counted once per stretch of ``length`` samples."""
    k = max(1, int(length))
    white = float(np.quantile(variance, 0.1))
    # a stretch of white noise alone scatters by √(2/(3k)) of its variance: only an excess
    # beyond CHANCE such standard deviations above the quietest tenth is body acceleration
    chance = CHANCE * white * np.sqrt(2.0 / (3.0 * k))
    out: Array = white + np.maximum(variance - white - chance, 0.0) * k
    return out


def field_direction_variance(mag: Array, bias: Array) -> Array:
    """Eq. C6b: each magnetometer sample's added variance per axis (n,), raw units², from its
    reading's strength ``|m − b_m|`` and :data:`FIELD_DIRECTION_DEG`."""
    strength = np.linalg.norm(mag - bias, axis=1)
    out: Array = (2.0 / 3.0) * (np.radians(FIELD_DIRECTION_DEG) * strength) ** 2
    return out


def sample_excess(variance: Array, length: int) -> Array:
    """Eq. C6a at the knots: each stretch's excess over the white noise, read from the samples'
    residuals — per-sample variances ``variance`` (n,) over stretches of ``length`` samples —
    as :func:`once_per_stretch` reads it, per stretch (m,) in raw units².

    A knot's residual is its window's mean: it keeps the body acceleration below the knot rate
    and loses the rest, so the knots' own variances hold less of what the model leaves out than
    the samples' (module docstring). What the stretch can tell about the gravity
    direction is ``1 / excess`` whichever rows carry it, so the excess is read where it is
    seen whole, the samples, and spread over the stretch's knots as the samples' was."""
    k = max(1, int(length))
    n = len(variance)
    m = -(-n // k)
    per = np.add.reduceat(variance, np.arange(m) * k) / np.minimum(k, n - np.arange(m) * k)
    white = float(np.quantile(per, 0.1))
    chance = CHANCE * white * np.sqrt(2.0 / (3.0 * k))
    out: Array = np.maximum(per - white - chance, 0.0)
    return out
