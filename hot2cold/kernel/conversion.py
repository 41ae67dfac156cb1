"""The part in B-spline form, as the numeric core takes it: every face's surface a clamped, non-periodic
B-spline over its face's parameters, every edge's curve a clamped B-spline cut to the edge (its end poles are
its vertices: the premise of eq. 10).

:func:`to_bspline` works on a copy (``BRepBuilderAPI_NurbsConvert`` shares B-spline geometry with its input, and
the normalisation here changes that geometry in place: the part as read stays as read).  On the copy, a face on
a cylinder, cone, sphere or torus that runs outside the first turn of its surface (u from pi to 3 pi, or from
-pi to pi) has its surface's frame turned to where it begins (:func:`_turn_to_face`), so that the conversion
sees it from 0; then every surface and curve is converted, the B-spline faces whose surfaces the conversion
keeps left out of it (:func:`~hot2cold.kernel.kept_faces.convert_around`: it would project all their pcurves
anew, the most of its time), offset surfaces approximated closely (:func:`_tighten_offset`), the pcurves as read
put back where the conversion kept the parameters of surface and curve yet projected them anew
(:func:`_keep_pcurves`; with those faces left out, only where a face could not be), and each converted face that
the conversion broke while the face as read is valid is mended (:mod:`hot2cold.kernel.repair`) or named in a
:class:`~hot2cold.errors.KernelError`.  Last, periodic B-splines are brought to the period that holds their
face (:func:`_into_first_period`) and made non-periodic and clamped.
"""
from __future__ import annotations

import logging
import math
from typing import NoReturn

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepBuilderAPI import BRepBuilderAPI_Copy, BRepBuilderAPI_NurbsConvert
from OCP.BRepTools import BRepTools
from OCP.Geom import (Geom_BSplineCurve, Geom_BSplineSurface, Geom_ConicalSurface, Geom_CylindricalSurface,
                      Geom_Plane, Geom_SphericalSurface, Geom_ToroidalSurface)
from OCP.Geom2d import Geom2d_BSplineCurve
from OCP.gp import gp_Ax3, gp_Dir, gp_Vec2d
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_FORWARD, TopAbs_REVERSED, TopAbs_SOLID
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Shape

from ..errors import KernelError
from .explore import bspline_curve, bspline_surface, diagonal, edges_of, index_map, reals, shape_map
from .faults import describe_face, face_faults
from .kept_faces import convert_around
from .repair import face_valid, fix_faces, mend_face, pcurve_spline

log = logging.getLogger(__name__)

TWO_PI = 2 * math.pi


def to_bspline(shape: TopoDS_Shape) -> TopoDS_Shape:
    """A copy of ``shape`` (a solid or a compound of solids) in normalised B-spline form (see the module); raises
    :class:`KernelError` naming the solid or face the conversion fails on or breaks beyond mending."""
    hot = _convert(shape, _turned_copy(shape))
    for k, face in enumerate(shape_map(hot, TopAbs_FACE)):
        surface = bspline_surface(face)[0]
        _into_first_period(face, surface, k)
        _normalise_surface(surface)
    for edge in shape_map(hot, TopAbs_EDGE):
        if not BRep_Tool.Degenerated_s(edge):
            first, last = BRep_Tool.Range_s(edge)
            _normalise_curve(bspline_curve(edge)[0], first, last)
    BRepTools.RemoveUnusedPCurves_s(hot)
    return hot


def _turned_copy(shape: TopoDS_Shape) -> TopoDS_Shape:
    """A copy of ``shape``, geometry included, with its faces turned to begin at 0 (:func:`_turn_to_face`)."""
    copy = BRepBuilderAPI_Copy(shape, True, False).Shape()
    for k, face in enumerate(shape_map(copy, TopAbs_FACE)):
        _turn_to_face(face, k)
    return copy


