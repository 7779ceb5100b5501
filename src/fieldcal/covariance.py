"""The uncertainty of a calibration: the named parameters' covariance and the fit's goodness
(:class:`Diagnostics`: the χ² certificate of Eq. 8).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal, TypeAlias

import numpy as np
from numpy.typing import NDArray

from ._frozen import ArrayDataclass, frozen_array

__all__ = ["GYRO", "SENSORS", "Diagnostics", "ParameterCovariance", "Sensor"]

Array = NDArray[np.float64]
Sensor = Literal["accel", "mag"]
#: The index that takes a square block out of a covariance matrix: two slices when its
#: positions run in order (a view), else :func:`numpy.ix_` of them.
BlockIndex: TypeAlias = "tuple[slice, slice] | tuple[NDArray[np.intp], ...]"

#: The sensors of the joint model, in the order every table and parameter vector uses.
SENSORS: tuple[Sensor, ...] = ("accel", "mag")
#: The gyroscope: calibrated after the two field sensors, from the motion between the poses.
GYRO: Literal["gyro"] = "gyro"


def _gain_names(sensor: str) -> list[str]:
    return [f"{sensor}.gain[{j},{k}]" for j in range(3) for k in range(3)]


def _bias_names(sensor: str) -> list[str]:
    return [f"{sensor}.bias[{j}]" for j in range(3)]


@dataclass(frozen=True, eq=False)
class ParameterCovariance(ArrayDataclass):
    """Covariance of named global parameters (Cramér-Rao bound at the optimum).

    Names follow ``"accel.gain[i,j]"``, ``"accel.bias[i]"``, ``"mag.gain[i,j]"``,
    ``"mag.bias[i]"`` and ``"dip_deg"`` (0-based indices); gains in the units of
    :class:`SensorCalibration`, the dip in degrees.
    """

    names: tuple[str, ...]
    matrix: Array = field(metadata={"shape": (-1, -1)})

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(self.names))
        matrix = frozen_array(self.matrix)
        if matrix.shape != (len(self.names), len(self.names)):
            raise ValueError("covariance matrix must be square and match the names")
        object.__setattr__(self, "matrix", matrix)

    def index(self, name: str) -> int:
        """Position of parameter ``name``; ``KeyError`` listing the known names."""
        try:
            return self._positions[name]
        except KeyError:
            raise KeyError(f"no parameter named {name!r}; known: {', '.join(self.names)}") from None

    @functools.cached_property
    def _positions(self) -> dict[str, int]:
        """Name to position (the first, should a name repeat, as ``tuple.index`` gives)."""
        return {name: i for i, name in reversed(list(enumerate(self.names)))}

    def std(self, name: str) -> float:
        """Standard error of one named parameter."""
        i = self.index(name)
        return float(np.sqrt(max(self.matrix[i, i], 0.0)))

    def stds(self, names: list[str]) -> Array:
        """Standard errors of several parameters (0 for names not present)."""
        diag, where = np.maximum(np.diag(self.matrix), 0.0), self._positions
        return np.array([np.sqrt(diag[where[n]]) if n in where else 0.0 for n in names])

    def scaled(self, factors: Mapping[str, float]) -> ParameterCovariance:
        """Rescale parameters whose name starts with a key of ``factors`` (e.g. "accel.gain")."""
        s = np.array([*factors.values(), 1.0])[_factor_index(self.names, tuple(factors))]
        return ParameterCovariance(self.names, self.matrix * np.outer(s, s))

    def transformed(self, T: Array) -> ParameterCovariance:
        """The covariance of ``T @ parameters`` (same names)."""
        return ParameterCovariance(self.names, T @ self.matrix @ T.T)

    @functools.cached_property
    def sensor_blocks(self) -> dict[str, ParameterCovariance | None]:
        """Each sensor's (the gyroscope's too) gain and bias block, names without the sensor
        prefix (``None`` for a sensor with no parameters here); computed once per covariance,
        shared by every :class:`Calibration` that holds it."""
        return {name: _sensor_block(self, name) for name in (*SENSORS, GYRO)}


@dataclass(frozen=True, eq=False)
class Diagnostics(ArrayDataclass):
    """Goodness of fit at the end of a calibration.

    ``statistic`` is the cost ``J`` of Eq. 8 (the sum over poses and sensors of
    ``rᵀ C_i⁻¹ r`` with the pose mean's covariance ``C_i = Σ/Δ_i + Q``), which at the
    maximum-likelihood optimum follows a χ² distribution with ``dof`` degrees of freedom
    (``3N − 22`` for the joint problem); ``p_value`` is its upper tail probability.
    ``pose_cost`` (N,) is each pose's contribution to ``J``. ``status`` is a short word from a
    fixed set (``"ok"``, ``"degenerate poses"``, ``"pose noise estimated"`` ...).
    """

    statistic: float
    dof: int
    p_value: float
    pose_cost: Array = field(metadata={"shape": (-1,)})
    status: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "pose_cost", frozen_array(self.pose_cost))
        object.__setattr__(self, "statistic", float(self.statistic))
        object.__setattr__(self, "p_value", float(self.p_value))
        object.__setattr__(self, "dof", int(self.dof))

    @property
    def pose_share(self) -> Array:
        """Each pose's share of the total cost (sums to 1)."""
        total = float(np.sum(self.pose_cost))
        return self.pose_cost / total if total > 0 else np.zeros_like(self.pose_cost)


_SENSOR_NAMES: dict[str, list[str]] = {s: _gain_names(s) + _bias_names(s) for s in (*SENSORS, GYRO)}


@functools.lru_cache(maxsize=256)
def _factor_index(names: tuple[str, ...], prefixes: tuple[str, ...]) -> NDArray[np.intp]:
    """Per name, the position of the last prefix it starts with (that prefix's factor is its
    own), ``len(prefixes)`` for none (factor 1); found once per set of names and prefixes."""
    last = [max((k for k, p in enumerate(prefixes) if n.startswith(p)), default=-1) for n in names]
    return np.array([len(prefixes) if k < 0 else k for k in last], dtype=np.intp)


@functools.lru_cache(maxsize=256)
def _block_layout(names: tuple[str, ...], sensor: str) -> tuple[tuple[str, ...], BlockIndex]:
    """One sensor's gain, bias and temperature names (prefix dropped) and the index that takes
    its block: two slices when the positions run in order (the usual layout: a view, not
    numpy's slower fancy indexing), else :func:`numpy.ix_` of them."""
    first = {n: i for i, n in reversed(list(enumerate(names)))}
    chosen = [n for n in _SENSOR_NAMES[sensor] if n in first]
    chosen += [n for n in names if n.startswith(f"{sensor}.temp[")]
    idx = [first[n] for n in chosen]
    run = bool(idx) and idx == list(range(idx[0], idx[0] + len(idx)))
    take = (slice(idx[0], idx[0] + len(idx)),) * 2 if run else np.ix_(idx, idx)
    return tuple(n.split(".", 1)[1] for n in chosen), take


def _sensor_block(
    covariance: ParameterCovariance | None, sensor: str
) -> ParameterCovariance | None:
    """The gain and bias block of one sensor, names without the sensor prefix."""
    names, take = ((), ()) if covariance is None else _block_layout(covariance.names, sensor)
    if not names or covariance is None:
        return None
    return ParameterCovariance(names, covariance.matrix[take])
