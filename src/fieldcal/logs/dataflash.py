"""Reading ArduPilot DataFlash flight logs (``.bin``) with pymavlink's ``DFReader``.

pymavlink is an optional extra (``pip install 'fieldcal[dataflash]'``), imported when a
``.bin`` file is read. The log describes itself (``FMT`` messages: the fields; ``FMTU``: their
units); pymavlink applies the format's multipliers (``L``: 1e-7 degrees). Messages read, with
the units ArduPilot logs them in (libraries/AP_Logger/LogStructure.h, AP_InertialSensor and
AP_Compass logging):

- ``IMU`` (``I`` the instance; ``IMU2``/``IMU3`` in old logs): ``AccX..Z`` m/s², ``GyrX..Z``
  rad/s, ``T`` °C, body frame (FRD, ``AHRS_ORIENTATION`` applied), calibrated by ArduPilot;
- ``MAG`` (``I``; ``MAG2``/``MAG3``): ``MagX..Z`` milligauss, body frame, **corrected**:
  ArduPilot logs ``M·(raw + OFS) + MOT·u`` (``AP_Compass_Backend::correct_field``); the reader
  undoes it with the log's own ``PARM`` values (``COMPASS_OFS*``, ``DIA*``, ``ODI*``,
  ``SCALE*``) and the logged motor offsets ``MOX..Z``, so fieldcal sees the raw body-frame
  field (the note says when parameters were missing and the field stays as logged);
- ``BAT`` (``Inst``/``I``): ``Curr`` A, ``Volt`` V; ``CTUN`` ``ThO`` throttle 0–1;
- ``ATT``: ``Roll``, ``Pitch``, ``Yaw`` degrees (body FRD → NED, Z-Y-X) as a quaternion;
- ``GPS`` (``Status`` ≥ 3): ``Lat``, ``Lng`` degrees, ``Alt`` m.

Timestamps: ``TimeUS`` (µs, the autopilot's clock).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .flight import FlightLog, Stream, median_location, optional_module, stream, unreadable

__all__ = ["read_dataflash", "uncorrect_compass"]

Array = NDArray[np.float64]

_INSTALL = "reading ArduPilot DataFlash logs needs pymavlink; pip install 'fieldcal[dataflash]'"
_TYPES = ["IMU", "IMU2", "IMU3", "MAG", "MAG2", "MAG3", "BAT", "CTUN", "ATT", "GPS", "PARM"]
_BODY = "body FRD"


#: One DataFlash message as pymavlink's ``to_dict`` gives it: its fields by name.
Row = dict[str, object]


def _instance(message: object, name: str) -> int:
    for key in ("I", "Inst", "Instance"):
        value = getattr(message, key, None)
        if isinstance(value, int):
            return value
    return int(name[-1]) - 1 if name[-1].isdigit() else 0


def _collect(reader: Any) -> tuple[dict[tuple[str, int], list[Row]], dict[str, float]]:
    rows: dict[tuple[str, int], list[Row]] = defaultdict(list)
    params: dict[str, float] = {}
    while True:
        message = reader.recv_match(type=_TYPES)
        if message is None:
            break
        name = message.get_type()
        if name == "PARM":
            params.setdefault(str(message.Name), float(message.Value))
            continue
        base = name.rstrip("23")
        rows[(base, _instance(message, name))].append(message.to_dict())
    return rows, params


def _column(rows: list[Row], *keys: str) -> Array | None:
    if not all(k in rows[0] for k in keys):
        return None
    return np.array([[row[k] for k in keys] for row in rows], dtype=float).reshape(len(rows), -1)


def uncorrect_compass(
    field: Array, motor: Array | None, params: dict[str, float], instance: int
) -> tuple[Array, str]:
    """The raw body-frame field from ArduPilot's logged ``MagX..Z``: ``correct_field`` logs
    ``M (raw + OFS) + MOT u``, so ``raw = M⁻¹ (logged − MOX..Z) − OFS`` with the log's own
    parameters of that compass (``COMPASS_OFS``, ``COMPASS_OFS2`` ...). Returns the field and
    a note saying what was undone."""
    suffix = "" if instance == 0 else str(instance + 1)
    out = field - motor if motor is not None else field.copy()
    ofs = [params.get(f"COMPASS_OFS{suffix}_{a}") for a in "XYZ"]
    if any(v is None for v in ofs):
        return out, "COMPASS_OFS not in the log: the field stays as ArduPilot corrected it"
    dia = [params.get(f"COMPASS_DIA{suffix}_{a}", 1.0) for a in "XYZ"]
    odi = [params.get(f"COMPASS_ODI{suffix}_{a}", 0.0) for a in "XYZ"]
    dia = [1.0 if d == 0 else d for d in dia]  # ArduPilot treats 0 as 1 (an uncalibrated M)
    M = np.array(
        [[dia[0], odi[0], odi[1]], [odi[0], dia[1], odi[2]], [odi[1], odi[2], dia[2]]],
        dtype=float,
    )
    scale = params.get(f"COMPASS_SCALE{suffix}", 0.0) or 1.0
    raw = np.linalg.solve(M * scale, out.T).T - np.asarray(ofs, dtype=float)
    return raw, "ArduPilot's COMPASS_OFS/DIA/ODI/SCALE and motor offsets undone (raw field)"


def _attitude_quaternion(rpy_deg: Array) -> Array:
    r, p, y = np.radians(rpy_deg).T / 2.0
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.column_stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def _streams(
    rows: dict[tuple[str, int], list[Row]], params: dict[str, float]
) -> list[Stream | None]:
    out: list[Stream | None] = []
    for (name, inst), msgs in sorted(rows.items()):
        t_us = _column(msgs, "TimeUS")
        if t_us is None:
            continue
        t = t_us[:, 0] * 1e-6
        src = f"{name}[{inst}]"
        if name == "IMU":
            acc, gyr, temp = (
                _column(msgs, "AccX", "AccY", "AccZ"),
                _column(msgs, "GyrX", "GyrY", "GyrZ"),
                _column(msgs, "T"),
            )
            if acc is not None:
                out.append(stream("accel", src, inst, t, acc, "m/s^2", _BODY))
            if gyr is not None:
                out.append(stream("gyro", src, inst, t, gyr, "rad/s", _BODY))
            if temp is not None:
                out.append(stream("temperature", src, inst, t, temp[:, 0], "degC"))
        elif name == "MAG":
            field = _column(msgs, "MagX", "MagY", "MagZ")
            if field is not None:
                raw, note = uncorrect_compass(
                    field, _column(msgs, "MOX", "MOY", "MOZ"), params, inst
                )
                out.append(stream("mag", src, inst, t, raw, "mGauss", _BODY, note))
        elif name == "BAT":
            for key, role, unit in (("Curr", "current", "A"), ("Volt", "voltage", "V")):
                values = _column(msgs, key)
                if values is not None:
                    out.append(stream(role, src, inst, t, values[:, 0], unit))
        elif name == "CTUN":
            tho = _column(msgs, "ThO")
            if tho is not None:
                out.append(stream("throttle", src, inst, t, tho[:, 0], "0-1", note="ThO"))
        elif name == "ATT":
            rpy = _column(msgs, "Roll", "Pitch", "Yaw")
            if rpy is not None:
                q = _attitude_quaternion(rpy)
                out.append(stream("attitude", src, inst, t, q, "quaternion", "body FRD -> NED"))
    return out


def _position(rows: dict[tuple[str, int], list[Row]]) -> dict[str, str]:
    msgs = rows.get(("GPS", 0), [])
    if not msgs:
        return {}
    status = _column(msgs, "Status")
    fix = np.ones(len(msgs), dtype=bool) if status is None else status[:, 0] >= 3
    lla = _column(msgs, "Lat", "Lng", "Alt")
    if lla is None or not fix.any():
        return {}
    where = median_location(lla[fix, 0], lla[fix, 1], lla[fix, 2])
    return {} if where is None else {"gps_location": where}


def read_dataflash(path: str | Path) -> FlightLog:
    """Every stream fieldcal reads from an ArduPilot DataFlash ``.bin`` log (see the module
    docstring).

    Raises
    ------
    InputError
        pymavlink missing, or a file it cannot read (one line, with the fix).
    """
    dfreader = optional_module("pymavlink.DFReader", _INSTALL)
    path = Path(path)
    try:
        with path.open("rb") as handle:
            head = handle.read(3)
        if len(head) < 3 or head[0] != 0xA3 or head[1] != 0x95:
            raise ValueError("it does not start with a DataFlash message header (A3 95)")
        reader = dfreader.DFReader_binary(str(path), zero_time_base=False)
        rows, params = _collect(reader)
    except Exception as exc:  # DFReader raises bare exceptions on damaged files
        fix = "give the .bin file as downloaded from the autopilot"
        raise unreadable(path, exc, "ArduPilot DataFlash log", fix) from None
    found = [s for s in _streams(rows, params) if s is not None]
    found.sort(key=lambda s: (s.instance, -len(s.time)))
    metadata = _position(rows)
    return FlightLog(str(path), "ArduPilot DataFlash", tuple(found), metadata)
