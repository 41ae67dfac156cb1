"""k-d trees (:mod:`hot2cold.core.trees`): the quick build and the query answer as scipy's defaults do, and a
query runs in threads only when it is large."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from hot2cold.core.trees import PARALLEL_QUERY, kd_tree, query

RNG = np.random.default_rng(11)


def test_quick_build_and_query_answer_as_scipy_s_defaults():
    points = RNG.random((3000, 3))
    asked = RNG.random((PARALLEL_QUERY // 4 + 10, 3))           # k = 4: a query in threads; k = 1: not
    reference = cKDTree(points)
    for k in (1, 4):
        dist, idx = query(kd_tree(points), asked, k=k)
        ref_dist, ref_idx = reference.query(asked, k=k)
        assert np.array_equal(idx, ref_idx) and np.array_equal(dist, ref_dist)
    far = query(kd_tree(points), asked[:5] + 10.0, distance_upper_bound=1.0)
    assert np.all(np.isinf(far[0])) and np.all(far[1] == len(points))


def test_only_large_queries_start_threads():
    class Recording:
        def __init__(self):
            self.workers = []

        def query(self, points, k, workers, **options):
            self.workers.append(workers)
            return np.zeros((len(points), k)), np.zeros((len(points), k), int)

    tree = Recording()
    query(tree, np.zeros((40, 3)), k=16)
    query(tree, np.zeros((PARALLEL_QUERY, 3)))
    query(tree, np.zeros((PARALLEL_QUERY // 16, 3)), k=16)
    assert tree.workers == [1, -1, -1]
