"""Index arrays: their distinct values, their runs, and the places within runs laid one after another.

numpy 2.3 and later find ``np.unique(values)`` of integers (given no ``return_*`` option) by a hash table: on
a million node or face indices that costs many times a sort, and the morph asks for the distinct nodes of every
candidate pair, element, and group of surface nodes.  :func:`distinct` gives the same sorted array by a sort.
"""
from __future__ import annotations

import numpy as np


def distinct(values) -> np.ndarray:
    """The sorted distinct values ``(d,)`` of ``values`` (any shape, flattened), as ``np.unique(values)`` gives them
    for integers (and for floats but NaN, which ``np.unique`` merges and this keeps, each NaN apart)."""
    ordered = np.sort(np.asarray(values).ravel())
    if len(ordered) < 2:
        return ordered
    return ordered[np.concatenate([[True], ordered[1:] != ordered[:-1]])]


def run_places(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For runs of ``counts (n,)`` elements laid one after another (``sum(counts)`` in all): the run ``(sum,)`` of
    each element and its place ``(sum,)`` in its run, from 0."""
    run = np.repeat(np.arange(len(counts)), counts)
    return run, np.arange(len(run)) - np.repeat(np.cumsum(counts) - counts, counts)


def runs(values: np.ndarray) -> list[tuple[int, slice]]:
    """``(value, slice)`` of each run of equal values of the sorted ``values (c,)``, in order."""
    cuts = np.flatnonzero(np.diff(values)) + 1
    starts = np.concatenate([[0], cuts])
    ends = np.concatenate([cuts, [len(values)]])
    return [(int(values[a]), slice(a, b)) for a, b in zip(starts, ends) if b > a]
