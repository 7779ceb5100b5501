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

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["CUT", "MIN_SAMPLES", "Unsteady", "trim_unsteady", "unsteady"]

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
        The samples kept, in order (``stacked`` itself when none is cut).
    kept_counts, trimmed : (N,) int arrays
        Samples kept and cut per pose. A pose never loses more than half its samples: the
        median stays inside what is kept.
    """
    x = np.ascontiguousarray(stacked.T)  # a copy: unsteady overwrites it
    found = unsteady(x, counts, np.empty((10, x.shape[1])))
    if found.cut is None:
        return stacked, counts, found.trimmed
    return stacked[~found.cut], counts - found.trimmed, found.trimmed


@dataclass
class Unsteady:
    """What :func:`unsteady` found, and what it computed on the way that Eq. 5 and 7 reuse.

    Attributes
    ----------
    cut : (ΣΔ,) bool array or None
        The samples to cut (``None``: none).
    trimmed : (N,) int array
        Samples cut per pose.
    medians : (3, N) array
        Each pose's median per axis.
    deviations, squares : (3, ΣΔ) arrays
        Each sample minus its pose's median, and its square (views into the work space).
    """

    cut: NDArray[np.bool_] | None
    trimmed: NDArray[np.int64]
    medians: Array
    deviations: Array
    squares: Array


def unsteady(x: Array, counts: NDArray[np.int64], work: Array) -> Unsteady:
    """The samples to cut, for concatenated poses with the axes as rows.

    Parameters
    ----------
    x : (3, ΣΔ) array
        The poses' samples, one pose after the other; overwritten by their squared
        deviations from their pose's median (``Unsteady.squares``).
    counts : (N,) int array
        Samples per pose.
    work : (10, ΣΔ) array
        Work space (overwritten): the steps write into it rather than into temporaries of
        the data's size; the deviations returned live in it.
    """
    n = len(counts)
    trimmed = np.zeros(n, dtype=np.int64)
    keys, scratch, deviations, d2 = work[:3], work[3:6], work[6:9], work[9]
    index = np.repeat(np.arange(n), counts)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    eligible = counts >= MIN_SAMPLES
    # beside the medians, two order statistics per pose that bound its MAD from below
    lo = (counts[eligible] - 1) // 2
    a = starts[eligible] + lo // 2
    medians, (y_a, y_b) = _segment_medians(x, index, starts, counts, keys, scratch, (a, a + lo + 1))
    np.subtract(x, np.repeat(medians, counts, axis=1), out=deviations)
    squares = np.multiply(deviations, deviations, out=x)  # the samples are not needed again
    found = Unsteady(None, trimmed, medians, deviations, squares)
    if not eligible.any() or _none_cut(squares, medians[:, eligible], y_a, y_b, d2):
        return found
    absolute = np.abs(deviations, out=scratch)
    mads, _ = _segment_medians(absolute, index, starts, counts, keys, scratch)
    scale = 1.4826 * _median(mads[:, eligible])
    usable = scale > 0
    if not usable.any():
        return found
    if usable.all():
        z = np.divide(deviations, scale[:, None], out=scratch)
    else:
        z = deviations[usable] / scale[usable, None]
    np.einsum("ij,ij->j", z, z, out=d2)
    d2 *= 3.0 / usable.sum()
    cut = d2 > CUT
    if not cut.any():
        return found
    cut &= np.repeat(eligible, counts)
    trimmed = np.add.reduceat(cut, starts, dtype=np.int64)
    too_many = trimmed > counts // 2  # a pose mostly "unsteady": keep it whole, let tests judge it
    if too_many.any():
        cut &= ~np.repeat(too_many, counts)
        trimmed[too_many] = 0
    if not cut.any():
        return found
    return Unsteady(cut, trimmed, medians, deviations, squares)


def _none_cut(squares: Array, medians: Array, y_a: Array, y_b: Array, d2: Array) -> bool:
    """True when no sample can be cut, proven without the MADs (which take a second sort).

    In a pose's sorted samples ``y``, take positions ``a`` and ``b = a + lo + 1`` around the
    median ``m`` (``lo = (n − 1) // 2``). A deviation ``|y − m|`` below
    ``L = min(m − y_a, y_b − m)`` puts ``y`` strictly between ``y_a`` and ``y_b``: at most
    ``lo`` samples, so the MAD (the mean of the deviations ranked ``lo`` and ``lo + 1``) is at
    least ``L``. The scale from these ``L`` (the same median over the poses) is then at most
    the true scale, and every ``d²`` it gives at least the true one: if none of these reaches
    :data:`CUT` (with a margin far above rounding), none of the true ones does. Usually the
    case for a still session; ``squares`` holds the squared deviations from the medians.
    """
    bound = 1.4826 * _median(np.minimum(medians - y_a, y_b - medians)) * (1.0 - 1e-6)
    if not np.all(bound > 0):
        return False
    np.matmul(1.0 / (bound * bound), squares, out=d2)
    return bool(d2.max() <= CUT * (1.0 - 1e-6))


def _median(x: Array) -> Array:
    """``np.median(x, axis=1)`` (the same numbers) without its fixed cost: sort, mean of the
    middle pair."""
    ranked = np.sort(x, axis=1)
    k = x.shape[1]
    return np.asarray((ranked[:, (k - 1) // 2] + ranked[:, k // 2]) / 2.0)


def _segment_medians(
    x: Array,
    index: NDArray[np.intp],
    starts: NDArray[np.int64],
    counts: NDArray[np.int64],
    keys: Array,
    work: Array,
    positions: tuple[NDArray[np.int64], ...] = (),
) -> tuple[Array, list[Array]]:
    """Per-pose medians of concatenated poses, (3, ΣΔ) in, (3, N) out, with one sort; and the
    sorted samples at ``positions`` (each an array of indices into the concatenation).

    Sorting ``pose · span + (x − min)`` orders the samples by pose, then by value, so each
    pose's median sits at fixed positions of the sorted array (rounding of the key is far
    below any sensor's resolution). ``index`` holds each sample's pose; ``keys`` and ``work``
    are scratch arrays like ``x`` (``work`` may be ``x`` itself: it is read first).
    """
    lo = starts + (counts - 1) // 2
    hi = starts + counts // 2
    low = x.min(axis=1, keepdims=True)
    # relative to the data's own range (readings may be 1e-30 or 1e30)
    span = 2.0 * (x.max(axis=1, keepdims=True) - low)
    span[span == 0] = 1.0
    # keys = pose · span + (x − low), built in place; sorted, they keep the poses in order, so
    # position k still belongs to the pose of sample k
    np.subtract(x, low, out=work)
    np.multiply(index, span, out=keys)
    keys += work
    keys.sort(axis=1)
    below = keys[:, lo] - index[lo] * span + low
    above = keys[:, hi] - index[hi] * span + low
    at = [keys[:, k] - index[k] * span + low for k in positions]
    return np.asarray(0.5 * (below + above)), at
