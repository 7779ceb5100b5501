"""The ``fieldcal`` command: calibrate a log, apply and export the result, simulate, report, demo.

Commands only: parse the options, call the library, print, choose the exit code.

Exit codes: 0 success; 1 a bug in fieldcal (one line asking for a report; ``FIELDCAL_DEBUG=1``
shows the traceback); 2 a mistake in the user's input (file, columns, options, too few or
degenerate poses, an output that exists or is an input), reported as one ``Error: ...`` line on
stderr, never a traceback; 3 the calibration's verdict is ``fail`` (every requested file is
still written); 130 interrupted (Ctrl-C): one line saying which files were completed.

Files: every output is checked before any work (never an input of the command, compared by
file identity; an existing file only with ``--force``) and written atomically
(:mod:`fieldcal._files`), so an error or an interrupt leaves the old file or the new one.

Startup: ``fieldcal --version`` and ``--help`` load numpy, click and fieldcal's light modules
only. Rich, the pipeline and the output modules load inside the commands, through
:func:`_lazy`; SciPy and matplotlib load when a calibration or a report first needs them.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import importlib
import importlib.util
import inspect
import json
import math
import os
import sys
import tempfile
import time
import warnings
import zipfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, TypedDict, TypeVar, Unpack, cast

import click
import numpy as np

from . import _files
from ._version import __version__
from .api import calibrate as _calibrate
from .calibration import Calibration, SensorCalibration
from .errors import InputError
from .geometry.frames import ACCEL_SIGNS
from .methods import METHODS
from .metrics import reconstruction_error
from .output import exports
from .simulation.session import PRESETS, Preset, Session
from .simulation.session import simulate as simulate_session

if TYPE_CHECKING:
    from rich.console import Console

    from .logs import Log, PoseSet

__all__ = ["EXIT_BUG", "EXIT_FAIL", "EXIT_INTERRUPTED", "EXIT_OK", "EXIT_USAGE", "cli", "main"]

#: Exit codes: success; a bug in fieldcal; a mistake in the input or options; a calibration whose
#: verdict is fail; interrupted (128 + SIGINT, as shells report Ctrl-C).
EXIT_OK, EXIT_BUG, EXIT_USAGE, EXIT_FAIL, EXIT_INTERRUPTED = 0, 1, 2, 3, 130

#: Exceptions a user can cause with a file or an option: one ``Error:`` line, exit code 2.
_USER_ERRORS = (
    InputError,
    ValueError,  # UnicodeError, json's and pyarrow's ArrowInvalid among them
    OSError,
    np.linalg.LinAlgError,
    OverflowError,  # extreme values
    FloatingPointError,
    MemoryError,
    EOFError,  # a truncated .npy
    zipfile.BadZipFile,  # a damaged .npz
    csv.Error,
)
#: The environment variable that shows the traceback of an unexpected error (and warnings).
_DEBUG = "FIELDCAL_DEBUG"
#: The calibration file ``calibrate`` writes when neither ``-o`` nor ``--json`` is given.
_DEFAULT_OUTPUT = "cal.json"
#: The library's default method: the command line has no default of its own.
_DEFAULT_METHOD = inspect.signature(_calibrate).parameters["method"].default
#: Largest (and 1 / smallest) magnitude taken for a field, a noise or a threshold: its square
#: stays a finite, normal double, over the raw scales fieldcal supports (1e-30 to 1e149).
_BIG = 1e150

#: A command function, as click's decorators take and return it.
_Command = TypeVar("_Command", bound=Callable[..., object])
#: What the commands pass to the library for progress: one line of text, or nothing.
_Progress = Callable[[str], None] | None


class _LogOptions(TypedDict, total=False):
    """What :func:`_log_options` adds to a command (popped by :func:`_load`)."""

    accel_cols: str | None
    mag_cols: str | None
    gyro_cols: str | None
    time_col: str | None
    pose_col: str | None
    drop_nan: bool
    decimal: str | None
    split_on_reset: bool
    imu_topic: str | None
    mag_topic: str | None


class _CalibrateOptions(_LogOptions, total=False):
    """The ``calibrate`` command's options other than ``--pose-noise``; absent ones take the
    library's defaults."""

    method: str
    gravity: float | None
    field_strength: float | str | None
    location: str | None
    date: str | None
    dip_allowance: float | None
    noise: str | None
    no_robust: bool
    mag_axes: str | None
    mag_mirrored: bool
    rate: float | None
    min_still: float | None
    window: float | None
    trim: float | None
    still_threshold: float | None
    poses: str
    accel_sign: str
    gyro: bool | None


class _ParsedOptions(_CalibrateOptions, total=False):
    """The options :func:`_run_calibration` takes: ``--pose-noise`` parsed."""

    pose_noise: str | float | dict[str, str | float]


def _lazy(name: str) -> ModuleType:
    """Import ``name`` (``".pipeline"`` is fieldcal's) when a command first needs it.

    The one place that imports lazily: rich, the pipeline and the summary would add about
    40 % to the import time of ``--version`` and ``--help``, which need none of them; the
    report brings matplotlib.
    """
    return importlib.import_module(name, __package__)


def _console(*, stderr: bool = False) -> Console:
    """The console every command prints through: user text (paths, column names, labels,
    reasons) is printed literally, never read as markup or emoji codes."""
    console: type[Console] = _lazy("rich.console").Console
    return console(stderr=stderr, markup=False, emoji=False, highlight=False, soft_wrap=True)


def _debug() -> bool:
    return os.environ.get(_DEBUG, "").strip() not in ("", "0")


def _one_line(text: str) -> str:
    return " ".join(text.split())


class _UsageError(click.ClickException):
    """A usage error shown as one ``Error: ...`` line (click's adds the usage block)."""

    exit_code = EXIT_USAGE

    @classmethod
    def of(cls, exc: click.UsageError) -> _UsageError:
        where = exc.ctx.command_path if exc.ctx is not None else "fieldcal"
        return cls(f"{_one_line(exc.format_message()).rstrip('.')}; see '{where} --help'")


def _user_message(exc: BaseException) -> str:
    if isinstance(exc, MemoryError):
        return "not enough memory for this input; give a smaller log (apply streams CSV files)"
    message = _one_line(str(exc)) or type(exc).__name__
    if isinstance(exc, OSError) and exc.filename and str(exc.filename) not in message:
        message = f"{exc.filename}: {message}"
    return message


def _show_warnings(caught: Sequence[warnings.WarningMessage]) -> None:
    """Warnings meant for the user as ``warning:`` lines on stderr; numpy's floating-point
    RuntimeWarnings (and warnings for developers) never reach the terminal."""
    hidden = (DeprecationWarning, PendingDeprecationWarning, FutureWarning)
    shown: list[str] = []
    for w in caught:
        if w.category is RuntimeWarning or issubclass(w.category, hidden):
            continue
        text = f"warning: {_one_line(str(w.message))}"
        if text not in shown:
            shown.append(text)
    for text in shown:
        click.echo(text, err=True)


