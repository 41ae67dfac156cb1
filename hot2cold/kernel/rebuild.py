"""Rebuilding the cold part: the morphed poles written into the kernel's working copy.

Only poles move (same degrees, knots and weights; a face refined to meet a tolerance gets the refined
record's extra knots first, which leaves its shape as it was), and they move in the very geometry objects the
working copy's faces and edges hold, so the topology of the hot part is kept: every edge is still one edge
used by both of its faces, every vertex one vertex.  Vertices are moved to the ends of their morphed edges.
"""
from __future__ import annotations

import logging

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.gp import gp_Pnt

from ..bspline import BSplineCurve, BSplineSurface
from ..errors import KernelError
from .convert import set_curve_poles, set_surface_poles
from .topology import KernelPart

log = logging.getLogger(__name__)


def _insert_missing_knots(surface, record: BSplineSurface) -> None:
    """Insert into the kernel surface the knots a refined record has and it lacks (shape unchanged)."""
    for knots, flat, insert in ((record.u_knots, surface.UKnotSequence(), surface.InsertUKnot),
                                (record.v_knots, surface.VKnotSequence(), surface.InsertVKnot)):
        have = list(flat)
        for x in knots:
            if x in have:
                have.remove(x)
            else:
                insert(float(x), 1, 0.0, True)


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
            _insert_missing_knots(surface, record)
            set_surface_poles(surface, record.poles, trsf)
        for entry, record in zip(kernel.curves, curves):
            if entry is not None:
                set_curve_poles(entry[0], record.poles, entry[1])
        builder = BRep_Builder()
        for vertex, point in zip(kernel.vertices, np.asarray(vertices, float)):
            builder.UpdateVertex(vertex, gp_Pnt(*point), BRep_Tool.Tolerance_s(vertex))
    except KernelError:
        raise
    except Exception as exc:
        raise KernelError(f"rebuilding the cold geometry failed: {exc}") from exc
    log.info("rebuilt %d faces, %d edges, %d vertices", len(surfaces), len(curves), len(vertices))
