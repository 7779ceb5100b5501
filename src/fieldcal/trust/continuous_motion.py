"""The shared trust path for a calibration from continuous motion: handedness, accuracy, verdict.

:func:`fieldcal.methods.continuous.fit_continuous` gives the parameters, their covariance (the
trajectory marginalised, widened for correlated residuals) and its own motion- and
stretch-level findings (undetermined by the motion, a fit that did not settle, stretches
down-weighted for the body's acceleration). What the pose path adds after a fit
(:func:`fieldcal.trust.fitting.fit_trusted`) is added here the same way, by the same code:

- the magnetometer's handedness, decided once by :func:`~fieldcal.trust.handedness.decide`
  (the World Magnetic Model's dip when there is a reference and it can decide, otherwise
  what the user stated with ``mag_mirrored``): readings cannot tell the twin apart, and neither
  can the gyroscope (``docs/methods/continuous.md``, gauge);
- the predicted accuracy in the user's terms (:func:`~fieldcal.trust.accuracy.predict_accuracy`);
- the verdict from :data:`fieldcal.trust.verdict.CHECKS` (:func:`~fieldcal.trust.verdict.judge`
  with no pose statistics: the rules on convergence, accuracy against the targets, plausible
  gains, coverage — of the trajectory's gravity directions —, the dip and the reference
  apply; the pose-level ones do not), and the rules on the estimator's typed findings
  (:class:`fieldcal.findings.MotionFindings`: ``continuous_undetermined`` ...).
"""

from __future__ import annotations

from collections.abc import Mapping

from ..calibration import Calibration
from ..reference import FieldReference
from .fitting import conclude
from .targets import Targets

__all__ = ["trust_continuous"]


def trust_continuous(
    cal: Calibration,
    *,
    mag_mirrored: bool = False,
    reference: FieldReference | None = None,
    dip_allowance_deg: float = 0.0,
    targets: Targets | None = None,
    magnitudes: Mapping[str, float | None] | None = None,
) -> Calibration:
    """Attach handedness, accuracy and verdict to a calibration from continuous motion.

    Parameters
    ----------
    cal : Calibration
        From :func:`~fieldcal.methods.continuous.fit_continuous`, its gains already in raw
        units per unit of the magnitudes given (:meth:`Calibration.with_field_magnitudes`).
    mag_mirrored : bool
        The handedness stated (``--mag-mirrored``); a reference that can decide overrides it.
    reference : FieldReference, optional
        The World Magnetic Model's field where the log was recorded (``--location``,
        ``--date``): decides the handedness and is compared with the fitted dip.
    dip_allowance_deg : float
        Degrees of dip allowed for local anomalies in that comparison.
    targets : Targets, optional
        The accuracy targets of the verdict (default :class:`~fieldcal.trust.targets.Targets`).
    magnitudes : mapping, optional
        ``{"accel": gravity, "mag": field_strength}`` as given (``None``: not given), for the
        plausible-gain rules.

    Returns
    -------
    Calibration
        With ``accuracy``, ``verdict``, ``field_reference`` and the options ``mag_mirrored``,
        ``mag_handedness`` (``"stated"`` or ``"reference"``).
    """
    given = {s: (1.0, m) for s, m in (magnitudes or {}).items() if m}  # gains in those units
    return conclude(
        cal, bool(mag_mirrored), reference, dip_allowance_deg, targets=targets, magnitudes=given
    )
