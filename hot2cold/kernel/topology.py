"""Decomposing a solid into B-spline faces, shared edges and vertices.

The input is converted to B-spline form (planes, cylinders, cones, tori, fillets and surfaces of revolution
included) with ``BRepBuilderAPI_NurbsConvert`` and copied: ``hot`` is the converted part, ``work`` its copy
whose faces and edges the morph projects onto; neither is changed by the morph, whose rebuild
(:mod:`hot2cold.kernel.rebuild`) writes the cold geometry into a further copy of ``work``.  Every face keeps
its edges by reference, so the two faces of a shared edge see the very same edge before and after the
morph: this is what keeps the cold solid watertight.

Geometry is normalised so that the numeric core can treat it uniformly: periodic surfaces and curves become
non-periodic, and every surface and edge curve is clamped (end poles on the boundary); an edge curve is
cut to the edge's range, so its end poles are its vertices (the premise of eq. 10).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from OCP.Bnd import Bnd_Box
from OCP.BRep import BRep_Tool
from OCP.BRepBndLib import BRepBndLib
from OCP.BRep import BRep_Builder
from OCP.BRepBuilderAPI import BRepBuilderAPI_Copy, BRepBuilderAPI_NurbsConvert
from OCP.BRepTools import BRepTools
from OCP.Geom import Geom_BSplineCurve, Geom_BSplineSurface
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_FORWARD, TopAbs_REVERSED, TopAbs_SOLID, TopAbs_VERTEX
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedMapOfShape
from OCP.gp import gp_Vec2d

from ..errors import InputError, KernelError
from ..core.model import Edge, EdgeUse, Face, Part
from .convert import curve_to_record, surface_to_record
from .faults import describe_face, face_faults, face_label, solid_faults
from .repair import face_valid, mend_face

log = logging.getLogger(__name__)


@dataclass(eq=False)
class KernelPart:
    """The kernel side of a :class:`~hot2cold.core.model.Part` (opaque to the numeric core), as loaded: the morph
    does not change it (the cold part is a :class:`~hot2cold.kernel.rebuild.ColdKernel`).

    ``faces``, ``edges`` and ``vertices`` are shapes of ``work`` in the part's numbering; ``surfaces`` and
    ``curves`` are their geometry handles with the location that places them (``None`` for degenerate
    edges).  ``hot_faces`` and ``hot_edges`` are the same shapes in ``hot``.
    """

    source: TopoDS_Shape
    hot: TopoDS_Shape
    work: TopoDS_Shape
    faces: list
    edges: list
    vertices: list
    surfaces: list
    curves: list
    hot_faces: list
    hot_edges: list


def shape_map(shape: TopoDS_Shape, kind) -> list:
    """Sub-shapes of ``kind`` in ``TopExp.MapShapes`` order, 0-based: the project's numbering."""
    m = index_map(shape, kind)
    cast = {TopAbs_FACE: TopoDS.Face_s, TopAbs_EDGE: TopoDS.Edge_s, TopAbs_VERTEX: TopoDS.Vertex_s,
            TopAbs_SOLID: TopoDS.Solid_s}[kind]
    return [cast(m.FindKey(i)) for i in range(1, m.Size() + 1)]


def index_map(shape: TopoDS_Shape, kind) -> TopTools_IndexedMapOfShape:
    """The kernel's indexed map of the sub-shapes of ``kind`` (1-based; ``FindIndex`` gives k + 1)."""
    m = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, kind, m)
    return m


def _clamped(knots: list[float], degree: int) -> bool:
    return (all(k == knots[0] for k in knots[:degree + 1])
            and all(k == knots[-1] for k in knots[-degree - 1:]))


