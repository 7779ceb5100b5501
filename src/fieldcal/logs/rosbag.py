"""Reading ROS bags: sensor_msgs/Imu and sensor_msgs/MagneticField topics as a log :class:`Table`.

A ROS 1 ``.bag`` file, a rosbag2 folder (``metadata.yaml`` beside ``.db3`` or ``.mcap`` files)
or a single rosbag2 ``.db3``/``.mcap`` file is read with `rosbags
<https://gitlab.com/ternaris/rosbags>`_ (pure Python, loaded only when a bag is read). The
result has the columns a log reader gives: ``t`` (seconds, from the header stamps), ``ax ay az``
(``linear_acceleration``), ``gx gy gz`` (``angular_velocity``) and ``mx my mz``
(``magnetic_field``, Tesla as recorded).

The two topics come at different rates, so they are matched by header stamp: one row per
message of the slower topic, paired with the nearest message of the other; a pair further
apart than half the slower topic's period is dropped and counted in the notes (see
``docs/ros.md``).

Speed: the messages' bytes are decoded with numpy at fixed offsets (the fields of these
messages sit at fixed places after the header's ``frame_id``), a batch at a time; the first
message of every batch is also decoded by rosbags' own deserialiser and must agree, and a
batch that does not fit the layout goes through the deserialiser message by message.
"""

from __future__ import annotations

import importlib
import math
import os
import stat
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from itertools import compress, islice
from operator import attrgetter, itemgetter
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .readers import Table

__all__ = ["IMU", "MAGNETIC_FIELD", "VECTOR3_STAMPED", "is_bag", "read_bag"]

Array = NDArray[np.float64]
Ints = NDArray[np.int64]

IMU = "sensor_msgs/msg/Imu"
MAGNETIC_FIELD = "sensor_msgs/msg/MagneticField"
#: Older drivers publish the magnetometer as a stamped vector: read when named with mag_topic.
VECTOR3_STAMPED = "geometry_msgs/msg/Vector3Stamped"

_INSTALL = "reading ROS bags needs rosbags; pip install 'fieldcal[ros]'"
_WHAT = "a ROS bag (a ROS 1 .bag file, a rosbag2 folder, or a rosbag2 .mcap/.db3 file)"
_ROS1_MAGIC = b"#ROSBAG V2.0\n"
_MCAP_MAGIC = b"\x89MCAP0\r\n"
_SQLITE_MAGIC = b"SQLite format 3\x00"
_STORAGE = (".mcap", ".db3")

#: Messages decoded at once: bounds the memory of the joined bytes (~300 bytes a message).
BATCH = 65536

_NS = 1_000_000_000

# the parts of rosbags' (connection, receive time, bytes) and of a connection
_CONN, _TIME, _RAW, _TOPIC = itemgetter(0), itemgetter(1), itemgetter(2), attrgetter("topic")


@dataclass(frozen=True)
class _Layout:
    """Where a message's fields sit, in bytes from the end of the header's ``frame_id`` (in
    CDR rounded up to 8 bytes from the payload's start: the float64 that follows is aligned;
    ROS 1 packs without padding). ``size``: the bytes from there to the end.

    ``vectors``: (message field, offset, columns). ``absent``: (covariance field, offset of
    its first element, columns) -- sensor_msgs/Imu marks a field the sensor does not give with
    covariance[0] = -1.
    """

    size: int
    vectors: tuple[tuple[str, int, tuple[str, str, str]], ...]
    absent: tuple[tuple[str, int, tuple[str, str, str]], ...] = ()


# Imu: orientation (4 float64), orientation_covariance (9), angular_velocity (3),
# angular_velocity_covariance (9), linear_acceleration (3), linear_acceleration_covariance (9).
_LAYOUTS = {
    IMU: _Layout(
        size=37 * 8,
        vectors=(
            ("linear_acceleration", 200, ("ax", "ay", "az")),
            ("angular_velocity", 104, ("gx", "gy", "gz")),
        ),
        absent=(
            ("linear_acceleration_covariance", 224, ("ax", "ay", "az")),
            ("angular_velocity_covariance", 128, ("gx", "gy", "gz")),
        ),
    ),
    MAGNETIC_FIELD: _Layout(size=12 * 8, vectors=(("magnetic_field", 0, ("mx", "my", "mz")),)),
    VECTOR3_STAMPED: _Layout(size=3 * 8, vectors=(("vector", 0, ("mx", "my", "mz")),)),
}

