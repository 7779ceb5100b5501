"""Two calibrations of one device side by side: which parameters changed beyond their errors.

For a parameter present in both, with values ``a`` and ``b`` and standard errors ``σ_a`` and
``σ_b`` from each calibration's covariance, the change is ``b − a`` and its standard error
``σ = sqrt(σ_a² + σ_b²)`` (the two calibrations come from different logs: independent). The
parameter *changed* when ``|b − a| > sigmas · σ``; ``sigmas`` is 3 by default, because at 1 a
third of the parameters of an unchanged device would be flagged, and a calibration has about
thirty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import InputError

__all__ = ["Change", "Comparison", "compare", "parameter_values"]


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
    """

    changes: tuple[Change, ...]
    sigmas: float

    @property
    def changed(self) -> tuple[Change, ...]:
        """The parameters whose change exceeds ``sigmas`` combined standard errors."""
        return tuple(c for c in self.changes if abs(c.z) > self.sigmas)

    def to_dict(self) -> dict[str, Any]:
        return {
            "sigmas": self.sigmas,
            "changed": [c.name for c in self.changed],
            "parameters": [
                {"name": c.name, "before": c.before, "after": c.after, "std": c.std, "z": c.z}
                for c in self.changes
            ],
        }


def parameter_values(cal: Any) -> dict[str, float]:
    """Each named parameter's value (the names of ``cal.covariance``)."""
    out: dict[str, float] = {}
    for sensor in ("accel", "mag", "gyro"):
        part = getattr(cal, sensor)
        if part is None:
            continue
        for j in range(3):
            out[f"{sensor}.bias[{j}]"] = float(part.bias[j])
            for k in range(3):
                out[f"{sensor}.gain[{j},{k}]"] = float(part.gain[j, k])
    if cal.dip_deg is not None:
        out["dip_deg"] = float(cal.dip_deg)
    return out


def _stds(cal: Any, names: list[str]) -> np.ndarray:
    if cal.covariance is None:
        return np.full(len(names), np.nan)
    return np.array([cal.covariance.std(n) if n in cal.covariance.names else np.nan for n in names])


def compare(before: Any, after: Any, *, sigmas: float = 3.0) -> Comparison:
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
    first, second = parameter_values(before), parameter_values(after)
    names = [n for n in first if n in second]
    std = np.sqrt(_stds(before, names) ** 2 + _stds(after, names) ** 2)
    changes = tuple(
        Change(n, first[n], second[n], float(s)) for n, s in zip(names, std, strict=True)
    )
    return Comparison(changes, float(sigmas))