class _Group(click.Group):
    """The one error path of the commands.

    - usage errors (unknown option, bad value, missing argument): one ``Error:`` line, exit 2;
    - errors in the user's input (:data:`_USER_ERRORS`): one ``Error:`` line, exit 2;
    - Ctrl-C: ``Interrupted; ...`` naming the files completed, exit 130 (every file is written
      atomically, so nothing is left half-written);
    - anything else is a bug: one line asking for a report, exit 1 (the traceback with
      ``FIELDCAL_DEBUG=1``).

    Warnings are collected: numpy's floating-point RuntimeWarnings are dropped, others are
    printed as one ``warning:`` line each after a command that succeeded.
    """

    def make_context(
        self,
        info_name: str | None,
        args: list[str],
        parent: click.Context | None = None,
        **extra: Any,
    ) -> click.Context:
        try:
            return super().make_context(info_name, args, parent, **extra)
        except click.exceptions.NoArgsIsHelpError:
            raise  # `fieldcal` alone prints the help
        except click.UsageError as exc:
            raise _UsageError.of(exc) from None

    def invoke(self, ctx: click.Context) -> object:
        debug = _debug()
        caught: list[warnings.WarningMessage] = []
        succeeded = False
        with _files.record() as done:
            try:
                with warnings.catch_warnings(record=not debug) as recorded:
                    if recorded is not None:
                        warnings.simplefilter("always")
                        caught = recorded
                    result = super().invoke(ctx)
                succeeded = True
                return result
            except click.exceptions.Exit as exc:
                succeeded = exc.exit_code in (EXIT_OK, EXIT_FAIL)
                raise
            except click.UsageError as exc:
                raise _UsageError.of(exc) from None
            except (click.ClickException, click.Abort, BrokenPipeError):
                raise  # click's own handling (a closed pipe ends quietly)
            except KeyboardInterrupt:
                wrote = ", ".join(str(p) for p in done)
                click.echo(
                    f"Interrupted; completed {wrote}; nothing else was written"
                    if done
                    else "Interrupted; nothing was written",
                    err=True,
                )
                ctx.exit(EXIT_INTERRUPTED)
            except _USER_ERRORS as exc:
                click.echo(f"Error: {_user_message(exc)}", err=True)
                ctx.exit(EXIT_USAGE)
            except Exception as exc:
                message = _one_line(str(exc))
                click.echo(
                    f"Error: {type(exc).__name__}{': ' + message if message else ''}; this is a "
                    "bug in fieldcal; please report it with the command "
                    f"({_DEBUG}=1 shows the traceback)",
                    err=True,
                )
                if debug:
                    raise
                ctx.exit(EXIT_BUG)
            finally:
                if succeeded:
                    _show_warnings(caught)


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, "--version", prog_name="fieldcal")
def cli() -> None:
    """Calibrate an accelerometer and a magnetometer together from a log of still poses.

    Start with `fieldcal demo`, then `fieldcal calibrate LOG -o cal.json`.
    """


def main() -> None:
    """Console-script entry point."""
    cli(prog_name="fieldcal")


if TYPE_CHECKING:  # generic from click 8.2 on; fieldcal supports 8.1
    _NumberBase = click.ParamType[float]
else:
    _NumberBase = click.ParamType


class _Number(_NumberBase):
    """A finite number in a range, checked when the option is parsed (a one-line error naming
    the option and the range)."""

    name = "number"

    def __init__(self, low: float, high: float, *, low_open: bool = True) -> None:
        self.low, self.high, self.low_open = low, high, low_open

    def convert(
        self, value: Any, param: click.Parameter | None, ctx: click.Context | None
    ) -> float:
        if isinstance(value, float):
            number = value
        else:
            try:
                number = float(str(value).strip())
            except ValueError:
                self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        below = number <= self.low if self.low_open else number < self.low
        if below or number > self.high:
            low = "above" if self.low_open else "at least"
            self.fail(
                f"{value} is out of range; give a number {low} {self.low:g} and at most "
                f"{self.high:g}",
                param,
                ctx,
            )
        return number


#: Positive magnitudes (fields, thresholds, noise): their squares stay finite and normal.
_MAGNITUDE = _Number(1 / _BIG, _BIG, low_open=False)


class _FieldStrength(_Number):
    """``--field-strength``: a magnitude, or ``wmm`` (``wmm:uT``, ``wmm:nT``) for the World
    Magnetic Model's intensity at ``--location``."""

    name = "number|wmm"

    def convert(  # type: ignore[override]  # a number or the model's keyword
        self, value: Any, param: click.Parameter | None, ctx: click.Context | None
    ) -> float | str:
        text = str(value).strip()
        if text.lower() in ("wmm", "wmm:ut", "wmm:nt"):
            return text
        if not isinstance(value, float) and text[:1].isalpha():
            self.fail(
                f"{value!r} is neither a number nor wmm (wmm:uT, wmm:nT: the World Magnetic "
                "Model's intensity at --location)",
                param,
                ctx,
            )
        return super().convert(value, param, ctx)


#: Sample rates (Hz) and durations (seconds, or samples without a rate).
_POSITIVE = _Number(0.0, 1e12)
_NON_NEGATIVE = _Number(0.0, 1e12, low_open=False)


def _force(f: _Command) -> _Command:
    decorated: _Command = click.option(
        "--force",
        is_flag=True,
        help="Replace output files that exist (never an input of the command).",
    )(f)
    return decorated


def _claim(
    outputs: Sequence[str | Path | None],
    inputs: dict[str, str],
    force: bool,
    *,
    folders_made: bool = False,
) -> None:
    """Check the outputs before any work (:func:`fieldcal._files.check_outputs`)."""
    _files.check_outputs(
        [o for o in outputs if o is not None], inputs, force=force, folders_made=folders_made
    )


@contextmanager
def _progress(quiet: bool) -> Iterator[_Progress]:
    """A status line on stderr showing the library's progress messages, or ``None``: off
    with ``--quiet`` and when stderr is not a terminal (a pipe, a file, a test)."""
    stream = sys.stderr
    if quiet or stream is None or not stream.isatty():
        yield None
        return
    text = _lazy("rich.text").Text
    status = _console(stderr=True).status(text("working"), spinner="dots")
    with status:
        yield lambda line: status.update(text(_one_line(line)))


# ----------------------------------------------------------------------------- helpers
def _read_cal(path: str) -> Calibration:
    file = Path(path)
    if file.is_dir():
        raise InputError(f"{path}: is a folder; give the calibration JSON inside it")
    if not file.is_file():
        raise InputError(f"{path}: no such calibration file; write one with `fieldcal calibrate`")
    try:
        text = file.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(
            f"{path}: not a text file; give the calibration JSON `fieldcal calibrate` wrote"
        ) from None
    return Calibration.from_json(text)


def _finish(cal: Calibration, *, summary_shown: bool) -> None:
    """Exit with code 3 when the verdict is fail; say why on stderr if the summary did not."""
    if cal.verdict is None or cal.verdict.level != "fail":
        return
    if not summary_shown:
        _lazy(".output.summary").print_verdict(_console(stderr=True), cal)
    click.get_current_context().exit(EXIT_FAIL)


def _magnitude(text: str) -> float:
    """A standard deviation as ``--noise`` takes it: finite, within [1/_BIG, _BIG]."""
    value = float(text)
    if not (math.isfinite(value) and 1 / _BIG <= value <= _BIG):
        raise ValueError
    return value


def _parse_noise(text: str | None) -> float | dict[str, float] | None:
    """``"0.01"`` -> 0.01 for both sensors; ``"accel=0.01,mag=0.2"`` -> a per-sensor dict."""
    if text is None:
        return None
    try:
        if "=" not in text:
            return _magnitude(text)
        out = {}
        for part in text.split(","):
            key, _, number = part.partition("=")
            key = key.strip().lower()
            if key not in ("accel", "mag"):
                raise ValueError
            out[key] = _magnitude(number)
        return out
    except ValueError:
        raise InputError(
            f"--noise {text!r} is not understood; give one standard deviation of a raw sample "
            f"between {1 / _BIG:g} and {_BIG:g} (e.g. 0.01) or one per sensor, e.g. "
            "accel=0.01,mag=0.2"
        ) from None