def _normalise_surface(surface: Geom_BSplineSurface) -> None:
    """Make a face's surface non-periodic and clamped, in place, without changing its geometry."""
    if surface.IsUPeriodic():
        surface.SetUNotPeriodic()
    if surface.IsVPeriodic():
        surface.SetVNotPeriodic()
    uk = list(surface.UKnotSequence())
    vk = list(surface.VKnotSequence())
    if not (_clamped(uk, surface.UDegree()) and _clamped(vk, surface.VDegree())):
        u0, u1, v0, v1 = surface.Bounds()
        surface.Segment(u0, u1, v0, v1)


def _normalise_curve(curve: Geom_BSplineCurve, first: float, last: float) -> None:
    """Make an edge's curve non-periodic, clamped and exactly the edge's range, in place."""
    if curve.IsPeriodic():
        curve.SetNotPeriodic()
    knots = list(curve.KnotSequence())
    if (not _clamped(knots, curve.Degree()) or curve.FirstParameter() != first
            or curve.LastParameter() != last):
        curve.Segment(first, last)


def bspline_surface(face) -> tuple[Geom_BSplineSurface, object]:
    """The face's own ``Geom_BSplineSurface`` (not a copy) and the ``gp_Trsf`` that places it."""
    loc = TopLoc_Location()
    surface = BRep_Tool.Surface_s(face, loc)
    if not isinstance(surface, Geom_BSplineSurface):
        raise KernelError(f"face surface is a {surface.DynamicType().Name()} after B-spline conversion")
    return surface, loc.Transformation()


def bspline_curve(edge) -> tuple[Geom_BSplineCurve, object]:
    """The edge's own ``Geom_BSplineCurve`` (not a copy) and the ``gp_Trsf`` that places it."""
    loc = TopLoc_Location()
    curve = BRep_Tool.Curve_s(edge, loc, 0.0, 0.0)
    if not isinstance(curve, Geom_BSplineCurve):
        name = "no curve" if curve is None else curve.DynamicType().Name()
        raise KernelError(f"edge curve is {name} after B-spline conversion")
    return curve, loc.Transformation()


def diagonal(shape: TopoDS_Shape) -> float:
    """Bounding-box diagonal of ``shape`` in mm."""
    box = Bnd_Box()
    BRepBndLib.Add_s(shape, box, False)
    if box.IsVoid():
        raise KernelError("the part has an empty bounding box")
    x0, y0, z0, x1, y1, z1 = box.Get()
    return float(np.linalg.norm([x1 - x0, y1 - y0, z1 - z0]))


def _edge_parameters(curve_record, per_span: int) -> np.ndarray:
    """Parameters ``(m,)`` on an edge curve: ``per_span`` intervals in every knot span, ends included."""
    breaks = np.unique(curve_record.knots[curve_record.degree:curve_record.n_poles + 1])
    pieces = [np.linspace(a, b, per_span + 1)[:-1] for a, b in zip(breaks[:-1], breaks[1:])]
    return np.concatenate(pieces + [breaks[-1:]])


def _convert(shape: TopoDS_Shape) -> TopoDS_Shape:
    """``shape`` with every surface and curve in B-spline form (``BRepBuilderAPI_NurbsConvert``); a failure
    names the solid and face it fails on (each face converted alone to find it), with its surface type and a
    point on it."""
    try:
        converter = BRepBuilderAPI_NurbsConvert(shape, True)
        converted = converter.Shape()
    except Exception as exc:  # Standard_Failure
        failure = exc
    else:
        size = diagonal(shape)
        faces = shape_map(shape, TopAbs_FACE)
        for k, face in enumerate(faces):
            surface = BRep_Tool.Surface_s(face)
            if surface.DynamicType().Name() == "Geom_OffsetSurface":
                _tighten_offset(surface, TopoDS.Face_s(converter.ModifiedShape(face)), _OFFSET_TOLERANCE * size)
        for k, (face, converted_face) in enumerate(zip(faces, shape_map(converted, TopAbs_FACE))):
            _mend(face, converted_face, k, _MEND_TOLERANCE * size)
        return converted
    faces = index_map(shape, TopAbs_FACE)
    for s, solid in enumerate(shape_map(shape, TopAbs_SOLID)):
        for face in shape_map(solid, TopAbs_FACE):
            try:
                BRepBuilderAPI_NurbsConvert(face, True)
            except Exception as exc:  # Standard_Failure
                raise KernelError(f"B-spline conversion of solid {s} failed at "
                                  f"{describe_face(face, faces.FindIndex(face) - 1)}: {exc}") from exc
    raise KernelError(f"B-spline conversion of the part failed (on no face alone): {failure}") from failure


