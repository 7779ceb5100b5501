"""The range of numbers fieldcal takes (fieldcal.limits): squares of the extremes stay finite
and normal, and the power of two nearest a magnitude changes no digit."""

from __future__ import annotations

import math
import sys

from hypothesis import given, settings
from hypothesis import strategies as st

from fieldcal.limits import LARGEST, SMALLEST, in_range, power_of_two


def test_squares_of_the_extremes_are_finite_normal_doubles():
    assert math.isfinite(LARGEST**2) and LARGEST**2 < sys.float_info.max
    assert SMALLEST**2 >= sys.float_info.min  # normal, not subnormal


def test_in_range_bounds():
    assert in_range(SMALLEST) and in_range(LARGEST) and in_range(1.0)
    assert not in_range(SMALLEST / 2) and not in_range(LARGEST * 2)
    assert not in_range(math.nan) and not in_range(0.0) and not in_range(-1.0)


@settings(max_examples=300, deadline=None)
@given(
    largest=st.floats(min_value=SMALLEST, max_value=LARGEST),
    x=st.floats(min_value=SMALLEST, max_value=LARGEST),
    sign=st.sampled_from([-1.0, 1.0]),
)
def test_the_power_of_two_is_nearest_in_the_logarithm_and_exact(largest, x, sign):
    p = power_of_two(largest)
    k = math.log2(p)
    assert k == round(k) and abs(math.log2(largest) - k) <= 0.5
    # within the range taken, x / 2^k stays a normal double: no digit changes
    assert (sign * x / p) * p == sign * x


def test_nothing_to_scale_gives_one():
    assert power_of_two(0.0) == power_of_two(math.inf) == power_of_two(math.nan) == 1.0
    assert power_of_two(-5.0) == 1.0
    assert power_of_two(1000.0) == 1024.0 and power_of_two(0.3) == 0.25
