"""k-d trees over many points, built the quick way.

:func:`kd_tree` builds scipy's ``cKDTree`` splitting at the sliding midpoint and keeping each node's box as
split (``balanced_tree=False, compact_nodes=False``): over a million foot points or nodes it builds in under
half the time of the default (median splits, shrunk boxes), and its queries are as fast.  Queries are exact
either way, so which build is used changes no result.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

#: The build options of :func:`kd_tree`.
QUICK_BUILD = {"balanced_tree": False, "compact_nodes": False}


def kd_tree(points: np.ndarray) -> cKDTree:
    """A ``cKDTree`` over ``points (n, k)``, built with :data:`QUICK_BUILD`."""
    return cKDTree(points, **QUICK_BUILD)
