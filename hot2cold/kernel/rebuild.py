"""Rebuilding the cold part: the morphed poles written into a fresh copy of the hot part's kernel shape.

The hot part (:class:`~hot2cold.kernel.topology.KernelPart`) stays as it was loaded: :func:`rebuild` copies
its working shape, geometry included, and returns the copy as a :class:`ColdKernel`, which
:func:`~hot2cold.kernel.tolerances.fit_tolerances`, the checks and the writers then take.

Only poles move (same degrees, knots and weights; a face or edge refined to meet a tolerance first gets the
refined record's higher degree and extra knots, which leaves its shape as it was), and they move in the very
geometry objects the cold copy's faces and edges hold, so the topology of the hot part is kept: every edge
is still one edge used by both of its faces, every vertex one vertex.  Vertices are moved to the ends of their
morphed edges.
"""
from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepBuilderAPI import BRepBuilderAPI_Copy
from OCP.gp import gp_Pnt
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_VERTEX
from OCP.TopoDS import TopoDS_Shape

from ..core.bspline import BSplineCurve, BSplineSurface
from ..errors import KernelError
from .convert import set_curve_poles, set_surface_poles
from .explore import bspline_curve, bspline_surface, reals, shape_map
from .topology import KernelPart

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class ColdKernel:
    """The cold part's kernel shape: a copy of the hot part's working shape with the morphed geometry.

    ``faces``, ``edges`` and ``vertices`` are the sub-shapes of ``shape`` in the part's numbering (face ``k``
    of the hot part is face ``k`` here); the morph changes only their geometry, and
    :func:`~hot2cold.kernel.tolerances.fit_tolerances` their tolerances.
    """

    shape: TopoDS_Shape
    faces: list
    edges: list
    vertices: list


def _insert_missing(flat: list[float], knots, insert) -> None:
    """Insert each of ``knots`` (a record's full knot vector) that the kernel's full knot sequence ``flat`` lacks
    (multiplicities counted) by ``insert(knot, 1, 0.0, True)``, in order."""
    have = Counter(float(x) for x in flat)
    for x in map(float, knots):
        if have[x] > 0:
            have[x] -= 1
        else:
            insert(x, 1, 0.0, True)


def _refine_surface(surface, record: BSplineSurface) -> None:
    """Give the kernel surface the degrees and knots of a record refined by
    :func:`hot2cold.core.bspline.refine_surface` (the one refinement; the poles the kernel computes here are
    overwritten by the record's).  Done in place, by the kernel's IncreaseDegree and InsertUKnot/InsertVKnot,
    because a Geom_BSplineSurface has no setter for its knots and a new surface object would lose the edges'
    curves on the face, which the kernel finds by the face's surface handle."""
    if record.u_degree > surface.UDegree() or record.v_degree > surface.VDegree():
        surface.IncreaseDegree(max(record.u_degree, surface.UDegree()), max(record.v_degree, surface.VDegree()))
    _insert_missing(reals(surface.UKnotSequence()), record.u_knots, surface.InsertUKnot)
    _insert_missing(reals(surface.VKnotSequence()), record.v_knots, surface.InsertVKnot)


def _refine_curve(curve, record: BSplineCurve) -> None:
    """Give the kernel curve the degree and knots of a record refined by :func:`hot2cold.core.bspline.refine_curve`
    (in place, as :func:`_refine_surface`; the record's poles are written afterwards)."""
    if record.degree > curve.Degree():
        curve.IncreaseDegree(record.degree)
    _insert_missing(reals(curve.KnotSequence()), record.knots, curve.InsertKnot)


def rebuild(kernel: KernelPart, surfaces: list[BSplineSurface], curves: list[BSplineCurve | None],
            vertices: np.ndarray) -> ColdKernel:
    """The cold kernel shape: a copy of ``kernel.work`` (which is left as it is) with the morphed geometry.

    Parameters
    ----------
    kernel : the hot part's kernel side.
    surfaces : one morphed surface per face, in the part's numbering.
    curves : one morphed curve per edge (None for degenerate edges).
    vertices : (nv, 3) morphed vertex points.
    """
    if len(surfaces) != len(kernel.faces) or len(curves) != len(kernel.edges):
        raise KernelError(f"rebuild needs {len(kernel.faces)} surfaces and {len(kernel.edges)} curves, "
                          f"got {len(surfaces)} and {len(curves)}")
    try:
        # the copy has the work shape's tree, so its TopExp numbering is the part's
        shape = BRepBuilderAPI_Copy(kernel.work, True, False).Shape()
        cold = ColdKernel(shape, shape_map(shape, TopAbs_FACE), shape_map(shape, TopAbs_EDGE),
                          shape_map(shape, TopAbs_VERTEX))
        if (len(cold.faces), len(cold.edges), len(cold.vertices)) != (
                len(kernel.faces), len(kernel.edges), len(kernel.vertices)):
            raise KernelError("the copy of the part for the cold geometry has other faces, edges or vertices")
        for face, record in zip(cold.faces, surfaces):
            surface, trsf = bspline_surface(face)
            _refine_surface(surface, record)
            set_surface_poles(surface, record.poles, trsf)
        for edge, hot, record in zip(cold.edges, kernel.curves, curves):
            if hot is not None:
                curve, trsf = bspline_curve(edge)
                _refine_curve(curve, record)
                set_curve_poles(curve, record.poles, trsf)
        builder = BRep_Builder()
        for vertex, point in zip(cold.vertices, np.asarray(vertices, float)):
            builder.UpdateVertex(vertex, gp_Pnt(*point), BRep_Tool.Tolerance_s(vertex))
    except KernelError:
        raise
    except Exception as exc:
        raise KernelError(f"rebuilding the cold geometry failed: {exc}") from exc
    log.info("rebuilt %d faces, %d edges, %d vertices", len(surfaces), len(curves), len(vertices))
    return cold
