"""Comparisons "the same result to 1e-9 relative" (issue 24): two code paths that do the same
arithmetic in a different order or batching may round differently on another CPU or BLAS, so
results are compared with a tolerance, never bit for bit; strings, ints and flags exactly."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

import fieldcal
from fieldcal.batch import COLUMNS

#: relative tolerance of "the same result" (issue 24); absolute floor for values that are zero
RTOL, ATOL = 1e-9, 1e-12


def assert_close_tree(a: Any, b: Any, where: str = "") -> None:
    """Equal JSON-like trees, floats to :data:`RTOL` (NaN equal to NaN)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for key in a:
            assert_close_tree(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_close_tree(x, y, f"{where}[{k}]")
    elif isinstance(a, float) and not isinstance(b, bool) and isinstance(b, (int, float)):
        same_nan = math.isnan(a) and math.isnan(float(b))
        assert same_nan or math.isclose(a, b, rel_tol=RTOL, abs_tol=ATOL), (where, a, b)
    elif isinstance(a, np.ndarray):
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=ATOL, err_msg=where)
    else:
        assert a == b, (where, a, b)


def assert_same_calibration(a: fieldcal.Calibration, b: fieldcal.Calibration) -> None:
    """Every number of the two calibrations' documents to :data:`RTOL`."""
    da, db = a.to_dict(), b.to_dict()
    da.pop("created"), db.pop("created")
    assert_close_tree(da, db)


def assert_same_file(a: Any, b: Any) -> None:
    """Two calibration files (``cal.json``) with the same numbers to :data:`RTOL`."""
    with open(a, encoding="utf-8") as fa, open(b, encoding="utf-8") as fb:
        assert_close_tree(json.load(fa), json.load(fb))


def assert_same_rows(a: Any, b: Any) -> None:
    """Two batches' summary rows alike, column by column to :data:`RTOL` (``seconds`` aside:
    the time a log took)."""
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        for name in COLUMNS:
            if name != "seconds":
                assert_close_tree(x[name], y[name], name)
