"""Flight logs (PX4 ULog, ArduPilot DataFlash) as one table on one time base.

A flight-log reader (:mod:`.ulog`, :mod:`.dataflash`) gives :class:`Stream` objects: one
sensor instance or signal, its own timestamps (seconds on the autopilot's clock), its values,
the unit and frame the log's own definitions give (uORB message definitions, DataFlash
``FMT``/``FMTU``). :func:`flight_table` puts them on one time base, the chosen magnetometer's
samples (the sensor the interference term is about; the accelerometer's when the log has no
magnetometer), dropping the samples outside the span every core sensor covers:

- accelerometer, gyroscope, temperature, current, voltage and throttle are interpolated
  linearly at those times (they are sampled at least as fast, or change slowly);
- the attitude quaternion is interpolated componentwise after its sign is made continuous,
  then normalised (a step of a few degrees between samples: the error is far below a degree);
- GPS fixes give one position (the median of the 3-D fixes) in the table's metadata
  (``gps_location``: ``LAT,LON,ALT_M``), used as ``--location`` is, for the World Magnetic Model.

Columns: ``t`` (s from the first row), ``ax ay az``, ``gx gy gz``, ``mx my mz``, ``temp``
(°C), ``current`` (A), ``voltage`` (V), ``throttle`` (0-1), ``attitude_qw`` ... ``attitude_qz``
(body → NED, Hamilton, scalar first). Every stream's unit, frame and source is written in the
table's notes (``docs/flight-logs.md``).
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .raw_table import Table

__all__ = [
    "ATTITUDE",
    "FlightLog",
    "Stream",
    "choose",
    "flight_table",
    "info_lines",
    "median_location",
    "optional_module",
    "stream",
    "unreadable",
]

Array = NDArray[np.float64]

#: Names of the attitude quaternion's columns (body → NED, scalar first).
ATTITUDE = ("attitude_qw", "attitude_qx", "attitude_qy", "attitude_qz")
_COLUMNS = {
    "accel": ("ax", "ay", "az"),
    "gyro": ("gx", "gy", "gz"),
    "mag": ("mx", "my", "mz"),
    "temperature": ("temp",),
    "current": ("current",),
    "voltage": ("voltage",),
    "throttle": ("throttle",),
    "attitude": ATTITUDE,
}
#: Fewest samples a stream needs to be used.
FEWEST = 20


@dataclass(frozen=True)
class Stream:
    """One signal of a flight log: ``values`` (n,) or (n, k) at ``time`` (s, the log's clock).

    ``source`` names the log's topic or message and instance (``sensor_mag[1]``, ``MAG[0]``);
    ``unit`` and ``frame`` are those the log defines; ``note`` says what was done to it.
    """

    role: str
    source: str
    instance: int
    time: Array
    values: Array
    unit: str
    frame: str = ""
    note: str = ""

    @property
    def rate(self) -> float:
        span = float(self.time[-1] - self.time[0]) if len(self.time) > 1 else 0.0
        return (len(self.time) - 1) / span if span > 0 else 0.0


@dataclass(frozen=True)
class FlightLog:
    """Everything a flight log holds that fieldcal reads: every candidate stream per role
    (all instances), the log's own description, and what it says about itself."""

    path: str
    kind: str
    streams: tuple[Stream, ...]
    metadata: dict[str, str] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    def of(self, role: str) -> list[Stream]:
        """The usable streams of ``role`` (at least :data:`FEWEST` samples), in the reader's
        order of preference."""
        return [s for s in self.streams if s.role == role and len(s.time) >= FEWEST]


def choose(log: FlightLog, role: str, instance: int | None, flag: str) -> Stream | None:
    """The stream of ``role``: instance ``instance`` when given (an error naming the
    instances the log holds when it has not that one), else the reader's first choice."""
    streams = log.of(role)
    if instance is None:
        return streams[0] if streams else None
    found = [s for s in streams if s.instance == instance]
    if not found:
        have = sorted({s.instance for s in streams})
        listing = ", ".join(map(str, have)) if have else "none"
        raise InputError(
            f"{log.path}: no {role} instance {instance} with data (instances: {listing}); "
            f"pick one with {flag} N, or run 'fieldcal info {log.path}'"
        )
    return found[0]


def _interpolate(stream: Stream, at: Array) -> Array:
    values = stream.values.reshape(len(stream.time), -1)
    order = np.argsort(stream.time, kind="stable")
    t, values = stream.time[order], values[order]
    if stream.role == "attitude":  # q and -q are one rotation: make the sign continuous
        flips = np.cumsum(np.r_[0, np.sum(values[1:] * values[:-1], axis=1) < 0]) % 2
        values = np.where(flips[:, None] == 1, -values, values)
    out = np.column_stack([np.interp(at, t, v) for v in values.T])
    if stream.role == "attitude":
        out /= np.linalg.norm(out, axis=1, keepdims=True)
    return out


def flight_table(log: FlightLog, *, mag: int | None = None, imu: int | None = None) -> Table:
    """The log's chosen streams as one :class:`Table` on the magnetometer's time base.

    Parameters
    ----------
    log : FlightLog
    mag, imu : int, optional
        The magnetometer and IMU instances (``--mag N``, ``--imu N``); the reader's first
        choice by default (the primary sensor, the best-sampled raw topic).

    Returns
    -------
    Table
        Columns as the module docstring lists them; ``notes`` each stream's source, unit and
        frame; ``metadata`` the log's (``location`` from the GPS, ``log_format`` ...).
    """
    chosen: dict[str, Stream] = {}
    for role, instance, flag in (
        ("mag", mag, "--mag"),
        ("accel", imu, "--imu"),
        ("gyro", imu, "--imu"),
    ):
        stream = choose(log, role, instance, flag)
        if stream is not None:
            chosen[role] = stream
    # the IMU's temperature when logged (an IMU without one is no error)
    temps = [s for s in log.of("temperature") if imu is None or s.instance == imu]
    # a temperature that never moves by a hundredth of a kelvin is a placeholder (a simulator
    # logs 0.0): no thermometer, not a board held at one temperature
    temps = [s for s in temps if np.ptp(s.values) >= 0.01]
    if temps:
        chosen["temperature"] = temps[0]
    for role in ("current", "voltage", "throttle", "attitude"):
        stream = choose(log, role, None, "")
        if stream is not None:
            chosen[role] = stream
    if "mag" not in chosen and "accel" not in chosen:
        raise InputError(
            f"{log.path}: no accelerometer or magnetometer with {FEWEST} samples or more; "
            f"run 'fieldcal info {log.path}' to see what the log holds"
        )
    base = chosen.get("mag") or chosen["accel"]
    core = [chosen[r] for r in ("mag", "accel", "gyro") if r in chosen]
    start = max(float(s.time.min()) for s in core)
    stop = min(float(s.time.max()) for s in core)
    at = np.unique(base.time[(base.time >= start) & (base.time <= stop)])
    if len(at) < FEWEST:
        raise InputError(
            f"{log.path}: the sensors' recordings overlap in {len(at)} samples only; give a log "
            "where the IMU and the magnetometer are logged together"
        )
    names: list[str] = ["t"]
    columns: dict[str, NDArray[np.generic]] = {"t": at - at[0]}
    notes = list(log.notes)
    notes.append(
        f"{log.kind}: {len(at)} rows on the time base of {base.source} "
        f"({base.rate:.3g} Hz), the other streams interpolated linearly"
    )
    for role, stream in chosen.items():
        values = _interpolate(stream, at)
        for j, name in enumerate(_COLUMNS[role]):
            names.append(name)
            columns[name] = values[:, j]
        where = f", {stream.frame}" if stream.frame else ""
        extra = f"; {stream.note}" if stream.note else ""
        notes.append(
            f"{role}: {stream.source} ({stream.unit}{where}, {len(stream.time)} samples, "
            f"{stream.rate:.3g} Hz){extra}"
        )
    metadata = dict(log.metadata)
    metadata["log_format"] = log.kind
    metadata["mag_unit"] = chosen["mag"].unit if "mag" in chosen else ""
    if "mag" in chosen:
        metadata["mag_instance"] = str(chosen["mag"].instance)
    if "accel" in chosen:  # "body ...": calibrated by the autopilot (the fit may hold it)
        metadata["accel_frame"] = chosen["accel"].frame
    return Table(log.path, names, columns, notes=notes, metadata=metadata)


def info_lines(log: FlightLog) -> list[str]:
    """What ``fieldcal info LOG`` prints: each role's streams with instance, source, samples,
    rate, unit and frame; the first of each role marked as the default."""
    lines = [f"{log.path}: {log.kind}"]
    for key in ("gps_location", "date", "vehicle", "firmware"):
        if key in log.metadata:
            lines.append(f"  {key}: {log.metadata[key]}")
    seen: set[str] = set()
    roles = list(_COLUMNS)
    for stream in sorted(log.streams, key=lambda s: roles.index(s.role)):
        default = stream.role not in seen and len(stream.time) >= FEWEST
        if default:
            seen.add(stream.role)
        span = float(stream.time[-1] - stream.time[0]) if len(stream.time) > 1 else 0.0
        frame = f", {stream.frame}" if stream.frame else ""
        lines.append(
            f"  {stream.role:<11} instance {stream.instance}  {stream.source:<28} "
            f"{len(stream.time):>7} samples  {stream.rate:8.3g} Hz  {span:8.1f} s  "
            f"{stream.unit}{frame}" + ("  (default)" if default else "")
        )
    lines += [f"  note: {n}" for n in log.notes]
    return lines


def stream(
    role: str,
    source: str,
    instance: int,
    time: Sequence[float] | Array,
    values: Sequence[float] | Array,
    unit: str,
    frame: str = "",
    note: str = "",
) -> Stream | None:
    """A :class:`Stream` of the finite samples of ``values``; ``None`` when none is left."""
    t = np.asarray(time, dtype=float)
    v = np.asarray(values, dtype=float)
    if len(t) == 0 or len(v) != len(t):
        return None
    keep = np.isfinite(t) & np.isfinite(v.reshape(len(t), -1)).all(axis=1)
    if not keep.any():
        return None
    return Stream(role, source, instance, t[keep], v[keep], unit, frame, note)


def median_location(lat: Array, lon: Array, alt: Array) -> str | None:
    """``LAT,LON,ALT_M`` of the median fix (``None`` without a plausible fix)."""
    ok = (
        np.isfinite(lat)
        & np.isfinite(lon)
        & (np.abs(lat) <= 90)
        & (np.abs(lon) <= 180)
        & ~((lat == 0) & (lon == 0))
    )
    if not ok.any():
        return None
    alt_ok = alt[ok][np.isfinite(alt[ok])]
    height = float(np.median(alt_ok)) if alt_ok.size else 0.0
    return f"{float(np.median(lat[ok])):.6f},{float(np.median(lon[ok])):.6f},{height:.1f}"


def optional_module(name: str, install: str) -> ModuleType:
    """The optional extra ``name`` (a flight log's reader), imported when such a file is read;
    the one-line ``install`` advice when it is missing."""
    try:
        return importlib.import_module(name)
    except ImportError:
        raise InputError(install) from None


def unreadable(path: Path, exc: BaseException, what: str, fix: str) -> InputError:
    """The one-line error for a file a reader library could not read (its own exceptions
    are many and bare): the file, what it should be, the library's reason, the fix."""
    reason = " ".join(str(exc).split())[:120] or type(exc).__name__
    return InputError(f"{path}: not a readable {what} ({reason}); {fix}")
