"""The sensor model of Miranda & Ferreira (Eq. 1-4) and the calibration result.

Model (Eq. 1, 4). While the device rests in pose ``i`` each sensor ``s`` reads

    s_s[i, j] = K_s R_i f_s + b_s + ε,   ε ~ N(0, Σ_s)

with ``K_s`` the gain matrix (scale, cross-axis, soft iron), ``b_s`` the bias (offset, hard
iron), ``R_i`` the rotation from the world frame to the body frame and ``f_s`` the reference
field in the world frame (``g`` for the accelerometer, ``h`` for the magnetometer).

Gauge (Eq. 2 and Sec. 4.3). The world frame is North-East-Down: the accelerometer's reference
vector (the specific force read at rest) is ``g = (0, 0, −|g|)`` and the magnetic field is
``h = |h| (cos dip, 0, sin dip)``, so the dip is positive when the field points below the
horizon (northern hemisphere). By default ``|g| = |h| = 1``; ``gravity=`` and
``field_strength=`` rescale the gains to physical units. The body frame is fixed by making the
accelerometer's gain symmetric positive definite (``body_frame="accel"``, the paper's choice)
or the magnetometer's (``body_frame="mag"``).

The inverse model maps a raw reading to a vector in that common body frame:
``K_s⁻¹ (raw − b_s)``. Everything here imports nothing else of fieldcal but :mod:`rotations`.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .rotations import rotation_angle_deg

__all__ = [
    "SCHEMA",
    "SCHEMA_VERSION",
    "Calibration",
    "Diagnostics",
    "ParameterCovariance",
    "SensorCalibration",
    "canonical_gauge",
    "dip_of",
    "misalignment_angle_deg",
]

SCHEMA = "fieldcal.calibration"
SCHEMA_VERSION = 1

Array = NDArray[np.float64]


def _arrays_equal(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if a is None or b is None:
            return False
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=True))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


class _ArrayDataclass:
    """Equality by value for frozen dataclasses holding numpy arrays."""

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return all(
            _arrays_equal(getattr(self, f.name), getattr(other, f.name))
            for f in dataclasses.fields(self)  # type: ignore[arg-type]
        )

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True, eq=False)
class SensorCalibration(_ArrayDataclass):
    """One sensor's parameters in the model ``mean raw reading = gain @ R_i @ field + bias``.

    Attributes
    ----------
    gain : (3, 3) array
        ``K_s``: maps a body-frame field vector to raw units (scale, cross-axis, soft iron).
    bias : (3,) array
        ``b_s`` in raw units (offset, hard iron).
    noise_cov : (3, 3) array
        ``Σ_s``, covariance of one raw sample, raw units squared.
    gain_std, bias_std, noise_cov_std : arrays or None
        Standard errors of each entry (Cramér-Rao bound at the optimum for ``gain``/``bias``,
        Wishart standard error for ``noise_cov``); ``None`` when the method gives none.
    noise_source : str
        How ``noise_cov`` was obtained: ``"scatter"`` (Eq. 7, within-pose scatter),
        ``"residuals"`` (isotropic, from the fit's residuals) or ``"user"``.
    """

    gain: Array
    bias: Array
    noise_cov: Array
    gain_std: Array | None = None
    bias_std: Array | None = None
    noise_cov_std: Array | None = None
    noise_source: str = "scatter"

    def __post_init__(self) -> None:
        for name in ("gain", "bias", "noise_cov", "gain_std", "bias_std", "noise_cov_std"):
            value = getattr(self, name)
            if value is not None:
                array = np.array(value, dtype=float)
                array.setflags(write=False)
                object.__setattr__(self, name, array)

    def predict(self, rotations: Array, reference: Array) -> Array:
        """Noise-free mean reading per pose, ``gain @ R_i @ reference + bias`` (Eq. 4)."""
        body = np.einsum("nij,j->ni", np.asarray(rotations, dtype=float), reference)
        return self.distort(body)

    def distort(self, body: Array) -> Array:
        """Forward model: body-frame vectors (..., 3) -> raw readings ``gain @ v + bias``."""
        return np.asarray(body, dtype=float) @ self.gain.T + self.bias

    def correct(self, raw: Array) -> Array:
        """Inverse model: raw readings (..., 3) -> body-frame vectors ``gain⁻¹ (raw − bias)``."""
        raw = np.asarray(raw, dtype=float)
        if raw.shape[-1:] != (3,):
            raise ValueError(f"raw readings must have shape (..., 3), got {raw.shape}")
        return np.linalg.solve(self.gain, (raw - self.bias).reshape(-1, 3).T).T.reshape(raw.shape)

    def scaled(self, factor: float) -> SensorCalibration:
        """The same sensor with the reference field magnitude divided by ``factor``.

        Multiplying the gain (and its standard error) by ``factor`` while the field is divided
        by it leaves every predicted reading unchanged.
        """
        return dataclasses.replace(
            self,
            gain=self.gain * factor,
            gain_std=None if self.gain_std is None else self.gain_std * abs(factor),
        )


@dataclass(frozen=True, eq=False)
class ParameterCovariance(_ArrayDataclass):
    """Covariance of named global parameters (Cramér-Rao bound at the optimum).

    Names follow ``"accel.gain[i,j]"``, ``"accel.bias[i]"``, ``"mag.gain[i,j]"``,
    ``"mag.bias[i]"`` and ``"dip_deg"`` (0-based indices); gains in the units of
    :class:`SensorCalibration`, the dip in degrees.
    """

    names: tuple[str, ...]
    matrix: Array

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(self.names))
        matrix = np.array(self.matrix, dtype=float)
        if matrix.shape != (len(self.names), len(self.names)):
            raise ValueError("covariance matrix must be square and match the names")
        matrix.setflags(write=False)
        object.__setattr__(self, "matrix", matrix)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no parameter named {name!r}; known: {', '.join(self.names)}") from None

    def std(self, name: str) -> float:
        """Standard error of one named parameter."""
        i = self.index(name)
        return float(np.sqrt(max(self.matrix[i, i], 0.0)))

    def submatrix(self, names: list[str] | tuple[str, ...]) -> Array:
        idx = [self.index(n) for n in names]
        return self.matrix[np.ix_(idx, idx)]

    def scaled(self, factors: Mapping[str, float]) -> ParameterCovariance:
        """Rescale parameters whose name starts with a key of ``factors`` (e.g. "accel.gain")."""
        s = np.ones(len(self.names))
        for i, name in enumerate(self.names):
            for prefix, factor in factors.items():
                if name.startswith(prefix):
                    s[i] = factor
        return ParameterCovariance(self.names, self.matrix * np.outer(s, s))


@dataclass(frozen=True, eq=False)
class Diagnostics(_ArrayDataclass):
    """Goodness of fit at the end of a calibration.

    ``statistic`` is the cost ``J`` of Eq. 8 (the sum over poses and sensors of
    ``Δ_i rᵀ Σ⁻¹ r``), which at the maximum-likelihood optimum follows a χ² distribution with
    ``dof`` degrees of freedom (``3N − 22`` for the joint problem); ``p_value`` is its upper tail
    probability. ``pose_cost`` (N,) is each pose's contribution to ``J``.
    """

    statistic: float
    dof: int
    p_value: float
    pose_cost: Array
    status: str = ""

    def __post_init__(self) -> None:
        pose_cost = np.array(self.pose_cost, dtype=float)
        pose_cost.setflags(write=False)
        object.__setattr__(self, "pose_cost", pose_cost)

    @property
    def pose_share(self) -> Array:
        """Each pose's share of the total cost (sums to 1)."""
        total = float(np.sum(self.pose_cost))
        return self.pose_cost / total if total > 0 else np.zeros_like(self.pose_cost)


def dip_of(magnetic: Array) -> float:
    """Dip (inclination) in degrees of a field ``(h_x, 0, h_z)`` in the NED world frame.

    Positive when the field points below the horizon: ``dip = atan2(h_z, h_x)``.
    """
    return float(np.degrees(np.arctan2(magnetic[2], magnetic[0])))


def _nearest_signed_permutation(U: Array) -> Array:
    S = np.zeros((3, 3))
    order = np.argsort(-np.abs(U), axis=None)
    used_rows: set[int] = set()
    used_cols: set[int] = set()
    for flat in order:
        r, c = divmod(int(flat), 3)
        if r not in used_rows and c not in used_cols:
            S[r, c] = np.sign(U[r, c]) or 1.0
            used_rows.add(r)
            used_cols.add(c)
    return S


def _orthogonal_polar_factor(K: Array) -> Array:
    W, _, Vt = np.linalg.svd(K)
    return W @ Vt


def misalignment_angle_deg(accel_gain: Array, mag_gain: Array) -> float:
    """Angle between the accelerometer's and the magnetometer's axis triads, in degrees.

    Each gain splits (polar decomposition) into a symmetric stretch and an orthogonal factor
    ``U_s``: the direction the sensor's own axes point in the body frame. The misalignment is
    the rotation angle of ``U_m U_aᵀ`` once a mirrored or permuted axis convention (the nearest
    signed permutation) is taken out, so a magnetometer wired ``+y+x−z`` is not "90° off".
    """
    U = _orthogonal_polar_factor(mag_gain) @ _orthogonal_polar_factor(accel_gain).T
    S = _nearest_signed_permutation(U)
    return float(rotation_angle_deg(S.T @ U))


def canonical_gauge(
    rotations: Array,
    accel_gain: Array | None,
    mag_gain: Array | None,
    gravity: Array | None,
    magnetic: Array | None,
    body_frame: str = "accel",
) -> tuple[Array, Array | None, Array | None, Array | None, Array | None]:
    """Re-express any parameter set in fieldcal's gauge without changing one prediction.

    1. World frame (Eq. 2): rotate the world so that ``g = (0, 0, −|g|)`` and ``h`` lies in the
       x-z plane with ``h_x > 0``.
    2. Magnitudes (Sec. 4.3): fold ``|g|`` into ``K_a`` and ``|h|`` into ``K_m`` so both fields
       have unit length.
    3. Body frame (Sec. 4.3): write the chosen sensor's gain as ``P U`` (polar decomposition)
       and move the rotation ``U`` into every ``R_i``, leaving that gain symmetric positive
       definite.

    Returns ``(rotations, accel_gain, mag_gain, gravity, magnetic)``.
    """
    R = np.array(rotations, dtype=float)
    Ka = None if accel_gain is None else np.array(accel_gain, dtype=float)
    Km = None if mag_gain is None else np.array(mag_gain, dtype=float)
    g = None if gravity is None else np.array(gravity, dtype=float)
    h = None if magnetic is None else np.array(magnetic, dtype=float)

    # 1. world frame: columns of W^T are the new world axes expressed in the old world frame.
    down = -g / np.linalg.norm(g) if g is not None else None
    if down is not None and h is not None:
        north = h - np.dot(h, down) * down
        north /= np.linalg.norm(north)
    elif down is not None:
        helper = np.eye(3)[int(np.argmin(np.abs(down)))]
        north = helper - np.dot(helper, down) * down
        north /= np.linalg.norm(north)
    else:
        assert h is not None
        north = h / np.linalg.norm(h)
        helper = np.eye(3)[int(np.argmin(np.abs(north)))]
        down = helper - np.dot(helper, north) * north
        down /= np.linalg.norm(down)
    east = np.cross(down, north)
    W = np.stack([north, east, down])  # new_world = W @ old_world
    R = R @ W.T

    # 2. unit fields
    if g is not None:
        Ka = Ka * np.linalg.norm(g)
        g = np.array([0.0, 0.0, -1.0])
    if h is not None:
        hw = W @ h
        Km = Km * np.linalg.norm(hw)
        h = hw / np.linalg.norm(hw)

    # 3. symmetric gain for the chosen sensor
    K = Ka if body_frame == "accel" else Km
    if K is None:
        K = Km if Ka is None else Ka
    U = _orthogonal_polar_factor(K)
    if np.linalg.det(U) < 0:
        raise ValueError(
            f"the {body_frame} gain has a negative determinant, so it cannot be made symmetric "
            "positive definite by a rotation; choose the other body_frame or remap its axes"
        )
    R = U @ R
    if Ka is not None:
        Ka = Ka @ U.T
    if Km is not None:
        Km = Km @ U.T
    # symmetrise away round-off on the sensor that defines the frame
    if body_frame == "accel" and Ka is not None:
        Ka = 0.5 * (Ka + Ka.T)
    elif Km is not None and (body_frame == "mag" or Ka is None):
        Km = 0.5 * (Km + Km.T)
    return R, Ka, Km, g, h


@dataclass(frozen=True, eq=False)
class Calibration(_ArrayDataclass):
    """The result of a calibration: both sensors, the fields, every pose's rotation.

    Conventions (``docs/conventions.md``): world frame North-East-Down with
    ``gravity = (0, 0, −|g|)`` (the accelerometer's reading at rest, "up") and
    ``magnetic = |h| (cos dip, 0, sin dip)``; ``rotations[i]`` maps world vectors to the body
    frame in pose ``i``; a sensor reads ``gain @ R_i @ field + bias`` on average (Eq. 1, 4).

    Attributes
    ----------
    accel, mag : SensorCalibration or None
        ``None`` for a sensor that was not calibrated.
    gravity, magnetic : (3,) arrays or None
        Reference fields in the world frame of Eq. 2.
    rotations : (N, 3, 3) array
        ``R_i``, world frame to body frame, per pose.
    method : str
        ``"greedy"``, ``"ellipsoid"``, ``"mle"`` (or ``"truth"`` for simulated truth).
    cost : float
        ``J`` of Eq. 8 at the end, with the noise covariances in ``noise_cov``.
    iterations : int
    converged : bool
    options : dict
        The method's options as used, for provenance.
    dip_std_deg, misalignment_std_deg : float or None
        Standard errors (``None`` when the method gives none).
    covariance : ParameterCovariance or None
        Joint covariance of the named global parameters.
    diagnostics : Diagnostics or None
        Fit certificate and per-pose cost.
    poses : tuple of dict
        One entry per pose (``index``, ``samples``, ``cost``, ``share`` and, from log files,
        ``start``/``stop`` or ``label``); written as the top-level ``poses`` list in JSON.
    units : dict
        Units of raw and calibrated readings, for humans and exports.
    version, created : str
        fieldcal version and ISO 8601 UTC time that produced the result.
    """

    accel: SensorCalibration | None
    mag: SensorCalibration | None
    gravity: Array | None
    magnetic: Array | None
    rotations: Array
    method: str
    cost: float = float("nan")
    iterations: int = 0
    converged: bool = True
    options: dict[str, Any] = field(default_factory=dict)
    dip_std_deg: float | None = None
    misalignment_std_deg: float | None = None
    covariance: ParameterCovariance | None = None
    diagnostics: Diagnostics | None = None
    poses: tuple[dict[str, Any], ...] = ()
    units: dict[str, str] = field(default_factory=dict)
    version: str = ""
    created: str = ""

    def __post_init__(self) -> None:
        for name in ("gravity", "magnetic", "rotations"):
            value = getattr(self, name)
            if value is not None:
                array = np.array(value, dtype=float)
                array.setflags(write=False)
                object.__setattr__(self, name, array)
        object.__setattr__(self, "poses", tuple(dict(p) for p in self.poses))
        object.__setattr__(self, "cost", float(self.cost))
        object.__setattr__(self, "iterations", int(self.iterations))
        object.__setattr__(self, "converged", bool(self.converged))
        if not self.version:
            from . import __version__

            object.__setattr__(self, "version", __version__)
        if not self.created:
            now = _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat()
            object.__setattr__(self, "created", now)
        if not self.units:
            object.__setattr__(self, "units", default_units(self))

    # ----------------------------------------------------------------- derived quantities
    @property
    def n_poses(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def dip_deg(self) -> float | None:
        """Magnetic dip in degrees, positive when the field points below the horizon."""
        return None if self.magnetic is None else dip_of(self.magnetic)

    @property
    def gravity_norm(self) -> float | None:
        return None if self.gravity is None else float(np.linalg.norm(self.gravity))

    @property
    def field_strength(self) -> float | None:
        return None if self.magnetic is None else float(np.linalg.norm(self.magnetic))

    @property
    def misalignment_deg(self) -> float | None:
        """Angle between the magnetometer's and the accelerometer's axes (degrees)."""
        if self.accel is None or self.mag is None:
            return None
        return misalignment_angle_deg(self.accel.gain, self.mag.gain)

    # ----------------------------------------------------------------- model
    def predicted_means(self) -> tuple[Array | None, Array | None]:
        """The model's noise-free reading per pose, ``gain @ R_i @ field + bias`` (Eq. 4)."""
        accel = None if self.accel is None else self.accel.predict(self.rotations, self.gravity)
        mag = None if self.mag is None else self.mag.predict(self.rotations, self.magnetic)
        return accel, mag

    def correct_accel(self, raw: Array) -> Array:
        """Raw accelerometer readings (..., 3) -> body-frame specific force (inverse model)."""
        if self.accel is None:
            raise ValueError("this calibration has no accelerometer; calibrate one first")
        return self.accel.correct(raw)

    def correct_mag(self, raw: Array) -> Array:
        """Raw magnetometer readings (..., 3) -> body-frame magnetic field (inverse model)."""
        if self.mag is None:
            raise ValueError("this calibration has no magnetometer; calibrate one first")
        return self.mag.correct(raw)

    def with_field_magnitudes(
        self, gravity: float | None = None, field_strength: float | None = None
    ) -> Calibration:
        """The same calibration with ``|g| = gravity`` and ``|h| = field_strength``.

        Gains (and their standard errors and covariance entries) are divided by the new
        magnitude relative to the old one; every predicted reading is unchanged.
        """
        accel, mag, g, h = self.accel, self.mag, self.gravity, self.magnetic
        factors: dict[str, float] = {}
        if gravity is not None and accel is not None and g is not None:
            if not (np.isfinite(gravity) and gravity > 0):
                raise ValueError(f"gravity must be a positive number, got {gravity!r}")
            c = float(np.linalg.norm(g)) / float(gravity)
            accel, g, factors["accel.gain"] = accel.scaled(c), g / c, c
        if field_strength is not None and mag is not None and h is not None:
            if not (np.isfinite(field_strength) and field_strength > 0):
                raise ValueError(
                    f"field_strength must be a positive number, got {field_strength!r}"
                )
            c = float(np.linalg.norm(h)) / float(field_strength)
            mag, h, factors["mag.gain"] = mag.scaled(c), h / c, c
        covariance = None if self.covariance is None else self.covariance.scaled(factors)
        result = dataclasses.replace(
            self, accel=accel, mag=mag, gravity=g, magnetic=h, covariance=covariance, units={}
        )
        return result

    def with_mag_handedness(self, mirrored: bool = False) -> Calibration:
        """The twin of this result whose magnetometer has the requested handedness.

        Static poses cannot tell a magnetometer mirrored relative to the accelerometer from an
        unmirrored one in the opposite magnetic hemisphere. Negating the gain of the sensor that
        does not define the body frame, with ``h → (h_x, 0, −h_z)`` (the dip's sign flips) and
        ``R_i → R_i D``, predicts identical readings: ``D = diag(−1, −1, 1)`` (a half turn about
        the down axis, leaving ``g`` alone) when the magnetometer's gain is negated,
        ``D = diag(1, −1, −1)`` (a half turn about north, leaving ``h``'s new direction
        consistent) when the accelerometer's is. Both have the same likelihood; this picks
        ``det(K_a K_m) > 0`` (``mirrored`` false: both triads right-handed as given) or
        ``det(K_a K_m) < 0`` (a mirrored chip).
        """
        if self.mag is None or self.accel is None or self.magnetic is None:
            return self
        relative = np.linalg.det(self.accel.gain) * np.linalg.det(self.mag.gain)
        if (relative < 0) == bool(mirrored):
            return self
        Ka = self.accel.gain
        accel_frame = np.allclose(Ka, Ka.T, rtol=0, atol=1e-9 * np.abs(Ka).max())
        name, D = (
            ("mag", np.diag([-1.0, -1.0, 1.0]))
            if accel_frame
            else (
                "accel",
                np.diag([1.0, -1.0, -1.0]),
            )
        )
        sensor = getattr(self, name)
        h = self.magnetic
        covariance = self.covariance
        if covariance is not None:
            covariance = covariance.scaled({f"{name}.gain": -1.0, "dip_deg": -1.0})
        return dataclasses.replace(
            self,
            **{name: dataclasses.replace(sensor, gain=-sensor.gain)},
            magnetic=np.array([h[0], h[1], -h[2]]),
            rotations=self.rotations @ D,
            covariance=covariance,
        )

    # ----------------------------------------------------------------- JSON
    def to_dict(self) -> dict[str, Any]:
        """The JSON document as Python objects (see ``docs/json-schema.md``)."""
        return _calibration_to_dict(self)

    def to_json(self, indent: int | None = 2) -> str:
        """Serialise to the versioned JSON schema (lossless: floats are written exactly)."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Calibration:
        return _calibration_from_dict(data)

    @classmethod
    def from_json(cls, text: str) -> Calibration:
        """Read a calibration written by :meth:`to_json` (any schema version up to ours)."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"not a fieldcal calibration JSON: {exc}") from None
        return cls.from_dict(data)


def default_units(cal: Calibration) -> dict[str, str]:
    g = cal.gravity_norm
    h = cal.field_strength
    units = {"accel_raw": "as given", "mag_raw": "as given"}
    units["accel_calibrated"] = "|g| = 1" if g is None or g == 1.0 else f"|g| = {g:g}"
    units["mag_calibrated"] = "|h| = 1" if h is None or h == 1.0 else f"|h| = {h:g}"
    units["angles"] = "degrees"
    return units


# --------------------------------------------------------------------- JSON helpers
def _encode(value: Any) -> Any:
    if value is None:
        return None
    if isinstance(value, np.ndarray):
        return _encode(value.tolist())
    if isinstance(value, (list, tuple)):
        return [_encode(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _encode(v) for k, v in value.items()}
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return value
    return value


def _decode_array(value: Any) -> Array | None:
    if value is None:
        return None
    return np.array(_decode_floats(value), dtype=float)


def _decode_floats(value: Any) -> Any:
    if isinstance(value, list):
        return [_decode_floats(v) for v in value]
    if isinstance(value, str) and value in ("nan", "inf", "-inf"):
        return float(value)
    return value


def _sensor_to_dict(sensor: SensorCalibration | None) -> dict[str, Any] | None:
    if sensor is None:
        return None
    return {
        "gain": _encode(sensor.gain),
        "bias": _encode(sensor.bias),
        "noise_cov": _encode(sensor.noise_cov),
        "gain_std": _encode(sensor.gain_std),
        "bias_std": _encode(sensor.bias_std),
        "noise_cov_std": _encode(sensor.noise_cov_std),
        "noise_source": sensor.noise_source,
    }


def _sensor_from_dict(data: Mapping[str, Any] | None) -> SensorCalibration | None:
    if data is None:
        return None
    return SensorCalibration(
        gain=_decode_array(data["gain"]),
        bias=_decode_array(data["bias"]),
        noise_cov=_decode_array(data["noise_cov"]),
        gain_std=_decode_array(data.get("gain_std")),
        bias_std=_decode_array(data.get("bias_std")),
        noise_cov_std=_decode_array(data.get("noise_cov_std")),
        noise_source=data.get("noise_source", "scatter"),
    )


def _calibration_to_dict(cal: Calibration) -> dict[str, Any]:
    diag = cal.diagnostics
    cov = cal.covariance
    return {
        "schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "fieldcal_version": cal.version,
        "created": cal.created,
        "method": cal.method,
        "options": _encode(cal.options),
        "units": dict(cal.units),
        "conventions": {
            "model": "mean raw reading in pose i = gain @ R_i @ field + bias",
            "correction": "body = inv(gain) @ (raw - bias)",
            "world_frame": "NED: gravity = (0, 0, -|g|), magnetic = |h| (cos dip, 0, sin dip)",
            "rotations": "R_i maps world-frame vectors to the body frame",
            "dip": "degrees, positive when the field points below the horizon",
        },
        "accel": _sensor_to_dict(cal.accel),
        "mag": _sensor_to_dict(cal.mag),
        "gravity": _encode(cal.gravity),
        "magnetic": _encode(cal.magnetic),
        "dip_deg": _encode(cal.dip_deg),
        "dip_std_deg": _encode(cal.dip_std_deg),
        "misalignment_deg": _encode(cal.misalignment_deg),
        "misalignment_std_deg": _encode(cal.misalignment_std_deg),
        "rotations": _encode(cal.rotations),
        "cost": _encode(cal.cost),
        "iterations": cal.iterations,
        "converged": cal.converged,
        "covariance": None
        if cov is None
        else {"names": list(cov.names), "matrix": _encode(cov.matrix)},
        "diagnostics": None
        if diag is None
        else {
            "statistic": _encode(diag.statistic),
            "dof": diag.dof,
            "p_value": _encode(diag.p_value),
            "pose_cost": _encode(diag.pose_cost),
            "status": diag.status,
        },
        "poses": _encode(list(cal.poses)),
    }


def _calibration_from_dict(data: Mapping[str, Any]) -> Calibration:
    if data.get("schema") != SCHEMA:
        raise ValueError(
            f"not a fieldcal calibration (schema {data.get('schema')!r}); "
            f"expected a file written by fieldcal with schema {SCHEMA!r}"
        )
    version = data.get("schema_version")
    if not isinstance(version, int) or version > SCHEMA_VERSION:
        raise ValueError(
            f"calibration schema version {version!r} is newer than this fieldcal understands "
            f"({SCHEMA_VERSION}); upgrade fieldcal"
        )
    cov = data.get("covariance")
    diag = data.get("diagnostics")
    dip_std = data.get("dip_std_deg")
    mis_std = data.get("misalignment_std_deg")
    return Calibration(
        accel=_sensor_from_dict(data.get("accel")),
        mag=_sensor_from_dict(data.get("mag")),
        gravity=_decode_array(data.get("gravity")),
        magnetic=_decode_array(data.get("magnetic")),
        rotations=_decode_array(data["rotations"]).reshape(-1, 3, 3),
        method=data["method"],
        cost=float(_decode_floats(data.get("cost", "nan"))),
        iterations=int(data.get("iterations", 0)),
        converged=bool(data.get("converged", True)),
        options=dict(data.get("options") or {}),
        dip_std_deg=None if dip_std is None else float(_decode_floats(dip_std)),
        misalignment_std_deg=None if mis_std is None else float(_decode_floats(mis_std)),
        covariance=None
        if cov is None
        else ParameterCovariance(tuple(cov["names"]), _decode_array(cov["matrix"])),
        diagnostics=None
        if diag is None
        else Diagnostics(
            statistic=float(_decode_floats(diag["statistic"])),
            dof=int(diag["dof"]),
            p_value=float(_decode_floats(diag["p_value"])),
            pose_cost=_decode_array(diag["pose_cost"]),
            status=diag.get("status", ""),
        ),
        poses=tuple(_decode_floats(p) if isinstance(p, list) else p for p in data.get("poses", [])),
        units=dict(data.get("units") or {}),
        version=data.get("fieldcal_version", ""),
        created=data.get("created", ""),
    )
