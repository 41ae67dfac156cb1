"""Finding one's way in a kernel shape: its sub-shapes in the project's numbering, its size, and the B-spline
geometry of a converted face or edge.  The base the other kernel modules build on (it imports none of them).
"""
from __future__ import annotations

import numpy as np
from OCP.Bnd import Bnd_Box
from OCP.BRep import BRep_Tool
from OCP.BRepBndLib import BRepBndLib
from OCP.Geom import Geom_BSplineCurve, Geom_BSplineSurface
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_SOLID, TopAbs_VERTEX, TopAbs_WIRE
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedMapOfShape

from ..errors import KernelError


def shape_map(shape: TopoDS_Shape, kind) -> list:
    """Sub-shapes of ``kind`` in ``TopExp.MapShapes`` order, 0-based: the project's numbering."""
    m = index_map(shape, kind)
    cast = {TopAbs_FACE: TopoDS.Face_s, TopAbs_EDGE: TopoDS.Edge_s, TopAbs_VERTEX: TopoDS.Vertex_s,
            TopAbs_SOLID: TopoDS.Solid_s}[kind]
    return [cast(m.FindKey(i)) for i in range(1, m.Size() + 1)]


def reals(array) -> list[float]:
    """The values of an OCCT array of reals (a knot sequence, knots: ``TColStd_Array1OfReal``, or the handle
    ``TColStd_HArray1OfReal`` that other builds of OCP return), in order, read one by one: Python's own
    iteration over such an array is far slower (a part of hundreds of faces reads thousands)."""
    if hasattr(array, "Array1"):                        # a handle: its array
        array = array.Array1()
    if not hasattr(array, "Value"):                     # no accessor to read it by: Python's iteration
        return [float(x) for x in array]
    return [array.Value(i) for i in range(array.Lower(), array.Upper() + 1)]


def edges_of(shape: TopoDS_Shape, once: bool = False) -> list:
    """The edges of ``shape`` as ``TopExp_Explorer`` meets them, oriented as they are used there (a seam of a
    face twice, once each way); with ``once``, each edge once (its first use)."""
    edges, seen = [], TopTools_IndexedMapOfShape()
    explorer = TopExp_Explorer(shape, TopAbs_EDGE)
    while explorer.More():
        edge = TopoDS.Edge_s(explorer.Current())
        explorer.Next()
        if once:
            if seen.Contains(edge):
                continue
            seen.Add(edge)
        edges.append(edge)
    return edges



def wire_edges(face) -> list[list]:
    """Per wire of ``face`` as ``TopExp_Explorer`` meets them, its edge uses (:func:`edges_of`), oriented as the
    face runs them."""
    out = []
    explorer = TopExp_Explorer(face, TopAbs_WIRE)
    while explorer.More():
        out.append(edges_of(explorer.Current()))
        explorer.Next()
    return out

def index_map(shape: TopoDS_Shape, kind) -> TopTools_IndexedMapOfShape:
    """The kernel's indexed map of the sub-shapes of ``kind`` (1-based; ``FindIndex`` gives k + 1)."""
    m = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, kind, m)
    return m


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
