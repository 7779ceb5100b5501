"""Each pose's temperature samples from a log's temperature column and the poses found in it."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from .log import Log

__all__ = ["pose_temperature_samples"]

if TYPE_CHECKING:
    from .pose_finding import PoseEntry

Array = NDArray[np.float64]


def pose_temperature_samples(log: Log, entries: Sequence[PoseEntry]) -> list[Array] | None:
    """The temperature column's values in each pose (``entries``: the poses' ``pieces``,
    ``start``/``stop`` data rows or pose-column ``label``), or ``None`` when the log has no
    temperature or a pose's rows cannot be located."""
    if log.temperature is None:
        return None
    out: list[Array] = []
    for entry in entries:
        if entry.get("pieces"):
            runs = [(int(a), int(b)) for a, b in entry["pieces"]]
        elif "start" in entry and "stop" in entry:
            runs = [(int(entry["start"]), int(entry["stop"]))]
        elif "label" in entry and log.pose is not None:
            mask = np.asarray(log.pose).astype(str) == str(entry["label"])
            if not mask.any():
                return None
            out.append(log.temperature[mask])
            continue
        else:
            return None
        # data-row numbers of the file -> positions among the kept rows
        parts = [
            log.temperature[np.searchsorted(log.index, a) : np.searchsorted(log.index, b)]
            for a, b in runs
        ]
        values = np.concatenate(parts) if parts else np.empty(0)
        if values.size == 0:
            return None
        out.append(values)
    return out
