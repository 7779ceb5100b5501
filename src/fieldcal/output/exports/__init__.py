"""The exports registry: one table of formats (name → writer, suffix, formula), one module each.

fieldcal's correction is ``v = inv(gain) @ (raw − bias)`` on column vectors. Every format
writes the same numbers in its target's convention and states its formula in the text. The
CLI's ``--format`` choices, :func:`export`'s validation and the formats table of
``docs/cli.md`` (:func:`markdown_table`) come from :data:`FORMATS`.

To add a format: write ``exports/<name>.py`` with ``write(cal) -> str``, ``FORMULA`` and
``CONTENT``, and add one :class:`ExportFormat` to :data:`FORMATS`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import PurePath

from ...calibration import Calibration
from . import c_header, document, magneto, matlab

__all__ = ["DEFAULT", "FORMATS", "ExportFormat", "export", "for_path", "get", "markdown_table"]


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
    """

    name: str
    write: Callable[[Calibration], str]
    suffix: str
    formula: str
    content: str


FORMATS: dict[str, ExportFormat] = {
    f.name: f
    for f in (
        ExportFormat("c-header", c_header.write, ".h", c_header.FORMULA, c_header.CONTENT),
        ExportFormat("matlab", matlab.write, ".m", matlab.FORMULA, matlab.CONTENT),
        ExportFormat("magneto", magneto.write, ".txt", magneto.FORMULA, magneto.CONTENT),
        ExportFormat("json", document.write, ".json", document.FORMULA, document.CONTENT),
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
