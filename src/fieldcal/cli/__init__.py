"""The ``fieldcal`` command: calibrate a log, apply and export the result, simulate, report,
capture live, plan poses, measure noise, keep calibrations over time, batch, demo.

Commands only: parse the options, call the library, print, choose the exit code. One module
per command family; :mod:`~fieldcal.cli.group` holds the group, its error path and exit codes
(0 ok, 1 a bug, 2 the user's input, 3 verdict fail, 130 interrupted) and the console;
:mod:`~fieldcal.cli.options` the options the commands share; :mod:`~fieldcal.cli.library` the
library's names, typed and imported on first use.

Startup: ``fieldcal --version`` loads numpy, click and the group only (the command modules load
when a command is first looked up); ``--help`` loads fieldcal's light modules too. Rich, the
pipeline and the output modules load inside the commands, through :mod:`~fieldcal.cli.library`;
SciPy and matplotlib load when a calibration or a report first needs them.
"""

from __future__ import annotations

import sys
from types import ModuleType

from .group import EXIT_BUG, EXIT_FAIL, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE, cli, main

__all__ = ["EXIT_BUG", "EXIT_FAIL", "EXIT_INTERRUPTED", "EXIT_OK", "EXIT_USAGE", "cli", "main"]


def __getattr__(name: str) -> tuple[ModuleType, ...]:
    """``COMMAND_MODULES``: the command modules, one per family, imported when the group's
    commands are first needed (``fieldcal --version`` imports none of them)."""
    if name != "COMMAND_MODULES":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    cli.commands  # noqa: B018  # imports the command modules
    return tuple(sys.modules[f"{__name__}.{m}"] for m in cli.command_modules)
