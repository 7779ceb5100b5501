"""The options the commands share, generated from :mod:`fieldcal.settings`, and their way
into the library.

The option decorators (``log_options``, ``detect_options``, ``fit_options``, ...) are made from
the settings table: a new option there appears on every command that takes its stage. The value
types check a number when it is parsed (a one-line error naming the option and the range);
``--noise`` and ``--pose-noise`` are parsed by the settings' parsers before any work, with one
line saying what they take.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Any

import click

from ..errors import NOT_A_SENSOR, InputError
from ..limits import LARGEST, SMALLEST
from ..methods import METHODS
from ..settings import MAGNITUDE as _MAGNITUDE
from ..settings import NON_NEGATIVE as _NON_NEGATIVE
from ..settings import (
    OPTIONS,
    READ_OPTIONS,
    TARGET_OPTIONS,
    Option,
    Range,
    Stage,
    parse_field_strength,
    parse_noise,
    parse_pose_noise,
)
from ..settings import POSITIVE as _POSITIVE
from ..trust.targets import DEFAULT_TARGETS
from . import library
from .group import Command, Progress, one_line

if TYPE_CHECKING:
    from ..calibration import Calibration
    from ..logs import Log, PoseSet

__all__ = [
    "MAGNITUDE",
    "NON_NEGATIVE",
    "POSES_OPTION",
    "POSITIVE",
    "FieldStrength",
    "Number",
    "check_reference",
    "detect_options",
    "fit_options",
    "flight_instances",
    "keywords",
    "load",
    "log_options",
    "parse_noise_option",
    "parse_pose_noise_option",
    "reader_options",
    "run_calibration",
    "sensor_columns",
    "settings",
    "target_options",
    "targets",
]

#: The options of a command, by click's parameter names (``no_robust``, ``trim``, ...).
Given = Mapping[str, Any]

if TYPE_CHECKING:  # generic from click 8.2 on; fieldcal supports 8.1
    NumberBase = click.ParamType[float]
else:
    NumberBase = click.ParamType


class Number(NumberBase):
    """A finite number in a range, checked when the option is parsed (a one-line error naming
    the option and the range)."""

    name = "number"

    def __init__(self, low: float, high: float, *, low_open: bool = True) -> None:
        self.range = Range(low, high, low_open)

    @classmethod
    def of(cls, valid: Range) -> Number:
        """The type of an option whose values are ``valid``."""
        return cls(valid.low, valid.high, low_open=valid.low_open)

    def convert(
        self, value: object, param: click.Parameter | None, ctx: click.Context | None
    ) -> float:
        try:
            return self.range.check(value)
        except ValueError as exc:
            self.fail(str(exc), param, ctx)


#: Positive magnitudes (fields, thresholds, noise): their squares stay finite and normal.
MAGNITUDE = Number.of(_MAGNITUDE)
#: Sample rates (Hz) and durations (seconds, or samples without a rate).
POSITIVE = Number.of(_POSITIVE)
NON_NEGATIVE = Number.of(_NON_NEGATIVE)


class FieldStrength(Number):
    """``--field-strength``: a magnitude, or ``wmm`` (``wmm:uT``, ``wmm:nT``) for the World
    Magnetic Model's intensity at ``--location``."""

    name = "number|wmm"

    def convert(  # type: ignore[override]  # a number or the model's keyword
        self, value: object, param: click.Parameter | None, ctx: click.Context | None
    ) -> float | str:
        if isinstance(value, float):
            return super().convert(value, param, ctx)
        try:
            parsed = parse_field_strength(str(value))
        except ValueError as exc:
            self.fail(str(exc), param, ctx)
        return parsed if isinstance(parsed, str) else super().convert(value, param, ctx)


def _click_type(option: Option) -> click.ParamType[Any] | None:
    valid = option.valid
    if isinstance(valid, Range):
        return Number.of(valid)
    if isinstance(valid, tuple):
        return click.Choice(list(valid))
    if valid is None:  # the method: its registry's names
        return click.Choice(list(METHODS))
    if option.name == "field_strength":
        return FieldStrength(SMALLEST, LARGEST, low_open=False)
    return None  # text, parsed by the command (--noise, --pose-noise) or the library


def _help(option: Option) -> str:
    if option.name == "method":
        return (
            f"{option.help}: " + "; ".join(f"{m.name}, {m.summary}" for m in METHODS.values()) + "."
        )
    return option.help


