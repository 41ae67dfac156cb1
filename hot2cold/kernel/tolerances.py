"""Fitting the cold part's edge and vertex tolerances to the true gaps left by the morph (no sewing).

The morph keeps the hot topology (see :mod:`hot2cold.kernel.rebuild`), so faces are never separated and
there is nothing to re-match as ``BRepBuilderAPI_Sewing`` would on a loose set of faces.  What the morph
can open is a small gap between an edge's 3D curve and the surface of a face it bounds, where the edge is
not a whole side of that face (trimmed faces).  This step measures that gap on every edge use and widens
the edge's tolerance to cover it, then lets ``BRepLib`` bring vertex tolerances into line, so that the
kernel sees a closed, valid solid whose tolerances state the true gaps.
"""
from __future__ import annotations

import logging

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.BRepLib import BRepLib
from OCP.TopAbs import TopAbs_EDGE
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopTools import TopTools_IndexedMapOfShape
from OCP.TopoDS import TopoDS

from ..errors import KernelError
from .rebuild import ColdKernel

log = logging.getLogger(__name__)


def _gap(edge, face, n: int) -> float:
    """Largest distance between the edge's 3D curve and its curve on ``face`` at ``n`` parameters."""
    c3d = BRepAdaptor_Curve(edge)
    on_face = BRepAdaptor_Curve(edge, face)
    gap = 0.0
    for t in np.linspace(c3d.FirstParameter(), c3d.LastParameter(), n):
        gap = max(gap, c3d.Value(t).Distance(on_face.Value(t)))
    return gap


def fit_tolerances(cold: ColdKernel, samples: int = 51, margin: float = 1.5) -> np.ndarray:
    """Fit edge and vertex tolerances of the cold shape ``cold`` (from :func:`~hot2cold.kernel.rebuild.rebuild`,
    changed in place) to the morphed geometry.

    Returns the gap ``(n_edges,)`` in mm of every edge: the largest distance, over ``samples`` points, between
    its 3D curve and the surface of any face it bounds.  Edge tolerances become at least ``margin`` times
    that gap.
    """
    edge_index = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(cold.shape, TopAbs_EDGE, edge_index)
    gaps = np.zeros(len(cold.edges))
    try:
        for face in cold.faces:
            explorer = TopExp_Explorer(face, TopAbs_EDGE)
            while explorer.More():
                edge = TopoDS.Edge_s(explorer.Current())
                explorer.Next()
                if BRep_Tool.Degenerated_s(edge):
                    continue
                e = edge_index.FindIndex(edge) - 1
                gaps[e] = max(gaps[e], _gap(edge, face, samples))
        builder = BRep_Builder()
        for e, edge in enumerate(cold.edges):
            if margin * gaps[e] > BRep_Tool.Tolerance_s(edge):
                builder.UpdateEdge(edge, margin * gaps[e])
        BRepLib.UpdateTolerances_s(cold.shape, False)
    except Exception as exc:
        raise KernelError(f"fitting the cold part's tolerances failed: {exc}") from exc
    log.info("sewed: largest edge gap %.3g mm", gaps.max() if len(gaps) else 0.0)
    return gaps