def _pose_noise_value(text: str, spec: str) -> str | float:
    word = text.strip().lower()
    if word in ("auto", "none"):
        return word
    try:
        value = float(word)
    except ValueError:
        value = float("nan")
    if not (math.isfinite(value) and 0 <= value <= _BIG):
        raise InputError(
            f"--pose-noise {spec!r} is not understood; give auto (estimate it), none (zero), a "
            f"standard deviation in raw units from 0 to {_BIG:g} (e.g. 0.01), or per sensor, "
            "e.g. accel=0.01,mag=0.2"
        )
    return value


def _parse_pose_noise(spec: str) -> str | float | dict[str, str | float]:
    """``auto``, ``none``, a number, or ``accel=0.01,mag=auto`` as :func:`fieldcal.calibrate`
    takes it (a sensor not named is estimated)."""
    if "=" not in spec:
        return _pose_noise_value(spec, spec)
    out: dict[str, str | float] = {}
    for part in spec.split(","):
        key, _, value = part.partition("=")
        key = key.strip().lower()
        if key not in ("accel", "mag"):
            raise InputError(
                f"--pose-noise {spec!r}: {key!r} is not a sensor; name accel and/or mag, e.g. "
                "accel=0.01,mag=0.2"
            )
        out[key] = _pose_noise_value(value, spec)
    return out


#: How a log without a pose column is cut into poses (``calibrate``, ``batch``).
_POSES_OPTION = click.option(
    "--poses",
    type=click.Choice(["still", "windows"]),
    default="still",
    show_default=True,
    help="Without a pose column: detect still intervals, or cut the log into windows of "
    "--window seconds (a log turned slowly with no rests).",
)


def _sensor_columns(f: _Command) -> _Command:
    """``--accel-cols``, ``--mag-cols``, ``--gyro-cols``: every command that reads a log."""
    options = [
        click.option("--accel-cols", help="Accelerometer columns x,y,z (default: recognised)."),
        click.option("--mag-cols", help="Magnetometer columns x,y,z (default: recognised)."),
        click.option("--gyro-cols", help="Gyroscope columns x,y,z (helps still detection)."),
    ]
    for option in reversed(options):
        f = option(f)
    return f


def _log_options(f: _Command) -> _Command:
    options = [
        _sensor_columns,
        click.option("--time-col", help="Time column (s; ms/us/ns recognised)."),
        click.option("--pose-col", help="Pose-label column: rows are grouped by it."),
        click.option("--drop-nan", is_flag=True, help="Drop rows with NaN/inf instead of failing."),
        click.option(
            "--decimal",
            type=click.Choice([".", ","]),
            help="Decimal mark of a text log (default: '.', or ',' when the file shows it).",
        ),
        click.option(
            "--split-on-reset",
            is_flag=True,
            help="Time going backwards starts a new segment instead of being an error.",
        ),
        click.option("--imu-topic", help="ROS bag: the sensor_msgs/Imu topic (default: the one)."),
        click.option(
            "--mag-topic", help="ROS bag: the sensor_msgs/MagneticField topic (default: the one)."
        ),
    ]
    for option in reversed(options):
        f = option(f)
    return f


def _detect_options(f: _Command) -> _Command:
    options = [
        click.option(
            "--rate", type=_POSITIVE, help="Sample rate in Hz when there is no time column."
        ),
        click.option(
            "--min-still",
            type=_POSITIVE,
            help="Shortest still interval: seconds (samples without time/rate). Default 1 s / 50.",
        ),
        click.option(
            "--window",
            type=_POSITIVE,
            help="Moving-variance window: seconds (samples without time/rate). Default 0.5 s / 25.",
        ),
        click.option(
            "--trim", type=_NON_NEGATIVE, help="Cut at each end of an interval (s or samples)."
        ),
        click.option(
            "--still-threshold",
            type=_MAGNITUDE,
            help="Accelerometer threshold, per-axis std in raw units (default: 3x noise floor).",
        ),
    ]
    for option in reversed(options):
        f = option(f)
    return f


def _fit_options(f: _Command) -> _Command:
    """The calibration's options, shared by ``calibrate`` and ``capture``."""
    options = [
        click.option(
            "--method",
            type=click.Choice(list(METHODS)),
            default=_DEFAULT_METHOD,
            show_default=True,
            help="Calibration method: "
            + "; ".join(f"{m.name}, {m.summary}" for m in METHODS.values())
            + ".",
        ),
        click.option(
            "--gravity",
            type=_MAGNITUDE,
            help="|g| for calibrated accel units (e.g. 9.80665).",
        ),
        click.option(
            "--field-strength",
            type=_FieldStrength(1 / _BIG, _BIG, low_open=False),
            help="|h| for calibrated mag units (e.g. 48.5), or wmm: the World Magnetic Model's "
            "intensity at --location in µT (wmm:nT for nT).",
        ),
        click.option(
            "--location",
            metavar="LAT,LON[,ALT_M]",
            help="Where the log was recorded (decimal degrees, metres above the WGS 84 "
            "ellipsoid): the World Magnetic Model's dip, intensity and declination there are "
            "the reference; its dip decides the magnetometer's handedness and is checked.",
        ),
        click.option(
            "--date",
            metavar="YYYY-MM-DD",
            help="When the log was recorded, for --location (default: today).",
        ),
        click.option(
            "--dip-allowance",
            type=_Number(0.0, 89.0, low_open=False),
            help="Degrees of dip allowed for a local anomaly beyond the uncertainties before "
            "the verdict warns (default 2).",
        ),
        click.option(
            "--noise",
            help="Noise std of one raw sample: one value, or accel=0.01,mag=0.2 "
            "(default: estimated).",
        ),
        click.option(
            "--pose-noise",
            default="auto",
            show_default=True,
            help="Pose-level noise std of each pose mean, raw units: auto (estimated), none "
            "(zero, the seed paper's model), one value, or accel=0.01,mag=0.2.",
        ),
        click.option(
            "--no-robust",
            is_flag=True,
            help="Keep every pose and every sample: no rejection of disturbed poses, no "
            "trimming of bumps inside a pose.",
        ),
        click.option(
            "--mag-axes",
            help="Magnetometer axis map onto the accelerometer's, e.g. +y+x-z.",
        ),
        click.option(
            "--accel-sign",
            type=click.Choice(ACCEL_SIGNS),
            default=ACCEL_SIGNS[0],
            show_default=True,
            help="What the accelerometer reports at rest: specific force (+1 g up) or gravity "
            "(-1 g up, some loggers); the result corrects to specific force either way.",
        ),
        click.option(
            "--gyro/--no-gyro",
            default=None,
            help="Calibrate the gyroscope from the motion between the poses: by default when "
            "the log has one and it can be (a note says why not); --gyro makes that an error.",
        ),
        click.option(
            "--mag-mirrored",
            is_flag=True,
            help="The magnetometer's axes (after --mag-axes) are left-handed relative to the "
            "accelerometer's; static data cannot tell this from the dip's sign.",
        ),
    ]
    for option in reversed(options):
        f = option(f)
    return f


