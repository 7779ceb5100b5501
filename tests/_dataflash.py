"""A small DataFlash writer for tests: FMT messages, then messages in ArduPilot's binary
layout (header A3 95, the type, the packed fields), so that pymavlink's DFReader reads back
what the test meant: fieldcal's reader is never on both sides."""

from __future__ import annotations

import struct
from pathlib import Path

_STRUCT = {"Q": "Q", "B": "B", "f": "f", "L": "i", "n": "4s", "N": "16s", "Z": "64s", "h": "h"}
_SCALE = {"L": 1e7}

#: name -> (type id, format, columns); the fields ArduPilot logs (LogStructure.h).
MESSAGES = {
    "IMU": (10, "QBfffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,T"),
    "MAG": (11, "QBffffff", "TimeUS,I,MagX,MagY,MagZ,MOX,MOY,MOZ"),
    "BAT": (12, "QBff", "TimeUS,Inst,Volt,Curr"),
    "CTUN": (13, "Qf", "TimeUS,ThO"),
    "ATT": (14, "Qfff", "TimeUS,Roll,Pitch,Yaw"),
    "GPS": (15, "QBLLf", "TimeUS,Status,Lat,Lng,Alt"),
    "PARM": (16, "QNf", "TimeUS,Name,Value"),
}


def _fmt_message(type_id: int, name: str, fmt: str, columns: str) -> bytes:
    length = 3 + struct.calcsize("<" + "".join(_STRUCT[c] for c in fmt))
    body = struct.pack(
        "<BB4s16s64s", type_id, length, name.encode(), fmt.encode(), columns.encode()
    )
    return bytes([0xA3, 0x95, 0x80]) + body


def _message(name: str, values: tuple) -> bytes:
    type_id, fmt, _ = MESSAGES[name]
    packed = []
    for code, value in zip(fmt, values, strict=True):
        if code in _SCALE:
            value = round(value * _SCALE[code])
        elif code in "nNZ":
            value = str(value).encode()
        packed.append(value)
    body = struct.pack("<" + "".join(_STRUCT[c] for c in fmt), *packed)
    return bytes([0xA3, 0x95, type_id]) + body


def write_dataflash(path: Path, messages: list[tuple[str, tuple]]) -> Path:
    """``messages``: (name, field values in :data:`MESSAGES` order) in log order."""
    out = bytearray()
    out += _fmt_message(0x80, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns")
    for name, (type_id, fmt, columns) in MESSAGES.items():
        out += _fmt_message(type_id, name, fmt, columns)
    for name, values in messages:
        out += _message(name, values)
    path.write_bytes(bytes(out))
    return path