_ORDER = ("t", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz")


# ---------------------------------------------------------------------------------------------
# What is a bag


def is_bag(path: str | Path) -> bool:
    """Whether ``path`` is a ROS bag :func:`read_bag` should read (never raises).

    A ROS 1 ``.bag`` file (or any file starting with ``#ROSBAG V2.0``, such as an unfinished
    ``.bag.active``), a rosbag2 folder (``metadata.yaml``, or ``.db3``/``.mcap`` files inside),
    or a single ``.mcap``/``.db3`` file. Special files are not opened (a FIFO would block).

    Parameters
    ----------
    path : str or Path
        A file or folder.

    Returns
    -------
    bool
        True for a bag (also a broken one with a bag's suffix, so that :func:`read_bag` can
        say what is wrong with it); False for anything else, a missing path included.
    """
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
        if stat.S_ISDIR(mode):
            return (path / "metadata.yaml").is_file() or any(
                p.suffix.lower() in _STORAGE for p in path.iterdir()
            )
        if not stat.S_ISREG(mode):
            return False
        if path.suffix.lower() in (".bag", *_STORAGE):
            return True
        with path.open("rb") as handle:
            head = handle.read(16)
    except OSError:
        return False
    return head.startswith((_ROS1_MAGIC, _MCAP_MAGIC))


def _locate(path: Path) -> tuple[bool, Path, list[str]]:
    """(ROS 1?, the path rosbags opens, notes); an :class:`InputError` for what is no bag."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise InputError(f"{path}: no such file or folder; check the path") from None
    except OSError as exc:
        raise InputError(
            f"{path}: cannot read it ({exc.strerror or exc}); check the path"
        ) from None
    if stat.S_ISDIR(mode):
        if (path / "metadata.yaml").is_file():
            return False, path, []
        try:
            storage = sorted(
                p for p in path.iterdir() if p.suffix.lower() in _STORAGE and p.is_file()
            )
        except OSError as exc:
            raise InputError(
                f"{path}: cannot list the folder ({exc.strerror or exc}); check the path"
            ) from None
        if not storage:
            raise InputError(
                f"{path}: a folder without metadata.yaml or .db3/.mcap files; give {_WHAT}"
            )
        if len(storage) > 1:
            shown = ", ".join(p.name for p in storage[:4]) + (" ..." if len(storage) > 4 else "")
            raise InputError(
                f"{path}: {len(storage)} storage files ({shown}) but no metadata.yaml to join "
                "them; give one of the files, or restore metadata.yaml ('ros2 bag reindex')"
            )
        note = f"no metadata.yaml in {path}; read {storage[0].name} alone"
        return False, storage[0], [note]
    if not stat.S_ISREG(mode):
        kind = "a pipe (FIFO)" if stat.S_ISFIFO(mode) else "a device or socket"
        raise InputError(f"{path}: is {kind}, not a file; give {_WHAT}")
    try:
        with path.open("rb") as handle:
            head = handle.read(16)
    except OSError as exc:
        raise InputError(
            f"{path}: cannot read it ({exc.strerror or exc}); check the path"
        ) from None
    suffix = path.suffix.lower()
    if head.startswith(_ROS1_MAGIC):
        return True, path, []
    if head.startswith(b"#ROSBAG"):
        version = head.split(b"\n")[0].decode("ascii", "replace")
        raise InputError(
            f"{path}: {version!r} is an old ROS 1 bag format; only V2.0 is read: convert it "
            "with the ROS 1 rosbag tools, then give the new file"
        )
    if head.startswith(_MCAP_MAGIC) and suffix != ".mcap":
        raise InputError(f"{path}: an MCAP file without the .mcap suffix; rename it to .mcap")
    if suffix == ".db3" and not head.startswith(_SQLITE_MAGIC):
        raise InputError(
            f"{path}: not an SQLite database (a rosbag2 .db3 is one); check the file was "
            "copied whole, or give the bag folder"
        )
    if suffix in _STORAGE:
        return False, path, []
    found = "the file is empty" if not head else "it does not start with '#ROSBAG V2.0'"
    raise InputError(f"{path}: not a ROS bag ({found}); give {_WHAT}")


# ---------------------------------------------------------------------------------------------
# rosbags, loaded when a bag is read


def _module(name: str, path: Path) -> ModuleType:
    try:
        return importlib.import_module(name)
    except ImportError:
        raise InputError(f"{path}: {_INSTALL}") from None


def _reason(exc: BaseException) -> str:
    return " ".join(str(exc).split())[:120] or type(exc).__name__


def _repair(path: Path) -> str:
    """How to mend a damaged bag of ``path``'s kind (only computed for a message)."""
    whole = "check the file was copied whole"
    try:
        if path.is_dir():
            mcap = any(p.suffix.lower() == ".mcap" for p in path.iterdir())
        else:
            with path.open("rb") as handle:
                if handle.read(len(_ROS1_MAGIC)) == _ROS1_MAGIC:
                    return f"{whole}; a recording cut off is mended by 'rosbag reindex'"
            mcap = path.suffix.lower() == ".mcap"
    except OSError:
        return whole
    if mcap:
        return f"{whole}; a recording cut off is mended by 'mcap recover'"
    return f"{whole}; a recording cut off is mended by 'ros2 bag reindex'"


@contextmanager
def _library(path: Path, what: str = "not a readable ROS bag") -> Iterator[None]:
    """rosbags' failures on a damaged bag as one-line :class:`InputError` s.

    rosbags raises many types on damaged input (its ReaderError, SerdeError and TypesysError,
    struct.error, IndexError, KeyError, OverflowError, the SQLite and zstd libraries' errors),
    so everything but an InputError of ours is caught -- only around calls into rosbags.
    """
    try:
        yield
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"{path}: {what} ({_reason(exc)}); {_repair(path)}") from None


