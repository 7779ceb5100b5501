"""Where a capture's lines come from: a serial port, standard input, or a file (followed).

Each :class:`LineSource` runs one reader thread that puts items into a queue: a
:class:`Line` ``(arrival, text)`` per line received, and finally one :class:`End` saying why
the lines stopped (``end of input``, ``disconnected: ...``, ``error: ...``, ``closed``).
``arrival`` is ``time.monotonic()`` minus the capture's start, taken when the bytes ending
the line were read. :meth:`LineSource.close` stops the thread within half a second in every
case (a serial read waits at most :data:`POLL` seconds, standard input is polled with
``select``, a followed file every :data:`POLL` seconds).

Bytes are cut into lines at ``\\r\\n``, ``\\r`` or ``\\n`` (a ``\\r\\n`` split across two reads
is one line end) and decoded as UTF-8 with ``errors="replace"``: a byte that is not UTF-8
becomes U+FFFD, which the parser counts as binary. A line is a :class:`PartialLine` (a
:class:`Line` too) when it may be cut: the first line read from a serial port (the port may
have been opened in the middle of a line), the unterminated rest at a disconnect or at
:meth:`~LineSource.close`, and a run of :data:`LONGEST` bytes without a line end. Pass
``partial=isinstance(item, PartialLine)`` to :meth:`LineParser.feed
<fieldcal.logs.stream.LineParser.feed>`. At the end of a file or of standard input the last
line is complete even without its line end.

pyserial is imported when a port is opened; without it the error says how to install it.
"""

from __future__ import annotations

import errno
import importlib
import os
import queue
import re
import select
import stat
import sys
import threading
import time
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, BinaryIO, Literal, NamedTuple

from ..errors import InputError

__all__ = [
    "LONGEST",
    "POLL",
    "End",
    "Item",
    "Line",
    "LineSource",
    "LineSplitter",
    "PartialLine",
    "open_source",
]

#: Seconds a read waits before looking whether the source was closed; also the follow poll.
POLL = 0.1
#: Bytes without a line end delivered as a (partial) line: binary noise never grows the
#: buffer without bound.
LONGEST = 1 << 16
#: Items a file source reads ahead of its consumer (a live source's queue is unbounded: its
#: device would overrun the operating system's buffer instead).
READ_AHEAD = 50_000
_CHUNK = 1 << 16
_LINE_END = re.compile(rb"\r\n|\r|\n")
_PYSERIAL = "reading a serial port needs pyserial: pip install 'fieldcal[serial]'"


class Line(NamedTuple):
    """A line received: ``(arrival, text)``, the text without its line end."""

    arrival: float
    text: str


class PartialLine(Line):
    """A line that may be cut (see the module's docstring)."""

    __slots__ = ()


@dataclass(frozen=True)
class End:
    """Why the lines stopped; always the last item.

    Attributes
    ----------
    kind : {"end", "disconnected", "error", "closed"}
    reason : str
        One line: ``end of input``, ``disconnected: <why>``, ``error: <why>``, ``closed``.
    arrival : float
        When, in seconds since the capture started.
    """

    kind: Literal["end", "disconnected", "error", "closed"]
    reason: str
    arrival: float


Item = Line | End


class _EndedError(Exception):
    """Raised by a reader: the source went away (disconnected) or failed (error)."""

    def __init__(self, kind: Literal["disconnected", "error"], why: str) -> None:
        super().__init__(why)
        self.kind: Literal["disconnected", "error"] = kind


class LineSplitter:
    """Bytes in, lines out: ``\\r\\n``, ``\\r`` and ``\\n`` end lines, UTF-8 with U+FFFD for
    bytes that are not UTF-8.

    Parameters
    ----------
    longest : int
        Bytes without a line end given out as a partial line (:data:`LONGEST`).
    """

    def __init__(self, longest: int = LONGEST) -> None:
        self._buffer = bytearray()
        self._after_cr = False  # the last byte seen was a '\r': a '\n' next is its pair
        self._longest = longest

    def feed(self, chunk: bytes) -> list[tuple[str, bool]]:
        """The lines that ``chunk`` completes, each with whether it may be cut.

        Parameters
        ----------
        chunk : bytes

        Returns
        -------
        list of (str, bool)
        """
        if not chunk:
            return []
        if self._after_cr and chunk[:1] == b"\n":
            chunk = chunk[1:]
        self._after_cr = chunk[-1:] == b"\r"
        self._buffer += chunk
        parts = _LINE_END.split(self._buffer)
        rest = parts.pop()
        out = [(_decode(p), False) for p in parts]
        if len(rest) >= self._longest:
            out.append((_decode(rest), True))
            rest = b""
        self._buffer = bytearray(rest)
        return out

    def rest(self) -> str | None:
        """The bytes after the last line end, as text (None when there are none); cleared."""
        if not self._buffer:
            return None
        text = _decode(self._buffer)
        self._buffer = bytearray()
        return text


