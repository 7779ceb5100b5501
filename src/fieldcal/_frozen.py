"""Frozen dataclasses that hold numpy arrays: read-only arrays, equality by value."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["ArrayDataclass", "frozen_array"]


def frozen_array(value: ArrayLike) -> NDArray[np.float64]:
    """A float copy of ``value`` that cannot be written to (``value`` itself when it is one
    already: a result rebuilt with a field replaced shares its other arrays)."""
    if (
        type(value) is np.ndarray
        and value.dtype == np.float64
        and not value.flags.writeable
        and value.base is None
    ):
        return value
    array = np.array(value, dtype=float)
    array.setflags(write=False)
    return array


def _values_equal(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if a is None or b is None:
            return False
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=True))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return bool(a == b)


class ArrayDataclass:
    """Equality by value for frozen dataclasses holding numpy arrays.

    Fields declared with ``field(compare=False)`` (provenance such as a creation time) are left
    out, so two results computed a second apart from the same data compare equal.
    """

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return all(
            _values_equal(getattr(self, f.name), getattr(other, f.name))
            for f in dataclasses.fields(self)  # type: ignore[arg-type]  # mixed into dataclasses
            if f.compare
        )

    __hash__ = None  # type: ignore[assignment]  # equal by value, unhashable like its arrays
