"""The exports registry: one table of formats (name → writer, suffix, formula), one module each.

fieldcal's correction is ``v = inv(gain) @ (raw − bias)`` on column vectors. Every format
writes the same numbers in its target's convention and states its formula in the text. The
CLI's ``--format`` choices, :func:`export`'s validation and the formats table of
``docs/cli.md`` (:func:`markdown_table`) come from :data:`FORMATS`.

To add a format: write ``exports/<name>.py`` with ``write(cal) -> str``, ``FORMULA`` and
``CONTENT``, and add one :class:`ExportFormat` to :data:`FORMATS`. A binary format (``mat``)
also gives ``binary``, ``(Calibration) -> bytes``; its ``write`` refuses in one line, and
:func:`export_bytes` is the file's content for every format. A format of several files
(``c-library``) gives ``files``, ``(Calibration) -> {file name: text}``, written into a folder
(:func:`export_files`). A format's keyword options (``sysid``, ``allow_out_of_range``) are
listed in ``options``; :func:`export` refuses any other in one line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import PurePath

from ...calibration import Calibration
from ...errors import InputError
from . import ardupilot, c_header, c_library, document, kalibr, magneto, mat_file, matlab, px4

__all__ = [
    "DEFAULT",
    "FORMATS",
    "ExportFormat",
    "export",
    "export_bytes",
    "export_files",
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
    options : tuple of str
        The keyword options ``write`` (and ``files``) take.
    files : callable or None
        ``(Calibration) -> {file name: text}`` for a format of several files, written into a
        folder (whose ``write`` refuses); ``None`` for one file.
    """

    name: str
    write: Callable[..., str]
    suffix: str
    formula: str
    content: str
    binary: Callable[[Calibration], bytes] | None = None
    options: tuple[str, ...] = ()
    files: Callable[..., dict[str, str]] | None = None


FORMATS: dict[str, ExportFormat] = {
    f.name: f
    for f in (
        ExportFormat("c-header", c_header.write, ".h", c_header.FORMULA, c_header.CONTENT),
        ExportFormat("matlab", matlab.write, ".m", matlab.FORMULA, matlab.CONTENT),
        ExportFormat("magneto", magneto.write, ".txt", magneto.FORMULA, magneto.CONTENT),
        ExportFormat("json", document.write, ".json", document.FORMULA, document.CONTENT),
        ExportFormat(
            "ardupilot",
            ardupilot.write,
            ".parm",
            ardupilot.FORMULA,
            ardupilot.CONTENT,
            options=("allow_out_of_range",),
        ),
        ExportFormat(
            "px4",
            px4.write,
            ".params",
            px4.FORMULA,
            px4.CONTENT,
            options=("sysid", "compid", "allow_out_of_range"),
        ),
        ExportFormat(
            "mat",
            mat_file.write,
            ".mat",
            mat_file.FORMULA,
            mat_file.CONTENT,
            binary=mat_file.write_bytes,
        ),
        ExportFormat("kalibr", kalibr.write, ".yaml", kalibr.FORMULA, kalibr.CONTENT),
        ExportFormat(
            "openvins", kalibr.write_openvins, ".yaml", kalibr.FORMULA, kalibr.OPENVINS_CONTENT
        ),
        ExportFormat(
            "c-library",
            c_library.write,
            "",
            c_library.FORMULA,
            c_library.CONTENT,
            options=("sensor_id",),
            files=c_library.files,
        ),
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
    return next((f for f in FORMATS.values() if f.suffix and f.suffix == suffix), None)


def _format(fmt: str, options: dict[str, object]) -> ExportFormat:
    """The format, after refusing options it does not take (one line naming those it does)."""
    f = get(fmt)
    unknown = sorted(set(options) - set(f.options))
    if unknown:
        takes = ", ".join(f.options) if f.options else "none"
        raise InputError(
            f"the {f.name} export does not take {', '.join(unknown)} (its options: {takes})"
        )
    return f


def export(cal: Calibration, fmt: str, **options: object) -> str:
    """The calibration as text in format ``fmt``.

    Parameters
    ----------
    cal : Calibration
    fmt : str
        A name in :data:`FORMATS`; another is a ``ValueError`` listing them.
    **options
        The format's keyword options (``ExportFormat.options``), e.g. ``sysid=2`` for ``px4``,
        ``allow_out_of_range=True`` for ``ardupilot`` and ``px4``; another is refused.

    Returns
    -------
    str
        The text, its convention and formula stated in it.
    """
    return _format(fmt, options).write(cal, **options)


def export_bytes(cal: Calibration, fmt: str, **options: object) -> bytes:
    """The file's content in format ``fmt``: the binary writer's bytes, or the text in UTF-8.

    Parameters
    ----------
    cal : Calibration
    fmt : str
        A name in :data:`FORMATS`; another is a ``ValueError`` listing them.
    **options
        As :func:`export`.

    Returns
    -------
    bytes
        What ``fieldcal export -o`` writes (text ends with a newline).
    """
    f = _format(fmt, options)
    if f.binary is not None:
        return f.binary(cal)
    text = f.write(cal, **options)
    return (text if text.endswith("\n") else text + "\n").encode("utf-8")


def export_files(cal: Calibration, fmt: str, **options: object) -> dict[str, bytes]:
    """The files of a format written into a folder (``c-library``): name -> content.

    Parameters
    ----------
    cal : Calibration
    fmt : str
        A name in :data:`FORMATS` whose entry has ``files``; another is refused in one line.
    **options
        As :func:`export`.

    Returns
    -------
    dict of str to bytes
        File names (no folders) and their UTF-8 content.
    """
    f = _format(fmt, options)
    if f.files is None:
        raise InputError(f"the {f.name} export is one file, not a folder; use -o FILE")
    return {name: text.encode("utf-8") for name, text in f.files(cal, **options).items()}


def markdown_table() -> str:
    """The formats table of ``docs/cli.md``, from the registry.

    Returns
    -------
    str
        A Markdown table: format, suffix, content, formula; one row per format.
    """
    rows = ["| format | suffix | content | formula |", "|---|---|---|---|"]
    rows += [
        f"| `{f.name}` | {f'`{f.suffix}`' if f.suffix else 'folder'} | {f.content} | "
        f"`{f.formula}` |"
        for f in FORMATS.values()
    ]
    return "\n".join(rows)
