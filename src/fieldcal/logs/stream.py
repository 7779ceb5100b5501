"""Lines of a live stream into a growing table: the input side of ``fieldcal capture``.

:class:`LineParser` takes the text lines a device sends, one at a time with their arrival
time, and keeps the data rows in float arrays that grow by half when full (amortised O(1) per
row, one float per value: an hour at 1 kHz of ten columns is 3.6 M rows, 320 MB). Whatever is
not a data row is skipped and counted by reason (:data:`REASONS`), never an error: a partial
line at connect, a debug print, binary noise, a line with a field missing, a header repeated
by a device that reset.

**The header.** Without ``columns`` the stream must send a header line: the first line whose
fields are all names (none a number, none repeated) among which
:func:`~fieldcal.logs.columns.recognise_columns` finds an accelerometer or a magnetometer
triple, as offline. It may be written as a ``#`` comment (``# t,ax,ay,...``). Its delimiter is
the offline reader's choice (``,`` then ``;`` then tab, else blanks). With ``columns`` (the
names of bare-number lines, e.g. ``t,ax,ay,az,mx,my,mz``) the delimiter is that of the first
line which splits into as many numbers.

**Data lines** hold as many fields as the header, each a decimal number
(``[+-]digits[.digits][e[+-]digits]``, blanks around it allowed; no ``nan``, ``inf`` or
``1_000``: the offline reader must read back exactly what was kept) of magnitude at most
:data:`~fieldcal.logs.log.LARGEST`. A column whose header name is empty (a trailing
delimiter on every line) may hold empty fields (NaN), as offline. Decimal commas are read with
``decimal=","``, or with ``decimal=None`` when the fields are separated by ``;`` or tabs and
the first data line writes its numbers with commas and never with points (that line fixes
the mark for the stream: lines of the other mark are then skipped).

**No header at all.** A board that printed its header before the port was opened (a
native-USB board that does not reset on open) sends bare numbers only. Without ``columns``,
the first :data:`GUESS_LINES` lines of numbers (skipped as ``before header``) decide the
layout from their field count (:data:`LAYOUTS`: 9 or 10 numbers are ``[t,] ax..az, gx..gz,
mx..mz``, 6 or 7 are ``[t,] ax..az, mx..mz``) and magnitudes: the first column is a time when it
never decreases (it must, for 7 and 10, and must not for 6 and 9), and the gyroscope is the
middle three (checked when the board moved: the gyroscope's norm is near zero at rest and
large in motion, an accelerometer's and a magnetometer's stay near their field's; another
triple reading so is a contradiction). The layout read is said in
:attr:`LineParser.layout_note`; a line count or magnitudes that fit no layout leave the stream
without a header and :attr:`LineParser.layout_problem` says why (``--columns`` names the
fields).

**Time.** The arrival time of every row is kept, to the microsecond (:func:`arrival_text`),
as the last column: ``arrival_s`` when the stream has a time column (which
:func:`~fieldcal.logs.log.load_log` then uses, so a replay at any speed gives the same
result), ``time_arrival_s`` when it has none (then it is the time column: a time name).

The raw recorder (:mod:`fieldcal.capture.recorder`) writes each line as the parser judged it,
so ``fieldcal calibrate`` reads back exactly the parser's table from the recorded file.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .columns import recognise_columns
from .log import LARGEST
from .raw_table import Table
from .text_layout import _COMMA_NUMBER, _POINT_NUMBER
from .text_lines import _fields, _is_number, _sniff_delimiter

__all__ = [
    "ARRIVAL",
    "ARRIVAL_AS_TIME",
    "DROPPED_REASONS",
    "GUESS_LINES",
    "HEADER",
    "LAYOUTS",
    "MAX_LINE",
    "REASONS",
    "LineParser",
    "arrival_text",
]

Array = NDArray[np.float64]

#: The arrival column's name when the stream has a time column of its own (not a time name).
ARRIVAL = "arrival_s"
#: The arrival column's name when the stream has no time column: recognised as the time.
ARRIVAL_AS_TIME = "time_arrival_s"
#: Longest line read (characters): sensor lines are short, and the recorded file stays on the
#: offline reader's fast path (lines under 990 characters) with the arrival time appended.
MAX_LINE = 800
#: Why a line is not a data row, in the order the checks are made.
REASONS = (
    "too long",  # over MAX_LINE characters
    "binary",  # NUL or other control characters, bytes that are not UTF-8
    "blank",
    "comment",  # a '#' line after the header
    "before header",  # no header yet (without columns)
    "partial line",  # cut at connect or disconnect (the source says so)
    "repeated header",  # the header again (a device that reset)
    "another header",  # a header with other names
    "text",  # characters that are not numbers and delimiters (a debug print)
    "field count",  # numbers, but not as many as the columns
    "not a number",  # nan/inf, an empty field, '1.2.3', a decimal mark of the other kind
    "out of range",  # a magnitude over LARGEST (or inf)
)
#: ``last_reason`` of the line taken as the header (it is not a row, and not skipped).
HEADER = "header"
#: Lines of bare numbers before any header that decide the layout (half a second at 100 Hz)
#: ... or, for 9 or 10 numbers while the board has not moved (the gyroscope cannot be told
#: from the other triples), up to this many.
GUESS_LINES = 50
GUESS_MOST = 300
#: The layouts of headerless lines, by their number of fields.
LAYOUTS: dict[int, tuple[str, ...]] = {
    6: ("ax", "ay", "az", "mx", "my", "mz"),
    7: ("t", "ax", "ay", "az", "mx", "my", "mz"),
    9: ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz"),
    10: ("t", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz"),
}
#: A triple is the gyroscope's when the median of its norm is under this share of its 95th
#: percentile and under half that of every other triple (a gyroscope reads about zero at rest;
#: an accelerometer's and a magnetometer's norms stay near the field's).
GYRO_RATIO = 0.5
#: The skip reasons of a data line gone wrong (garbled, cut, a field missing, NaN, beyond the
#: range): what :attr:`LineParser.dropped` counts. Blank lines, comments, headers, debug prints
#: (``text``) and the lines cut at connect or disconnect (``partial line``) are not data lost.
DROPPED_REASONS = ("too long", "binary", "field count", "not a number", "out of range")

#: Rows kept as Python lists before they are moved into the arrays (bounded: a flush copies
#: a block, which is cheaper than one numpy assignment per row).
_BLOCK = 1024
#: Control characters: a tab is a delimiter; U+FFFD marks bytes that were not UTF-8.
_BINARY = re.compile("[\x00-\x08\x0a-\x1f\x7f\ufffd]")
_BOM = "\ufeff"


def arrival_text(arrival: float, decimal: str = ".") -> str:
    """An arrival time as the recorder writes it: seconds to the microsecond (``%.6f``).

    The parser keeps ``float(arrival_text(arrival))``, so the recorded text reads back as
    the very float the parser's table holds.

    Parameters
    ----------
    arrival : float
        Seconds since the capture started.
    decimal : {".", ","}
        The stream's decimal mark.

    Returns
    -------
    str
    """
    text = f"{arrival:.6f}"
    return text.replace(".", ",") if decimal == "," else text


def _chars(delimiter: str | None, decimal: str) -> re.Pattern[str]:
    """A character that cannot be in a data line (numbers, the delimiter, blanks)."""
    allowed = "0-9eE+\\- \t" + re.escape(decimal)
    if delimiter is not None:
        allowed += re.escape(delimiter)
    return re.compile(f"[^{allowed}]")


#: A character that no data line of any layout holds (a debug print, a header).
_TEXT = re.compile(r"[^0-9eE+\-., \t;]")


class LineParser:
    """A live stream's lines into a growing table (see the module's docstring).

    Parameters
    ----------
    columns : sequence of str, optional
        Names of the fields of bare-number lines (``["t", "ax", "ay", "az", "mx", "my",
        "mz"]``); without them the stream must send a header line.
    decimal : {None, ".", ","}
        The decimal mark; None recognises decimal commas in ``;`` or tab separated lines.
    name : str
        What the table is called in messages (:attr:`Table.path`).

    Raises
    ------
    InputError
        ``columns`` that are not distinct names free of delimiters among which an
        accelerometer or magnetometer x,y,z is recognised, or a ``decimal`` not ``.``/``,``.

    Notes
    -----
    Not thread-safe: one thread feeds and reads it. Invariant: ``n_rows + sum(skipped) +
    (header_index is not None) == lines``.
    """

    def __init__(
        self,
        columns: Sequence[str] | None = None,
        *,
        decimal: str | None = None,
        name: str = "stream",
    ) -> None:
        if decimal not in (None, ".", ","):
            raise InputError(
                f"decimal must be '.' or ',' (or None to recognise it); got {decimal!r}"
            )
        self._name = name
        self._decimal_given = decimal
        self._columns: tuple[str, ...] | None = None
        if columns is not None:
            self._columns = _check_columns(columns)
        self._header: tuple[str, ...] | None = None
        self._header_line: str | None = None
        self._header_index: int | None = None
        self._delimiter: str | None = None
        self._decimal: str | None = None  # decided: '.' or ','
        self._arrival = ""
        self._roles: dict[str, list[str]] = {}
        self._blank_ok: tuple[int, ...] = ()  # columns with an empty name: empty fields allowed
        self._bad: re.Pattern[str] | None = None  # set once delimiter and decimal are known
        self._width = 0
        self._values: Array = np.empty((0, 0))
        self._stored = 0
        self._pending: list[list[float]] = []
        self._skipped: dict[str, int] = {}
        self._lines = 0
        self._last_reason: str | None = None
        self._last_line = ""
        # bare numbers before any header: rows by (delimiter, field count), to guess a layout
        self._guess: dict[tuple[str | None, int], list[list[float]]] = {}
        self._layout_note: str | None = None
        self._layout_problem: str | None = None
        if self._columns is not None:
            self._set_header(self._columns, None)

    # ------------------------------------------------------------------ properties
    @property
    def header(self) -> tuple[str, ...] | None:
        """The stream's column names (from its header line, or ``columns``); None before."""
        return self._header

    @property
    def header_line(self) -> str | None:
        """The line taken as the header, as received (None with ``columns`` or before)."""
        return self._header_line

    @property
    def header_index(self) -> int | None:
        """Which line (counted from 0) was the header; None with ``columns`` or before."""
        return self._header_index

    @property
    def names(self) -> list[str]:
        """The table's column names: the header's, then the arrival column ([] before)."""
        return [] if self._header is None else [*self._header, self._arrival]

    @property
    def arrival_column(self) -> str | None:
        """``arrival_s`` or ``time_arrival_s`` (see the module's docstring); None before."""
        return self._arrival or None

    @property
    def time_column(self) -> str | None:
        """The table's time column: the stream's recognised one, else the arrival column."""
        if self._header is None:
            return None
        return self._roles.get("time", [self._arrival])[0]

    def has(self, role: str) -> bool:
        """Whether the header names columns of ``role`` (``accel``, ``mag``, ``gyro``,
        ``time``, ``pose``), as :func:`~fieldcal.logs.columns.recognise_columns` finds them."""
        return role in self._roles

    @property
    def delimiter(self) -> str | None:
        """The field delimiter (``,`` ``;`` tab, or None for blanks); None also before it is
        known (bare numbers: until the first data line)."""
        return self._delimiter

    @property
    def decimal(self) -> str:
        """The decimal mark of the numbers (``.`` until a line shows decimal commas)."""
        return self._decimal or self._decimal_given or "."

    @property
    def n_rows(self) -> int:
        """Data rows kept."""
        return self._stored + len(self._pending)

    @property
    def lines(self) -> int:
        """Lines fed."""
        return self._lines

    @property
    def skipped(self) -> Mapping[str, int]:
        """Lines skipped, by reason (:data:`REASONS`; only reasons met, in order of first
        occurrence). A read-only view that follows the parser."""
        return MappingProxyType(self._skipped)

    @property
    def layout_note(self) -> str | None:
        """How a stream without a header was read (None: it had one, or ``columns``)."""
        return self._layout_note

    @property
    def layout_problem(self) -> str | None:
        """Why the bare numbers before any header fit no layout (None: not tried, or fit)."""
        return self._layout_problem

    @property
    def dropped(self) -> int:
        """Data lines dropped: the lines skipped for a reason of :data:`DROPPED_REASONS`."""
        return sum(self._skipped.get(reason, 0) for reason in DROPPED_REASONS)

    @property
    def last_reason(self) -> str | None:
        """What the last line was: None for a data row, ``"header"`` for the header line,
        else its skip reason."""
        return self._last_reason

    @property
    def last_line(self) -> str:
        """The last line fed, its line ending and a leading byte-order mark removed."""
        return self._last_line

    # ------------------------------------------------------------------ feeding
    def feed(self, line: str, arrival: float, *, partial: bool = False) -> bool:
        """Read one line.

        Parameters
        ----------
        line : str
            The line, with or without its line ending.
        arrival : float
            Its arrival time, seconds since the capture started (kept to the microsecond).
        partial : bool
            The source says the line may be cut (the first line of a port opened
            mid-stream, the last one before a disconnect): skipped as ``"partial line"``
            unless it is the header the parser is waiting for.

        Returns
        -------
        bool
            True when the line became a data row.

        Raises
        ------
        ValueError
            ``arrival`` is not a finite number (a caller's mistake, not the stream's).
        """
        if not isinstance(arrival, (int, float)) or not math.isfinite(arrival):
            raise ValueError(f"arrival must be a finite number of seconds, got {arrival!r}")
        self._lines += 1
        text = line.rstrip("\r\n")
        if text.startswith(_BOM):
            text = text[1:]
        self._last_line = text
        reason = self._read(text, float(arrival_text(arrival)), partial)
        self._last_reason = reason
        if reason is None:
            return True
        if reason != HEADER:
            self._skipped[reason] = self._skipped.get(reason, 0) + 1
        return False

    def _read(self, text: str, arrival: float, partial: bool) -> str | None:
        """None for a data row, HEADER for the header, else the skip reason."""
        bad = self._bad
        if bad is not None and not partial and len(text) <= MAX_LINE and bad.search(text) is None:
            # the everyday line: only number characters, delimiters and blanks
            fields = text.split(self._delimiter)
            if len(fields) == self._width and not self._blank_ok:
                if self._decimal == ",":
                    fields = [f.replace(",", ".") for f in fields]
                try:
                    values = list(map(float, fields))
                except ValueError:
                    pass  # the careful path below names it
                else:
                    if (len(text) > 150 or "e" in text or "E" in text) and not _in_range(values):
                        return "out of range"
                    values.append(arrival)
                    self._keep(values)
                    return None
        return self._careful(text, arrival, partial)

    def _careful(self, text: str, arrival: float, partial: bool) -> str | None:
        if len(text) > MAX_LINE:
            return "too long"
        if _BINARY.search(text) is not None:
            return "binary"
        if not text.strip():
            return "blank"
        if self._header is None:
            found = self._as_header(text)
            if found is not None:
                self._header_line = text
                self._header_index = self._lines - 1
                self._set_header(*found)
                return HEADER
            if self._columns is None and not partial and self._layout_problem is None:
                self._guess_layout(text)
            return "before header"
        if text.lstrip().startswith("#"):
            return "comment"
        if partial:
            return "partial line"
        if _TEXT.search(text) is not None:
            found = self._as_header(text)
            if found is not None:
                return "repeated header" if found[0] == self._header else "another header"
            return "not a number" if self._non_finite(text) else "text"
        deciding = self._bad is None  # the first data line fixes the layout
        delimiter = self._delimiter
        if deciding and self._columns is not None:
            delimiter = self._detect_delimiter(text)
        fields = _fields(text, delimiter) or []
        if len(fields) != self._width:
            return "field count"
        decimal = self._decide_decimal(delimiter, fields) if deciding else self.decimal
        if _chars(delimiter, decimal).search(text) is not None:
            return "not a number"  # a decimal mark of the other kind
        values = self._numbers(fields, decimal)
        if values is None:
            return "not a number"
        if not _in_range(values):
            return "out of range"
        if deciding:
            self._fix_layout(delimiter, decimal)
        values.append(arrival)
        self._keep(values)
        return None

    def _non_finite(self, text: str) -> bool:
        """A data line with ``nan`` or ``inf`` for some readings (a sensor that failed to
        read): as many fields as the columns, each a number or such a word."""
        if self._bad is None:
            return False  # the layout is not known yet
        fields = _fields(text, self._delimiter) or []
        if len(fields) != self._width:
            return False
        cells = [f.strip().lower().lstrip("+-") for f in fields]
        words = [c in _NON_FINITE for c in cells]
        return (
            any(words)
            and self._numbers(
                [f for f, w in zip(fields, words, strict=True) if not w], self.decimal
            )
            is not None
        )

    def _numbers(self, fields: list[str], decimal: str) -> list[float] | None:
        """The fields as floats (empty ones NaN in columns with an empty name), or None."""
        comma = decimal == ","
        out: list[float] = []
        for j, cell in enumerate(fields):
            cell = cell.strip()
            if not cell and j in self._blank_ok:
                out.append(math.nan)
                continue
            if comma:
                cell = cell.replace(",", ".")
            if not _NUMBER.fullmatch(cell):
                return None
            out.append(float(cell))
        return out

    # ------------------------------------------------------------------ header and layout
    def _as_header(self, text: str) -> tuple[tuple[str, ...], str | None] | None:
        """(names, delimiter) when ``text`` is a header line, else None."""
        body = text.lstrip()
        if body.startswith("#"):
            body = body[1:]
        comma = self._decimal_given == ","
        delimiter = _sniff_delimiter(body, comma)
        if delimiter != "," and "," in body:
            return None  # offline, a comma in the header makes it comma separated
        fields = _fields(body, delimiter)
        if not fields or len(fields) < 3:
            return None
        names = tuple(f.strip() for f in fields)
        if len(set(names)) != len(names) or any(_numeric(n) for n in names):
            return None
        roles = recognise_columns(list(names))
        if "accel" not in roles and "mag" not in roles:
            return None
        return names, delimiter

    def _guess_layout(self, text: str) -> None:
        """Keep a line of bare numbers; after :data:`GUESS_LINES` of one field count, take
        the layout they show (see the module's docstring) or say why none fits."""
        comma = self._decimal_given == ","
        for delimiter in (";", "\t", None) if comma else (",", ";", "\t", None):
            fields = _fields(text, delimiter) or []
            cells = [f.strip().replace(",", ".") if comma else f.strip() for f in fields]
            if len(cells) >= 3 and all(_NUMBER.fullmatch(c) for c in cells):
                break
        else:
            return
        rows = self._guess.setdefault((delimiter, len(cells)), [])
        rows.append([float(c) for c in cells])
        if len(rows) < GUESS_LINES:
            return
        names, said, checked = _layout(np.array(rows))
        if names is None:
            self._layout_problem = said
            self._guess = {}
            return
        if not checked and len(rows) < GUESS_MOST:
            return  # wait for the board to move
        self._guess = {}
        self._layout_note = (
            f"no header line: {len(names)} numbers per line read as {','.join(names)} ({said}; "
            f"the first {len(rows)} lines decided it and are kept as comments); give "
            "--columns to name them otherwise"
        )
        self._set_header(names, delimiter)

    def _set_header(self, names: tuple[str, ...], delimiter: str | None) -> None:
        self._header = names
        self._roles = recognise_columns(list(names))
        base = ARRIVAL if "time" in self._roles else ARRIVAL_AS_TIME
        arrival, k = base, 1
        while arrival in names:
            k += 1
            arrival = f"{base}_{k}"
        self._arrival = arrival
        self._width = len(names)
        self._blank_ok = tuple(j for j, n in enumerate(names) if not n)
        self._values = np.empty((self._width + 1, 4096))
        if self._columns is None:
            self._delimiter = delimiter
            if delimiter in (",", None) or self._decimal_given is not None:
                self._fix_layout(delimiter, self._decide_decimal(delimiter, []))

    def _detect_delimiter(self, text: str) -> str | None:
        """Bare numbers: the first delimiter that splits ``text`` into as many numbers as
        there are columns (``,`` ``;`` tab, blanks); blanks when none does."""
        candidates: tuple[str | None, ...] = (",", ";", "\t", None)
        if self._decimal_given == ",":
            candidates = (";", "\t", None)
        for delimiter in candidates:
            fields = _fields(text, delimiter)
            if fields is None or len(fields) != self._width:
                continue
            decimal = self._decide_decimal(delimiter, fields)
            if self._numbers(fields, decimal) is not None:
                return delimiter
        return None

    def _decide_decimal(self, delimiter: str | None, fields: Sequence[str]) -> str:
        """The decimal mark: ``decimal`` if given, else from a data line's ``fields``."""
        if self._decimal_given is not None:
            return self._decimal_given
        if delimiter in (";", "\t"):
            cells = [f.strip() for f in fields]
            comma = any(_COMMA_NUMBER.fullmatch(c) for c in cells)
            point = any(_POINT_NUMBER.fullmatch(c) for c in cells)
            return "," if comma and not point else "."
        return "."

    def _fix_layout(self, delimiter: str | None, decimal: str) -> None:
        self._delimiter = delimiter
        self._decimal = decimal
        self._bad = _chars(delimiter, decimal)

    # ------------------------------------------------------------------ storage
    def _keep(self, values: list[float]) -> None:
        self._pending.append(values)
        if len(self._pending) >= _BLOCK:
            self._flush()

    def _flush(self) -> None:
        k = len(self._pending)
        if k == 0:
            return
        needed = self._stored + k
        if needed > self._values.shape[1]:
            # grow by half: amortised O(1) per row, at most a third of the arrays unused
            grown = np.empty((self._values.shape[0], max(needed, int(1.5 * self._values.shape[1]))))
            grown[:, : self._stored] = self._values[:, : self._stored]
            self._values = grown
        self._values[:, self._stored : needed] = np.array(self._pending, dtype=np.float64).T
        self._stored = needed
        self._pending = []

    def table(self) -> Table:
        """The rows so far as a :class:`~fieldcal.logs.text.Table` for
        :func:`~fieldcal.logs.log.load_log`.

        Returns
        -------
        Table
            One float column per name of :attr:`names` (none before the header). The columns
            are read-only **views** of the parser's arrays: cheap, and they never change
            (later rows go beyond them, or into new arrays when the arrays grow).
        """
        self._flush()
        n = self._stored
        columns: dict[str, NDArray[np.generic]] = {}
        for j, name in enumerate(self.names):
            view = self._values[j, :n]
            view.flags.writeable = False
            columns[name] = view
        notes = ["decimal commas read as points"] if self._decimal == "," else []
        return Table(self._name, self.names, columns, notes, self.decimal)


