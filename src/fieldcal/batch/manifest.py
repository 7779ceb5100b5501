"""Which logs a batch calibrates: paths, globs and manifests, each log with its device and
options.

A LOG argument is a path or an fsspec URL (``s3://bucket/unit7.csv``), a glob
(``logs/*.csv``; sorted, each match once) or a manifest: a ``.csv`` file whose header names a
``log`` column. A manifest's other columns are ``device`` (the id the results are filed
under) and per-log options named as the command's options (``accel-cols`` or
``accel_cols``, ``rate``, ``method``, ``no-robust``, ...); an empty cell takes the batch's
value. A relative log path in a manifest is relative to the manifest's folder.

The whole manifest is checked before any work: an unknown column, a bad value or an empty
``log`` cell is one :class:`~fieldcal.errors.InputError` naming the file, the row (as a text
editor numbers its lines) and the column.

The device id of a log is the manifest's ``device``, else the id the log's own metadata names
(read on the worker, :attr:`fieldcal.logs.Log.device`), else the file's stem; ids become
folder names as :mod:`fieldcal.store` allows them (letters, digits, ``.``, ``_``, ``-``).
"""

from __future__ import annotations

import csv
import functools
import glob
import importlib
import os
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from urllib.parse import urlparse

from ..errors import InputError
from ..methods import METHODS
from ..settings import OPTIONS, Option, parse
from ..store import valid_device

__all__ = [
    "OPTION_COLUMNS",
    "LogSpec",
    "check_devices",
    "device_id",
    "expand_logs",
    "fallback_device",
    "read_manifest",
]


@dataclass(frozen=True)
class LogSpec:
    """One log of a batch.

    Attributes
    ----------
    log : str
        The path or fsspec URL the worker reads (as given; a manifest's relative paths joined
        to its folder). It is also the log's key in the summary and for ``resume``.
    device : str or None
        The device id the manifest gives (checked as a folder name), else ``None``.
    options : dict
        Options for this log alone, as :func:`fieldcal.calibrate_many` keywords; they
        override the batch's.
    source : str
        Where the log was named, for messages: ``"argument"``, or ``"<manifest> row <n>"``.
    """

    log: str
    device: str | None = None
    options: dict[str, object] = field(default_factory=dict)
    source: str = "argument"


def _is_url(text: str) -> bool:
    return "://" in text


def fallback_device(log: str) -> str:
    """The device id a log gets when neither a manifest nor its metadata names one: its file
    stem, with characters a folder name may not hold replaced by ``_``.

    Parameters
    ----------
    log : str
        A path or URL.

    Returns
    -------
    str
    """
    name = PurePosixPath(urlparse(log).path).name if _is_url(log) else Path(log).name
    stem = name.split(".", 1)[0] if not name.startswith(".") else name.lstrip(".")
    return device_id(stem or "log")


def device_id(text: str) -> str:
    """A device id as a folder name: characters :mod:`fieldcal.store` does not allow in one
    (spaces, slashes, ...) become ``_``.

    Parameters
    ----------
    text : str
        An id as a log's metadata or file name gives it.

    Returns
    -------
    str
    """
    clean = re.sub(r"[^A-Za-z0-9._-]+", "_", text.strip()).lstrip("._-")[:100]
    return valid_device(clean or "log")


# ----------------------------------------------------------------------------- option columns
def _cell_parser(option: Option) -> Callable[[str], object]:
    """The parser of an option's cells: :func:`fieldcal.settings.parse`; a method's name is
    checked against the registry."""
    if option.name == "method":
        allowed = tuple(METHODS)

        def method(value: str) -> str:
            if value not in allowed:
                raise ValueError(f"give one of {', '.join(allowed)}")
            return value

        return method
    return functools.partial(parse, option)


#: The per-log option columns a manifest may have, one per command-line option of
#: :data:`fieldcal.settings.OPTIONS`: column name (the command's option without its dashes,
#: ``_`` for ``-``) -> (keyword of :func:`fieldcal.calibrate_many`, parser of the cell's
#: text). ``no_robust`` turns robust fitting and the trimming of bumps off together, as
#: ``--no-robust`` does; ``target_tilt``, ``target_heading``, ``target_norm`` set the
#: verdict's accuracy targets for that log.
OPTION_COLUMNS: dict[str, tuple[str, Callable[[str], object]]] = {
    column: (option.name, _cell_parser(option))
    for option in OPTIONS.values()
    if option.on_command_line
    for column in (option.column, option.old_column)  # an old spelling still read
    if column
}


def _column(name: str) -> str:
    return name.strip().lower().lstrip("-").replace("-", "_")


def _row_options(cells: Mapping[str, str], where: str) -> dict[str, object]:
    options: dict[str, object] = {}
    for column, text in cells.items():
        if not text:
            continue
        keyword, parse = OPTION_COLUMNS[column]
        try:
            value = parse(text)
        except ValueError as exc:
            raise InputError(
                f"{where}, column {column}: {text!r} is not understood; {exc}"
            ) from None
        if keyword == "robust":
            if not value:
                options.update(robust=False, cut_unsteady=False)
            continue
        options[keyword] = value
    return options


# ----------------------------------------------------------------------------- manifests
def _header(path: Path) -> list[str] | None:
    """The manifest's column names, or ``None`` when ``path`` is not a manifest (a log)."""
    try:
        with path.open(encoding="utf-8-sig", newline="") as f:
            for line in f:
                if line.strip():
                    names = [_column(n) for n in next(csv.reader([line]))]
                    return names if "log" in names else None
    except (OSError, UnicodeDecodeError, csv.Error):
        return None
    return None