def _load(log: str, cols: _LogOptions, progress: _Progress = None) -> Log:
    """The log, its columns and reading options as the ``_log_options`` give them (popped
    from ``cols``); options left at their defaults are not passed."""
    load_log = _lazy(".logs").load_log
    given: dict[str, Any] = cols  # type: ignore[assignment]
    taken = {name: given.pop(name) for name in _LogOptions.__annotations__ if name in given}
    reading = {k: v for k, v in taken.items() if v is not None and v is not False}
    if progress is not None:
        reading["on_progress"] = progress
    loaded: Log = load_log(log, **reading)
    return loaded


def _check_reference(opts: _ParsedOptions) -> None:
    """``--location``, ``--date`` and ``--field-strength wmm`` checked before the slow part (the
    library checks them again, as it must for its own callers)."""
    location, date = opts.get("location"), opts.get("date")
    if location is not None:
        _lazy(".reference").expected_field(location, date)
    elif date is not None:
        raise InputError("--date was given without --location; give --location LAT,LON too")
    strength = opts.get("field_strength")
    if isinstance(strength, str) and location is None:
        raise InputError(
            f"--field-strength {strength} takes the World Magnetic Model's intensity where the "
            "log was recorded: give --location LAT,LON too"
        )


def _fit_choices(opts: _ParsedOptions) -> dict[str, Any]:
    """The options of :func:`fieldcal.pipeline.run_log` that shape the fit (not the
    detection), from the ``_fit_options``; absent ones take the library's defaults (the
    method, robust fitting, estimated pose-level noise)."""
    choices: dict[str, Any] = {
        key: opts[key]
        for key in ("method", "pose_noise", "accel_sign", "mag_axes", "gyro")
        if opts.get(key) is not None
    }
    if opts.get("no_robust"):
        # trimming bumps inside a pose is part of the robust fit: off together
        choices.update(robust=False, trim=False)
    if opts.get("location") is not None or opts.get("date") is not None:
        choices.update(location=opts.get("location"), date=opts.get("date"))
    if opts.get("dip_allowance") is not None:
        choices["dip_allowance_deg"] = opts.get("dip_allowance")
    return {
        **choices,
        "gravity": opts.get("gravity"),
        "field_strength": opts.get("field_strength"),
        "noise": _parse_noise(opts.get("noise")),
        "mag_mirrored": bool(opts.get("mag_mirrored")),
    }


def _run_options(opts: _ParsedOptions) -> dict[str, Any]:
    """:func:`fieldcal.pipeline.run_log`'s keywords from the command's options: how the log is
    cut into poses (absent ones take the library's defaults) and the fit's choices."""
    cut = {k: opts.get(k) for k in ("poses", "rate") if opts.get(k) is not None}
    return {
        "window": opts.get("window"),
        "min_still": opts.get("min_still"),
        "still_trim": opts.get("trim"),
        "still_threshold": opts.get("still_threshold"),
        **cut,
        **_fit_choices(opts),
    }


