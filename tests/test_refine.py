"""Knot insertion keeps the hot shape exactly; the kernel agrees."""
from __future__ import annotations

import numpy as np
import pytest

from hot2cold.bspline import BSplineSurface, evaluate_surface, insert_knots
from hot2cold.kernel.convert import record_to_surface, surface_to_record

RNG = np.random.default_rng(4)


def _surface(rational):
    u = np.concatenate([np.zeros(4), [0.3, 0.6], np.ones(4)])
    v = np.concatenate([np.zeros(3), [0.5], np.ones(3)])
    w = RNG.uniform(0.5, 2.0, (6, 4)) if rational else None
    return BSplineSurface(RNG.normal(size=(6, 4, 3)), u, v, 3, 2, w)


@pytest.mark.parametrize("rational", [False, True])
@pytest.mark.parametrize("axis", [0, 1])
def test_insert_knots_keeps_the_surface_and_matches_the_kernel(rational, axis):
    surface = _surface(rational)
    new_knots = [0.15, 0.45, 0.6] if axis == 0 else [0.25, 0.75]
    refined = insert_knots(surface, axis, new_knots)
    assert refined.shape[axis] == surface.shape[axis] + len(new_knots)
    u, v = RNG.uniform(0, 1, 500), RNG.uniform(0, 1, 500)
    assert np.abs(evaluate_surface(refined, u, v) - evaluate_surface(surface, u, v)).max() <= 1e-12
    kernel = record_to_surface(surface)
    for x in new_knots:
        (kernel.InsertUKnot if axis == 0 else kernel.InsertVKnot)(x, 1, 1e-12, True)
    oracle = surface_to_record(kernel)
    assert np.abs(oracle.poles - refined.poles).max() <= 1e-12
    assert np.array_equal(oracle.u_knots, refined.u_knots) and np.array_equal(oracle.v_knots, refined.v_knots)


def test_tolerance_refines_a_face_that_cannot_follow_the_field(tmp_path):
    """The blade's planar tip cap (a 2x2 bilinear net) cannot bend: with --tolerance it is refined."""
    from hot2cold.kernel.sampling import fe_surface_nodes
    from hot2cold.kernel.step import read_step
    from hot2cold.morph import morph
    from hot2cold.settings import Settings
    from conftest import SAMPLES
    shape = read_step(SAMPLES / "twisted_blade.step")
    nodes = fe_surface_nodes(shape, 1.0, seed=1)[0]
    bend = np.column_stack([np.zeros(len(nodes)), np.zeros(len(nodes)), 2e-3 * nodes[:, 0] ** 2])   # bends the caps
    plain = morph(shape, (nodes, bend))
    refined = morph(shape, (nodes, bend), Settings(tolerance=1e-3))
    caps = [f.index for f in plain.report.faces if f.control_points == "2x2"]
    assert max(plain.report.faces[k].delta_max for k in caps) > 1e-2
    assert max(refined.report.faces[k].delta_max for k in caps) < max(plain.report.faces[k].delta_max for k in caps) / 10
    assert {r["face"] for r in refined.report.refinements if r["rounds"] > 0} >= set(caps)
    assert all(s.valid and s.closed for s in refined.report.solids)
