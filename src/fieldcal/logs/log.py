"""A log's sensor data: the columns picked, rows with missing values handled, time in seconds.

Every value a calibration cannot use is refused here, naming its row and column: NaN, inf or
an empty field (unless dropped), a reading beyond :data:`LARGEST`, one column read as two
things (two sensors, or a sensor and the time), a second sensor under a name not understood,
time going backwards.

Time
----
The time column is read in seconds, milliseconds, microseconds or nanoseconds (from its name,
else from its typical step). The sample rate is :func:`sample_rate`: the number of steps over
their total length, leaving out the pauses of the logger. A step is a pause when it is longer
than :data:`PAUSE` typical steps, the typical step being the one that holds most of the log's
time (the time-weighted median step, to a factor of two). This is ``(samples - 1) / span`` for a
regular log, and stays right for a log whose samples come in bursts (two sensors on one clock:
several samples share a timestamp or come 1 ms apart, then a 40 ms gap), where the median step
would give the rate inside a burst.

A timestamp smaller than the previous one by more than a typical step is a reset of the clock:
an error naming the data row, or with ``split_on_reset=True`` the start of a new segment
(``Log.segment``). Each segment's time is then shifted to continue one mean step after the
previous segment's latest time, so the log's time increases across the resets; still detection
and the pose windows never cross a segment's boundary.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..limits import (
    LARGEST,  # checked here so the message names the row and column
    PLAUSIBLE_C,
)
from .columns import (
    SPELLINGS,
    explicit_columns,
    incomplete_sensors,
    label_columns,
    normalise,
    recognise_columns,
    sensor_like_triples,
)
from .drive_inputs import attitude_of, drive_inputs
from .readers import Table, read_table
from .rosbag import is_bag, read_bag

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["LARGEST", "PAUSE", "Log", "load_log", "sample_rate"]

Array = NDArray[np.float64]

#: A time step longer than this many typical steps is a pause of the logger, left out of the
#: sample rate. Bursts are at most a few typical steps apart, pauses (a logger writing its
#: buffer, a paused recording) far more.
PAUSE = 10.0

_ROLE_NAMES = {
    "accel": "the accelerometer",
    "mag": "the magnetometer",
    "gyro": "the gyroscope",
    "time": "the time",
    "pose": "the pose labels",
    "temperature": "the temperature",
}


#: Metadata keys naming the device, first match wins (lower case, spaces and dashes as ``_``).
DEVICE_KEYS = ("device", "device_id", "serial", "serial_number", "sn", "board", "board_id", "uid")


@dataclass
class Log:
    """A log's sensor data, ready for still detection and calibration.

    ``index`` maps each kept row to its data-row number in the file (0-based; rows with NaN
    are dropped only with ``drop_nan=True``), so positions are reported as the user sees them.
    ``time`` is in seconds from the first sample. ``segment`` is the segment number of each
    kept row when the time column was split at resets of the clock (``split_on_reset=True``),
    ``None`` for a log of one segment.
    """

    path: str
    accel: Array | None
    mag: Array | None
    gyro: Array | None
    time: Array | None
    pose: NDArray[np.generic] | None
    index: NDArray[np.int64]
    used: dict[str, list[str]]
    names: list[str]
    dropped: int = 0
    notes: list[str] = field(default_factory=list)
    segment: NDArray[np.int64] | None = None
    metadata: dict[str, str] = field(default_factory=dict)
    #: the die temperature of each kept row, °C (``temp``, ``temperature``, ``t_degc`` ...)
    temperature: Array | None = None
    #: the temperature column left out and why (``(name, why)``), when its values are unusable
    #: and the user asked to go on (``ignore_bad_temp``; reason ``temperature_ignored``)
    temperature_ignored: tuple[str, str] | None = None
    #: other columns that may label poses or devices (``shot``, ``position``, ``device``; see
    #: :func:`~fieldcal.logs.columns.label_columns`), each kept row's value: the advice when
    #: too few poses are found tries them
    labels: dict[str, NDArray[np.generic]] = field(default_factory=dict)
    #: what drives the magnetometer's interference term, per kept row: ``{"current": A}`` or
    #: ``{"throttle": 0-1}`` (:mod:`~fieldcal.logs.drive_inputs`); empty without such a column
    inputs: dict[str, Array] = field(default_factory=dict)
    #: the autopilot's attitude estimate of a flight log (n, 4), body → NED, scalar first
    attitude: Array | None = None

    @property
    def n(self) -> int:
        return len(self.index)

    @property
    def device(self) -> str | None:
        """The device id the log names in its metadata (:data:`DEVICE_KEYS`), else ``None``."""
        for key in DEVICE_KEYS:
            value = self.metadata.get(key, "").strip()
            if value:
                return value
        return None

    @property
    def rate(self) -> float | None:
        """Samples per second from the time column (:func:`sample_rate`); ``None`` without one."""
        return None if self.time is None else sample_rate(self.time, self.segment)

    def to_pandas(self) -> pd.DataFrame:
        """The log as a pandas DataFrame.

        Columns ``t`` (seconds), ``ax, ay, az``, ``mx, my, mz``, ``gx, gy, gz``, ``pose`` and
        ``segment``, those present; the index (``data_row``) is each row's data-row number in
        the file, counted from 1 as in fieldcal's messages. pandas is imported here: an
        :class:`InputError` says how to install it when it is missing.
        """
        try:
            pandas = importlib.import_module("pandas")
        except ImportError:
            raise InputError(
                "Log.to_pandas needs pandas, which is not installed; pip install pandas"
            ) from None
        columns: dict[str, NDArray[np.generic]] = {}
        if self.time is not None:
            columns["t"] = self.time
        for letter, values in (("a", self.accel), ("m", self.mag), ("g", self.gyro)):
            if values is not None:
                for j, axis in enumerate("xyz"):
                    columns[letter + axis] = values[:, j]
        if self.pose is not None:
            columns["pose"] = self.pose
        if self.segment is not None:
            columns["segment"] = self.segment
        index = pandas.Index(self.index + 1, name="data_row")
        return pandas.DataFrame(columns, index=index, copy=False)


def _typical_step(steps: Array) -> float:
    """The step that holds most of the time, to a factor of two: the power of two just above
    the time-weighted median of the positive steps (0 when no step is positive).

    Binning by the exponent keeps it O(n); a factor of two is all :data:`PAUSE` and the reset
    tolerance need.
    """
    positive = np.maximum(steps, 0.0)  # steps back and repeated times weigh nothing
    # the biased exponent field of each float64: x in [2**(e-1023), 2**(e-1022)), frexp's
    # exponent + 1022, read from the bits without frexp's arrays (and 0 for a zero)
    exponent = positive.view(np.int64) >> 52
    weight = np.bincount(exponent, weights=positive, minlength=2048)
    total = float(weight.sum())
    if not (total > 0 and math.isfinite(total)):
        return 0.0 if total == 0 else math.inf
    k = int(np.searchsorted(np.cumsum(weight), 0.5 * total))
    return math.ldexp(1.0, min(k, 2047) - 1022)


def _mean_step(steps: Array, typical: float | None = None) -> float:
    """Mean of the steps that are not pauses (:data:`PAUSE`); 0 when they span no time.
    ``typical``: :func:`_typical_step` of ``steps`` when already known."""
    typical = _typical_step(steps) if typical is None else typical
    if typical == 0:
        return 0.0
    kept = steps[steps <= PAUSE * typical]
    span = float(kept.sum())
    return span / kept.size if span > 0 and math.isfinite(span) else 0.0


def sample_rate(time: Array, segment: NDArray[np.int64] | None = None) -> float | None:
    """Samples per second of a time column (seconds): the steps' count over their total length,
    without the logger's pauses and without the steps across a segment's boundary.

    Robust to bursts (several samples at one timestamp, then a gap) and to duplicated
    timestamps; ``None`` when the time never advances. The pauses are found against the
    time-weighted median step, so they must take less than half the log's time.
    """
    time = np.asarray(time, dtype=np.float64)
    if time.size < 2:
        return None
    with np.errstate(over="ignore", invalid="ignore"):  # a span beyond floats: no rate
        steps = np.diff(time)
        if segment is not None:
            steps = steps[segment[1:] == segment[:-1]]
        step = _mean_step(steps)
    return 1.0 / step if step > 0 and math.isfinite(1.0 / step) else None


def _time_in_seconds(
    values: Array, name: str, path: str = "", typical: float | None = None
) -> tuple[Array, str | None]:
    """Seconds from a time column in s, ms, µs or ns (from the name, else from the mean step
    without pauses; ``typical``: :func:`_typical_step` of the column's steps when known)."""
    norm = normalise(name)
    scale = None
    for token, factor in (("ns", 1e-9), ("us", 1e-6), ("micros", 1e-6), ("ms", 1e-3)):
        if norm.endswith(token) or f"_{token}_" in norm or norm == token:
            scale = factor
    note = None
    with np.errstate(all="ignore"):  # a span beyond the float range is refused below
        if scale is None:
            # the mean step without pauses: a bursty log's median step can be 0 or 1 ms
            step = _mean_step(np.diff(values), typical) if values.size > 1 else 0.0
            # a sensor log between 0.5 Hz and 100 kHz: steps ≥ 1e5 are ns, from 2000 µs (ms
            # would be under 0.5 Hz, ns over 100 kHz), from 2 ms
            if step >= 1e5:
                scale, note = 1e-9, f"time column {name!r} read as nanoseconds"
            elif step >= 2000:
                scale, note = 1e-6, f"time column {name!r} read as microseconds"
            elif step >= 2:
                scale, note = 1e-3, f"time column {name!r} read as milliseconds"
            else:
                scale = 1.0
        seconds = (values - values[0]) * scale
    if not np.all(np.isfinite(seconds)):
        raise InputError(
            f"{path}: time column {name!r} spans more than floating point can hold; give the "
            "time in seconds (or choose another column with --time-col)"
        )
    return seconds, note


def _split_resets(
    time: Array,
    steps: Array,
    typical: float,
    index: NDArray[np.int64],
    name: str,
    path: str,
    split: bool,
) -> tuple[Array, NDArray[np.int64] | None, str | None]:
    """Time made to increase across resets of the clock, each row's segment (``None``: no
    reset) and a note; a reset is an :class:`InputError` unless ``split``.

    ``time`` is in seconds; ``steps`` and their ``typical`` step are the column's, in its own
    unit. A reset is a step back by more than a typical step (smaller steps back are jitter,
    e.g. two sensors' samples written slightly out of order, and are kept as they are).
    """
    resets = np.flatnonzero(steps < -typical)
    if resets.size == 0:
        return time, None, None
    first = int(resets[0])
    if not split:
        back = time[first] - time[first + 1]
        raise InputError(
            f"{path}: the time column {name!r} goes back by {back:.6g} s at data row "
            f"{index[first + 1] + 1} ({resets.size} such reset(s) of the clock); pass "
            "--split-on-reset to start a new segment at each, or fix the time column"
        )
    starts = np.concatenate([[0], resets + 1])
    segment = np.zeros(len(time), dtype=np.int64)
    segment[resets + 1] = 1
    np.cumsum(segment, out=segment)
    step = _mean_step(np.diff(time)[segment[1:] == segment[:-1]]) or 1.0
    low = np.minimum.reduceat(time, starts)
    high = np.maximum.reduceat(time, starts)
    # segment k starts one mean step after segment k-1's latest time
    shift = np.concatenate([[0.0], np.cumsum(high[:-1] + step - low[1:])])
    note = (
        f"the time column {name!r} restarts {resets.size} time(s) (first at data row "
        f"{index[first + 1] + 1}): {resets.size + 1} segments, each continuing the time of "
        "the one before"
    )
    return time + shift[segment], segment, note


def _check_roles(path: str, used: dict[str, list[str]]) -> None:
    """One column cannot be two things (``--accel-cols mx,my,mz`` beside the recognised mag)."""
    owner: dict[str, str] = {}
    for role, cols in used.items():
        for c in cols:
            if c in owner and owner[c] != role:
                raise InputError(
                    f"{path}: column {c!r} is used for {_ROLE_NAMES[owner[c]]} and for "
                    f"{_ROLE_NAMES[role]}; give each its own columns (--accel-cols, --mag-cols, "
                    "--gyro-cols, --time-col, --pose-col)"
                )
            owner[c] = role
        if len(set(cols)) != len(cols):
            raise InputError(
                f"{path}: {_ROLE_NAMES[role]} columns {','.join(cols)} repeat a column; name "
                "three different columns x,y,z"
            )


def _check_second_sensor(table: Table, used: dict[str, list[str]]) -> None:
    """Only one of accelerometer and magnetometer recognised while numeric columns x,y,z of
    another look like a sensor: refused rather than fitted as a one-sensor log."""
    found = [role for role in ("accel", "mag") if role in used]
    if len(found) != 1:
        return
    taken = {c for cols in used.values() for c in cols}
    numeric = [n for n in table.names if table.columns[n].dtype.kind in "fiu"]
    triples = sensor_like_triples(numeric, exclude=taken)
    if not triples:
        return
    role, other = found[0], "mag" if found[0] == "accel" else "accel"
    cols, candidate = ",".join(used[role]), ",".join(triples[0])
    flag = {"accel": "--accel-cols", "mag": "--mag-cols"}
    raise InputError(
        f"{table.path}: only {_ROLE_NAMES[role]} was recognised ({cols}), but {candidate} "
        f"look like another sensor's x,y,z (columns: {_listing(table.names, 8)}); pass "
        f"{flag[other]} {candidate} if they are {_ROLE_NAMES[other]}, or {flag[role]} {cols} "
        f"to calibrate {_ROLE_NAMES[role]} alone (names understood: {SPELLINGS})"
    )


def _check_values(
    table: Table, used: dict[str, list[str]], data: dict[str, Array], index: NDArray[np.int64]
) -> None:
    """Readings whose square overflows are refused, naming the first one's row and column
    (``index``: the data row of each kept row)."""
    for role, values in data.items():
        # max and min first: no (n, 3) temporary for the everyday log with no such value
        if values.size == 0 or (-LARGEST <= values.min() and values.max() <= LARGEST):
            continue
        i, j = np.argwhere(np.abs(values) > LARGEST)[0]
        raise InputError(
            f"{table.path}: column {used[role][j]!r} has the value {values[i, j]:.3g} at "
            f"data row {index[i] + 1}; readings beyond {LARGEST:.0e} are too large to square "
            "in floating point: give them in a smaller unit (divide the column by a power of "
            "ten)"
        )


def _first_bad(values: dict[str, Array], names: dict[str, list[str]]) -> tuple[int, str]:
    """Data row (0-based) and column of the first NaN or inf."""
    best = (np.iinfo(np.int64).max, "")
    for role, array in values.items():
        bad = np.argwhere(~np.isfinite(array))
        if bad.size:
            i, j = bad[0]
            best = min(best, (int(i), names[role][j]))
    return best


def _listing(names: Sequence[str], limit: int = 12) -> str:
    shown = ", ".join(n if len(n) <= 30 else n[:30] + "..." for n in names[:limit])
    return shown + (f" ... ({len(names)} columns)" if len(names) > limit else "")


def load_log(
    path: str | Path | Table,
    *,
    accel_cols: str | Sequence[str] | None = None,
    mag_cols: str | Sequence[str] | None = None,
    gyro_cols: str | Sequence[str] | None = None,
    time_col: str | None = None,
    pose_col: str | None = None,
    drop_nan: bool = False,
    split_on_reset: bool = False,
    need: Sequence[str] = ("accel", "mag"),
    temp_col: str | None = None,
    sensors: str | None = None,
    ignore_bad_temp: bool = False,
    **reading: Any,
) -> Log:
    """Read a log and pick its sensor columns.

    Parameters
    ----------
    path : path or Table
        The log file (see :func:`~fieldcal.logs.readers.read_table`), or a table already read.
    accel_cols, mag_cols, gyro_cols : "x,y,z" names or a sequence of three, optional
        Explicit columns; by default they are recognised by name (see :func:`recognise_columns`).
        When only one of accelerometer and magnetometer is recognised and other numeric
        columns look like a sensor's x,y,z (``tx,ty,tz``, ``X,Y,Z``), the log is refused, naming
        them; explicit sensor columns (either option) skip that check.
    time_col, pose_col : str, optional
        Explicit time (seconds, or ms/µs/ns recognised from the name or step) and pose-label
        columns; ``time``/``t``/``timestamp`` and ``pose``/``label`` are recognised by default.
    drop_nan : bool
        Drop rows with NaN or inf in a used column instead of refusing them.
    split_on_reset : bool
        Where the time goes back (a reset of the logger's clock), start a new segment
        (``Log.segment``) instead of refusing the log; each segment's time continues after
        the one before.
    need : sequence of str
        The roles of which at least one must be found (by default accelerometer or magnetometer).
    temp_col : str, optional
        The temperature column (°C); ``temp``, ``temperature``, ``t_degc`` ... are recognised.
        One with NaN/inf or values outside -80..200 °C (kelvins, a wrong column) is an error
        when named here; one recognised by name is left out, with a note and the reason code
        ``temperature_ignored``.
    ignore_bad_temp : bool
        Leave an unusable ``temp_col`` out (with the note and the reason code) instead of
        refusing the log.
    sensors : {None, "accel", "mag", "both"}
        Which of accelerometer and magnetometer to read: ``"accel"`` or ``"mag"`` alone (the
        other's columns are left out), ``"both"`` (either missing is an error), or None:
        those recognised, but a sensor with two of its axes recognised and the third missing
        (``ay, az`` without ``ax``) is an error naming the column, unless the column options
        name the other sensor only (``--accel-cols`` alone: the accelerometer is wanted).
    **reading
        Options of the file reader, passed on when not ``None``: ``decimal`` and
        ``on_progress`` for text logs, ``imu_topic`` and ``mag_topic`` (and ``on_progress``)
        for ROS bags (:func:`fieldcal.logs.rosbag.read_bag`); ignored for a table already read.
    """
    _check_load_options(drop_nan, split_on_reset, need, time_col, pose_col)
    _check_choices(temp_col, sensors)
    current_col, throttle_col = reading.pop("current_col", None), reading.pop("throttle_col", None)
    table = _open_table(path, reading)
    used = _pick_columns(table, accel_cols, mag_cols, gyro_cols, time_col, pose_col, need, temp_col)
    used = _chosen_sensors(table, used, sensors, accel_cols is not None, mag_cols is not None)
    data = _sensor_arrays(table, used)
    time = table.numeric(used["time"][0]) if "time" in used else None
    pose = table.columns[used["pose"][0]] if "pose" in used else None
    data, time, pose, index, n_bad = _finite_rows(table, used, data, time, pose, drop_nan)
    _check_values(table, used, data, index)
    notes: list[str] = list(getattr(table, "notes", ()))
    segment = None
    if time is not None:
        time, segment, time_notes = _time_axis(time, used["time"][0], index, table, split_on_reset)
        notes += time_notes
    temperature, ignored = _temperature(table, used, index, temp_col, ignore_bad_temp, notes)
    inputs, input_notes = drive_inputs(table, index, current_col, throttle_col)
    notes += input_notes
    return Log(
        path=table.path,
        accel=data.get("accel"),
        mag=data.get("mag"),
        gyro=data.get("gyro"),
        time=time,
        pose=pose,
        index=index,
        used=used,
        names=table.names,
        dropped=n_bad,
        notes=notes,
        segment=segment,
        metadata=dict(getattr(table, "metadata", {})),
        temperature=temperature,
        temperature_ignored=ignored,
        labels=_labels(table, used, index),
        inputs=inputs,
        attitude=attitude_of(table, index),
    )


def _sensor_arrays(table: Table, used: dict[str, list[str]]) -> dict[str, Array]:
    """One (n, 3) array per sensor, stacked once (rows are selected later, only when some are
    dropped)."""
    return {
        role: np.column_stack([table.numeric(c) for c in used[role]])
        for role in ("accel", "mag", "gyro")
        if role in used
    }


def _labels(
    table: Table, used: dict[str, list[str]], index: NDArray[np.int64]
) -> dict[str, NDArray[np.generic]]:
    """The text columns no role took (a shot name, a device), in the rows kept."""
    taken = [c for cols in used.values() for c in cols]
    return {
        name: table.columns[name] if index.size == table.n_rows else table.columns[name][index]
        for name in label_columns(table.names, exclude=taken)
    }


def _check_choices(temp_col: object, sensors: object) -> None:
    """``temp_col`` a column name and ``sensors`` one of the choices, else a one-line error."""
    if temp_col is not None and not isinstance(temp_col, str):
        raise InputError(f"temp_col must be a column name, got {temp_col!r}")
    if sensors not in (None, "accel", "mag", "both"):
        raise InputError(f"sensors must be 'accel', 'mag' or 'both', got {sensors!r}"[:200])


def _temperature(
    table: Table,
    used: dict[str, list[str]],
    index: NDArray[np.int64],
    temp_col: str | None,
    ignore_bad_temp: bool,
    notes: list[str],
) -> tuple[Array | None, tuple[str, str] | None]:
    """The temperature column's values in the rows kept, or ``None`` and ``(column, why)`` when
    they cannot be temperatures in °C (a column named by ``temp_col`` is then refused, unless
    ``ignore_bad_temp``; one recognised by name is ignored with a note)."""
    if "temperature" not in used:
        return None, None
    name = used["temperature"][0]
    temperature = table.numeric(name)[index]
    why = unusable_temperature(temperature)
    if why is not None:
        if temp_col is not None and not ignore_bad_temp:
            raise InputError(
                f"the temperature column {name!r} {why}; give it in °C with finite values "
                "(or pass --ignore-bad-temp to calibrate without temperature terms)"
            )
        notes.append(f"temperature column {name!r} {why}: ignored")
        return None, (name, why)
    return temperature, None


def unusable_temperature(values: Array) -> str | None:
    """Why a temperature column cannot give temperature terms (it "has ..."), or None."""
    finite = np.isfinite(values)
    if not finite.any():
        return "has no finite value (all NaN or inf)"
    if not finite.all():
        return f"has {int((~finite).sum())} of {values.size} values NaN or inf"
    low, high = float(values.min()), float(values.max())
    if low >= 190.0 and high <= 420.0:  # a die between -83 and 147 °C, in kelvins
        return f"reads {low:.4g} to {high:.4g}: kelvins, not °C (subtract 273.15)"
    if low < PLAUSIBLE_C[0] or high > PLAUSIBLE_C[1]:
        return (
            f"reads {low:.4g} to {high:.4g}, outside the {PLAUSIBLE_C[0]:g}..{PLAUSIBLE_C[1]:g} °C "
            "a sensor's die can have"
        )
    return None


def _check_load_options(
    drop_nan: object,
    split_on_reset: object,
    need: Sequence[str],
    time_col: object,
    pose_col: object,
) -> None:
    """The one-line errors for options of the wrong kind."""
    if not isinstance(drop_nan, (bool, np.bool_)):
        raise InputError(f"drop_nan must be True or False, got {drop_nan!r}")
    if not isinstance(split_on_reset, (bool, np.bool_)):
        raise InputError(f"split_on_reset must be True or False, got {split_on_reset!r}")
    if isinstance(need, str) or not all(role in ("accel", "mag", "gyro") for role in need):
        raise InputError(f"need must be a sequence of 'accel', 'mag', 'gyro'; got {need!r}")
    for label, name in (("time_col", time_col), ("pose_col", pose_col)):
        if name is not None and not isinstance(name, str):
            raise InputError(f"{label} must be a column name, got {name!r}")


def _open_table(path: str | Path | Table, reading: dict[str, Any]) -> Table:
    """The table of ``path`` (a ROS bag, a file by its suffix, or a table already read)."""
    options = {k: v for k, v in reading.items() if v is not None}
    topics = {k: options.pop(k) for k in ("imu_topic", "mag_topic") if k in options}
    if isinstance(path, Table):
        return path
    if is_bag(path):  # before read_table: a rosbag2 bag is a folder
        return read_bag(path, on_progress=options.get("on_progress"), **topics)
    if topics:
        raise InputError(
            f"{path}: --imu-topic/--mag-topic are for ROS bags (.bag, .mcap, .db3 or a rosbag2 "
            "folder); leave them out for this log"
        )
    return read_table(path, **options)


def _pick_columns(
    table: Table,
    accel_cols: str | Sequence[str] | None,
    mag_cols: str | Sequence[str] | None,
    gyro_cols: str | Sequence[str] | None,
    time_col: str | None,
    pose_col: str | None,
    need: Sequence[str],
    temp_col: str | None = None,
) -> dict[str, list[str]]:
    """The columns of each role: given, else recognised by name; checked."""
    guessed = recognise_columns(table.names)
    explicit = {
        "accel": explicit_columns(accel_cols),
        "mag": explicit_columns(mag_cols),
        "gyro": explicit_columns(gyro_cols),
        "time": None if time_col is None else [time_col],
        "pose": None if pose_col is None else [pose_col],
        "temperature": None if temp_col is None else [temp_col],
    }
    used: dict[str, list[str]] = {}
    for role in ("accel", "mag", "gyro", "time", "pose", "temperature"):
        cols = explicit[role] if explicit[role] is not None else guessed.get(role)
        if cols is None:
            continue
        missing = [c for c in cols if c not in table.columns]
        if missing:
            raise InputError(
                f"{table.path}: no column {missing[0]!r} (for {role}); columns found: "
                f"{_listing(table.names)}"
            )
        used[role] = cols
    _check_roles(table.path, used)
    if not any(role in used for role in need):
        raise InputError(
            f"{table.path}: no accelerometer or magnetometer columns recognised among "
            f"{_listing(table.names)}; name them ax,ay,az,mx,my,mz or pass --accel-cols/--mag-cols"
        )
    if explicit["accel"] is None and explicit["mag"] is None:
        _check_second_sensor(table, used)
    return used


def _chosen_sensors(
    table: Table, used: dict[str, list[str]], sensors: str | None, accel: bool, mag: bool
) -> dict[str, list[str]]:
    """The sensors to read (``sensors`` of :func:`load_log`): one left out, or a sensor with
    a missing axis refused, naming the column."""
    flags = {"accel": "--accel-cols", "mag": "--mag-cols"}
    if sensors in ("accel", "mag"):
        if sensors not in used:
            raise InputError(
                f"{table.path}: --sensors {sensors} but no {_ROLE_NAMES[sensors][4:]} columns "
                f"recognised among {_listing(table.names, 8)}; name them with {flags[sensors]}"
            )
        other = "mag" if sensors == "accel" else "accel"
        return {role: cols for role, cols in used.items() if role != other}
    wanted = [] if accel != mag else ["accel", "mag"]  # one sensor's columns given: that one
    for role, (names, axis) in incomplete_sensors(table.names, used).items():
        if role not in wanted:
            continue
        alone = "mag" if role == "accel" else "accel"
        rest = f", or calibrate {_ROLE_NAMES[alone]} alone with --sensors {alone}"
        raise InputError(
            f"{table.path}: {_ROLE_NAMES[role]}'s {axis} column is missing ({', '.join(names)} "
            f"are recognised, no {axis} beside them); name the three with {flags[role]} X,Y,Z"
            + (rest if alone in used else "")
        )
    if sensors == "both":
        for role in ("accel", "mag"):
            if role not in used:
                raise InputError(
                    f"{table.path}: --sensors both but no {_ROLE_NAMES[role][4:]} columns "
                    f"recognised among {_listing(table.names, 8)}; name them with {flags[role]}"
                )
    return used


def _finite_rows(
    table: Table,
    used: dict[str, list[str]],
    data: dict[str, Array],
    time: Array | None,
    pose: NDArray[np.generic] | None,
    drop_nan: bool,
) -> tuple[dict[str, Array], Array | None, NDArray[np.generic] | None, NDArray[np.int64], int]:
    """The rows whose used values are all finite: refused, or dropped with ``drop_nan``.
    Returns the data, time and pose of those rows, their row numbers and how many dropped."""
    # min and max are NaN or inf when any value is: the everyday log (every value finite)
    # needs no (n, 3) mask and no row selection
    arrays = [*data.values(), *([] if time is None else [time])]
    if all(np.isfinite(x.min()) and np.isfinite(x.max()) for x in arrays if x.size):
        finite, n_bad = None, 0
    else:
        finite = np.ones(table.n_rows, dtype=bool)
        for values in data.values():
            finite &= np.isfinite(values).all(axis=1)
        if time is not None:
            finite &= np.isfinite(time)
        n_bad = table.n_rows - int(np.count_nonzero(finite))
    if n_bad and not drop_nan:
        checked = dict(data)
        if time is not None:
            checked["time"] = time[:, None]
        row, column = _first_bad(checked, used)
        raise InputError(
            f"{table.path}: {n_bad} row(s) have NaN, inf or empty values (first at data row "
            f"{row + 1}, column {column!r}); pass --drop-nan to drop them, or clean the file"
        )
    if finite is not None:
        index = np.flatnonzero(finite)
        data = {role: values[finite] for role, values in data.items()}
        time = None if time is None else time[finite]
        pose = None if pose is None else pose[finite]
    else:
        index = np.arange(table.n_rows, dtype=np.int64)
    if index.size == 0:
        raise InputError(
            f"{table.path}: no data rows"
            + (" left after dropping those with NaN, inf or empty values" if n_bad else "")
            + "; give a log with readings"
        )
    return data, time, pose, index, n_bad


def _time_axis(
    time: Array, name: str, index: NDArray[np.int64], table: Table, split_on_reset: bool
) -> tuple[Array, NDArray[np.int64] | None, list[str]]:
    """The time column in seconds, split at resets (or refused there); the notes it leaves."""
    with np.errstate(over="ignore", invalid="ignore"):  # a span too wide is refused below
        steps = np.diff(time)  # in the column's unit; its typical step found once
        typical = _typical_step(steps)
    seconds, note = _time_in_seconds(time, name, table.path, typical)
    time, segment, split = _split_resets(
        seconds, steps, typical, index, name, table.path, bool(split_on_reset)
    )
    del steps
    return time, segment, [n for n in (note, split) if n]
