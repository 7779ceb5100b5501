"""What a verdict rule reads and how a check declares its codes: the :class:`Case` (the
calibration, the pose statistics, the pose path's :class:`PoseFindings`, the accuracy, the
Earth's field check, the targets), what a check yields (:data:`Fired`) and :data:`OWNER`, the
one check of each code of :data:`~fieldcal.trust.rule_table.RULES` (filled by :func:`owns`).

The checks themselves and :func:`~fieldcal.trust.verdict.judge` are in
:mod:`fieldcal.trust.verdict`, which exports these names as before.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..calibration import Accuracy, Calibration
from ..reference import FieldReference
from ..stats.pose_stats import PoseStats
from .rule_table import RULES
from .targets import DEFAULT_TARGETS, Targets

__all__ = [
    "OWNER",
    "Case",
    "Check",
    "Findings",
    "Fired",
    "PoseFindings",
    "ReferenceCheck",
    "owns",
]

Array = NDArray[np.float64]


@dataclass
class PoseFindings:
    """What the pose path's trust stage measured (rejected poses, the condition of the reduced
    system, a method's excess cost over the optimum), for the rules."""

    n_total: int
    rejected: list[tuple[int, str]]
    unflagged_left: int
    condition: float
    excess: dict[str, object] | None


#: The old name of :class:`PoseFindings` (fieldcal 0.2; kept for one release).
Findings = PoseFindings


@dataclass(frozen=True)
class ReferenceCheck:
    """The World Magnetic Model's field for the verdict: the reference, the allowance for local
    anomalies (degrees of dip), the handedness the user stated and the one the reference decided
    (``None``: it could not)."""

    field: FieldReference
    allowance_deg: float
    stated_mirrored: bool
    decided_mirrored: bool | None


@dataclass(frozen=True)
class Case:
    """Everything the rules read: the finished calibration (in the fit's units), the pose
    statistics it was fitted to, the trust path's findings, the predicted accuracy, the Earth's
    field check, the targets, and ``magnitudes``: for each sensor whose field magnitude the user
    gave, ``(factor, given)`` — the factor that takes the fitted gain to the user's units
    (raw units per unit of the given magnitude) and the magnitude as given.

    ``stats`` and ``found`` are ``None`` for a calibration from continuous motion
    (:func:`fieldcal.trust.continuous_motion.trust_continuous`): the pose-level rules then do
    not apply, the others read the trajectory (``cal.rotations``) where they read poses."""

    cal: Calibration
    stats: PoseStats | None
    found: PoseFindings | None
    accuracy: Accuracy | None = None
    reference: ReferenceCheck | None = None
    targets: Targets = DEFAULT_TARGETS
    magnitudes: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def sensors(self) -> tuple[str, ...]:
        """The sensors calibrated: the pose statistics', else the calibration's."""
        if self.stats is not None:
            return tuple(self.stats.sensors)
        return tuple(s for s in ("accel", "mag") if getattr(self.cal, s) is not None)

    def body_directions(self, sensor: str) -> Array:
        """The unit field directions in the body frame, per pose (continuous motion: per kept
        epoch of the trajectory, ``R_j`` applied to the sensor's reference field)."""
        if self.stats is None:
            x = np.asarray(self.cal.rotations) @ self.cal.reference(sensor)
        else:
            x = self.stats.sensor(sensor).means - self.cal.sensor(sensor).bias
        return np.asarray(x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300))


#: What a check yields: a code of :data:`RULES` and the numbers its message needs.
Fired = tuple[str, dict[str, object]]
Check = Callable[[Case], Iterator[Fired]]

#: Each code of :data:`RULES` and the one check that fires it (filled in by :func:`_owns`; a test
#: holds that every code has exactly one owner and that no path emits an unregistered code).
OWNER: dict[str, str] = {}


def owns(*codes: str) -> Callable[[Check], Check]:
    """Declare the codes a check fires: each code is owned by exactly one check."""

    def register(check: Check) -> Check:
        for code in codes:
            if code not in RULES:
                raise KeyError(f"{check.__name__} owns {code!r}, which is not in RULES")
            if code in OWNER:
                raise KeyError(f"{code!r} is owned by {OWNER[code]} and {check.__name__}")
            OWNER[code] = check.__name__
        return check

    return register