def option_for(option: Option, **override: Any) -> Callable[[Command], Command]:
    """The click option of a settings option (``override``: another help text, say)."""
    kwargs: dict[str, Any] = {"help": _help(option)}
    if option.valid == "flag":
        kwargs["is_flag"] = True
    elif option.valid == "switch":
        kwargs["default"] = None
    else:
        kind = _click_type(option)
        if kind is not None:
            kwargs["type"] = kind
    if option.show_default:
        kwargs.update(default=option.default, show_default=True)
    if option.target:  # unset (None): the default of fieldcal.Targets, shown as click does
        kwargs["help"] += f"  [default: {getattr(DEFAULT_TARGETS, option.target):g}]"
    if option.metavar is not None:
        kwargs["metavar"] = option.metavar
    kwargs.update(override)
    decorator: Callable[[Command], Command] = click.option(option.flag, **kwargs)
    if not option.old_flag:
        return decorator
    # the old spelling, taken for one release (keywords() notes the new one)
    old = {k: v for k, v in kwargs.items() if k not in ("help", "show_default", "default")}
    hidden = click.option(option.old_flag, f"old_{option.column}", hidden=True, **old)

    def both(f: Command) -> Command:
        return decorator(hidden(f))

    return both


def _options(
    names: Iterable[str], helps: Mapping[str, str] | None = None
) -> Callable[[Command], Command]:
    """The click options of ``names`` (settings options), ``helps`` another help text for some
    (by library keyword)."""
    helps = helps or {}
    decorators = [
        option_for(OPTIONS[name], **({"help": helps[name]} if name in helps else {}))
        for name in names
    ]

    def add(f: Command) -> Command:
        for decorator in reversed(decorators):
            f = decorator(f)
        return f

    return add


def _stage(*stages: Stage, leave: tuple[str, ...] = ()) -> list[str]:
    """The command-line options of ``stages`` (the library's own options have no flag)."""
    return [
        n for n, o in OPTIONS.items() if o.stage in stages and o.on_command_line and n not in leave
    ]


#: How a log without a pose column is cut into poses (``calibrate``, ``batch``).
POSES_OPTION = option_for(OPTIONS["poses"])
#: ``--accel-cols``, ``--mag-cols``, ``--gyro-cols``: every command that reads a log.
sensor_columns = _options(["accel_cols", "mag_cols", "gyro_cols"])
#: ``--mag N``, ``--imu N``: a flight log's sensor instances (``noise``; ``calibrate`` and
#: ``batch`` take them with the reader's options).
flight_instances = _options(["mag_instance", "imu_instance"])


def reader_options(**helps: str) -> Callable[[Command], Command]:
    """The reader's options (:data:`fieldcal.settings.READ_OPTIONS`): the same flags on every
    command that reads a log, ``helps`` another help text for some where the command uses them
    otherwise (``apply``'s ``--gyro-cols``), by library keyword."""
    return _options(READ_OPTIONS, helps)


#: The reader's options: columns, missing values, the text's decimal mark, time resets, topics.
log_options = reader_options()
#: Still detection's options (``--poses`` is :data:`POSES_OPTION`).
detect_options = _options(_stage("detect", leave=("poses",)))
#: The calibration's and the check's options (the accuracy targets among them), shared by
#: ``calibrate``, ``capture``, ``batch``.
fit_options = _options(_stage("fit", "trust"))


def parse_noise_option(text: str | None) -> float | dict[str, float] | None:
    """``--noise``: ``"0.01"`` for both sensors, ``"accel=0.01,mag=0.2"`` per sensor."""
    if text is None:
        return None
    try:
        return parse_noise(text)
    except ValueError:
        raise InputError(
            f"--noise {text!r} is not understood; give one standard deviation of a raw sample "
            f"between {SMALLEST:g} and {LARGEST:g} (e.g. 0.01) or one per sensor, e.g. "
            "accel=0.01,mag=0.2"
        ) from None


