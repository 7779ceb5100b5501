"""Reading PX4 ULog flight logs (``.ulg``) with `pyulog <https://github.com/PX4/pyulog>`_.

pyulog is an optional extra (``pip install 'fieldcal[ulog]'``), imported when a ``.ulg`` file
is read. Units and frames are those of PX4's uORB message definitions (msg/*.msg):

- ``sensor_accel``/``sensor_gyro``/``sensor_mag`` ``x y z``: m/s², rad/s, gauss, in the
  sensor's frame after the driver's fixed rotation, before PX4's calibration (``CAL_*``): the
  raw readings a calibration wants; ``temperature`` °C;
- ``vehicle_imu`` ``delta_velocity``/``delta_angle`` over ``*_dt`` (µs): m/s², rad/s, body
  frame (FRD), calibrated by PX4; ``sensor_combined`` the same for the primary IMU;
- ``vehicle_magnetometer`` ``magnetometer_ga``: gauss, body frame, calibrated by PX4;
- ``battery_status`` ``current_a`` (A), ``voltage_v`` (V);
- ``actuator_controls_0`` ``control[3]``, ``vehicle_thrust_setpoint`` ``-xyz[2]`` or the
  mean of ``actuator_motors`` ``control[]``: throttle, 0–1;
- ``vehicle_attitude`` ``q``: body (FRD) → NED, Hamilton, scalar first;
- ``vehicle_gps_position``/``sensor_gps``: ``lat``/``lon`` (1e-7 deg) and ``alt`` (mm) or
  ``latitude_deg``/``longitude_deg``/``altitude_msl_m``; ``time_utc_usec`` the date.

Timestamps are µs on the autopilot's clock (``timestamp_sample`` where logged, the moment of
the measurement). For each role the raw topic comes first when it is logged at least half as
often as the calibrated one (the small logging profile logs ``sensor_*`` at 0.1 Hz only).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .flight import FlightLog, Stream, median_location, optional_module, stream, unreadable

__all__ = ["read_ulog"]

Array = NDArray[np.float64]

_INSTALL = "reading PX4 ULog files needs pyulog; pip install 'fieldcal[ulog]'"
_TOPICS = [
    "sensor_accel",
    "sensor_gyro",
    "sensor_mag",
    "vehicle_imu",
    "sensor_combined",
    "vehicle_magnetometer",
    "battery_status",
    "actuator_controls_0",
    "vehicle_thrust_setpoint",
    "actuator_motors",
    "vehicle_attitude",
    "vehicle_gps_position",
    "sensor_gps",
]
_RAW = "sensor frame, uncalibrated"
_BODY = "body FRD, calibrated by PX4"


#: A ULog message's fields by name (pyulog's ``data``): one array per field.
Columns = Mapping[str, NDArray[np.generic]]


def _floats(values: NDArray[np.generic]) -> Array:
    """A field as float64 (the log's integer or float32 field)."""
    return np.asarray(values, dtype=np.float64)


def _time(data: Columns) -> Array:
    key = "timestamp_sample" if "timestamp_sample" in data else "timestamp"
    return np.asarray(data[key], dtype=float) * 1e-6


def _vector(data: Columns, *keys: str) -> Array | None:
    if not all(k in data for k in keys):
        return None
    return np.column_stack([np.asarray(data[k], dtype=float) for k in keys])


def _streams(name: str, instance: int, data: Columns) -> list[Stream | None]:
    t = _time(data)
    src = f"{name}[{instance}]"
    xyz = _vector(data, "x", "y", "z")
    out: list[Stream | None] = []
    if name in ("sensor_accel", "sensor_gyro", "sensor_mag") and xyz is not None:
        role, unit = {
            "sensor_accel": ("accel", "m/s^2"),
            "sensor_gyro": ("gyro", "rad/s"),
            "sensor_mag": ("mag", "gauss"),
        }[name]
        out.append(stream(role, src, instance, t, xyz, unit, _RAW))
        if "temperature" in data and name != "sensor_mag":
            out.append(
                stream("temperature", src, instance, t, _floats(data["temperature"]), "degC")
            )
    elif name == "vehicle_imu":
        dv = _vector(data, *(f"delta_velocity[{k}]" for k in range(3)))
        da = _vector(data, *(f"delta_angle[{k}]" for k in range(3)))
        for role, delta, key, unit in (
            ("accel", dv, "delta_velocity_dt", "m/s^2"),
            ("gyro", da, "delta_angle_dt", "rad/s"),
        ):
            if delta is not None and key in data:
                span = np.asarray(data[key], dtype=float) * 1e-6
                with np.errstate(divide="ignore", invalid="ignore"):
                    rate = delta / span[:, None]
                note = f"{key.split('_dt')[0]} / {key}"
                out.append(stream(role, src, instance, t, rate, unit, _BODY, note))
    elif name == "sensor_combined":
        acc = _vector(data, *(f"accelerometer_m_s2[{k}]" for k in range(3)))
        gyr = _vector(data, *(f"gyro_rad[{k}]" for k in range(3)))
        if acc is not None:
            out.append(stream("accel", src, instance, t, acc, "m/s^2", _BODY, "primary IMU"))
        if gyr is not None:
            out.append(stream("gyro", src, instance, t, gyr, "rad/s", _BODY, "primary IMU"))
    elif name == "vehicle_magnetometer":
        mag = _vector(data, *(f"magnetometer_ga[{k}]" for k in range(3)))
        if mag is not None:
            note = "already corrected by CAL_MAG*: fieldcal's result is relative to it"
            out.append(stream("mag", src, instance, t, mag, "gauss", _BODY, note))
    elif name == "battery_status":
        if "current_a" in data:
            current = np.asarray(data["current_a"], dtype=float)
            current = np.where(current < -0.5, np.nan, current)  # -1: not measured
            out.append(stream("current", src, instance, t, current, "A"))
        if "voltage_v" in data:
            out.append(stream("voltage", src, instance, t, _floats(data["voltage_v"]), "V"))
    else:
        out.append(_throttle_or_attitude(name, instance, data, t, src))
    return out


def _throttle_or_attitude(
    name: str, instance: int, data: Columns, t: Array, src: str
) -> Stream | None:
    if name == "actuator_controls_0" and "control[3]" in data:
        return stream("throttle", src, instance, t, _floats(data["control[3]"]), "0-1")
    if name == "vehicle_thrust_setpoint" and "xyz[2]" in data:
        thrust = -np.asarray(data["xyz[2]"], dtype=float)
        return stream("throttle", src, instance, t, thrust, "0-1", note="-xyz[2]")
    if name == "actuator_motors":
        motors = [np.asarray(v, dtype=float) for k, v in data.items() if k.startswith("control[")]
        if motors:
            stacked = np.column_stack(motors)
            used = np.isfinite(stacked).any(axis=0)
            if used.any():
                mean = np.nanmean(stacked[:, used], axis=1)
                return stream("throttle", src, instance, t, mean, "0-1", note="motors' mean")
    if name == "vehicle_attitude":
        q = _vector(data, *(f"q[{k}]" for k in range(4)))
        if q is not None:
            return stream("attitude", src, instance, t, q, "quaternion", "body FRD -> NED")
    return None


def _position(ulog: Any) -> dict[str, str]:
    """The median 3-D fix's position and the date of the first UTC time."""
    for data in ulog.data_list:
        if data.name not in ("vehicle_gps_position", "sensor_gps"):
            continue
        d = data.data
        fix = np.asarray(d.get("fix_type", np.full(len(d["timestamp"]), 3)), dtype=float) >= 3
        if "latitude_deg" in d:
            lat, lon = d["latitude_deg"], d["longitude_deg"]
            alt = d.get("altitude_msl_m", np.zeros(len(lat)))
        elif "lat" in d:
            lat = np.asarray(d["lat"], dtype=float) * 1e-7
            lon = np.asarray(d["lon"], dtype=float) * 1e-7
            alt = np.asarray(d.get("alt", np.zeros(len(lat))), dtype=float) * 1e-3
        else:
            continue
        lat, lon, alt = (np.asarray(x, dtype=float)[fix] for x in (lat, lon, alt))
        where = median_location(lat, lon, alt)
        if where is None:
            continue
        out = {"gps_location": where}
        times = np.asarray(d.get("time_utc_usec", np.zeros(len(fix))), dtype=float)[fix]
        utc = times[times > 1e15]
        if utc.size:
            day = dt.datetime.fromtimestamp(float(utc[0]) * 1e-6, tz=dt.UTC).date()
            out["date"] = day.isoformat()
        return out
    return {}


def read_ulog(path: str | Path) -> FlightLog:
    """Every stream fieldcal reads from a PX4 ULog (see the module docstring).

    Raises
    ------
    InputError
        pyulog missing, or a file it cannot read (one line, with the fix).
    """
    pyulog = optional_module("pyulog", _INSTALL)
    path = Path(path)
    try:
        ulog = pyulog.ULog(str(path), _TOPICS)
    except Exception as exc:  # pyulog raises bare exceptions on damaged files
        fix = "give the .ulg file as downloaded from the vehicle"
        raise unreadable(path, exc, "PX4 ULog", fix) from None
    found: list[Stream] = []
    for data in ulog.data_list:
        if len(data.data.get("timestamp", ())) == 0:
            continue
        found += [s for s in _streams(data.name, int(data.multi_id), data.data) if s is not None]
    best: dict[str, int] = {}
    for s in found:
        best[s.role] = max(best.get(s.role, 0), len(s.time))

    def preference(s: Stream) -> tuple[int, int, int]:
        """Raw topics logged at least half as often as the best first, then the calibrated
        ones, then raw ones logged too rarely; the better sampled first within each."""
        raw = s.source.startswith(("sensor_accel", "sensor_gyro", "sensor_mag"))
        group = (0 if 2 * len(s.time) >= best[s.role] else 2) if raw else 1
        return (group, -len(s.time), s.instance)

    found.sort(key=preference)
    metadata = _position(ulog)
    info = getattr(ulog, "msg_info_dict", {})
    if "ver_hw" in info:
        metadata["vehicle"] = str(info["ver_hw"])[:80]
    if "ver_sw" in info:
        metadata["firmware"] = f"PX4 {str(info['ver_sw'])[:40]}"
    return FlightLog(str(path), "PX4 ULog", tuple(found), metadata)
