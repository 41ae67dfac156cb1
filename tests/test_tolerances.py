"""The cold part's tolerances state the true gaps between its edges and faces (kernel.tolerances)."""
from __future__ import annotations

import numpy as np

from hot2cold.kernel.rebuild import rebuild
from hot2cold.kernel.step import read_step, write_step
from hot2cold.kernel.tolerances import fit_tolerances
from hot2cold.kernel.validity import check_solids
from hot2cold.pipeline.load import load_part
from hot2cold.settings import Settings


def _slid_box():
    """A 10 mm box whose top face's surface is the same plane with its parameters slid along it: its poles
    spread 20 % about the face's centre (the plane 12 mm across, holding the 10 mm face), every edge as it
    was.  The edges lie on the surface; their curves on the face (kept from the hot part) miss them by up to
    1.4 mm (at the corners, 1 mm along x and y)."""
    import cadquery as cq

    part = load_part(cq.Workplane().box(10, 10, 10).val(), Settings())
    top = max(part.faces, key=lambda f: f.surface.poles[..., 2].min())
    surfaces = [f.surface for f in part.faces]
    poles = top.surface.poles.copy()
    centre = poles.reshape(-1, 3).mean(axis=0)
    poles[..., :2] = centre[:2] + 1.2 * (poles[..., :2] - centre[:2])
    surfaces[top.index] = top.surface.with_poles(poles)
    edges = {use.edge for use in top.uses}
    return part, surfaces, edges


def test_curves_on_a_face_whose_parameters_slid_are_projected_again(tmp_path):
    part, surfaces, top_edges = _slid_box()
    curves = [e.curve for e in part.edges]

    stale = rebuild(part.kernel, surfaces, curves, part.vertices)
    gaps = fit_tolerances(stale)                                  # the curves on the face kept
    np.testing.assert_allclose(gaps[list(top_edges)], np.sqrt(2.0), rtol=1e-9)
    assert np.delete(gaps, list(top_edges)).max() < 1e-12

    cold = rebuild(part.kernel, surfaces, curves, part.vertices)
    gaps = fit_tolerances(cold, reproject_above=1e-6)
    assert gaps.max() < 1e-6, gaps                                # the edges lie on the plane
    assert all(c.valid and c.closed for c in check_solids(cold.shape))
    write_step(cold.shape, tmp_path / "cold.step")
    back = check_solids(read_step(tmp_path / "cold.step"))
    assert len(back) == 1 and back[0].valid and back[0].closed
    np.testing.assert_allclose(back[0].volume, 1000.0, rtol=1e-9)
