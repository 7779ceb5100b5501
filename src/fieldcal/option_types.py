"""What an option is: its :class:`Option` record (flag, help, unit, valid values, the stage
and paths that read it), a :class:`Range` of valid numbers, and :func:`meta` /
:func:`library_only` that declare a settings field's option. The options themselves are the
fields of :mod:`fieldcal.settings`, which exports these names as before."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

from .limits import LARGEST, SMALLEST

__all__ = [
    "MAGNITUDE",
    "NON_NEGATIVE",
    "POSITIVE",
    "Option",
    "Range",
    "Stage",
    "Valid",
    "library_only",
    "meta",
]


Stage = Literal["read", "detect", "fit", "trust"]


@dataclass(frozen=True)
class Range:
    """A finite number from ``low`` (excluded when ``low_open``) to ``high``."""

    low: float
    high: float
    low_open: bool = True

    def check(self, text: object) -> float:
        """``text`` (a string or a number) as a float in the range.

        Raises
        ------
        ValueError
            With the reason, e.g. ``'abc' is not a number``.
        """
        if isinstance(text, float):
            number = text
        else:
            try:
                number = float(str(text).strip())
            except ValueError:
                raise ValueError(f"{text!r} is not a number") from None
        if not math.isfinite(number):
            raise ValueError(f"{text!r} is not a finite number")
        below = number <= self.low if self.low_open else number < self.low
        if below or number > self.high:
            low = "above" if self.low_open else "at least"
            raise ValueError(
                f"{text} is out of range; give a number {low} {self.low:g} and at most "
                f"{self.high:g}"
            )
        return number


#: Positive magnitudes (fields, thresholds, noise): their squares stay finite and normal.
MAGNITUDE = Range(SMALLEST, LARGEST, low_open=False)


#: Sample rates (Hz) and durations (seconds, or samples without a rate).
POSITIVE = Range(0.0, 1e12)


NON_NEGATIVE = Range(0.0, 1e12, low_open=False)


#: What an option takes: ``text``, ``flag`` (on or off), ``switch`` (on, off or unset), a
#: :class:`Range`, a tuple of choices (``None``: the choices of a registry the command line
#: fills in), or a parser of its text.
Valid = Literal["text", "flag", "switch"] | Range | tuple[str, ...] | None | Callable[[str], object]


@dataclass(frozen=True)
class Option:
    """How an option is given and checked; the field's name is its library keyword.

    Attributes
    ----------
    name : str
        The library's keyword (filled in from the field).
    stage : {"read", "detect", "fit", "trust"}
        The stage that uses it (filled in from the class).
    default : object
        The library's default (filled in from the field).
    flag : str
        The command line's option (``--no-robust``); its column in a manifest drops the dashes
        and writes ``_`` for ``-`` (``no_robust``). Empty for an option of the library alone.
    help : str
        The command line's help text.
    unit : str
        The unit of its value, ``""`` for none.
    valid : Valid
        What it takes (see :data:`Valid`).
    inverted : bool
        A flag that turns the field off (``--no-robust`` sets ``robust=False``).
    metavar : str or None
        The value's placeholder in the help.
    show_default : bool
        The command line shows the default.
    target : str
        The attribute of :class:`fieldcal.Targets` the option sets (``--target-tilt``:
        ``tilt_deg``); its default (``None``) is that class's default.
    old_flag : str
        A former spelling of ``flag`` still taken (a deprecation note says the new one); its
        manifest column too.
    paths : tuple of str
        The estimation paths that read it (:data:`ESTIMATION_PATHS`): a value given to a path
        that does not read it is noted as unused, never silently dropped.
    """

    flag: str
    help: str
    unit: str = ""
    valid: Valid = "text"
    inverted: bool = False
    metavar: str | None = None
    show_default: bool = False
    target: str = ""
    paths: tuple[str, ...] = ("poses", "continuous")
    old_flag: str = ""
    name: str = ""
    stage: Stage = "fit"
    default: object = None

    @property
    def column(self) -> str:
        """The option's column in a batch manifest (empty for the library's own options)."""
        return self.flag.split("/")[0].lstrip("-").replace("-", "_")

    @property
    def old_column(self) -> str:
        """The manifest column of :attr:`old_flag` (empty for none)."""
        return self.old_flag.lstrip("-").replace("-", "_")

    @property
    def on_command_line(self) -> bool:
        """Whether the command line (and a manifest) takes it."""
        return bool(self.flag)


def meta(flag: str, help: str, **how: Any) -> dict[str, Option]:
    """A settings field's metadata: its :class:`Option` (see its attributes for ``how``)."""
    return {"option": Option(flag, help, **how)}


def library_only(help: str, **how: Any) -> dict[str, Option]:
    """The metadata of an option of the library alone: no flag, no manifest column."""
    return meta("", help, **how)
