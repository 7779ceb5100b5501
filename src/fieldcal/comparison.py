"""Two calibrations of one device side by side: which parameters changed beyond their errors.

For a parameter present in both, with values ``a`` and ``b`` and standard errors ``σ_a`` and
``σ_b`` from each calibration's covariance, the change is ``b − a`` and its standard error
``σ = sqrt(σ_a² + σ_b²)`` (the two calibrations come from different logs: independent). The
parameter *changed* when ``|b − a| > sigmas · σ``; ``sigmas`` is 3 by default, because at 1 a
third of the parameters of an unchanged device would be flagged, and a calibration has about
thirty.

**Temperature and ageing apart.** A bias moves with the die temperature (``cal.<sensor>.
temperature``, :mod:`fieldcal.thermal`), so two calibrations made at different temperatures
differ even when nothing aged. When both have a temperature model for a sensor, its biases are
compared at one common temperature (:func:`common_temperature`: the middle of the temperatures
both saw, or where the one without fitted terms holds), ``b(T_c) = b + Σ c_k (T_c − T_ref)^k``
with the standard error of that sum from each covariance (the delta method, exact for a
polynomial); a change there is ageing. The coefficients ``<sensor>.temp[k,j]`` present in
both are compared too, each polynomial re-expanded about the same temperature: a change there
is the temperature behaviour itself.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from .errors import InputError

__all__ = [
    "Change",
    "Comparison",
    "common_temperature",
    "compare",
    "parameter_stds",
    "parameter_values",
    "temperature_values",
]


Array = NDArray[np.float64]


# What this module reads of a calibration, its sensors, their temperature models and the
# covariance: those classes live above it (fieldcal.calibration, fieldcal.thermal,
# fieldcal.covariance), which call it.
class _TemperatureModel(Protocol):
    @property
    def reference(self) -> float: ...
    @property
    def coefficients(self) -> Array: ...
    @property
    def span(self) -> Array: ...
    @property
    def order(self) -> int: ...
    def shift(self, temperature: float) -> Array: ...


class _Sensor(Protocol):
    @property
    def gain(self) -> Array: ...
    @property
    def bias(self) -> Array: ...
    @property
    def temperature(self) -> _TemperatureModel | None: ...


class _Covariance(Protocol):
    @property
    def names(self) -> tuple[str, ...]: ...
    @property
    def matrix(self) -> Array: ...
    def index(self, name: str) -> int: ...
    def std(self, name: str) -> float: ...


class Calibrated(Protocol):
    """What a comparison reads of a :class:`fieldcal.Calibration` (its sensors by name,
    ``accel``, ``mag``, ``gyro``, through ``getattr``)."""

    @property
    def dip_deg(self) -> float | None: ...
    @property
    def gravity_norm(self) -> float | None: ...
    @property
    def field_strength(self) -> float | None: ...
    @property
    def options(self) -> Mapping[str, object]: ...
    @property
    def covariance(self) -> _Covariance | None: ...


def _sensor(cal: Calibrated, name: str) -> _Sensor | None:
    part: _Sensor | None = getattr(cal, name)
    return part


@dataclass(frozen=True)
class Change:
    """One parameter in both calibrations: ``before``, ``after``, the change's standard
    error ``std`` and ``z = (after − before) / std`` (``nan`` without error bars)."""

    name: str
    before: float
    after: float
    std: float

    @property
    def difference(self) -> float:
        return self.after - self.before

    @property
    def z(self) -> float:
        return self.difference / self.std if self.std > 0 else math.nan


@dataclass(frozen=True)
class Comparison:
    """Every parameter both calibrations have, and which of them changed.

    Attributes
    ----------
    changes : tuple of Change
        In the covariance's order (gains, biases, dip, the gyroscope's).
    sigmas : float
        The threshold, in combined standard errors.
    temperature : dict of str to float
        The common temperature (°C) each sensor's biases were compared at (empty when neither
        calibration has a temperature model).
    """

    changes: tuple[Change, ...]
    sigmas: float
    temperature: Mapping[str, float] = field(default_factory=dict)

    @property
    def changed(self) -> tuple[Change, ...]:
        """The parameters whose change exceeds ``sigmas`` combined standard errors."""
        return tuple(c for c in self.changes if abs(c.z) > self.sigmas)

    def to_dict(self) -> dict[str, object]:
        return {
            "sigmas": self.sigmas,
            "temperature_c": dict(self.temperature),
            "changed": [c.name for c in self.changed],
            "parameters": [
                {"name": c.name, "before": c.before, "after": c.after, "std": c.std, "z": c.z}
                for c in self.changes
            ],
        }


def _reexpansion(model: _TemperatureModel, temperature: float) -> np.ndarray:
    """``A`` (K+1, K+1): ``(b, c_1, …, c_K)`` about ``T_ref`` to the same polynomial about
    ``T_c`` (``temperature`` clipped to the span, as the model holds it beyond):
    ``c'_k = Σ_{j≥k} C(j, k) δ^(j−k) c_j`` with ``δ = T_c − T_ref`` (``c_0 = b``)."""
    d = float(np.clip(temperature, model.span[0], model.span[1])) - model.reference
    K = model.order
    A = np.zeros((K + 1, K + 1))
    for k in range(K + 1):
        for j in range(k, K + 1):
            A[k, j] = math.comb(j, k) * d ** (j - k)
    return A


def _theta(part: _Sensor, model: _TemperatureModel) -> np.ndarray:
    """(K+1, 3): a sensor's bias and its temperature coefficients, one row per order."""
    return np.vstack([part.bias, model.coefficients])


