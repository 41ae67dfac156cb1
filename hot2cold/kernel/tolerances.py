"""Fitting the cold part's edge and vertex tolerances to the true gaps left by the morph (no sewing).

The morph keeps the hot topology (see :mod:`hot2cold.kernel.rebuild`), so faces are never separated and
there is nothing to re-match as ``BRepBuilderAPI_Sewing`` would on a loose set of faces.  What the morph
can open is a small gap between an edge's 3D curve and the surface of a face it bounds, where the edge is
not a whole side of that face (trimmed faces).  This step measures that gap on every edge use and widens
the edge's tolerance to cover it, then lets ``BRepLib`` bring vertex tolerances into line, so that the
kernel sees a closed, valid solid whose tolerances state the true gaps.

The gap is measured against the edge's curve on the face (its pcurve), which the morph keeps from the hot
part.  Under a field that is not affine a face's parameters slide along its surface against its edges' (most
on a long, narrow bilinear plane between many straight edges), so the pcurve misses the cold edge by far more
than the edge misses the cold surface.  Where the gap is above ``reproject_above``, the pcurve is projected
again from the cold edge (``ShapeFix_Edge``) and kept if it is nearer: the tolerance then states the true gap,
and the STEP file reads back valid (with the old pcurves, widened tolerances alone can leave faces that
cannot be oriented when the file is read back).  A face with such curves
then has the ends of its curves closed onto each other where they part
(:func:`~hot2cold.kernel.repair.close_gaps`): a projection stops at the edge of the surface's domain, which a
face may overrun, where its neighbour's curve ends outside it.
"""
from __future__ import annotations

import logging

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.BRepLib import BRepLib, BRepLib_ValidateEdge
from OCP.BRepTools import BRepTools
from OCP.Geom2dAdaptor import Geom2dAdaptor_Curve
from OCP.Geom2dInt import Geom2dInt_GInter
from OCP.GeomAbs import GeomAbs_BSplineCurve
from OCP.gp import gp_Identity
from OCP.IntRes2d import IntRes2d_Domain
from OCP.Precision import Precision
from OCP.ShapeBuild import ShapeBuild_Edge
from OCP.ShapeFix import ShapeFix_Edge
from OCP.TopAbs import TopAbs_EDGE, TopAbs_VERTEX
from OCP.TopExp import TopExp
from OCP.TopoDS import TopoDS
from OCP.TopTools import TopTools_IndexedMapOfShape

from ..errors import KernelError
from .explore import edges_of, wire_edges
from .rebuild import ColdKernel
from .repair import close_gaps

log = logging.getLogger(__name__)


#: A B-spline edge is sampled at least this many times per knot of its 3D curve.
_PER_KNOT = 8
#: Two curves on a face meet where they are less than this apart in its parameters (BRepCheck's own).
_MEET_TOLERANCE = 1e-10


def _gap(edge, face, n: int) -> float:
    """Largest distance between the edge's 3D curve and its curve on ``face`` at ``n`` parameters, or at
    ``_PER_KNOT`` per knot of a B-spline curve where that is more: an edge refined to a tolerance has many
    spans, and a gap that rises and falls within a span slips between evenly spread samples, to be found by
    BRepCheck later (InvalidCurveOnSurface, on arcs refined under a field with a kink).  The same parameter on
    both curves, evenly spread over the edge's range, its ends included.

    Measured by ``BRepLib_ValidateEdge`` (the kernel's loop, at those parameters) where the two curves have the
    same range and the same rigid placement (measured where they are defined, the distances the same);
    :func:`_sampled_gap` elsewhere, the same measure point by point."""
    c3d = BRepAdaptor_Curve(edge)
    on_face = BRepAdaptor_Curve(edge, face)
    if c3d.GetType() == GeomAbs_BSplineCurve:
        n = max(n, _PER_KNOT * c3d.NbKnots())
    first, last = c3d.FirstParameter(), c3d.LastParameter()
    if (n >= 2 and c3d.Is3DCurve() and _same_rigid(c3d.Trsf(), on_face.Trsf())
            and abs(on_face.FirstParameter() - first) <= Precision.PConfusion_s()
            and abs(on_face.LastParameter() - last) <= Precision.PConfusion_s()):
        validate = BRepLib_ValidateEdge(c3d.Curve(), on_face.CurveOnSurface(), True)
        validate.SetControlPointsNumber(n - 1)          # intervals: n parameters, the ends included
        validate.Process()
        if validate.IsDone():
            return validate.GetMaxDistance() / _VALIDATE_MARGIN
    return _sampled_gap(c3d, on_face, first, last, n)


