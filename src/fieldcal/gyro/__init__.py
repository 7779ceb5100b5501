"""The gyroscope stage: its gain, misalignment and bias from the motion between still poses.

- :mod:`.integrate` — a body-frame rate integrated exactly into a rotation over the timestamps
  as given (quaternions, a log-depth scan; bursts of equal timestamps spread);
- :mod:`.estimate` — :func:`fit_gyro`: maximum likelihood against the poses' rotations of a
  joint calibration (``method="rotations"``) or, with an accelerometer alone, against the
  gravity directions (``"gravity"``); the result is a :class:`GyroFit` (:mod:`.result`).
  Its steps: :mod:`.data` (poses, drift, segments), :mod:`.model` (residuals,
  Jacobians), :mod:`.passes` (one pass over the intervals, a chunk at a time),
  :mod:`.start`, :mod:`.noise` (the segments' covariance in its
  structure), :mod:`.banded` and :mod:`.normal` (normal equations linear in the
  number of poses), :mod:`.solver`, :mod:`.observability`,
  :mod:`.uncertainty`;
- :mod:`.temperature` — the bias against temperature from the still poses' means
  (:func:`with_bias_temperature`).

``docs/methods/gyro.md`` describes the method.
"""

from __future__ import annotations

from .estimate import BIAS_NAMES, GAIN_NAMES, GyroFit, fit_gyro
from .integrate import effective_time, integrate, rotation_vector
from .temperature import with_bias_temperature

__all__ = [
    "BIAS_NAMES",
    "GAIN_NAMES",
    "GyroFit",
    "effective_time",
    "fit_gyro",
    "integrate",
    "rotation_vector",
    "with_bias_temperature",
]
