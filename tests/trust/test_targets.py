"""The accuracy targets (fieldcal.trust.targets): the documented defaults, and every value
checked in one line."""

from __future__ import annotations

import math

import pytest

from fieldcal.errors import InputError
from fieldcal.trust.targets import DEFAULT_TARGETS, Targets


def test_defaults_are_the_documented_ones():
    assert (DEFAULT_TARGETS.heading_deg, DEFAULT_TARGETS.tilt_deg) == (2.0, 1.0)
    assert (DEFAULT_TARGETS.dip_deg, DEFAULT_TARGETS.norm_pct) == (None, 2.0)


def test_values_are_stored_as_floats():
    t = Targets(heading_deg=3, dip_deg=1)
    assert t.heading_deg == 3.0 and isinstance(t.heading_deg, float)
    assert isinstance(t.dip_deg, float)


@pytest.mark.parametrize(
    ("field", "value", "unit"),
    [
        ("heading_deg", 0, "degrees"),
        ("tilt_deg", -1.0, "degrees"),
        ("norm_pct", math.inf, "percent"),
        ("tilt_deg", math.nan, "degrees"),
        ("heading_deg", True, "degrees"),
        ("dip_deg", "1", "degrees"),
        ("norm_pct", None, "percent"),
    ],
)
def test_a_bad_target_is_refused_naming_it(field, value, unit):
    with pytest.raises(InputError, match=f"Targets.{field} must be a positive number of {unit}"):
        Targets(**{field: value})
