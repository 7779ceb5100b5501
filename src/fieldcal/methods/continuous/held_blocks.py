"""Blocks of parameters held fixed at an earlier calibration's values (``hold=``, ``prior=``).

A gyroscope gain measured once on a turntable, or a bias from a static session, need not be
fitted again from six single-axis turns (the Huang–Hendeby–Skog configuration: fitting the 9
gain terms costs 3.4x on the gyroscope's bias). Held blocks keep the earlier values exactly: the
Levenberg–Marquardt step and the covariance are taken over the free parameters only (the
held ones' rows and columns of the Schur complement are dropped, their standard errors 0 — the
earlier calibration's own error is not propagated; say so when it matters).

Only blocks whose units do not depend on the field magnitudes a calibration file was written
with can be held: the gyroscope's gain and bias (raw per rad/s, raw) and the field sensors'
biases (raw units).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ...calibration import Calibration
from ...errors import InputError
from .model import LEVER, State

__all__ = ["HOLDABLE", "Held", "held_blocks"]

Array = NDArray[np.float64]

#: The blocks that can be held, and where each sits in the parameter vector.
HOLDABLE = {
    "gyro.gain": slice(22, 31),
    "gyro.bias": slice(31, 34),
    "accel.bias": slice(6, 9),
    "mag.bias": slice(18, 21),
}


@dataclass(frozen=True)
class Held:
    """The blocks held, their values (in the parameter vector's units) and the mask of the
    parameter vector's first :data:`.model.LEVER` ``.stop`` entries they cover."""

    names: tuple[str, ...]
    values: dict[str, Array]
    mask: NDArray[np.bool_]
    source: str

    def apply(self, state: State) -> State:
        """``state`` with the held blocks at their values."""
        out = state.copy()
        for name, value in self.values.items():
            sensor, part = name.split(".")
            setattr(out, f"{sensor}_{part}", value.reshape(3, 3) if part == "gain" else value)
        return out


def _load(prior: object) -> tuple[Calibration, str]:
    if isinstance(prior, Calibration):
        return prior, "the calibration given (prior=)"
    if isinstance(prior, (str, os.PathLike)):
        path = Path(prior)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise InputError(f"cannot read --prior {path}: {exc.strerror or exc}") from None
        try:
            return Calibration.from_json(text), str(path)
        except (ValueError, KeyError, TypeError) as exc:
            raise InputError(
                f"--prior {path} is not a fieldcal calibration file ({exc})"[:200]
            ) from None
    raise InputError("prior must be a Calibration or the path of a calibration file (cal.json)")


def _names(hold: str | Sequence[str]) -> tuple[str, ...]:
    items = hold.split(",") if isinstance(hold, str) else list(hold)
    names = tuple(dict.fromkeys(str(x).strip() for x in items if str(x).strip()))
    for name in names:
        if name not in HOLDABLE:
            raise InputError(
                f"hold: {name!r} is not a block that can be held; give any of "
                f"{', '.join(HOLDABLE)} (comma-separated)"[:200]
            )
    return names


def held_blocks(hold: str | Sequence[str] | None, prior: object) -> Held | None:
    """The blocks ``hold`` names (``"gyro.gain,gyro.bias"``), at ``prior``'s values (a
    :class:`~fieldcal.calibration.Calibration` or a calibration file's path); ``None`` when
    nothing is held.

    Raises
    ------
    InputError
        A block that cannot be held, no ``prior``, or a prior without that sensor.
    """
    if hold is None or (not isinstance(hold, str) and len(hold) == 0) or hold == "":
        if prior is not None:
            raise InputError("prior (--prior) is given but nothing is held: add --hold gyro.gain")
        return None
    names = _names(hold)
    if prior is None:
        raise InputError(
            f"hold={','.join(names)} needs the earlier calibration to hold them at: --prior "
            "cal.json (library prior=)"
        )
    cal, source = _load(prior)
    values: dict[str, Array] = {}
    mask = np.zeros(LEVER.stop, dtype=bool)
    for name in names:
        sensor, part = name.split(".")
        sc = getattr(cal, sensor, None)
        if sc is None:
            raise InputError(f"hold={name}: the prior ({source}) has no {sensor} calibration")
        value = np.array(sc.gain if part == "gain" else sc.bias, dtype=float)
        if not np.all(np.isfinite(value)):
            raise InputError(f"hold={name}: the prior's {name} is not finite")
        values[name] = value.ravel() if part == "gain" else value
        mask[HOLDABLE[name]] = True
    return Held(names, values, mask, source)
