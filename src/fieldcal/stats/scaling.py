"""Each sensor's readings divided by an exact power of two, so every result is scale-invariant.

Raw readings come in any unit: counts of a 16-bit converter (1e4), gauss (0.5), tesla (5e-5),
milli-g... Dividing by ``2^k`` changes no digit of a float, so calibrating ``x / 2^k`` and
scaling the result back gives the same numbers, to rounding, whatever the unit — the fitting
code then only ever sees readings of order one. Readings whose squares overflow (beyond
1e150) cannot have a covariance and are refused.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .poses import Samples, as_pose_list

__all__ = ["LARGEST", "normalise"]

Array = NDArray[np.float64]

#: Largest reading whose square (a covariance entry) is still a finite float64.
LARGEST = 1e150


def _scale_of(largest: float, name: str) -> float:
    if not largest > 0 or not math.isfinite(largest):
        return 1.0  # all zero, or non-finite: the input checks say what is wrong
    if largest > LARGEST:
        raise ValueError(
            f"{name}: readings up to {largest:.3g} are too large to square in floating point; "
            "give them in a smaller unit (e.g. divide by a power of ten) and scale the gain back"
        )
    return float(2.0 ** round(math.log2(largest)))


def normalise(samples: Samples | None, name: str) -> tuple[Samples | None, float]:
    """``samples / 2^k`` (per-pose list, or a continuous (n, 3) array) and ``2^k``.

    Per-pose input is validated as :func:`fieldcal.stats.poses.as_pose_list` does.
    """
    if samples is None:
        return None, 1.0
    if isinstance(samples, np.ndarray) and samples.ndim == 2:
        array = np.asarray(samples)
        if array.dtype.kind not in "biuf":
            return samples, 1.0  # the method's own check names the problem
        x = np.asarray(array, dtype=float)
        finite = np.abs(x[np.isfinite(x)])
        scale = _scale_of(float(finite.max()) if finite.size else 0.0, name)
        return x / scale, scale
    poses = as_pose_list(samples, name)
    largest = max((float(np.abs(p[np.isfinite(p)]).max(initial=0.0)) for p in poses), default=0.0)
    scale = _scale_of(largest, name)
    return ([p / scale for p in poses] if scale != 1.0 else poses), scale
