"""When too few poses are found: the detection tried again with looser settings on the log
already loaded, and the options that would find more, with how many (``with --min-still 0.5:
21 poses; with --pose-col shot: 24``).

The retries are few and cheap: at most :data:`MAX_RETRIES` still detections (each O(n), on the
arrays in memory; fewer on a long log, :data:`RETRY_SAMPLES` samples in all) and one grouping
per column that may label poses (:data:`~fieldcal.logs.columns.LABEL_WORDS`). What is tried:

- a log without time and without ``--rate`` counts durations in samples: a few sample rates of
  cheap IMUs (:data:`RATE_GUESSES`), said as "give its --rate";
- a shorter ``--min-still`` (a half, a quarter), alone and with ``--window`` as much
  shorter, a shorter or a longer ``--window`` alone, and a ``--still-threshold`` twice the
  one used;
- each column named like a pose label (``shot``, ``position``, ``orientation`` ...) as
  ``--pose-col``; when a column names several devices (``device``, ``serial`` ...) its rows
  are counted for the first device only, and the advice says that one log must hold one
  device;
- ``--poses windows`` when the log turns slowly without rests, ``--poses samples`` when its
  rows are separate readings (neighbouring rows as far apart as rows half the log apart).
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .columns import DEVICE_WORDS, normalise
from .log import Log
from .orientation_labels import unit_directions
from .pose_finding import PoseSet, poses_from_log, turns_slowly

__all__ = [
    "MAX_RETRIES",
    "RATE_GUESSES",
    "RETRY_SAMPLES",
    "SEPARATE_READINGS",
    "PoseHint",
    "pose_advice",
    "pose_hints",
]

#: Most still detections tried again (each reads the whole log once).
MAX_RETRIES = 9
#: Most samples read by the retries together: a long log gets fewer (10⁶ rows: 8 retries).
RETRY_SAMPLES = 8_000_000
#: Sample rates tried on a log without a time column (Hz): cheap IMU loggers' usual rates.
RATE_GUESSES = (10.0, 25.0, 100.0)
#: Hints shown in a message (the best first).
SHOWN = 3
_S = TypeVar("_S", bound=np.generic)
_DEFAULTS = {"window": (0.5, 25), "min_still": (1.0, 50)}


@dataclass(frozen=True)
class PoseHint:
    """Options that find more poses on this log, and how many.

    ``options`` are the library's keywords (``{"min_still": 0.5}``), ``flags`` the same for
    the command line (``"--min-still 0.5"``); ``orientations`` counts the distinct ones
    (closer than 3° count as one) of ``poses``.
    """

    options: Mapping[str, float | str]
    flags: str
    poses: int
    orientations: int
    note: str = ""

    def text(self) -> str:
        """``"with --min-still 0.5: 21 poses"`` (the distinct orientations when fewer)."""
        fewer = f", {self.orientations} orientations" if self.orientations < self.poses else ""
        rate = self.options.get("rate")
        when = f" (if recorded at {rate:g} Hz)" if rate is not None else ""
        return f"with {self.flags}{when}: {self.poses} poses{fewer}{self.note}"


def _number(x: float) -> str:
    return f"{x:.3g}"


def _count(log: Log, found: PoseSet) -> tuple[int, int]:
    """Poses and distinct orientations of ``found`` (its entries' labels)."""
    return found.n, len({e.get("orientation", i) for i, e in enumerate(found.entries)})


def _try(log: Log, **options: Any) -> tuple[int, int] | None:
    """Poses and orientations with ``options``, None when the detection refuses them."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return _count(log, poses_from_log(log, **options))
    except InputError:
        return None


def _detection_options(
    log: Log, rate: float | None, settings: dict[str, float | None]
) -> list[tuple[dict[str, float], str]]:
    """The looser still-detection settings to try, as keywords and flags (bounded)."""
    given = {k: v for k, v in settings.items() if v is not None}
    hz = rate if rate is not None else (log.rate if log.n > 1 else None)
    out: list[tuple[dict[str, float], str]] = []
    if hz is None and "window" not in given and "min_still" not in given:
        out += [({"rate": r}, f"--rate {r:g}") for r in RATE_GUESSES]
    unit = 0 if hz else 1
    window = float(given.get("window", _DEFAULTS["window"][unit]))
    least = float(given.get("min_still", _DEFAULTS["min_still"][unit]))

    def length(x: float) -> float:
        return float(f"{x:.3g}") if hz else float(max(1, round(x)))

    for changes in (
        {"min_still": least / 2},
        {"window": window / 2, "min_still": least / 2},
        {"min_still": least / 4},
        {"window": window / 4, "min_still": least / 4},
        {"window": window / 2},
        {"window": window * 2},
    ):
        changes = {k: length(v) for k, v in changes.items()}
        flags = " ".join(f"--{k.replace('_', '-')} {_number(v)}" for k, v in changes.items())
        out.append((changes, flags))
    return out


def _label_columns(log: Log) -> tuple[list[str], tuple[str, list[str]] | None]:
    """Columns that may label poses, and a column naming several devices with its devices."""
    pose_like, devices = [], None
    for name, values in log.labels.items():
        if DEVICE_WORDS.intersection(normalise(name).split("_")):
            kinds = list(dict.fromkeys(str(v) for v in np.asarray(values).tolist()))
            if len(kinds) > 1 and devices is None:
                devices = (name, kinds)
        else:
            pose_like.append(name)
    return pose_like, devices


def _rows_are_readings(log: Log) -> bool:
    """Neighbouring rows read as differently as rows half the log apart: each row is a
    separate reading (a shot), not a sample of a continuous log."""
    ref = log.accel if log.accel is not None else log.mag
    if ref is None or len(ref) < 8:
        return False
    d = unit_directions(ref)
    neighbours = float(np.median(np.linalg.norm(d[1:] - d[:-1], axis=1)))
    apart = float(np.median(np.linalg.norm(d - np.roll(d, len(d) // 2, axis=0), axis=1)))
    return neighbours > 0.5 * apart


def pose_hints(
    log: Log,
    *,
    rate: float | None = None,
    window: float | None = None,
    min_still: float | None = None,
    trim: float | None = None,
    threshold: float | None = None,
    found: PoseSet | None = None,
) -> list[PoseHint]:
    """The options that find more poses on ``log`` than the settings given, best first.

    Parameters
    ----------
    log : Log
        The log as loaded (its arrays are reused; nothing is read again).
    rate, window, min_still, trim, threshold
        The settings the poses were looked for with (as :func:`poses_from_log` takes them).
    found : PoseSet, optional
        What they found (None: nothing, or the detection refused the log).

    Returns
    -------
    list of PoseHint
        Each set of options that finds more distinct orientations than ``found``, the ones
        with a pose column first, then by orientations and poses; at most
        :data:`MAX_RETRIES` detections are run.
    """
    settings = {"window": window, "min_still": min_still, "trim": trim, "threshold": threshold}
    # a hint must find more distinct orientations than the settings given, and at least two
    base = max(1, 0 if found is None else _count(log, found)[1])
    hints: list[PoseHint] = []
    pose_like, devices = _label_columns(log)
    rows, note = None, ""
    if devices is not None:  # one device's rows: a pose column counted as one fit would see it
        name, kinds = devices
        rows = np.flatnonzero(np.asarray(log.labels[name]).astype(str) == kinds[0])
        note = f" (rows of {name} {kinds[0]})"
    for name in pose_like:
        if log.used.get("pose") == [name]:
            continue
        part = _subset(log, rows)
        used = {**log.used, "pose": [name]}
        labelled = dataclasses.replace(part, pose=part.labels[name], used=used)
        counted = _try(labelled, rate=rate)
        if counted is not None and counted[1] > base:
            hints.append(PoseHint({"pose_col": name}, f"--pose-col {name}", *counted, note))
    budget = min(MAX_RETRIES, RETRY_SAMPLES // max(log.n, 1))
    threshold_used = None if found is None or found.detection is None else found.detection
    for options, flags in _detection_options(log, rate, settings)[:budget]:
        merged = {"rate": rate, **settings, **options}
        counted = _try(log, **merged)
        if counted is not None and counted[1] > base:
            hints.append(PoseHint(options, flags, *counted))
    if threshold_used is not None and threshold is None and len(hints) < SHOWN:
        looser = 2.0 * threshold_used.threshold_std
        counted = _try(log, rate=rate, **{**settings, "threshold": looser})
        if counted is not None and counted[1] > base:
            hints.append(
                PoseHint({"threshold": looser}, f"--still-threshold {_number(looser)}", *counted)
            )
    if turns_slowly(log, rate=rate):
        counted = _try(log, rate=rate, poses="windows")
        if counted is not None and counted[1] > base:
            hints.append(PoseHint({"poses": "windows"}, "--poses windows", *counted))
    elif _rows_are_readings(log):
        counted = _try(_subset(log, rows), rate=rate, poses="samples")
        if counted is not None and counted[1] > base:
            hints.append(PoseHint({"poses": "samples"}, "--poses samples", *counted, note))
    order = sorted(
        range(len(hints)),
        key=lambda i: (
            "pose_col" not in hints[i].options,
            -hints[i].orientations,
            -hints[i].poses,
            # a guessed sample rate last among equals: a wrong one skews every duration
            "rate" in hints[i].options,
            i,
        ),
    )
    best: dict[frozenset[str] | str, PoseHint] = {}  # the best of each kind, every column
    for i in order:
        column = hints[i].options.get("pose_col")
        best.setdefault(
            column if isinstance(column, str) else frozenset(hints[i].options), hints[i]
        )
    return list(best.values())


def _subset(log: Log, rows: NDArray[np.intp] | None) -> Log:
    """``log`` restricted to ``rows`` (None: the whole log)."""
    if rows is None:
        return log

    def pick(x: NDArray[_S] | None) -> NDArray[_S] | None:
        return None if x is None else x[rows]

    return dataclasses.replace(
        log,
        accel=pick(log.accel),
        mag=pick(log.mag),
        gyro=pick(log.gyro),
        time=pick(log.time),
        pose=pick(log.pose),
        index=log.index[rows],
        segment=pick(log.segment),
        temperature=pick(log.temperature),
        labels={k: v[rows] for k, v in log.labels.items()},
    )


#: The advice for a log with neither time nor gyroscope whose rows are too few or too far
#: apart for still detection: a Magneto-style log of readings taken now and then.
SEPARATE_READINGS = (
    "for a log of separate readings turned by hand (no time column, a reading now and then, "
    "as Magneto and MotionCal record) use --poses samples (poses='samples'): each row is a "
    "pose; for a stream, give its sample rate with --rate HZ"
)


def pose_advice(log: Log, **settings: Any) -> str | None:
    """The advice for a message that too few poses were found: the best hints (:data:`SHOWN`)
    and, when the rows come from several devices, that a log must hold one; None when no
    looser setting finds more. ``settings``: as :func:`pose_hints` takes them."""
    hints = pose_hints(log, **settings)
    _, devices = _label_columns(log)
    parts = []
    if devices is not None:
        name, kinds = devices
        listed = ", ".join(kinds[:4]) + (", ..." if len(kinds) > 4 else "")
        parts.append(
            f"the rows come from {len(kinds)} devices (column {name!r}: {listed}): give each "
            "device its own log"
        )
    if hints:
        shown = hints[:SHOWN]
        lead = "other settings find more"
        if any("rate" in h.options for h in shown):
            lead += " (no time column: durations count samples)"
        parts.append(f"{lead}: {'; '.join(h.text() for h in shown)}")
    return "; ".join(parts) if parts else None