@contextmanager
def _opened(path: Path, ros1: bool, target: Path) -> Iterator[Any]:
    """An open rosbags reader of ``target``; closed on the way out."""
    module = _module("rosbags.rosbag1" if ros1 else "rosbags.rosbag2", path)
    suffix = target.suffix.lower()
    if suffix in _STORAGE and suffix not in getattr(module.Reader, "STORAGE_PLUGINS", {}):
        # rosbags before its storage-file plugins opens rosbag2 folders only
        raise InputError(
            f"{path}: this rosbags version reads a rosbag2 bag as a folder only; give the bag "
            "folder (with metadata.yaml), or pip install -U rosbags"
        )
    with _library(path):
        reader = module.Reader(target)
        reader.open()
    try:
        yield reader
    finally:
        with _library(path):
            reader.close()


# ---------------------------------------------------------------------------------------------
# Topics


@dataclass
class _Topic:
    name: str
    msgtype: str
    count: int
    connections: list[Any] = field(default_factory=list)


def _topics(reader: Any, path: Path) -> dict[str, _Topic]:
    topics: dict[str, _Topic] = {}
    with _library(path):
        for conn in reader.connections:
            name, msgtype = str(conn.topic), str(conn.msgtype)
            topic = topics.setdefault(name, _Topic(name, msgtype, 0))
            if topic.msgtype != msgtype:
                raise InputError(
                    f"{path}: topic {name!r} carries two message types ({topic.msgtype}, "
                    f"{msgtype}); record one type per topic"
                )
            topic.count += int(conn.msgcount)
            topic.connections.append(conn)
    return topics


def _listing(topics: dict[str, _Topic], limit: int = 12) -> str:
    if not topics:
        return "the bag has no topics"
    shown = [f"{t.name} [{t.msgtype}]" for t in sorted(topics.values(), key=lambda t: t.name)]
    return (
        "topics: "
        + ", ".join(shown[:limit])
        + (f" ... ({len(shown)})" if len(shown) > limit else "")
    )