#: ``BRepLib_ValidateEdge.GetMaxDistance`` gives the largest distance it found times this (a margin of its own,
#: for the tolerances it sets); :func:`_gap` takes it off, to state the distance itself.
_VALIDATE_MARGIN = 1.00001


def _same_rigid(a, b) -> bool:
    """Whether the placements ``a`` and ``b`` (``gp_Trsf``) are one and the same rotation and translation."""
    if a.Form() == gp_Identity and b.Form() == gp_Identity:
        return True
    return abs(a.ScaleFactor()) == 1.0 and all(a.Value(r, c) == b.Value(r, c) for r in (1, 2, 3) for c in (1, 2, 3, 4))


def _sampled_gap(c3d, on_face, first: float, last: float, n: int) -> float:
    """:func:`_gap` point by point: the largest distance between the curves ``c3d`` and ``on_face`` (adaptors of
    the edge and of its curve on the face) at ``n`` parameters evenly spread over ``[first, last]``."""
    gap = 0.0
    for t in np.linspace(first, last, n):
        gap = max(gap, c3d.Value(t).Distance(on_face.Value(t)))
    return gap


def _reproject(edge, face, gap: float, samples: int) -> float:
    """Replace ``edge``'s curve on ``face`` by the projection of its 3D curve onto the face's surface if that
    is nearer than ``gap`` (mm, the old curve's) and lies where the old one lies in the face's parameters
    (:func:`_slid`); the gap of the curve kept."""
    first, last = BRep_Tool.Range_s(edge, face)
    old = BRep_Tool.CurveOnSurface_s(edge, face, first, last)
    tolerance = BRep_Tool.Tolerance_s(edge)
    u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
    reach = _SLIDE_SHARE * max(u1 - u0, v1 - v0)
    ShapeBuild_Edge().RemovePCurve(edge, face)
    if ShapeFix_Edge().FixAddPCurve(edge, face, False, tolerance):
        BRepLib.SameParameter_s(edge, tolerance)
        new = _gap(edge, face, samples)
        if new < gap and _slid(old, (first, last), edge, face) <= reach:
            return new
        ShapeBuild_Edge().RemovePCurve(edge, face)
    builder = BRep_Builder()
    builder.UpdateEdge(edge, old, face, tolerance)
    builder.Range(edge, face, first, last)
    return gap


#: A curve projected again may lie at most this share of its face's extent in parameters from the old one.
#: Where the morph slid a face's parameters against its edges, the two lie a gap's length apart; a projection
#: onto a closed surface may land on the far side of its seam instead (a curve along the seam of a sphere-like
#: B-spline projected to the period's other end, its neighbour round the other way), which reads back as a
#: face inside out.
_SLIDE_SHARE = 0.25


def _slid(old, old_range: tuple, edge, face, n: int = 21) -> float:
    """Largest distance, in the face's parameters, between the curve ``old`` (over ``old_range``) and
    ``edge``'s curve on ``face``, at ``n`` matching shares of their ranges."""
    first, last = BRep_Tool.Range_s(edge, face)
    new = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
    shares = np.linspace(0.0, 1.0, n)
    a = [old.Value(old_range[0] + s * (old_range[1] - old_range[0])) for s in shares]
    b = [new.Value(first + s * (last - first)) for s in shares]
    return max(max(abs(p.X() - q.X()), abs(p.Y() - q.Y())) for p, q in zip(a, b))


def _on_face(edge, face) -> tuple:
    """The curve of ``edge`` on ``face`` and its domain, as BRepCheck intersects the wires of a face."""
    first, last = BRep_Tool.Range_s(edge, face)
    curve = Geom2dAdaptor_Curve(BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0))
    first, last = max(first, curve.FirstParameter()), min(last, curve.LastParameter())
    return curve, IntRes2d_Domain(curve.Value(first), first, _MEET_TOLERANCE, curve.Value(last), last,
                                  _MEET_TOLERANCE)