def _run_calibration(
    log: Log, opts: _ParsedOptions, progress: _Progress = None
) -> tuple[Calibration, PoseSet, dict[str, Any], list[str]]:
    """Poses, calibration, the JSON document and the notes on the input for a loaded log.

    ``opts`` holds the ``calibrate`` command's options (``pose_noise`` parsed); any left out
    take the library's defaults (the method, robust fitting, estimated pose-level noise).
    ``progress`` hears the steps (and the library's progress lines) when given.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = _lazy(".pipeline").run_log(log, on_progress=progress, **_run_options(opts))
    # the library's warnings belong in the summary, not as tracebacks; numpy's floating-point
    # RuntimeWarnings are the library's business and never reach the terminal
    notes = list(run.notes) + [
        f"warning: {_one_line(str(w.message))}" for w in caught if w.category is not RuntimeWarning
    ]
    return run.calibration, run.poses, run.document(), notes


def _write_json(path: str | Path, doc: dict[str, object]) -> None:
    _files.write_text(path, json.dumps(doc, indent=2, allow_nan=False) + "\n")


# ----------------------------------------------------------------------------- calibrate
@cli.command()
@click.argument("log", type=click.Path())
@click.option(
    "-o",
    "--output",
    help=f"Calibration JSON to write. [default: {_DEFAULT_OUTPUT}; with --json, only when given]",
)
@_fit_options
@_POSES_OPTION
@_log_options
@_detect_options
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print the result as JSON instead of the summary (writes a file only with -o).",
)
@click.option("--quiet", "-q", is_flag=True, help="Print only errors and a fail verdict.")
@_force
def calibrate(
    log: str,
    output: str | None,
    as_json: bool,
    quiet: bool,
    force: bool,
    pose_noise: str,
    **opts: Unpack[_CalibrateOptions],
) -> None:
    """Calibrate from LOG (CSV with header, .npz or .parquet) and write the calibration JSON.

    The verdict (PASS, WARN or FAIL, with reasons) comes first. Exit code 3 when it is FAIL;
    the JSON is written all the same.
    """
    if output is None and not as_json:
        output = _DEFAULT_OUTPUT
    _claim([output], {"log": log}, force)
    # the options given as text are parsed before the slow part
    options: _ParsedOptions = {**opts, "pose_noise": _parse_pose_noise(pose_noise)}
    _parse_noise(opts.get("noise"))
    _check_reference(options)
    with _progress(quiet) as progress:
        if progress is not None:
            progress(f"reading {log}")
        data = _load(log, options, progress)
        cal, _, doc, notes = _run_calibration(data, options, progress)
    if output is not None:
        _write_json(output, doc)
    if as_json:
        click.echo(json.dumps(doc, indent=2, allow_nan=False))
    elif not quiet:
        console = _console()
        _lazy(".output.summary").print_summary(console, cal, doc, notes)
        console.print(f"wrote {output}")
    _finish(cal, summary_shown=not (as_json or quiet))


# ----------------------------------------------------------------------------- apply
@cli.command()
@click.argument("cal_json", type=click.Path())
@click.argument("log", type=click.Path())
@click.option(
    "-o",
    "--output",
    required=True,
    help="The log with calibrated columns, in the format of its suffix (.csv, .parquet, .npz).",
)
@click.option("--accel-cols", help="Accelerometer columns x,y,z (default: recognised).")
@click.option("--mag-cols", help="Magnetometer columns x,y,z (default: recognised).")
@click.option(
    "--decimal", type=click.Choice([".", ","]), help="Decimal mark of a text log (default: seen)."
)
@click.option("--imu-topic", help="ROS bag: the sensor_msgs/Imu topic (default: the one).")
@click.option("--mag-topic", help="ROS bag: the sensor_msgs/MagneticField topic.")
@click.option("--quiet", "-q", is_flag=True, help="Print only errors.")
@_force
def apply(
    cal_json: str,
    log: str,
    output: str,
    accel_cols: str | None,
    mag_cols: str | None,
    decimal: str | None,
    imu_topic: str | None,
    mag_topic: str | None,
    quiet: bool,
    force: bool,
) -> None:
    """Append calibrated columns (<col>_cal) to LOG, keeping everything else as it was.

    The output's suffix names its format; CSV to CSV is streamed in chunks, every input
    line kept byte for byte. A ROS bag gives its table (t, ax.., gx.., mx..) with the
    calibrated columns.
    """
    _claim([output], {"calibration": cal_json, "log": log}, force)
    logs = _lazy(".logs.apply")
    logs.check_pyarrow(log, output)
    cal = _read_cal(cal_json)
    with _progress(quiet) as progress:
        if progress is not None:
            progress(f"applying the calibration to {log}")
        used = logs.apply_to_file(
            cal,
            log,
            output,
            accel_cols=accel_cols,
            mag_cols=mag_cols,
            decimal=decimal,
            imu_topic=imu_topic,
            mag_topic=mag_topic,
            on_progress=progress,
        )
    if not quiet:
        cols = "; ".join(f"{s}: {','.join(c)}" for s, c in used.items())
        _console().print(f"calibrated {cols} -> {output}")


# ----------------------------------------------------------------------------- export
_SUFFIXES = ", ".join(f"{f.suffix} {f.name}" for f in exports.FORMATS.values())


@cli.command()
@click.argument("cal_json", type=click.Path())
@click.option(
    "--format",
    "fmt",
    type=click.Choice(list(exports.FORMATS)),
    help=f"Target convention. [default: from -o's suffix ({_SUFFIXES}), else {exports.DEFAULT}]",
)
@click.option("-o", "--output", help="Write to this file instead of stdout.")
@_force
def export(cal_json: str, fmt: str | None, output: str | None, force: bool) -> None:
    """Write the calibration for firmware or another tool, its convention stated in the text."""
    _claim([output], {"calibration": cal_json}, force)
    if fmt is None:
        by_suffix = exports.for_path(output) if output else None
        fmt = by_suffix.name if by_suffix else exports.DEFAULT
    cal = _read_cal(cal_json)
    if exports.get(fmt).binary is not None:  # a binary file (.mat) only goes to -o
        data = exports.export_bytes(cal, fmt)
        if not output:
            raise InputError(f"the {fmt} format is binary: give -o FILE{exports.get(fmt).suffix}")
        _files.write_bytes(output, data)
        return
    text = exports.export(cal, fmt)
    if output:
        _files.write_text(output, text if text.endswith("\n") else text + "\n")
    else:
        click.echo(text.rstrip("\n"))


# ----------------------------------------------------------------------------- simulate
@cli.command()
@click.option(
    "--preset",
    type=click.Choice(list(PRESETS)),
    default="paper",
    show_default=True,
    help="Simulation preset.",
)
@click.option(
    "--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Random seed."
)
@click.option("-o", "--output", default="session.csv", show_default=True, help="Session CSV.")
@click.option("--truth", help="Also write the true calibration as JSON.")
@click.option("--continuous", is_flag=True, help="Time-stamped log with motion between poses.")
@click.option("--poses", type=click.IntRange(1, 1000), help="Number of poses (preset default: 15).")
@click.option(
    "--handheld", is_flag=True, help="Hand-held poses (mostly < 60° tilt) instead of uniform."
)
@click.option(
    "--rate",
    type=_Number(10.0, 10_000.0, low_open=False),
    default=100.0,
    show_default=True,
    help="Hz (--continuous).",
)
@_force
def simulate(
    preset: str,
    seed: int,
    output: str,
    truth: str | None,
    continuous: bool,
    poses: int | None,
    handheld: bool,
    rate: float,
    force: bool,
) -> None:
    """Write a synthetic session to try the tool on (a `pose` column, or --continuous)."""
    _claim([output, truth], {}, force)
    extra: Preset = {"n_poses": poses} if poses else {}
    if handheld:
        extra["pose_distribution"] = "handheld"
    if continuous:
        log = _lazy(".simulation.continuous").simulate_continuous(
            preset, seed=seed, rate=rate, **extra
        )
        with _files.replacing(output) as temp:
            log.write_csv(str(temp))
        session: Session = log.session
        true_cal = session.truth
        gyro = log.gyro_truth
        if gyro is not None:  # in fieldcal's body frame, as an estimate from the log is
            sensor = SensorCalibration(
                gain=gyro.gain, bias=gyro.bias, noise_cov=gyro.noise_std**2 * np.eye(3)
            )
            true_cal = dataclasses.replace(true_cal, gyro=sensor)
    else:
        session = simulate_session(preset, seed=seed, **extra)
        true_cal = session.truth
        with _files.replacing(output) as temp:
            session.write_csv(temp)
    if truth:
        _files.write_text(truth, true_cal.to_json() + "\n")
    click.echo(f"wrote {output}" + (f" and {truth}" if truth else ""))


# ----------------------------------------------------------------------------- report
def _check_matplotlib() -> None:
    if importlib.util.find_spec("matplotlib") is None:
        raise InputError(
            "the report needs matplotlib, which is not installed; pip install 'fieldcal[plot]'"
        )


@cli.command()
@click.argument("cal_json", type=click.Path())
@click.argument("log", type=click.Path())
@click.option("-o", "--output", default="report.html", show_default=True, help="HTML report.")
@click.option("--png", "png_dir", help="Also write each figure as PNG into this folder.")
@_log_options
@click.option("--quiet", "-q", is_flag=True, help="Print only errors.")
@_force
def report(
    cal_json: str,
    log: str,
    output: str,
    png_dir: str | None,
    quiet: bool,
    force: bool,
    **cols: Unpack[_LogOptions],
) -> None:
    """Pictures of the calibration: spheres, pose coverage, residuals, norm and dip histograms."""
    inputs = {"calibration": cal_json, "log": log}
    _claim([output], inputs, force)
    report_module = _lazy(".output.report")
    if png_dir is not None:
        pngs = [Path(png_dir) / f"{name}.png" for name in report_module.FIGURES]
        _claim(pngs, inputs, force, folders_made=True)
    _check_matplotlib()
    cal = _read_cal(cal_json)
    with _progress(quiet) as progress:
        if progress is not None:
            progress(f"reading {log}")
        data = _load(log, cols, progress)
        if progress is not None:
            progress("drawing the report")
        report_module.write_report(cal, data, output, png_dir=png_dir, on_progress=progress)
    if not quiet:
        click.echo(f"wrote {output}" + (f" and PNGs in {png_dir}" if png_dir else ""))


# ----------------------------------------------------------------------------- capture
#: The files a capture writes into its folder.
_CAPTURE_FILES = ("log.csv", "cal.json", "report.html")


def _capture_folder(out_dir: str | None, force: bool, inputs: dict[str, str]) -> Path:
    """The capture's folder; its files checked before any line is read."""
    folder = Path(out_dir or time.strftime("capture-%Y%m%d-%H%M%S"))
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder}: exists and is not a folder; give --out a folder")
    # the recorder makes the folder once the source is open: a wrong port leaves nothing
    _claim([folder / name for name in _CAPTURE_FILES], inputs, force, folders_made=True)
    return folder


def _targets(heading: float, tilt: float, dip: float | None = None) -> Any:
    return _lazy(".trust.plan").Targets(heading_deg=heading, tilt_deg=tilt, dip_deg=dip)


def _target_options(f: _Command) -> _Command:
    options = [
        click.option(
            "--target-heading",
            type=_POSITIVE,
            default=1.0,
            show_default=True,
            help="Predicted heading error (1σ, degrees) to reach.",
        ),
        click.option(
            "--target-tilt",
            type=_POSITIVE,
            default=0.5,
            show_default=True,
            help="Predicted tilt error (1σ, degrees) to reach.",
        ),
    ]
    for option in reversed(options):
        f = option(f)
    return f


