"""What the kernel finds wrong with a solid, face by face, in words a message can name.

:func:`solid_faults` lists the faces of a solid that ``BRepCheck_Analyzer`` refuses (with their surface
type, a point on them and the statuses BRepCheck gives the face, its wires, edges and vertices), or the
solid's own statuses (e.g. an unorientable shell) when no face is at fault; :func:`describe_face` names one
face for a message and :func:`face_label` for a report.  Used on the hot part as read (a broken input) and on
the part after B-spline conversion (a conversion that broke it).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Surface
from OCP.BRepClass import BRepClass_FaceClassifier
from OCP.GCPnts import GCPnts_AbscissaPoint
from OCP.gp import gp_Pnt2d
from OCP.BRepCheck import BRepCheck_Analyzer, BRepCheck_NoError
from OCP.BRepTools import BRepTools
from OCP.TopAbs import TopAbs_EDGE, TopAbs_IN, TopAbs_ON, TopAbs_SHELL, TopAbs_VERTEX, TopAbs_WIRE
from OCP.TopExp import TopExp_Explorer
from OCP.TopoDS import TopoDS

from .explore import shape_map

#: Statuses named in a message at the most.
_STATUSES = 3


def surface_type(face) -> str:
    """The kind of ``face``'s surface as OCCT names it without its prefix: "Plane", "Cone", "BSplineSurface"."""
    name = BRepAdaptor_Surface(face).GetType().name
    return name.removeprefix("GeomAbs_")


def face_point(face) -> tuple[float, float, float]:
    """A point ``(3,)`` on ``face`` in mm: its surface at the middle of its parameter box where that lies on
    the face, else the middle of its longest edge (the middle of a trimmed or overrun face's box can lie far
    from it, and a face named there would be named at a point far outside the part)."""
    try:
        u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
        u, v = (u0 + u1) / 2, (v0 + v1) / 2
        if BRepClass_FaceClassifier(face, gp_Pnt2d(u, v), 1e-7).State() in (TopAbs_IN, TopAbs_ON):
            p = BRepAdaptor_Surface(face).Value(u, v)
            return (p.X(), p.Y(), p.Z())
        longest, most = None, -1.0
        explorer = TopExp_Explorer(face, TopAbs_EDGE)
        while explorer.More():
            edge = TopoDS.Edge_s(explorer.Current())
            explorer.Next()
            if not BRep_Tool.Degenerated_s(edge):
                curve = BRepAdaptor_Curve(edge)
                length = GCPnts_AbscissaPoint.Length_s(curve)
                if length > most:
                    longest, most = curve, length
        if longest is None:
            return (float("nan"),) * 3
        p = longest.Value((longest.FirstParameter() + longest.LastParameter()) / 2)
        return (p.X(), p.Y(), p.Z())
    except Exception:  # Standard_Failure on a face without a usable surface
        return (float("nan"),) * 3


#: Words for the surface kinds of :func:`surface_type` in a face's label.
_KIND_WORDS = {"Plane": "plane", "Cylinder": "cylinder", "Cone": "cone", "Sphere": "sphere", "Torus": "torus",
               "BezierSurface": "Bezier surface", "BSplineSurface": "B-spline surface",
               "SurfaceOfRevolution": "surface of revolution", "SurfaceOfExtrusion": "extruded surface",
               "OffsetSurface": "offset surface"}


def _axis_name(direction) -> str | None:
    """"x", "y" or "z" when the gp_Dir ``direction`` lies along that axis (either way), else None."""
    d = np.array([direction.X(), direction.Y(), direction.Z()])
    k = int(np.argmax(np.abs(d)))
    return "xyz"[k] if abs(d[k]) > 1.0 - 1e-9 else None


