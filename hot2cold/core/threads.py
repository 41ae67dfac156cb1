"""Independent pieces of work (one per face, mostly) in a few threads: the same results in the same order as
one after the other, sooner where the machine has cores to spare.

The heavy steps of a morph are numpy, scipy and k-d tree calls on large arrays, which release Python's
global interpreter lock while they run, so two faces' foot points, grids or fits proceed side by side.
The kernel's calls keep the lock: they run one at a time, whichever thread makes them.  A piece of work must
not write what another one reads; each writes its own face's entries of shared caches, if any.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, Sequence, TypeVar

import numpy as np

T = TypeVar("T")
R = TypeVar("R")


#: A face's work is worth a thread of its own from about this many nodes (its rows, foot points, grid
#: points): below, Python's own steps outweigh the array work, and two threads only take the lock from each
#: other, so a part of many faces with tens to hundreds of nodes each gains nothing from threads; a few large
#: faces do.
LARGE = 4_000


def map_threads(fn: Callable[[T], R], items: Iterable[T], threads: int,
                cost: Sequence[float] | None = None, large: float | None = None) -> list[R]:
    """``[fn(item) for item in items]``, in up to ``threads`` threads (one: in this thread, in order).

    ``cost``: a guess of each item's work in nodes (or points); the items run in threads only where two of
    them reach ``large`` (default :data:`LARGE`; no ``cost``: always), the costliest started first, so that
    one large face does not come last and run alone.  An exception of ``fn`` is raised here, that of the
    first item in ``items``' order that raised, once every item started has ended."""
    items = list(items)
    if cost is not None and np.count_nonzero(np.asarray(cost, float) >= (LARGE if large is None else large)) < 2:
        threads = 1
    if threads <= 1 or len(items) <= 1:
        return [fn(item) for item in items]
    order = range(len(items)) if cost is None else sorted(range(len(items)), key=lambda i: -cost[i])
    with ThreadPoolExecutor(min(threads, len(items))) as pool:
        futures = {i: pool.submit(fn, items[i]) for i in order}
    return [futures[i].result() for i in range(len(items))]