def _convert(shape: TopoDS_Shape, copy: TopoDS_Shape) -> TopoDS_Shape:
    """``copy`` (of ``shape``, as read) with every surface and curve in B-spline form
    (``BRepBuilderAPI_NurbsConvert``, around the faces it would keep:
    :func:`~hot2cold.kernel.kept_faces.convert_around`; where that fails, the whole part at once on a new copy),
    offset surfaces approximated closely and the faces it broke mended; a failure names the solid and face it
    fails on (:func:`_refuse`)."""
    try:
        converted = convert_around(copy)
    except Exception as exc:  # Standard_Failure, KernelError: the whole part converted at once instead
        log.debug("converting around the kept faces failed (%s): the whole part converted at once", exc)
        converted, copy = None, _turned_copy(shape)
    if converted is None:
        try:
            converted = BRepBuilderAPI_NurbsConvert(copy, True).Shape()
        except Exception as exc:  # Standard_Failure
            _refuse(shape, copy, exc)
    size = diagonal(shape)
    faces = shape_map(shape, TopAbs_FACE)
    converted_faces = shape_map(converted, TopAbs_FACE)
    for face, converted_face in zip(faces, converted_faces):
        surface = BRep_Tool.Surface_s(face)
        if surface.DynamicType().Name() == "Geom_OffsetSurface":
            _tighten_offset(surface, converted_face, _OFFSET_TOLERANCE * size)
    kept = [k for k, (face, converted_face) in enumerate(zip(faces, converted_faces))
            if _keep_pcurves(face, converted_face, _SAME_PARAMETERS * size)]
    if kept:
        log.debug("faces that keep their pcurves as read: %s", kept)
    return _mend(faces, converted, converted_faces, _MEND_TOLERANCE * size)


def _refuse(shape: TopoDS_Shape, copy: TopoDS_Shape, failure: Exception) -> NoReturn:
    """Raise :class:`KernelError` for the conversion of ``copy`` (of ``shape``) that failed with ``failure``,
    naming the solid and face it fails on (each face converted alone to find it), with its surface type and a
    point on it."""
    names, numbers = shape_map(shape, TopAbs_FACE), index_map(copy, TopAbs_FACE)
    for s, solid in enumerate(shape_map(copy, TopAbs_SOLID)):
        for face in shape_map(solid, TopAbs_FACE):
            try:
                BRepBuilderAPI_NurbsConvert(face, True)
            except Exception as exc:  # Standard_Failure
                k = numbers.FindIndex(face) - 1
                raise KernelError(f"B-spline conversion of solid {s} failed at {describe_face(names[k], k)}: "
                                  f"{exc}") from exc
    raise KernelError(f"B-spline conversion of the part failed (on no face alone): {failure}") from failure


#: Share of the part's diagonal within which a converted surface or curve is taken to keep its parameters.
_SAME_PARAMETERS = 1e-9
#: Parameters at which a pcurve and its edge are compared (shares of the edge's range).
_SAMPLES = np.linspace(0.0, 1.0, 9)


def _keep_pcurves(face, converted_face, tol: float) -> bool:
    """Give ``converted_face`` (``face`` after ``BRepBuilderAPI_NurbsConvert``), in place, the pcurves ``face``
    has as read wherever the conversion changed neither the surface's parameters nor the edge curve's, yet made
    another pcurve (not the same B-spline); True if it did, and the face is still valid.

    The conversion projects the converted edge curve onto the surface anew whenever it converts the edge (its
    curve, or a face of it, is no B-spline), with ``ProjLib_ComputeApproxOnPolarSurface``.  On a B-spline
    surface with a pole, along an edge whose curve lies a loose tolerance from its pcurve as read, that
    projection made a pcurve of degree 8 whose poles swing over three periods of the surface and whose points
    leave its domain: the morphed face's wire then read as a hole.  Where the parameters are kept, the pcurve
    as read is the one the face was valid with.
    Planes are left alone (their pcurves are projected onto the plane itself); so are pcurves that are no line
    or B-spline (a conic's B-spline has other parameters).  ``tol`` (mm) bounds what counts as unchanged."""
    surface = BRep_Tool.Surface_s(face, TopLoc_Location())
    if isinstance(surface, Geom_Plane):
        return False
    converted_surface = BRep_Tool.Surface_s(converted_face, TopLoc_Location())
    face = TopoDS.Face_s(face.Oriented(TopAbs_FORWARD))
    converted_face = TopoDS.Face_s(converted_face.Oriented(TopAbs_FORWARD))
    was_valid, changes = None, []
    for edge, converted_edge in zip(edges_of(face, once=True), edges_of(converted_face, once=True)):
        if BRep_Tool.Degenerated_s(edge) or not _same_curve(edge, converted_edge, tol):
            continue
        first, last = BRep_Tool.Range_s(edge, face)
        if BRep_Tool.Range_s(converted_edge, converted_face) != (first, last):
            continue
        uses = [TopAbs_FORWARD, TopAbs_REVERSED] if BRep_Tool.IsClosed_s(edge, face) else [TopAbs_FORWARD]
        old = [pcurve_spline(TopoDS.Edge_s(edge.Oriented(o)), face) for o in uses]
        if any(c is None for c in old):
            continue
        new = [BRep_Tool.CurveOnSurface_s(TopoDS.Edge_s(converted_edge.Oriented(o)), converted_face, 0.0, 0.0)
               for o in uses]
        ts = first + _SAMPLES * (last - first)
        if not all(_on_same_points(surface, converted_surface, c, ts, tol) for c in old):
            continue
        if all(_identical(a, b) for a, b in zip(old, new)):
            continue
        if was_valid is None:
            was_valid = face_valid(converted_face)
        forward = TopoDS.Edge_s(converted_edge.Oriented(TopAbs_FORWARD))
        changes.append((forward, new, old))
        BRep_Builder().UpdateEdge(forward, *old, converted_face, BRep_Tool.Tolerance_s(converted_edge))
    if not changes:
        return False
    if face_valid(converted_face) or not was_valid:
        return True
    for forward, new, _ in changes:     # valid as converted, invalid with the pcurves as read: undone
        BRep_Builder().UpdateEdge(forward, *new, converted_face, BRep_Tool.Tolerance_s(forward))
    return False