#: The largest edge tolerance (share of the part's diagonal) that mending a converted face may give an edge.
_MEND_TOLERANCE = 1e-7


def _mend(face, converted_face, index: int, bound: float) -> None:
    """Mend, in place, ``converted_face`` (the conversion of ``face``, numbered ``index``) where it is invalid
    and ``face`` as read is valid (:func:`hot2cold.kernel.repair.mend_face`); a face that stays invalid raises
    :class:`KernelError` naming it, its surface type as read, a point on it and what BRepCheck says."""
    if face_valid(converted_face) or not face_valid(face):
        return
    failed = mend_face(converted_face, bound)
    if failed:
        faults = face_faults(converted_face)
        raise KernelError(f"B-spline conversion broke {describe_face(face, index)}: {faults or 'invalid'} "
                          f"({failed})")


#: Offset surfaces are approximated to this share of the part's diagonal.  ``BRepBuilderAPI_NurbsConvert``
#: approximates them to about 1e-6 of their size (a build123d hull's offset faces: 4.0e-6 mm off, one
#: Bezier patch of degree 7), and a morph exact on the converted part is then that far off the part.
_OFFSET_TOLERANCE = 1e-11
#: Largest degree and number of spans per direction of that approximation; one that misses its tolerance by
#: more than ``_OFFSET_ACCEPT`` times is not taken.
_OFFSET_DEGREE, _OFFSET_SPANS, _OFFSET_ACCEPT = 9, 200, 1e3


def _tighten_offset(offset, face, tolerance: float) -> None:
    """Replace, in place, the poles of ``face``'s surface (the B-spline ``BRepBuilderAPI_NurbsConvert`` made of
    the offset surface ``offset`` over the face's parameter box) by those of a closer approximation over the
    same box, to ``tolerance`` (mm) if it gets there, and fit the tolerances of the face's edges to it.

    In place, so that the face keeps its pcurves: both surfaces are brought to one degree and one knot vector
    (degree elevation and knot insertion, which change no shape), and the poles (and unit weights) of the
    close one are set on the converted one.  Both approximate ``offset`` over its parameters, so the pcurves
    stay where they were.  A periodic surface, or an approximation that does not get close, is left as it
    was."""
    from OCP.BRepLib import BRepLib
    from OCP.Geom import Geom_RectangularTrimmedSurface
    from OCP.GeomAbs import GeomAbs_C2
    from OCP.GeomConvert import GeomConvert_ApproxSurface

    converted = bspline_surface(face)[0]
    if converted.IsUPeriodic() or converted.IsVPeriodic():
        return
    piece = Geom_RectangularTrimmedSurface(offset, *converted.Bounds())
    approx = GeomConvert_ApproxSurface(piece, tolerance, GeomAbs_C2, GeomAbs_C2, _OFFSET_DEGREE, _OFFSET_DEGREE,
                                       _OFFSET_SPANS, 1)
    if not approx.HasResult() or approx.MaxError() > _OFFSET_ACCEPT * tolerance:
        log.debug("offset surface: no close approximation; kept the conversion")
        return
    close = approx.Surface()
    du, dv = max(close.UDegree(), converted.UDegree()), max(close.VDegree(), converted.VDegree())
    close.IncreaseDegree(du, dv)
    converted.IncreaseDegree(du, dv)
    for a, b in ((close, converted), (converted, close)):
        for k in range(1, a.NbUKnots() + 1):
            b.InsertUKnot(a.UKnot(k), a.UMultiplicity(k), 1e-12, False)
        for k in range(1, a.NbVKnots() + 1):
            b.InsertVKnot(a.VKnot(k), a.VMultiplicity(k), 1e-12, False)
    if (close.NbUPoles(), close.NbVPoles()) != (converted.NbUPoles(), converted.NbVPoles()):
        log.debug("offset surface: the two B-splines did not reach one knot vector; kept the conversion")
        return
    for i in range(1, close.NbUPoles() + 1):
        for j in range(1, close.NbVPoles() + 1):
            converted.SetPole(i, j, close.Pole(i, j), 1.0)
    for edge in shape_map(face, TopAbs_EDGE):
        BRepLib.SameParameter_s(edge, 1e-7, True)
    log.debug("offset surface approximated to %.3g mm with %d x %d poles", approx.MaxError(), close.NbUPoles(),
              close.NbVPoles())


