"""The kernel's measures of a part: tolerances that state the true gaps between edges and faces
(kernel.tolerances), volumes and areas (kernel.validity)."""
from __future__ import annotations

import numpy as np
import pytest

from hot2cold.kernel.rebuild import rebuild
from hot2cold.kernel.step import read_step, write_step
from hot2cold.kernel.tolerances import fit_tolerances
from hot2cold.kernel.tessellate import tessellate
from hot2cold.kernel.validity import check_solids, face_areas, volume
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


def _edge_uses(shape):
    """``(edge, face)`` of every non-degenerate edge use of ``shape``'s faces (a seam twice)."""
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopoDS import TopoDS

    from hot2cold.kernel.explore import edges_of, shape_map

    return [(edge, TopoDS.Face_s(face)) for face in shape_map(shape, TopAbs_FACE) for edge in edges_of(face)
            if not BRep_Tool.Degenerated_s(edge)]


def test_the_kernels_gap_measure_is_the_point_by_point_one(monkeypatch):
    """``_gap`` measures with ``BRepLib_ValidateEdge`` where an edge's curve and its curve on the face have one
    rigid placement (the curves where they are defined), point by point elsewhere: the same largest distance
    (the slid box's top edges 1.4 mm off their curves on the face, the others on them), the box moved too."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt, gp_Trsf, gp_Vec
    from OCP.TopLoc import TopLoc_Location

    import hot2cold.kernel.tolerances as tolerances

    part, surfaces, _ = _slid_box()
    stale = rebuild(part.kernel, surfaces, [e.curve for e in part.edges], part.vertices)
    placement = gp_Trsf()
    placement.SetRotation(gp_Ax1(gp_Pnt(1.0, 2.0, 3.0), gp_Dir(1.0, 1.0, 0.0)), 0.7)
    placement.SetTranslationPart(gp_Vec(5.0, -3.0, 2.0))
    moved = stale.shape.Moved(TopLoc_Location(placement))
    for shape in (stale.shape, moved):
        by_points = []
        for edge, face in _edge_uses(shape):
            c3d, on_face = BRepAdaptor_Curve(edge), BRepAdaptor_Curve(edge, face)
            by_points.append(tolerances._sampled_gap(c3d, on_face, c3d.FirstParameter(), c3d.LastParameter(), 51))
        by_points = np.array(by_points)
        assert np.isclose(by_points.max(), np.sqrt(2.0), rtol=1e-9) and by_points.min() < 1e-12

        point_by_point = []
        monkeypatch.setattr(tolerances, "_sampled_gap", lambda *args: point_by_point.append(args) or np.inf)
        gaps = np.array([tolerances._gap(edge, face, 51) for edge, face in _edge_uses(shape)])
        monkeypatch.undo()
        assert not point_by_point                             # the kernel's loop measured them all
        np.testing.assert_allclose(gaps, by_points, rtol=0, atol=1e-12)

    shifted, scaled = gp_Trsf(), gp_Trsf()
    shifted.SetTranslation(gp_Vec(1.0, 0.0, 0.0))
    scaled.SetScale(gp_Pnt(0.0, 0.0, 0.0), 2.0)
    assert tolerances._same_rigid(gp_Trsf(), gp_Trsf()) and tolerances._same_rigid(placement, placement)
    assert not tolerances._same_rigid(shifted, gp_Trsf()) and not tolerances._same_rigid(scaled, scaled)


def _lofted_blade():
    """Three spline sections (12 points each, 80 mm apart, twisted by 50 degrees and tapered) lofted into a
    smooth blade, as a CAD system's loft gives it."""
    import cadquery as cq

    def section(z, twist, scale):
        t = np.linspace(0, 2 * np.pi, 13)[:-1]
        x, y = 30 * scale * np.cos(t), 4 * scale * np.sin(t) + 3 * scale * np.cos(t) ** 2
        c, s = np.cos(np.radians(twist)), np.sin(np.radians(twist))
        pts = [cq.Vector(c * a - s * b, s * a + c * b, z) for a, b in zip(x, y)]
        return cq.Wire.assembleEdges([cq.Edge.makeSpline(pts + [pts[0]])])

    return cq.Solid.makeLoft([section(0, 0, 1.0), section(40, 25, 0.8), section(80, 50, 0.6)]).wrapped