def _decode(raw: bytes | bytearray) -> str:
    return bytes(raw).decode("utf-8", errors="replace")


class LineSource:
    """Lines from somewhere, read by a thread into a queue (see the module's docstring).

    Use :func:`open_source`; then :meth:`start`, :meth:`get` until an :class:`End`, and
    :meth:`close` (also a context manager).
    """

    #: Whether the first line may start in the middle (a port opened mid-stream).
    first_may_be_cut = False

    def __init__(self, name: str, t0: float | None, read_ahead: int = 0) -> None:
        self.name = name
        self.t0 = time.monotonic() if t0 is None else float(t0)
        self._queue: queue.Queue[Item] = queue.Queue(read_ahead)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"fieldcal-read {name}", daemon=True)
        self._started = False
        self._end: End | None = None
        self._released = False
        self._release_lock = threading.Lock()

    # ------------------------------------------------------------------ the consumer's side
    def start(self) -> None:
        """Start the reader thread (again: nothing)."""
        if not self._started and not self._stop.is_set():
            self._started = True
            self._thread.start()

    def get(self, timeout: float | None = None) -> Item | None:
        """The next item; None when none came within ``timeout`` seconds (None: wait).

        After the :class:`End` every call returns it again at once.
        """
        if self._end is not None:
            return self._end
        try:
            item = self._queue.get(timeout=timeout) if timeout != 0 else self._queue.get_nowait()
        except queue.Empty:
            return None
        if isinstance(item, End):
            self._end = item
        return item

    def close(self) -> None:
        """Stop the reader (within half a second) and release the device or file."""
        self._stop.set()
        self._interrupt()
        if self._started:
            self._thread.join(timeout=1.0)
        if not self._started or not self._thread.is_alive():
            self._release_once()

    def __enter__(self) -> LineSource:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    # ------------------------------------------------------------------ the reader's side
    def _read(self) -> bytes | None:
        """Bytes read (b"" when none came within :data:`POLL`), None at the end of input;
        :class:`_EndedError` when the source went away."""
        raise NotImplementedError

    def _interrupt(self) -> None:
        """Make a blocked :meth:`_read` return soon (the reads wait at most POLL anyway)."""

    def _release(self) -> None:
        """Close the device or file."""

    def _release_once(self) -> None:
        with self._release_lock:
            if not self._released:
                self._released = True
                self._release()

    def _now(self) -> float:
        return time.monotonic() - self.t0

    def _put(self, item: Item) -> bool:
        """Queue ``item``; False when the source was closed while the queue was full."""
        while True:
            try:
                self._queue.put(item, timeout=POLL)
                return True
            except queue.Full:
                if self._stop.is_set():
                    return False

    def _run(self) -> None:
        splitter = LineSplitter()
        first = self.first_may_be_cut
        end: End | None = None
        try:
            while not self._stop.is_set():
                chunk = self._read()
                if chunk is None:
                    rest = splitter.rest()
                    if rest is not None:
                        self._put(Line(self._now(), rest))
                    end = End("end", "end of input", self._now())
                    break
                if not chunk:
                    continue
                now = self._now()
                for text, cut in splitter.feed(chunk):
                    item = PartialLine(now, text) if cut or first else Line(now, text)
                    first = False
                    if not self._put(item):
                        break
        except _EndedError as exc:
            end = End(exc.kind, f"{exc.kind}: {exc}", self._now())
        except Exception as exc:  # a reader must end with a reason, never a traceback
            end = End("error", f"error: {type(exc).__name__}: {exc}", self._now())
        finally:
            self._release_once()
        if end is None:
            end = End("closed", "closed", self._now())
        if end.kind != "end":
            rest = splitter.rest()
            if rest is not None:
                self._put(PartialLine(self._now(), rest))
        self._put(end)


