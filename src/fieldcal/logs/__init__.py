"""From a log file to poses: readers (by suffix), column recognition, still detection, pose
grouping, streaming apply.

The names most callers need are re-exported here: :func:`load_log`, :class:`Log`,
:func:`sample_rate`, :func:`read_table`, :func:`recognise_columns`, :func:`apply_to_file`,
:func:`poses_from_log` (still intervals, a pose column or windows), :func:`turns_slowly`.
"""

from __future__ import annotations

from ..geometry.frames import parse_axes
from .apply import apply_to_file
from .columns import recognise_columns
from .log import Log, load_log, sample_rate
from .pose_finding import PoseSet, WindowCut, poses_from_log, turns_slowly
from .readers import Table, read_table

__all__ = [
    "Log",
    "PoseSet",
    "Table",
    "WindowCut",
    "apply_to_file",
    "load_log",
    "parse_axes",
    "poses_from_log",
    "read_table",
    "recognise_columns",
    "sample_rate",
    "turns_slowly",
]