@pytest.mark.heavy
def test_volume_and_areas_agree_with_a_fine_triangulation():
    """The kernel's default Gauss rule gave 15 441 mm³ for this blade of 19 690 mm³ (-22 %); the volume and
    the face areas the checks and the report use agree with a triangulation to 1 um to 1e-4 (5e-5 measured)."""
    shape = _lofted_blade()
    mesh = tessellate(shape, 1e-3)
    v = mesh.vertices[mesh.triangles]
    cross = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    mesh_volume = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0
    assert volume(shape) == pytest.approx(mesh_volume, rel=1e-4)
    assert 19_600 < volume(shape) < 19_800
    from hot2cold.kernel.explore import shape_map
    from OCP.TopAbs import TopAbs_FACE
    areas = face_areas(shape_map(shape, TopAbs_FACE))
    assert areas.sum() == pytest.approx(0.5 * np.linalg.norm(cross, axis=1).sum(), rel=1e-4)


def test_a_reprojected_curve_whose_end_parts_from_its_neighbours_is_closed_onto_them(monkeypatch):
    """A projection stops at the edge of the surface's domain, which a face may overrun (an Autodesk base
    plate: a face 5.6e-4 beyond its surface in v); its neighbours' curves end outside.  Here one projected curve
    of the slid box's top face is made to end 1e-3 off in the face's parameters: the face is closed again in
    its parameters and the cold solid is valid."""
    from OCP.BRep import BRep_Builder, BRep_Tool
    from OCP.gp import gp_Pnt2d
    from hot2cold.kernel import repair, tolerances

    part, surfaces, top_edges = _slid_box()
    cold = rebuild(part.kernel, surfaces, [e.curve for e in part.edges], part.vertices)
    top = next(k for k, f in enumerate(part.faces) if {u.edge for u in f.uses} == top_edges)
    plain, spoiled = tolerances._reproject, []

    def reproject_then_spoil(edge, face, gap, samples):
        kept = plain(edge, face, gap, samples)
        if not spoiled and kept < gap:
            spline = repair.pcurve_spline(edge, face)
            end = spline.Pole(spline.NbPoles())
            spline.SetPole(spline.NbPoles(), gp_Pnt2d(end.X() + 1e-3, end.Y()))
            BRep_Builder().UpdateEdge(edge, spline, face, BRep_Tool.Tolerance_s(edge))
            spoiled.append(edge)
        return kept

    monkeypatch.setattr(tolerances, "_reproject", reproject_then_spoil)
    fit_tolerances(cold, reproject_above=1e-6)
    face = cold.faces[top]
    assert spoiled and max(np.linalg.norm(repair._ends(a, face)[1] - repair._ends(b, face)[0])
                           for a, b in repair._junctions(face)) == 0
    assert all(c.valid and c.closed for c in check_solids(cold.shape))


def _touching_hole(centre_x: float):
    """A 20 x 10 mm plane face (in B-spline form, as a morph leaves it) with a round hole whose circle passes
    through the vertex (10, 0) of the face's outline and shares it: centred at (``centre_x``, 3), so tangent to
    the outline there (a hole that touches it) or turned and crossing the outline again at ``2 centre_x - 10``,
    as a morph leaves such a touch (on a real part 6e-3 to 8e-3 mm off the vertex)."""
    from OCP.BRepBuilderAPI import (BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakeVertex,
                                    BRepBuilderAPI_MakeWire, BRepBuilderAPI_NurbsConvert)
    from OCP.gp import gp_Ax2, gp_Circ, gp_Dir, gp_Pnt
    from OCP.TopoDS import TopoDS

    touch = BRepBuilderAPI_MakeVertex(gp_Pnt(10, 0, 0)).Vertex()
    corners = [BRepBuilderAPI_MakeVertex(gp_Pnt(*p)).Vertex() for p in ((20, 0, 0), (20, 10, 0), (0, 10, 0), (0, 0, 0))]
    ring = [touch, *corners, touch]
    outline = BRepBuilderAPI_MakeWire()
    for a, b in zip(ring[:-1], ring[1:]):
        outline.Add(BRepBuilderAPI_MakeEdge(a, b).Edge())
    radius = float(np.hypot(centre_x - 10.0, 3.0))
    circle = gp_Circ(gp_Ax2(gp_Pnt(centre_x, 3, 0), gp_Dir(0, 0, -1)), radius)
    hole = BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(circle, touch, touch).Edge()).Wire()
    maker = BRepBuilderAPI_MakeFace(outline.Wire())
    maker.Add(hole)
    return TopoDS.Face_s(BRepBuilderAPI_NurbsConvert(maker.Face(), True).Shape())


