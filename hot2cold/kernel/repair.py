"""Mending a face that the B-spline conversion broke while the face as read was valid.

``BRepBuilderAPI_NurbsConvert`` re-approximates a face's pcurves where the B-spline's parameters are not the
elementary surface's (the rational arcs of a cone, a sphere, a torus): near a singular point of the surface
(a cone's apex, a sphere's pole) the projection that makes them drifts, and two pcurves that met at the
degenerate edge of the apex no longer meet in the parameter plane (BRepCheck: ``NotClosed`` on the wire,
``UnorientableShape`` on the face), although both edges still meet in space.

:func:`mend_face` closes such gaps: it walks each wire of the converted face from vertex to vertex (not from
pcurve end to pcurve end, which would stop at the gap) and moves the end of a pcurve onto the start of the
next where the two differ.  Where one of the two is a degenerate edge (an apex, a pole: its pcurve is an
iso-line the conversion keeps exact), the other one moves; so where one is a seam (its two pcurves must stay
a period apart); otherwise the end whose point on the surface lies farther from the vertex moves onto the
other.  A move changes the curve near its end only (the end pole of a clamped B-spline), by the gap.  Where
that leaves the face invalid, the second way makes the edges' tolerances cover their pcurves
(``BRepLib.SameParameter``), up to a bound the caller gives; :func:`fix_faces` is the last, ``ShapeFix_Face``
on the faces still broken.
"""
from __future__ import annotations

import logging

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Surface
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.BRepLib import BRepLib
from OCP.Geom2d import Geom2d_BSplineCurve, Geom2d_Line, Geom2d_TrimmedCurve
from OCP.Geom2dConvert import Geom2dConvert
from OCP.gp import gp_Pnt2d
from OCP.ShapeBuild import ShapeBuild_ReShape
from OCP.ShapeFix import ShapeFix_Face
from OCP.TopAbs import TopAbs_FORWARD, TopAbs_REVERSED
from OCP.TopExp import TopExp
from OCP.TopoDS import TopoDS

from .explore import edges_of, wire_edges

log = logging.getLogger(__name__)


def face_valid(face) -> bool:
    """Whether ``BRepCheck_Analyzer`` finds ``face`` (its wires, edges and vertices) valid."""
    return BRepCheck_Analyzer(face).IsValid()


def pcurve_spline(edge, face) -> Geom2d_BSplineCurve | None:
    """The pcurve of the oriented ``edge`` on ``face`` as a new clamped B-spline over exactly the edge's range,
    with its parameters (its end poles are the pcurve's ends); None for a pcurve that is no line or B-spline
    (a conic's B-spline would have other parameters)."""
    first, last = BRep_Tool.Range_s(edge, face)
    curve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
    basis = curve.BasisCurve() if isinstance(curve, Geom2d_TrimmedCurve) else curve
    if not isinstance(basis, (Geom2d_BSplineCurve, Geom2d_Line)):
        return None
    spline = Geom2dConvert.CurveToBSplineCurve_s(Geom2d_TrimmedCurve(curve, first, last))
    if spline.IsPeriodic():
        spline.SetNotPeriodic()
    if (spline.FirstParameter(), spline.LastParameter()) != (first, last):
        spline.Segment(first, last)
    return spline


def _ends(edge, face) -> tuple[np.ndarray, np.ndarray]:
    """Where the oriented ``edge`` starts and ends on ``face``, in the face's parameters, ``(2,)`` each."""
    first, last = BRep_Tool.Range_s(edge, face)
    curve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
    a, b = curve.Value(first), curve.Value(last)
    a, b = np.array([a.X(), a.Y()]), np.array([b.X(), b.Y()])
    return (b, a) if edge.Orientation() == TopAbs_REVERSED else (a, b)


def _junctions(face) -> list[tuple]:
    """Per wire of ``face``, each place where one edge use ends and the next begins: ``(arriving, departing)``
    oriented edges as the face runs them.  The next is the use that starts at the vertex where one ends (of
    several, as at a seam's vertex, the one whose pcurve starts nearest); found from the vertices, so a gap in
    the parameter plane does not stop the walk."""
    junctions = []
    for uses in wire_edges(face):
        ends = [_ends(use, face) for use in uses]
        pairs = []
        for i, arriving in enumerate(uses):
            vertex = TopExp.LastVertex_s(arriving, True)
            for j, departing in enumerate(uses):
                if TopExp.FirstVertex_s(departing, True).IsSame(vertex):
                    pairs.append((float(np.linalg.norm(ends[i][1] - ends[j][0])), i, j))
        taken_i, taken_j = set(), set()
        for _, i, j in sorted(pairs):
            if i not in taken_i and j not in taken_j:
                taken_i.add(i)
                taken_j.add(j)
                junctions.append((uses[i], uses[j]))
    return junctions


