"""From information to error bars, for every estimator: the Cramér–Rao covariance (the inverse
of the Fisher information, Jacobi-scaled so that parameters in units far apart invert
accurately) and the sandwich form ``I⁻¹ Ω I⁻¹`` where the scores' long-run covariance ``Ω``
replaces the information (time-correlated residuals: the continuous estimator, Eq. C9).

The pose methods invert their reduced system here (:mod:`.cramer_rao`), the continuous
estimator its profiled information and sandwich (:mod:`fieldcal.methods.continuous.
uncertainty`); the gyroscope stage's banded system gives the covariance of the few
combinations it reports directly (:meth:`fieldcal.gyro.normal.NormalSystem.covariance_of`).
"""

from __future__ import annotations

import functools
from typing import cast

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.lapack import dgesv as _dgesv

__all__ = ["jacobi_scaled", "sandwich", "scaled_inverse"]

Array = NDArray[np.float64]


def jacobi_scaled(S: Array) -> tuple[Array, Array]:
    """``S`` scaled to a unit diagonal, ``S / (d dᵀ)``, and ``d dᵀ`` (``d = √diag S``)."""
    d = np.sqrt(np.maximum(np.diag(S), 1e-300))
    scale = d[:, None] * d  # np.outer's numbers, without its wrapper
    return S / scale, scale


def scaled_inverse(S: Array, *, pseudo: bool = False) -> Array:
    """The inverse of the information ``S`` through its Jacobi scaling.

    Parameters
    ----------
    S : (p, p) array
        A symmetric information matrix.
    pseudo : bool
        Moore–Penrose (``rcond`` 1e-13 on the scaled matrix) for an information that may be
        singular in directions a prior holds; otherwise LAPACK's LU, a singular ``S`` raising
        ``LinAlgError`` as :func:`numpy.linalg.inv` does, and the result symmetrised.

    Returns
    -------
    (p, p) array
    """
    if pseudo:
        d = np.sqrt(np.maximum(np.diag(S), 1e-300))
        outer = np.outer(d, d)
        inv: Array = np.linalg.pinv(S / outer, rcond=1e-13) / outer
        return inv
    Sn, scale = jacobi_scaled(S)
    # np.linalg.inv is LAPACK's gesv against the identity: called directly (its wrapper costs
    # more than a 22x22 solve)
    _, _, inverse, info = _dgesv(Sn, _identity(len(Sn)))
    if info > 0:
        raise np.linalg.LinAlgError("Singular matrix")
    C = cast(Array, inverse) / scale
    return 0.5 * (C + C.T)


def sandwich(inverse: Array, meat: Array) -> Array:
    """``I⁻¹ Ω I⁻¹``: the covariance of an M-estimator whose scores have the long-run
    covariance ``Ω`` (``inverse`` = ``I⁻¹``)."""
    out: Array = inverse @ meat @ inverse
    return out


@functools.cache
def _identity(n: int) -> Array:
    eye = np.eye(n)
    eye.setflags(write=False)
    return eye
