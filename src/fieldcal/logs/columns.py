"""Which columns of a log hold which sensor: common spellings, explicit overrides.

``ax``, ``acc_x``, ``accX``, ``AccX (g)``, ``accel_x``, ``acc_x[m/s^2]``, ``grav_x``, ``ax_g``,
``AcX``, ``x_acc``, ``accel[0]``, ``mag_x``, ``Mag_X_uT``, ``magX``, ``mx_rawdiv10``,
``magneticField.x``, ``gyr_x``, ``rotationRate.x``, ROS's ``field.linear_acceleration.x`` ...
are recognised, also behind a device or topic prefix (``imu.linear_acceleration.x``,
``LSM9DS1 ax``, ``sensor2_mag_x``); a time column and a pose-label column too. Every problem is
an :class:`~fieldcal.errors.InputError` naming the fix.

:func:`sensor_like_triples` finds x,y,z triples that are *not* recognised (``tx,ty,tz``,
``sensor2_x,...``, ``X,Y,Z``), so a log whose second sensor goes by an unknown name is refused
instead of silently calibrated as a one-sensor log.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Sequence

from ..errors import InputError

__all__ = [
    "DEVICE_WORDS",
    "LABEL_WORDS",
    "SPELLINGS",
    "explicit_columns",
    "incomplete_sensors",
    "label_columns",
    "normalise",
    "recognise_columns",
    "sensor_like_triples",
]

# Prefix spellings per sensor, longest first so "accel_x" is not read as "a" + "ccel_x". An
# underscore inside a prefix is optional ("magneticField.x" -> "magneticfield_x").
_PREFIXES: dict[str, tuple[str, ...]] = {
    "accel": (
        "field_linear_acceleration",
        "linear_acceleration",
        "accelerometer",
        "acceleration",
        "gravity",
        "accel",
        "accl",
        "grav",
        "acc",
        "ac",  # MPU-6050 sketches: AcX, AcY, AcZ
        "a",
    ),
    "mag": (
        "field_magnetic_field",
        "magnetic_field",
        "magnetometer",
        "magnetic",
        "compass",
        "magn",
        "mag",
        "m",
    ),
    "gyro": (
        "field_angular_velocity",
        "angular_velocity",
        "rotation_rate",  # iOS CoreMotion: rotationRate.x
        "gyroscope",
        "omega",
        "gyro",
        "gyr",
        "gy",  # MPU-6050 sketches: GyX, GyY, GyZ
        "g",
        "w",
    ),
}
#: A device or topic prefix ends in one of these: the quantity is not the raw reading (Android's
#: and the BNO055's linear acceleration and iOS's user acceleration have gravity taken out).
_NOT_RAW = frozenset({"lin", "linear", "user"})
# lazy: a name is read without a device prefix when it can be ("field_linear_acceleration_x")
_NS = r"(?:(?P<ns>[a-z0-9_]*?)_)??"


def _alternatives(prefixes: Sequence[str]) -> str:
    return "|".join(p.replace("_", "_?") for p in prefixes)


def _patterns(prefixes: tuple[str, ...]) -> tuple[re.Pattern[str], ...]:
    every, words = _alternatives(prefixes), _alternatives([p for p in prefixes if len(p) > 2])
    return (
        # [namespace_]prefix[_]axis[_suffix]: ax, acc_x, imu_accel_x_g, lsm9ds1_ax
        re.compile(rf"^{_NS}(?P<prefix>{every})_?(?P<axis>[xyz])(?P<suffix>_.*)?$"),
        # an index for an axis, only after a word (accel[0] -> accel_0): "a0" is too vague
        re.compile(rf"^{_NS}(?P<prefix>{words})_(?P<axis>[012])(?P<suffix>_.*)?$"),
        # the axis first, only before a word: x_acc, xAccel
        re.compile(rf"^{_NS}(?P<axis>[xyz])_?(?P<prefix>{words})(?P<suffix>_.*)?$"),
    )


_SENSOR_RE = {sensor: _patterns(p) for sensor, p in _PREFIXES.items()}
_AXIS = {"x": "x", "y": "y", "z": "z", "0": "x", "1": "y", "2": "z"}
_TIME_RE = re.compile(
    r"^(?:t|time|timestamp|stamp|field_header_stamp|sec|secs|seconds|millis|micros|elapsed)"
    r"(?:_.*)?$"
)
_POSE_NAMES = ("pose", "pose_id", "pose_label", "label")
#: Words in a column's name that may label poses (``shot``, ``pose_no``, ``Position``) or the
#: device a row comes from: such columns are kept beside the readings (:func:`label_columns`)
#: for the advice when too few poses are found.
LABEL_WORDS = frozenset({"shot", "pose", "position", "orientation", "label", "station", "face"})
DEVICE_WORDS = frozenset({"device", "serial", "board", "instrument", "unit"})
#: A die temperature in °C: temp, temperature, t_degc, imu_temp, temp_c, die_temperature ...
_TEMP_RE = re.compile(
    r"^(?:[a-z0-9_]*_)?(?:temp|temperature|t_degc|degc|celsius)(?:_(?:c|degc|deg_c|celsius))?$"
)

#: The spellings understood, in short, for messages.
SPELLINGS = (
    "ax, acc_x, accX, linear_acceleration.x; mx, mag_x, magX, magnetic_field.x; gx, gyr_x; "
    "also after a device name and before a unit (LSM9DS1 ax, Mag_X_uT)"
)

# x,y,z triples of quantities that are not a sensor's raw readings: never "another sensor"
_NOT_SENSORS = frozenset(
    {
        "p", "pos", "position", "v", "vel", "velocity", "euler", "angle", "angles",
        "orientation", "ori", "att", "attitude", "q", "quat", "quaternion", "gps", "lla",
        "ecef", "enu", "ned", "std", "var", "sigma", "bias", "offset", "cov", "covariance",
    }
)  # fmt: skip
_TRIPLE_RE = (
    re.compile(r"^(?P<stem>.*?)_?(?P<axis>[xyzw])(?P<suffix>_.*)?$"),
    re.compile(r"^(?P<axis>[xyzw])_?(?P<stem>[a-z][a-z0-9]*)(?P<suffix>_.*)?$"),
)


def normalise(name: str) -> str:
    """``"Acc X (m/s^2)"`` -> ``"acc_x_m_s_2"``: lower case, runs of other characters -> ``_``."""
    return re.sub(r"[^a-z0-9]+", "_", name.strip().lower()).strip("_")


def _match(sensor: str, norm: str) -> tuple[tuple[str, str, str], str] | None:
    """(namespace, prefix, suffix) and the axis of a column name of ``sensor``, or None."""
    for pattern in _SENSOR_RE[sensor]:
        match = pattern.match(norm)
        if match is None:
            continue
        ns = match["ns"] or ""
        if ns and ns.rsplit("_", 1)[-1] in _NOT_RAW:
            return None
        prefix = match["prefix"].replace("_", "")
        return (ns, prefix, match["suffix"] or ""), _AXIS[match["axis"]]
    return None


def recognise_columns(names: Sequence[str]) -> dict[str, list[str]]:
    """Guess each role's columns from their names.

    Returns a dict with keys among ``accel``, ``mag``, ``gyro`` (three names each, x, y, z),
    ``time``, ``pose`` and ``temperature`` (one name each). Columns of one sensor share a
    device prefix, a sensor prefix and a suffix (``ax_g, ay_g, az_g``); the first complete
    x/y/z triple of a sensor in column order wins.
    """
    found: dict[str, list[str]] = {}
    normalised = [normalise(name) for name in names]
    for sensor in _SENSOR_RE:
        groups: dict[tuple[str, str, str], dict[str, str]] = {}
        for name, norm in zip(names, normalised, strict=True):
            hit = _match(sensor, norm)
            if hit is not None:
                groups.setdefault(hit[0], {}).setdefault(hit[1], name)
        for axes in groups.values():
            if len(axes) == 3:
                found[sensor] = [axes["x"], axes["y"], axes["z"]]
                break
    for name, norm in zip(names, normalised, strict=True):
        if "temperature" not in found and _TEMP_RE.match(norm):
            found["temperature"] = [name]
            continue  # t_degc is not a time
        if "time" not in found and _TIME_RE.match(norm):
            found["time"] = [name]
        if "pose" not in found and norm in _POSE_NAMES:
            found["pose"] = [name]
    return found


def incomplete_sensors(
    names: Sequence[str], found: Collection[str] = ()
) -> dict[str, tuple[list[str], str]]:
    """Accelerometer and magnetometer (not in ``found``) of which two axes are recognised by
    name but the third is missing (``ay, az`` without ``ax``): ``{sensor: (the two names, the
    missing axis)}``. One axis alone is not counted (``az`` may be an azimuth)."""
    out: dict[str, tuple[list[str], str]] = {}
    for sensor in ("accel", "mag"):
        if sensor in found:
            continue
        groups: dict[tuple[str, str, str], dict[str, str]] = {}
        for name in names:
            hit = _match(sensor, normalise(name))
            if hit is not None:
                groups.setdefault(hit[0], {}).setdefault(hit[1], name)
        for axes in groups.values():
            if len(axes) == 2:
                missing = next(a for a in "xyz" if a not in axes)
                out[sensor] = ([axes[a] for a in "xyz" if a in axes], missing)
                break
    return out


def label_columns(names: Sequence[str], exclude: Collection[str] = (), limit: int = 8) -> list[str]:
    """Columns not in ``exclude`` whose name holds a word of :data:`LABEL_WORDS` or
    :data:`DEVICE_WORDS` (``shot``, ``pose_no``, ``device``) and is not one axis of a triple
    (``position_x``), at most ``limit`` of them, in column order."""
    skip = set(exclude)
    found = []
    for name in names:
        words = normalise(name).split("_")
        if name in skip or words[-1] in ("x", "y", "z", "0", "1", "2"):
            continue
        if (LABEL_WORDS | DEVICE_WORDS).intersection(words):
            found.append(name)
    return found[:limit]


def sensor_like_triples(names: Sequence[str], exclude: Collection[str] = ()) -> list[list[str]]:
    """x,y,z column triples that look like a sensor's readings but are not recognised as one.

    Names that differ only in an ``x``/``y``/``z`` before an optional suffix (``tx,ty,tz``,
    ``sensor2_x,...``, ``X,Y,Z``, ``x_foo,y_foo,z_foo``) make a triple, in column order; names in
    ``exclude`` (the columns already used), names any sensor pattern recognises, quaternions
    (a ``w`` beside the x, y, z) and quantities that are not raw readings (position, velocity,
    Euler angles, standard deviations ...) are left out.
    """
    skip = set(exclude)
    groups: dict[tuple[int, str, str], dict[str, str]] = {}
    for name in names:
        if name in skip:
            continue
        norm = normalise(name)
        if any(_match(sensor, norm) is not None for sensor in _SENSOR_RE):
            continue
        for kind, pattern in enumerate(_TRIPLE_RE):
            match = pattern.match(norm)
            if match is None:
                continue
            stem = match["stem"]
            words = set(stem.split("_")) | set((match["suffix"] or "").split("_"))
            if not words & _NOT_SENSORS:
                key = (kind, stem, match["suffix"] or "")
                groups.setdefault(key, {}).setdefault(match["axis"], name)
            break
    return [
        [axes["x"], axes["y"], axes["z"]]
        for axes in groups.values()
        if len(axes) == 3 and "x" in axes and "y" in axes and "z" in axes
    ]


def explicit_columns(spec: str | Sequence[str] | None) -> list[str] | None:
    """``"ax,ay,az"`` or a sequence of three names as a list; ``None`` stays ``None``."""
    if spec is None:
        return None
    if isinstance(spec, str):
        names = [s.strip() for s in spec.split(",")]
    elif isinstance(spec, Sequence) and all(isinstance(s, str) for s in spec):
        names = list(spec)
    else:
        names = []
    if len(names) != 3 or not all(names):
        raise InputError(f"give three column names x,y,z, e.g. 'ax,ay,az'; got {spec!r}"[:200])
    return names
