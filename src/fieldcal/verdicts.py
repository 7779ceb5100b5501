"""A calibration's verdict and what it rests on: each :class:`Reason` (a rule's code, level and
text), the :class:`Verdict`, the predicted :class:`Accuracy` and the poses left out
(:class:`RejectedPose`). The rules that make them live in :mod:`fieldcal.trust.verdict`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

from ._frozen import ArrayDataclass

__all__ = [
    "PLAIN_CODE",
    "REASON_LEVELS",
    "Accuracy",
    "Level",
    "Reason",
    "RejectedPose",
    "Verdict",
    "VerdictLevel",
]

#: A reason's level, mildest first (a ``note`` never raises the verdict).
Level = Literal["note", "warn", "fail"]
#: A verdict's level.
VerdictLevel = Literal["pass", "warn", "fail"]


@dataclass(frozen=True, eq=False)
class RejectedPose(ArrayDataclass):
    """A pose left out of the fit because its readings do not fit the model.

    ``index`` is the pose's number in the caller's numbering; ``sensor`` is ``"accel"``,
    ``"mag"`` or ``"both"``; ``statistic`` the pose's outlier statistic (leverage-corrected,
    whitened residual, see ``docs/trust.md``) and ``p_value`` its tail probability under the
    model; ``reason`` one line naming the likely cause.
    """

    index: int
    sensor: str
    statistic: float
    p_value: float
    reason: str


#: The levels a verdict reason can have, mildest first (a ``note`` never raises the verdict).
REASON_LEVELS: tuple[Level, ...] = get_args(Level)
#: The code of a reason that came as plain text (a verdict built by hand, an old file's
#: sentence that matches no rule).
PLAIN_CODE = "other"


@dataclass(frozen=True)
class Reason:
    """One reason of a verdict: a stable ``code`` (what scripts and the batch table read; the
    rule table in ``docs/trust.md``), its ``level`` (``"note"``, ``"warn"`` or ``"fail"``) and
    the ``text`` people read (the rule's fixed message with the numbers filled in).

    ``str(reason)`` is the text.
    """

    code: str
    level: Level
    text: str

    def __post_init__(self) -> None:
        if self.level not in REASON_LEVELS:
            raise ValueError(f"reason level must be note, warn or fail, got {self.level!r}"[:120])
        for name in ("code", "text"):
            if not isinstance(getattr(self, name), str):
                raise ValueError(f"reason {name} must be text")
        if not self.code or not self.code.replace("_", "").isalnum() or not self.code.isascii():
            raise ValueError(f"reason code must be a short identifier, got {self.code!r}"[:120])

    def __str__(self) -> str:
        return self.text


@dataclass(frozen=True, eq=False)
class Verdict(ArrayDataclass):
    """Whether to trust the calibration: ``level`` in ``"pass" | "warn" | "fail"`` and one
    :class:`Reason` per finding, each naming the cause and the fix (rules in
    ``docs/trust.md``), the most severe first.

    A reason given as plain text (older code) becomes ``Reason("other", level, text)`` with the
    verdict's level (``note`` under ``pass``).
    """

    level: VerdictLevel
    reasons: tuple[Reason, ...] = ()

    def __post_init__(self) -> None:
        if self.level not in ("pass", "warn", "fail"):
            raise ValueError(f"verdict level must be pass, warn or fail, got {self.level!r}")
        plain_level = "note" if self.level == "pass" else self.level
        reasons = tuple(
            r if isinstance(r, Reason) else Reason(PLAIN_CODE, plain_level, str(r))
            for r in self.reasons
        )
        object.__setattr__(self, "reasons", reasons)

    @property
    def codes(self) -> tuple[str, ...]:
        """The reasons' codes, in order (what a script tests)."""
        return tuple(r.code for r in self.reasons)

    @property
    def summary(self) -> str:
        """The level and the codes on one line: ``"WARN (accuracy, untested)"``, ``"PASS"``
        (what the CLI's first line, the report's banner and the batch table show)."""
        codes = ", ".join(dict.fromkeys(self.codes))
        return self.level.upper() + (f" ({codes})" if codes else "")


@dataclass(frozen=True, eq=False)
class Accuracy(ArrayDataclass):
    """Predicted 1σ errors after calibration, in the user's terms (``None``: not applicable).

    ``tilt_deg``: the angle between the true and the corrected gravity direction, RMS over
    orientations. ``heading_deg``: a tilt-compensated compass heading for a level device, RMS
    over headings. ``accel_norm_rel`` / ``mag_norm_rel``: the relative error of ``|a|`` and
    ``|m|``, RMS over orientations. From the parameter covariance plus the pose-level noise.
    """

    tilt_deg: float | None = None
    heading_deg: float | None = None
    accel_norm_rel: float | None = None
    mag_norm_rel: float | None = None
