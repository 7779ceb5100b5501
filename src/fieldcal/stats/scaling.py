"""Each sensor's readings divided by an exact power of two, so every result is scale-invariant.

Raw readings come in any unit: counts of a 16-bit converter (1e4), gauss (0.5), tesla (5e-5),
milli-g... Dividing by ``2^k`` changes no digit of a float, so calibrating ``x / 2^k`` and
scaling the result back gives the same numbers, to rounding, whatever the unit — the fitting
code then only ever sees readings of order one. Readings whose squares overflow (beyond
1e150) cannot have a covariance and are refused.

This module scales continuous (n, 3) input. Per-pose input is never copied to be scaled: its
pose statistics are divided instead (:func:`fieldcal.stats.pose_stats.summarize_scaled`), which
gives the same digits.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..limits import LARGEST, power_of_two
from .pose_stats import Samples, as_pose_list, as_readings

__all__ = ["LARGEST", "normalise"]

Array = NDArray[np.float64]


def _scale_of(largest: float, name: str, where: str = "") -> float:
    if not largest > 0 or not math.isfinite(largest):
        return 1.0  # all zero, or non-finite: the input checks say what is wrong
    if largest > LARGEST:
        raise ValueError(
            f"{name}: readings up to {largest:.3g}{where} are too large to square in floating "
            "point; give them in a smaller unit (e.g. divide by a power of ten) and scale the "
            "gain back"
        )
    return power_of_two(largest)


def _largest(x: Array) -> tuple[float, str]:
    """The largest finite ``|x|`` of an (n, 3) array and where it is (sample, axis)."""
    magnitude = np.where(np.isfinite(x), np.abs(x), 0.0)
    if magnitude.size == 0:
        return 0.0, ""
    i, j = np.unravel_index(int(np.argmax(magnitude)), magnitude.shape)
    return float(magnitude[i, j]), f" (sample {i}, axis {'xyz'[j]})"


def normalise(samples: Samples | None, name: str) -> tuple[Samples | None, float]:
    """``samples / 2^k`` (per-pose list, or a continuous (n, 3) array) and ``2^k``.

    Per-pose input is validated as :func:`fieldcal.stats.pose_stats.as_pose_list` does.
    """
    if samples is None:
        return None, 1.0
    if isinstance(samples, np.ndarray) and samples.ndim == 2:
        x = as_readings(samples, name)
        if x.shape[1:] != (3,):
            return x, 1.0  # the method's own check names the problem
        largest, where = _largest(x)
        scale = _scale_of(largest, name, where)
        return x / scale, scale
    poses = as_pose_list(samples, name)  # also refuses readings beyond LARGEST
    largest = max((_largest(p)[0] for p in poses), default=0.0)
    scale = _scale_of(largest, name)
    return ([p / scale for p in poses] if scale != 1.0 else poses), scale