@cli.command()
@click.option("--port", help="Serial port of the device (e.g. /dev/ttyACM0, COM3); pyserial.")
@click.option(
    "--baud",
    type=click.IntRange(1),
    default=115200,
    show_default=True,
    help="Bits per second of the serial port.",
)
@click.option(
    "--from",
    "from_path",
    help="Read the lines from FILE instead, or from standard input with - (a command's output).",
)
@click.option("--follow", is_flag=True, help="With --from FILE: keep reading as it grows.")
@click.option(
    "--columns",
    help="Names of the fields of bare-number lines, e.g. t,ax,ay,az,mx,my,mz (else the stream "
    "sends a header line).",
)
@click.option(
    "--out",
    "out_dir",
    help="Folder for log.csv, cal.json and report.html [default: capture-DATE-TIME].",
)
@click.option(
    "--until",
    type=click.Choice(["pass"]),
    help="Stop by itself once the verdict is pass and the accuracy targets are met.",
)
@_target_options
@click.option("--plain", is_flag=True, help="One line per event instead of the live view.")
@_fit_options
@_sensor_columns
@click.option("--time-col", help="Time column (s; ms/us/ns recognised); default: arrival time.")
@click.option("--decimal", type=click.Choice([".", ","]), help="Decimal mark of the numbers.")
@_detect_options
@click.option("--quiet", "-q", is_flag=True, help="Print only errors and a fail verdict.")
@_force
def capture(
    port: str | None,
    baud: int,
    from_path: str | None,
    follow: bool,
    columns: str | None,
    out_dir: str | None,
    until: str | None,
    target_heading: float,
    target_tilt: float,
    plain: bool,
    quiet: bool,
    force: bool,
    pose_noise: str,
    **opts: Any,
) -> None:
    """Calibrate live from a device: catch each still pose, say which pose to take next.

    Reads CSV lines (a header, or bare numbers with --columns) from a serial port, standard
    input or a file. Stops at the end of the input, when --until is met, on q or Ctrl-C; then
    writes log.csv (every line received, with its arrival time), cal.json and the report into
    --out. Exit code 3 when the final verdict is FAIL.
    """
    if (port is None) == (from_path is None):
        raise click.UsageError("give the device's --port, or --from FILE (- for standard input)")
    if follow and (from_path is None or from_path == "-"):
        raise click.UsageError("--follow is for --from FILE (a file that is still being written)")
    source_name = (
        port if port is not None else ("standard input" if from_path == "-" else from_path)
    )
    options = cast(_ParsedOptions, {**opts, "pose_noise": _parse_pose_noise(pose_noise)})
    _check_reference(options)
    inputs = {} if from_path in (None, "-") else {"log": str(from_path)}
    folder = _capture_folder(out_dir, force, inputs)
    session_module = _lazy(".capture.session")
    names = [name.strip() for name in columns.split(",")] if columns else None
    settings = session_module.CaptureOptions(
        columns=None if names is None else tuple(names),
        decimal=opts.get("decimal"),
        read={k: opts.get(k) for k in ("accel_cols", "mag_cols", "gyro_cols", "time_col")},
        detection={
            "rate": opts.get("rate"),
            "window": opts.get("window"),
            "min_still": opts.get("min_still"),
            "trim": opts.get("trim"),
            "threshold": opts.get("still_threshold"),
        },
        calibration=_fit_choices(options),
        until=until,
        targets=_targets(target_heading, target_tilt),
    )
    source = _lazy(".capture.sources").open_source(
        port=port, baud=baud, path=from_path, follow=follow
    )
    view_module = _lazy(".capture.view")
    live = not (plain or quiet) and sys.stdout.isatty()
    console = _console()
    with contextlib.ExitStack() as stack:
        if live:
            view = stack.enter_context(view_module.LiveView(console, str(source_name)))
        else:
            view = view_module.PlainView(open(os.devnull, "w") if quiet else None)  # noqa: SIM115
            if quiet:
                stack.callback(view.stream.close)
        session = session_module.CaptureSession(settings, folder, view.event)
        key = stack.enter_context(view_module.key_reader(live and from_path != "-"))
        result = session_module.run_capture(source, session, refresh=view.refresh, key=key)
    written = ", ".join(str(p) for p in result.files)
    if result.error is not None:
        raise InputError(f"{result.error} (kept: {written})")
    cal = result.calibration
    if not quiet:
        _lazy(".output.summary").print_summary(
            console, cal, json.loads((folder / "cal.json").read_text()), []
        )
        console.print(f"wrote {written}")
    _finish(cal, summary_shown=not quiet)


# ----------------------------------------------------------------------------- field
@cli.command()
@click.option(
    "--location",
    required=True,
    metavar="LAT,LON[,ALT_M]",
    help="Decimal degrees (north and east positive) and metres above the WGS 84 ellipsoid.",
)
@click.option("--date", metavar="YYYY-MM-DD", help="The date (default: today).")
@click.option("--json", "as_json", is_flag=True, help="Print the values as JSON.")
def field(location: str, date: str | None, as_json: bool) -> None:
    """The Earth's magnetic field expected at --location (World Magnetic Model): dip,
    intensity and declination with their uncertainties, as calibrate --location uses them."""
    ref = _lazy(".reference").expected_field(location, date)
    if as_json:
        click.echo(json.dumps(dataclasses.asdict(ref), indent=2))
        return
    east = "east" if ref.declination_deg >= 0 else "west"
    click.echo(
        f"{ref.model} at {ref.place}, {ref.altitude_m:g} m, on {ref.date}:\n"
        f"  dip (inclination)  {ref.dip_deg:+.2f}° ± {ref.dip_std_deg:.2f}° "
        "(positive below the horizon)\n"
        f"  total intensity    {ref.intensity / 1000:.3f} µT ± {ref.intensity_std / 1000:.3f} "
        f"({ref.intensity:.0f} nT)\n"
        f"  declination        {abs(ref.declination_deg):.2f}° {east} ± "
        f"{ref.declination_std_deg:.2f}° (true heading = magnetic heading "
        f"{'+' if ref.declination_deg >= 0 else '-'} {abs(ref.declination_deg):.2f}°)"
    )


# ----------------------------------------------------------------------------- plan
@cli.command()
@click.argument("cal_json", type=click.Path())
@click.option(
    "-n",
    "count",
    type=click.IntRange(1, 100),
    default=1,
    show_default=True,
    help="How many poses to plan.",
)
@_target_options
@click.option("--target-dip", type=_POSITIVE, help="Dip standard error (degrees) to reach too.")
@click.option("--json", "as_json", is_flag=True, help="Print the plan as JSON.")
def plan(
    cal_json: str,
    count: int,
    target_heading: float,
    target_tilt: float,
    target_dip: float | None,
    as_json: bool,
) -> None:
    """The next poses to take for CAL_JSON: the ones that most reduce the predicted error.

    Each pose is said in words (which axis points down, which way it faces) and predicted
    errors after taking it and the ones before it.
    """
    cal = _read_cal(cal_json)
    planner = _lazy(".trust.plan")
    poses = planner.plan_poses(
        cal, count, targets=_targets(target_heading, target_tilt, target_dip)
    )
    if as_json:
        click.echo(json.dumps([p.to_dict() for p in poses], indent=2, allow_nan=False))
        return
    console = _console()
    for i, pose in enumerate(poses, 1):
        console.print(f"{i}. {pose.words}")
        console.print(f"   then: {planner.predicted_line(pose)}")


# ----------------------------------------------------------------------------- noise
def _unit(text: str | None) -> str | float | None:
    """A unit option: a name (``g``, ``deg/s``) or SI units per raw unit (a number)."""
    if text is None:
        return None
    try:
        return float(text)
    except ValueError:
        return text