def _into_first_period(face, surface: Geom_BSplineSurface, index: int) -> None:
    """Bring ``face``'s parameters into its periodic surface's first period, in place, before the surface is
    made non-periodic (which keeps only that period).

    A periodic direction whose face parameters lie a whole number of periods away (a torus face of an
    Autodesk export runs over u 5.34 to 11.63 on a surface of 0 to 2 pi) has the face's pcurves moved by those
    periods; one that straddles the period's end has the surface's origin set where the face begins (a knot
    inserted there, the geometry unchanged), so that one period holds the whole face.  ``index`` numbers the face
    in a message.
    """
    bounds = BRepTools.UVBounds_s(face)
    shift = [0.0, 0.0]
    for d, (periodic, lo, hi) in enumerate(((surface.IsUPeriodic(), *bounds[:2]),
                                            (surface.IsVPeriodic(), *bounds[2:]))):
        if not periodic:
            continue
        first, last = surface.Bounds()[2 * d:2 * d + 2]
        period = last - first
        tol = 1e-9 * period
        if lo >= first - tol and hi <= last + tol:
            continue
        if hi - lo > period * (1 + 1e-7):    # pcurves overshooting a whole turn: clipped to the domain later
            log.debug("face %d runs over %.6g in %s, more than its surface's period %.6g", index, hi - lo, "uv"[d],
                      period)
            continue
        turns = np.floor((lo - first + tol) / period)
        shift[d] = -turns * period
        start = lo + shift[d]
        if hi + shift[d] > last + tol:     # straddles the end of the period: start the period at the face
            _set_origin(surface, d, start, tol)
    if shift != [0.0, 0.0]:
        _move_pcurves(face, gp_Vec2d(*shift))


def _set_origin(surface: Geom_BSplineSurface, d: int, at: float, tol: float) -> None:
    """Make ``at`` the first parameter of the periodic direction ``d`` of ``surface`` (same geometry)."""
    if d == 0:
        surface.InsertUKnot(at, 1, tol, True)
        knots = list(surface.UKnots())
    else:
        surface.InsertVKnot(at, 1, tol, True)
        knots = list(surface.VKnots())
    index = int(np.argmin(np.abs(np.asarray(knots) - at))) + 1
    if d == 0:
        surface.SetUOrigin(index)
    else:
        surface.SetVOrigin(index)


def _move_pcurves(face, by: gp_Vec2d) -> None:
    """Translate the pcurves of every edge of ``face`` on it by ``by`` (both of a seam), in place."""
    builder = BRep_Builder()
    done = TopTools_IndexedMapOfShape()
    explorer = TopExp_Explorer(face, TopAbs_EDGE)
    while explorer.More():
        edge = TopoDS.Edge_s(explorer.Current())
        explorer.Next()
        if done.Contains(edge):
            continue
        done.Add(edge)
        tol = BRep_Tool.Tolerance_s(edge)
        forward = TopoDS.Edge_s(edge.Oriented(TopAbs_FORWARD))
        first = BRep_Tool.CurveOnSurface_s(forward, face, 0.0, 0.0).Copy()
        first.Translate(by)
        if BRep_Tool.IsClosed_s(edge, face):
            second = BRep_Tool.CurveOnSurface_s(TopoDS.Edge_s(edge.Oriented(TopAbs_REVERSED)), face, 0.0, 0.0).Copy()
            second.Translate(by)
            builder.UpdateEdge(forward, first, second, face, tol)
        else:
            builder.UpdateEdge(forward, first, face, tol)