def face_label(face) -> str:
    """A name for ``face`` from its surface kind and place, for a part whose STEP names none: "plane z = 10",
    "cylinder r 5 about z", "B-spline surface near (1, 2, 3)" (lengths in mm, 4 significant digits)."""
    kind = surface_type(face)
    word = _KIND_WORDS.get(kind, "surface")
    try:
        adaptor = BRepAdaptor_Surface(face)
        if kind == "Plane":
            plane = adaptor.Plane()
            axis = _axis_name(plane.Axis().Direction())
            if axis is not None:
                at = plane.Location()
                return f"plane {axis} = {getattr(at, axis.upper())():.4g}"
        elif kind in ("Cylinder", "Sphere", "Torus"):
            shape = getattr(adaptor, kind)()
            radius = shape.MajorRadius() if kind == "Torus" else shape.Radius()
            axis = None if kind == "Sphere" else _axis_name(shape.Axis().Direction())
            return f"{word} r {radius:.4g}" + (f" about {axis}" if axis else "")
    except Exception:  # Standard_Failure: the near point below still names it
        pass
    return f"{word} near ({', '.join(f'{x:.4g}' for x in face_point(face))})"


def describe_face(face, index: int) -> str:
    """E.g. "face 12 (Cone, near (1, 2, 3) mm)"."""
    at = ", ".join(f"{x:.4g}" for x in face_point(face))
    return f"face {index} ({surface_type(face)}, near ({at}) mm)"


@dataclass(frozen=True)
class Fault:
    """A face a solid's check refuses: ``face`` (0-based in the solid's shape numbering, or None for a fault of
    the solid or shell as a whole), ``where`` (:func:`describe_face`, or "its shell") and the BRepCheck
    ``statuses`` (names without the ``BRepCheck_`` prefix)."""

    face: int | None
    where: str
    statuses: tuple[str, ...]

    def __str__(self) -> str:
        shown = ", ".join(self.statuses[:_STATUSES]) + (", ..." if len(self.statuses) > _STATUSES else "")
        return f"{self.where}: {shown or 'invalid'}"


def _statuses(analyzer: BRepCheck_Analyzer, shape, context) -> list[str]:
    """The BRepCheck statuses of ``shape`` alone and within ``context`` (None: alone only), no-error left out."""
    result = analyzer.Result(shape)
    if result is None:
        return []
    found = list(result.Status())
    if context is not None:
        try:
            found += list(result.StatusOnShape(context))
        except Exception:  # no status recorded in that context
            pass
    return [s.name.removeprefix("BRepCheck_") for s in found if s != BRepCheck_NoError]


def _face_statuses(face) -> tuple[str, ...] | None:
    """The BRepCheck statuses of ``face`` alone, of its wires, edges and vertices on it (each once, in that
    order); None when the face is valid."""
    local = BRepCheck_Analyzer(face)
    if local.IsValid():
        return None
    found = _statuses(local, face, None)
    for kind in (TopAbs_WIRE, TopAbs_EDGE, TopAbs_VERTEX):
        explorer = TopExp_Explorer(face, kind)
        while explorer.More():
            found += _statuses(local, explorer.Current(), face)
            explorer.Next()
    return tuple(dict.fromkeys(found))


def face_faults(face) -> str:
    """What ``BRepCheck_Analyzer`` finds wrong with ``face`` alone, as "NotClosed, UnorientableShape" (at most
    a few statuses); empty when it is valid."""
    found = _face_statuses(face) or ()
    return ", ".join(found[:_STATUSES]) + (", ..." if len(found) > _STATUSES else "")


def solid_faults(solid, faces: list[tuple[int, object]]) -> list[Fault]:
    """The faults of ``solid`` (valid: none): each face of ``faces`` (pairs of the number to report and the
    face, for the solid's faces) that ``BRepCheck_Analyzer`` refuses, or the solid's own when none is."""
    analyzer = BRepCheck_Analyzer(solid)
    if analyzer.IsValid():
        return []
    out = []
    for k, face in faces:
        found = _face_statuses(face)
        if found is not None:
            out.append(Fault(k, describe_face(face, k), found))
    if out:
        return out
    shells = shape_map(solid, TopAbs_SHELL)
    found = _statuses(analyzer, solid, None)
    for shell in shells:
        found += _statuses(analyzer, shell, solid) + _statuses(analyzer, shell, None)
    # the first face whose status within a shell is not clean (e.g. badly oriented)
    faulty = next(((k, face) for k, face in faces
                   if _statuses(analyzer, face, None) or any(_statuses(analyzer, face, s) for s in shells)), None)
    where = "its shell" + (f" at {describe_face(faulty[1], faulty[0])}" if faulty else "")
    return [Fault(faulty[0] if faulty else None, where, tuple(dict.fromkeys(found)))]
