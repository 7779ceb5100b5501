"""One capture: lines in, poses found as they happen, a running calibration, the next pose.

:class:`CaptureSession` holds the state and does the work; it knows nothing of threads or
terminals. :func:`run_capture` is the loop: it takes lines from a source, lets the session
work between them, shows the session in a view and, on every way out (the targets met, the
end of the input, a disconnect, ``q``, Ctrl-C, an exception), writes what it has: the raw log
(every line received, with its arrival time), the last calibration and the report.

The final calibration is the one ``fieldcal calibrate`` gives on the recorded ``log.csv``
with the same options: the same reader's columns, the offline still detector on every sample
(:class:`~fieldcal.logs.live.LiveDetector` with ``final=True`` is that detector) and the same
fit. The calibrations along the way use the settled poses only.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import math
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _files
from ..api import targets_for
from ..calibration import Calibration
from ..errors import InputError
from ..geometry.orientations import Orientation, angle_deg, describe, orientation_from_vectors
from ..logs.live import LiveDetector, LiveState
from ..logs.log import Log, load_log
from ..logs.pose_finding import PoseSet
from ..logs.stream import DROPPED_REASONS, LineParser
from ..methods import get as get_method
from ..methods.continuous import MIN_SECONDS
from ..methods.continuous.trajectory import RawMotion, raw_motion
from ..output.report import write_report
from ..pipeline import LogCalibration, LogSettings, run_log
from ..planning.next_pose import (
    PlannedPose,
    Targets,
    first_poses,
    plan_poses,
    targets_met,
    unreachable,
)
from ..planning.warmer_poses import temperature_advice
from ..serialize import dumps
from ..trust.targets import DEFAULT_TARGETS
from ..trust.verdict import with_dropped_lines
from .feeds import End, Line, LineSource, PartialLine
from .recorder import Recorder

__all__ = ["CaptureOptions", "CaptureResult", "CaptureSession", "Event", "run_capture"]

Array = NDArray[np.float64]

#: ``until`` values: stop by themselves when ...
UNTIL = ("pass",)
#: Poses planned ahead, so that the one suggested can avoid where the device rests now.
PLAN_AHEAD = 3
#: A suggestion closer than this (degrees) to the device's orientation now would repeat the
#: pose it rests in.
SAME_POSE_DEG = 20.0
#: ``--poses continuous``: a running calibration once the log holds this many seconds more
#: than the last one's, or this share more (the fits' cost grows with the log).
REFIT_SECONDS, REFIT_SHARE = 5.0, 0.25


@dataclass(frozen=True)
class Event:
    """Something the user should hear of: ``kind`` is one of ``pose`` (a pose captured),
    ``rejected`` (a pose the robust fit dropped), ``next`` (the pose to take next),
    ``calibration`` (the running calibration updated), ``note`` and ``done``."""

    kind: str
    text: str
    data: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class CaptureOptions:
    """How to read, detect, calibrate and when to stop.

    Attributes
    ----------
    columns : tuple of str, optional
        Names of the fields of bare-number lines (``t,ax,ay,az,mx,my,mz``); without them the
        stream must send a header line.
    settings : LogSettings
        The reader's (``settings.read``: the sensor and time columns, the decimal mark), the
        still detector's, the fit's and the check's settings, as :func:`fieldcal.pipeline.
        run_log` takes them; the target options (``--target-tilt`` ...) are also what the
        planner and ``until`` aim at.
    until : {"pass"} or None
        Stop by itself once the verdict is pass and the predicted accuracy meets
        :attr:`targets`.
    """

    columns: tuple[str, ...] | None = None
    settings: LogSettings = field(default_factory=LogSettings)
    until: str | None = None

    def __post_init__(self) -> None:
        if self.until is not None and self.until not in UNTIL:
            raise InputError(f"until must be one of {', '.join(UNTIL)}, got {self.until!r}")

    @functools.cached_property
    def targets(self) -> Targets:
        """The predicted errors to reach: the verdict's, the planner's and ``until``'s."""
        chosen = targets_for(self.settings.targets, self.settings.trust)
        return DEFAULT_TARGETS if chosen is None else chosen


@dataclass(frozen=True)
class CaptureResult:
    """How a capture ended and what it wrote.

    ``calibration`` is the final one (None when the poses were too few: ``error`` says why);
    ``files`` the paths written.
    """

    reason: str
    calibration: Calibration | None
    error: str | None
    files: tuple[Path, ...]
    poses: int
    lines: int


@dataclass(frozen=True)
class PoseMark:
    """A pose as the view lists it."""

    index: int
    start: int
    stop: int
    seconds: float | None
    words: str
    down: tuple[float, float, float]
    rejected: str | None = None


def _rows_overlap(a: tuple[int, int], b: tuple[int, int]) -> bool:
    return a[0] < b[1] and b[0] < a[1]


class CaptureSession:
    """The state of one capture and the work between lines (see the module's docstring).

    Parameters
    ----------
    options : CaptureOptions
    folder : Path
        Where ``log.csv`` (as it comes), ``cal.json`` and ``report.html`` (at the end) go.
    emit : callable
        Hears every :class:`Event`.
    clock : callable
        Seconds, for the run's duration (``time.monotonic``).
    """

    def __init__(
        self,
        options: CaptureOptions,
        folder: Path,
        emit: Callable[[Event], None],
        *,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.options = options
        self.folder = folder
        self.emit = emit
        self.clock = clock
        self.started = clock()
        self.parser = LineParser(
            list(options.columns) if options.columns else None,
            decimal=options.settings.read.decimal,
        )
        self.recorder = Recorder(folder, self.parser)
        self.detector = LiveDetector(options.settings.detect.detector_keywords())
        self.state: LiveState = self.detector.state
        self.poses: list[PoseMark] = []
        self.run: LogCalibration | None = None
        self.next_pose: Orientation | None = None
        self.planned: PlannedPose | None = None
        self.floor_note: str | None = None
        self.message = "waiting for data"
        self.done = False
        self._fit_key: tuple[int, ...] = ()
        self._suggested_after = -1
        self.captured_count = 0
        self._taken: list[Orientation] = []
        self._log: Log | None = None
        self._log_rows = -1
        self._rate: float | None = None
        self._advised: str | None = None
        self._layout_said = False
        self.motion: RawMotion | None = None  # --poses continuous: the motion so far
        self._fitted_seconds = -math.inf

    @property
    def continuous(self) -> bool:
        """``--poses continuous``: a running calibration from the motion, no poses."""
        return self.options.settings.detect.poses == "continuous"

    # ------------------------------------------------------------------ input
    def receive(self, line: Line) -> None:
        """One line of the stream, as received, with its arrival time (s): parsed and
        recorded."""
        self.recorder.feed(line.text, line.arrival, partial=isinstance(line, PartialLine))
        if not self._layout_said and self.parser.layout_note is not None:
            self._layout_said = True  # a stream without a header: how it was read, once
            self.emit(Event("note", self.parser.layout_note))

    def log(self) -> Log | None:
        """The samples so far as a :class:`~fieldcal.logs.log.Log` (None before any)."""
        if self.parser.n_rows == 0:
            return None
        if self._log_rows != self.parser.n_rows:
            table = self.parser.table()
            arrival = self.parser.arrival_column
            if self.options.settings.detect.rate is not None and arrival == self.parser.time_column:
                # a stream without its own time, at a rate the user states: the arrival times
                # (a replay's are as fast as the disk) are recorded, not used
                names = [n for n in table.names if n != arrival]
                table = dataclasses.replace(
                    table, names=names, columns={n: table.columns[n] for n in names}
                )
            self._log = load_log(table, **self._read_options())
            self._log_rows = self.parser.n_rows
        return self._log

    def _read_options(self) -> dict[str, Any]:
        read = self.options.settings.read.keywords()
        # a device reset mid-capture restarts its clock: a new segment, not an error
        read["split_on_reset"] = True
        stated_rate = self.options.settings.detect.rate is not None
        arrival_only = self.parser.time_column == self.parser.arrival_column
        own_time = self.parser.time_column is not None and not (stated_rate and arrival_only)
        if "time_col" not in read and own_time:
            read["time_col"] = self.parser.time_column
        return read

    def latest(self) -> dict[str, Array]:
        """The last reading of each sensor (raw) and of the temperature column (one value,
        °C), for the view's "now": from the parser's table (cheap views), with the columns the
        last log recognised."""
        out: dict[str, Array] = {}
        if self._log is None or self.parser.n_rows == 0:
            return out
        table = self.parser.table()
        for role in ("accel", "mag", "gyro", "temperature"):
            names = self._log.used.get(role)
            if names is not None:
                out[role] = np.array([float(table.columns[c][-1]) for c in names])
        return out

    # ------------------------------------------------------------------ work
    def step(self, *, force: bool = False) -> None:
        """Detect, calibrate and plan when enough new samples have come (with ``force``,
        whenever any has: the stream is quiet, the user waits)."""
        if self.next_pose is None and self.parser.header is not None and not self.continuous:
            self._suggest_first()  # the first pose, as soon as the sensors are known
        rows = self.parser.n_rows
        # whether to look is decided before the log is made: making it copies every column
        due = rows > self.detector.rows if force else self.detector.due(rows, self._rate)
        if rows == 0 or not due:
            return
        try:
            log = self.log()
        except InputError as exc:
            self.message = str(exc)
            return
        if log is None:
            return
        self._rate = log.rate
        if self.continuous:
            self._continuous(log)
            return
        self.state = self.detector.update(log)
        if self.state.poses is None:
            self.message = self.state.message
            return
        self.message = ""
        self._announce(self.state)
        self._calibrate(log, self.state)

    def _continuous(self, log: Log) -> None:
        """``--poses continuous``: the rotations covered so far (raw readings), and a running
        calibration from the whole log as it grows (:data:`REFIT_SECONDS`, :data:`REFIT_SHARE`)."""
        if log.accel is None or log.gyro is None:
            self.message = "--poses continuous needs accelerometer and gyroscope columns"
            return
        rate = self.options.settings.detect.rate or log.rate or 1.0
        t = np.asarray(log.time, dtype=float) if log.time is not None else np.arange(log.n) / rate
        up = -log.accel if self.options.settings.fit.accel_sign == "gravity" else log.accel
        motion = raw_motion(t, up, log.gyro)
        advice = motion["advice"]
        if self.motion is None or advice != self.motion["advice"]:
            text = "next: " + (advice or "keep turning through every orientation")
            self.emit(Event("next", text, {"advice": advice}))
        self.motion = motion
        turned = ", ".join(f"{k} {v:.0f}°" for k, v in motion["turned_deg"].items())
        self.message = (
            f"motion so far: {motion['seconds']:.0f} s, "
            f"{100 * motion['gravity_coverage']:.0f} % of gravity directions, turned {turned}"
        ) + ("" if advice is None else f"\nnext: {advice}")
        seconds = motion["seconds"]
        grown = seconds - self._fitted_seconds
        if seconds < MIN_SECONDS or grown < max(REFIT_SECONDS, REFIT_SHARE * self._fitted_seconds):
            return
        self._fitted_seconds = seconds
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the final fit reports them
            try:
                run = self._with_dropped(run_log(log, self.options.settings))
            except InputError as exc:
                self.message = str(exc)
                return
        self.run = run
        cal = run.calibration
        self.emit(Event("calibration", calibration_line(cal, 0, self.options.targets), {}))
        if self.options.until == "pass" and targets_met(cal, self.options.targets):
            self.done = True

    def _mark(self, poses: PoseSet, i: int) -> PoseMark:
        entry = poses.entries[i]
        down = self._down(poses, i)
        mag = None if poses.mag is None else poses.means("mag")[i]
        words = self._words(down, mag)
        seconds = entry["samples"] / poses.rate if poses.rate else None
        return PoseMark(
            i,
            int(entry["start"]),
            int(entry["stop"]),
            seconds,
            words,
            (float(down[0]), float(down[1]), float(down[2])),
        )

    def _down(self, poses: PoseSet, i: int) -> Array:
        """The body-frame direction of gravity in pose ``i`` (unit), calibrated when a
        calibration is there, else from the raw readings."""
        if poses.accel is None:
            return np.zeros(3)
        raw = poses.means("accel")[i]
        cal = None if self.run is None else self.run.calibration
        up = cal.correct_accel(raw[None])[0] if cal is not None and cal.accel is not None else raw
        if self.options.settings.fit.accel_sign == "gravity" and cal is None:
            up = -up
        norm = float(np.linalg.norm(up))
        return -up / norm if norm > 0 else np.zeros(3)

    def _words(self, down: Array, mag_raw: Array | None) -> str:
        """The nearest candidate's words for a pose, once a calibration corrects its readings
        (raw directions can be tens of degrees off: an offset of 0.3 g turns them by 17°);
        empty before."""
        cal = None if self.run is None else self.run.calibration
        if cal is None or cal.accel is None or not np.any(down):
            return ""
        field_body = None
        if mag_raw is not None and cal.mag is not None:
            field_body = cal.correct_mag(mag_raw[None])[0]
        R = orientation_from_vectors(-down, field_body)
        return describe(R, heading=field_body is not None)

    def _announce(self, state: LiveState) -> None:
        poses = state.poses
        assert poses is not None
        captured = [(int(e["start"]), int(e["stop"])) for e in poses.entries[: state.captured]]
        marks = []
        for i, rows in enumerate(captured):
            known = next((m for m in self.poses if _rows_overlap((m.start, m.stop), rows)), None)
            mark = self._mark(poses, i)
            if known is not None:
                mark = dataclasses.replace(mark, rejected=known.rejected)
            marks.append(mark)
            if known is None:
                if self.next_pose is not None:
                    self._taken.append(self.next_pose)  # what the user was asked to do
                # numbered by capture, not by the detection's index: the final detection on
                # every sample may find an early pose shorter or gone, and a number once said
                # is not said again
                self.captured_count += 1
                text = f"pose {self.captured_count} captured"
                text += f": {mark.words}" if mark.words else ""
                if mark.seconds is not None:
                    text += f" ({mark.seconds:.1f} s still)"
                self.emit(Event("pose", text, {"index": i, "start": rows[0], "stop": rows[1]}))
        self.poses = marks

    def need(self) -> int:
        """Poses the method needs before a calibration is tried."""
        method = self.options.settings.fit.method
        sensors = 2 if self.parser.has("accel") and self.parser.has("mag") else 1
        need = get_method(method).min_poses_for(sensors)
        return max(need, 8 if sensors == 2 else 9)

    def _calibrate(self, log: Log, state: LiveState) -> None:
        poses = state.captured_poses()
        # refit when a pose is captured or settles (its rows final), not while one is held
        key = (state.settled, *(int(e["start"]) for e in (poses.entries if poses else [])))
        if key == self._fit_key:
            return
        self._fit_key = key
        need = self.need()
        if poses is None or poses.n < need:
            self._suggest_first()
            return
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the final fit reports them
            try:
                run = self._with_dropped(run_log(log, self.options.settings, found=poses))
            except InputError as exc:
                self.message = str(exc)
                self._suggest_first()
                return
        self.run = run
        cal = run.calibration
        self._redescribe(poses)
        self._mark_rejected(cal)
        self.emit(
            Event(
                "calibration",
                calibration_line(cal, poses.n, self.options.targets),
                {"poses": poses.n},
            )
        )
        self._plan(cal)
        self._advise_temperature(cal)
        if self.options.until == "pass" and targets_met(cal, self.options.targets):
            self.done = True

    def _advise_temperature(self, cal: Calibration) -> None:
        """A note when the poses' temperatures limit the temperature terms (once per advice)."""
        advice = temperature_advice(cal)
        if advice is not None and advice != self._advised:
            self._advised = advice
            self.emit(Event("note", advice, {"temperature": cal.options.get("temperature")}))

    def _redescribe(self, poses: PoseSet) -> None:
        """The captured poses' words again, through the calibration just made."""
        self.poses = [
            dataclasses.replace(self._mark(poses, m.index), rejected=m.rejected)
            if m.index < poses.n
            else m
            for m in self.poses
        ]

    def _mark_rejected(self, cal: Calibration) -> None:
        was = {m.index for m in self.poses if m.rejected}
        reasons = {r.index: f"{r.sensor}: {r.reason}" for r in cal.rejected}
        self.poses = [dataclasses.replace(m, rejected=reasons.get(m.index)) for m in self.poses]
        for index, reason in sorted(reasons.items()):
            if index not in was:
                self.emit(
                    Event(
                        "rejected",
                        f"pose {index + 1} rejected: {reason}",
                        {"index": index, "reason": reason},
                    )
                )

    def _suggest_first(self) -> None:
        """The next of the starter poses. Before a calibration the raw directions can be far
        off (offsets), so each pose captured counts as the suggestion it followed."""
        down = np.array([o.down for o in self._taken]).reshape(-1, 3)
        # first_poses reads the accelerometer's directions (up = −down) and, given, a
        # magnetometer's means only as the sign that the suggestions need a heading
        mag = -down if self.parser.has("mag") else None
        self._set_next(first_poses(-down if self.parser.has("accel") else None, mag, 1)[0], None)

    def _plan(self, cal: Calibration) -> None:
        try:
            plan = plan_poses(cal, PLAN_AHEAD, targets=self.options.targets)
        except InputError as exc:
            self.message = str(exc)
            return
        # the best pose not where the device rests now: a pose taken again must be left
        # and come back to, or it is not a new pose (the still interval goes on)
        now = self.orientation_now()
        far = [p for p in plan if now is None or angle_deg(p.rotation, now) > SAME_POSE_DEG]
        chosen = far[0] if far else plan[0]
        self.floor_note = unreachable(cal, self.options.targets)
        self._set_next(chosen.orientation, chosen)

    def orientation_now(self) -> Array | None:
        """World → body rotation of the device now, from its latest readings corrected by the
        running calibration (None before one, or without both sensors)."""
        cal = None if self.run is None else self.run.calibration
        latest = self.latest()
        if cal is None or cal.accel is None or cal.mag is None or "mag" not in latest:
            return None
        if "accel" not in latest:
            return None
        try:
            return orientation_from_vectors(
                cal.correct_accel(latest["accel"][None])[0], cal.correct_mag(latest["mag"][None])[0]
            )
        except InputError:
            return None

    def _set_next(self, orientation: Orientation, planned: PlannedPose | None) -> None:
        """Say the next pose when it changes, and again after each pose captured (the user
        waits for it, even when it is the same)."""
        self.planned = planned
        same = self.next_pose is not None and self.next_pose.words == orientation.words
        if same and self._suggested_after == len(self.poses):
            return
        self.next_pose = orientation
        self._suggested_after = len(self.poses)
        self.emit(Event("next", f"next pose: {orientation.words}", {"words": orientation.words}))

    # ------------------------------------------------------------------ the end
    def finish(self, reason: str) -> CaptureResult:
        """The final detection and calibration on every sample; write the files."""
        files: list[Path] = []
        error = None
        cal = None
        try:
            log = self.log()
            if log is None:
                raise InputError(self._nothing_read())
            if not self.continuous:
                self.state = self.detector.update(log, final=True)
            if self.state.poses is not None and not self.continuous:
                self._announce(self.state)  # the pose held at the end, too
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                final = self._with_dropped(run_log(log, self._final_settings()))
            for w in caught:
                if issubclass(w.category, UserWarning):
                    self.emit(Event("note", f"warning: {w.message}"))
            cal = final.calibration
            self.run = final
            if self.state.poses is not None:
                self._redescribe(self.state.poses)
            self._mark_rejected(cal)
            self.emit(
                Event("calibration", calibration_line(cal, final.poses.n, self.options.targets))
            )
            self._advise_temperature(cal)  # a replay may end before any running fit
            document = final.document()
            document["capture"] = self.record(reason)
            path = self.folder / "cal.json"
            _files.write_text(path, dumps(document) + "\n")  # as `fieldcal calibrate` writes it
            files.append(path)
        except InputError as exc:
            error = str(exc)
        except OSError as exc:  # a full disk: the recorder's failure names it first
            error = self.recorder.failure or f"{exc.filename or self.folder}: {exc.strerror}"
        finally:
            files.insert(0, self.recorder.close())
            self._note_skipped()
        if self.recorder.failure is not None:
            error = self.recorder.failure
        elif cal is not None and importlib.util.find_spec("matplotlib") is not None:
            try:
                files.append(self._report(cal))
            except OSError as exc:
                error = f"{exc.filename or self.folder}: cannot be written ({exc.strerror})"
        n = 0 if self.run is None else self.run.poses.n
        self.emit(Event("done", f"done: {reason}", {"reason": reason}))
        return CaptureResult(reason, cal, error, tuple(files), n, self.parser.lines)

    def _with_dropped(self, run: LogCalibration) -> LogCalibration:
        """``run`` with the verdict's input rule on the stream's dropped data lines
        (``dropped_lines``, :func:`~fieldcal.trust.verdict.with_dropped_lines`)."""
        cal = run.calibration
        if cal.verdict is None:
            return run
        dropped = {k: v for k, v in self.parser.skipped.items() if k in DROPPED_REASONS}
        verdict = with_dropped_lines(cal.verdict, dropped, self.parser.n_rows)
        if verdict is cal.verdict:
            return run
        return dataclasses.replace(run, calibration=dataclasses.replace(cal, verdict=verdict))

    def _note_skipped(self) -> None:
        """The lines skipped, by reason (also in ``cal.json``'s ``capture.skipped``)."""
        skipped = {k: v for k, v in self.parser.skipped.items() if v}
        if skipped:
            total = sum(skipped.values())
            which = ", ".join(f"{k} {v}" for k, v in skipped.items())
            dropped = self.parser.dropped
            lost = f"; {dropped} of them data lines lost" if dropped else ""
            self.emit(Event("note", f"skipped {total} line(s): {which}{lost}", {**skipped}))

    def _nothing_read(self) -> str:
        before = self.parser.skipped.get("before header", 0)
        problem = self.parser.layout_problem
        if before:
            why = f" ({problem})" if problem else ""
            return (
                f"no data lines received: {before} line(s) came before any header line{why}; "
                "reset the board so it prints its header, or name the fields with --columns "
                "t,ax,ay,az,mx,my,mz"
            )
        return (
            f"no data lines received ({self.parser.lines} line(s) read); check the port, the "
            "baud rate and that the device prints CSV lines"
        )

    def _final_settings(self) -> LogSettings:
        """The capture's settings as given, on every sample: ``fieldcal calibrate``'s path on
        the recorded log, so both choose the same mode (``--poses auto``: rests when the log
        has them, else the continuous motion) and give the same result."""
        return self.options.settings

    def _report(self, cal: Calibration) -> Path:
        path = self.folder / "report.html"
        log = self.log()
        assert log is not None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            write_report(cal, log, str(path))
        return path

    def record(self, reason: str) -> dict[str, Any]:
        """What the capture was, for ``cal.json``'s ``capture`` object."""
        return {
            "stopped": reason,
            "seconds": round(self.clock() - self.started, 3),
            "lines": self.parser.lines,
            "rows": self.parser.n_rows,
            "skipped": dict(self.parser.skipped),
            "dropped": self.parser.dropped,
            "until": self.options.until,
            "targets": {
                "heading_deg": self.options.targets.heading_deg,
                "tilt_deg": self.options.targets.tilt_deg,
            },
        }


def calibration_line(cal: Calibration, poses: int, targets: Targets) -> str:
    """One line on a running calibration: verdict, dip, predicted errors against targets."""
    verdict = "?" if cal.verdict is None else cal.verdict.summary
    source = f"{poses} poses"
    if cal.options.get("mode") == "continuous":
        source = f"{cal.options['trajectory']['duration_s']:.0f} s of continuous motion"
    parts = [f"calibration: {verdict} from {source}"]
    if cal.dip_deg is not None:
        std = cal.dip_std_deg
        parts.append(f"dip {cal.dip_deg:.2f}" + (f" ± {std:.2f}°" if std is not None else "°"))
    acc = cal.accuracy
    if acc is not None:
        if acc.heading_deg is not None and math.isfinite(acc.heading_deg):
            parts.append(f"heading {acc.heading_deg:.2f}° (target {targets.heading_deg:g}°)")
        if acc.tilt_deg is not None and math.isfinite(acc.tilt_deg):
            parts.append(f"tilt {acc.tilt_deg:.2f}° (target {targets.tilt_deg:g}°)")
    return ", ".join(parts)


def run_capture(
    source: LineSource,
    session: CaptureSession,
    *,
    refresh: Callable[[CaptureSession], None] | None = None,
    key: Callable[[], str | None] | None = None,
    budget: float = 0.05,
) -> CaptureResult:
    """Read ``source`` into ``session`` until it ends, the targets are met, ``q`` or Ctrl-C.

    ``refresh`` redraws a view between batches of lines; ``key`` returns a key pressed, if
    any. Every way out goes through :meth:`CaptureSession.finish`, which writes the files.
    """
    reason = "stopped"
    source.start()
    session.emit(Event("note", f"reading {source.name}"))
    try:
        while True:
            item = source.get(timeout=budget)
            idle = item is None
            ended = None
            deadline = time.monotonic() + budget
            while item is not None:
                if isinstance(item, End):
                    ended = item
                    break
                session.receive(item)
                if time.monotonic() > deadline:
                    break
                item = source.get(timeout=0)
            if ended is not None:
                reason = ended.reason
                break
            # a quiet stream (a user holding a pose, waiting to be told): look at what came
            session.step(force=idle)
            if refresh is not None:
                refresh(session)
            if session.done:
                reason = "the verdict is pass and the targets are met"
                break
            if key is not None and key() == "q":
                reason = "stopped by the user (q)"
                break
    except KeyboardInterrupt:
        reason = "stopped by the user (Ctrl-C)"
    except BaseException as exc:  # written all the same, then raised
        reason = f"error: {type(exc).__name__}: {exc}"
        raise
    finally:
        source.close()
        result = session.finish(reason)
        if refresh is not None:
            refresh(session)
    return result
