"""The magnetometer's handedness: from the World Magnetic Model's dip when there is a reference,
otherwise from what the user states (the prior: right-handed).

Static poses cannot tell a magnetometer mirrored relative to the accelerometer from one in the
other magnetic hemisphere (:func:`fieldcal.geometry.frames.twin_flip`): the two twins fit
equally and their dips are opposite. The model's dip at the site tells them apart, unless either
dip is too close to zero to have a sign.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..calibration import Calibration
from ..reference import FieldReference

__all__ = ["SIGNIFICANT", "Handedness", "decide", "reference_mirrored"]

#: A dip has a sign when it is this many standard errors away from zero.
SIGNIFICANT = 3.0


def reference_mirrored(
    cal: Calibration, reference: FieldReference, allowance_deg: float
) -> bool | None:
    """Whether the reference's dip makes the magnetometer mirrored (``True``), right-handed
    (``False``), or cannot say (``None``: the model's dip is within ``SIGNIFICANT`` standard
    uncertainties plus the local-anomaly allowance of zero, or the fitted dip within
    ``SIGNIFICANT`` standard errors of zero)."""
    unmirrored = cal.with_mag_handedness(False)
    dip = unmirrored.dip_deg
    if dip is None:
        return None
    std = unmirrored.dip_std_deg
    fitted_signed = abs(dip) > SIGNIFICANT * (std if std is not None else 0.0)
    model_signed = abs(reference.dip_deg) > SIGNIFICANT * reference.dip_std_deg + allowance_deg
    if not (fitted_signed and model_signed):
        return None
    return math.copysign(1.0, dip) != math.copysign(1.0, reference.dip_deg)


@dataclass(frozen=True)
class Handedness:
    """The one decision: whether the magnetometer is mirrored, what the reference decided
    (``None``: no reference, or it could not), and so who decided."""

    mirrored: bool
    decided: bool | None

    @property
    def options(self) -> dict[str, object]:
        """The provenance entries ``mag_mirrored`` and ``mag_handedness`` (``"reference"`` or
        ``"stated"``)."""
        return {
            "mag_mirrored": self.mirrored,
            "mag_handedness": "stated" if self.decided is None else "reference",
        }


def decide(
    cal: Calibration, stated: bool, reference: FieldReference | None, allowance_deg: float
) -> Handedness:
    """The magnetometer's handedness for ``cal``: the reference's when there is one and it can
    decide (:func:`reference_mirrored`), otherwise ``stated`` (``mag_mirrored``)."""
    decided = None if reference is None else reference_mirrored(cal, reference, allowance_deg)
    return Handedness(bool(stated) if decided is None else decided, decided)
