"""Calibrations over time: a folder of calibration JSON files by device and date.

Layout: ``<root>/<device>/<created>.json``, one file per calibration in fieldcal's JSON schema,
named by its ``created`` time (UTC, ``2026-11-24T061500Z``; ``-2``, ``-3`` ... when two share a
second). A device id is letters, digits, ``.``, ``_`` and ``-`` (no path separators), so the
folder is the device. Files are written atomically and never replaced; anything else in the
folder is ignored. The layout is plain files on purpose: a store can be copied, versioned with
git or synced, and read without fieldcal.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

from . import _files
from .calibration import Calibration
from .comparison import Comparison, compare
from .errors import InputError

__all__ = ["DriftRow", "Store", "StoreEntry", "valid_device"]

_DEVICE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")
_STAMP = "%Y-%m-%dT%H%M%SZ"


@dataclass(frozen=True)
class StoreEntry:
    """One stored calibration: its device, when it was made (UTC) and its file."""

    device: str
    created: _dt.datetime
    path: Path


@dataclass(frozen=True)
class DriftRow:
    """One calibration in a device's history, against the one before it (``None`` first, or
    when the two cannot be compared: ``note`` then says why, e.g. different units)."""

    entry: StoreEntry
    calibration: Calibration
    since_previous: Comparison | None
    note: str = ""


def valid_device(device: object) -> str:
    """A device id as the store files it: letters, digits, ``.``, ``_``, ``-`` (up to 100).

    Parameters
    ----------
    device : object
        The id to check.

    Returns
    -------
    str
        The id, unchanged.

    Raises
    ------
    InputError
        When it is not such a string, in one line.
    """
    if not isinstance(device, str) or not _DEVICE.match(device):
        raise InputError(
            f"device id must be letters, digits, '.', '_' or '-' (up to 100, no spaces or "
            f"slashes), got {device!r}"[:200]
        )
    return device


def _when(value: str | _dt.date | _dt.datetime) -> _dt.datetime:
    """A date or time as an aware UTC datetime (a date is its midnight)."""
    if isinstance(value, _dt.datetime):
        moment = value
    elif isinstance(value, _dt.date):
        moment = _dt.datetime(value.year, value.month, value.day)
    else:
        try:
            moment = _dt.datetime.fromisoformat(str(value).replace("Z", "+00:00"))
        except ValueError:
            raise InputError(
                f"date must be ISO 8601 (2026-11-24 or 2026-11-24T06:15:00Z), got {value!r}"[:200]
            ) from None
    return moment.replace(tzinfo=_dt.UTC) if moment.tzinfo is None else moment.astimezone(_dt.UTC)


class Store:
    """Calibrations of many devices over time, in a folder (see the module's docstring).

    Parameters
    ----------
    path : str or path
        The store's folder (made on the first :meth:`add`).
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        if not isinstance(path, str | os.PathLike):
            raise InputError(
                f"Store takes the store's folder (a str or path), got {type(path).__name__}"
            )
        self.root = Path(path)
        if self.root.exists() and not self.root.is_dir():
            raise InputError(f"{self.root}: is not a folder; give the store's folder")

    def add(self, cal: Calibration, *, device: str | None = None) -> Path:
        """Store ``cal`` for ``device`` (default: the device its log named,
        ``cal.options["device"]``); returns the file written (never replacing one)."""
        if not isinstance(cal, Calibration):
            raise InputError(f"add takes a fieldcal.Calibration, got {type(cal).__name__}")
        device = device or cal.options.get("device")
        if not device:
            raise InputError(
                "no device id: the calibration's log did not name one (a '# device: ID' line "
                "above its header); give device=ID (fieldcal store add --device ID)"
            )
        folder = self.root / valid_device(device)
        folder.mkdir(parents=True, exist_ok=True)
        stem = _when(cal.created or _dt.datetime.now(_dt.UTC)).strftime(_STAMP)
        path, k = folder / f"{stem}.json", 1
        while path.exists():
            k += 1
            path = folder / f"{stem}-{k}.json"
        _files.write_text(path, cal.to_json() + "\n")
        return path

    def devices(self) -> list[str]:
        """The devices with at least one calibration, sorted."""
        if not self.root.is_dir():
            return []
        return sorted(p.name for p in self.root.iterdir() if p.is_dir() and self.entries(p.name))

    def entries(self, device: str) -> list[StoreEntry]:
        """A device's calibrations, oldest first."""
        folder = self.root / valid_device(device)
        out = []
        for path in folder.glob("*.json") if folder.is_dir() else ():
            stamp = path.stem.split("-")[0:3]
            try:
                created = _dt.datetime.strptime("-".join(stamp), _STAMP).replace(tzinfo=_dt.UTC)
            except ValueError:
                continue  # not a file of the store's
            out.append(StoreEntry(device, created, path))
        return sorted(out, key=lambda e: (e.created, e.path.name))

    def _entries(self, device: str) -> list[StoreEntry]:
        found = self.entries(device)
        if not found:
            known = ", ".join(self.devices()[:10]) or "none yet"
            raise InputError(
                f"no calibration of device {device!r} in {self.root} (devices: {known})"
            )
        return found

    @staticmethod
    def load(entry: StoreEntry) -> Calibration:
        """The calibration of ``entry`` (validated as any calibration file)."""
        return Calibration.from_json(entry.path.read_text(encoding="utf-8"))

    def latest(self, device: str) -> Calibration:
        """The device's most recent calibration."""
        return self.load(self._entries(device)[-1])

    def closest(self, device: str, date: str | _dt.date | _dt.datetime) -> Calibration:
        """The device's calibration made closest in time to ``date`` (ISO text, a date or a
        datetime; naive ones are UTC)."""
        when = _when(date)
        found = self._entries(device)
        return self.load(min(found, key=lambda e: abs((e.created - when).total_seconds())))

    def drift(self, device: str, *, sigmas: float = 3.0) -> list[DriftRow]:
        """The device's calibrations in time order, each compared with the one before
        (:meth:`Calibration.compare`: the parameters that changed beyond ``sigmas`` combined
        standard errors). Two that cannot be compared (made with different ``--gravity`` or
        ``--field-strength``, or body frames) are listed all the same: the row's
        ``since_previous`` is None and its ``note`` says why."""
        if isinstance(sigmas, bool) or not (
            isinstance(sigmas, (int, float)) and math.isfinite(sigmas) and sigmas > 0
        ):
            raise InputError(f"sigmas must be a positive number, got {sigmas!r}"[:200])
        rows: list[DriftRow] = []
        previous: Calibration | None = None
        for entry in self._entries(device):
            cal = self.load(entry)
            since, note = None, ""
            if previous is not None:
                try:
                    since = compare(previous, cal, sigmas=sigmas)
                except InputError as exc:  # different units: nothing to compare, still listed
                    note = "not compared with the one before: " + str(exc).split(";")[0]
            rows.append(DriftRow(entry, cal, since, note))
            previous = cal
        return rows