def _same_curve(edge, converted_edge, tol: float) -> bool:
    """Whether the converted edge has the range and, at the same parameters, the points of ``edge``."""
    first, last = BRep_Tool.Range_s(edge)
    if BRep_Tool.Range_s(converted_edge) != (first, last):
        return False
    curve, converted = BRep_Tool.Curve_s(edge, 0.0, 0.0), BRep_Tool.Curve_s(converted_edge, 0.0, 0.0)
    if curve is None or converted is None:
        return False
    return all(curve.Value(t).Distance(converted.Value(t)) <= tol for t in first + _SAMPLES * (last - first))


def _on_same_points(surface, converted_surface, pcurve, ts, tol: float) -> bool:
    """Whether the two surfaces give the same points at ``pcurve``'s parameters ``ts``."""
    for t in ts:
        uv = pcurve.Value(t)
        if surface.Value(uv.X(), uv.Y()).Distance(converted_surface.Value(uv.X(), uv.Y())) > tol:
            return False
    return True


def _identical(a, b) -> bool:
    """Whether the 2D B-splines ``a`` and ``b`` have the same degree, knots and poles (to rounding)."""
    if not (isinstance(b, Geom2d_BSplineCurve) and a.Degree() == b.Degree() and a.NbPoles() == b.NbPoles()
            and reals(a.KnotSequence()) == reals(b.KnotSequence())):
        return False
    poles = [(a.Pole(i), b.Pole(i)) for i in range(1, a.NbPoles() + 1)]
    scale = 1.0 + max(abs(c) for p, _ in poles for c in (p.X(), p.Y()))
    return all(p.Distance(q) <= 1e-12 * scale for p, q in poles)


#: The largest edge tolerance (share of the part's diagonal) that mending a converted face may give an edge.
_MEND_TOLERANCE = 1e-7


def _mend(faces: list, converted: TopoDS_Shape, converted_faces: list, bound: float) -> TopoDS_Shape:
    """``converted`` with every face that is invalid where the face as read (of ``faces``, in the same order)
    is valid mended: in place (:func:`~hot2cold.kernel.repair.mend_face`), else by ``ShapeFix_Face``
    (:func:`~hot2cold.kernel.repair.fix_faces`; edge tolerances up to ``bound`` mm).  A face still invalid
    raises :class:`KernelError` naming it, its surface type as read, a point on it and what BRepCheck says."""
    left = [k for k, (face, converted_face) in enumerate(zip(faces, converted_faces))
            if not face_valid(converted_face) and face_valid(face) and mend_face(converted_face, bound)]
    if not left:
        return converted
    fixed = fix_faces(converted, [converted_faces[k] for k in left], bound)
    fixed_faces = shape_map(fixed, TopAbs_FACE)
    if len(fixed_faces) != len(faces):
        k = left[0]
        raise KernelError(f"B-spline conversion broke {describe_face(faces[k], k)}: "
                          f"{face_faults(converted_faces[k]) or 'invalid'}; mending it split faces")
    for k in left:
        if not face_valid(fixed_faces[k]):
            raise KernelError(f"B-spline conversion broke {describe_face(faces[k], k)}: "
                              f"{face_faults(fixed_faces[k]) or 'invalid'}, mended or not")
    log.debug("converted faces mended by ShapeFix_Face: %s", left)
    return fixed


#: The elementary surfaces whose u is the angle about their axis: their frame can be turned about it.
_TURNABLE = (Geom_CylindricalSurface, Geom_ConicalSurface, Geom_SphericalSurface, Geom_ToroidalSurface)


