"""A simulated IMU board on a pseudo-terminal, for tests of the live capture.

:class:`PtyDevice` opens a pty (``os.openpty``, the slave in raw mode: no echo, no CR/LF
translation) and, once :meth:`PtyDevice.start` is called, a thread writes CSV lines into its
master side as a board on a USB serial port would: the header ``t,ax,ay,az,gx,gy,gz,mx,my,mz``,
then rows at ``rate`` Hz of simulated time (:class:`fieldcal.simulation.device.Device`), a
still pose held ``hold`` seconds, a turn of ``move`` seconds to the next pose, and so on.
Poses come from a list of world-to-body rotations or from a callable asked for each next
pose (``next_pose(i)``, None to stop), so a test can play a user who follows the printed
suggestions. Rows are written as fast as the reader takes them, or paced (``speed`` times
real time). ``garbage=True`` adds what real boards send: a partial first line, a boot
message, a debug print between poses and a line of binary noise. ``disconnect_after=N``
closes the master after N lines, as an unplugged board (the reader then sees EIO / a
SerialException); ``end="disconnect"`` does so after the last pose.

Start it after the reader opened :attr:`PtyDevice.port` (pyserial flushes the input on open):

    with PtyDevice(rotations, seed=1, garbage=True, end="disconnect") as device:
        source = open_source(port=device.port)
        source.start()
        device.start()
        ...
"""

from __future__ import annotations

import fcntl
import importlib.util
import os
import select
import struct
import termios
import threading
import time
import tty
from collections.abc import Callable, Sequence
from contextlib import suppress
from typing import Literal

import numpy as np
import pytest
from numpy.typing import ArrayLike, NDArray

from fieldcal.calibration import Calibration
from fieldcal.simulation.device import COLUMNS, Device, Samples

#: A test that reads a board on a serial port needs pyserial (the ``serial`` extra).
needs_serial = pytest.mark.skipif(
    importlib.util.find_spec("serial") is None,
    reason="pyserial (the serial extra) not installed: a serial port is read with it",
)

Array = NDArray[np.float64]
NextPose = Callable[[int], ArrayLike | None]

HEADER = ",".join(COLUMNS)
#: What ``garbage=True`` writes (bytes, each ending a line).
PARTIAL_FIRST = b"0213,-0.98,0.5\n"  # the end of a row cut at connect
BOOT = b"MPU9250 ready\n"
DEBUG = b"[I] calib: pose done\n"
BINARY = b"\x00\xff\xfe\x01 noise \x9f\n"


