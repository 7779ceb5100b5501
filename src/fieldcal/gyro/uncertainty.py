"""The gyroscope's error bars: the Cramér-Rao covariance of ``K_g`` and ``b_g`` at the optimum
(mapped from ``M = K_g⁻¹`` and the poses' biases), widened by ``χ²/dof`` when the segments' χ²
rejects the model, and the segments' residual angles."""

from __future__ import annotations

import numpy as np

from ..calibration import ParameterCovariance
from .model import Array
from .normal import NormalSystem
from .result import BIAS_NAMES, GAIN_NAMES

#: The segments' χ² test level below which the covariance is widened by χ²/dof.
WIDEN_P = 0.05


def named_covariance(
    normal: NormalSystem,
    K: Array,
    restrict: Array | None,
    weights: Array,
    scale: float,
    unobservable: tuple[str, ...],
) -> ParameterCovariance:
    """Covariance of ``gyro.gain[j,k]`` and ``gyro.bias[j]`` from the normal equations in
    ``x = (gain coordinates, b_0, …)``: ``dK = −K dM K`` (row-major), ``bias = Σ w_i b_i``;
    ``restrict`` (9, r) the gain directions the fit moved along (the coordinates of
    ``normal``), ``scale`` the factor on the covariance (widening times the raw unit squared);
    the ``unobservable`` names are left out."""
    gain_map = -np.kron(K, K.T)
    if restrict is not None:
        gain_map = gain_map @ restrict
    L = np.zeros((12, gain_map.shape[1] + 3 * len(weights)))
    L[:9, : gain_map.shape[1]] = gain_map
    L[9:, gain_map.shape[1] :] = np.kron(weights[None, :], np.eye(3))
    C12 = scale * normal.covariance_of(L)
    names = list(GAIN_NAMES + BIAS_NAMES)
    keep = [i for i, nm in enumerate(names) if nm not in unobservable]
    return ParameterCovariance(
        tuple(names[i] for i in keep), 0.5 * (C12 + C12.T)[np.ix_(keep, keep)]
    )


def residual_degrees(r: Array, method: str) -> Array:
    """Each segment's residual as an angle (degrees): the rotation vector's length, or the
    angle between the predicted and the observed gravity direction."""
    norms = np.linalg.norm(r, axis=1)
    out: Array = np.degrees(norms if method == "rotations" else np.arcsin(np.clip(norms, 0.0, 1.0)))
    return out
