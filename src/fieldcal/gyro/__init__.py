"""The gyroscope stage: its gain, misalignment and bias from the motion between still poses.

- :mod:`.integrate` — a body-frame rate integrated exactly into a rotation over the timestamps
  as given (quaternions, a log-depth scan; bursts of equal timestamps spread);
- :mod:`.estimate` — :func:`fit_gyro`: maximum likelihood against the poses' rotations of a
  joint calibration (``method="rotations"``) or, with an accelerometer alone, against the
  gravity directions (``"gravity"``); the result is a :class:`GyroFit` (:mod:`.gyro_result`).
  Its steps: :mod:`.gyro_data` (poses, drift, segments), :mod:`.gyro_model` (residuals,
  Jacobians), :mod:`.gyro_pass` (one pass over the intervals, a chunk at a time),
  :mod:`.gyro_start`, :mod:`.gyro_noise` (the segments' covariance in its
  structure), :mod:`.gyro_banded` and :mod:`.gyro_normal` (normal equations linear in the
  number of poses), :mod:`.gyro_solver`, :mod:`.gyro_observability`,
  :mod:`.gyro_uncertainty`;
- :mod:`.gyro_temperature` — the bias against temperature from the still poses' means
  (:func:`with_bias_temperature`).

``docs/methods/gyro.md`` describes the method.
"""

from __future__ import annotations

from .estimate import BIAS_NAMES, GAIN_NAMES, GyroFit, fit_gyro
from .gyro_temperature import with_bias_temperature
from .integrate import effective_time, integrate, rotation_vector

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