def _choose(
    path: Path,
    topics: dict[str, _Topic],
    name: str | None,
    types: tuple[str, ...],
    auto: str,
    option: str,
) -> _Topic | None:
    """The topic named (any of ``types``) or the one topic of type ``auto``; None when none.

    An empty name skips the sensor.
    """
    if name == "":
        return None
    if name is not None:
        if not isinstance(name, str):
            raise InputError(f"{option} must be a topic name, got {name!r}")
        if name not in topics:
            raise InputError(
                f"{path}: no topic {name!r}; pass one of the bag's to {option} ({_listing(topics)})"
            )
        topic = topics[name]
        if topic.msgtype not in types:
            raise InputError(
                f"{path}: topic {name!r} is {topic.msgtype}, not {' or '.join(types)}; choose "
                f"another with {option} ({_listing(topics)})"
            )
    else:
        found = [t for t in topics.values() if t.msgtype == auto]
        if not found:
            return None
        if len(found) > 1:
            names = ", ".join(sorted(t.name for t in found))
            raise InputError(
                f"{path}: {len(found)} {auto} topics ({names}); choose one with {option} "
                f"({_listing(topics)})"
            )
        topic = found[0]
    if topic.count == 0:
        raise InputError(
            f"{path}: topic {topic.name!r} has no messages; choose another with {option} "
            f"({_listing(topics)})"
        )
    return topic


# ---------------------------------------------------------------------------------------------
# Decoding


def _gather(buf: NDArray[np.uint8], at: Ints, count: int, dtype: str) -> NDArray[np.generic]:
    """``count`` values of ``dtype`` at byte offsets ``at`` of ``buf``, one row per offset
    (unaligned reads: the bytes are gathered, then viewed)."""
    size = np.dtype(dtype).itemsize
    index = at[:, None] + np.arange(count * size, dtype=np.int64)
    return buf[index].view(dtype).reshape(len(at), count)


def _decode(
    raws: Sequence[bytes | memoryview], layout: _Layout, ros1: bool
) -> tuple[Ints, dict[str, Array]] | None:
    """Header stamps (ns) and the layout's columns of serialised messages, read with numpy.

    None when a message does not fit the layout (another encapsulation, another length): the
    caller then uses the library's deserialiser.
    """
    n = len(raws)
    lengths = np.fromiter(map(len, raws), dtype=np.int64, count=n)
    buf = np.frombuffer(b"".join(raws), dtype=np.uint8)
    starts = np.zeros(n, dtype=np.int64)
    np.cumsum(lengths[:-1], out=starts[1:])
    if ros1:
        # Header: uint32 seq, uint32 sec, uint32 nsec, uint32 length, frame_id; then packed.
        base, stamp_at, string_at, little, slack = starts, 4, 12, True, 0
    else:
        # CDR: 2 bytes encapsulation kind (0 1: little-endian, 0 0: big), 2 bytes options;
        # then Header: int32 sec, uint32 nanosec, uint32 length (with the NUL), frame_id.
        if np.any(lengths < 16):
            return None
        kind = buf[starts + 1]
        if np.any(buf[starts] != 0) or not (np.all(kind == 1) or np.all(kind == 0)):
            return None
        base, stamp_at, string_at, little, slack = starts + 4, 0, 8, bool(kind[0] == 1), 3
    if np.any(lengths - (base - starts) < string_at + 4):
        return None
    order = "<" if little else ">"
    text = _gather(buf, base + string_at, 1, f"{order}u4")[:, 0].astype(np.int64)
    body = string_at + 4 + text
    if not ros1:
        body = (body + 7) & ~7  # CDR aligns a float64 to 8 bytes from the payload's start
    spare = lengths - (base - starts) - body - layout.size
    if np.any(spare < 0) or np.any(spare > slack):  # CDR may pad the end to 4 bytes
        return None
    sec = _gather(buf, base + stamp_at, 1, f"{order}{'u4' if ros1 else 'i4'}")[:, 0]
    nsec = _gather(buf, base + stamp_at + 4, 1, f"{order}u4")[:, 0]
    at = base + body
    columns: dict[str, Array] = {}
    for _, offset, names in layout.vectors:
        values = _gather(buf, at + offset, 3, f"{order}f8").astype(np.float64)
        for j, name in enumerate(names):
            columns[name] = values[:, j]
    for _, offset, names in layout.absent:
        flag = _gather(buf, at + offset, 1, f"{order}f8")[:, 0] == -1.0
        columns[f"absent_{names[0]}"] = flag.astype(np.float64)
    return sec.astype(np.int64) * _NS + nsec.astype(np.int64), columns


