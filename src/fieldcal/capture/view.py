"""What the user sees during a capture: a live terminal view (rich) or one line per event.

Everything that comes from the stream or the library is shown as plain text (rich ``Text``),
never read as markup: a device printing ``[bold]`` shows ``[bold]``.
"""

from __future__ import annotations

import contextlib
import math
import os
import select
import sys
import time
from collections.abc import Callable, Iterator
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray
from rich.console import Console, Group
from rich.live import Live
from rich.panel import Panel
from rich.table import Table
from rich.text import Text

from ..calibration import Calibration
from ..geometry.orientations import orientation_from_vectors
from ..geometry.rotations import rotation_angle_deg
from ..methods.continuous import MIN_SECONDS
from ..planning.next_pose import predicted_line
from ..planning.warmer_poses import temperature_advice, temperature_span_line
from .live_session import CaptureSession, Event, calibration_line

__all__ = ["LiveView", "PlainView", "coverage_map", "key_reader", "temperature_lines"]

Array = NDArray[np.float64]

#: Coverage map: rows of elevation of the body-frame down direction, columns of azimuth.
MAP_ROWS, MAP_COLUMNS = 9, 24


class PlainView:
    """One line per event on ``stream``, flushed at once (for scripts and tests)."""

    def __init__(self, stream: IO[str] | None = None) -> None:
        self.stream = stream if stream is not None else sys.stdout

    def event(self, event: Event) -> None:
        self.stream.write(event.text + "\n")
        self.stream.flush()

    def refresh(self, session: CaptureSession) -> None:
        """Nothing to redraw."""


def _cell(down: Array) -> tuple[int, int]:
    """Row and column of a unit down direction on the coverage map."""
    z = float(np.clip(down[2], -1.0, 1.0))
    row = round((1.0 - (math.degrees(math.asin(z)) + 90.0) / 180.0) * (MAP_ROWS - 1))
    azimuth = math.degrees(math.atan2(down[1], down[0])) % 360.0
    column = round(azimuth / 360.0 * MAP_COLUMNS) % MAP_COLUMNS
    return row, column


def coverage_map(
    captured: list[tuple[Array, bool]], now: Array | None, target: Array | None
) -> list[str]:
    """Text rows of the orientations captured, as the body-frame direction of gravity.

    Top row: +Z pointing down; bottom row: +Z pointing up; across: the azimuth of the down
    direction from +X through +Y. ``captured`` pairs a unit down direction with whether the
    pose was rejected; ``●`` a pose, ``✗`` a rejected one, ``◎`` the next pose, ``+`` now.
    """
    grid = [["·"] * MAP_COLUMNS for _ in range(MAP_ROWS)]
    marks = [(d, "✗" if bad else "●") for d, bad in captured]
    if target is not None:
        marks.append((target, "◎"))
    if now is not None:
        marks.append((now, "+"))
    for down, char in marks:
        if np.any(down):
            r, c = _cell(down)
            grid[r][c] = char
    labels = ["+Z down", "", "", "", "level", "", "", "", "+Z up"]
    return [f"{label:>8} " + "".join(row) for label, row in zip(labels, grid, strict=True)]


