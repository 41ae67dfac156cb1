"""Foot points: projection of points onto faces and edges with the kernel (eq. 4, 21, 27).

``GeomAPI_ProjectPointOnSurf`` and ``GeomAPI_ProjectPointOnCurve`` are initialised once per face or edge
and then asked point by point.  They are the reference the vectorised foot points of
:mod:`hot2cold.core.footpoint` are checked against, and they settle the nodes that Newton's method leaves open.
The default (gradient) algorithm is used: the tree one (``Extrema_ExtAlgo_Tree``) is faster but misses the
foot point of some points that lie on a thin, strongly curved face (a leading edge), and the reference must
not miss.

Whether a parameter pair lies in a face's trimmed domain is read off a raster of the domain
(:class:`hot2cold.core.domain.DomainRaster`) built from polylines of the face's pcurves; next to the boundary the
polylines decide, and ``BRepTopAdaptor_FClass2d`` only the points within a margin of a pcurve (the polyline's
distance from it, and the kernel's tolerance) or near a vertex.  Where the two differ beyond that margin, the
polylines answer as the pcurves do and the kernel does not (:meth:`Projector.classify`).
"""
from __future__ import annotations

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve2d
from OCP.BRepTools import BRepTools
from OCP.BRepTopAdaptor import BRepTopAdaptor_FClass2d
from OCP.Extrema import Extrema_ExtAlgo_Grad
from OCP.GeomAbs import GeomAbs_BSplineCurve, GeomAbs_Circle, GeomAbs_Line
from OCP.GeomAPI import GeomAPI_ProjectPointOnCurve, GeomAPI_ProjectPointOnSurf
from OCP.gp import gp_Pnt, gp_Pnt2d
from OCP.TopAbs import TopAbs_EDGE, TopAbs_IN, TopAbs_ON
from OCP.TopExp import TopExp_Explorer
from OCP.TopoDS import TopoDS

from ..core.bspline import cut_intervals, evaluate_curve
from ..core.domain import DomainRaster, Trim
from .convert import curve2d_to_record

#: Fewest and most cells along each side of a face's domain raster.
RASTER_CELLS = (64, 2048)
#: A face's raster is built once it has been asked about this many points in all (building it costs about
#: as much as the kernel's classifying them one by one next to the boundary; a morph asks most faces many times
#: about a few points each).
RASTER_WORTH = 200


def pcurve_points(curve: BRepAdaptor_Curve2d):
    """``points(t)``: the pcurve ``curve`` at parameters ``t (m,)`` as ``(m, 2)``.  Lines, circles and non-periodic
    B-splines are evaluated in numpy from their definition (the kernel's points to rounding: a line ``P + t D``, a
    circle ``C + r (cos t X + sin t Y)``, a B-spline from its poles, knots and weights), other curves point by
    point by the kernel (a Python call per point, where a face's raster asks for thousands)."""
    kind = curve.GetType()
    if kind == GeomAbs_Line:
        line = curve.Line()
        at, along = line.Location(), line.Direction()
        at, along = np.array([at.X(), at.Y()]), np.array([along.X(), along.Y()])
        return lambda t: at + np.asarray(t, float)[:, None] * along
    if kind == GeomAbs_Circle:
        circle = curve.Circle()
        axes = circle.Position()
        centre, x, y = axes.Location(), axes.XDirection(), axes.YDirection()
        centre, r = np.array([centre.X(), centre.Y()]), circle.Radius()
        x, y = r * np.array([x.X(), x.Y()]), r * np.array([y.X(), y.Y()])
        return lambda t: centre + np.cos(t)[:, None] * x + np.sin(t)[:, None] * y
    if kind == GeomAbs_BSplineCurve and not curve.IsPeriodic():
        record = curve2d_to_record(curve.BSpline())
        lo, hi = record.domain
        if lo <= curve.FirstParameter() and curve.LastParameter() <= hi:     # else the kernel extends it
            return lambda t: evaluate_curve(record, t)[:, :2]
    return lambda t: np.array([(q.X(), q.Y()) for q in map(curve.Value, t)]).reshape(-1, 2)


#: Points of a pcurve's polyline at the most (:func:`_pcurve_polylines`).
POLYLINE_MOST = 200_000