def close_gaps(face) -> int:
    """Close, in place, the gaps in the parameter plane between consecutive pcurves in every wire of ``face``.
    Returns how many pcurve ends were moved."""
    moves: list = []          # [(forward edge, orientation of its pcurve, {0 first or 1 last: uv})]
    surface = BRepAdaptor_Surface(face)
    for edge, following in _junctions(face):
        end, start = _ends(edge, face)[1], _ends(following, face)[0]
        if np.array_equal(end, start):
            continue
        degenerate = BRep_Tool.Degenerated_s(edge), BRep_Tool.Degenerated_s(following)
        seam = BRep_Tool.IsClosed_s(edge, face), BRep_Tool.IsClosed_s(following, face)
        if degenerate[0] != degenerate[1]:        # an apex or a pole: the iso-line of the degenerate edge holds
            target = end if degenerate[0] else start
        elif seam[0] != seam[1]:                  # a seam's two pcurves stay one curve apart by a period
            target = end if seam[0] else start
        else:                                     # the end whose point on the surface is nearer the vertex
            vertex = BRep_Tool.Pnt_s(TopExp.LastVertex_s(edge, True))
            off = [vertex.Distance(surface.Value(*uv)) for uv in (end, start)]
            target = end if off[0] <= off[1] else start
        for use, which in ((edge, 1), (following, 0)):
            if not np.array_equal(_ends(use, face)[which], target):
                _plan(moves, use, which, target, face)
    for forward, orientation, ends in moves:
        _move_ends(forward, orientation, ends, face)
    return sum(len(ends) for _, _, ends in moves)


def _plan(moves: list, use, which: int, target: np.ndarray, face) -> None:
    """Record that end ``which`` (0 start, 1 end, along the use) of the oriented edge ``use`` goes to
    ``target``: as an end of the pcurve that use runs on (a seam has one per orientation)."""
    forward = TopoDS.Edge_s(use.Oriented(TopAbs_FORWARD))
    reversed_use = use.Orientation() == TopAbs_REVERSED
    along_curve = 1 - which if reversed_use else which
    orientation = TopAbs_FORWARD
    if BRep_Tool.IsClosed_s(forward, face):      # which of a seam's pcurves: as the forward face stores them
        orientation = TopAbs_REVERSED if reversed_use != (face.Orientation() == TopAbs_REVERSED) else TopAbs_FORWARD
    for known, known_orientation, ends in moves:
        if known.IsSame(forward) and known_orientation == orientation:
            ends[along_curve] = target
            return
    moves.append((forward, orientation, {along_curve: target}))


def _move_ends(forward, orientation, ends: dict, face) -> None:
    """Move ends (0 first, 1 last) of the pcurve of ``forward`` on ``face`` (taken forward) run in
    ``orientation`` to their points ``(2,)``, and store it (with the other pcurve of a seam unchanged)."""
    face = TopoDS.Face_s(face.Oriented(TopAbs_FORWARD))
    use = TopoDS.Edge_s(forward.Oriented(orientation))
    spline = pcurve_spline(use, face)
    if spline is None:
        log.debug("a pcurve that is a conic keeps its ends")
        return
    for along_curve, target in ends.items():
        spline.SetPole(1 if along_curve == 0 else spline.NbPoles(), gp_Pnt2d(*target))
    builder = BRep_Builder()
    tolerance = BRep_Tool.Tolerance_s(forward)
    if BRep_Tool.IsClosed_s(forward, face):
        other = TopAbs_REVERSED if orientation == TopAbs_FORWARD else TopAbs_FORWARD
        kept = BRep_Tool.CurveOnSurface_s(TopoDS.Edge_s(forward.Oriented(other)), face, 0.0, 0.0)
        first, second = (spline, kept) if orientation == TopAbs_FORWARD else (kept, spline)
        builder.UpdateEdge(forward, first, second, face, tolerance)
    else:
        builder.UpdateEdge(forward, spline, face, tolerance)


def widen_tolerances(face, bound: float) -> bool:
    """The second way: let each edge of ``face`` take the tolerance its pcurves need
    (``BRepLib.SameParameter``, forced).  Returns whether every edge stayed within ``bound`` (mm)."""
    within = True
    for edge in edges_of(face, once=True):
        if not BRep_Tool.Degenerated_s(edge):
            BRepLib.SameParameter_s(edge, BRep_Tool.Tolerance_s(edge), True)
            within &= BRep_Tool.Tolerance_s(edge) <= bound
    return within


def fix_faces(shape, faces: list, bound: float):
    """The last way: ``ShapeFix_Face`` on each of ``faces`` (faces of ``shape``), edge tolerances up to
    ``bound`` mm; returns ``shape`` with the faces and edges it replaced in their places (the caller checks
    that they are valid and that no face was split)."""
    reshape = ShapeBuild_ReShape()
    for face in faces:
        fix = ShapeFix_Face(face)
        fix.SetContext(reshape)
        fix.SetPrecision(BRep_Tool.Tolerance_s(face))
        fix.SetMaxTolerance(bound)
        fix.Perform()
    return reshape.Apply(shape)


def mend_face(face, bound: float) -> str | None:
    """Make the converted ``face`` valid, in place: first :func:`close_gaps`, then :func:`widen_tolerances` up
    to ``bound`` (mm).  Returns None when the face is valid (as converted, or mended), else what was tried."""
    if face_valid(face):
        return None
    moved = close_gaps(face)
    if face_valid(face):
        log.debug("converted face mended: %d pcurve ends moved onto their neighbours'", moved)
        return None
    if widen_tolerances(face, bound) and face_valid(face):
        log.debug("converted face mended: %d pcurve ends moved, edge tolerances widened", moved)
        return None
    return f"{moved} pcurve ends moved, edge tolerances widened up to {bound:.3g} mm: still invalid"
