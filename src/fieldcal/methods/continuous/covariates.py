"""The magnetometer's interference term in the continuous fit: fitted jointly (issue 36).

With ``u_j`` the battery current (A) or the throttle (0–1) at sample ``j``, centred on its log
mean ``ū`` (the value at which the bias holds, :mod:`fieldcal.interference`, Eq. I1), the
magnetometer reads (Eq. C2 with the term)::

    m_j = K_m R_j h(δ) + b_m + C (u_j − ū) + ε_m,j      ∂f_j/∂C[i, :] = (u_ij − ū_i) I   (C2i)

the same shape as the bias's temperature terms (:mod:`.thermal_terms`, ``∂f_j/∂c_k = d_j^k
I``): a per-sample covariate times the identity. ``State.interference`` holds ``C`` (k, 3,
raw units per input unit), after the temperature coefficients in the parameter vector;
``Data.inputs`` the centred inputs (n, k). The gains, biases, dip and the whole orientation
trajectory are fitted with it by the same likelihood, so the error bars (sandwich and
Cramér–Rao, :mod:`.uncertainty`) take in what the trajectory and the gains share with it; the
covariance names its entries ``mag.interference[i,j]`` (input ``i``, axis ``j``).

Identifiability (:func:`fieldcal.interference.missing_variation`): an input that spans less
than :data:`fieldcal.interference.MIN_SPAN` is left out of the fit (the term is refused before
it, with what to fly); one whose variation follows the orientation (the share left free by the
fitted field direction and a constant under :data:`fieldcal.interference.MIN_FREE`) is fitted
but not reported (zeros, ``identifiable`` false).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...calibration import ParameterCovariance
from ...errors import InputError
from ...geometry.frames import magnetic_reference
from ...interference import InterferenceModel, missing_variation, summarised

__all__ = [
    "JOINT",
    "Inputs",
    "interference_inputs",
    "interference_labels",
    "interference_model",
    "interference_shift",
]

Array = NDArray[np.float64]

#: Where the coefficients came from (``InterferenceModel.trajectory``).
JOINT = "fitted jointly with the gains, biases and orientation trajectory (continuous motion)"


class Inputs:
    """The inputs driving the term: their names, the values as logged (n, k), their means
    and whether they vary enough to be fitted (``missing``: what the log lacks, else "")."""

    def __init__(self, names: list[str], values: Array) -> None:
        self.names = names
        self.values = values
        self.reference = values.mean(axis=0)
        self.missing = missing_variation(names[0], values[:, 0], 1.0)

    @property
    def centred(self) -> Array:
        out: Array = self.values - self.reference
        return out


def interference_inputs(inputs: Mapping[str, ArrayLike] | None, n: int) -> Inputs | None:
    """The first input of ``inputs`` (``{"current": (n,)}`` or ``{"throttle": (n,)}``),
    checked; ``None`` without one."""
    if not inputs:
        return None
    name = next(iter(inputs))
    if name not in ("current", "throttle"):
        raise InputError(f"inputs: {name!r} is not current or throttle")
    u = np.asarray(inputs[name], dtype=float).reshape(-1)
    if len(u) != n or not np.all(np.isfinite(u)):
        raise InputError(f"inputs[{name!r}] must be {n} finite values, one per sample")
    return Inputs([name], u[:, None])


def interference_shift(
    coefficients: Array, mag: Array, inputs: Array | None
) -> tuple[Array, Array]:
    """The reading less the term ``C (u_j − ū)`` and the term's Jacobian (n, 3, 3k) with
    respect to ``C`` (row-major: ``(u_ij − ū_i) I`` per input, Eq. C2i)."""
    n = len(mag)
    k = len(coefficients)
    if k == 0 or inputs is None:
        return mag, np.zeros((n, 3, 0))
    U = inputs[:, :k]
    J = (U[:, None, :, None] * np.eye(3)[None, :, None, :]).reshape(n, 3, 3 * k)
    return mag - U @ coefficients, J


def interference_labels(k: int) -> list[str]:
    """Covariance names of ``k`` inputs' coefficients, in the parameter vector's order."""
    return [f"mag.interference[{i},{j}]" for i in range(k) for j in range(3)]


def interference_model(
    coefficients: Array,
    inputs: Inputs,
    rotations: Array,
    mag_gain: Array,
    dip: float,
    covariances: tuple[ParameterCovariance, ParameterCovariance],
) -> InterferenceModel:
    """The fitted term as an :class:`~fieldcal.interference.InterferenceModel`: standard
    errors from the sandwich, bounds from the Cramér–Rao covariance (``covariances``), the
    share of the Earth's field and the heading errors at the highest input (the fitted gain
    and field), zeros when the input's variation follows the orientation."""
    k = len(inputs.names)
    C = np.asarray(coefficients, dtype=float).reshape(-1, 3)
    std, bound = np.zeros((k, 3)), np.zeros((k, 3))
    if len(C) == k:
        names = interference_labels(k)
        std = covariances[0].stds(names).reshape(k, 3)
        bound = covariances[1].stds(names).reshape(k, 3)
    else:  # refused before the fit (:attr:`Inputs.missing`)
        C = np.zeros((k, 3))
    h = magnetic_reference(dip)
    # the share of the input's variance the field's body direction and a constant leave free
    Z = np.column_stack([rotations @ h, np.ones(len(rotations))])
    U = inputs.centred
    fitted = Z @ np.linalg.lstsq(Z, U, rcond=None)[0]
    free = 1.0 - float(np.sum(fitted[:, 0] ** 2)) / max(float(np.sum(U[:, 0] ** 2)), 1e-300)
    field = (mag_gain, h, float(np.linalg.norm(mag_gain @ h)))
    return summarised(inputs.names, inputs.values, (C, std, bound), field, free, JOINT)
