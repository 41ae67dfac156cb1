"""k-d trees (:mod:`hot2cold.core.trees`): the quick build and the query answer as scipy's defaults do, and a
query runs in threads only when it is large."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from hot2cold.core.trees import BOUNDED_QUERY, PARALLEL_QUERY, kd_tree, query

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


def test_a_large_query_of_several_neighbours_is_bounded_and_answers_as_the_unbounded_one():
    # a surface-like cloud (a wavy sheet) with a few far points, whose neighbours lie beyond any bound from the
    # probes, and a grid, whose neighbours tie at equal distances
    uv = RNG.random((BOUNDED_QUERY + 500, 2))
    sheet = np.column_stack([uv, 0.05 * np.sin(6.0 * uv[:, 0])])
    sheet[::5000] += 3.0
    grid = np.stack(np.meshgrid(*[np.arange(42.0)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    for points in (sheet, grid):
        tree = kd_tree(points)
        dist, idx = query(tree, points, k=6)
        ref_dist, ref_idx = tree.query(points, k=6)
        assert np.array_equal(dist, ref_dist)
        # the indices too, but among neighbours at the same distance (the k-th's may tie with the next)
        moved = idx != ref_idx
        tied = ((ref_dist[:, :, None] == ref_dist[:, None, :]).sum(axis=2) > 1) | (ref_dist == ref_dist[:, -1:])
        assert not np.any(moved & ~tied) and (points is grid or not moved.any())
        assert np.array_equal(np.linalg.norm(points[idx] - points[:, None], axis=2), dist)

    class Recording:
        def __init__(self, tree):
            self.tree, self.bounds, self.asked = tree, [], []

        def query(self, points, k, workers, distance_upper_bound=np.inf):
            self.bounds.append(distance_upper_bound)
            self.asked.append(len(points))
            return self.tree.query(points, k=k, workers=workers, distance_upper_bound=distance_upper_bound)

    recording = Recording(kd_tree(sheet))
    query(recording, sheet, k=6)
    far = len(sheet[::5000])
    assert np.isinf(recording.bounds[0]) and 0.0 < recording.bounds[1] < 0.1 and np.isinf(recording.bounds[2])
    assert recording.asked[1] == len(sheet) and far <= recording.asked[2] < len(sheet) // 50