def _fields(message: Any, layout: _Layout) -> tuple[int, dict[str, float]]:
    """Stamp (ns) and values of one deserialised message (AttributeError if it lacks one)."""
    stamp = message.header.stamp
    values: dict[str, float] = {}
    for name, _, cols in layout.vectors:
        vector = getattr(message, name)
        for c, axis in zip(cols, ("x", "y", "z"), strict=True):
            values[c] = float(getattr(vector, axis))
    for name, _, cols in layout.absent:
        values[f"absent_{cols[0]}"] = float(getattr(message, name)[0] == -1.0)
    return int(stamp.sec) * _NS + int(stamp.nanosec), values


class _Decoder:
    """Decodes one topic's messages: numpy at fixed offsets, checked against rosbags'
    deserialiser (built from the bag's own message definition when it has one)."""

    def __init__(self, path: Path, topic: _Topic, ros1: bool) -> None:
        self.path, self.topic, self.ros1 = path, topic, ros1
        self.layout = _LAYOUTS[topic.msgtype]
        self._deserialize = self._deserializer()

    def _deserializer(self) -> Callable[[bytes | memoryview], Any]:
        typesys = _module("rosbags.typesys", self.path)
        msgtype = self.topic.msgtype
        definition = self.topic.connections[0].msgdef
        store = typesys.get_typestore(typesys.Stores.EMPTY)
        try:
            fmt = definition.format.name
            if fmt == "MSG":
                store.register(typesys.get_types_from_msg(definition.data, msgtype))
            elif fmt == "IDL":
                # the rosbag2 layout of several IDL files joined by '=' lines (as AnyReader)
                sep = "=" * 80 + "\n"
                text = definition.data
                parts = [text]
                if text.startswith(f"{sep}IDL: "):
                    parts = [p.split("\n", 1)[1] for p in text.split(sep)[1:]]
                for part in parts:
                    store.register(typesys.get_types_from_idl(part))
            store.get_msgdef(msgtype)
        except Exception:
            # no definition stored (older rosbag2) or one rosbags cannot parse: the standard one
            stock = typesys.Stores.ROS1_NOETIC if self.ros1 else typesys.Stores.LATEST
            store = typesys.get_typestore(stock)
        method = store.deserialize_ros1 if self.ros1 else store.deserialize_cdr
        return lambda raw: method(raw, msgtype)

    def _one(self, raw: bytes | memoryview, index: int) -> tuple[int, dict[str, float]]:
        where = f"message {index + 1:,} of topic {self.topic.name!r}"
        with _library(self.path, f"{where} cannot be decoded"):
            message = self._deserialize(raw)
        try:
            return _fields(message, self.layout)
        except (AttributeError, TypeError, IndexError):
            raise InputError(
                f"{self.path}: {where}: its {self.topic.msgtype} definition lacks the fields "
                f"{', '.join(f for f, _, _ in self.layout.vectors)}; record the standard message"
            ) from None

    def decode(
        self, raws: Sequence[bytes | memoryview], first: int
    ) -> tuple[Ints, dict[str, Array]]:
        """Stamps and columns of a batch (``first``: index of its first message in the topic)."""
        fast = _decode(raws, self.layout, self.ros1)
        if fast is not None:
            stamp, values = self._one(raws[0], first)
            same = stamp == fast[0][0] and all(
                np.array_equal(v, fast[1][k][0], equal_nan=True) for k, v in values.items()
            )
            if same:
                return fast
        decoded = [self._one(raw, first + i) for i, raw in enumerate(raws)]
        stamps = np.fromiter((s for s, _ in decoded), dtype=np.int64, count=len(decoded))
        names = list(decoded[0][1])
        columns = {
            k: np.fromiter((v[k] for _, v in decoded), dtype=np.float64, count=len(decoded))
            for k in names
        }
        return stamps, columns


