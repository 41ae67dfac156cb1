"""Index arrays (:mod:`hot2cold.core.arrays`): distinct values as numpy's, runs of sorted values, places in runs."""
from __future__ import annotations

import numpy as np
import pytest

from hot2cold.core.arrays import distinct, run_places, runs

RNG = np.random.default_rng(5)


@pytest.mark.parametrize("values", [
    np.zeros(0, np.int64), np.array([7]), np.array([3, 3, 3]), RNG.integers(-5, 5, 1000),
    RNG.integers(0, 10**6, 50_000), RNG.integers(0, 40, (300, 8)), np.array([2.5, -1.0, 2.5, np.inf]),
    np.array([True, False, True]), [4, 1, 4, 9],
])
def test_distinct_is_numpy_s_unique(values):
    got, want = distinct(values), np.unique(values)
    assert got.dtype == want.dtype and np.array_equal(got, want)


def test_runs_cover_sorted_values_in_order():
    values = np.array([0, 0, 2, 5, 5, 5])
    assert [(v, (s.start, s.stop)) for v, s in runs(values)] == [(0, (0, 2)), (2, (2, 3)), (5, (3, 6))]
    assert runs(np.zeros(0, int)) == []


def test_run_places_number_each_run_from_0():
    run, place = run_places(np.array([2, 0, 3, 1]))
    assert run.tolist() == [0, 0, 2, 2, 2, 3] and place.tolist() == [0, 1, 0, 1, 2, 0]
    run, place = run_places(np.zeros(3, int))
    assert len(run) == len(place) == 0
