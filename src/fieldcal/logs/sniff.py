"""What a file that is not a log looks like, for the message that refuses it.

A text log that does not parse is most often another file given by mistake: the calibration
JSON (``fieldcal apply`` with its arguments swapped), a Markdown note, an HTML report, or a
binary file. Called only once the file was refused, so a guess costs nothing when it is a log.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

__all__ = ["is_calibration_json", "not_a_log"]

#: Leading bytes of binary formats a user may give instead of a log, and what they are.
_MAGIC = (
    (b"ULog", "a PX4 ULog flight log", "convert it to CSV first (pyulog's ulog2csv)"),
    (b"#ROSBAG", "a ROS 1 bag", "give it the .bag suffix"),
    (b"PAR1", "a Parquet file", "give it the .parquet suffix"),
    (b"PK\x03\x04", "a zip archive", "give an .npz its suffix; export a spreadsheet as CSV"),
    (b"\x93NUMPY", "a NumPy .npy array", "save the columns by name with numpy.savez (.npz)"),
    (b"\x89PNG", "a PNG image", "give the log file"),
    (b"%PDF", "a PDF document", "give the log file"),
    (b"\x1f\x8b", "a gzip archive", "decompress it first"),
    (b"SQLite format 3", "an SQLite database", "export the table as CSV"),
)
#: A Markdown table's separator row (``|---|:--:|``) or a fenced code block.
_MARKDOWN = re.compile(r"^\s*(\|?\s*:?-{3,}:?\s*\|[\s|:-]*|```.*)$")
#: A heading line (``# Title``, ``## Setup``) with no delimiter (``# t,ax`` is a header).
_HEADING = re.compile(r"^#{1,6}\s+[^,;\t]+$")
#: A line of prose: four or more words, no delimiter, not a comment.
_PROSE = re.compile(r"^[^#,;\t|][^,;\t|]*(\s+\S+){3,}\s*$")
#: A data line: numbers separated by a delimiter.
_NUMBERS = re.compile(r"^\s*[-+.\d]+([eE][-+]?\d+)?(\s*[,;\t ]\s*[-+.\deE]+){2,}\s*$")
#: Keys only a calibration file has together.
_CALIBRATION_KEYS = {"accel", "mag", "verdict", "accuracy", "schema_version", "fieldcal"}


def _head(path: Path, size: int = 65536) -> bytes:
    try:
        with path.open("rb") as f:
            return f.read(size)
    except OSError:
        return b""


def is_calibration_json(path: str | Path) -> bool:
    """Whether ``path`` holds a JSON object with a calibration's keys (``accel``,
    ``verdict`` ...)."""
    head = _head(Path(path), 1 << 22).decode("utf-8", errors="replace").lstrip("\ufeff \t\r\n")
    if not head.startswith("{"):
        return False
    try:
        doc = json.loads(head)
    except ValueError:
        # a long file cut short: its keys are still plain to see
        return sum(f'"{key}"' in head for key in _CALIBRATION_KEYS) >= 2
    return isinstance(doc, dict) and len(_CALIBRATION_KEYS & set(doc)) >= 2


def not_a_log(path: str | Path) -> str | None:
    """One line saying what ``path`` looks like when it is plainly not a log (a calibration
    JSON, another JSON document, Markdown, HTML, a known binary format), with the fix;
    ``None`` when it could be a log with a mistake in it."""
    path = Path(path)
    raw = _head(path)
    for magic, what, fix in _MAGIC:
        if raw.startswith(magic):
            return f"{path}: is {what}, not a CSV log; {fix}"
    if b"\x00" in raw:
        return (
            f"{path}: not a text file (binary, no known format); give a CSV with a header "
            "line, .npz or .parquet"
        )
    text = raw.decode("utf-8", errors="replace").lstrip("\ufeff \t\r\n")
    if is_calibration_json(path):
        return (
            f"{path}: is a calibration JSON (what fieldcal calibrate writes), not a log; give "
            "the log (CSV, .npz, .parquet); to correct a log with it: fieldcal apply CAL_JSON "
            "LOG -o OUT"
        )
    if text.startswith(("{", "[")):
        return (
            f"{path}: is a JSON document, not a CSV log; give the readings as a CSV with a "
            "header line (or .npz / .parquet)"
        )
    if text[:200].lower().startswith(("<!doctype html", "<html", "<?xml")):
        return f"{path}: is an HTML or XML page, not a CSV log; give the log itself"
    lines = text.splitlines()[:200]
    numbers = sum(bool(_NUMBERS.match(line)) for line in lines)
    marks = sum(bool(_MARKDOWN.match(line)) for line in lines)
    headings = sum(bool(_HEADING.match(line)) for line in lines)
    prose = sum(bool(_PROSE.match(line)) for line in lines)
    # a CSV's "# units: g" comment is no heading: Markdown shows tables, fences or prose too
    if numbers < 3 and (marks or (headings and prose)):
        return (
            f"{path}: looks like Markdown (headings, tables or code fences) with no rows of "
            "numbers, not a CSV log; give the log file (a header line, then one row of "
            "readings a line)"
        )
    return None
