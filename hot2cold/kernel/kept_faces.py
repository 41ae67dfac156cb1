"""The B-spline conversion around the faces it would keep as they are (:func:`convert_around`), for
:mod:`hot2cold.kernel.conversion`.

``BRepBuilderAPI_NurbsConvert`` rebuilds every face one of whose edges it converts and projects each pcurve of a
rebuilt face that is no plane onto its surface anew (``ProjLib_ComputeApproxOnPolarSurface``), a B-spline
surface it keeps as it is included: on parts with many B-spline faces most of its time.  A B-spline face whose
edges are B-splines, lines, circles or ellipses is kept out of it: its pcurves stay as read where the edge's
curve keeps its parameters, and follow the new curve where a conic's conversion changes them.
"""
from __future__ import annotations

import logging
import math

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert
from OCP.BSplCLib import BSplCLib
from OCP.Geom import Geom_BSplineCurve, Geom_BSplineSurface, Geom_Circle, Geom_Ellipse, Geom_Line, Geom_TrimmedCurve
from OCP.Geom2d import Geom2d_BSplineCurve, Geom2d_Line, Geom2d_TrimmedCurve
from OCP.GeomConvert import GeomConvert
from OCP.TColStd import TColStd_Array1OfReal
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_FORWARD, TopAbs_REVERSED, TopAbs_VERTEX
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Compound, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedMapOfShape

from ..core.bspline import clip_uv, evaluate_curve, evaluate_surface, fit_curve
from ..core.footpoint import project_to_surface
from ..errors import KernelError
from .convert import apply_trsf, curve2d_to_record, curve_to_record, record_to_curve2d, surface_to_record
from .explore import edges_of, index_map, reals, shape_map
from .repair import pcurve_spline

log = logging.getLogger(__name__)

TWO_PI = 2 * math.pi


def convert_around(copy: TopoDS_Shape) -> TopoDS_Shape | None:
    """``copy`` converted in place, ``BRepBuilderAPI_NurbsConvert`` run on its faces but those it would keep as
    they are (:func:`_kept`); None if it would keep none (then the whole part is converted at once).

    The faces but the kept ones (and the edges of no face) are converted as a compound, and what the conversion
    made of them (surfaces, edge curves, pcurves, tolerances) is written into ``copy``'s own faces, edges and
    vertices.  A kept face's pcurves along edges whose curves keep their parameters are its pcurves as read made
    B-splines over their edge's range (:func:`~hot2cold.kernel.repair.pcurve_spline`), as
    :func:`~hot2cold.kernel.conversion._keep_pcurves` would have put them back after the conversion projected
    them; along a conic, which the conversion makes a B-spline with other parameters (:func:`_conic_spline`),
    they follow the new curve (:func:`_pcurves_along`; found before the conversion runs: a face where one cannot
    is converted with the others), and the edge's tolerance grows to the distance between the two where that is
    farther.  Raises what the conversion raises, or :class:`KernelError` where the conversion made another curve
    of a conic than :func:`_conic_spline`."""
    faces = shape_map(copy, TopAbs_FACE)
    kept = [_kept(face) for face in faces]
    edge_ids = index_map(copy, TopAbs_EDGE)
    splines, along = {}, {}          # by edge number: a conic's B-spline; by (face, edge): pcurves and distance
    for k, face in enumerate(faces):
        if kept[k]:
            try:
                along.update(_pcurves_along_conics(face, k, edge_ids, splines))
            except (KernelError, ValueError) as exc:         # ValueError: the records' checks on entry
                log.debug("face %d converted with the others: %s", k, exc)
                kept[k] = False
    if not any(kept):
        return None
    builder = BRep_Builder()
    compound = TopoDS_Compound()
    builder.MakeCompound(compound)
    for face, keep in zip(faces, kept):
        if not keep:
            builder.Add(compound, face)
    on_faces = TopTools_IndexedMapOfShape()
    for face in faces:
        for edge in edges_of(face, once=True):
            on_faces.Add(edge)
    for edge in shape_map(copy, TopAbs_EDGE):
        if not on_faces.Contains(edge):             # an edge of no face (a wire in the part): converted too
            builder.Add(compound, edge)
    conversion = BRepBuilderAPI_NurbsConvert(compound, True)
    if not conversion.IsDone():
        raise KernelError("BRepBuilderAPI_NurbsConvert did not finish")
    _take_conversion(conversion, compound, [face for face, keep in zip(faces, kept) if not keep])
    converted_edges = index_map(compound, TopAbs_EDGE)
    for k, face in enumerate(faces):
        if not kept[k]:
            continue
        face = TopoDS.Face_s(face.Oriented(TopAbs_FORWARD))
        for edge in edges_of(face, once=True):
            number = edge_ids.FindIndex(edge)
            if number in splines:
                _take_spline(edge, splines[number], converted_edges.Contains(edge))
            elif not converted_edges.Contains(edge):
                _line_to_spline(edge)
            forward = TopoDS.Edge_s(edge.Oriented(TopAbs_FORWARD))
            tolerance = BRep_Tool.Tolerance_s(edge)
            if (k, number) in along:
                pcurves, gap = along[k, number]
                if gap > tolerance:                 # the curve lies farther from the face: the edge says so
                    tolerance = _TOLERANCE_MARGIN * gap
            else:
                pcurves = [pcurve_spline(use, face) for use in _uses(edge, face)]
            builder.UpdateEdge(forward, *pcurves, face, tolerance)
            for vertex in shape_map(edge, TopAbs_VERTEX):
                if BRep_Tool.Tolerance_s(vertex) < tolerance:
                    builder.UpdateVertex(vertex, tolerance)
    return copy