class LiveView:
    """The live terminal view: now, coverage, poses, calibration, next pose.

    Parameters
    ----------
    console : Console
        Where to draw (stdout's terminal).
    source : str
        Where the lines come from, for the title.
    """

    def __init__(self, console: Console, source: str) -> None:
        self.console = console
        self.source = source
        self.notes: list[str] = []
        self.live = Live(console=console, auto_refresh=False, transient=False)
        self._drawn = 0.0

    def __enter__(self) -> LiveView:
        self.live.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        self.live.__exit__(None, None, None)

    def event(self, event: Event) -> None:
        if event.kind == "pose":
            self.console.bell()
        if event.kind in ("pose", "rejected", "note", "done"):
            self.notes = [*self.notes, event.text][-4:]

    def refresh(self, session: CaptureSession) -> None:
        now = time.monotonic()
        if now - self._drawn < 0.2:  # 5 frames a second is plenty, drawing costs
            return
        self._drawn = now
        self.live.update(self.render(session), refresh=True)

    def render(self, session: CaptureSession) -> Group:
        parts: list[Any] = [self._title(session), self._now(session)]
        captured = [(np.array(m.down), m.rejected is not None) for m in session.poses]
        if session.motion is not None:  # --poses continuous: the directions visited so far
            captured += [(-np.asarray(up), False) for up in session.motion["visited"]]
        down_now = self._down_now(session)
        target = None if session.next_pose is None else session.next_pose.down
        parts.append(
            Panel(
                Text("\n".join(coverage_map(captured, down_now, target))),
                title="coverage (direction of gravity in the body frame)",
            )
        )
        # a continuous capture has no poses: what its motion covered instead of an empty table
        parts.append(self._motion(session) if session.continuous else self._poses(session))
        parts.append(self._calibration(session))
        if session.next_pose is not None:
            body = Text(session.next_pose.words, style="bold")
            if session.planned is not None:  # what the calibration should reach with it
                body.append("\nthen: " + predicted_line(session.planned), style="")
            parts.append(Panel(body, title="next pose"))
        if self.notes:
            parts.append(Text("\n".join(self.notes)))
        return Group(*parts)

    def _title(self, session: CaptureSession) -> Text:
        parser = session.parser
        skipped = sum(parser.skipped.values())
        text = f"fieldcal capture: {self.source}: {parser.lines} lines, {parser.n_rows} samples"
        if skipped:
            text += (
                f", {skipped} skipped ("
                + ", ".join(f"{k} {v}" for k, v in parser.skipped.items() if v)
                + ")"
            )
        text += "; q or Ctrl-C to stop"
        return Text(text)

    def _down_now(self, session: CaptureSession) -> Array | None:
        latest = session.latest()
        accel = latest.get("accel")
        if accel is None:
            return None
        cal = None if session.run is None else session.run.calibration
        up = cal.correct_accel(accel[None])[0] if cal is not None and cal.accel else accel
        if session.options.settings.fit.accel_sign == "gravity" and cal is None:
            up = -up
        norm = float(np.linalg.norm(up))
        return None if norm == 0 else -up / norm

    def _now(self, session: CaptureSession) -> Panel:
        latest = session.latest()
        lines = []
        down = self._down_now(session)
        if down is not None:
            lines.append("gravity (down) in the body frame: " + _vector(down))
        mag = latest.get("mag")
        cal = None if session.run is None else session.run.calibration
        if mag is not None:
            field = cal.correct_mag(mag[None])[0] if cal is not None and cal.mag else mag
            norm = float(np.linalg.norm(field))
            if norm > 0:
                lines.append("magnetic field in the body frame:   " + _vector(field / norm))
        temperature = latest.get("temperature")
        if temperature is not None and np.isfinite(temperature[0]):
            lines.append(f"temperature {float(temperature[0]):.1f} °C")
        state = session.state
        if state.still_seconds is not None:
            lines.append(f"still for {state.still_seconds:.1f} s")
        elif state.poses is not None:
            lines.append("moving")
        away = _distance(session, down)
        if away is not None:
            lines.append(f"{away:.0f}° from the next pose")
        if session.message:
            lines.append(session.message)
        return Panel(Text("\n".join(lines) or "waiting for data"), title="now")

    def _poses(self, session: CaptureSession) -> Table:
        table = Table(title=f"poses ({len(session.poses)})", expand=False)
        for name in ("#", "s", "orientation", "status"):
            table.add_column(name)
        for mark in session.poses[-8:]:
            seconds = "" if mark.seconds is None else f"{mark.seconds:.1f}"
            status = (
                Text("ok")
                if mark.rejected is None
                else Text(f"rejected: {mark.rejected}", style="red")
            )
            table.add_row(Text(str(mark.index + 1)), Text(seconds), Text(mark.words), status)
        return table

    def _motion(self, session: CaptureSession) -> Table:
        """``--poses continuous``: the motion so far, in place of the poses table."""
        table = Table(title="motion (no still poses)", expand=False)
        for name in ("seconds", "gravity directions", "turned about x, y, z"):
            table.add_column(name)
        motion = session.motion
        if motion is not None:
            turned = ", ".join(f"{float(v):.0f}°" for v in motion["turned_deg"].values())
            table.add_row(
                Text(f"{motion['seconds']:.0f}"),
                Text(f"{100 * motion['gravity_coverage']:.0f} %"),
                Text(turned),
            )
        return table

    def _calibration(self, session: CaptureSession) -> Panel:
        run = session.run
        if run is None:
            need = session.need()
            text = f"{len(session.poses)} of the {need} poses a calibration needs"
            if session.continuous:
                text = f"a calibration from the motion once it lasts {MIN_SECONDS:g} s"
            return Panel(Text(text), title="calibration")
        cal = run.calibration
        line = calibration_line(cal, run.poses.n, session.options.targets)
        style = {"pass": "green", "warn": "yellow", "fail": "red"}.get(
            "" if cal.verdict is None else cal.verdict.level, ""
        )
        body = Text(line, style=style)
        if cal.verdict is not None and cal.verdict.reasons:
            body.append("\n" + "\n".join(r.text for r in cal.verdict.reasons[:3]), style="")
        if session.floor_note:
            body.append("\n" + session.floor_note)
        for line in temperature_lines(cal):
            body.append("\n" + line)
        return Panel(body, title="calibration")


