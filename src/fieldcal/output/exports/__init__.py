"""The exports registry: one table of formats (name → writer, suffix, formula), one module each.

fieldcal's correction is ``v = inv(gain) @ (raw − bias)`` on column vectors. Every format
writes the same numbers in its target's convention and states its formula in the text. The
CLI's ``--format`` choices, :func:`export`'s validation and the formats table of
``docs/cli.md`` (:func:`markdown_table`) come from :data:`FORMATS`.

To add a format: write ``exports/<name>.py`` with ``write(cal) -> str``, ``FORMULA`` and
``CONTENT``, and add one :class:`ExportFormat` to :data:`FORMATS`. A binary format (``mat``)
also gives ``binary``, ``(Calibration) -> bytes``; its ``write`` refuses in one line, and
:func:`export_bytes` is the file's content for every format.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import PurePath

from ...calibration import Calibration
from . import ardupilot, c_header, document, kalibr, magneto, mat_file, matlab, px4

__all__ = [
    "DEFAULT",
    "FORMATS",
    "ExportFormat",
    "export",
    "export_bytes",
    "for_path",
    "get",
    "markdown_table",
]


@dataclass(frozen=True)
class ExportFormat:
    """One export format.

    Attributes
    ----------
    name : str
        The registry name (``--format`` on the command line, ``fmt`` of :func:`export`).
    write : callable
        ``(Calibration) -> str``: the calibration as text in this format.
    suffix : str
        The file suffix, with its dot (``".h"``).
    formula : str
        The correction as the format applies it, word for word as the text states it.
    content : str
        One line (Markdown) on what the text defines, for the docs.
    binary : callable or None
        ``(Calibration) -> bytes`` for a binary format (whose ``write`` refuses); ``None`` for
        text.
    """

    name: str
    write: Callable[[Calibration], str]
    suffix: str
    formula: str
    content: str
    binary: Callable[[Calibration], bytes] | None = None


FORMATS: dict[str, ExportFormat] = {
    f.name: f
    for f in (
        ExportFormat("c-header", c_header.write, ".h", c_header.FORMULA, c_header.CONTENT),
        ExportFormat("matlab", matlab.write, ".m", matlab.FORMULA, matlab.CONTENT),
        ExportFormat("magneto", magneto.write, ".txt", magneto.FORMULA, magneto.CONTENT),
        ExportFormat("json", document.write, ".json", document.FORMULA, document.CONTENT),
        ExportFormat("ardupilot", ardupilot.write, ".parm", ardupilot.FORMULA, ardupilot.CONTENT),
        ExportFormat("px4", px4.write, ".params", px4.FORMULA, px4.CONTENT),
        ExportFormat(
            "mat",
            mat_file.write,
            ".mat",
            mat_file.FORMULA,
            mat_file.CONTENT,
            binary=mat_file.write_bytes,
        ),
        ExportFormat("kalibr", kalibr.write, ".yaml", kalibr.FORMULA, kalibr.CONTENT),
    )
}

#: The format written when neither a name nor a known file suffix says which.
DEFAULT = "c-header"


def get(name: object) -> ExportFormat:
    """The registered format called ``name``; a one-line ``ValueError`` listing the names.

    Parameters
    ----------
    name : str

    Returns
    -------
    ExportFormat
    """
    if not isinstance(name, str) or name not in FORMATS:
        raise ValueError(f"unknown export format {name!r}; choose one of {', '.join(FORMATS)}")
    return FORMATS[name]


def for_path(path: str | PurePath) -> ExportFormat | None:
    """The format whose suffix ``path`` has (case-insensitive), or ``None``.

    Parameters
    ----------
    path : str or path

    Returns
    -------
    ExportFormat or None
    """
    suffix = PurePath(path).suffix.lower()
    return next((f for f in FORMATS.values() if f.suffix == suffix), None)


def export(cal: Calibration, fmt: str) -> str:
    """The calibration as text in format ``fmt``.

    Parameters
    ----------
    cal : Calibration
    fmt : str
        A name in :data:`FORMATS`; another is a ``ValueError`` listing them.

    Returns
    -------
    str
        The text, its convention and formula stated in it.
    """
    return get(fmt).write(cal)


def export_bytes(cal: Calibration, fmt: str) -> bytes:
    """The file's content in format ``fmt``: the binary writer's bytes, or the text in UTF-8.

    Parameters
    ----------
    cal : Calibration
    fmt : str
        A name in :data:`FORMATS`; another is a ``ValueError`` listing them.

    Returns
    -------
    bytes
        What ``fieldcal export -o`` writes (text ends with a newline).
    """
    f = get(fmt)
    if f.binary is not None:
        return f.binary(cal)
    text = f.write(cal)
    return (text if text.endswith("\n") else text + "\n").encode("utf-8")


def markdown_table() -> str:
    """The formats table of ``docs/cli.md``, from the registry.

    Returns
    -------
    str
        A Markdown table: format, suffix, content, formula; one row per format.
    """
    rows = ["| format | suffix | content | formula |", "|---|---|---|---|"]
    rows += [
        f"| `{f.name}` | `{f.suffix}` | {f.content} | `{f.formula}` |" for f in FORMATS.values()
    ]
    return "\n".join(rows)
