"""Old module paths that moved, kept importable for one release (listed in CHANGELOG.md).

``import fieldcal.stats.poses`` still works and gives :mod:`fieldcal.stats.pose_stats`, with a
``DeprecationWarning`` naming the new path. The table is the one place that knows the old names;
:func:`install` (called by ``fieldcal/__init__``) puts a finder for them on ``sys.meta_path``.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from collections.abc import Sequence
from types import ModuleType

__all__ = ["MOVED", "install"]

#: Old dotted path → new dotted path (fieldcal 0.4; the old paths go in the next release).
MOVED: dict[str, str] = {
    "fieldcal.logs.poses": "fieldcal.logs.pose_finding",
    "fieldcal.stats.poses": "fieldcal.stats.pose_stats",
    "fieldcal.output.summary": "fieldcal.output.terminal",
    "fieldcal.batch.summary": "fieldcal.batch.table",
    "fieldcal.capture.sources": "fieldcal.capture.feeds",
    "fieldcal.logs.sources": "fieldcal.logs.inputs",
    "fieldcal.capture.session": "fieldcal.capture.live_session",
    "fieldcal.stats.noise": "fieldcal.stats.noise_models",
    "fieldcal.trust.plan": "fieldcal.planning.next_pose",
    "fieldcal.methods.mle.model": "fieldcal.likelihood.pose_model",
    "fieldcal.methods.mle.lm": "fieldcal.likelihood.levenberg",
    "fieldcal.methods.mle.uncertainty": "fieldcal.likelihood.cramer_rao",
    # fieldcal 0.5: the gyroscope room's modules without the room's prefix
    "fieldcal.gyro.gyro_banded": "fieldcal.gyro.banded",
    "fieldcal.gyro.gyro_data": "fieldcal.gyro.data",
    "fieldcal.gyro.gyro_model": "fieldcal.gyro.model",
    "fieldcal.gyro.gyro_noise": "fieldcal.gyro.noise",
    "fieldcal.gyro.gyro_normal": "fieldcal.gyro.normal",
    "fieldcal.gyro.gyro_observability": "fieldcal.gyro.observability",
    "fieldcal.gyro.gyro_pass": "fieldcal.gyro.passes",
    "fieldcal.gyro.gyro_result": "fieldcal.gyro.result",
    "fieldcal.gyro.gyro_solver": "fieldcal.gyro.solver",
    "fieldcal.gyro.gyro_start": "fieldcal.gyro.start",
    "fieldcal.gyro.gyro_temperature": "fieldcal.gyro.temperature",
    "fieldcal.gyro.gyro_uncertainty": "fieldcal.gyro.uncertainty",
}


class _Alias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old path and loads it as the module at its new path."""

    def find_spec(
        self,
        fullname: str,
        path: Sequence[str] | None = None,
        target: ModuleType | None = None,
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        new = MOVED[spec.name]
        warnings.warn(
            f"{spec.name} moved to {new}; the old path goes in the next release",
            DeprecationWarning,
            stacklevel=2,
        )
        return importlib.import_module(new)

    def exec_module(self, module: ModuleType) -> None:
        """The module at the new path is already executed."""


def install() -> None:
    """Put the finder of old paths on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _Alias) for f in sys.meta_path):
        sys.meta_path.append(_Alias())