@cli.command()
@click.argument("log", type=click.Path())
@click.option("--cal", "cal_json", help="Analyse the readings as this calibration corrects them.")
@click.option(
    "--still",
    type=click.Choice(["auto", "detect", "all"]),
    default="auto",
    show_default=True,
    help="The still intervals detected, the whole log as one still recording, or auto.",
)
@click.option(
    "--export",
    "export_format",
    type=click.Choice(["kalibr"]),
    help="Write Kalibr/OpenVINS imu.yaml (to -o, else stdout).",
)
@click.option("-o", "--output", help="File for --export (e.g. imu.yaml).")
@click.option("--plot", help="Allan deviation figure: a .png, or .html with the table.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@click.option("--accel-unit", help="Raw accelerometer unit: g, mg, m/s^2, or m/s^2 per count.")
@click.option("--gyro-unit", help="Raw gyroscope unit: deg/s, rad/s, or rad/s per count.")
@click.option("--rate", type=_POSITIVE, help="Sample rate in Hz when there is no time column.")
@_sensor_columns
@click.option("--time-col", help="Time column (s; ms/us/ns recognised).")
@click.option("--quiet", "-q", is_flag=True, help="Print only errors.")
@_force
def noise(
    log: str,
    cal_json: str | None,
    still: str,
    export_format: str | None,
    output: str | None,
    plot: str | None,
    as_json: bool,
    accel_unit: str | None,
    gyro_unit: str | None,
    rate: float | None,
    quiet: bool,
    force: bool,
    **cols: str | None,
) -> None:
    """Noise of each sensor from the still parts of LOG: Allan deviation, noise density,
    random walk and bias instability; Kalibr / OpenVINS imu.yaml with --export kalibr."""
    if output is not None and export_format is None:
        raise click.UsageError("-o is the file for --export; add --export kalibr")
    inputs = {"log": log, **({"calibration": cal_json} if cal_json else {})}
    _claim([output, plot], inputs, force)
    cal = _read_cal(cal_json) if cal_json else None
    with _progress(quiet) as progress:
        if progress is not None:
            progress(f"reading {log} and computing Allan deviations")
        report = _lazy(".noise").characterise_noise(
            log,
            cal=cal,
            still=still,
            rate=rate,
            accel_unit=_unit(accel_unit),
            gyro_unit=_unit(gyro_unit),
            **{k: v for k, v in cols.items() if v is not None},
        )
        yaml = report.kalibr_yaml() if export_format == "kalibr" else None
        if plot is not None:
            _check_matplotlib()
            _lazy(".output.noise_figures").write_noise_figure(report, plot)
    if yaml is not None and output is not None:
        _files.write_text(output, yaml)
    if as_json:
        click.echo(json.dumps(report.to_dict(), indent=2, allow_nan=False))
    elif yaml is not None and output is None:
        click.echo(yaml, nl=False)
    elif not quiet:
        _lazy(".output.summary").print_noise(_console(), report)
    if not quiet and not as_json:
        for path in (output, plot):
            if path is not None:
                click.echo(f"wrote {path}", err=output is None and yaml is not None)


# ----------------------------------------------------------------------------- store
#: The store's folder when --store is not given: $FIELDCAL_STORE, else ./fieldcal-store.
_STORE_ENV = "FIELDCAL_STORE"


def _store_option(f: _Command) -> _Command:
    decorated: _Command = click.option(
        "--store",
        "store_dir",
        help=f"The store's folder [default: ${_STORE_ENV}, else ./fieldcal-store].",
    )(f)
    return decorated


def _open_store(store_dir: str | None) -> Any:
    folder = store_dir or os.environ.get(_STORE_ENV) or "fieldcal-store"
    return _lazy(".store").Store(folder)


@cli.group()
def store() -> None:
    """Calibrations over time: a folder of calibration files by device and date."""


@store.command("add")
@click.argument("cal_json", type=click.Path())
@click.option("--device", help="The device's id (letters, digits, . _ -) [default: from the file].")
@_store_option
def store_add(cal_json: str, device: str | None, store_dir: str | None) -> None:
    """Keep CAL_JSON in the store under its device and date."""
    cal = _read_cal(cal_json)
    device = device or cal.options.get("device")
    if not device:
        raise InputError(f"{cal_json}: no device id in the file; give --device ID")
    path = _open_store(store_dir).add(cal, device=device)
    click.echo(f"stored {cal_json} as {path}")


@store.command("list")
@click.argument("device", required=False)
@_store_option
def store_list(device: str | None, store_dir: str | None) -> None:
    """The devices and how many calibrations each has; with DEVICE, its calibrations."""
    opened = _open_store(store_dir)
    if device is None:
        for name in opened.devices():
            entries = opened.entries(name)
            click.echo(
                f"{name}: {len(entries)} calibration(s), latest {entries[-1].created:%Y-%m-%d}"
            )
        return
    rows = opened.drift(device)
    _console().print(_lazy(".output.drift").drift_table(rows))


@store.command("drift")
@click.argument("device")
@click.option(
    "--sigmas",
    type=_POSITIVE,
    default=3.0,
    show_default=True,
    help="A change is flagged beyond this many combined standard errors.",
)
@click.option("--plot", help="Also draw every parameter against time (.png).")
@_store_option
@_force
def store_drift(
    device: str, sigmas: float, plot: str | None, store_dir: str | None, force: bool
) -> None:
    """Every calibration of DEVICE against the one before: the parameters that changed
    beyond their uncertainty; --plot draws them over time with error bars."""
    _claim([plot], {}, force)
    rows = _open_store(store_dir).drift(device, sigmas=sigmas)
    drift = _lazy(".output.drift")
    _console().print(drift.drift_table(rows))
    if plot is not None:
        figure = drift.drift_figure(rows)
        with _files.replacing(plot) as temp:
            figure.savefig(temp, format="png", dpi=90)
        click.echo(f"wrote {plot}")


# ----------------------------------------------------------------------------- batch
#: Failures listed by name at the end of a batch; the rest are counted (all are in the summary).
_BATCH_SHOWN = 50


def _batch_options(opts: _ParsedOptions) -> dict[str, Any]:
    """:func:`fieldcal.calibrate_many`'s keywords from the command's options: the reading
    options as :func:`_load` passes them, the rest as :func:`_run_calibration` does."""
    reading = {
        k: v
        for k in _LogOptions.__annotations__
        if (v := opts.get(k)) is not None and v is not False
    }
    return {**reading, **_run_options(opts)}


@contextmanager
def _batch_bar(quiet: bool, total: int) -> Iterator[Callable[[Any], None]]:
    """A progress bar on stderr (logs done, logs/s, time left), or nothing: off with
    ``--quiet`` and when stderr is not a terminal."""
    stream = sys.stderr
    if quiet or stream is None or not stream.isatty():
        yield lambda row: None
        return
    rich_progress = _lazy("rich.progress")
    bar = rich_progress.Progress(
        rich_progress.TextColumn("calibrating"),
        rich_progress.BarColumn(),
        rich_progress.MofNCompleteColumn(),
        rich_progress.TextColumn("{task.fields[rate]}"),
        rich_progress.TextColumn("ETA"),
        rich_progress.TimeRemainingColumn(),
        console=_console(stderr=True),
    )
    started = time.perf_counter()
    with bar:
        task = bar.add_task("batch", total=total, rate="")

        def advance(row: Any) -> None:
            done = bar.tasks[0].completed + 1
            rate = done / max(time.perf_counter() - started, 1e-9)
            bar.update(task, advance=1, rate=f"{rate:.3g} logs/s")

        yield advance


@cli.command()
@click.argument("logs", nargs=-1, required=True)
@click.option(
    "--out",
    "out_dir",
    required=True,
    help="Folder for <device>/cal.json (and exports) and summary.parquet / summary.csv.",
)
@_fit_options
@_POSES_OPTION
@_log_options
@_detect_options
@click.option(
    "--export",
    "export_names",
    multiple=True,
    type=click.Choice(list(exports.FORMATS)),
    help="Also write this format beside each cal.json (repeat for more): cal.h, cal.parm, ...",
)
@click.option("--jobs", "-j", type=click.IntRange(1), help="Worker processes. [default: the cores]")
@click.option(
    "--scheduler",
    envvar="DASK_SCHEDULER_ADDRESS",
    help="Run on this Dask cluster (tcp://HOST:PORT; default: $DASK_SCHEDULER_ADDRESS): the "
    "workers read the logs from a shared path or fsspec URL and write into --out.",
)
@click.option("--resume", is_flag=True, help="Skip the logs whose results --out already holds.")
@click.option("--quiet", "-q", is_flag=True, help="Print only errors and the failures.")
@_force
def batch(
    logs: tuple[str, ...],
    out_dir: str,
    export_names: tuple[str, ...],
    jobs: int | None,
    scheduler: str | None,
    resume: bool,
    quiet: bool,
    force: bool,
    pose_noise: str,
    **opts: Unpack[_CalibrateOptions],
) -> None:
    """Calibrate every LOG on its own (files, globs, fsspec URLs, manifest .csv files) and
    write one summary table.

    Each log's results go to OUT/<device>/cal.json; OUT/summary.parquet and summary.csv
    hold one row per log (verdict, reasons, dip, gains and biases with their errors, error).
    A log that fails never stops the batch. Exit code 3 when any log fails.
    """
    options: _ParsedOptions = {**opts, "pose_noise": _parse_pose_noise(pose_noise)}
    _parse_noise(opts.get("noise"))
    _check_reference(options)
    many = _lazy(".batch")
    specs = _lazy(".batch.manifest").expand_logs(logs)
    started = time.perf_counter()
    try:
        with _batch_bar(quiet, len(specs)) as advance:
            result = many.calibrate_many(
                specs,
                out=out_dir,
                jobs=jobs,
                scheduler=scheduler or None,
                exports=export_names,
                resume=resume,
                force=force,
                keep_calibrations=False,
                on_result=advance,
                **_batch_options(options),
            )
    except KeyboardInterrupt:
        click.echo(
            f"Interrupted; the logs finished are kept in {out_dir} (summary.csv lists them); "
            "run the same command with --resume to calibrate the rest",
            err=True,
        )
        click.get_current_context().exit(EXIT_INTERRUPTED)
    seconds = time.perf_counter() - started
    rows = result.rows
    failures = result.failed
    console = _console()
    if not quiet:
        levels = [r["verdict"] for r in rows]
        errors = sum(1 for r in rows if r["error"])
        console.print(
            f"calibrated {len(rows)} log(s) in {seconds:.1f} s "
            f"({len(rows) / max(seconds, 1e-9):.3g} logs/s): {levels.count('pass')} pass, "
            f"{levels.count('warn')} warn, {levels.count('fail')} fail"
            + (f" ({errors} with an error)" if errors else "")
            + (f"; {result.resumed} kept from an earlier batch" if result.resumed else "")
        )
        console.print("wrote " + ", ".join(str(p) for p in result.files))
    if failures:
        console.print(f"failed ({len(failures)}):")
        for row in failures[:_BATCH_SHOWN]:
            why = row["error"] or row["reasons"] or "verdict fail"
            console.print(f"  {row['device']} ({row['log']}): {why}")
        if len(failures) > _BATCH_SHOWN:
            console.print(
                f"  ... and {len(failures) - _BATCH_SHOWN} more: the rows with verdict fail "
                "in the summary"
            )
        click.get_current_context().exit(EXIT_FAIL)


# ----------------------------------------------------------------------------- demo
def _deltas(session: Session, cal: Calibration, n_found: int) -> dict[str, float | None]:
    """δ of Eq. 19 per sensor, when the poses found are the simulated ones."""
    truth = session.truth
    if n_found != truth.n_poses or truth.accel is None or truth.mag is None:
        return {"accel": None, "mag": None}
    true_a, true_m = truth.predicted_means()
    est_a, est_m = cal.predicted_means()
    if true_a is None or true_m is None or est_a is None or est_m is None:
        return {"accel": None, "mag": None}
    counts = session.counts
    return {
        "accel": reconstruction_error(true_a, est_a, truth.accel.noise_cov, counts),
        "mag": reconstruction_error(true_m, est_m, truth.mag.noise_cov, counts),
    }


@cli.command()
@click.option(
    "--seed", type=click.IntRange(min=0), default=1, show_default=True, help="Random seed."
)
@click.option("--out", "out_dir", help="Folder for session.csv, cal.json and report.html.")
@click.option("--no-report", is_flag=True, help="Skip the HTML report.")
@_force
def demo(seed: int, out_dir: str | None, no_report: bool, force: bool) -> None:
    """Simulate a Table 1 session as a continuous log, find its poses, calibrate, compare."""
    with_report = not no_report and importlib.util.find_spec("matplotlib") is not None
    if out_dir:
        names = ["session.csv", "cal.json"] + (["report.html"] if with_report else [])
        _claim([Path(out_dir) / name for name in names], {}, force, folders_made=True)
    load_log = _lazy(".logs").load_log
    summary = _lazy(".output.summary")
    console = _console()
    started = time.perf_counter()
    folder = Path(out_dir) if out_dir else Path(tempfile.mkdtemp(prefix="fieldcal-demo-"))
    folder.mkdir(parents=True, exist_ok=True)
    sim = _lazy(".simulation.continuous").simulate_continuous("paper", seed=seed)
    log_path = folder / "session.csv"
    with _files.replacing(log_path) as temp:
        sim.write_csv(str(temp))
    console.print(
        f"simulated a session of the seed paper's Table 1 as a continuous log: "
        f"{sim.session.truth.n_poses} poses, "
        f"{len(sim.columns['t'])} samples at {sim.rate:g} Hz -> {log_path}"
    )
    with _progress(False) as progress:
        cal, poses, doc, notes = _run_calibration(load_log(log_path), {}, progress)
    _write_json(folder / "cal.json", doc)
    summary.print_summary(console, cal, doc, notes)
    summary.print_truth_comparison(
        console, sim.session.truth, cal, _deltas(sim.session, cal, poses.n)
    )
    if not no_report and not with_report:
        console.print(
            "matplotlib is not installed: skipped the report (pip install 'fieldcal[plot]')"
        )
    elif with_report:
        with _progress(False) as progress:
            if progress is not None:
                progress("drawing the report")
            _lazy(".output.report").write_report(cal, load_log(log_path), folder / "report.html")
        console.print(f"report: {folder / 'report.html'}")
    console.print(f"done in {time.perf_counter() - started:.1f} s; files in {folder}")
    _finish(cal, summary_shown=True)


if __name__ == "__main__":  # pragma: no cover
    main()