@dataclass
class _Stream:
    """One topic as read: header stamps, receive times (both ns) and columns."""

    topic: _Topic
    stamps: Ints
    received: Ints
    columns: dict[str, Array]

    @property
    def n(self) -> int:
        return len(self.stamps)


def _read_streams(
    path: Path,
    reader: Any,
    decoders: list[_Decoder],
    on_progress: Callable[[str], None] | None,
) -> list[_Stream]:
    """All messages of the chosen topics in one pass, decoded :data:`BATCH` at a time.

    The loop over messages is the cost left in Python: a batch is taken with ``islice`` and
    split by topic with map and compress, and rosbags' errors are caught once per batch.
    """
    which = {d.topic.name: i for i, d in enumerate(decoders)}
    received: list[list[int]] = [[] for _ in decoders]
    parts: list[list[tuple[Ints, dict[str, Array]]]] = [[] for _ in decoders]
    done = [0] * len(decoders)
    total = sum(d.topic.count for d in decoders)
    with _library(path):
        messages = iter(
            reader.messages(connections=[c for d in decoders for c in d.topic.connections])
        )
    while True:
        with _library(path):
            batch = list(islice(messages, BATCH))
        if not batch:
            break
        # C-level loops (map, compress, numpy): a comprehension or zip(*batch) costs as much
        # again as rosbags' own iteration
        if len(decoders) == 1:
            split = [(0, batch)]
        else:
            index = np.fromiter(
                map(which.__getitem__, map(_TOPIC, map(_CONN, batch))), np.int64, len(batch)
            )
            split = [
                (i, list(compress(batch, (index == i).tolist()))) for i in range(len(decoders))
            ]
        for i, part in split:
            if not part:
                continue
            raw, stamp = list(map(_RAW, part)), list(map(_TIME, part))
            parts[i].append(decoders[i].decode(raw, done[i]))
            received[i].extend(stamp)
            done[i] += len(raw)
        if on_progress is not None:
            on_progress(f"{path.name}: {sum(done):,} of {total:,} messages read")
    streams = []
    for i, decoder in enumerate(decoders):
        if not parts[i]:
            raise InputError(
                f"{path}: topic {decoder.topic.name!r} has no messages (the bag's index counts "
                f"{decoder.topic.count:,}); check the file was copied whole"
            )
        streams.append(
            _Stream(
                decoder.topic,
                np.concatenate([p[0] for p in parts[i]]),
                np.array(received[i], dtype=np.int64),
                {k: np.concatenate([p[1][k] for p in parts[i]]) for k in parts[i][0][1]},
            )
        )
    return streams


# ---------------------------------------------------------------------------------------------
# Times and matching


def _period(times: Ints) -> int | None:
    """Median step between distinct times (ns); None with fewer than two distinct times."""
    steps = np.diff(times)
    steps = steps[steps > 0]
    return int(np.median(steps)) if steps.size else None


def _ms(ns: float) -> str:
    return f"{ns / 1e6:.3g} ms"


def _hz(period: int | None) -> str:
    return "?" if period is None else f"{_NS / period:.4g} Hz"


def _in_order(stream: _Stream, times: Ints, notes: list[str]) -> tuple[Ints, Ints]:
    """``times`` sorted (stable) and the order that sorts them; a note when they were not."""
    back = int(np.count_nonzero(np.diff(times) < 0))
    if not back:
        return times, np.arange(len(times))
    order = np.argsort(times, kind="stable")
    notes.append(f"{back:,} {stream.topic.name} message(s) were out of time order; sorted")
    return times[order], order


