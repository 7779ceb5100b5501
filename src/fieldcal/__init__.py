"""fieldcal: joint maximum-likelihood calibration of an accelerometer and a magnetometer.

>>> import fieldcal
>>> session = fieldcal.simulate("paper", seed=1)
>>> cal = fieldcal.calibrate(session.accel, session.mag)          # doctest: +SKIP
>>> cal = fieldcal.calibrate_log("log.csv")                        # doctest: +SKIP

Conventions are stated once in :mod:`fieldcal.geometry.frames` and ``docs/conventions.md``;
the rooms of the package are described in ``docs/architecture.md``. Importing fieldcal loads
no numerical module: each public name loads its module on first use (numpy with the first
one), and SciPy, matplotlib and pyarrow load when a function first needs them.
"""

from __future__ import annotations

import importlib
import importlib.util
from typing import TYPE_CHECKING

from . import _aliases
from ._version import __version__

_aliases.install()

if TYPE_CHECKING:
    from . import metrics
    from .api import calibrate
    from .batch import calibrate_many
    from .calibration import (
        Accuracy,
        Calibration,
        Diagnostics,
        ParameterCovariance,
        Reason,
        RejectedPose,
        SensorCalibration,
        Verdict,
    )
    from .errors import InputError
    from .findings import Findings
    from .logs import Log
    from .methods import ESTIMATORS, METHODS, estimator
    from .methods.ellipsoid import align, fit_ellipsoid
    from .pipeline import calibrate_log, read_log
    from .planning.next_pose import PlannedPose, plan_poses
    from .reference import expected_field
    from .simulation.session import Session, simulate
    from .stats.pose_stats import PoseStats, SensorStats, stats_from_means, summarize
    from .store import Store
    from .trust.targets import Targets

__all__ = [
    "ESTIMATORS",
    "METHODS",
    "Accuracy",
    "Calibration",
    "Diagnostics",
    "Findings",
    "InputError",
    "Log",
    "ParameterCovariance",
    "PlannedPose",
    "PoseStats",
    "Reason",
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
    "estimator",
    "expected_field",
    "fit_ellipsoid",
    "metrics",
    "plan_poses",
    "read_log",
    "simulate",
    "stats_from_means",
    "summarize",
]

#: Public names imported on first use (PEP 562), so that ``import fieldcal`` and
#: ``fieldcal --version`` load no numerical module: each name's module loads when the name is
#: first used (``fieldcal.calibrate`` loads the calibration path, numpy with it; SciPy, pyarrow
#: and matplotlib load later still, when a function first needs them).
_LAZY = {
    "calibrate": "fieldcal.api",
    **dict.fromkeys(
        (
            "Accuracy",
            "Calibration",
            "Diagnostics",
            "ParameterCovariance",
            "Reason",
            "RejectedPose",
            "SensorCalibration",
            "Verdict",
        ),
        "fieldcal.calibration",
    ),
    "InputError": "fieldcal.errors",
    "METHODS": "fieldcal.methods",
    "ESTIMATORS": "fieldcal.methods",
    "estimator": "fieldcal.methods",
    "Findings": "fieldcal.findings",
    "Session": "fieldcal.simulation.session",
    "simulate": "fieldcal.simulation.session",
    **dict.fromkeys(
        ("PoseStats", "SensorStats", "stats_from_means", "summarize"), "fieldcal.stats.pose_stats"
    ),
    "Targets": "fieldcal.trust.targets",
    "align": "fieldcal.methods.ellipsoid",
    "fit_ellipsoid": "fieldcal.methods.ellipsoid",
    # the log path: commands that never read a log (--version, --help, export) skip it
    "Log": "fieldcal.logs",
    "calibrate_log": "fieldcal.pipeline",
    "read_log": "fieldcal.pipeline",
    # experiment design: which pose to take next
    "PlannedPose": "fieldcal.planning.next_pose",
    "plan_poses": "fieldcal.planning.next_pose",
    "Store": "fieldcal.store",
    "calibrate_many": "fieldcal.batch",
    "expected_field": "fieldcal.reference",
}


def __getattr__(name: str) -> object:
    """A public name, or a subpackage (``fieldcal.metrics``, ``fieldcal.output``), on first use."""
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value  # later look-ups skip this function
        return value
    if not name.startswith("_") and importlib.util.find_spec(f"{__name__}.{name}") is not None:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module 'fieldcal' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