def _touches(face) -> list[tuple]:
    """Where two wires of ``face`` share a vertex (a hole whose outline touches the face's outline there): per
    such vertex and pair of its edges on two wires, ``(vertex, d)``, ``d`` the distance (mm) from the vertex
    to the farthest point where the two edges' curves on the face meet (0 where they meet at the vertex
    alone)."""
    wires = wire_edges(face)
    if len(wires) < 2:
        return []
    vertices = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(face, TopAbs_VERTEX, vertices)
    at: dict[int, list] = {}            # vertex (its index) -> [(wire, edge)]
    for w, edges in enumerate(wires):
        for edge in edges:
            if not BRep_Tool.Degenerated_s(edge):
                for vertex in (TopExp.FirstVertex_s(edge), TopExp.LastVertex_s(edge)):
                    at.setdefault(vertices.FindIndex(vertex), []).append((w, edge))
    surface = BRep_Tool.Surface_s(face)
    out = []
    for index, uses in at.items():
        if len({w for w, _ in uses}) < 2:
            continue
        vertex = TopoDS.Vertex_s(vertices.FindKey(index))
        point = BRep_Tool.Pnt_s(vertex)
        for i, (wa, ea) in enumerate(uses):
            for wb, eb in uses[i + 1:]:
                if wa == wb:
                    continue
                found = Geom2dInt_GInter(*_on_face(ea, face), *_on_face(eb, face), _MEET_TOLERANCE, _MEET_TOLERANCE)
                if not found.IsDone():
                    continue
                ends = [found.Point(k).Value() for k in range(1, found.NbPoints() + 1)]
                for k in range(1, found.NbSegments() + 1):
                    segment = found.Segment(k)
                    ends += [p.Value() for p, has in ((segment.FirstPoint(), segment.HasFirstPoint()),
                                                      (segment.LastPoint(), segment.HasLastPoint())) if has]
                d = max((surface.Value(q.X(), q.Y()).Distance(point) for q in ends), default=0.0)
                out.append((vertex, d))
    return out


def fit_tolerances(cold: ColdKernel, samples: int = 51, margin: float = 1.5,
                   reproject_above: float = np.inf, touch_bound: float = 0.0) -> np.ndarray:
    """Fit edge and vertex tolerances of the cold shape ``cold`` (from :func:`~hot2cold.kernel.rebuild.rebuild`,
    changed in place) to the morphed geometry.

    Returns the gap ``(n_edges,)`` in mm of every edge: the largest distance, over ``samples`` points, between
    its 3D curve and its curve on any face it bounds; where that is above ``reproject_above`` (mm) on a face
    the edge bounds once (not a seam), the curve on the face is projected again from the 3D curve and kept
    if nearer (see the module docstring).  Edge tolerances become at least ``margin`` times that gap.

    A vertex that two wires of a face share (a hole touching the face's outline) gets at least ``margin``
    times the distance to where their curves on the face meet near it, up to ``touch_bound`` (mm)
    (:func:`_touches`): two edges tangent there when hot, each fitted to its own nodes, part at slightly
    different angles and meet again a little way off, with a sliver between them far thinner than that
    distance; BRepCheck takes a meeting of two wires within the tolerance of a vertex they share as that
    vertex, any other as IntersectingWires.
    """
    edge_index = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(cold.shape, TopAbs_EDGE, edge_index)
    pair_gaps: dict = {}          # (edge, face) -> gap
    reprojected = []              # faces with a curve projected again
    try:
        for k, face in enumerate(cold.faces):
            for edge in edges_of(face):
                if BRep_Tool.Degenerated_s(edge):
                    continue
                e = edge_index.FindIndex(edge) - 1
                gap = _gap(edge, face, samples)
                if gap > reproject_above and not BRep_Tool.IsClosed_s(edge, face):
                    kept = _reproject(edge, face, gap, samples)
                    if kept < gap:
                        reprojected.append(k)
                    gap = kept
                pair_gaps[e, k] = max(pair_gaps.get((e, k), 0.0), gap)
        for k in dict.fromkeys(reprojected):
            face = cold.faces[k]
            if close_gaps(face):
                for e in [e for e, f in pair_gaps if f == k]:
                    pair_gaps[e, k] = 0.0
                for edge in edges_of(face):            # each use: a seam's two pcurves
                    if not BRep_Tool.Degenerated_s(edge):
                        e = edge_index.FindIndex(edge) - 1
                        pair_gaps[e, k] = max(pair_gaps[e, k], _gap(edge, face, samples))
        gaps = np.zeros(len(cold.edges))
        for (e, _), gap in pair_gaps.items():
            gaps[e] = max(gaps[e], gap)
        builder = BRep_Builder()
        for e, edge in enumerate(cold.edges):
            if margin * gaps[e] > BRep_Tool.Tolerance_s(edge):
                builder.UpdateEdge(edge, margin * gaps[e])
        BRepLib.UpdateTolerances_s(cold.shape, False)
        touching = 0
        for face in cold.faces:
            for vertex, d in _touches(face):
                if BRep_Tool.Tolerance_s(vertex) < d <= touch_bound:
                    builder.UpdateVertex(vertex, margin * d)
                    touching += 1
        if touching:
            log.info("%d vertices where two wires of a face touch hold where the wires meet beside them", touching)
    except Exception as exc:
        raise KernelError(f"fitting the cold part's tolerances failed: {exc}") from exc
    log.info("sewed: largest edge gap %.3g mm (%d curves on faces projected again)", gaps.max() if len(gaps) else 0.0,
             len(reprojected))
    return gaps