def parse_pose_noise_option(spec: str) -> str | float | dict[str, str | float]:
    """``--pose-noise``: ``auto``, ``none``, a number, or ``accel=0.01,mag=auto``."""
    try:
        return parse_pose_noise(spec)
    except ValueError as exc:
        if getattr(exc, "code", None) == NOT_A_SENSOR:
            raise InputError(
                f"--pose-noise {spec!r}: {getattr(exc, 'subject', '')} is not a sensor; name "
                "accel and/or mag, e.g. accel=0.01,mag=0.2"
            ) from None
        raise InputError(
            f"--pose-noise {spec!r} is not understood; give auto (estimate it), none (zero), a "
            f"standard deviation in raw units from 0 to {LARGEST:g} (e.g. 0.01), or per sensor, "
            "e.g. accel=0.01,mag=0.2"
        ) from None


def keywords(given: Given, stages: Iterable[Stage]) -> dict[str, Any]:
    """The library's keywords (:data:`fieldcal.settings.OPTIONS` names) for the options of
    ``stages`` a command was given; options left out, and flags not set, take the library's
    defaults. ``--noise`` and ``--pose-noise`` are parsed (one line when not understood)."""
    wanted = set(stages)
    out: dict[str, Any] = {}
    for name, option in OPTIONS.items():
        value = given.get(option.column)
        old = given.get(f"old_{option.column}") if option.old_flag else None
        if old is not None and option.stage in wanted:
            click.echo(
                f"note: {option.old_flag} is now {option.flag} (the old spelling is taken "
                "until the next release)",
                err=True,
            )
            value = old if value is None else value
        if option.stage not in wanted or value is None:
            continue
        if option.valid == "flag" and value is False:
            continue
        if option.inverted:
            value = not value
        elif name == "noise":
            value = parse_noise_option(value)
        elif name == "pose_noise" and isinstance(value, str):
            value = parse_pose_noise_option(value)
        out[name] = value
    return out


def settings(given: Given, stages: Iterable[Stage]) -> library.LogSettings:
    """The settings objects of ``stages`` from a command's options (:func:`keywords`), built
    once: the library checks each value when its stage runs."""
    return library.LogSettings.of(keywords(given, stages))


def load(log: str, given: Given, progress: Progress = None) -> Log:
    """The log, with the reading options a command was given (``log_options``)."""
    reading: dict[str, Any] = keywords(given, ["read"])
    if progress is not None:
        reading["on_progress"] = progress
    loaded: Log = library.load_log(log, **reading)
    return loaded


def check_reference(opts: Given) -> None:
    """``--location``, ``--date`` and ``--field-strength wmm`` checked before the slow part (the
    library checks them again, as it must for its own callers)."""
    location, date = opts.get("location"), opts.get("date")
    if location is not None:
        library.expected_field(location, date)
    elif date is not None:
        raise InputError("--date was given without --location; give --location LAT,LON too")
    strength = opts.get("field_strength")
    if isinstance(strength, str) and location is None:
        raise InputError(
            f"--field-strength {strength} takes the World Magnetic Model's intensity where the "
            "log was recorded: give --location LAT,LON too"
        )


def run_calibration(
    log: Log, chosen: library.LogSettings, progress: Progress = None
) -> tuple[Calibration, PoseSet, dict[str, Any], list[str]]:
    """Poses, calibration, the JSON document and the notes on the input for a loaded log.

    ``chosen`` holds the command's detection, fit and trust settings (:func:`settings`); the
    options left out take the library's defaults (the method, robust fitting, estimated
    pose-level noise). ``progress`` hears the steps (and the library's progress lines).
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = library.run_log(log, chosen, on_progress=progress)
    # the library's warnings belong in the summary, not as tracebacks; numpy's floating-point
    # RuntimeWarnings are the library's business and never reach the terminal
    notes = list(run.notes) + [
        f"warning: {one_line(str(w.message))}" for w in caught if w.category is not RuntimeWarning
    ]
    return run.calibration, run.poses, run.document(), notes


def targets(given: Given, dip: float | None = None) -> library.Targets:
    """The accuracy targets of ``plan`` from its ``--target-*`` options: those left out take
    :class:`fieldcal.Targets`' defaults."""
    values = {OPTIONS[n].target: given[OPTIONS[n].column] for n in TARGET_OPTIONS}
    chosen = {k: v for k, v in values.items() if v is not None}
    return library.Targets(**chosen, dip_deg=dip)


#: ``--target-tilt``, ``--target-heading``, ``--target-norm`` alone (``plan``; the commands
#: that calibrate have them among :data:`fit_options`).
target_options = _options(TARGET_OPTIONS)