def _uses(edge, face) -> list:
    """``edge`` forward, and reversed too if it is a seam of ``face``: its uses that have a pcurve each."""
    forward = TopoDS.Edge_s(edge.Oriented(TopAbs_FORWARD))
    if BRep_Tool.IsClosed_s(edge, face):
        return [forward, TopoDS.Edge_s(edge.Oriented(TopAbs_REVERSED))]
    return [forward]


def _pcurves_along_conics(face, k: int, edge_ids, splines: dict) -> dict:
    """Per ``(k, edge number)`` of each edge of ``face`` (face ``k``) along a conic, the pcurves that follow the
    conic's B-spline (:func:`_pcurves_along`, one per use) and their largest distance; the B-splines made on the
    way go into ``splines`` by edge number."""
    face = TopoDS.Face_s(face.Oriented(TopAbs_FORWARD))
    uses, numbers = [], []
    for edge in edges_of(face, once=True):
        conic = None if BRep_Tool.Degenerated_s(edge) else _raw_curve(edge)
        if not isinstance(conic, _CONICS):
            continue
        number = edge_ids.FindIndex(edge)
        if number not in splines:
            splines[number] = _conic_spline(edge)
        for use in _uses(edge, face):
            uses.append((use, conic, splines[number]))
            numbers.append(number)
    out = {}
    for number, (pcurve, gap) in zip(numbers, _pcurves_along(face, uses) if uses else ()):
        pcurves, gaps = out.get((k, number), ([], 0.0))
        out[k, number] = (pcurves + [pcurve], max(gaps, gap))
    return out


def _kept(face) -> bool:
    """Whether the conversion would keep ``face``'s surface as it is: a B-spline surface with a line or a B-spline
    for each pcurve, whose every edge has a B-spline or a line for its curve (the same points at the same
    parameters once converted), a circle or an ellipse over the pcurves' range (other parameters once converted:
    the pcurves along it are made anew, :func:`_pcurves_along`), or none (degenerate)."""
    if not isinstance(BRep_Tool.Surface_s(face, TopLoc_Location()), Geom_BSplineSurface):
        return False
    face = TopoDS.Face_s(face.Oriented(TopAbs_FORWARD))
    for edge in edges_of(face):                  # a seam twice: both its pcurves
        if not isinstance(_basis(BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)),
                          (Geom2d_BSplineCurve, Geom2d_Line)):
            return False
        if BRep_Tool.Degenerated_s(edge):
            continue
        curve = _basis(BRep_Tool.Curve_s(edge, 0.0, 0.0))
        if isinstance(curve, _CONICS):           # its pcurves follow the conic's B-spline: ranges to match
            if not (BRep_Tool.SameRange_s(edge) and BRep_Tool.SameParameter_s(edge)
                    and BRep_Tool.Range_s(edge, face) == BRep_Tool.Range_s(edge)):
                return False
        elif not isinstance(curve, (Geom_BSplineCurve, Geom_Line)):
            return False
    return True