#: Words for a reading that is not a finite number (lower case, without a sign).
_NON_FINITE = frozenset({"nan", "inf", "infinity", "ovf", "nan(ind)"})
#: A number as both the parser and the offline reader read it (ASCII digits only).
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")


def _layout(rows: Array) -> tuple[tuple[str, ...] | None, str, bool]:
    """The layout of headerless rows (k, n), why, and whether the magnitudes confirmed it
    (:data:`LAYOUTS`); or None and the problem."""
    n = rows.shape[1]
    if n not in LAYOUTS:
        known = ", ".join(str(k) for k in LAYOUTS)
        return None, f"lines of {n} numbers fit no layout fieldcal knows ({known} numbers)", True
    names = LAYOUTS[n]
    steps = np.diff(rows[:, 0])
    timed = bool(np.all(steps >= 0) and np.any(steps > 0))
    if timed != (names[0] == "t"):
        which = "increases like a time" if timed else "does not increase as a time would"
        return None, f"lines of {n} numbers, but their first number {which}", True
    body = rows[:, 1:] if timed else rows
    said = "the first number increases: the time" if timed else "no time column"
    if body.shape[1] == 9:
        norms = np.linalg.norm(body.reshape(len(body), 3, 3), axis=2)
        top = np.percentile(norms, 95, axis=0)
        ratio = np.median(norms, axis=0) / np.where(top > 0, top, 1.0)
        gyro_like = [
            bool(r < GYRO_RATIO and np.all(r < 0.5 * np.delete(ratio, k)))
            for k, r in enumerate(ratio.tolist())
        ]
        if gyro_like[1]:
            said += "; the middle three read near zero at rest: the gyroscope"
        elif any(gyro_like):
            which = "first" if gyro_like[0] else "last"
            return (
                None,
                (
                    f"lines of {n} numbers, but the {which} three read near zero at rest as a "
                    "gyroscope's would, not the middle three"
                ),
                True,
            )
        else:  # a board at rest all along: nothing tells the triples apart
            said += "; the gyroscope taken as the middle three (not checked: no motion yet)"
            return names, said, False
    return names, said, True