def _nearest(base: Ints, other: Ints) -> tuple[Ints, Ints]:
    """For each of ``base`` (sorted), the index of the nearest of ``other`` (sorted; a tie
    goes to the earlier) and the distance."""
    right = np.clip(np.searchsorted(other, base), 0, len(other) - 1)
    left = np.clip(right - 1, 0, len(other) - 1)
    d_left, d_right = np.abs(base - other[left]), np.abs(other[right] - base)
    pick = np.where(d_left <= d_right, left, right)
    return pick, np.minimum(d_left, d_right)


def _assemble(path: Path, streams: list[_Stream], notes: list[str]) -> dict[str, Array]:
    """Columns of the table: one topic's as they are, two matched by time."""
    zero = [(s, int(np.count_nonzero(s.stamps == 0))) for s in streams]
    if any(k for _, k in zero):
        told = ", ".join(f"{k:,} of {s.n:,} {s.topic.name}" for s, k in zero if k)
        notes.append(
            f"header stamps are zero in {told} message(s); timed and matched by the bag's "
            "receive time instead"
        )
        times = [s.received for s in streams]  # one clock for both topics
        clock = "receive time"
    else:
        times = [s.stamps for s in streams]
        clock = "header stamp"
    ordered = [_in_order(s, t, notes) for s, t in zip(streams, times, strict=True)]
    if len(streams) == 1:
        (t, order), (stream,) = ordered[0], streams
        return {"t": t / _NS, **{k: v[order] for k, v in stream.columns.items()}}

    periods = [_period(t) for t, _ in ordered]

    def slowness(i: int) -> tuple[float, int, bool]:
        # the longer period; then the fewer messages; then the magnetometer (streams[1])
        p = periods[i]
        return (math.inf if p is None else p, -streams[i].n, i == 1)

    slow = max(range(2), key=slowness)
    fast = 1 - slow
    period = next((p for p in (periods[slow], periods[fast]) if p is not None), 0)
    (t_slow, o_slow), (t_fast, o_fast) = ordered[slow], ordered[fast]
    pick, distance = _nearest(t_slow, t_fast)
    # a pair further apart than half the slower topic's period is no pair
    keep = 2 * distance <= period
    s_slow, s_fast = streams[slow], streams[fast]
    n_keep = int(np.count_nonzero(keep))
    if n_keep == 0:
        span = ", ".join(
            f"{s.topic.name} {t[0] / _NS:.3f} to {t[-1] / _NS:.3f} s"
            for s, (t, _) in zip(streams, ordered, strict=True)
        )
        raise InputError(
            f"{path}: no {s_fast.topic.name} message is within half a period "
            f"({_ms(period / 2)}) of any {s_slow.topic.name} message ({span}); the topics "
            "do not overlap in time: are their stamps on one clock? (or give one topic only)"
        )
    notes.append(
        f"rows: {s_slow.topic.name} ({_hz(periods[slow])}), each with the nearest "
        f"{s_fast.topic.name} message ({_hz(periods[fast])}) by "
        f"{clock}; largest offset {_ms(float(distance[keep].max()))}"
    )
    dropped = len(keep) - n_keep
    if dropped:
        notes.append(
            f"dropped {dropped:,} of {len(keep):,} {s_slow.topic.name} message(s) with no "
            f"{s_fast.topic.name} message within {_ms(period / 2)} (half the slower period)"
        )
    rows_slow = o_slow[keep]
    rows_fast = o_fast[pick[keep]]
    columns = {"t": t_slow[keep] / _NS}
    columns.update({k: v[rows_slow] for k, v in s_slow.columns.items()})
    columns.update({k: v[rows_fast] for k, v in s_fast.columns.items()})
    return columns