def _pcurve_polylines(face, box: np.ndarray, cells: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Every edge use's pcurve on ``face`` as a polyline ``(m, 2)`` whose segments are at most a raster cell
    long (``cells`` cells across ``box``), and the pcurve at each segment's middle parameter ``(m - 1, 2)``.

    From 16 segments of equal parameter, each segment longer than a cell is cut into as many of equal parameter
    as it is cells long, until none is longer (or the polyline has ``POLYLINE_MOST`` points): a pcurve that runs
    slowly over most of its parameters and crosses the face in a short stretch (a parametrisation far from
    its arc length) gets its points where it moves, not everywhere."""
    cell = np.array([(box[1] - box[0]) / cells, (box[3] - box[2]) / cells])
    lines, middles = [], []
    explorer = TopExp_Explorer(face, TopAbs_EDGE)
    while explorer.More():
        curve = BRepAdaptor_Curve2d(TopoDS.Edge_s(explorer.Current()), face)
        points = pcurve_points(curve)
        t = np.linspace(curve.FirstParameter(), curve.LastParameter(), 17)
        pts = points(t)
        while len(t) < POLYLINE_MOST:
            pieces = np.ceil(np.max(np.abs(np.diff(pts, axis=0)) / cell, axis=1))      # cells each segment spans
            pieces = np.where(np.isfinite(pieces), np.maximum(pieces, 1.0), 1.0).astype(int)
            if np.all(pieces == 1):
                break
            t = cut_intervals(t, pieces)
            pts = points(t)
        lines.append(pts)
        middles.append(points(0.5 * (t[:-1] + t[1:])))
        explorer.Next()
    return lines, middles


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
        self._raster: dict[int, DomainRaster] = {}
        self._curve: dict[int, tuple] = {}
        self._asked: dict[int, int] = {}

    def _surface_projector(self, k: int) -> GeomAPI_ProjectPointOnSurf:
        proj = self._surf.get(k)
        if proj is None:
            u0, u1, v0, v1 = self.face_box(k)
            proj = GeomAPI_ProjectPointOnSurf()
            proj.Init(BRep_Tool.Surface_s(self._faces[k]), u0, u1, v0, v1, Extrema_ExtAlgo_Grad)
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

    def face_box(self, k: int) -> np.ndarray:
        """The parameter box ``(u0, u1, v0, v1)`` :meth:`to_face` searches on face ``k``: the face's box
        within its surface's bounds (a trimmed face's box may overshoot its surface)."""
        face = self._faces[k]
        u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
        su0, su1, sv0, sv1 = BRep_Tool.Surface_s(face).Bounds()
        return np.array([max(u0, su0), min(u1, su1), max(v0, sv0), min(v1, sv1)])

    def _domain(self, k: int, points: int) -> DomainRaster:
        """Face ``k``'s raster, with more cells the more ``points`` it is asked about at once (the share of
        points left to the kernel falls as the cells shrink); built again, finer, when a larger request
        comes."""
        cells = int(np.clip(2 ** np.ceil(np.log2(2.0 * np.sqrt(max(points, 1)))), *RASTER_CELLS))
        raster = self._raster.get(k)
        if raster is None or raster.state.shape[0] < cells:
            face = self._faces[k]
            box = np.array(BRepTools.UVBounds_s(face))
            lines, middles = _pcurve_polylines(face, box, cells)
            raster = DomainRaster.build(lines, box, cells, middles, self._tol)
            self._raster[k] = raster
        return raster

    def classify(self, k: int, uv: np.ndarray) -> np.ndarray:
        """State ``(n,)`` int of parameters ``uv (n, 2)`` in face ``k``'s trimmed domain: Trim.INSIDE,
        Trim.ON_BOUNDARY or Trim.OUTSIDE.

        The raster and the pcurves' polylines decide the points farther from a pcurve than its margin (see
        :class:`~hot2cold.core.domain.DomainRaster`), ``BRepTopAdaptor_FClass2d`` the rest (all of them until the
        face has been asked about ``RASTER_WORTH`` points in all).  The kernel classifies with a polygon of its
        own, which on some faces lies farther from the pcurves than its tolerance, and on some answers
        ON_BOUNDARY farther out than it (the docs' measurements); the polylines answer as the pcurves do.
        """
        uv = np.asarray(uv, float).reshape(-1, 2)
        self._asked[k] = asked = self._asked.get(k, 0) + len(uv)
        if k not in self._raster and asked < RASTER_WORTH:
            return self.classify_exactly(k, uv)
        state = self._domain(k, len(uv)).classify(uv).astype(int)
        unsure = np.flatnonzero(state == Trim.UNSURE)
        if len(unsure):
            state[unsure] = self.classify_exactly(k, uv[unsure])
        return state

    def classify_exactly(self, k: int, uv: np.ndarray) -> np.ndarray:
        """:meth:`classify` by ``BRepTopAdaptor_FClass2d`` alone, one point at a time (the reference)."""
        cls = self._class.get(k)
        if cls is None:
            cls = BRepTopAdaptor_FClass2d(self._faces[k], self._tol)
            self._class[k] = cls
        state = np.full(len(uv), Trim.OUTSIDE)
        for i, (u, v) in enumerate(np.asarray(uv, float)):
            if np.isfinite(u) and np.isfinite(v):
                s = cls.Perform(gp_Pnt2d(u, v))
                state[i] = Trim.INSIDE if s == TopAbs_IN else Trim.ON_BOUNDARY if s == TopAbs_ON else Trim.OUTSIDE
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
