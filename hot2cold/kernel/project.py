"""Foot points: projection of points onto faces and edges with the kernel (eq. 4, 21, 27).

``GeomAPI_ProjectPointOnSurf`` and ``GeomAPI_ProjectPointOnCurve`` are initialised once per face or edge
(the surface's sample tree is built once) and then asked point by point.  The tree algorithm
(``Extrema_ExtAlgo_Tree``) finds the same foot points as the default gradient one at a quarter of the time
(measured on the twisted blade: 116 us against 510 us a point, distances equal to 1e-15 mm).  ``BRepTopAdaptor_FClass2d``
tells whether a foot point lies in a face's trimmed domain.
"""
from __future__ import annotations

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepTools import BRepTools
from OCP.BRepTopAdaptor import BRepTopAdaptor_FClass2d
from OCP.Extrema import Extrema_ExtAlgo_Tree
from OCP.GeomAPI import GeomAPI_ProjectPointOnCurve, GeomAPI_ProjectPointOnSurf
from OCP.gp import gp_Pnt, gp_Pnt2d
from OCP.TopAbs import TopAbs_IN, TopAbs_ON

#: Position states of :meth:`Projector.classify`.
INSIDE, ON_BOUNDARY, OUTSIDE = 0, 1, 2


class Projector:
    """Projects points onto the faces and edges of a shape (lists of ``TopoDS_Face``/``TopoDS_Edge``).

    Build one after the geometry is final: the kernel caches per-surface data on first use.
    """

    def __init__(self, faces: list, edges: list, boundary_tolerance: float = 1e-7):
        self._faces = faces
        self._edges = edges
        self._tol = boundary_tolerance
        self._surf: dict[int, GeomAPI_ProjectPointOnSurf] = {}
        self._class: dict[int, BRepTopAdaptor_FClass2d] = {}
        self._curve: dict[int, tuple] = {}

    def _surface_projector(self, k: int) -> GeomAPI_ProjectPointOnSurf:
        proj = self._surf.get(k)
        if proj is None:
            face = self._faces[k]
            surface = BRep_Tool.Surface_s(face)
            u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
            su0, su1, sv0, sv1 = surface.Bounds()       # a trimmed face's box may overshoot its surface
            proj = GeomAPI_ProjectPointOnSurf()
            proj.Init(surface, max(u0, su0), min(u1, su1), max(v0, sv0), min(v1, sv1), Extrema_ExtAlgo_Tree)
            self._surf[k] = proj
        return proj

    def to_face(self, k: int, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Foot points of ``points`` ``(n, 3)`` on the surface of face ``k`` within its UV box.

        Returns ``uv (n, 2)`` and ``distance (n,)``; where the kernel finds no foot point the distance is
        ``inf`` and uv is NaN.
        """
        proj = self._surface_projector(k)
        uv = np.full((len(points), 2), np.nan)
        dist = np.full(len(points), np.inf)
        for i, p in enumerate(np.asarray(points, float)):
            proj.Perform(gp_Pnt(*p))
            if proj.NbPoints() > 0:
                uv[i] = proj.LowerDistanceParameters()
                dist[i] = proj.LowerDistance()
        return uv, dist

    def classify(self, k: int, uv: np.ndarray) -> np.ndarray:
        """State of parameters ``uv (n, 2)`` in face ``k``'s trimmed domain: INSIDE, ON_BOUNDARY or OUTSIDE."""
        cls = self._class.get(k)
        if cls is None:
            cls = BRepTopAdaptor_FClass2d(self._faces[k], self._tol)
            self._class[k] = cls
        state = np.full(len(uv), OUTSIDE)
        for i, (u, v) in enumerate(np.asarray(uv, float)):
            if np.isfinite(u) and np.isfinite(v):
                s = cls.Perform(gp_Pnt2d(u, v))
                state[i] = INSIDE if s == TopAbs_IN else ON_BOUNDARY if s == TopAbs_ON else OUTSIDE
        return state

    def to_edge(self, e: int, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Foot points of ``points`` ``(n, 3)`` on edge ``e``'s curve within its range.

        Returns ``t (n,)`` and ``distance (n,)``; the nearer end is taken where no orthogonal foot exists.
        """
        entry = self._curve.get(e)
        if entry is None:
            edge = self._edges[e]
            first, last = BRep_Tool.Range_s(edge)
            curve = BRep_Tool.Curve_s(edge, 0.0, 0.0)
            proj = GeomAPI_ProjectPointOnCurve()
            proj.Init(curve, first, last)
            ends = np.array([[q.X(), q.Y(), q.Z()] for q in (curve.Value(first), curve.Value(last))])
            entry = (proj, first, last, ends)
            self._curve[e] = entry
        proj, first, last, ends = entry
        t = np.empty(len(points))
        dist = np.empty(len(points))
        for i, p in enumerate(np.asarray(points, float)):
            end_d = np.linalg.norm(ends - p, axis=1)
            j = int(np.argmin(end_d))
            t[i], dist[i] = (first, last)[j], end_d[j]
            proj.Perform(gp_Pnt(*p))
            if proj.NbPoints() > 0 and proj.LowerDistance() < dist[i]:
                t[i], dist[i] = proj.LowerDistanceParameter(), proj.LowerDistance()
        return t, dist
