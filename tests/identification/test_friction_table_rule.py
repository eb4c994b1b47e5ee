"""identification/friction.py: when an identified slope table is good enough to write."""

import numpy as np

from groundstation.analysis.friction_id import DEFAULT_X_GRID
from groundstation.identification.friction import _table_not_determined

X = DEFAULT_X_GRID


def test_a_table_from_whole_loops_is_written():
    assert _table_not_determined(X, X <= 1.7, 12.7, 0.25) == ""


def test_a_table_with_an_uncertain_turnaround_slope_is_not():
    # a triangle cut short: f(0) = 4.16 +- 37 from two branches (seen in the benchmark)
    why = _table_not_determined(X, X <= 1.7, 4.16, 37.0)
    assert "known only to" in why and "record more or longer triangle cycles" in why
    assert "single branch" in _table_not_determined(X, X <= 1.7, 12.0, None)


def test_a_table_from_loops_inside_the_presliding_range_is_not():
    why = _table_not_determined(X, X <= 0.4, 12.0, 0.5)
    assert "reach x = 0.4" in why and "presliding" in why
    assert _table_not_determined(X, np.zeros(X.size, bool), 12.0, 0.5).startswith("the loops")