def _basis(curve):
    """The curve a trimmed curve trims, else ``curve`` itself (None stays None)."""
    return curve.BasisCurve() if isinstance(curve, (Geom_TrimmedCurve, Geom2d_TrimmedCurve)) else curve


def _take_conversion(conversion, compound: TopoDS_Compound, faces: list) -> None:
    """Write what ``conversion`` (``BRepBuilderAPI_NurbsConvert`` of ``compound``, made of ``faces``) made of
    them into the faces themselves, their edges and vertices, in place: each face's new surface, each edge's
    new curve and its new pcurves on the faces (both of a seam), and the tolerances where they grew.  All of it
    is read before any of it is written: the new pcurves are found against the new faces."""
    builder = BRep_Builder()
    surfaces, pcurves = [], []
    for face in faces:
        new = conversion.ModifiedShape(face)
        if new.IsSame(face):
            continue
        face = TopoDS.Face_s(face.Oriented(TopAbs_FORWARD))
        new = TopoDS.Face_s(new.Oriented(TopAbs_FORWARD))
        location = TopLoc_Location()
        surfaces.append((face, BRep_Tool.Surface_s(new, location), location, BRep_Tool.Tolerance_s(new)))
        for edge in edges_of(face, once=True):
            forward = TopoDS.Edge_s(edge.Oriented(TopAbs_FORWARD))
            new_edge = TopoDS.Edge_s(conversion.ModifiedShape(edge).Oriented(TopAbs_FORWARD))
            uses = [new_edge, TopoDS.Edge_s(new_edge.Oriented(TopAbs_REVERSED))] \
                if BRep_Tool.IsClosed_s(edge, face) else [new_edge]
            pcurves.append((forward, face, [BRep_Tool.CurveOnSurface_s(use, new, 0.0, 0.0) for use in uses],
                            BRep_Tool.Range_s(new_edge, new), BRep_Tool.Tolerance_s(new_edge)))
    curves = []
    for edge in shape_map(compound, TopAbs_EDGE):
        new = TopoDS.Edge_s(conversion.ModifiedShape(edge).Oriented(TopAbs_FORWARD))
        if new.IsSame(edge) or BRep_Tool.Degenerated_s(edge):
            continue
        location = TopLoc_Location()
        curves.append((TopoDS.Edge_s(edge.Oriented(TopAbs_FORWARD)), BRep_Tool.Curve_s(new, location, 0.0, 0.0),
                       location, BRep_Tool.Range_s(new), (BRep_Tool.SameRange_s(new), BRep_Tool.SameParameter_s(new)),
                       BRep_Tool.Tolerance_s(new)))
    tolerances = [(vertex, BRep_Tool.Tolerance_s(TopoDS.Vertex_s(conversion.ModifiedShape(vertex))))
                  for vertex in shape_map(compound, TopAbs_VERTEX)]
    for face, surface, location, tolerance in surfaces:
        builder.UpdateFace(face, surface, location, max(tolerance, BRep_Tool.Tolerance_s(face)))
    for edge, curve, location, (first, last), (same_range, same_parameter), tolerance in curves:
        builder.UpdateEdge(edge, curve, location, max(tolerance, BRep_Tool.Tolerance_s(edge)))
        builder.Range(edge, first, last, True)
        builder.SameRange(edge, same_range)
        builder.SameParameter(edge, same_parameter)
    for edge, face, uses, (first, last), tolerance in pcurves:
        builder.UpdateEdge(edge, *uses, face, max(tolerance, BRep_Tool.Tolerance_s(edge)))
        builder.Range(edge, face, first, last)
    for vertex, tolerance in tolerances:
        if tolerance > BRep_Tool.Tolerance_s(vertex):
            builder.UpdateVertex(vertex, tolerance)


