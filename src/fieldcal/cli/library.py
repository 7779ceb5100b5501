"""The library as the commands call it: typed names, each imported when first used.

``fieldcal --version`` and ``--help`` need neither rich nor the pipeline, the output modules or
SciPy; the commands reach them through this module (``library.run_log(...)``). For the type
checker every name below is the real one (imported under ``TYPE_CHECKING``), so ``mypy
--strict`` checks each call from the CLI into the library; at run time the module's
``__getattr__`` imports the name's module on first access (:data:`WHERE`), and reads the name
there on every access (a test's ``monkeypatch`` of the library module is seen).

To give the commands another library name: one import below and one entry in :data:`WHERE`
(``tests/cli/test_library.py`` checks that the two agree).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

#: Each name and the module that defines it (relative to ``fieldcal``, or a third-party one).
WHERE: dict[str, str] = {
    "Console": "rich.console",
    "Text": "rich.text",
    "Progress": "rich.progress",
    "BarColumn": "rich.progress",
    "MofNCompleteColumn": "rich.progress",
    "TextColumn": "rich.progress",
    "TimeRemainingColumn": "rich.progress",
    "Calibration": "..calibration",
    "load_log": "..logs",
    "FLIGHT_READERS": "..logs.readers",
    "regular_file": "..logs.readers",
    "info_lines": "..logs.flight",
    "check_pyarrow": "..logs.apply",
    "apply_to_file": "..logs.apply",
    "run_log": "..pipeline",
    "LogSettings": "..pipeline",
    "expected_field": "..reference",
    "simulate_continuous": "..simulation.continuous",
    "print_summary": "..output.terminal",
    "print_verdict": "..output.terminal",
    "print_noise": "..output.terminal",
    "print_truth_comparison": "..output.terminal",
    "FIGURES": "..output.report",
    "write_report": "..output.report",
    "write_noise_figure": "..output.noise_figures",
    "drift_table": "..output.drift",
    "drift_figure": "..output.drift",
    "Targets": "..planning.next_pose",
    "plan_poses": "..planning.next_pose",
    "predicted_line": "..planning.next_pose",
    "unreachable": "..planning.next_pose",
    "temperature_advice": "..planning.warmer_poses",
    "CaptureOptions": "..capture.live_session",
    "CaptureSession": "..capture.live_session",
    "run_capture": "..capture.live_session",
    "open_source": "..capture.feeds",
    "LiveView": "..capture.view",
    "PlainView": "..capture.view",
    "key_reader": "..capture.view",
    "characterise_noise": "..noise",
    "Store": "..store",
    "calibrate_many": "..batch",
    "expand_logs": "..batch.manifest",
    "dumps": "..serialize",
}

__all__ = [
    "FIGURES",
    "FLIGHT_READERS",
    "BarColumn",
    "Calibration",
    "CaptureOptions",
    "CaptureSession",
    "Console",
    "LiveView",
    "LogSettings",
    "MofNCompleteColumn",
    "PlainView",
    "Progress",
    "Store",
    "Targets",
    "Text",
    "TextColumn",
    "TimeRemainingColumn",
    "apply_to_file",
    "calibrate_many",
    "characterise_noise",
    "check_pyarrow",
    "drift_figure",
    "drift_table",
    "dumps",
    "expand_logs",
    "expected_field",
    "info_lines",
    "key_reader",
    "load_log",
    "open_source",
    "plan_poses",
    "predicted_line",
    "print_noise",
    "print_summary",
    "print_truth_comparison",
    "print_verdict",
    "regular_file",
    "run_capture",
    "run_log",
    "simulate_continuous",
    "temperature_advice",
    "unreachable",
    "write_noise_figure",
    "write_report",
]

if TYPE_CHECKING:
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
    )
    from rich.text import Text

    from ..batch import calibrate_many
    from ..batch.manifest import expand_logs
    from ..calibration import Calibration
    from ..capture.feeds import open_source
    from ..capture.live_session import CaptureOptions, CaptureSession, run_capture
    from ..capture.view import LiveView, PlainView, key_reader
    from ..logs import load_log
    from ..logs.apply import apply_to_file, check_pyarrow
    from ..logs.flight import info_lines
    from ..logs.readers import FLIGHT_READERS, regular_file
    from ..noise import characterise_noise
    from ..output.drift import drift_figure, drift_table
    from ..output.noise_figures import write_noise_figure
    from ..output.report import FIGURES, write_report
    from ..output.terminal import print_noise, print_summary, print_truth_comparison, print_verdict
    from ..pipeline import LogSettings, run_log
    from ..planning.next_pose import Targets, plan_poses, predicted_line, unreachable
    from ..planning.warmer_poses import temperature_advice
    from ..reference import expected_field
    from ..serialize import dumps
    from ..simulation.continuous import simulate_continuous
    from ..store import Store
else:

    def __getattr__(name: str) -> object:
        """The library name ``name``, its module imported on first use."""
        where = WHERE.get(name)
        if where is None:
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
        return getattr(importlib.import_module(where, __package__), name)
