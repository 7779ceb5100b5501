"""fieldcal: joint maximum-likelihood calibration of an accelerometer and a magnetometer.

>>> import fieldcal
>>> session = fieldcal.simulate("paper", seed=1)
>>> cal = fieldcal.calibrate(session.accel, session.mag)          # doctest: +SKIP
>>> cal = fieldcal.calibrate_log("log.csv")                        # doctest: +SKIP

Conventions are stated once in :mod:`fieldcal.geometry.frames` and ``docs/conventions.md``;
the rooms of the package are described in ``docs/architecture.md``. Importing fieldcal loads
numpy only: SciPy, matplotlib and pyarrow load when a function first needs them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from . import metrics
from ._version import __version__
from .api import calibrate
from .calibration import (
    Accuracy,
    Calibration,
    Diagnostics,
    ParameterCovariance,
    RejectedPose,
    SensorCalibration,
    Verdict,
)
from .errors import InputError
from .methods import METHODS
from .simulation.session import Session, simulate
from .stats.poses import PoseStats, SensorStats, stats_from_means, summarize

if TYPE_CHECKING:
    from .batch import calibrate_many
    from .logs import Log
    from .methods.ellipsoid import align, fit_ellipsoid
    from .pipeline import calibrate_log, read_log
    from .reference import expected_field
    from .store import Store
    from .trust.plan import PlannedPose, Targets, plan_poses

__all__ = [
    "METHODS",
    "Accuracy",
    "Calibration",
    "Diagnostics",
    "InputError",
    "Log",
    "ParameterCovariance",
    "PlannedPose",
    "PoseStats",
    "RejectedPose",
    "SensorCalibration",
    "SensorStats",
    "Session",
    "Store",
    "Targets",
    "Verdict",
    "__version__",
    "align",
    "calibrate",
    "calibrate_log",
    "calibrate_many",
    "expected_field",
    "fit_ellipsoid",
    "metrics",
    "plan_poses",
    "read_log",
    "simulate",
    "stats_from_means",
    "summarize",
]

#: Public names imported on first use, keeping ``import fieldcal`` light.
_LAZY = {
    "align": "fieldcal.methods.ellipsoid",
    "fit_ellipsoid": "fieldcal.methods.ellipsoid",
    # the log path: commands that never read a log (--version, --help, export) skip it
    "Log": "fieldcal.logs",
    "calibrate_log": "fieldcal.pipeline",
    "read_log": "fieldcal.pipeline",
    # experiment design: which pose to take next
    "PlannedPose": "fieldcal.trust.plan",
    "Targets": "fieldcal.trust.plan",
    "plan_poses": "fieldcal.trust.plan",
    "Store": "fieldcal.store",
    "calibrate_many": "fieldcal.batch",
    "expected_field": "fieldcal.reference",
}


def __getattr__(name: str) -> object:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'fieldcal' has no attribute {name!r}")
