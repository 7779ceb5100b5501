"""The range of numbers fieldcal takes, defined once.

Raw readings, fields, noise values and thresholds are taken from :data:`SMALLEST` to
:data:`LARGEST` in magnitude: the square of either stays a finite, normal double, so every
covariance and every sum of squares fieldcal forms is finite (raw scales from 1e-30 to 1e149
are supported). :func:`power_of_two` brings readings to order one without changing a digit.
"""

from __future__ import annotations

import math

__all__ = [
    "LARGEST",
    "MOST_PLANNED",
    "PLAUSIBLE_C",
    "RANGE_TEXT",
    "SMALLEST",
    "in_range",
    "power_of_two",
]

#: Largest magnitude taken for a reading, a field, a noise or a threshold.
LARGEST = 1e150
#: Smallest positive magnitude taken for a field, a noise or a threshold.
SMALLEST = 1.0 / LARGEST
#: The range as messages say it.
RANGE_TEXT = "from 1e-150 to 1e150"
#: Most poses one plan proposes (``fieldcal plan -n``, ``fieldcal.plan_poses(cal, k)``): each
#: costs a pass over the candidates, and a plan longer than a session is planned again anyway.
MOST_PLANNED = 100
#: The hottest and coldest die temperature taken (°C): beyond is a wrong column or unit.
PLAUSIBLE_C = (-80.0, 200.0)


def in_range(value: float) -> bool:
    """Whether a positive magnitude lies in ``[SMALLEST, LARGEST]`` (NaN does not)."""
    return bool(SMALLEST <= value <= LARGEST)


def power_of_two(largest: float) -> float:
    """``2^k`` nearest ``largest`` in the logarithm (1 for 0 or a non-finite value): dividing
    by it changes no digit of a float and brings the readings to order one."""
    if not largest > 0 or not math.isfinite(largest):
        return 1.0
    return float(2.0 ** round(math.log2(largest)))
