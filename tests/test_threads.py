"""Per-face work in threads (``Settings.threads``): the same results as in one thread."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from hot2cold.core.threads import map_threads


def test_map_threads_keeps_the_order_and_starts_the_costliest_first(monkeypatch):
    import hot2cold.core.threads as threads

    started, submitted = [], []

    class Recording(threads.ThreadPoolExecutor):
        def submit(self, fn, *args):
            submitted.append(args[0])
            return super().submit(fn, *args)

    def work(x):
        started.append(x)
        time.sleep(0.01 * (x % 3))
        return x * x, threading.get_ident()

    monkeypatch.setattr(threads, "ThreadPoolExecutor", Recording)
    items = list(range(10))
    out = map_threads(work, items, 3, cost=[x % 4 for x in items], large=1)
    assert [r for r, _ in out] == [x * x for x in items]
    assert len({t for _, t in out}) > 1                                  # it did run in threads
    assert submitted == [3, 7, 2, 6, 1, 5, 9, 0, 4, 8]                   # the costliest first, ties in order
    started.clear()
    assert [r for r, _ in map_threads(work, items, 1, cost=[x % 4 for x in items])] == [x * x for x in items]
    assert started == items                                              # one thread: in order, here
    assert {t for _, t in map_threads(work, items, 1)} == {threading.get_ident()}
    # items too small for threads (fewer than two of them reach `large`): in this thread, in order
    started.clear()
    out = map_threads(work, items, 3, cost=[10 if x == 4 else 1 for x in items], large=10)
    assert started == items and {t for _, t in out} == {threading.get_ident()}


def test_map_threads_raises_the_first_items_error():
    def work(x):
        if x in (2, 5):
            raise ValueError(f"item {x}")
        return x

    with pytest.raises(ValueError, match="item 2"):
        map_threads(work, range(8), 2)


def test_threads_must_be_positive():
    from hot2cold.settings import Settings

    with pytest.raises(ValueError, match="threads must be at least 1"):
        Settings(threads=0)


@pytest.mark.heavy
def test_a_morph_in_two_threads_is_the_morph_in_one(block_shape, block_nodes, monkeypatch):
    """The filleted block under the untwist whose G1 refines faces along two edges (``test_g1``'s
    ``..._refined_along_the_edges_its_nets_cannot_close``): classification, refinement to the tolerance, G1
    with its refinement trial; every surface, curve, node error, report figure and G1 decision the same in two
    threads as in one."""
    from hot2cold.pipeline.g1 import REFINED
    from hot2cold.pipeline.morph import morph
    from hot2cold.settings import Settings
    from hot2cold.testing.synthetic import UntwistField

    import hot2cold.core.threads as threads

    data = (block_nodes, UntwistField.over(block_nodes, 0.05, 1e-4)(block_nodes))
    one = morph(block_shape, data, Settings(threads=1))
    seen = set()
    run = threads.ThreadPoolExecutor.submit

    def submit(pool, fn, *args):                                      # which threads the work ran in
        return run(pool, lambda *a: (seen.add(threading.get_ident()), fn(*a))[1], *args)

    monkeypatch.setattr(threads, "LARGE", 0)           # the block's faces (about 700 nodes) in threads too
    monkeypatch.setattr(threads.ThreadPoolExecutor, "submit", submit)
    two = morph(block_shape, data, Settings(threads=2))
    assert len(seen) >= 2
    for a, b in zip(one.faces, two.faces):
        assert np.array_equal(a.surface.poles, b.surface.poles) and a.rank == b.rank
    for a, b in zip(one.edges, two.edges):
        assert np.array_equal(a.curve.poles, b.curve.poles)
    assert np.array_equal(one.node_errors, two.node_errors, equal_nan=True)
    assert np.array_equal(one.classification.uv, two.classification.uv, equal_nan=True)
    for key in ("delta_max", "delta_mean", "valid", "g1", "refinements", "faces"):
        assert one.report.to_dict()[key] == two.report.to_dict()[key], key
    assert any(g["method"].endswith(REFINED) for g in one.report.g1)   # G1's trial was taken


def test_the_morph_command_takes_the_cores_and_a_batch_job_one(tmp_path, monkeypatch, blade_step):
    """``hot2cold morph`` runs the faces' work in the process's cores; a batch job (one per core) in one."""
    import os

    import hot2cold.pipeline.morph as pipeline_morph
    from hot2cold.cli import main
    from hot2cold.cli.options import MorphOptions
    from hot2cold.cli.run import run_morph
    from hot2cold.errors import InputError

    seen = []

    def fake_morph(hot, field, settings, **kwargs):
        seen.append(settings.threads)
        raise InputError("stopped here")

    monkeypatch.setattr(pipeline_morph, "morph", fake_morph)
    field = tmp_path / "field.csv"
    field.write_text("x,y,z,dx,dy,dz\n0,0,0,0,0,0\n")
    assert main(["morph", str(blade_step), str(field), "-o", str(tmp_path / "cold.step"), "-q"]) == 2
    assert seen == [len(os.sched_getaffinity(0))]
    with pytest.raises(InputError):
        run_morph(blade_step, field, MorphOptions())               # as a batch job calls it
    assert seen[-1] == 1
