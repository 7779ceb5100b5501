"""The accuracy a calibration should reach (:class:`Targets`): the verdict's ``accuracy`` rule
compares the predicted errors with them, and planning and ``capture --until targets`` aim at
them.

One set of defaults everywhere (library, ``calibrate``, ``batch``, ``capture``), chosen for what
a typical attitude and heading filter (a complementary, Madgwick or EKF AHRS on a hobby or
industrial board) needs from its sensors:

- ``tilt_deg = 1``: such filters quote about 1° static roll and pitch; a calibration that adds
  less than that leaves the filter's own error in charge. A tilt error also turns into heading
  error through the tilt compensation (by about ``tan(dip)``, ×1.7 at 60° dip).
- ``heading_deg = 2``: the static magnetic heading such filters quote (2–2.5°); the tilt target
  above keeps the tilt's share of it within that.
- ``norm_pct = 2``: filters gate a reading as disturbed (linear acceleration, iron nearby) when
  ``|a|`` or ``|m|`` leaves its nominal value by a few percent; a calibration error of 2 % keeps
  that gate meaningful.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from ..errors import InputError

__all__ = ["DEFAULT_TARGETS", "Targets"]


@dataclass(frozen=True)
class Targets:
    """The errors a calibration should reach (predicted 1σ, :class:`fieldcal.Accuracy`).

    Attributes
    ----------
    heading_deg : float
        Predicted heading error (``cal.accuracy.heading_deg``), default 2°.
    tilt_deg : float
        Predicted tilt error (``cal.accuracy.tilt_deg``), default 1°.
    dip_deg : float or None
        Standard error of the dip (``cal.dip_std_deg``) for planning and ``capture``;
        ``None`` (default): no target. The verdict does not read it.
    norm_pct : float
        Predicted error of ``|a|`` and ``|m|`` (``accel_norm_rel``, ``mag_norm_rel``), in
        percent, default 2 %.

    Notes
    -----
    Why these defaults: see :mod:`fieldcal.trust.targets`. A prediction worse than a target
    makes the verdict warn (code ``accuracy``); worse than :data:`fieldcal.trust.verdict.
    UNUSABLE_FACTOR` (5) times a target, fail (code ``unusable``).
    """

    heading_deg: float = 2.0
    tilt_deg: float = 1.0
    dip_deg: float | None = None
    norm_pct: float = 2.0

    def __post_init__(self) -> None:
        for name in ("heading_deg", "tilt_deg", "dip_deg", "norm_pct"):
            value = getattr(self, name)
            if value is None and name == "dip_deg":
                continue
            ok = isinstance(value, numbers.Real) and not isinstance(value, bool)
            if not ok or not (math.isfinite(float(value)) and float(value) > 0):
                unit = "percent" if name == "norm_pct" else "degrees"
                raise InputError(
                    f"Targets.{name} must be a positive number of {unit}, got {value!r}"[:160]
                )
            object.__setattr__(self, name, float(value))


#: The defaults, once.
DEFAULT_TARGETS = Targets()
