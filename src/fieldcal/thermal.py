"""A sensor's bias as a polynomial in temperature: the model and its evaluation.

Each sensor's bias at die temperature ``T`` (°C, as the log reports it) is::

    b(T) = b + Σ_{k=1..K} c_k (T − T_ref)^k

with ``b`` the sensor's ``bias`` (the bias at ``T_ref``), ``c_k`` (3,) the coefficient of order
``k`` and ``T_ref`` the mean of the poses' temperatures. ``K = 0`` (no coefficients) is a
calibration made at ``T_ref`` alone: either the data showed no temperature effect, or the
temperature span was too small to fit one (``refused``). Outside the span seen, the shift is
held at its value at the nearest end (a polynomial is not extrapolated; PX4 clips the same way,
``src/modules/temperature_compensation/TemperatureCompensation.cpp``). The estimation is
:mod:`fieldcal.likelihood.temperature`; ``docs/methods/temperature.md`` states the model.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._frozen import ArrayDataclass, frozen_array

__all__ = ["TemperatureModel", "temperature_names"]

Array = NDArray[np.float64]


def temperature_names(order: int) -> list[str]:
    """Covariance names of the coefficients of orders 1..``order``, without the sensor prefix:
    ``temp[k,j]`` (order ``k``, axis ``j``), in the order of ``coefficients.ravel()``."""
    return [f"temp[{k},{j}]" for k in range(1, order + 1) for j in range(3)]


@dataclass(frozen=True, eq=False)
class TemperatureModel(ArrayDataclass):
    """One sensor's bias against temperature (see the module docstring).

    Attributes
    ----------
    reference : float
        ``T_ref``: the temperature (°C) at which the sensor's ``bias`` holds.
    coefficients : (K, 3) array
        ``c_k`` per row, raw units per K^k; K = 0 when no temperature term was fitted.
    span : (2,) array
        The lowest and highest pose temperature seen (°C): the range the model was fitted on.
    refused : bool
        The temperature terms were refused because the span was too small to identify them
        (the calibration holds at ``reference``).
    std : (K, 3) array or None
        Standard errors of ``coefficients`` (Cramér–Rao), derived from the covariance of the
        calibration that holds the sensor (not stored).
    """

    reference: float
    coefficients: Array = field(metadata={"shape": (-1, 3)})
    span: Array = field(metadata={"shape": (2,)})
    refused: bool = False
    std: Array | None = field(default=None, repr=False, metadata={"stored": False})

    def __post_init__(self) -> None:
        coefficients = np.asarray(self.coefficients, dtype=float).reshape(-1, 3)
        object.__setattr__(self, "coefficients", frozen_array(coefficients))
        object.__setattr__(self, "span", frozen_array(self.span))
        object.__setattr__(self, "reference", float(self.reference))
        object.__setattr__(self, "refused", bool(self.refused))
        if self.std is not None:
            object.__setattr__(self, "std", frozen_array(np.reshape(self.std, (-1, 3))))
        if self.span.shape != (2,) or not self.span[0] <= self.span[1]:
            raise ValueError("temperature span must be (lowest, highest)")
        if not (np.isfinite(self.reference) and np.isfinite(self.coefficients).all()):
            raise ValueError("temperature model values must be finite")

    @property
    def order(self) -> int:
        """``K``, the highest power fitted (0: none)."""
        return int(self.coefficients.shape[0])

    @property
    def width(self) -> float:
        """The span seen, in kelvin."""
        return float(self.span[1] - self.span[0])

    def shift(self, temperature: ArrayLike) -> Array:
        """``b(T) − b`` for temperatures (...) in °C: (..., 3), raw units; ``T`` is clipped to the
        span seen (no extrapolation)."""
        t = np.asarray(temperature, dtype=float)
        if not np.isfinite(t).all():
            raise ValueError("temperatures must be finite numbers (°C)")
        d = np.clip(t, self.span[0], self.span[1]) - self.reference
        out = np.zeros((*d.shape, 3))
        for k in range(self.order, 0, -1):  # Horner: ((c_K d + c_{K−1}) d + ...) d
            out = (out + self.coefficients[k - 1]) * d[..., None]
        return out

    def scaled(self, factor: float) -> TemperatureModel:
        """The same model for raw readings multiplied by ``factor``."""
        return TemperatureModel(
            self.reference,
            self.coefficients * factor,
            self.span,
            self.refused,
            None if self.std is None else self.std * abs(factor),
        )