def _open(solid) -> bool:
    """Whether ``solid`` has free edges (an open shell, which BRepCheck refuses too)."""
    from .validity import free_edges     # validity builds on this module

    return free_edges(solid) > 0


def _refuse_broken(shape: TopoDS_Shape) -> None:
    """Raise :class:`InputError` naming the first face at fault of the first solid of ``shape`` that the kernel
    finds invalid as given; nothing when every solid is valid."""
    message = broken_solid(shape)
    if message:
        raise InputError(message)


def broken_solid(shape: TopoDS_Shape) -> str | None:
    """"hot solid S is not valid: face F (Plane, near (x, y, z) mm): <BRepCheck statuses>" for the first solid of
    ``shape`` that ``BRepCheck_Analyzer`` refuses, or None when every solid is valid."""
    for s, solid in enumerate(shape_map(shape, TopAbs_SOLID)):
        if _open(solid):     # named as open by check_hot
            continue
        faults = solid_fault(shape, s)
        if faults:
            return f"hot solid {s} is not valid: {faults}"
    return None


def solid_fault(shape: TopoDS_Shape, s: int) -> str | None:
    """What ``BRepCheck_Analyzer`` finds wrong with solid ``s`` of ``shape``: "face F (Plane, near (x, y, z) mm):
    <statuses>" for the first face at fault, "(and N more)" for the others; None when the solid is valid.
    Faces are numbered as in ``shape``."""
    faces = index_map(shape, TopAbs_FACE)
    solid = shape_map(shape, TopAbs_SOLID)[s]
    faults = solid_faults(solid, [(faces.FindIndex(f) - 1, f) for f in shape_map(solid, TopAbs_FACE)])
    if not faults:
        return None
    return f"{faults[0]}" + (f" (and {len(faults) - 1} more)" if len(faults) > 1 else "")


