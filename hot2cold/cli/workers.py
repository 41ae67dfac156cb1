"""What a local batch worker process does first: the numeric libraries at one thread (the pool is the
parallelism).

:func:`one_thread_each` is the pool's ``initializer``.  A "spawn" worker unpickles it, and so imports this
module, before anything else of hot2cold's: this module (and :mod:`hot2cold.cli`, its package) must import
nothing heavy at module level, numpy least of all, so that the variables are set before the numeric
libraries are loaded and read them.  The parent's environment is left as it is.
"""
from __future__ import annotations

import os

#: Environment of the local workers: one thread each for OpenMP, OpenBLAS and MKL.
ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def one_thread_each() -> None:
    """Run in a pool's worker process before its first job: set :data:`ONE_THREAD` in the worker's own
    environment (read by the libraries it loads later) and limit those already loaded (threadpoolctl)."""
    os.environ.update(ONE_THREAD)
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