def _conic_spline(edge) -> Geom_BSplineCurve:
    """The B-spline ``BRepTools_NurbsConvertModification::NewCurve`` makes of ``edge``'s circle or ellipse (in the
    frame of the edge's curve, as :func:`_raw_curve`): of the whole conic where the edge runs once around it from
    within its first period, else of the conic cut to the edge's range, with its knots brought to that range."""
    curve = _raw_curve(edge)
    first, last = BRep_Tool.Range_s(edge)
    tolerance = 0.1 * BRep_Tool.Tolerance_s(edge)
    if abs(abs(last - first) - curve.Period()) <= tolerance and last <= curve.Period():
        return GeomConvert.CurveToBSplineCurve_s(curve)
    spline = GeomConvert.CurveToBSplineCurve_s(Geom_TrimmedCurve(curve, first, last))
    if not spline.IsPeriodic():
        resolution = spline.Resolution(BRep_Tool.Tolerance_s(edge))[0]
        if abs(first - spline.FirstParameter()) > resolution or abs(last - spline.LastParameter()) > resolution:
            knots = TColStd_Array1OfReal(1, spline.NbKnots())
            spline.Knots(knots)
            BSplCLib.Reparametrize_s(first, last, knots)
            spline.SetKnots(knots)
    return spline


def _raw_curve(edge):
    """The curve ``edge`` trims (what a trimmed curve trims), in the frame its location places (not a copy moved
    there, as ``BRep_Tool.Curve`` without a location returns it)."""
    return _basis(BRep_Tool.Curve_s(edge, TopLoc_Location(), 0.0, 0.0))


def _take_spline(edge, spline: Geom_BSplineCurve, converted: bool) -> None:
    """Give ``edge``, in place, ``spline`` (:func:`_conic_spline` of its conic) as its curve; where the conversion
    has ``converted`` it already, check that it made the same B-spline (raises :class:`KernelError` if not)."""
    location = TopLoc_Location()
    curve = BRep_Tool.Curve_s(edge, location, 0.0, 0.0)
    if not converted:
        BRep_Builder().UpdateEdge(TopoDS.Edge_s(edge.Oriented(TopAbs_FORWARD)), spline, location,
                                  BRep_Tool.Tolerance_s(edge))
        return
    if not (isinstance(curve, Geom_BSplineCurve) and curve.NbPoles() == spline.NbPoles()
            and reals(curve.KnotSequence()) == reals(spline.KnotSequence())
            and all(curve.Pole(i).Distance(spline.Pole(i)) <= 1e-12 * (1.0 + spline.Pole(i).XYZ().Modulus())
                    for i in range(1, spline.NbPoles() + 1))):
        raise KernelError("the conversion made another B-spline of a conic than the kept face's pcurves follow")


def _line_to_spline(edge) -> None:
    """Give ``edge``, in place, for a line as its curve a B-spline of degree 1 over the edge's range with the
    line's parameters (so its pcurves stay as they are)."""
    location = TopLoc_Location()
    curve = BRep_Tool.Curve_s(edge, location, 0.0, 0.0)
    if BRep_Tool.Degenerated_s(edge) or not isinstance(_basis(curve), Geom_Line):
        return
    first, last = BRep_Tool.Range_s(edge)
    spline = GeomConvert.CurveToBSplineCurve_s(Geom_TrimmedCurve(_basis(curve), first, last))
    BRep_Builder().UpdateEdge(TopoDS.Edge_s(edge.Oriented(TopAbs_FORWARD)), spline, location,
                              BRep_Tool.Tolerance_s(edge))


#: An edge whose curve lies farther from a kept face than its tolerance takes this many times that distance.
_TOLERANCE_MARGIN = 1.05
#: The conics whose conversion changes their parameters.
_CONICS = (Geom_Circle, Geom_Ellipse)
#: How far (share of the edge's tolerance) a pcurve along a converted conic may leave, on its surface, the foot
#: points of the new curve it is fitted to.
_ALONG_SHARE = 0.1
#: How far (share of the surface's parameter box) a foot point that did not settle may lie from its start.
_ALONG_NEAR = 1e-3
#: Pieces of each span of the new curve, tried in turn until a fit stays that close; the fit's degree.
_ALONG_PIECES = (2, 4, 8, 16)
_ALONG_DEGREE = 7


