"""Rebuilding the cold part: the morphed poles written into the kernel's working copy.

Only poles move (same degrees, knots and weights; a face or edge refined to meet a tolerance first gets the
refined record's higher degree and extra knots, which leaves its shape as it was), and they move in the very
geometry objects the working copy's faces and edges hold, so the topology of the hot part is kept: every edge
is still one edge used by both of its faces, every vertex one vertex.  Vertices are moved to the ends of their
morphed edges.
"""
from __future__ import annotations

import logging

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.gp import gp_Pnt

from ..core.bspline import BSplineCurve, BSplineSurface
from ..errors import KernelError
from .convert import set_curve_poles, set_surface_poles
from .topology import KernelPart

log = logging.getLogger(__name__)


def _insert_missing(flat: list, knots, insert) -> None:
    have = list(flat)
    for x in knots:
        if x in have:
            have.remove(x)
        else:
            insert(float(x), 1, 0.0, True)


def _refine_surface(surface, record: BSplineSurface) -> None:
    """Give the kernel surface the degrees and knots of a record refined by
    :func:`hot2cold.core.bspline.refine_surface` (the one refinement; the poles the kernel computes here are
    overwritten by the record's).  Done in place, by the kernel's IncreaseDegree and InsertUKnot/InsertVKnot,
    because a Geom_BSplineSurface has no setter for its knots and a new surface object would lose the edges'
    curves on the face, which the kernel finds by the face's surface handle."""
    if record.u_degree > surface.UDegree() or record.v_degree > surface.VDegree():
        surface.IncreaseDegree(max(record.u_degree, surface.UDegree()), max(record.v_degree, surface.VDegree()))
    _insert_missing(surface.UKnotSequence(), record.u_knots, surface.InsertUKnot)
    _insert_missing(surface.VKnotSequence(), record.v_knots, surface.InsertVKnot)


def _refine_curve(curve, record: BSplineCurve) -> None:
    """Give the kernel curve the degree and knots of a record refined by :func:`hot2cold.core.bspline.refine_curve`
    (in place, as :func:`_refine_surface`; the record's poles are written afterwards)."""
    if record.degree > curve.Degree():
        curve.IncreaseDegree(record.degree)
    _insert_missing(curve.KnotSequence(), record.knots, curve.InsertKnot)


def rebuild(kernel: KernelPart, surfaces: list[BSplineSurface], curves: list[BSplineCurve | None],
            vertices: np.ndarray) -> None:
    """Write morphed geometry into ``kernel.work`` in place.

    Parameters
    ----------
    surfaces : one morphed surface per face, in the part's numbering.
    curves : one morphed curve per edge (None for degenerate edges).
    vertices : (nv, 3) morphed vertex points.
    """
    if len(surfaces) != len(kernel.faces) or len(curves) != len(kernel.edges):
        raise KernelError(f"rebuild needs {len(kernel.faces)} surfaces and {len(kernel.edges)} curves, "
                          f"got {len(surfaces)} and {len(curves)}")
    try:
        for (surface, trsf), record in zip(kernel.surfaces, surfaces):
            _refine_surface(surface, record)
            set_surface_poles(surface, record.poles, trsf)
        for entry, record in zip(kernel.curves, curves):
            if entry is not None:
                _refine_curve(entry[0], record)
                set_curve_poles(entry[0], record.poles, entry[1])
        builder = BRep_Builder()
        for vertex, point in zip(kernel.vertices, np.asarray(vertices, float)):
            builder.UpdateVertex(vertex, gp_Pnt(*point), BRep_Tool.Tolerance_s(vertex))
    except KernelError:
        raise
    except Exception as exc:
        raise KernelError(f"rebuilding the cold geometry failed: {exc}") from exc
    log.info("rebuilt %d faces, %d edges, %d vertices", len(surfaces), len(curves), len(vertices))
