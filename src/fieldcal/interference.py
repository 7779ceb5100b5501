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

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._frozen import ArrayDataclass, frozen_array

__all__ = [
    "MIN_FREE",
    "MIN_SPAN",
    "UNITS",
    "InterferenceModel",
    "heading_error",
    "missing_variation",
    "summarised",
]

Array = NDArray[np.float64]

#: Smallest span of each input that identifies its coefficients: 3 A of current (a hover
#: against the ground idle: ArduPilot's compassmot asks for 50-75 % throttle), 0.15 of
#: throttle.
MIN_SPAN = {"current": 3.0, "throttle": 0.15}
#: Smallest share of the input's variance the orientation does not explain (``1 − R²``).
MIN_FREE = 0.05
#: Each input's unit.
UNITS = {"current": "A", "throttle": "0-1", "temperature": "degC"}


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


def missing_variation(name: str, u: Array, free: float) -> str:
    """What the log lacks for input ``name`` to identify its term ("" when nothing): a span
    under :data:`MIN_SPAN`, or ``free`` (the share of its variance the orientation does not
    explain) under :data:`MIN_FREE`."""
    lo, hi = float(u.min()), float(u.max())
    unit = UNITS[name]
    if hi - lo < MIN_SPAN[name]:
        if name == "current" and hi < MIN_SPAN[name]:
            return (
                f"current never exceeded {hi:.3g} A: hover longer or add a throttle sweep "
                f"(at least {MIN_SPAN[name]:g} A of change)"
            )
        return (
            f"the {name} stayed within {lo:.3g}-{hi:.3g} {unit}: add a throttle sweep (climbs "
            f"and descents) so that it changes by at least {MIN_SPAN[name]:g} {unit}"
        )
    if free < MIN_FREE:
        return (
            f"the {name} moved with the orientation ({100 * (1 - free):.0f} % of its variation "
            "follows the heading and tilt): change throttle at several headings"
        )
    return ""


def heading_error(A: Array, h: Array, d: Array) -> float:
    """Worst heading error (degrees) a body-frame disturbance ``d`` (raw units) causes on a
    level vehicle: its horizontal part against the field's horizontal part (``A`` the
    magnetometer's gain for a field ``h`` of unit length, world frame)."""
    delta = np.linalg.solve(A, d)  # in units of the field (|h| = 1), the body frame
    horizontal = math.hypot(float(h[0]), float(h[1]))
    ratio = math.hypot(float(delta[0]), float(delta[1])) / max(horizontal, 1e-12)
    return math.degrees(math.asin(min(1.0, ratio)))


def summarised(
    names: list[str],
    values: Array,
    fitted: tuple[Array, Array, Array],
    field: tuple[Array, Array, float],
    free: float,
    trajectory: str,
) -> InterferenceModel:
    """The :class:`InterferenceModel` of a fit: ``names`` the inputs, ``values`` their values as
    logged (n, k; the reference their means), ``fitted`` the coefficients, standard errors and
    bounds (k, 3 each), ``field`` the magnetometer's gain, the field's unit direction (world) and
    its strength in raw units, ``free`` the share of the first input's variance the orientation
    leaves free. Not identifiable (:func:`missing_variation`): zeros and the reason. The figures
    at the highest input (the temperature's span for a heater alone)."""
    C, std, crb = (np.asarray(x, dtype=float).reshape(-1, 3) for x in fitted)
    gain, h, strength = field
    missing = missing_variation(names[0], values[:, 0], free)
    if missing:
        C, std, crb = np.zeros_like(C), np.zeros_like(C), np.zeros_like(C)
    u = values[:, 0]
    peak = float(np.ptp(u)) if names[0] == "temperature" else float(u.max())
    d = C[0] * peak
    return InterferenceModel(
        inputs=tuple(names),
        units=tuple(UNITS[n] for n in names),
        coefficients=C,
        reference=values.mean(axis=0),
        std=std,
        crb=crb,
        span=np.column_stack([values.min(axis=0), values.max(axis=0)]),
        identifiable=not missing,
        reason=missing,
        field_share=float(np.linalg.norm(d)) / strength if strength > 0 else 0.0,
        heading_error_deg=heading_error(gain, h, d),
        heading_error_corrected_deg=heading_error(gain, h, 2.0 * std[0] * peak),
        trajectory=trajectory,
    )
