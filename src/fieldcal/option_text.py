"""The text of an option's value parsed (a command-line value, a manifest cell): noise and
pose noise for both sensors or per sensor, a field strength or the World Magnetic Model's
keyword (the one parser of ``wmm``), a flag's true or false; ``ValueError`` (or a coded
:class:`~fieldcal.errors.InputError`) with the reason."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .errors import NOT_A_SENSOR, InputError
from .limits import LARGEST
from .option_types import MAGNITUDE, Range

__all__ = [
    "WMM_UNITS",
    "parse_field_strength",
    "parse_flag",
    "parse_noise",
    "parse_pose_noise",
    "wmm_unit",
]


def _per_sensor(text: str, one: Callable[[str], Any], example: str) -> Any:
    if "=" not in text:
        return one(text)
    out: dict[str, Any] = {}
    for part in text.split(","):
        key, _, value = part.partition("=")
        key = key.strip().lower()
        if key not in ("accel", "mag"):
            raise InputError(
                f"{key!r} is not a sensor; name accel and/or mag, e.g. {example}",
                code=NOT_A_SENSOR,
                subject=repr(key),
            )
        out[key] = one(value.strip())
    return out


def parse_noise(text: str) -> float | dict[str, float]:
    """``"0.01"`` for both sensors, or ``"accel=0.01,mag=0.2"`` per sensor.

    Raises
    ------
    ValueError
        With the reason.
    """
    parsed: float | dict[str, float] = _per_sensor(text, MAGNITUDE.check, "accel=0.01,mag=0.2")
    return parsed


def _pose_noise_one(text: str) -> str | float:
    word = text.strip().lower()
    if word in ("auto", "none"):
        return word
    return Range(0.0, LARGEST, low_open=False).check(word)


def parse_pose_noise(text: str) -> str | float | dict[str, str | float]:
    """``auto``, ``none``, a number, or ``accel=0.01,mag=auto`` (a sensor not named is
    estimated).

    Raises
    ------
    ValueError
        With the reason.
    """
    parsed: str | float | dict[str, str | float] = _per_sensor(
        text, _pose_noise_one, "accel=0.01,mag=auto"
    )
    return parsed


#: ``field_strength`` keywords for the World Magnetic Model's intensity, and their unit.
WMM_UNITS = {
    "wmm": "uT",
    "wmm:ut": "uT",
    "wmm:µt": "uT",
    "wmm:nt": "nT",
    "wmm:g": "G",
    "wmm:gauss": "G",
    "wmm:mg": "mG",
    "wmm:mgauss": "mG",
}


def wmm_unit(value: object) -> str | None:
    """The unit a ``field_strength`` of ``wmm``, ``wmm:uT`` or ``wmm:nT`` asks for (``None``:
    not one of them); the one parser of the keyword."""
    return WMM_UNITS.get(value.strip().lower()) if isinstance(value, str) else None


def parse_field_strength(text: str) -> float | str:
    """``--field-strength``: a magnitude, or ``wmm`` (:data:`WMM_UNITS`) for the World Magnetic
    Model's intensity at ``--location``; ``ValueError`` with the reason otherwise."""
    if wmm_unit(text) is not None:
        return text.strip()
    if text.strip()[:1].isalpha():
        raise ValueError(
            f"{text!r} is neither a number nor wmm (wmm:uT, wmm:nT, wmm:gauss, wmm:mgauss: the "
            "World Magnetic Model's intensity at --location)"
        )
    return MAGNITUDE.check(text)


def parse_flag(text: str) -> bool:
    word = text.strip().lower()
    if word in ("1", "true", "yes", "y", "on"):
        return True
    if word in ("0", "false", "no", "n", "off"):
        return False
    raise ValueError("give true or false")
