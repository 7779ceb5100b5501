"""Is every parameter determined by the motion, and if not, which rotations to add?

Judged on the Cramér–Rao standard errors of the fit itself (the Fisher information with the
trajectory marginalised), never on a rule of thumb: the gyroscope's gain column ``b`` is what
turns about the body's ``b`` axis show, so a column whose relative error exceeds
:data:`GYRO_LIMIT` names that axis; a field sensor's gain whose relative error exceeds
:data:`FIELD_LIMIT` asks for more directions of gravity / of the field through the body.
A log that turns about every axis gets no advice to turn about them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ...calibration import ParameterCovariance
from ...errors import InputError

__all__ = [
    "FIELD_LIMIT",
    "FLAT",
    "GYRO_LIMIT",
    "HOPELESS_DEG",
    "MIN_TURN_DEG",
    "UNSETTLED",
    "UP_DOWN_DEG",
    "Identifiability",
    "check_motion",
    "identifiability",
    "motion_advice",
]

Array = NDArray[np.float64]

#: Relative standard error of a gyroscope gain column beyond which its axis is "not turned".
GYRO_LIMIT = 0.01
#: Relative standard error of a field sensor's gain beyond which it is "not determined".
FIELD_LIMIT = 0.02
AXES = "xyz"
#: An axis counts as having pointed up (down) when the body's "up" came within this angle of
#: it (judged on the raw accelerometer's direction, when the fit did not settle).
UP_DOWN_DEG = 65.0
#: The same before the fit, on the raw accelerometer's direction, for the refusal's words.
HOPELESS_DEG = 80.0
#: Before the fit: the smallest eigenvalue of the raw gravity directions' second moment below
#: which they lie near one plane (about 6°) and the log is refused.
FLAT = 0.01
#: Before the fit: the raw gyroscope's total turn about an axis below which it is "not turned".
MIN_TURN_DEG = 90.0


def motion_advice(up: Array, turned_deg: Array, limit_deg: float = UP_DOWN_DEG) -> str | None:
    """What the motion lacks, in words, or ``None``: a body axis that never pointed up and down
    (``up`` (n, 3), the body's "up" direction per sample, within ``limit_deg`` of the axis)
    leaves the field sensors' gains undetermined. The turns to add are those about the axes
    turned less than :data:`MIN_TURN_DEG` in all (``turned_deg`` per body axis); a log that
    turned about every axis is asked to point the missing axes up and down, never to "add
    turns about x, y, z"."""
    u = up / np.maximum(np.linalg.norm(up, axis=1, keepdims=True), 1e-300)
    c = np.cos(np.radians(limit_deg))
    never = [AXES[b] for b in range(3) if not (np.max(u[:, b]) > c and np.min(u[:, b]) < -c)]
    if not never:
        return None
    little = [AXES[b] for b in range(3) if turned_deg[b] < MIN_TURN_DEG]
    say = ", ".join
    plural = "es" if len(never) > 1 else "is"
    turns = ", ".join(f"{AXES[b]} {turned_deg[b]:.0f}°" for b in range(3))
    if little:
        advice = (
            f"add turns about the body's {say(little)} ax{'es' if len(little) > 1 else 'is'} "
            "so that every axis points up and down"
        )
    else:
        verb = "point" if len(never) > 1 else "points"
        advice = f"turn the device until its {say(never)} ax{plural} {verb} up, then down"
    return (
        f"the motion does not determine the calibration: the body's {say(never)} ax{plural} "
        f"never pointed up and down (turned {turns}); {advice}"
    )


def check_motion(accel: Array, gyro: Array, time: Array) -> None:
    """Refuse, before any fit, a log whose motion is hopeless: the raw accelerometer's
    directions all lie near one plane (the smallest eigenvalue of their second moment below
    :data:`FLAT`: a robot turning in place, a board turned about one axis). The message
    (:func:`motion_advice` at :data:`HOPELESS_DEG`, the raw gyroscope's turns) names the turns
    to add. Milder gaps are judged after the fit, on the fitted trajectory, and only when the
    fit did not settle."""
    u = accel / np.maximum(np.linalg.norm(accel, axis=1, keepdims=True), 1e-300)
    if np.linalg.eigvalsh(u.T @ u / len(u))[0] >= FLAT:
        return
    dt = np.diff(time)
    turned = np.degrees(np.sum(np.abs(0.5 * (gyro[1:] + gyro[:-1])) * dt[:, None], axis=0))
    advice = motion_advice(accel, turned, HOPELESS_DEG) or (
        "the motion does not determine the calibration: gravity stayed near one plane through "
        "the body; turn the device so that every axis points up and down"
    )
    raise InputError(advice)


#: A body axis the fitted trajectory turned about by more than this (degrees, in all) is not
#: "missing": an undetermined gain there means the fit went wrong, not the motion.
TURNED_DEG = 360.0
#: Share of gravity directions visited above which the field sensors' motion is sufficient.
COVERED = 0.5
#: A gain the motion was there for is blamed on the fit ("unsettled") only when its relative
#: error exceeds this many times the limit: a gain known to 1.2 % after thousands of degrees of
#: fast turning (BROAD trial 06) is determined, if imprecisely, and its error bars say so.
UNSETTLED = 5.0


class Identifiability:
    """The check's findings: ``missing_turns`` (body axes to turn about), ``undetermined``
    (field sensors whose gain is not fixed), ``unsettled`` (parameters undetermined although
    the motion was there: the fit, not the recording, is at fault), ``advice`` (one line each,
    empty when all is determined) and ``relative_std`` (the standard errors judged)."""

    def __init__(
        self,
        missing_turns: list[str],
        undetermined: list[str],
        relative_std: dict[str, float],
        unsettled: list[str] | None = None,
    ) -> None:
        self.missing_turns = missing_turns
        self.undetermined = undetermined
        self.relative_std = relative_std
        self.unsettled = unsettled or []

    @property
    def advice(self) -> list[str]:
        lines = []
        if self.missing_turns:
            axes = ", ".join(self.missing_turns)
            lines.append(
                f"the gyroscope's gain is not determined about the body's {axes} "
                f"ax{'es' if len(self.missing_turns) > 1 else 'is'}: add turns about {axes}"
            )
        for sensor in self.undetermined:
            lines.append(
                f"the {'accelerometer' if sensor == 'accel' else 'magnetometer'}'s gain is not "
                "determined: turn the device so that each of its axes points up and down"
            )
        return lines

    @property
    def determined(self) -> bool:
        return not (self.missing_turns or self.undetermined or self.unsettled)


def _relative(cov: ParameterCovariance, sensor: str, gain: Array, columns: list[int]) -> float:
    names = [f"{sensor}.gain[{i},{j}]" for i in range(3) for j in columns]
    std = cov.stds(names)
    return float(np.sqrt(np.sum(std**2)) / max(np.linalg.norm(gain[:, columns]), 1e-300))


def identifiability(
    cov: ParameterCovariance,
    gains: dict[str, Array],
    turned_deg: dict[str, float],
    coverage: float,
) -> Identifiability:
    """Judge the covariance (:class:`Identifiability`): a gain the Fisher information leaves
    undetermined is blamed on the motion only when the fitted trajectory lacks it (turned less
    than :data:`TURNED_DEG` about that axis; gravity directions covered below
    :data:`COVERED`), otherwise on the fit (``unsettled``, beyond :data:`UNSETTLED` times the
    limit: determined, if imprecisely, below that)."""
    rel: dict[str, float] = {}
    missing: list[str] = []
    unsettled: list[str] = []
    for b in range(3):
        axis = AXES[b]
        rel[f"gyro.{axis}"] = _relative(cov, "gyro", gains["gyro"], [b])
        if turned_deg[axis] < TURNED_DEG and rel[f"gyro.{axis}"] > GYRO_LIMIT:
            missing.append(f"gyro.{axis}")
        elif rel[f"gyro.{axis}"] > UNSETTLED * GYRO_LIMIT:
            unsettled.append(f"gyro.{axis}")
    undetermined: list[str] = []
    for sensor in ("accel", "mag"):
        rel[sensor] = _relative(cov, sensor, gains[sensor], [0, 1, 2])
        if coverage < COVERED and rel[sensor] > FIELD_LIMIT:
            undetermined.append(sensor)
        elif rel[sensor] > UNSETTLED * FIELD_LIMIT:
            unsettled.append(sensor)
    return Identifiability([m.split(".")[1] for m in missing], undetermined, rel, unsettled)