def decompose(shape: TopoDS_Shape, samples_per_span: int = 4) -> Part:
    """Decompose ``shape`` (a solid or a compound of solids) into a :class:`~hot2cold.core.model.Part`.

    ``samples_per_span`` sets how densely each edge's pcurve is sampled in every knot span of its curve.
    """
    solids = shape_map(shape, TopAbs_SOLID)
    if not solids:
        raise KernelError("the shape holds no solid")
    try:
        hot = _convert(shape)
        # Normalise the hot copy's geometry, then copy it: hot and work share parameterisations exactly.
        for k, face in enumerate(shape_map(hot, TopAbs_FACE)):
            surface = bspline_surface(face)[0]
            _into_first_period(face, surface, k)
            _normalise_surface(surface)
    except KernelError:
        _refuse_broken(shape)     # a broken input is named as such, not as a failure of the conversion
        raise
    for edge in shape_map(hot, TopAbs_EDGE):
        if not BRep_Tool.Degenerated_s(edge):
            first, last = BRep_Tool.Range_s(edge)
            _normalise_curve(bspline_curve(edge)[0], first, last)
    work = BRepBuilderAPI_Copy(hot, True, False).Shape()

    faces = shape_map(work, TopAbs_FACE)
    edges = shape_map(work, TopAbs_EDGE)
    vertices = shape_map(work, TopAbs_VERTEX)
    face_ids = index_map(work, TopAbs_FACE)
    edge_ids = index_map(work, TopAbs_EDGE)
    vertex_ids = index_map(work, TopAbs_VERTEX)

    vertex_points = np.array([[p.X(), p.Y(), p.Z()] for p in (BRep_Tool.Pnt_s(v) for v in vertices)])

    curves, edge_records = [], []
    for edge in edges:
        if BRep_Tool.Degenerated_s(edge):
            curves.append(None)
            edge_records.append(None)
            continue
        curve, trsf = bspline_curve(edge)
        curves.append((curve, trsf))
        edge_records.append(curve_to_record(curve, trsf))

    edge_faces: list[list[int]] = [[] for _ in edges]
    surfaces, face_records = [], []
    for k, face in enumerate(faces):
        surface, trsf = bspline_surface(face)
        surfaces.append((surface, trsf))
        record = surface_to_record(surface, trsf)
        u_lo, u_hi, v_lo, v_hi = record.domain
        uses = []
        explorer = TopExp_Explorer(face, TopAbs_EDGE)
        while explorer.More():
            edge = TopoDS.Edge_s(explorer.Current())
            e = edge_ids.FindIndex(edge) - 1
            if k not in edge_faces[e]:
                edge_faces[e].append(k)
            first, last = BRep_Tool.Range_s(edge, face)
            if edge_records[e] is not None:
                t = _edge_parameters(edge_records[e], samples_per_span)
            else:
                t = np.linspace(first, last, 2 * samples_per_span + 1)
            pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
            if pcurve is None:
                raise KernelError(f"edge {e} of face {k} has no curve on the face")
            # pcurves of boolean results may overshoot the surface's domain by a hair: clip to it
            uv = np.array([[p.X(), p.Y()] for p in (pcurve.Value(float(x)) for x in t)])
            uv = np.clip(uv, [u_lo, v_lo], [u_hi, v_hi])
            uses.append(EdgeUse(edge=e, t=t, uv=uv))
            explorer.Next()
        box = np.array(BRepTools.UVBounds_s(face))
        box = np.clip(box, [u_lo, u_lo, v_lo, v_lo], [u_hi, u_hi, v_hi, v_hi])
        face_records.append((record, box, tuple(uses)))

    solid_of_face = np.full(len(faces), -1)
    solid_faces = []
    for s, solid in enumerate(shape_map(work, TopAbs_SOLID)):     # work's solids: its faces are numbered
        members = tuple(face_ids.FindIndex(f) - 1 for f in shape_map(solid, TopAbs_FACE))
        solid_faces.append(members)
        solid_of_face[list(members)] = s

    edge_list = []
    for e, edge in enumerate(edges):
        forward = edge.Oriented(TopAbs_FORWARD)
        v0 = vertex_ids.FindIndex(TopExp.FirstVertex_s(TopoDS.Edge_s(forward))) - 1
        v1 = vertex_ids.FindIndex(TopExp.LastVertex_s(TopoDS.Edge_s(forward))) - 1
        edge_list.append(Edge(index=e, curve=edge_records[e], vertices=(v0, v1), faces=tuple(edge_faces[e])))

    face_list = [Face(index=k, surface=rec, uv_box=box, uses=uses, solid=int(solid_of_face[k]))
                 for k, (rec, box, uses) in enumerate(face_records)]
    kernel = KernelPart(source=shape, hot=hot, work=work, faces=faces, edges=edges, vertices=vertices,
                        surfaces=surfaces, curves=curves, hot_faces=shape_map(hot, TopAbs_FACE),
                        hot_edges=shape_map(hot, TopAbs_EDGE))
    log.info("decomposed %d solid(s): %d faces, %d edges, %d vertices",
             len(solids), len(faces), len(edges), len(vertices))
    source_faces = shape_map(shape, TopAbs_FACE)       # as read: its planes are planes yet
    labels = tuple(face_label(f) for f in source_faces) if len(source_faces) == len(faces) else ()
    return Part(faces=face_list, edges=edge_list, vertices=vertex_points, solids=solid_faces,
                diagonal=diagonal(shape), kernel=kernel, face_labels=labels)
