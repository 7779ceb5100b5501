"""The calibration result: sensors, fields, pose rotations, uncertainty and the verdict.

Model (seed paper Eq. 1, 4). While the device rests in pose ``i`` each sensor ``s`` reads

    s_s[i, j] = K_s R_i f_s + b_s + ε,   ε ~ N(0, Σ_s)

with ``K_s`` the gain matrix (scale, cross-axis, soft iron), ``b_s`` the bias (offset, hard
iron), ``R_i`` the rotation from the world frame to the body frame and ``f_s`` the reference
field in the world frame (conventions in :mod:`fieldcal.geometry.frames`). Each pose mean also
carries a pose-level error of covariance ``Q_s`` (``pose_noise_std² I``) that does not average
away with the samples. The inverse model maps a raw reading to the common body frame:
``K_s⁻¹ (raw − b_s)``.

Everything here is stored once: standard errors are derived from :attr:`Calibration.covariance`,
the cost from :attr:`Calibration.diagnostics`; the JSON form lives in :mod:`fieldcal.serialize`.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import functools
import importlib
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._frozen import ArrayDataclass, frozen_array
from ._version import __version__
from .comparison import Comparison, compare
from .covariance import (
    GYRO,
    SENSORS,
    Diagnostics,
    ParameterCovariance,
    _bias_names,
    _gain_names,
)
from .findings import Findings, GyroSegment
from .geometry.frames import (
    dip_of,
    misalignment_angle_deg,
    misalignment_rotvec,
    nearest_signed_permutation,
    orthogonal_polar_factor,
    twin_flip,
)
from .interference import InterferenceModel
from .limits import LARGEST, RANGE_TEXT, in_range
from .notebook import calibration_html
from .reference import FieldReference
from .serialize import SCHEMA, SCHEMA_VERSION, decode, dumps, encode, upgrade
from .thermal import TemperatureModel, temperature_names
from .verdicts import Accuracy, Reason, RejectedPose, Verdict

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "GYRO",
    "SENSORS",
    "Accuracy",
    "Calibration",
    "Diagnostics",
    "ParameterCovariance",
    "Reason",
    "RejectedPose",
    "SensorCalibration",
    "Verdict",
]

Array = NDArray[np.float64]

_MATRIX = {"shape": (3, 3)}
_VECTOR = {"shape": (3,)}


@dataclass(frozen=True, eq=False)
class SensorCalibration(ArrayDataclass):
    """One sensor's parameters in the model ``mean raw reading = gain @ R_i @ field + bias``.

    Attributes
    ----------
    gain : (3, 3) array
        ``K_s``: maps a body-frame field vector to raw units (scale, cross-axis, soft iron).
    bias : (3,) array
        ``b_s`` in raw units (offset, hard iron).
    noise_cov : (3, 3) array
        ``Σ_s``, covariance of one raw sample, raw units squared.
    noise_cov_std : (3, 3) array or None
        Standard error of each entry of ``noise_cov`` (Wishart for the within-pose scatter).
    noise_source : str
        How ``noise_cov`` was obtained: ``"scatter"`` (Eq. 7, within-pose scatter),
        ``"residuals"`` (one sample per pose: isotropic, from the fit's residuals) or ``"user"``.
    pose_noise_std : float
        ``q_s``: standard deviation (raw units, per axis) of the pose-level error that each pose
        mean carries on top of ``Σ_s/Δ_i`` (non-linearity, a field varying across the desk,
        drift, flexing). 0 when the data show none.
    pose_noise_std_se : float or None
        Its standard error (``None`` when it was not estimated).
    covariance : ParameterCovariance or None
        This sensor's block of :attr:`Calibration.covariance` (names ``"gain[j,k]"``,
        ``"bias[j]"``, ``"temp[k,j]"``), filled in by the :class:`Calibration` that holds it.
    temperature : TemperatureModel or None
        The bias against temperature, ``bias(T) = bias + Σ c_k (T − T_ref)^k``
        (:mod:`fieldcal.thermal`); ``None`` when the log had no temperature.
    """

    gain: Array = field(metadata=_MATRIX)
    bias: Array = field(metadata=_VECTOR)
    noise_cov: Array = field(metadata=_MATRIX)
    noise_cov_std: Array | None = field(default=None, metadata=_MATRIX)
    noise_source: str = "scatter"
    pose_noise_std: float = 0.0
    pose_noise_std_se: float | None = None
    covariance: ParameterCovariance | None = field(
        default=None, repr=False, metadata={"stored": False}
    )
    temperature: TemperatureModel | None = None
    interference: InterferenceModel | None = None
    JSON_DERIVED = ("gain_std", "bias_std")

    def __post_init__(self) -> None:
        for name in ("gain", "bias", "noise_cov", "noise_cov_std"):
            if (value := getattr(self, name)) is not None:
                object.__setattr__(self, name, frozen_array(value))
        object.__setattr__(self, "pose_noise_std", float(self.pose_noise_std))
        if self.pose_noise_std_se is not None:
            object.__setattr__(self, "pose_noise_std_se", float(self.pose_noise_std_se))
        t = self.temperature
        if t is not None and self.covariance is not None and t.order:  # its error bars
            std = self.covariance.stds(temperature_names(t.order))
            object.__setattr__(self, "temperature", dataclasses.replace(t, std=std))

    @property
    def gain_std(self) -> Array | None:
        """Standard error of each entry of ``gain`` (from :attr:`covariance`), or ``None``."""
        if self.covariance is None:
            return None
        return self.covariance.stds([n.split(".", 1)[1] for n in _gain_names("s")]).reshape(3, 3)

    @property
    def bias_std(self) -> Array | None:
        """Standard error of each entry of ``bias`` (from :attr:`covariance`), or ``None``."""
        if self.covariance is None:
            return None
        return self.covariance.stds([n.split(".", 1)[1] for n in _bias_names("s")])

    def predict(self, rotations: Array, reference: Array) -> Array:
        """Noise-free mean reading per pose, ``gain @ R_i @ reference + bias`` (Eq. 4)."""
        body = np.einsum("nij,j->ni", np.asarray(rotations, dtype=float), reference)
        return self.distort(body)

    def distort(self, body: ArrayLike) -> Array:
        """Forward model: body-frame vectors (..., 3) -> raw readings ``gain @ v + bias``."""
        return np.asarray(body, dtype=float) @ self.gain.T + self.bias

    def correct(self, raw: ArrayLike, temperature: ArrayLike | None = None) -> Array:
        """Inverse model: raw readings (..., 3) -> body-frame vectors ``gain⁻¹ (raw − bias)``;
        with ``temperature`` (°C, one per reading or one for all) the bias is ``bias(T)``
        (:attr:`temperature`; ignored when the sensor has no temperature model)."""
        given = np.asarray(raw)
        if given.dtype.kind not in "fiu":
            raise ValueError(
                f"raw readings must be real numbers, got an array of {given.dtype.name}"
            )
        x = given.astype(float)
        if x.shape[-1:] != (3,):
            raise ValueError(f"raw readings must have shape (..., 3), got {x.shape}")
        if temperature is not None and self.temperature is not None and self.temperature.order:
            t = np.asarray(temperature, dtype=float)
            if t.shape not in ((), x.shape[:-1]):
                raise ValueError(
                    f"temperature must be one value or one per reading {x.shape[:-1]}, got "
                    f"shape {t.shape}"
                )
            x = x - self.temperature.shift(t)
        body = np.linalg.solve(self.gain, (x - self.bias).reshape(-1, 3).T).T.reshape(x.shape)
        return cast(Array, body)  # numpy's stubs widen solve's float64 to floating


@dataclass(frozen=True, eq=False)
class Calibration(ArrayDataclass):
    """The result of a calibration: both sensors, the fields, every pose's rotation.

    Conventions (:mod:`fieldcal.geometry.frames`, ``docs/conventions.md``): world frame
    North-East-Down with ``gravity = (0, 0, −|g|)`` (the accelerometer's reading at rest, "up")
    and ``magnetic = |h| (cos dip, 0, sin dip)``; ``rotations[i]`` maps world vectors to the
    body frame in pose ``i``; a sensor reads ``gain @ R_i @ field + bias`` on average.

    Attributes
    ----------
    accel, mag : SensorCalibration or None
        ``None`` for a sensor that was not calibrated.
    gravity, magnetic : (3,) arrays or None
        Reference fields in the world frame of Eq. 2.
    rotations : (N, 3, 3) array
        ``R_i``, world frame to body frame, per pose used in the fit.
    method : str
        The method's registry name (or ``"truth"`` for simulated truth).
    iterations : int
    converged : bool
        Whether the optimiser converged; nothing else (plausibility is in :attr:`verdict`).
    message : str
        The method's own one-line account of its optimisation (fits used, stopping reason).
    options : dict
        What was used, for provenance: every method option, ``body_frame``, ``mag_mirrored``,
        the noise sources.
    covariance : ParameterCovariance or None
        Joint covariance of the named global parameters; every standard error derives from it.
    diagnostics : Diagnostics or None
        Fit certificate and per-pose cost.
    poses : tuple of dict
        One entry per pose (``index``, ``samples``, ``cost``, ``share``, ``trimmed`` and, from
        log files, ``start``/``stop`` or ``label``); written as the ``poses`` list in JSON.
    verdict : Verdict or None
        Whether to trust the result, with reasons.
    rejected : tuple of RejectedPose
        Poses dropped by the robust fit.
    accuracy : Accuracy or None
        Predicted errors in the user's terms.
    gyro : SensorCalibration or None
        The gyroscope, fitted after the other sensors from the motion between the poses
        (:mod:`fieldcal.gyro`): ``raw_ω = gain @ ω + bias``, ω in rad/s in the common body
        frame; ``noise_cov`` of one raw sample; ``pose_noise_std`` unused (0). Its gain and
        bias are in :attr:`covariance` as ``gyro.gain[j,k]``, ``gyro.bias[j]`` (no
        correlation with the other sensors' parameters is kept). ``None`` without one.
    gyro_segments : tuple of dict
        One entry per motion segment the gyroscope was fitted on (``start``, ``stop`` rows,
        ``seconds``, ``angle_deg`` turned, ``residual_deg`` after calibration).
    findings : Findings
        What the estimators measured that the verdict's rules judge (:mod:`fieldcal.findings`:
        the gyroscope stage's misfit, correlated poses, the continuous motion's findings).
    field_reference : FieldReference or None
        JSON key ``reference``. The field the World Magnetic Model expects where and when the
        log was recorded (``location=``, :func:`fieldcal.expected_field`); it decided the
        magnetometer's handedness and the verdict compares the fitted dip with it. ``None``
        without one.
    units : dict
        Units of raw and calibrated readings, for humans and exports.
    version, created : str
        fieldcal version and ISO 8601 UTC time that produced the result (provenance: not part
        of equality).
    """

    accel: SensorCalibration | None
    mag: SensorCalibration | None
    gravity: Array | None = field(metadata=_VECTOR)
    magnetic: Array | None = field(metadata=_VECTOR)
    rotations: Array = field(metadata={"shape": (-1, 3, 3)})
    method: str
    iterations: int = 0
    converged: bool = True
    message: str = ""
    options: dict[str, Any] = field(default_factory=dict)
    covariance: ParameterCovariance | None = field(default=None, repr=False)
    diagnostics: Diagnostics | None = field(default=None, repr=False)
    poses: tuple[dict[str, Any], ...] = field(default=(), repr=False)
    verdict: Verdict | None = None
    rejected: tuple[RejectedPose, ...] = ()
    accuracy: Accuracy | None = None
    gyro: SensorCalibration | None = None
    gyro_segments: tuple[GyroSegment, ...] = field(default=(), repr=False)
    findings: Findings = field(default_factory=Findings, repr=False)
    field_reference: FieldReference | None = field(
        default=None, repr=False, metadata={"key": "reference"}
    )
    units: dict[str, str] = field(default_factory=dict, repr=False)
    version: str = field(
        default="", compare=False, repr=False, metadata={"key": "fieldcal_version"}
    )
    created: str = field(default="", compare=False, repr=False)

    JSON_DERIVED = (
        "dip_deg",
        "dip_std_deg",
        "misalignment_deg",
        "misalignment_std_deg",
        "cost",
    )

    def __post_init__(self) -> None:
        for name in ("gravity", "magnetic", "rotations"):
            if (value := getattr(self, name)) is not None:
                object.__setattr__(self, name, frozen_array(value))
        object.__setattr__(self, "poses", tuple(dict(p) for p in self.poses))
        segments = tuple(cast(GyroSegment, dict(p)) for p in self.gyro_segments)
        object.__setattr__(self, "gyro_segments", segments)
        object.__setattr__(self, "rejected", tuple(self.rejected))
        object.__setattr__(self, "iterations", int(self.iterations))
        object.__setattr__(self, "converged", bool(self.converged))
        blocks = None if self.covariance is None else self.covariance.sensor_blocks
        for name in (*SENSORS, GYRO):  # each sensor sees its block of the one covariance
            sensor = getattr(self, name)
            if sensor is not None:
                block = None if blocks is None else blocks[name]
                if block is not sensor.covariance and block != sensor.covariance:
                    object.__setattr__(self, name, dataclasses.replace(sensor, covariance=block))
        if not self.version:
            object.__setattr__(self, "version", __version__)
        if not self.created:
            now = _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat()
            object.__setattr__(self, "created", now)
        if not self.units:
            object.__setattr__(self, "units", _default_units(self))
        elif self.gyro is not None and "gyro_calibrated" not in self.units:
            units = {"gyro_raw": "as given", "gyro_calibrated": "rad/s"}
            object.__setattr__(self, "units", {**self.units, **units})

    def __repr__(self) -> str:
        sensors = "+".join(s for s in (*SENSORS, GYRO) if getattr(self, s) is not None) or "none"
        parts = [f"method={self.method!r}"]
        if self.verdict is not None:
            parts.append(f"verdict={self.verdict.level!r}")
        parts.append(f"poses={self.n_poses}")
        parts.append(f"sensors={sensors}")
        if self.dip_deg is not None:
            std = self.dip_std_deg
            parts.append(f"dip={self.dip_deg:.3f}" + (f"±{std:.2g}°" if std is not None else "°"))
        if self.rejected:
            parts.append(f"rejected={len(self.rejected)}")
        return f"Calibration({', '.join(parts)})"

    # ----------------------------------------------------------------- derived quantities
    @property
    def n_poses(self) -> int:
        """Number of poses in the fit (rejected ones excluded)."""
        return int(self.rotations.shape[0])

    @property
    def cost(self) -> float:
        """``J`` of Eq. 8 at the end (:attr:`diagnostics`' statistic; NaN without one)."""
        return float("nan") if self.diagnostics is None else self.diagnostics.statistic

    @property
    def dip_deg(self) -> float | None:
        """Magnetic dip in degrees, positive when the field points below the horizon."""
        if self.magnetic is None or self.gravity is None:
            return None
        return dip_of(self.magnetic)

    @property
    def dip_std_deg(self) -> float | None:
        """Standard error of :attr:`dip_deg` (degrees), from :attr:`covariance`."""
        if self.covariance is None or "dip_deg" not in self.covariance.names:
            return None
        return self.covariance.std("dip_deg")

    @property
    def gravity_norm(self) -> float | None:
        """``|g|``: the unit of the calibrated accelerometer."""
        return None if self.gravity is None else _norm(self.gravity)

    @property
    def field_strength(self) -> float | None:
        """``|h|``: the unit of the calibrated magnetometer."""
        return None if self.magnetic is None else _norm(self.magnetic)

    @property
    def misalignment_deg(self) -> float | None:
        """Angle between the magnetometer's and the accelerometer's axes (degrees)."""
        if self.accel is None or self.mag is None:
            return None
        return misalignment_angle_deg(self.accel.gain, self.mag.gain)

    @functools.cached_property
    def misalignment_std_deg(self) -> float | None:
        """Delta-method standard error (degrees) of :attr:`misalignment_deg`.

        Far from 0 the angle is smooth: ``σ = sqrt(nᵀ C_θ n)`` along its rotation vector θ.
        Near 0 (within 3σ) the angle is the norm of a nearly centred vector; ``sqrt(tr C_θ)``
        is then reported (its root mean square spread).
        """
        if self.accel is None or self.mag is None or self.covariance is None:
            return None
        names = _gain_names("accel") + _gain_names("mag")
        if not all(n in self.covariance.names for n in names):
            return None
        Ka, Km = self.accel.gain, self.mag.gain
        S = nearest_signed_permutation(orthogonal_polar_factor(Km) @ orthogonal_polar_factor(Ka).T)
        h = 1e-6 * max(float(np.abs(Ka).max()), float(np.abs(Km).max()))
        steps = (np.eye(9) * h).reshape(9, 3, 3)
        Kas = np.concatenate([Ka[None], Ka + steps, np.broadcast_to(Ka, (9, 3, 3))])
        Kms = np.concatenate([Km[None], np.broadcast_to(Km, (9, 3, 3)), Km + steps])
        theta = misalignment_rotvec(Kas, Kms, S)
        J = ((theta[1:] - theta[0]) / h).T  # (3, 18), forward differences
        idx = [self.covariance.index(n) for n in names]
        Ct = J @ self.covariance.matrix[np.ix_(idx, idx)] @ J.T
        norm = float(np.linalg.norm(theta[0]))
        spread = float(np.sqrt(max(np.trace(Ct), 0.0)))
        if norm > 3.0 * spread:
            n = theta[0] / norm
            return float(np.degrees(np.sqrt(max(n @ Ct @ n, 0.0))))
        return float(np.degrees(spread))

    # ----------------------------------------------------------------- model
    def sensor(self, name: str) -> SensorCalibration:
        """The calibration of sensor ``name`` (``"accel"``, ``"mag"`` or ``"gyro"``); a
        one-line error when it was not calibrated."""
        if name not in (*SENSORS, GYRO):
            raise ValueError(f"sensor must be one of {', '.join((*SENSORS, GYRO))}, got {name!r}")
        value: SensorCalibration | None = getattr(self, name)
        if value is None:
            raise ValueError(f"this calibration has no {name}; calibrate one first")
        return value

    def reference(self, name: str) -> Array:
        """The reference field of sensor ``name`` in the world frame."""
        value = self.gravity if name == "accel" else self.magnetic
        if value is None:
            raise ValueError(f"this calibration has no {name} reference field")
        return value

    def predicted_means(self) -> tuple[Array | None, Array | None]:
        """The model's noise-free reading per pose, ``gain @ R_i @ field + bias`` (Eq. 4)."""
        out = [
            None
            if getattr(self, s) is None
            else self.sensor(s).predict(self.rotations, self.reference(s))
            for s in SENSORS
        ]
        return out[0], out[1]

    def correct_accel(self, raw: ArrayLike, temperature: ArrayLike | None = None) -> Array:
        """Raw accelerometer readings (..., 3) -> body-frame specific force (inverse model);
        ``temperature`` (°C) applies the bias's temperature terms when fitted."""
        return self.sensor("accel").correct(raw, temperature)

    def correct_mag(self, raw: ArrayLike, temperature: ArrayLike | None = None) -> Array:
        """Raw magnetometer readings (..., 3) -> body-frame magnetic field (inverse model);
        ``temperature`` (°C) applies the bias's temperature terms when fitted."""
        return self.sensor("mag").correct(raw, temperature)

    def compare(self, other: Calibration, *, sigmas: float = 3.0) -> Comparison:
        """Which parameters of ``other`` (a later calibration of the same device) differ from
        this one's by more than ``sigmas`` combined standard errors
        (:mod:`fieldcal.comparison`)."""
        return compare(self, other, sigmas=sigmas)

    def _repr_html_(self) -> str:
        """The verdict, the key numbers with ± and units, rejected poses and a coverage
        picture, for notebooks (:mod:`fieldcal.notebook`)."""
        return calibration_html(self)

    def plot(self, log: object = None) -> dict[str, Figure]:
        """The report's figures as matplotlib Figures, by name.

        Parameters
        ----------
        log : Log, str or path, optional
            The log the calibration was made from (a path is read with the columns the
            calibration recorded): with it every figure of ``fieldcal report`` (``timeline``,
            ``residuals``, ``histograms``, ``accel_sphere``, ``mag_sphere``, ``coverage``,
            ``gyro``); without it those the calibration alone holds the data for
            (``residuals``, ``gyro``).

        Returns
        -------
        dict of str to matplotlib.figure.Figure
            Each figure is unattached to pyplot: show it in a notebook by leaving it as a
            cell's value, or ``fig.savefig("name.png")``.

        Notes
        -----
        Needs matplotlib (``pip install 'fieldcal[plot]'``). The figures are drawn by
        :func:`fieldcal.output.report.report_figures`, reached through importlib: the result
        class stays below the output room it would otherwise import.
        """
        report = importlib.import_module("fieldcal.output.report")
        figures: dict[str, Figure] = report.report_figures(self, log)
        return figures

    def correct_gyro(self, raw: ArrayLike, temperature: ArrayLike | None = None) -> Array:
        """Raw gyroscope readings (..., 3) -> body-frame angular rate in rad/s,
        ``gain⁻¹ (raw − bias)``, in the same body frame as the other sensors; ``temperature``
        (°C) applies the bias's temperature terms when fitted."""
        return self.sensor(GYRO).correct(raw, temperature)

    def with_field_magnitudes(
        self, gravity: float | None = None, field_strength: float | None = None
    ) -> Calibration:
        """The same calibration with ``|g| = gravity`` and ``|h| = field_strength``.

        Gains (and their covariance entries) are divided by the new magnitude relative to the
        old one; every predicted reading is unchanged.
        """
        factors: dict[str, float] = {}

        def rescaled(
            name: str, sensor: SensorCalibration | None, ref: Array | None, value: float | None
        ) -> tuple[SensorCalibration | None, Array | None]:
            if value is None or sensor is None or ref is None:
                return sensor, ref
            if not _magnitude_ok(value):
                label = "gravity" if name == "accel" else "field_strength"
                raise ValueError(
                    f"{label} must be a positive number {RANGE_TEXT}, got {value!r}"[:200]
                )
            c = float(np.linalg.norm(ref)) / float(value)
            factors[f"{name}.gain"] = c
            return dataclasses.replace(sensor, gain=sensor.gain * c), ref / c

        accel, g = rescaled("accel", self.accel, self.gravity, gravity)
        mag, h = rescaled("mag", self.mag, self.magnetic, field_strength)
        covariance = None if self.covariance is None else self.covariance.scaled(factors)
        return dataclasses.replace(
            self, accel=accel, mag=mag, gravity=g, magnetic=h, covariance=covariance, units={}
        )

    def with_raw_scale(
        self, scales: Mapping[str, float], *, options: Mapping[str, object] | None = None
    ) -> Calibration:
        """The same calibration for raw readings multiplied by ``scales[sensor]``.

        Gains, biases and pose-level noise scale by the factor, noise covariances by its square,
        and so do their covariance entries and the pose residuals; angles, the verdict and the
        relative accuracy do not change. :func:`fieldcal.calibrate` fits readings divided by a
        power of two and calls this to express the result in the user's units. ``options``,
        when given, are merged into :attr:`options` in the same step.
        """
        scaled = {n: c for n, c in scales.items() if getattr(self, n) is not None and c != 1.0}
        changes: dict[str, Any] = (
            {} if options is None else {"options": {**self.options, **options}}
        )
        covariance = self.covariance
        if scaled and covariance is not None:
            parts = ("gain", "bias", "temp")
            factors = {f"{name}.{part}": c for name, c in scaled.items() for part in parts}
            covariance = changes["covariance"] = covariance.scaled(factors)
        rows = [dict(p) for p in self.poses] if scaled else []
        for name, c in scaled.items():
            s: SensorCalibration = getattr(self, name)
            changes[name] = dataclasses.replace(
                s,
                gain=s.gain * c,
                bias=s.bias * c,
                noise_cov=s.noise_cov * c * c,
                noise_cov_std=None if s.noise_cov_std is None else s.noise_cov_std * c * c,
                pose_noise_std=s.pose_noise_std * c,
                pose_noise_std_se=None if s.pose_noise_std_se is None else s.pose_noise_std_se * c,
                temperature=None if s.temperature is None else s.temperature.scaled(c),
                # the block the result will hold (attached here, not by a second replace)
                covariance=None if covariance is None else covariance.sensor_blocks[name],
            )
            key = f"{name}_residual"
            for row in (r for r in rows if key in r):
                row[key] = [float(x) * c for x in row[key]]
        if rows:
            changes["poses"] = tuple(rows)
        return dataclasses.replace(self, **changes) if changes else self

    def with_mag_handedness(self, mirrored: bool = False) -> Calibration:
        """The twin of this result whose magnetometer has the requested handedness.

        Static poses cannot tell a magnetometer mirrored relative to the accelerometer from an
        unmirrored one in the opposite magnetic hemisphere (:func:`fieldcal.geometry.frames.
        twin_flip`). Both twins have the same likelihood; this picks ``det(K_a K_m) > 0``
        (``mirrored`` false: both triads right-handed as given) or ``det(K_a K_m) < 0``. The
        gain negated is that of the sensor that does not define the body frame.
        """
        if self.mag is None or self.accel is None or self.magnetic is None:
            return self
        # signs only (determinants of gains in large raw units overflow), both in one call
        relative = np.prod(np.linalg.slogdet(np.array([self.accel.gain, self.mag.gain]))[0])
        if (relative < 0) == bool(mirrored):
            return self
        Ka = self.accel.gain
        accel_frame = bool(np.abs(Ka - Ka.T).max() <= 1e-9 * np.abs(Ka).max())  # symmetric
        name = "mag" if accel_frame else "accel"
        sensor: SensorCalibration = getattr(self, name)
        flipped = dataclasses.replace(sensor, gain=-sensor.gain)
        h, covariance = self.magnetic, self.covariance
        if covariance is not None:
            covariance = covariance.scaled({f"{name}.gain": -1.0, "dip_deg": -1.0})
        return dataclasses.replace(
            self,
            accel=flipped if name == "accel" else self.accel,
            mag=flipped if name == "mag" else self.mag,
            magnetic=np.array([h[0], h[1], -h[2]]),
            rotations=self.rotations @ twin_flip(name),
            covariance=covariance,
            options={**self.options, "mag_mirrored": bool(mirrored)},
        )

    # ----------------------------------------------------------------- JSON
    def to_dict(self) -> dict[str, Any]:
        """The JSON document as Python objects (see ``docs/json-schema.md``)."""
        body = encode(self)
        assert isinstance(body, dict)  # a dataclass encodes as an object
        header = {
            "schema": SCHEMA,
            "schema_version": SCHEMA_VERSION,
            "fieldcal_version": body.pop("fieldcal_version"),
            "created": body.pop("created"),
            "method": body.pop("method"),
            "conventions": CONVENTIONS,
        }
        return {**header, **body}

    def to_json(self, indent: int | None = 2) -> str:
        """Serialise to the versioned JSON schema (lossless: floats are written exactly)."""
        return dumps(self.to_dict(), indent)

    @classmethod
    def from_dict(cls, data: Mapping[str, object]) -> Calibration:
        """Read the document of :meth:`to_dict` (any schema version up to ours).

        Validated completely: a one-line ``ValueError`` names the first problem (a missing
        key, a wrong type or shape, a non-finite or singular gain)."""
        if not isinstance(data, Mapping):
            raise ValueError("not a fieldcal calibration: the document is not an object")
        cal: Calibration = decode(cls, upgrade(data))
        cal.check_values()
        return cal

    @classmethod
    def from_json(cls, text: str) -> Calibration:
        """Read a calibration written by :meth:`to_json` (any schema version up to ours)."""
        if not isinstance(text, (str, bytes, bytearray)):
            raise ValueError(
                f"from_json takes the text of a calibration file, not {type(text).__name__}; "
                "read the file first (Path(name).read_text())"
            )
        try:
            data = json.loads(text)
        except RecursionError:
            raise ValueError("not a fieldcal calibration JSON: nested too deeply") from None
        except ValueError as exc:  # JSONDecodeError, an integer of thousands of digits
            reason = " ".join(str(exc).split())[:120]
            raise ValueError(f"not a fieldcal calibration JSON: {reason}") from None
        if not isinstance(data, dict):
            raise ValueError("not a fieldcal calibration JSON: the document is not an object")
        return cls.from_dict(data)

    def check_values(self) -> None:
        """Refuse values no correction can use: non-finite or singular gains, non-finite
        biases, reference fields or rotations, and gains or biases beyond the range fieldcal
        works in (an entry over :data:`~fieldcal.limits.LARGEST`, 1e150; a gain's scale
        under :data:`SMALLEST_GAIN`). One-line ``ValueError`` naming the first."""
        if self.accel is None and self.mag is None:
            raise ValueError(
                "invalid calibration: it has neither an accelerometer nor a magnetometer"
            )
        named = [(n, s) for n in (*SENSORS, GYRO) if (s := getattr(self, n)) is not None]
        gains = np.array([s.gain for _, s in named])
        # one SVD for every gain (a gain with NaN or inf is named below, before its SVD)
        singular = np.linalg.svd(gains, compute_uv=False) if np.isfinite(gains).all() else None
        if singular is not None and _at_a_glance(self, named, gains, singular):
            return  # the usual case: every check below passes (they name the first problem)
        for k, (name, sensor) in enumerate(named):
            field, q = name != GYRO, sensor.pose_noise_std
            for part in ("gain", "bias", "noise_cov"):
                if not np.all(np.isfinite(getattr(sensor, part))):
                    raise ValueError(f"invalid calibration: {name}.{part} has NaN or inf entries")
            if field and np.any(np.diag(sensor.noise_cov) < 0):
                raise ValueError(
                    f"invalid calibration: {name}.noise_cov has a negative variance on its diagonal"
                )
            if field and np.any(np.abs(sensor.noise_cov) > LARGEST * LARGEST):  # units²
                raise ValueError(
                    f"invalid calibration: {name}.noise_cov has an entry beyond {LARGEST**2:g}, "
                    "the square of the largest reading; write the file again with fieldcal"
                )
            if field and not (np.isfinite(q) and q >= 0):
                raise ValueError(
                    f"invalid calibration: {name}.pose_noise_std must be a finite number >= 0"
                )
            s = np.linalg.svd(sensor.gain, compute_uv=False) if singular is None else singular[k]
            _check_range(name, sensor.gain, sensor.bias, s)
            if not s[-1] > 1e-12 * s[0]:
                raise ValueError(
                    f"invalid calibration: {name}.gain is singular, so "
                    f"{'readings' if field else 'rates'} cannot be corrected"
                )
            ref = self.gravity if name == "accel" else self.magnetic
            if field and (ref is None or not (np.isfinite(ref).all() and _norm(ref) > 0)):
                raise ValueError(f"invalid calibration: the {name} reference field is not finite")
        if not np.all(np.isfinite(self.rotations)):
            raise ValueError("invalid calibration: rotations has NaN or inf entries")
        if self.covariance is not None and not np.all(np.isfinite(self.covariance.matrix)):
            raise ValueError("invalid calibration: covariance has NaN or inf entries")


#: The smallest scale (singular value) of a gain in a file, raw units per unit of field: the
#: smallest raw scale supported (1e-30) over the largest field taken (1e150) stays above it.
SMALLEST_GAIN = 1e-200


def _at_a_glance(
    cal: Calibration, named: Sequence[tuple[str, SensorCalibration]], gains: Array, singular: Array
) -> bool:
    """Whether every check of :meth:`Calibration.check_values` passes, in a few operations on
    all sensors at once (``gains`` finite, ``singular`` their singular values); ``False`` sends
    the checks one by one, to name the first problem. NaN fails every comparison."""
    fields = [s for n, s in named if n != GYRO]
    given = [cal.gravity if n == "accel" else cal.magnetic for n, _ in named if n != GYRO]
    refs = [r for r in given if r is not None]
    if len(refs) < len(given):
        return False
    noise = np.array([s.noise_cov for s in fields]).reshape(-1, 9)
    cov = () if cal.covariance is None else (cal.covariance.matrix.ravel(),)
    must_be_finite = [*refs, cal.rotations.ravel(), *(s.noise_cov.ravel() for _, s in named), *cov]
    entries = np.concatenate([gains.ravel(), *(s.bias for _, s in named)])
    return bool(
        np.isfinite(np.concatenate(must_be_finite)).all()
        and np.abs(entries).max() <= LARGEST
        and np.abs(noise).max() <= LARGEST * LARGEST
        and noise[:, ::4].min() >= 0
        and all(math.isfinite(s.pose_noise_std) and s.pose_noise_std >= 0 for s in fields)
        and all(s[-1] > 1e-12 * s[0] and s[-1] >= SMALLEST_GAIN for s in singular.tolist())
        and all(float(r @ r) > 0 for r in refs)
    )


def _check_range(name: str, gain: Array, bias: Array, singular: Array) -> None:
    """Gain and bias entries within :data:`~fieldcal.limits.LARGEST`, a gain's scale at least
    :data:`SMALLEST_GAIN`, naming the key; ``singular``: the gain's singular values."""
    for part, values in (("gain", gain), ("bias", bias)):
        big = np.abs(values) > LARGEST
        if big.any():
            at = np.unravel_index(int(np.argmax(big)), values.shape)
            key = f"{name}.{part}[{','.join(str(int(i)) for i in at)}]"
            raise ValueError(
                f"invalid calibration: {key} is {values[at]:.3g}, beyond the range fieldcal "
                f"works in ({RANGE_TEXT}); write the file again with fieldcal"
            )
    # a well-conditioned gain of no reading's scale (a singular one is said after)
    if singular[-1] > 1e-12 * singular[0] and not singular[-1] >= SMALLEST_GAIN:
        raise ValueError(
            f"invalid calibration: {name}.gain's smallest scale is {singular[-1]:.3g}, below "
            f"{SMALLEST_GAIN:g} (raw units per unit of field: no reading fieldcal takes gives "
            "it); write the file again with fieldcal"
        )


def _magnitude_ok(value: object) -> bool:
    """A field magnitude: a real number (not a bool) in :func:`fieldcal.limits.in_range`, so
    gains and their covariance stay in floating-point range."""
    if isinstance(value, (bool, np.bool_, np.complexfloating)):
        return False
    return isinstance(value, (int, float, np.number)) and in_range(float(value))


#: The conventions, stated in every document for readers without the docs.
CONVENTIONS = {
    "model": "mean raw reading in pose i = gain @ R_i @ field + bias",
    "correction": "body = inv(gain) @ (raw - bias)",
    "world_frame": "NED: gravity = (0, 0, -|g|), magnetic = |h| (cos dip, 0, sin dip)",
    "rotations": "R_i maps world-frame vectors to the body frame",
    "dip": "degrees, positive when the field points below the horizon",
    "pose_noise_std": "raw units per axis, the pose mean's error beyond noise_cov / samples",
    "gyro": "mean raw rate = gain @ omega + bias, omega in rad/s in the body frame",
}


#: Each sensor's gain and bias parameter names, in the order of its covariance block.
def _norm(v: Array) -> float:
    """``np.linalg.norm(v)``'s number (``sqrt(v·v)``), without its wrapper's cost."""
    return math.sqrt(float(v.ravel() @ v.ravel()))


def _default_units(cal: Calibration) -> dict[str, str]:
    g, h = cal.gravity_norm, cal.field_strength
    units = {"accel_raw": "as given", "mag_raw": "as given"}
    units["accel_calibrated"] = "|g| = 1" if g is None or g == 1.0 else f"|g| = {g:g}"
    units["mag_calibrated"] = "|h| = 1" if h is None or h == 1.0 else f"|h| = {h:g}"
    ref = cal.field_reference
    for unit in ("uT", "nT"):
        if ref is not None and h is not None and np.isclose(h, ref.intensity_in(unit), rtol=1e-9):
            units["mag_calibrated"] += f" {unit} ({ref.model} at {ref.place}, {ref.date})"
    if cal.gyro is not None:
        units.update(gyro_raw="as given", gyro_calibrated="rad/s")
    units["angles"] = "degrees"
    return units