def temperature_lines(cal: Calibration) -> list[str]:
    """The temperature span the captured poses cover and, when it limits the temperature
    terms, the advice to repeat a pose when warmer (nothing without a temperature column)."""
    record = cal.options.get("temperature")
    if not isinstance(record, dict):
        return []
    line = temperature_span_line(record)
    advice = temperature_advice(cal)
    return [text for text in (None if line is None else "temperature: " + line, advice) if text]


def _vector(v: Array) -> str:
    return "(" + ", ".join(f"{x:+.2f}" for x in v) + ")"


def _distance(session: CaptureSession, down: Array | None) -> float | None:
    """Degrees between the device now and the next pose (the full rotation when the
    calibration gives the heading, else the tilt alone)."""
    target = session.next_pose
    if target is None or down is None:
        return None
    cal = None if session.run is None else session.run.calibration
    mag = session.latest().get("mag")
    if (
        cal is not None
        and cal.mag is not None
        and mag is not None
        and target.heading_deg is not None
    ):
        R = orientation_from_vectors(-down, cal.correct_mag(mag[None])[0])
        return float(rotation_angle_deg(R @ target.rotation.T))
    return float(np.degrees(np.arccos(np.clip(down @ target.down, -1.0, 1.0))))


@contextlib.contextmanager
def key_reader(enabled: bool) -> Iterator[Callable[[], str | None]]:
    """A function returning a key pressed (or None) without waiting, the terminal in cbreak
    mode meanwhile; a function that never sees a key when ``enabled`` is false or standard
    input is not a terminal."""
    stdin = sys.stdin
    if not enabled or stdin is None or not stdin.isatty():
        yield lambda: None
        return
    try:
        import termios
        import tty
    except ImportError:  # not a POSIX terminal (Windows): Ctrl-C still stops
        yield lambda: None
        return

    fd = stdin.fileno()
    saved = termios.tcgetattr(fd)
    try:
        tty.setcbreak(fd)

        def key() -> str | None:
            ready, _, _ = select.select([fd], [], [], 0)
            return os.read(fd, 1).decode(errors="replace") if ready else None

        yield key
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
