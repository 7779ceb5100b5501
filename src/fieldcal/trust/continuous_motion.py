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
  apply; the pose-level ones do not), with the estimator's own reasons kept in place of them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..calibration import Calibration, Reason
from ..reference import FieldReference
from .fitting import conclude
from .targets import Targets
from .verdict import reason

__all__ = ["METHOD_OWN", "motion_reasons", "trust_continuous"]

#: RMS relative departure of the calibrated field's strength from 1 beyond which the field is
#: disturbed (BROAD: 2.5–3.7 % undisturbed in a lab, 15 % with a magnet 2 cm away).
FIELD_STRENGTH_LIMIT = 0.06
#: The gyroscope's rates over the magnetometer direction's turning outside this range: wrong
#: units (1 for rad/s; 57 for °/s). Wide: hard iron slows the raw direction's turns.
GYRO_UNITS_RANGE = (0.25, 8.0)
#: The gyroscope's scale (``|det K_g|^(1/3)``) beyond this share off 1: wrong units or columns.
GYRO_SCALE_LIMIT = 0.2
#: Degrees of misalignment of a gyroscope axis that draw a warning (when significant at 2σ).
GYRO_MISALIGNMENT_DEG = 3.0
#: A gyroscope axis's misalignment standard error (degrees) beyond which the log does not
#: determine it.
GYRO_UNDETERMINED_DEG = 1.0
#: Radians per sample (99th percentile of ``|ω| Δt``) beyond which the turns are too fast.
FAST_STEP_RAD = 0.25
_AXES = "xyz"

#: The estimator's reasons the shared rules replace (the generic ``not_converged`` says it).
METHOD_OWN = ("continuous_not_converged",)


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
    own = (*(cal.verdict.reasons if cal.verdict is not None else ()), *motion_reasons(cal.options))
    return conclude(
        cal,
        bool(mag_mirrored),
        reference,
        dip_allowance_deg,
        targets=targets,
        magnitudes=given,
        given=[r for r in own if r.code not in METHOD_OWN],
    )


def motion_reasons(options: Mapping[str, Any]) -> list[Reason]:
    """The rules on what the continuous fit measured (``options`` of
    :func:`~fieldcal.methods.continuous.fit_continuous`, :mod:`fieldcal.methods.continuous.
    motion_checks`): the field's consistency, the gyroscope's units, sign, scale and alignment,
    and the turns' speed (codes in ``docs/trust.md``)."""
    out: list[Reason] = []
    field = options.get("field_check")
    if field and field["strength_rms"] > FIELD_STRENGTH_LIMIT:
        out.append(
            reason(
                "continuous_field_disturbed",
                strength=field["strength_rms"],
                limit=FIELD_STRENGTH_LIMIT,
                dip=field["dip_spread_deg"],
                stretch=2.0,
            )
        )
    ratio = options.get("gyro_units_ratio")
    low, high = GYRO_UNITS_RANGE
    if ratio is not None and not low <= ratio <= high:
        out.append(reason("gyro_units", ratio=ratio))
    gyro = options.get("gyro_check")
    if gyro:
        out += _gyro_reasons(gyro, units_wrong=ratio is not None and not low <= ratio <= high)
    turns = options.get("turn_check")
    if turns and (turns["step_rad_p99"] > FAST_STEP_RAD or turns["clipped_axes"]):
        clipped = turns["clipped_axes"]
        where = (
            f"; the gyroscope's {', '.join(_AXES[i] for i in clipped)} at its range"
            if clipped
            else ""
        )
        out.append(
            reason(
                "continuous_fast_turns",
                rate=turns["max_rate"],
                step=turns["step_rad_p99"],
                clipped=where,
            )
        )
    return out


def _gyro_reasons(gyro: Mapping[str, Any], units_wrong: bool) -> list[Reason]:
    """Sign, scale (unless the units are already blamed) and alignment of the gyroscope."""
    out: list[Reason] = []
    negative = gyro["negative_axes"]
    if negative:
        values = ", ".join(f"{_AXES[i]} {gyro['diagonal'][i]:+.3g}" for i in negative)
        plural = "es" if len(negative) > 1 else "is"
        axes = ", ".join(_AXES[i] for i in negative)
        out.append(reason("gyro_gain_sign", axes=axes, plural=plural, values=values))
    if not units_wrong and abs(gyro["scale"] - 1.0) > GYRO_SCALE_LIMIT:
        out.append(reason("gyro_gain_scale", scale=gyro["scale"], limit=GYRO_SCALE_LIMIT))
    for i, (angle, std) in enumerate(
        zip(gyro["misalignment_deg"], gyro["misalignment_std_deg"], strict=True)
    ):
        if std > GYRO_UNDETERMINED_DEG:
            out.append(reason("gyro_undetermined", axis=_AXES[i], std=std))
        elif angle - 2.0 * std > GYRO_MISALIGNMENT_DEG:
            out.append(
                reason(
                    "gyro_misalignment",
                    axis=_AXES[i],
                    angle=angle,
                    std=std,
                    limit=GYRO_MISALIGNMENT_DEG,
                )
            )
    return out