def _absent(columns: dict[str, Array], topic: str, notes: list[str]) -> None:
    """Imu fields marked absent (covariance[0] = -1): gone if in every row, else NaN there."""
    for flag_name in [k for k in columns if k.startswith("absent_")]:
        flag = columns.pop(flag_name) == 1.0
        first = flag_name.removeprefix("absent_")
        group = ("ax", "ay", "az") if first == "ax" else ("gx", "gy", "gz")
        what = "linear_acceleration" if first == "ax" else "angular_velocity"
        if np.all(flag):
            for c in group:
                del columns[c]
            notes.append(
                f"{topic} marks {what} as absent (covariance[0] = -1) in every message; left out"
            )
        elif np.any(flag):
            for c in group:
                columns[c] = np.where(flag, np.nan, columns[c])
            notes.append(
                f"{topic} marks {what} as absent (covariance[0] = -1) in "
                f"{int(np.count_nonzero(flag)):,} row(s); those readings are NaN"
            )


# ---------------------------------------------------------------------------------------------
# The reader


def _attach_notes(table: Table, notes: list[str]) -> None:
    """The notes on ``table.notes``: the field when :class:`Table` has one, else an attribute
    of the same name (read it with ``getattr(table, "notes", [])``)."""
    current = getattr(table, "notes", None)
    if isinstance(current, list):
        current.extend(notes)
    else:
        vars(table)["notes"] = list(notes)


def read_bag(
    path: str | Path,
    *,
    imu_topic: str | None = None,
    mag_topic: str | None = None,
    on_progress: Callable[[str], None] | None = None,
) -> Table:
    """Read a ROS bag's IMU and magnetometer topics as a log table.

    Parameters
    ----------
    path : str or Path
        A ROS 1 ``.bag`` file, a rosbag2 folder, or a single rosbag2 ``.mcap``/``.db3`` file.
    imu_topic, mag_topic : str, optional
        The sensor_msgs/Imu topic and the sensor_msgs/MagneticField topic (or a
        geometry_msgs/Vector3Stamped one, read as the field). By default the one topic of each
        type; an empty string leaves that sensor out.
    on_progress : callable, optional
        Called with a line of text every :data:`BATCH` messages and at the end.

    Returns
    -------
    Table
        Columns ``t`` (seconds from the header stamps, as recorded: not starting at zero),
        ``ax ay az`` (linear_acceleration) and ``gx gy gz`` (angular_velocity) from the IMU
        topic, ``mx my mz`` (magnetic_field, Tesla as recorded) from the magnetometer topic; the
        columns of a sensor not in the bag are absent. With both topics, one row per message of
        the slower one, with the other's nearest message by stamp; pairs further apart than half
        the slower topic's period are dropped. What was decided (dropped pairs, stamps of zero
        replaced by receive times, fields marked absent) is in ``table.notes``.

    Raises
    ------
    InputError
        A missing path, no bag, a damaged bag, rosbags not installed, no IMU or magnetometer
        topic, several candidates, a topic of the wrong type or without messages.
    """
    path = Path(path)
    ros1, target, notes = _locate(path)
    _module("rosbags.typesys", path)  # the install hint before anything else can fail
    with _opened(path, ros1, target) as reader:
        topics = _topics(reader, path)
        imu = _choose(path, topics, imu_topic, (IMU,), IMU, "--imu-topic")
        mag = _choose(
            path,
            topics,
            mag_topic,
            (MAGNETIC_FIELD, VECTOR3_STAMPED),
            MAGNETIC_FIELD,
            "--mag-topic",
        )
        if imu is None and mag is None:
            raise InputError(
                f"{path}: no {IMU} or {MAGNETIC_FIELD} topic ({_listing(topics)}); name them "
                "with --imu-topic/--mag-topic"
            )
        decoders = [_Decoder(path, t, ros1) for t in (imu, mag) if t is not None]
        streams = _read_streams(path, reader, decoders, on_progress)
    columns = _assemble(path, streams, notes)
    if imu is not None:
        _absent(columns, imu.name, notes)
    if not any(c in columns for c in ("ax", "mx")):
        raise InputError(
            f"{path}: topic {imu.name if imu else ''!r} gives no linear_acceleration (marked "
            "absent) and no magnetometer topic was read: nothing to calibrate; name a "
            "sensor_msgs/MagneticField topic with --mag-topic"
        )
    names = [c for c in _ORDER if c in columns]
    table = Table(str(path), names, {c: columns[c] for c in names})
    _attach_notes(table, notes)
    return table
