"""The magnetometer's interference term: the field the vehicle's own currents add.

The magnetometer reads (``docs/flight-logs.md``, Eq. I1)::

    m(t) = K_m R(t) h + b + Σ_i c_i (u_i(t) − u_i,ref) + ε(t)                  (I1)

with ``u`` the battery current (A) or the throttle (0–1) — and, where a heater shows in the log,
the temperature (K) — and ``c_i`` a 3-vector per input in raw magnetometer units per input
unit. ``u_ref`` is the input's mean over the calibration log: the value at which the
sensor's ``bias`` holds (the fit without the term absorbed ``c·ū`` into it), so a
calibration without the term and one with it agree on the log's average. The bias at zero
input, what an autopilot's offsets need, is ``b − Σ c_i u_i,ref``.

:class:`InterferenceModel` holds the coefficients, their standard errors (the sandwich over
contiguous blocks: the residuals of a flight are correlated) and Cramér–Rao bounds (white
sensor noise only), the inputs' span, whether the log identified them (and what is missing
when not), and the figures the verdict uses: the interference at the log's highest input as
a share of the Earth's field and the heading error it causes, uncorrected and after correction.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._frozen import ArrayDataclass, frozen_array

__all__ = ["InterferenceModel"]

Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class InterferenceModel(ArrayDataclass):
    """The magnetometer's interference term (Eq. I1 of the module docstring).

    Attributes
    ----------
    inputs : tuple of str
        The inputs, in the rows' order: ``"current"`` (A), ``"throttle"`` (0–1),
        ``"temperature"`` (°C, a heater's).
    units : tuple of str
        Each input's unit.
    coefficients : (k, 3) array
        ``c_i`` per row: raw magnetometer units per input unit (zeros when not identifiable).
    reference : (k,) array
        ``u_ref``: the input values at which the sensor's bias holds (their log means).
    std : (k, 3) array
        Standard errors of ``coefficients`` (block sandwich: correlated residuals).
    crb : (k, 3) array
        Cramér–Rao bounds (standard deviations) for white sensor noise alone.
    span : (k, 2) array
        The lowest and highest value of each input in the log.
    identifiable : bool
        The log determines the term (the input varied enough, independently of orientation).
    reason : str
        What is missing when not identifiable ("" otherwise).
    field_share : float
        The interference at the highest first input (``c_0 · u_max``) over the Earth's field
        (a fraction, 0.3 = 30 %).
    heading_error_deg : float
        The heading error that interference causes on a level vehicle, uncorrected (worst
        heading).
    heading_error_corrected_deg : float
        The same after correction: from twice the coefficients' standard errors.
    trajectory : str
        Where the orientations held during the fit came from.
    """

    inputs: tuple[str, ...]
    units: tuple[str, ...]
    coefficients: Array = field(metadata={"shape": (-1, 3)})
    reference: Array = field(metadata={"shape": (-1,)})
    std: Array = field(metadata={"shape": (-1, 3)})
    crb: Array = field(metadata={"shape": (-1, 3)})
    span: Array = field(metadata={"shape": (-1, 2)})
    identifiable: bool = True
    reason: str = ""
    field_share: float = 0.0
    heading_error_deg: float = 0.0
    heading_error_corrected_deg: float = 0.0
    trajectory: str = ""

    def __post_init__(self) -> None:
        for name in ("coefficients", "std", "crb"):
            value = np.asarray(getattr(self, name), dtype=float).reshape(-1, 3)
            object.__setattr__(self, name, frozen_array(value))
        object.__setattr__(self, "reference", frozen_array(np.ravel(self.reference)))
        object.__setattr__(self, "span", frozen_array(np.reshape(self.span, (-1, 2))))
        object.__setattr__(self, "inputs", tuple(str(s) for s in self.inputs))
        object.__setattr__(self, "units", tuple(str(s) for s in self.units))
        k = len(self.inputs)
        if not (len(self.units) == k == len(self.coefficients) == len(self.reference)):
            raise ValueError("interference inputs, units, coefficients and reference differ")
        if not np.isfinite(self.coefficients).all():
            raise ValueError("interference coefficients must be finite")

    def shift(self, inputs: Mapping[str, ArrayLike]) -> Array:
        """The reading's shift ``Σ c_i (u_i − u_i,ref)`` (n, 3) for the inputs given by name
        (one value or one per reading); an input missing is taken at its reference."""
        total: Array = np.zeros(3)
        for i, name in enumerate(self.inputs):
            if name not in inputs:
                continue
            u = np.asarray(inputs[name], dtype=float) - self.reference[i]
            total = total + u[..., None] * self.coefficients[i]
        return total

    def at_zero(self) -> Array:
        """``Σ c_i u_i,ref``: what the bias loses at zero input (current, throttle) — the
        autopilots' offsets hold there. The temperature row is left out (it has no zero)."""
        out = np.zeros(3)
        for i, name in enumerate(self.inputs):
            if name != "temperature":
                out += self.coefficients[i] * self.reference[i]
        return out
