"""Integration of a rate into rotations: every segment's turn at once against the turn of each
segment alone, with bursts of equal timestamps and both holds; the scan by component."""

from __future__ import annotations

import numpy as np
import pytest

from fieldcal.errors import InputError
from fieldcal.gyro.integrate import (
    block_scan,
    cumulative_columns,
    cumulative_quaternions,
    integrate,
    multiply_columns,
    segment_turns,
)


@pytest.fixture(scope="module")
def motion():
    rng = np.random.default_rng(11)
    n = 3000
    t = np.cumsum(rng.uniform(0.005, 0.015, n))
    t[100:104] = t[100]  # a burst: four rows on one timestamp
    t[-3:] = t[-3]  # and one at the very end
    return t, rng.normal(size=(n, 3))


@pytest.mark.parametrize("hold", ["midpoint", "previous"])
def test_segment_turns_are_each_segment_integrated_alone(motion, hold):
    t, w = motion
    spans = [(0, 10), (20, 20), (50, 300), (90, 200), (400, 2999), (2990, 2999), (10, 11)]
    got = segment_turns(t, w, spans, hold=hold)
    want = np.array([integrate(t[a : b + 1], w[a : b + 1], hold=hold) for a, b in spans])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "spans", [[(0, 40), (2999, 2999)], [(7, 7)], [(0, 0), (1, 1)], [(95, 110), (2999, 2999)]]
)
def test_spans_of_one_row_anywhere_are_the_identity(motion, spans):
    """A span of one row last (its start past every interval), alone, or all such spans."""
    t, w = motion
    got = segment_turns(t, w, spans)
    want = np.array([integrate(t[a : b + 1], w[a : b + 1]) for a, b in spans])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_segment_turns_refuses_time_going_backwards_and_spans_outside(motion):
    t, w = motion
    back = t.copy()
    back[60] = back[57]  # two steps back: a reset, refused naming the flag that splits it
    with pytest.raises(InputError, match=r"time goes backwards.*--split-on-reset"):
        segment_turns(back, w, [(50, 70)])
    jitter = t.copy()
    jitter[60] = (t[59] + t[58]) / 2  # half a step back: the row shares t[59], spread after
    want = segment_turns(t, w, [(50, 70)])
    np.testing.assert_allclose(segment_turns(jitter, w, [(50, 70)]), want, atol=0.02)
    segment_turns(back, w, [(0, 40), (61, 80)])  # only within a span does it matter
    with pytest.raises(InputError, match="spans must be"):
        segment_turns(t, w, [(5, 3)])
    with pytest.raises(InputError, match="spans must be"):
        segment_turns(t, w, [(0, len(t))])


def test_the_block_scan_factors_are_the_scan():
    # inner[k] ⊗ before[k // block] is the scan at k, whether Hillis-Steele's or blocked
    rng = np.random.default_rng(3)
    for m, block in ((1, 4), (100, 4), (129, 4), (1000, 4), (5000, 64)):
        q = rng.normal(size=(4, m))
        q /= np.linalg.norm(q, axis=0)
        inner, before = block_scan(q, block)
        assert before.shape == (4, -(-m // block))
        got = multiply_columns(inner, before[:, np.arange(m) // block])
        np.testing.assert_allclose(got, cumulative_columns(q), rtol=0, atol=1e-13)


def test_the_scan_by_component_is_the_scan_of_quaternions():
    rng = np.random.default_rng(2)
    for m in (1, 5, 128, 129, 1000):
        q = rng.normal(size=(m, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        np.testing.assert_allclose(
            cumulative_columns(q.T.copy()).T, cumulative_quaternions(q), rtol=0, atol=1e-13
        )