def parameter_values(
    cal: Calibrated, temperature: Mapping[str, float] | None = None
) -> dict[str, float]:
    """Each named parameter's value (the names of ``cal.covariance``); with ``temperature``
    (°C per sensor) that sensor's bias at that temperature, ``bias + shift(T)``."""
    out: dict[str, float] = {}
    at = temperature or {}
    for sensor in ("accel", "mag", "gyro"):
        part = _sensor(cal, sensor)
        if part is None:
            continue
        bias = part.bias
        if sensor in at and part.temperature is not None:
            bias = bias + part.temperature.shift(at[sensor])
        for j in range(3):
            out[f"{sensor}.bias[{j}]"] = float(bias[j])
            for k in range(3):
                out[f"{sensor}.gain[{j},{k}]"] = float(part.gain[j, k])
    if cal.dip_deg is not None:
        out["dip_deg"] = float(cal.dip_deg)
    return out


def temperature_values(
    cal: Calibrated, temperature: Mapping[str, float] | None = None
) -> dict[str, float]:
    """Each fitted temperature coefficient ``<sensor>.temp[k,j]`` (order ``k`` from 1); with
    ``temperature`` (°C per sensor) the coefficients of the same polynomial about that
    temperature (its derivatives there over k!), which two calibrations with different
    reference temperatures share when the behaviour is the same."""
    out: dict[str, float] = {}
    at = temperature or {}
    for sensor in ("accel", "mag", "gyro"):
        part = _sensor(cal, sensor)
        model = None if part is None else part.temperature
        if part is None or model is None or not model.order:
            continue
        c = model.coefficients
        if sensor in at:
            c = (_reexpansion(model, at[sensor]) @ _theta(part, model))[1:]
        for k in range(model.order):
            for j in range(3):
                out[f"{sensor}.temp[{k + 1},{j}]"] = float(c[k, j])
    return out


def common_temperature(before: Calibrated, after: Calibrated, sensor: str) -> float | None:
    """The temperature (°C) to compare ``sensor``'s biases at, or ``None`` when either
    calibration has no temperature model for it: where the one without fitted terms holds
    (its reference), else the middle of the temperatures both saw (of the two spans' overlap;
    of the gap between them when they do not overlap)."""
    a, b = (getattr(_sensor(c, sensor), "temperature", None) for c in (before, after))
    if a is None or b is None:
        return None
    models = [a, b]
    flat = [m for m in models if m.order == 0]
    if flat:
        return float(flat[-1].reference)
    low = max(float(m.span[0]) for m in models)
    high = min(float(m.span[1]) for m in models)
    return 0.5 * (low + high)


def parameter_stds(
    cal: Calibrated, names: list[str], temperature: Mapping[str, float] | None = None
) -> np.ndarray:
    """Standard errors of the parameters ``names`` (NaN where the covariance has none); with
    ``temperature`` a sensor's bias and temperature coefficients are those about that
    temperature (:func:`parameter_values`, :func:`temperature_values`), their errors from
    ``A C Aᵀ`` (the re-expansion is linear: exact)."""
    if cal.covariance is None:
        return np.full(len(names), np.nan)
    cov = cal.covariance
    out = np.array([cov.std(n) if n in cov.names else np.nan for n in names])
    where = {n: i for i, n in enumerate(names)}
    for sensor, t in (temperature or {}).items():
        part = _sensor(cal, sensor)
        model = None if part is None else part.temperature
        if model is None or not model.order:
            continue
        A = _reexpansion(model, t)
        for j in range(3):
            terms = [f"{sensor}.bias[{j}]"]
            terms += [f"{sensor}.temp[{k},{j}]" for k in range(1, model.order + 1)]
            if not all(n in cov.names for n in terms):
                continue
            idx = [cov.index(n) for n in terms]
            C = A @ np.asarray(cov.matrix)[np.ix_(idx, idx)] @ A.T
            for k, name in enumerate(terms):
                if name in where:
                    out[where[name]] = math.sqrt(max(float(C[k, k]), 0.0))
    return out


def compare(before: Calibrated, after: Calibrated, *, sigmas: float = 3.0) -> Comparison:
    """The parameters of ``after`` against ``before``: see the module's docstring.

    Raises
    ------
    InputError
        The two are in different units (field magnitudes or gauges), or ``sigmas`` is not a
        positive number.
    """
    if not (isinstance(sigmas, (int, float)) and math.isfinite(sigmas) and sigmas > 0):
        raise InputError(f"sigmas must be a positive number, got {sigmas!r}")
    for what, a, b in (
        ("|g|", before.gravity_norm, after.gravity_norm),
        ("|h|", before.field_strength, after.field_strength),
    ):
        if a is not None and b is not None and not math.isclose(a, b, rel_tol=1e-9):
            raise InputError(
                f"the two calibrations are in different units ({what} = {a:g} and {b:g}); "
                "calibrate both with the same --gravity / --field-strength"
            )
    for key in ("body_frame",):
        if before.options.get(key, "accel") != after.options.get(key, "accel"):
            raise InputError(
                f"the two calibrations fix the body frame differently ({key}); compare "
                "calibrations made with the same options"
            )
    common = {
        s: t
        for s in ("accel", "mag", "gyro")
        if (t := common_temperature(before, after, s)) is not None
    }
    first = {**parameter_values(before, common), **temperature_values(before, common)}
    second = {**parameter_values(after, common), **temperature_values(after, common)}
    names = [n for n in first if n in second]
    std = np.sqrt(
        parameter_stds(before, names, common) ** 2 + parameter_stds(after, names, common) ** 2
    )
    changes = tuple(
        Change(n, first[n], second[n], float(s)) for n, s in zip(names, std, strict=True)
    )
    return Comparison(changes, float(sigmas), common)
