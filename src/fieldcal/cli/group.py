"""The ``fieldcal`` group: its one error path, exit codes, the console every command prints
through, and the helpers every command shares (outputs checked before work, progress, the
calibration file read, the fail exit).

Exit codes: 0 success; 1 a bug in fieldcal (one line asking for a report; ``FIELDCAL_DEBUG=1``
shows the traceback); 2 a mistake in the user's input (file, columns, options, too few or
degenerate poses, an output that exists or is an input), reported as one ``Error: ...`` line on
stderr, never a traceback; 3 the calibration's verdict is ``fail`` (every requested file is
still written); 130 interrupted (Ctrl-C): one line saying which files were completed.

Files: every output is checked before any work (never an input of the command, compared by
file identity; an existing file only with ``--force``) and written atomically
(:mod:`fieldcal._files`), so an error or an interrupt leaves the old file or the new one.
"""

from __future__ import annotations

import csv
import importlib
import importlib.util
import os
import signal
import sys
import threading
import warnings
import zipfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, TypeVar

import click
import numpy as np

from .. import _files
from .._version import __version__
from ..errors import InputError
from . import library

if TYPE_CHECKING:
    from rich.console import Console

    from ..calibration import Calibration

__all__ = [
    "EXIT_BUG",
    "EXIT_FAIL",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_USAGE",
    "Command",
    "Progress",
    "check_matplotlib",
    "claim",
    "cli",
    "finish",
    "force_option",
    "main",
    "one_line",
    "open_console",
    "progress_line",
    "read_cal",
    "write_json",
]

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

#: A command function, as click's decorators take and return it.
Command = TypeVar("Command", bound=Callable[..., object])
#: What the commands pass to the library for progress: one line of text, or nothing.
Progress = Callable[[str], None] | None


def open_console(*, stderr: bool = False) -> Console:
    """The console every command prints through: user text (paths, column names, labels,
    reasons) is printed literally, never read as markup or emoji codes."""
    return library.Console(
        stderr=stderr, markup=False, emoji=False, highlight=False, soft_wrap=True
    )


def _debug() -> bool:
    return os.environ.get(_DEBUG, "").strip() not in ("", "0")


def one_line(text: str) -> str:
    return " ".join(text.split())


class _UsageError(click.ClickException):
    """A usage error shown as one ``Error: ...`` line (click's adds the usage block)."""

    exit_code = EXIT_USAGE

    @classmethod
    def of(cls, exc: click.UsageError) -> _UsageError:
        where = exc.ctx.command_path if exc.ctx is not None else "fieldcal"
        return cls(f"{one_line(exc.format_message()).rstrip('.')}; see '{where} --help'")


def _user_message(exc: BaseException) -> str:
    if isinstance(exc, MemoryError):
        return "not enough memory for this input; give a smaller log (apply streams CSV files)"
    message = one_line(str(exc)) or type(exc).__name__
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
        text = f"warning: {one_line(str(w.message))}"
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

    #: The command modules, one per family (each adds its commands to the group when imported),
    #: imported when a command is first looked up or listed: ``--version`` needs none of them.
    command_modules = (
        "calibrate_cmd",
        "capture_cmd",
        "noise_cmd",
        "store_cmd",
        "batch_cmd",
        "demo_cmd",
        "info_cmd",
    )
    _loading = False

    @property  # type: ignore[override]  # click declares a plain attribute
    def commands(self) -> dict[str, click.Command]:
        """The group's commands, their modules imported on first access."""
        if not self._loading:
            self._loading = True
            for name in self.command_modules:
                importlib.import_module(f".{name}", __package__)
        return self._commands

    @commands.setter
    def commands(self, value: dict[str, click.Command]) -> None:
        self._commands = value

    def make_context(
        self,
        info_name: str | None,
        args: list[str],
        parent: click.Context | None = None,
        **extra: object,
    ) -> click.Context:
        try:
            return super().make_context(info_name, args, parent, **extra)
        except click.exceptions.NoArgsIsHelpError:
            raise  # `fieldcal` alone prints the help
        except click.UsageError as exc:
            raise _UsageError.of(exc) from None

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """Each command with its whole summary (the help's first paragraph), wrapped, not cut
        at click's 45 characters."""
        rows = []
        for name in self.list_commands(ctx):
            command = self.get_command(ctx, name)
            if command is None or command.hidden:
                continue
            text = command.short_help or (command.help or "").split("\n\n", 1)[0]
            rows.append((name, one_line(text)))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

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
            except KeyboardInterrupt as exc:
                wrote = ", ".join(str(p) for p in done)
                click.echo(
                    f"Interrupted; completed {wrote}; nothing else was written"
                    if done
                    else "Interrupted; nothing was written",
                    err=True,
                )
                ctx.exit(exc.code if isinstance(exc, Terminated) else EXIT_INTERRUPTED)
            except _USER_ERRORS as exc:
                click.echo(f"Error: {_user_message(exc)}", err=True)
                ctx.exit(EXIT_USAGE)
            except Exception as exc:
                message = one_line(str(exc))
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
    """Calibrate an IMU's accelerometer, magnetometer and gyroscope together, by maximum
    likelihood, from a log of rests, hand-held motion or a flight.

    Start with `fieldcal demo`, then `fieldcal calibrate LOG -o cal.json`.
    """


class Terminated(KeyboardInterrupt):
    """A kill (SIGTERM) unwinding like Ctrl-C: temporary files are removed on the way out;
    exit code 128 + 15, as shells report it."""

    code = 128 + signal.SIGTERM


def _terminate(signum: int, frame: FrameType | None) -> None:
    raise Terminated


def main() -> None:
    """Console-script entry point."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _terminate)
    cli(prog_name="fieldcal")


def force_option(f: Command) -> Command:
    decorated: Command = click.option(
        "--force",
        is_flag=True,
        help="Replace output files that exist (never an input of the command).",
    )(f)
    return decorated


def claim(
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
def progress_line(quiet: bool) -> Iterator[Progress]:
    """A status line on stderr showing the library's progress messages, or ``None``: off
    with ``--quiet`` and when stderr is not a terminal (a pipe, a file, a test)."""
    stream = sys.stderr
    if quiet or stream is None or not stream.isatty():
        yield None
        return
    text = library.Text
    status = open_console(stderr=True).status(text("working"), spinner="dots")
    with status:
        yield lambda line: status.update(text(one_line(line)))


def read_cal(path: str) -> Calibration:
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
    if not text.lstrip("\ufeff \t\r\n").startswith("{"):
        first = one_line(text.lstrip().split("\n", 1)[0])[:60]
        raise InputError(
            f"{path}: is not a calibration JSON (its first line is {first!r}); give the JSON "
            "`fieldcal calibrate` wrote"
        )
    return library.Calibration.from_json(text)


def finish(cal: Calibration, *, summary_shown: bool) -> None:
    """Exit with code 3 when the verdict is fail; say why on stderr if the summary did not."""
    if cal.verdict is None or cal.verdict.level != "fail":
        return
    if not summary_shown:
        library.print_verdict(open_console(stderr=True), cal)
    click.get_current_context().exit(EXIT_FAIL)


def write_json(path: str | Path, doc: dict[str, object]) -> None:
    """``doc`` as indented JSON (a matrix row a line, as ``cal.json``), written atomically."""
    _files.write_text(path, library.dumps(doc) + "\n")


def check_matplotlib() -> None:
    """Refuse a figure in one line before any work when matplotlib is not installed."""
    if importlib.util.find_spec("matplotlib") is None:
        raise InputError(
            "the report needs matplotlib, which is not installed; pip install 'fieldcal[plot]'"
        )