def read_manifest(path: Path) -> list[LogSpec]:
    """The logs a manifest lists, every row checked (see the module's docstring).

    Parameters
    ----------
    path : Path
        A CSV file whose header has a ``log`` column.

    Returns
    -------
    list of LogSpec

    Raises
    ------
    InputError
        An unknown or repeated column, an empty ``log``, a bad device id or option value;
        one line naming the row and the column.
    """
    folder = path.parent
    with path.open(encoding="utf-8-sig", newline="") as f:
        lines = list(enumerate(f, start=1))
    rows = [(n, line) for n, line in lines if line.strip()]
    names = [_column(n) for n in next(csv.reader([rows[0][1]]))]
    for name in names:
        if name not in OPTION_COLUMNS and name not in ("log", "device"):
            known = ", ".join(["log", "device", *OPTION_COLUMNS])
            raise InputError(
                f"{path}: unknown column {name!r} in the header; a manifest has the columns "
                f"{known}"[:400]
            )
        if names.count(name) > 1:
            raise InputError(f"{path}: the column {name!r} is given twice; keep one")
    specs: list[LogSpec] = []
    for number, line in rows[1:]:
        where = f"{path} row {number}"
        try:
            cells = next(csv.reader([line]))
        except csv.Error as exc:
            raise InputError(f"{where}: not a CSV row ({exc}); quote fields with commas") from None
        if len(cells) != len(names):
            raise InputError(
                f"{where}: {len(cells)} fields for {len(names)} columns; give one per column "
                "(quote fields with commas)"
            )
        values = {n: c.strip() for n, c in zip(names, cells, strict=True)}
        log = values.pop("log")
        if not log:
            raise InputError(f"{where}, column log: empty; give the log's path or URL")
        if not _is_url(log) and not Path(log).is_absolute():
            log = str(folder / log)
        device = values.pop("device", "") or None
        if device is not None:
            try:
                device = valid_device(device)
            except InputError as exc:
                raise InputError(f"{where}, column device: {exc}") from None
        specs.append(LogSpec(log, device, _row_options(values, where), where))
    if not specs:
        raise InputError(f"{path}: a manifest without rows; list one log per row under 'log'")
    return specs


def _url_glob(url: str) -> list[str]:
    """A URL, or the URLs a pattern in one matches (fsspec's glob on its file system)."""
    if not glob.has_magic(urlparse(url).path):
        return [url]
    try:
        fsspec = importlib.import_module("fsspec")
    except ImportError:
        raise InputError(f"{url}: a pattern in a URL needs fsspec; pip install fsspec") from None
    fs, path = fsspec.core.url_to_fs(url)
    matches = sorted(fs.unstrip_protocol(m) for m in fs.glob(path))
    if not matches:
        raise InputError(f"{url}: the pattern matches no file; check it (quote it)")
    return matches


def expand_logs(arguments: Iterable[str | os.PathLike[str] | LogSpec]) -> list[LogSpec]:
    """The logs named by paths, URLs, globs and manifests, in the order given.

    Parameters
    ----------
    arguments : iterable of str, path or LogSpec
        See the module's docstring; a :class:`LogSpec` is taken as it is.

    Returns
    -------
    list of LogSpec
        A log named twice (by two globs, say) is kept once, at its first place.

    Raises
    ------
    InputError
        A local path that does not exist, a glob that matches nothing, a malformed manifest,
        or no logs at all.
    """
    specs: list[LogSpec] = []
    for argument in arguments:
        if isinstance(argument, LogSpec):
            specs.append(argument)
            continue
        text = os.fspath(argument)
        if _is_url(text):
            specs.extend(LogSpec(url) for url in _url_glob(text))
            continue
        if glob.has_magic(text):
            matches = sorted(glob.glob(text, recursive=True))
            if not matches:
                raise InputError(f"{text}: the pattern matches no file; check it (quote it)")
            found = [Path(m) for m in matches]
        else:
            found = [Path(text)]
        for path in found:
            if not path.exists():
                raise InputError(f"{path}: no such log; check the path")
            if path.is_file() and path.suffix.lower() == ".csv" and _header(path) is not None:
                specs.extend(read_manifest(path))
            else:
                specs.append(LogSpec(str(path)))
    seen: set[str] = set()
    unique = []
    for spec in specs:
        if spec.log not in seen:
            seen.add(spec.log)
            unique.append(spec)
    if not unique:
        raise InputError("no logs given; name log files, globs or a manifest .csv")
    return unique


def check_devices(specs: Iterable[LogSpec]) -> None:
    """Refuse, before any work, two logs whose results would go to one device's folder.

    Without a manifest ``device``, a log's folder is the id its metadata names, known only
    when it is read; two such logs with one file stem are refused here too, as they would
    share a folder unless both name their devices.

    Raises
    ------
    InputError
        Naming both logs, suggesting a manifest with a ``device`` column.
    """
    first: dict[str, LogSpec] = {}
    for spec in specs:
        device = spec.device or fallback_device(spec.log)
        other = first.setdefault(device, spec)
        if other is not spec:
            fix = (
                f"give each its own device in {spec.source.rsplit(' row ', 1)[0]}"
                if spec.device is not None and other.device is not None
                else "give each log its device in a manifest .csv (columns log,device)"
            )
            raise InputError(
                f"{other.log} and {spec.log} would both be filed as device {device!r}; {fix}"
            )