class PtyDevice:
    """A simulated board on a pseudo-terminal (see the module's docstring).

    Parameters
    ----------
    poses : sequence of (3, 3) arrays, or callable
        World-to-body rotations of the still poses, or ``next_pose(i) -> rotation | None``
        asked when pose ``i`` is due (None: no more poses).
    preset, seed, rate
        The simulated board (:class:`~fieldcal.simulation.device.Device`).
    hold : float
        Seconds (simulated) the board rests in each pose.
    move : (float, float)
        Range of the seconds a turn between poses takes (drawn from the device's seed).
    speed : float, optional
        Pace the rows at ``speed`` times real time; None writes them as fast as they are read.
    garbage : bool
        Write a partial first line, a boot message, debug prints and binary noise too.
    disconnect_after : int, optional
        Close the master (an unplugged board) after this many lines, all kinds counted.
    end : {"idle", "disconnect"}
        After the last pose: stay connected and silent, or disconnect.
    decimals : int
        Significant digits of the values written.
    """

    def __init__(
        self,
        poses: Sequence[ArrayLike] | NextPose,
        *,
        preset: str = "paper",
        seed: int = 0,
        rate: float = 100.0,
        hold: float = 2.0,
        move: tuple[float, float] = (0.8, 1.5),
        speed: float | None = None,
        garbage: bool = False,
        disconnect_after: int | None = None,
        end: Literal["idle", "disconnect"] = "idle",
        decimals: int = 9,
    ) -> None:
        self.device = Device(preset, seed=seed, rate=rate)
        self._poses = poses
        self._hold = hold
        self._move = move
        self._speed = speed
        self._garbage = garbage
        self._disconnect_after = disconnect_after
        self._end = end
        self._format = f"{{:.{decimals}g}}"
        self._moves = np.random.default_rng([seed, 3])
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no CR/LF translation: bytes go through as written
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        #: Every line written, as bytes with its line end, in order.
        self.written: list[bytes] = []
        #: Data rows (0-based, stop exclusive, counted among data rows) of each still pose.
        self.pose_rows: list[tuple[int, int]] = []
        #: The rotation of each still pose written.
        self.rotations: list[Array] = []
        self.rows = 0
        self.disconnected = False
        self.finished = threading.Event()
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="pty-device", daemon=True)
        self._closed = False

    # ------------------------------------------------------------------ what tests use
    @property
    def truth(self) -> Calibration:
        """The board's true calibration (fieldcal's gauge; its rotations are the draw's)."""
        return self.device.truth

    def lines(self) -> list[str]:
        """Every line written as a reader delivers it (decoded, line end removed)."""
        return [b.rstrip(b"\r\n").decode("utf-8", errors="replace") for b in self.written]

    def start(self) -> None:
        """Start writing (after the reader opened :attr:`port`)."""
        self._thread.start()

    def wait(self, timeout: float = 10.0) -> bool:
        """Wait until every line was written (and the disconnect done); False on timeout."""
        done = self.finished.wait(timeout)
        if self.error is not None:
            raise self.error
        return done

    def close(self) -> None:
        """Stop writing and close both sides of the pty."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self._close_master()
        with suppress(OSError):
            os.close(self._slave)

    def __enter__(self) -> PtyDevice:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ the writer
    def _close_master(self) -> None:
        if self._master >= 0:
            with suppress(OSError):
                os.close(self._master)
            self._master = -1

    def _pending(self) -> int:
        """Bytes written but not yet read by the other side."""
        raw = fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0")
        return int(struct.unpack("i", raw)[0])

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            if self._stop.is_set():
                raise _StoppedError
            _, ready, _ = select.select([], [self._master], [], 0.05)
            if not ready:
                continue
            try:
                n = os.write(self._master, view)
            except BlockingIOError:
                continue
            view = view[n:]

    def _line(self, data: bytes, *, row: bool = False) -> None:
        if self._disconnect_after is not None and len(self.written) >= self._disconnect_after:
            raise _DisconnectError
        self._write(data)
        self.written.append(data)
        self.rows += row

    def _rows(self, samples: Samples) -> None:
        fmt = self._format
        columns = samples.columns()
        table = np.column_stack([columns[k] for k in COLUMNS])
        started = time.monotonic()
        t_first = float(samples.t[0])
        for i, values in enumerate(table):
            if self._speed is not None:
                due = started + (float(samples.t[i]) - t_first) / self._speed
                delay = due - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    raise _StoppedError
            line = ",".join(fmt.format(v) for v in values) + "\n"
            self._line(line.encode("ascii"), row=True)

    def _next(self, i: int) -> Array | None:
        poses = self._poses
        if callable(poses):
            value = poses(i)
            return None if value is None else np.asarray(value, dtype=float)
        return np.asarray(poses[i], dtype=float) if i < len(poses) else None

    def _run(self) -> None:
        try:
            if self._garbage:
                self._line(PARTIAL_FIRST)
                self._line(BOOT)
            self._line((HEADER + "\n").encode("ascii"))
            previous: Array | None = None
            i = 0
            while (rotation := self._next(i)) is not None:
                if previous is not None:
                    seconds = float(self._moves.uniform(*self._move))
                    self._rows(self.device.move(previous, rotation, seconds))
                    if self._garbage and i % 3 == 1:
                        self._line(DEBUG)
                    if self._garbage and i == 2:
                        self._line(BINARY)
                first = self.rows
                self._rows(self.device.still(rotation, self._hold))
                self.pose_rows.append((first, self.rows))
                self.rotations.append(rotation)
                previous = rotation
                i += 1
            if self._end == "disconnect":
                raise _DisconnectError
        except _DisconnectError:
            self._disconnect()
        except _StoppedError:
            pass
        except BaseException as exc:  # handed to wait()
            self.error = exc
        self.finished.set()

    def _disconnect(self) -> None:
        """Close the master once the reader has taken every byte (the kernel drops what is
        unread when the master closes)."""
        deadline = time.monotonic() + 10.0
        quiet = 0  # a few empty looks in a row: bytes may sit a moment between the two sides
        while quiet < 3 and time.monotonic() < deadline and not self._stop.is_set():
            quiet = quiet + 1 if self._pending() == 0 else 0
            time.sleep(0.01)
        self._close_master()
        self.disconnected = True


class _DisconnectError(Exception):
    pass


class _StoppedError(Exception):
    pass
