"""Samples within a pose that are not still (a bump, a tap) are cut before Eq. 5 and Eq. 7.

Each sample is compared with its pose's median, per axis, in units of the sensor's robust
within-pose scatter: ``d² = Σ_axes ((x − median_i) / s)²`` with ``s = 1.4826 · MAD`` pooled over
the poses (the median of the poses' MADs, so one shaken pose does not set its own scale). For a
Gaussian sample ``d²`` follows χ²(3) closely; samples with ``d²`` beyond the
``1 − 10⁻⁵`` quantile are cut (about one false cut per 100,000 samples, far too few to bias
Eq. 7). Poses with fewer than :data:`MIN_SAMPLES` samples are left as they are. A sensor whose
readings do not vary within poses (scale 0, e.g. a coarse quantiser) is not trimmed.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["CUT", "MIN_SAMPLES", "trim_unsteady"]

Array = NDArray[np.float64]

#: χ²(3) quantile at 1 − 1e-5: the squared robust distance beyond which a sample is cut.
CUT = 25.9
#: Fewest samples in a pose for a robust median.
MIN_SAMPLES = 10


def trim_unsteady(
    stacked: Array, counts: NDArray[np.int64]
) -> tuple[Array, NDArray[np.int64], NDArray[np.int64]]:
    """Cut unsteady samples from concatenated poses.

    Parameters
    ----------
    stacked : (ΣΔ, 3) array
        The poses' samples, one pose after the other.
    counts : (N,) int array
        Samples per pose.

    Returns
    -------
    kept : (ΣΔ', 3) array
        The samples kept, in order.
    kept_counts, trimmed : (N,) int arrays
        Samples kept and cut per pose. A pose never loses more than half its samples: the
        median stays inside what is kept.
    """
    n = len(counts)
    trimmed = np.zeros(n, dtype=np.int64)
    eligible = counts >= MIN_SAMPLES
    if not eligible.any():
        return stacked, counts, trimmed
    pose_of = np.repeat(np.arange(n), counts)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    medians = _segment_medians(stacked, pose_of, starts, counts)
    deviations = np.abs(stacked - medians[pose_of])
    mads = _segment_medians(deviations, pose_of, starts, counts)
    scale = 1.4826 * np.median(mads[eligible], axis=0)
    usable = scale > 0
    if not usable.any():
        return stacked, counts, trimmed
    z = (stacked[:, usable] - medians[pose_of][:, usable]) / scale[usable]
    d2 = np.einsum("ij,ij->i", z, z) * (3.0 / usable.sum())
    cut = (d2 > CUT) & eligible[pose_of]
    if not cut.any():
        return stacked, counts, trimmed
    trimmed = np.bincount(pose_of[cut], minlength=n).astype(np.int64)
    too_many = trimmed > counts // 2  # a pose mostly "unsteady": keep it whole, let tests judge it
    cut &= ~too_many[pose_of]
    trimmed[too_many] = 0
    keep = ~cut
    return stacked[keep], counts - trimmed, trimmed


def _segment_medians(
    x: Array, pose_of: NDArray[np.int64], starts: NDArray[np.int64], counts: NDArray[np.int64]
) -> Array:
    """Per-pose, per-axis medians of concatenated poses with one sort per axis.

    Sorting ``pose · span + (x − min)`` orders the samples by pose, then by value, so each
    pose's median sits at fixed positions of the sorted array (rounding of the key is far
    below any sensor's resolution)."""
    lo = starts + (counts - 1) // 2
    hi = starts + counts // 2
    out = np.empty((len(counts), x.shape[1]))
    for axis in range(x.shape[1]):  # three axes, each one vectorised sort
        column = x[:, axis]
        low = float(column.min())
        # relative to the data's own range (readings may be 1e-30 or 1e30)
        span = 2.0 * (float(column.max()) - low) or 1.0
        offset = pose_of * span
        # the sorted keys keep the poses in order, so position k still belongs to pose_of[k]
        ranked = np.sort(offset + (column - low)) - offset + low
        out[:, axis] = 0.5 * (ranked[lo] + ranked[hi])
    return out