# ----------------------------------------------------------------------------- serial
class _SerialSource(LineSource):
    first_may_be_cut = True

    def __init__(self, port: str, baud: int, t0: float | None) -> None:
        super().__init__(port, t0)
        self._serial = _open_serial(port, baud)

    def _read(self) -> bytes | None:
        try:
            waiting = self._serial.in_waiting
            data: bytes = self._serial.read(waiting or 1)  # waits up to POLL for a byte
        except Exception as exc:  # SerialException, or OSError (EIO) from in_waiting
            if self._stop.is_set():
                return b""
            raise _EndedError("disconnected", f"{self.name}: {_why(exc)}") from None
        return data

    def _interrupt(self) -> None:
        with suppress(Exception):  # the read returns within POLL anyway
            self._serial.cancel_read()

    def _release(self) -> None:
        with suppress(Exception):  # a port that vanished cannot be closed cleanly
            self._serial.close()


def _why(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text[:200]


def _serial_module() -> Any:
    try:
        return importlib.import_module("serial")
    except ImportError:
        raise InputError(_PYSERIAL) from None


def _ports() -> str:
    """The serial ports pyserial lists, for messages."""
    try:
        found = importlib.import_module("serial.tools.list_ports").comports()
        names = sorted(str(p.device) for p in found)
    except Exception:
        return ""
    return f"ports found: {', '.join(names)}" if names else "no serial ports found"


def _open_serial(port: str, baud: int) -> Any:
    """An open pyserial port (``timeout`` :data:`POLL`), or a one-line InputError."""
    serial = _serial_module()
    options: dict[str, Any] = {"timeout": POLL}
    if os.name == "posix":
        options["exclusive"] = True  # two programs reading one port each get half the lines
    try:
        return serial.Serial(port, baud, **options)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise InputError(_open_error(port, exc)) from None


def _open_error(port: str, exc: BaseException) -> str:
    code = getattr(exc, "errno", None)
    text = str(exc)
    if code == errno.ENOENT or "No such file" in text or "FileNotFoundError" in text:
        listing = _ports()
        return (
            f"{port}: no such serial port ({listing or 'none listed'}); check the name and "
            "that the board is plugged in"
        )
    if code == errno.EACCES or "Permission denied" in text or "PermissionError" in text:
        return (
            f"{port}: permission denied; add yourself to the port's group (sudo usermod -aG "
            "dialout $USER, then log in again) or check the port's permissions"
        )
    if code in (errno.EBUSY, errno.EAGAIN) or "exclusively lock" in text or "busy" in text:
        return (
            f"{port}: the port is in use by another program (a serial monitor?); close it "
            "and try again"
        )
    if "Inappropriate ioctl" in text or "Could not configure port" in text:
        return f"{port}: not a serial port; give the board's port ({_ports() or 'none listed'})"
    listing = _ports()
    return f"{port}: cannot open the serial port ({_why(exc)}); check the name" + (
        f" ({listing})" if listing else ""
    )


# ----------------------------------------------------------------------------- files and pipes
class _StreamSource(LineSource):
    """A pipe, standard input or a file read to its end, polled with ``select``."""

    def __init__(self, name: str, fd: int, t0: float | None, *, owned: bool, read_ahead: int):
        super().__init__(name, t0, read_ahead)
        self._fd = fd
        self._owned = owned

    def _read(self) -> bytes | None:
        if os.name == "posix":
            ready, _, _ = select.select([self._fd], [], [], POLL)
            if not ready:
                return b""
        try:
            data = os.read(self._fd, _CHUNK)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if exc.errno == errno.EIO:  # a terminal that went away
                raise _EndedError("disconnected", f"{self.name}: {_why(exc)}") from None
            raise _EndedError("error", f"{self.name}: {_why(exc)}") from None
        return data if data else None

    def _release(self) -> None:
        if self._owned:
            with suppress(OSError):
                os.close(self._fd)


class _FollowSource(LineSource):
    """A regular file read to its end, then polled for growth (``tail -f``)."""

    def __init__(self, path: Path, fd: int, t0: float | None) -> None:
        super().__init__(str(path), t0, READ_AHEAD)
        self._path = path
        self._fd = fd
        info = os.fstat(fd)
        self._identity = (info.st_dev, info.st_ino)
        self._offset = 0

    def _read(self) -> bytes | None:
        data = os.read(self._fd, _CHUNK)
        if data:
            self._offset += len(data)
            return data
        try:
            info = os.stat(self._path)
        except FileNotFoundError:
            raise _EndedError(
                "disconnected", f"{self._path} was removed (following stopped)"
            ) from None
        if (info.st_dev, info.st_ino) != self._identity:
            raise _EndedError(
                "disconnected", f"{self._path} was replaced by another file (following stopped)"
            )
        if info.st_size < self._offset:
            raise _EndedError(
                "disconnected",
                f"{self._path} was truncated from {self._offset:,} to {info.st_size:,} bytes "
                "(following stopped)",
            )
        self._stop.wait(POLL)
        return b""

    def _interrupt(self) -> None:
        pass  # the poll waits on the stop event

    def _release(self) -> None:
        with suppress(OSError):
            os.close(self._fd)


def _open_file(path: str, follow: bool, t0: float | None) -> LineSource:
    target = Path(path)
    try:
        info = os.stat(target)
    except FileNotFoundError:
        raise InputError(
            f"{path}: no such file; give the log to read (or - for standard input)"
        ) from None
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(info.st_mode):
        raise InputError(f"{path}: is a folder; give a file")
    if stat.S_ISCHR(info.st_mode):
        raise InputError(f"{path}: is a device; read a serial port with --port {path}")
    regular = stat.S_ISREG(info.st_mode)
    if follow and not regular:
        raise InputError(f"{path}: --follow is for a regular file that is being written")
    try:
        # non-blocking: a named pipe without a writer does not hang the open
        fd = os.open(target, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if follow:
        return _FollowSource(target, fd, t0)
    return _StreamSource(str(target), fd, t0, owned=True, read_ahead=READ_AHEAD)


class _ObjectSource(LineSource):
    """A binary file object without a file descriptor (standard input replaced in memory, as
    by a test runner): read in pieces; :meth:`close` waits for a read in progress to return."""

    def __init__(self, name: str, stream: BinaryIO, t0: float | None) -> None:
        super().__init__(name, t0)
        self._stream = stream

    def _read(self) -> bytes | None:
        read = getattr(self._stream, "read1", self._stream.read)
        data: bytes = read(_CHUNK)
        return data if data else None


def _open_stdin(t0: float | None) -> LineSource:
    stream = getattr(sys.stdin, "buffer", None)
    if stream is None:
        raise InputError("standard input cannot be read here; give --from FILE instead")
    try:
        fd = stream.fileno()
    except (AttributeError, OSError, ValueError):  # in memory: no descriptor to poll
        return _ObjectSource("standard input", stream, t0)
    return _StreamSource("standard input", fd, t0, owned=False, read_ahead=0)


def open_source(
    *,
    port: str | None = None,
    baud: int = 115200,
    path: str | os.PathLike[str] | None = None,
    follow: bool = False,
    t0: float | None = None,
) -> LineSource:
    """Open where the lines come from (the reader thread starts with :meth:`~LineSource.start`).

    Parameters
    ----------
    port : str, optional
        A serial port (``/dev/ttyACM0``, ``COM3``), read with pyserial at ``baud``.
    baud : int
        Bits per second of the serial port.
    path : str or path, optional
        A file (read to its end, or followed with ``follow``), or ``"-"`` for standard input.
    follow : bool
        Keep reading ``path`` as it grows until it is truncated, replaced or the source closed.
    t0 : float, optional
        ``time.monotonic()`` at the capture's start; arrival times count from it (default:
        now).

    Returns
    -------
    LineSource

    Raises
    ------
    InputError
        One line: neither or both of ``port`` and ``path``, ``follow`` without a file,
        pyserial missing, a port that cannot be opened (no such port, with the ports found;
        permission, with the dialout group; in use), a file that cannot be read.
    """
    if (port is None) == (path is None):
        raise InputError("give the device's port, or a file to read (- for standard input)")
    if port is not None:
        if follow:
            raise InputError("follow is for a file being written, not a serial port")
        if isinstance(baud, bool) or not isinstance(baud, int) or baud < 1:
            raise InputError(f"baud must be a positive whole number, e.g. 115200; got {baud!r}")
        return _SerialSource(port, baud, t0)
    assert path is not None
    if str(path) == "-":
        if follow:
            raise InputError("follow is for a file being written, not standard input")
        return _open_stdin(t0)
    return _open_file(os.fspath(path), follow, t0)
