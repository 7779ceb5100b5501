"""Each pose's orientation label: poses whose field directions are within a few degrees in
every sensor share one (revisits of one orientation), found through a grid of cells in
O(N log N)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .stillness import scale_of

__all__ = ["orientation_labels", "unit_directions"]

Array = NDArray[np.float64]


def unit_directions(points: Array) -> Array:
    """Unit directions of ``points`` (n, 3) about their mid-range point; zero where a point is
    the centre."""
    scaled = points / scale_of(points)
    centred = scaled - 0.5 * (scaled.max(axis=0) + scaled.min(axis=0))
    norm = np.linalg.norm(centred, axis=1, keepdims=True)
    return np.divide(centred, norm, out=np.zeros_like(centred), where=norm > 0)


def orientation_labels(directions: list[Array], tol_deg: float = 3.0) -> NDArray[np.int64]:
    """Label each pose with its orientation: poses closer than ``tol_deg`` in every sensor's
    field direction share a label (0, 1, ... in order of first appearance).

    Greedy in the order of the poses: the first pose not yet labelled takes every later
    unlabelled pose within ``tol_deg`` of it. Candidates come from a grid of cells as wide as
    the chord of ``tol_deg`` over the first sensor's directions (the 27 cells around a pose
    hold every direction within the tolerance), so N poses take O(N log N) work, not an N x N
    table: the cells are numbered so that the three cells stacked along z are consecutive,
    and each pose's 27 neighbours are 9 ranges of the poses sorted by cell, found for all
    poses at once; a pose alone in its neighbourhood takes its label without a numpy call.
    """
    n = len(directions[0])
    label = np.full(n, -1, dtype=np.int64)
    if n == 0:
        return label
    cos_tol = np.cos(np.radians(tol_deg))
    chord = 2.0 * np.sin(np.radians(tol_deg) / 2.0)
    cells = np.floor(directions[0] / chord).astype(np.int64)
    cells -= cells.min(axis=0) - 1  # every neighbouring cell's index is >= 0 ...
    size = cells.max(axis=0) + 2  # ... and < size
    key = (cells[:, 0] * size[1] + cells[:, 1]) * size[2] + cells[:, 2]
    order = np.argsort(key, kind="stable")
    ordered = key[order]
    lo = np.empty((n, 9), dtype=np.int64)
    hi = np.empty((n, 9), dtype=np.int64)
    for m, (a, b) in enumerate((a, b) for a in (-1, 0, 1) for b in (-1, 0, 1)):
        base = key + (a * size[1] + b) * size[2]
        lo[:, m] = np.searchsorted(ordered, base - 1, side="left")
        hi[:, m] = np.searchsorted(ordered, base + 1, side="right")
    alone = ((hi - lo).sum(axis=1) == 1).tolist()
    lows, highs = lo.tolist(), hi.tolist()
    count = 0
    for i in range(n):  # a loop over leaders; each compares against its neighbourhood at once
        if label[i] >= 0:
            continue
        if not alone[i]:
            ranges = [order[a:b] for a, b in zip(lows[i], highs[i], strict=True) if b > a]
            candidates = np.concatenate(ranges)
            candidates = candidates[label[candidates] < 0]
            same = np.ones(len(candidates), dtype=bool)
            for d in directions:
                same &= d[candidates] @ d[i] > cos_tol
            label[candidates[same]] = count
        label[i] = count
        count += 1
    return label