class _Along:
    """One edge use on a kept face along a conic, the pcurve :func:`_pcurves_along` makes for it: ``use`` the
    oriented edge, ``conic`` its circle or ellipse as read, ``curve`` the B-spline the conversion makes of it
    (the same range, other parameters: ``curve(t) = conic(mu(t))``), ``record`` and ``into_surface`` the face's
    surface and the placement of the edge's curve in its frame."""

    def __init__(self, use, face, conic, curve, record, into_surface):
        self.first, self.last = BRep_Tool.Range_s(use, face)
        self.read = curve2d_to_record(pcurve_spline(use, face))
        self.slack = _ALONG_SHARE * BRep_Tool.Tolerance_s(use)
        if curve.IsPeriodic():
            curve = curve.Copy()
            curve.SetNotPeriodic()
        self.spline = curve_to_record(curve)
        frame = (conic.Circ() if isinstance(conic, Geom_Circle) else conic.Elips()).Position()
        self.frame = [np.array([p.X(), p.Y(), p.Z()]) for p in (frame.Location(), frame.XDirection(),
                                                                 frame.YDirection())]
        self.radii = ((conic.Radius(),) * 2 if isinstance(conic, Geom_Circle)
                      else (conic.MajorRadius(), conic.MinorRadius()))
        self.record, self.into_surface = record, into_surface
        knots = np.unique(self.spline.knots)
        self.ends = np.r_[self.first, knots[(knots > self.first) & (knots < self.last)], self.last]

    def mu(self, t: np.ndarray) -> np.ndarray:
        """The conic's parameters ``(m,)`` of the new curve's points at ``t (m,)``."""
        origin, x_axis, y_axis = self.frame
        offsets = evaluate_curve(self.spline, t) - origin
        at = np.arctan2(offsets @ y_axis / self.radii[1], offsets @ x_axis / self.radii[0])
        return at + TWO_PI * np.round((t - at) / TWO_PI)

    def samples(self, pieces: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """With each span of the new curve cut into ``pieces``: the knots of the fit, the parameters ``t (m,)``
        fitted (``_ALONG_DEGREE + 1`` a piece), the curve's points there and midway between them ``(2m - 1, 3)``
        in the surface's frame, and the pcurve as read at the conic's parameters of those ``(2m - 1, 2)``."""
        degree = _ALONG_DEGREE
        cuts = np.concatenate([np.linspace(a, b, pieces + 1)[:-1] for a, b in zip(self.ends[:-1], self.ends[1:])]
                              + [self.ends[-1:]])
        inner = cuts[1:-1]            # mu is C1 where the spans meet
        knots = np.r_[np.full(degree + 1, self.first),
                      np.repeat(inner, np.where(np.isin(inner, self.ends), degree - 1, 1)),
                      np.full(degree + 1, self.last)]
        t = np.concatenate([np.linspace(a, b, degree + 2)[:-1] for a, b in zip(cuts[:-1], cuts[1:])]
                           + [self.ends[-1:]])
        at = np.r_[t, (t[1:] + t[:-1]) / 2]          # midway between the points fitted, where a fit strays
        points = apply_trsf(evaluate_curve(self.spline, at), self.into_surface)
        return knots, t, points, clip_uv(self.record, evaluate_curve(self.read, self.mu(at))[:, :2])

    def fit(self, knots, t, uv, gaps) -> tuple[Geom2d_BSplineCurve, float] | None:
        """The fit to the foot points ``uv (2m - 1, 2)`` at :meth:`samples`' parameters, and the largest distance
        ``gaps`` between; None if it strays farther than its slack between the points fitted."""
        fitted = fit_curve(t, np.c_[uv[:len(t)], np.zeros(len(t))], knots, _ALONG_DEGREE)
        between = (t[1:] + t[:-1]) / 2
        on = clip_uv(self.record, evaluate_curve(fitted, between)[:, :2])
        feet = uv[len(t):]
        stray = evaluate_surface(self.record, on[:, 0], on[:, 1]) - evaluate_surface(self.record, feet[:, 0],
                                                                                       feet[:, 1])
        if np.sqrt(np.einsum("ij,ij->i", stray, stray)).max() > self.slack:
            return None
        return record_to_curve2d(fitted), float(gaps[len(t):].max())


def _pcurves_along(face, uses: list) -> list[tuple[Geom2d_BSplineCurve, float]]:
    """For each ``(use, conic, curve)`` of ``uses`` on ``face``: the pcurve of the oriented edge ``use`` once its
    curve, the circle or ellipse ``conic`` as read, is the B-spline ``curve`` the conversion makes of it (the
    same range, other parameters: ``curve(t) = conic(mu(t))``), and the largest distance, between the points
    fitted, from ``curve`` to the face along it.

    As the conversion's own projection does, the pcurve follows the foot points of ``curve`` on the surface;
    they are found by Newton's method (:func:`~hot2cold.core.footpoint.project_to_surface`, the face's uses at
    once) from the pcurve as read at ``mu(t)``, where the conversion approximates the projection from scratch
    (the pcurve as read stays where a foot point does not settle and runs off from there, and where all of a
    use's lie within a hundredth of the edge's tolerance of the curve), and fitted
    (:func:`~hot2cold.core.bspline.fit_curve`, degree ``_ALONG_DEGREE``) with breakpoints where ``curve``'s
    spans meet (``mu`` is C1 there), each span cut into ``_ALONG_PIECES`` pieces in turn until the fit stays
    within ``_ALONG_SHARE`` of the edge's tolerance of the foot points midway between those it was fitted to;
    raises :class:`KernelError` if none does, or on a periodic surface."""
    face_location = TopLoc_Location()
    surface = BRep_Tool.Surface_s(face, face_location)
    if surface.IsUPeriodic() or surface.IsVPeriodic():
        raise KernelError("a periodic surface along a conic")
    record = surface_to_record(surface)
    box = np.array(record.domain)
    alongs = []
    for use, conic, curve in uses:
        curve_location = TopLoc_Location()
        BRep_Tool.Curve_s(use, curve_location, 0.0, 0.0)
        into_surface = face_location.Transformation().Inverted().Multiplied(curve_location.Transformation())
        alongs.append(_Along(use, face, conic, curve, record, into_surface))
    out = [None] * len(alongs)
    for pieces in _ALONG_PIECES:
        todo = [i for i, o in enumerate(out) if o is None]
        if not todo:
            return out
        asked = [alongs[i].samples(pieces) for i in todo]
        points = np.concatenate([a[2] for a in asked])
        start = np.concatenate([a[3] for a in asked])
        start_gaps = np.linalg.norm(evaluate_surface(record, start[:, 0], start[:, 1]) - points, axis=1)
        sizes = np.cumsum([0] + [len(a[2]) for a in asked])
        on_curve = np.concatenate([np.full(len(a[2]), start_gaps[b:c].max() <= _ALONG_SHARE * alongs[i].slack)
                                   for i, a, b, c in zip(todo, asked, sizes[:-1], sizes[1:])])
        uv, gaps = start.copy(), start_gaps.copy()      # the pcurve as read where it lies on the curve
        ask = np.flatnonzero(~on_curve)
        if len(ask):
            found = project_to_surface(record, points[ask], start[ask])
            # a foot point that did not settle slid along a border of the box to its nearest point there, or
            # ran off along a side the surface shrinks to a point (any u the same point) or got lost: taken if
            # it stayed near its start and is no farther, else the pcurve as read is
            near = np.all(np.abs(found.uv - start[ask]) <= _ALONG_NEAR * (box[[1, 3]] - box[[0, 2]]), axis=1)
            take = found.settled | (near & (found.distance <= start_gaps[ask]))
            uv[ask[take]], gaps[ask[take]] = found.uv[take], found.distance[take]
        for i, (knots, t, _, _), b, c in zip(todo, asked, sizes[:-1], sizes[1:]):
            out[i] = alongs[i].fit(knots, t, uv[b:c], gaps[b:c])
    if any(o is None for o in out):
        slack = min(alongs[i].slack for i, o in enumerate(out) if o is None)
        raise KernelError(f"no pcurve within {slack:.3g} mm of the foot points of a converted conic")
    return out