def _turn_to_face(face, index: int) -> None:
    """Where ``face`` lies on a cylinder, cone, sphere or torus and runs outside the first turn of its
    surface (its u, the angle about the axis, beyond 0 to 2 pi), give it, in place, the same surface with its
    frame turned about the axis to where the face begins, and its pcurves moved back by as much: the face and
    its edges stay where they are, its u now runs from 0.  ``index`` numbers the face in the log."""
    location = TopLoc_Location()
    surface = BRep_Tool.Surface_s(face, location)
    if not isinstance(surface, _TURNABLE):
        return
    u_lo, u_hi = BRepTools.UVBounds_s(face)[:2]
    slack = 1e-9 * TWO_PI
    if u_lo >= -slack and u_hi <= TWO_PI + slack:
        return
    frame = surface.Position()
    x, y = frame.XDirection(), frame.YDirection()
    c, s = math.cos(u_lo), math.sin(u_lo)
    start = gp_Dir(c * x.X() + s * y.X(), c * x.Y() + s * y.Y(), c * x.Z() + s * y.Z())
    turned = gp_Ax3(frame.Location(), frame.Direction(), start)
    if not frame.Direct():
        turned.YReverse()
    new = surface.Copy()
    new.SetPosition(turned)
    _move_pcurves(face, gp_Vec2d(-u_lo, 0.0), (new, location))
    log.debug("face %d runs over u %.6g to %.6g of its %s: its frame turned to begin there", index, u_lo, u_hi,
              surface.DynamicType().Name())


#: Offset surfaces are approximated to this share of the part's diagonal.  ``BRepBuilderAPI_NurbsConvert``
#: approximates them only coarsely (a single low-order patch, far looser than the morph's tolerance allows),
#: and a morph exact on the converted part is then that far off the part.
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

    A periodic direction whose face parameters lie a whole number of periods away (a torus face whose
    parameters run over its surface's second period rather than its first) has the face's pcurves moved by those
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
        knots = reals(surface.UKnots())
    else:
        surface.InsertVKnot(at, 1, tol, True)
        knots = reals(surface.VKnots())
    index = int(np.argmin(np.abs(np.asarray(knots) - at))) + 1
    if d == 0:
        surface.SetUOrigin(index)
    else:
        surface.SetVOrigin(index)


def _move_pcurves(face, by: gp_Vec2d, surface=None) -> None:
    """Translate the pcurves of every edge of ``face`` on it by ``by`` (both of a seam), in place; with
    ``surface`` (a ``Geom_Surface`` and its ``TopLoc_Location``), the face takes that surface first (the
    pcurves, stored against the face's surface, are read before)."""
    face = TopoDS.Face_s(face.Oriented(TopAbs_FORWARD))     # a seam's two pcurves read and written alike
    builder = BRep_Builder()
    moved = []
    for edge in edges_of(face, once=True):
        forward = TopoDS.Edge_s(edge.Oriented(TopAbs_FORWARD))
        curves = [BRep_Tool.CurveOnSurface_s(forward, face, 0.0, 0.0).Copy()]
        if BRep_Tool.IsClosed_s(edge, face):
            curves.append(BRep_Tool.CurveOnSurface_s(TopoDS.Edge_s(edge.Oriented(TopAbs_REVERSED)), face, 0.0,
                                                     0.0).Copy())
        for curve in curves:
            curve.Translate(by)
        moved.append((forward, curves, BRep_Tool.Tolerance_s(edge)))
    if surface is not None:
        builder.UpdateFace(face, surface[0], surface[1], BRep_Tool.Tolerance_s(face))
    for forward, curves, tolerance in moved:
        builder.UpdateEdge(forward, *curves, face, tolerance)


def _clamped(knots: list[float], degree: int) -> bool:
    return (all(k == knots[0] for k in knots[:degree + 1])
            and all(k == knots[-1] for k in knots[-degree - 1:]))


def _normalise_surface(surface: Geom_BSplineSurface) -> None:
    """Make a face's surface non-periodic and clamped, in place, without changing its geometry."""
    if surface.IsUPeriodic():
        surface.SetUNotPeriodic()
    if surface.IsVPeriodic():
        surface.SetVNotPeriodic()
    uk = reals(surface.UKnotSequence())
    vk = reals(surface.VKnotSequence())
    if not (_clamped(uk, surface.UDegree()) and _clamped(vk, surface.VDegree())):
        u0, u1, v0, v1 = surface.Bounds()
        surface.Segment(u0, u1, v0, v1)


def _normalise_curve(curve: Geom_BSplineCurve, first: float, last: float) -> None:
    """Make an edge's curve non-periodic, clamped and exactly the edge's range, in place."""
    if curve.IsPeriodic():
        curve.SetNotPeriodic()
    knots = reals(curve.KnotSequence())
    if (not _clamped(knots, curve.Degree()) or curve.FirstParameter() != first
            or curve.LastParameter() != last):
        curve.Segment(first, last)
