"""TT's error at a given number of link messages, interpolated between sample periods (sea_hil/sweep/frontier.py)."""
from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sea_hil.sweep.frontier import OutsideBaseline, dominates, tt_error_at

TT = [(2002.0, 0.0024), (1002.0, 0.0028), (668.0, 0.28), (402.0, 0.80)]   # unsorted on purpose: 10 20 30 50 ms


def test_linear_between_the_bracketing_periods():
    assert tt_error_at(1002, TT) == 0.0028 and tt_error_at(2002, TT) == 0.0024
    assert tt_error_at(835, TT) == pytest.approx(0.0028 + (0.28 - 0.0028) * (1002 - 835) / (1002 - 668))
    assert tt_error_at(535, TT) == pytest.approx((0.28 + 0.80) / 2)
    assert tt_error_at(5, [(5.0, 0.1)]) == 0.1
    assert tt_error_at(10, [(10.0, 0.1), (10.0, 0.3), (20.0, 0.5)]) == pytest.approx(0.2)   # same count: the mean


def test_no_extrapolation_and_no_bad_points():
    for outside in (401.9, 2003):
        with pytest.raises(OutsideBaseline, match="outside TT's measured range"):
            tt_error_at(outside, TT)
    with pytest.raises(ValueError):
        tt_error_at(1, [])
    with pytest.raises(ValueError, match="non-finite"):
        tt_error_at(1, [(1.0, math.inf)])


def test_dominates_means_at_most_half_of_tt_at_the_same_messages():
    assert dominates(668, 0.14, TT) == (True, 0.28)
    assert dominates(668, 0.1401, TT)[0] is False
    assert dominates(668, 0.2, TT, factor=1.0)[0] is True


@given(st.lists(st.tuples(st.integers(1, 3000), st.floats(0, 1)), min_size=1, max_size=12), st.floats(0, 1))
def test_interpolated_value_lies_between_its_neighbours(points, where):
    pts = [(float(m), e) for m, e in points]
    lo, hi = min(m for m, _ in pts), max(m for m, _ in pts)
    x = lo + where * (hi - lo)
    y = tt_error_at(x, pts)
    errs = [e for _, e in pts]
    assert min(errs) - 1e-12 <= y <= max(errs) + 1e-12