def test_a_hole_touching_the_outline_keeps_its_shared_vertex_valid():
    """A hole sharing a vertex with the face's outline: tangent there, valid, and its vertex keeps its
    tolerance; turned so that it meets the outline again 1 mm off the vertex, IntersectingWires, until the
    vertex's tolerance holds that meeting, within ``touch_bound`` (and only then)."""
    from hot2cold.kernel.explore import shape_map
    from hot2cold.kernel.faults import face_faults
    from hot2cold.kernel.rebuild import ColdKernel
    from hot2cold.kernel.repair import face_valid
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_VERTEX

    def fitted(face, bound):
        cold = ColdKernel(face, [face], shape_map(face, TopAbs_EDGE), shape_map(face, TopAbs_VERTEX))
        fit_tolerances(cold, touch_bound=bound)
        return max(BRep_Tool.Tolerance_s(v) for v in cold.vertices)

    tangent = _touching_hole(10.0)
    assert face_valid(tangent)
    assert fitted(tangent, 2.0) <= 1e-6
    for bound, valid in ((0.5, False), (2.0, True)):
        face = _touching_hole(10.5)
        assert "IntersectingWires" in face_faults(face)
        assert (fitted(face, bound) >= 1.0) is valid
        assert face_valid(face) is valid


def test_a_curve_projected_onto_a_closed_surface_stays_on_its_side_of_the_seam(monkeypatch):
    """A quarter of a sphere whose B-spline surface runs the whole turn (u from 0 to 2 pi, closed, made
    non-periodic), its surface turned by 1e-3 rad against its edges as a morph may slide it: the edge along
    u = 0 now lies just below u = 0, and its projection lands at u = 2 pi - 1e-3, across the seam (a tinymovr
    face read back BadOrientationOfSubshape).  Such a projection is not taken: the curve stays where it was,
    the tolerance covers the gap, and the face is valid."""
    import math

    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.Geom import Geom_SphericalSurface
    from OCP.GeomConvert import GeomConvert
    from OCP.gp import gp_Ax1, gp_Ax3, gp_Dir, gp_Pnt
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_VERTEX
    from OCP.TopLoc import TopLoc_Location
    from hot2cold.kernel.conversion import to_bspline
    from hot2cold.kernel.explore import edges_of, shape_map
    from hot2cold.kernel.rebuild import ColdKernel

    whole = GeomConvert.SurfaceToBSplineSurface_s(Geom_SphericalSurface(gp_Ax3(), 10.0))
    shape = to_bspline(BRepBuilderAPI_MakeFace(whole, 0.0, math.pi / 2, 0.5, math.pi / 2, 1e-7).Face())
    face = shape_map(shape, TopAbs_FACE)[0]
    surface = BRep_Tool.Surface_s(face, TopLoc_Location())
    assert surface.IsUClosed() and not surface.IsUPeriodic() and surface.Bounds()[1] == pytest.approx(2 * math.pi)
    surface.Rotate(gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), 1e-3)
    cold = ColdKernel(shape, [face], shape_map(shape, TopAbs_EDGE), shape_map(shape, TopAbs_VERTEX))
    gaps = fit_tolerances(cold, reproject_above=1e-6)
    assert gaps.max() <= 1.01 * 10.0 * 1e-3           # at most the slide: 1e-3 rad on a radius of 10
    for edge in edges_of(face):
        if not BRep_Tool.Degenerated_s(edge):
            first, last = BRep_Tool.Range_s(edge, face)
            curve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
            assert all(-0.01 <= curve.Value(t).X() <= math.pi / 2 + 0.01 for t in np.linspace(first, last, 11))
    assert BRepCheck_Analyzer(face).IsValid()
