"""The raw log of a capture: every line received, as received, with its arrival time.

:class:`Recorder` writes ``FOLDER/log.csv.partial`` as lines come (flushed to the operating
system at least every :data:`FLUSH_SECONDS` and every :data:`FLUSH_LINES` lines, so a killed
process leaves what it had) and :meth:`Recorder.close` renames it to ``FOLDER/log.csv``
(after an fsync: the rename is atomic and durable).

A write that fails (a full disk, a device gone) is an :class:`~fieldcal.errors.InputError`
naming the file and the fix, raised by the next :meth:`Recorder.feed` (the flushing thread
only records it: no traceback from a thread); :meth:`Recorder.close` then leaves the file as
``log.csv.partial``, holding what was written.

The file is a CSV that ``fieldcal calibrate FOLDER/log.csv`` reads back as exactly the table
the :class:`~fieldcal.logs.stream.LineParser` kept (same names, same floats):

- the header: the header line as received (a leading ``#`` and byte-order mark removed; a
  quoted header written as its names joined by the delimiter) + delimiter + the arrival
  column's name (``arrival_s``, or ``time_arrival_s`` when the stream has no time column);
  with bare numbers (``columns``), the columns joined by the stream's delimiter, written just
  before the first data line;
- each data line: the line as received (its line ending and a leading byte-order mark
  removed) + delimiter + the arrival time in seconds since the capture started, to the
  microsecond (``%.6f``, with the stream's decimal mark): the float the parser holds;
- each skipped line (and blank line): ``# skipped <reason> at <arrival>: <line>``, the line
  with backslash escapes for anything but printable ASCII (``\\x00``, ``\\t``, ``\\xb5``),
  for ``\\`` and ``"`` (and ``.`` when the decimal mark is ``,``), cut after
  :data:`COMMENT_CHARS` characters: comments are read over by the offline reader, and a file
  of such lines stays on its fast path.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from types import TracebackType
from typing import TextIO

from .._files import fsync_folder
from ..errors import InputError
from ..logs.stream import HEADER, LineParser, arrival_text

__all__ = ["COMMENT_CHARS", "FLUSH_LINES", "FLUSH_SECONDS", "Recorder", "escape"]

#: The recorder flushes at least this often (seconds) while lines are waiting ...
FLUSH_SECONDS = 0.5
#: ... and after this many lines.
FLUSH_LINES = 1000
#: A skipped line is shown up to this many characters (escaped) in its comment.
COMMENT_CHARS = 300

#: Escapes for the ASCII characters that are not printable, the backslash and the quote.
_ESCAPES = {i: f"\\x{i:02x}" for i in [*range(0x20), 0x7F]}
_ESCAPES.update({ord("\t"): "\\t", ord("\n"): "\\n", ord("\r"): "\\r"})
_ESCAPES.update({ord("\\"): "\\\\", ord('"'): "\\x22"})


def escape(line: str, decimal: str = ".") -> str:
    """``line`` as printable ASCII: backslash escapes for control characters, non-ASCII
    characters, ``\\`` and ``"`` (and ``.`` in a log with decimal commas, where the offline
    reader's fast path takes a point anywhere as a sign of trouble); cut after
    :data:`COMMENT_CHARS` characters.

    Parameters
    ----------
    line : str
    decimal : {".", ","}
        The log's decimal mark.

    Returns
    -------
    str
    """
    table = _ESCAPES if decimal == "." else {**_ESCAPES, ord("."): "\\x2e"}
    text = line.translate(table).encode("ascii", "backslashreplace").decode("ascii")
    if len(text) > COMMENT_CHARS:
        text = f"{text[:COMMENT_CHARS]}... ({len(line)} characters)"
    return text


class Recorder:
    """Write a capture's raw log as it comes (see the module's docstring for the format).

    Parameters
    ----------
    folder : path
        Where ``log.csv.partial`` and then ``log.csv`` go; made if missing. An existing
        ``log.csv`` is replaced when the recorder closes (the command checks ``--force``).
    parser : LineParser
        The parser of the stream: each line is fed to it, and written as it judged it.
    flush_seconds, flush_lines : float, int
        How often the file is flushed to the operating system.

    Raises
    ------
    InputError
        ``log.csv.partial`` is already there (an interrupted capture's raw log: kept, never
        overwritten), or the folder cannot be written.
    """

    def __init__(
        self,
        folder: str | os.PathLike[str],
        parser: LineParser,
        *,
        flush_seconds: float = FLUSH_SECONDS,
        flush_lines: int = FLUSH_LINES,
    ) -> None:
        self.folder = Path(folder)
        self.parser = parser
        self.final = self.folder / "log.csv"
        self.partial = self.folder / "log.csv.partial"
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            self._file: TextIO = open(  # noqa: SIM115  # held open until close()
                self.partial, "x", encoding="utf-8", newline="\n", buffering=1 << 16
            )
        except FileExistsError:
            raise InputError(
                f"{self.partial}: exists (the raw log of an interrupted capture?); rename it to "
                "keep it, or delete it"
            ) from None
        except OSError as exc:
            raise InputError(
                f"{self.partial}: cannot be written ({exc.strerror or exc}); choose another folder"
            ) from None
        self._lock = threading.Lock()
        self._flush_lines = int(flush_lines)
        self._unflushed = 0
        self._header_written = False
        self._lines = 0
        self._closed = False
        self._failed: OSError | None = None  # a write that failed, from any thread
        self._stop = threading.Event()
        self._flusher = threading.Thread(
            target=self._flush_every, args=(float(flush_seconds),), daemon=True
        )
        self._flusher.start()

    @property
    def path(self) -> Path:
        """The file being written (``log.csv.partial``), or ``log.csv`` once closed (unless a
        write failed)."""
        return self.final if self._closed and self._failed is None else self.partial

    @property
    def lines(self) -> int:
        """Lines recorded (the header line made for bare numbers not counted)."""
        return self._lines

    def feed(self, line: str, arrival: float, *, partial: bool = False) -> bool:
        """Feed ``line`` to the parser and write it as the parser judged it.

        Parameters
        ----------
        line : str
            As received (with or without its line ending).
        arrival : float
            Seconds since the capture started.
        partial : bool
            The source marked the line as possibly cut (:class:`~fieldcal.capture.feeds.
            PartialLine`).

        Returns
        -------
        bool
            What :meth:`LineParser.feed` returned: True for a data row.
        """
        if self._closed:
            raise ValueError(f"{self.final}: the recorder is closed")
        kept = self.parser.feed(line, arrival, partial=partial)
        parser = self.parser
        text = parser.last_line
        delimiter = _delimiter(parser)
        if kept:
            out = f"{text}{delimiter}{arrival_text(arrival, parser.decimal)}\n"
            if not self._header_written:
                out = self._columns_header() + out
        elif parser.last_reason == HEADER:
            out = f"{_header_text(parser)}{delimiter}{parser.arrival_column}\n"
            self._header_written = True
        else:
            when = arrival_text(arrival, parser.decimal)
            out = f"# skipped {parser.last_reason} at {when}: {escape(text, parser.decimal)}\n"
        with self._lock:
            if self._failed is None:
                try:
                    self._file.write(out)
                    self._lines += 1
                    self._unflushed += 1
                    if self._unflushed >= self._flush_lines:
                        self._flush()
                except OSError as exc:
                    self._failed = exc
            if self._failed is not None:
                raise InputError(self.failure or "")
        return kept

    @property
    def failure(self) -> str | None:
        """What went wrong writing the file, with the fix (None: nothing)."""
        if self._failed is None:
            return None
        why = self._failed.strerror or " ".join(str(self._failed).split())[:100]
        return (
            f"{self.partial}: cannot be written ({why}); free some space or give another "
            "--out folder (the lines written until then are kept in it)"
        )

    def _columns_header(self) -> str:
        """The header line of a bare-number stream (written once, before its first row)."""
        self._header_written = True
        return _delimiter(self.parser).join(self.parser.names) + "\n"

    def _flush(self) -> None:
        self._file.flush()
        self._unflushed = 0

    def _flush_every(self, seconds: float) -> None:
        while not self._stop.wait(seconds):
            with self._lock:
                if self._failed is not None:
                    return  # feed says so
                if self._unflushed and not self._file.closed:
                    try:
                        self._flush()
                    except OSError as exc:  # a full disk: recorded, never a thread's traceback
                        self._failed = exc
                        return

    def flush(self) -> None:
        """Flush what was written to the operating system now.

        Raises
        ------
        InputError
            The file cannot be written (see :attr:`failure`).
        """
        with self._lock:
            if self._failed is None and not self._file.closed:
                try:
                    self._flush()
                except OSError as exc:
                    self._failed = exc
            if self._failed is not None:
                raise InputError(self.failure or "")

    def close(self) -> Path:
        """Flush, fsync and rename ``log.csv.partial`` to ``log.csv``; idempotent.

        A stream of bare numbers that sent no data line still gets its header line, so the
        file names its columns. When a write failed (:attr:`failure`) the file is closed as
        it is and keeps its name ``log.csv.partial``: it lacks the lines after the failure.

        Returns
        -------
        Path
            ``FOLDER/log.csv`` (``FOLDER/log.csv.partial`` after a failed write).
        """
        if self._closed:
            return self.path
        self._stop.set()
        self._flusher.join()
        with self._lock:
            try:
                if self._failed is None:
                    if (
                        not self._header_written
                        and self.parser.header_line is None
                        and self.parser.names
                    ):
                        self._file.write(self._columns_header())
                    self._file.flush()
                    os.fsync(self._file.fileno())
            except OSError as exc:
                self._failed = exc
            try:
                self._file.close()
            except OSError as exc:  # the buffer's last flush
                self._failed = self._failed or exc
        if self._failed is not None:
            self._closed = True  # the file keeps its name: it is incomplete
            return self.partial
        os.replace(self.partial, self.final)
        fsync_folder(self.folder)
        self._closed = True
        return self.final

    def __enter__(self) -> Recorder:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


def _delimiter(parser: LineParser) -> str:
    """The delimiter to write: the stream's, or a blank for blank-separated fields."""
    return " " if parser.delimiter is None else parser.delimiter


def _header_text(parser: LineParser) -> str:
    """The header line to write: as received, without a leading ``#``; a quoted one as its
    names joined (the offline reader's fast path reads no quotes)."""
    text = parser.header_line or ""
    body = text.lstrip()
    if body.startswith("#"):
        text = body[1:]
    names = parser.header or ()
    delimiter = _delimiter(parser)
    if '"' in text and not any(delimiter in n or '"' in n or not n for n in names):
        text = delimiter.join(names)
    return text
