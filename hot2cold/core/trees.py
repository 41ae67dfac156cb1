"""k-d trees over many points, built the quick way, and queried in threads only where that pays.

:func:`kd_tree` builds scipy's ``cKDTree`` splitting at the sliding midpoint and keeping each node's box as
split (``balanced_tree=False, compact_nodes=False``): over a million foot points or nodes it builds in under
half the time of the default (median splits, shrunk boxes), and its queries are as fast.  Queries are exact
either way, so which build is used changes no result.

:func:`query` asks a tree for the nearest points, spread over every core (``workers=-1``) only when the query is
large: scipy starts its threads anew for each query, which costs more than a small query itself (a face's few
dozen nodes, asked about face by face on a part of hundreds of faces), and the answer is the same either way.
A large query for several neighbours is bounded first (:func:`_bounded`): the tree then skips the boxes that
cannot hold a point's neighbours, and the few points whose neighbours lie farther are asked again unbounded.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

#: The build options of :func:`kd_tree`.
QUICK_BUILD = {"balanced_tree": False, "compact_nodes": False}


def kd_tree(points: np.ndarray) -> cKDTree:
    """A ``cKDTree`` over ``points (n, k)``, built with :data:`QUICK_BUILD`."""
    return cKDTree(points, **QUICK_BUILD)


#: A query for at least this many neighbours in all (points times ``k``) runs in every core's thread
#: (:func:`query`); a smaller one in the caller's.
PARALLEL_QUERY = 16_384


#: A query of at least this many points for ``k > 1`` neighbours each, with no options, is bounded first
#: (:func:`_bounded`).
BOUNDED_QUERY = 65_536
#: Points of a bounded query whose ``k`` nearest set its bound: about this many, evenly spread over the query.
_PROBES = 1_024
#: The bound of a bounded query: this quantile of the probes' ``k``-th nearest distances, times ``_BOUND_SLACK``
#: (the points farther than it, about one in a hundred, are asked again without it).
_BOUND_QUANTILE, _BOUND_SLACK = 0.99, 1.1


def query(tree: cKDTree, points: np.ndarray, k: int = 1, **options) -> tuple[np.ndarray, np.ndarray]:
    """``tree.query(points (n, d), k, **options)``: the distances and indices ``(n, k)`` (``(n,)`` for ``k = 1``)
    of each point's ``k`` nearest, in every core's thread where ``n * k`` is at least :data:`PARALLEL_QUERY`,
    else in the caller's; bounded first (:func:`_bounded`: neighbours at equal distances may come in another
    order) where ``n`` is at least :data:`BOUNDED_QUERY`, ``k > 1`` and no options are given."""
    workers = -1 if len(points) * k >= PARALLEL_QUERY else 1
    if k > 1 and not options and len(points) >= BOUNDED_QUERY:
        return _bounded(tree, points, k, workers)
    return tree.query(points, k=k, workers=workers, **options)


def _bounded(tree: cKDTree, points: np.ndarray, k: int, workers: int) -> tuple[np.ndarray, np.ndarray]:
    """``tree.query(points (n, d), k)``'s distances and indices ``(n, k)``, asked with a distance bound first:
    about :data:`_PROBES` of the points, spread evenly, give their ``k``-th nearest distances, and
    ``_BOUND_SLACK`` times their ``_BOUND_QUANTILE`` quantile bounds the query of all; the points with fewer than
    ``k`` neighbours within it (their last distance inf) are asked again without it.  The distances are the
    unbounded query's; so are the indices, but for neighbours at the same distance, which may come in another
    order (or, tied at the ``k``-th, be another of them): the tree skips the boxes beyond the bound and meets
    the rest in another order."""
    probe = tree.query(points[::max(1, len(points) // _PROBES)], k=k, workers=workers)[0][:, -1]
    bound = _BOUND_SLACK * float(np.quantile(probe, _BOUND_QUANTILE))
    if not 0.0 < bound < np.inf:
        return tree.query(points, k=k, workers=workers)
    dist, idx = tree.query(points, k=k, workers=workers, distance_upper_bound=bound)
    short = np.flatnonzero(~np.isfinite(dist[:, -1]))
    if len(short):
        dist[short], idx[short] = tree.query(points[short], k=k, workers=workers)
    return dist, idx
