"""fieldcal: joint maximum-likelihood calibration of an accelerometer and a magnetometer.

>>> import fieldcal
>>> session = fieldcal.simulate("paper", seed=1)
>>> cal = fieldcal.calibrate(session.accel, session.mag)          # doctest: +SKIP

Conventions are stated once in ``docs/conventions.md`` and in :mod:`fieldcal.model`.
"""

from __future__ import annotations

__version__ = "0.1.0"

from . import metrics
from .api import calibrate
from .errors import InputError
from .methods.ellipsoid import align, fit_ellipsoid
from .model import Calibration, Diagnostics, ParameterCovariance, SensorCalibration
from .poses import PoseStats, SensorStats, stats_from_means, summarize
from .simulate import Session, simulate

__all__ = [
    "Calibration",
    "Diagnostics",
    "InputError",
    "ParameterCovariance",
    "PoseStats",
    "SensorCalibration",
    "SensorStats",
    "Session",
    "__version__",
    "align",
    "calibrate",
    "fit_ellipsoid",
    "metrics",
    "simulate",
    "stats_from_means",
    "summarize",
]