def _numeric(text: str) -> bool:
    return _is_number(text) or _is_number(text.replace(",", "."))


def _in_range(values: list[float]) -> bool:
    """No magnitude over LARGEST (NaN, from an empty field of an unnamed column, passes)."""
    return not any(v > LARGEST or v < -LARGEST for v in values)


def _check_columns(columns: Sequence[str]) -> tuple[str, ...]:
    if isinstance(columns, str) or not all(isinstance(c, str) for c in columns):
        raise InputError(f"columns must be a sequence of names, e.g. t,ax,ay,az; got {columns!r}")
    names = tuple(c.strip() for c in columns)
    shown = ",".join(names)[:120]
    if len(names) < 3 or not all(names) or len(set(names)) != len(names):
        raise InputError(
            f"columns {shown!r}: give at least three distinct names, e.g. t,ax,ay,az,mx,my,mz"
        )
    if any(re.search(r"[,;\s\"#]", c) or _numeric(c) for c in names):
        raise InputError(
            f"columns {shown!r}: a name holds a delimiter, a blank, a quote or a '#', or is a "
            "number; give plain names such as t,ax,ay,az,mx,my,mz"
        )
    roles = recognise_columns(list(names))
    if "accel" not in roles and "mag" not in roles:
        raise InputError(
            f"columns {shown!r}: no accelerometer or magnetometer x,y,z among them; name them "
            "e.g. t,ax,ay,az,mx,my,mz"
        )
    return names
