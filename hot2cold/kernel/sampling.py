"""Points on and in a solid: face samples, an FE-like surface node set and volume nodes.

Faces and edges are numbered as everywhere in the project (:func:`.topology.shape_map`): face ``k`` (from 0)
is index ``k + 1`` of ``TopExp.MapShapes_s(shape, TopAbs_FACE, map)``.

Location handling (checked on OCP 7.9): ``BRep_Tool.Surface_s(face)`` returns the surface with the face's
``TopLoc_Location`` already applied (a transformed copy when the location is not the identity; its
parameterisation is that of the raw surface), whereas ``BRep_Tool.Surface_s(face, loc)`` returns the raw,
untransformed surface and fills ``loc``.  Everything here uses the one-argument form, so all points are in
global coordinates and all ``(u, v)`` are parameters of ``BRep_Tool.Surface_s(face)``.  Edge points use
``BRepAdaptor_Curve``, which also applies the edge's location.

Random draws come from ``numpy.random.default_rng(seed)``: the same shape, spacing and seed give the same
points.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from OCP.Bnd import Bnd_Box
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.BRepBndLib import BRepBndLib
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
from OCP.BRepClass3d import BRepClass3d_SolidClassifier
from OCP.BRepExtrema import BRepExtrema_DistShapeShape
from OCP.BRepTools import BRepTools
from OCP.BRepTopAdaptor import BRepTopAdaptor_FClass2d
from OCP.GCPnts import GCPnts_AbscissaPoint, GCPnts_UniformAbscissa
from OCP.GeomLProp import GeomLProp_SLProps
from OCP.gp import gp_Pnt, gp_Pnt2d
from OCP.Precision import Precision
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_IN, TopAbs_REVERSED, TopAbs_VERTEX
from OCP.TopoDS import TopoDS, TopoDS_Compound, TopoDS_Edge, TopoDS_Face, TopoDS_Shape
from scipy.spatial import cKDTree

from .explore import index_map, shape_map

log = logging.getLogger(__name__)

#: Evaluations per direction of the coarse grid that estimates a face's size in 3D.
_COARSE = 41
#: How often the sampling grid of a face with no sample inside is doubled before giving up.
_MAX_REFINE = 6


def face_list(shape: TopoDS_Shape) -> list[TopoDS_Face]:
    """The faces of ``shape`` in the project's numbering (see :func:`.topology.shape_map`)."""
    return shape_map(shape, TopAbs_FACE)


def edge_list(shape: TopoDS_Shape) -> list[TopoDS_Edge]:
    """The edges of ``shape`` in the project's numbering (see :func:`.topology.shape_map`)."""
    return shape_map(shape, TopAbs_EDGE)


def _pnt(p: gp_Pnt) -> tuple[float, float, float]:
    return p.X(), p.Y(), p.Z()


def _evaluate(surface, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Points ``(m, 3)`` of a ``Geom_Surface`` at parameters ``u (m,)``, ``v (m,)``."""
    out = np.empty((len(u), 3))
    for i, (a, b) in enumerate(zip(u.tolist(), v.tolist())):
        out[i] = _pnt(surface.Value(a, b))
    return out


def _arc_map(lengths: np.ndarray) -> np.ndarray:
    """Normalised mean cumulative arc length ``(c,)`` of grid lines ``lengths (lines, c - 1)``.

    Strictly increasing from 0 to 1 (a small linear part keeps it invertible where a line degenerates).
    """
    cum = np.concatenate([[0.0], np.cumsum(lengths.mean(axis=0))])
    linear = np.linspace(0.0, 1.0, len(cum))
    if cum[-1] <= 0.0:
        return linear
    return 0.999 * cum / cum[-1] + 0.001 * linear


@dataclass
class _FaceGrid:
    """A roughly uniform sampling grid on one face, cells of about ``spacing`` mm in 3D.

    The grid is uniform in (mean) arc length along the u and v directions of the parameter box
    ``BRepTools.UVBounds_s(face)``.  A continuous grid coordinate ``(s, t)`` in ``[0, nu] x [0, nv]`` maps to
    ``(u, v)``; cell centres are at ``s = i + 0.5``, ``t = j + 0.5``.
    """

    face: TopoDS_Face
    surface: object          # Geom_Surface with the face location applied
    classifier: BRepTopAdaptor_FClass2d
    u_nodes: np.ndarray      # (c,) parameters of the coarse grid in u
    u_arc: np.ndarray        # (c,) normalised arc length at u_nodes
    v_nodes: np.ndarray      # (c,)
    v_arc: np.ndarray        # (c,)
    nu: int
    nv: int

    @classmethod
    def build(cls, face: TopoDS_Face, spacing: float) -> "_FaceGrid":
        surface = BRep_Tool.Surface_s(face)
        u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
        un = np.linspace(u0, u1, _COARSE)
        vn = np.linspace(v0, v1, _COARSE)
        uu, vv = np.meshgrid(un, vn, indexing="ij")
        pts = _evaluate(surface, uu.ravel(), vv.ravel()).reshape(_COARSE, _COARSE, 3)
        du = np.linalg.norm(np.diff(pts, axis=0), axis=2)  # (c-1, c): along u, one column per v line
        dv = np.linalg.norm(np.diff(pts, axis=1), axis=2)  # (c, c-1)
        length_u = du.sum(axis=0).max()
        length_v = dv.sum(axis=1).max()
        nu = max(1, math.ceil(length_u / spacing))
        nv = max(1, math.ceil(length_v / spacing))
        classifier = BRepTopAdaptor_FClass2d(face, Precision.PConfusion_s())
        return cls(face, surface, classifier, un, _arc_map(du.T), vn, _arc_map(dv), nu, nv)

    def uv(self, s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Parameters ``(m, 2)`` of grid coordinates ``s (m,)`` in ``[0, nu]``, ``t (m,)`` in ``[0, nv]``."""
        u = np.interp(np.clip(s / self.nu, 0.0, 1.0), self.u_arc, self.u_nodes)
        v = np.interp(np.clip(t / self.nv, 0.0, 1.0), self.v_arc, self.v_nodes)
        return np.column_stack([u, v])

    def cell_centres(self, refine: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Grid coordinates ``s (nu*nv*refine**2,)``, ``t (...)`` of the cell centres, ``refine`` times finer."""
        s = (np.arange(self.nu * refine) + 0.5) / refine
        t = (np.arange(self.nv * refine) + 0.5) / refine
        ss, tt = np.meshgrid(s, t, indexing="ij")
        return ss.ravel(), tt.ravel()

    def inside(self, uv: np.ndarray) -> np.ndarray:
        """Mask ``(m,)``: the parameters ``uv (m, 2)`` lie strictly inside the trimmed face."""
        return np.array([self.classifier.Perform(gp_Pnt2d(a, b)) == TopAbs_IN for a, b in uv.tolist()],
                        dtype=bool)

    def samples(self) -> tuple[np.ndarray, np.ndarray]:
        """``(uv (m, 2), points (m, 3))`` at the cell centres inside the face.

        A face smaller than a cell gets its grid doubled (up to ``_MAX_REFINE`` times) until at least one
        sample falls inside.
        """
        for level in range(_MAX_REFINE + 1):
            uv = self.uv(*self.cell_centres(2 ** level))
            uv = uv[self.inside(uv)]
            if len(uv):
                break
        return uv, _evaluate(self.surface, uv[:, 0], uv[:, 1])


def face_samples(shape: TopoDS_Shape, spacing: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Roughly uniform samples, about ``spacing`` mm apart in 3D, inside every face of ``shape``.

    Returns
    -------
    list over faces (project numbering, see :func:`face_list`) of ``(uv (m, 2), points (m, 3))``:
    parameters on ``BRep_Tool.Surface_s(face)`` and the global points there.  Only points classified
    ``TopAbs_IN`` by ``BRepTopAdaptor_FClass2d`` are kept (none on the boundary).  The grid is the cell
    centres of a grid uniform in mean arc length over ``BRepTools.UVBounds_s(face)``; a face smaller than a
    cell still gets at least one sample.
    """
    if not spacing > 0:
        raise ValueError(f"spacing must be positive, got {spacing!r}")
    out = []
    for k, face in enumerate(face_list(shape)):
        uv, pts = _FaceGrid.build(face, spacing).samples()
        log.debug("face %d: %d samples", k, len(uv))
        out.append((uv, pts))
    return out


def _edge_points(edge: TopoDS_Edge, spacing: float, ends: bool) -> np.ndarray:
    """Points ``(m, 3)`` about ``spacing`` apart (uniform in arc length) along an edge.

    ``ends``: include the two end points; otherwise only interior points (none for an edge shorter than
    about 1.5 spacings).  Degenerated edges give no points.
    """
    if BRep_Tool.Degenerated_s(edge):
        return np.empty((0, 3))
    curve = BRepAdaptor_Curve(edge)
    length = GCPnts_AbscissaPoint.Length_s(curve)
    n_seg = max(1, round(length / spacing))
    if n_seg == 1:
        params = [curve.FirstParameter(), curve.LastParameter()]
    else:
        uniform = GCPnts_UniformAbscissa(curve, n_seg + 1)
        if not uniform.IsDone() or uniform.NbPoints() != n_seg + 1:
            params = np.linspace(curve.FirstParameter(), curve.LastParameter(), n_seg + 1).tolist()
        else:
            params = [uniform.Parameter(i) for i in range(1, n_seg + 2)]
    if not ends:
        params = params[1:-1]
    return np.array([_pnt(curve.Value(t)) for t in params]).reshape(-1, 3)


def fe_surface_nodes(shape: TopoDS_Shape, spacing: float, seed: int = 0, jitter: float = 0.3,
                     clearance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """An FE-like surface node set of ``shape``, as a surface mesh of about ``spacing`` mm would have.

    * every vertex once;
    * every edge once (even though two faces share it): its interior points, uniform in arc length, about
      ``spacing`` apart;
    * inside every face, the grid of :func:`face_samples` with each point moved by a uniform random offset
      of up to ``jitter`` cells in each grid direction, kept only if still inside the face and at least
      ``clearance`` (default ``spacing / 3``) from the face's boundary, so they do not crowd the edge nodes.

    Parameters
    ----------
    shape : the solid (or any shape with faces).
    spacing : target node distance in mm.
    seed : seed of the jitter; the result is deterministic for a given seed.
    jitter : largest offset in grid cells, 0 <= jitter < 0.5.
    clearance : least 3D distance (mm) of a face node from its face's edges.

    Returns
    -------
    points : (N, 3) float array, node positions in mm (vertices, then edge nodes, then face nodes).
    face_index : (N,) int array, the face (project numbering) of a face node, -1 for vertex and edge nodes.
    """
    if not spacing > 0:
        raise ValueError(f"spacing must be positive, got {spacing!r}")
    if not 0 <= jitter < 0.5:
        raise ValueError(f"jitter must be in [0, 0.5), got {jitter!r}")
    clearance = spacing / 3 if clearance is None else float(clearance)
    rng = np.random.default_rng(seed)

    vmap = index_map(shape, TopAbs_VERTEX)
    vertices = np.array([_pnt(BRep_Tool.Pnt_s(TopoDS.Vertex_s(vmap.FindKey(i))))
                         for i in range(1, vmap.Extent() + 1)]).reshape(-1, 3)

    emap = index_map(shape, TopAbs_EDGE)
    edges = [TopoDS.Edge_s(emap.FindKey(i)) for i in range(1, emap.Extent() + 1)]
    edge_nodes = [_edge_points(e, spacing, ends=False) for e in edges]
    dense = [_edge_points(e, spacing / 8, ends=True) for e in edges]  # boundary polylines for clearance

    face_pts, face_idx = [], []
    for k, face in enumerate(face_list(shape)):
        grid = _FaceGrid.build(face, spacing)
        s, t = grid.cell_centres()
        s = s + rng.uniform(-jitter, jitter, len(s))
        t = t + rng.uniform(-jitter, jitter, len(t))
        uv = grid.uv(s, t)
        uv = uv[grid.inside(uv)]
        pts = _evaluate(grid.surface, uv[:, 0], uv[:, 1])
        fmap = index_map(face, TopAbs_EDGE)
        fvmap = index_map(face, TopAbs_VERTEX)
        boundary = [dense[emap.FindIndex(fmap.FindKey(i)) - 1] for i in range(1, fmap.Extent() + 1)]
        boundary += [vertices[vmap.FindIndex(fvmap.FindKey(i)) - 1][None] for i in range(1, fvmap.Extent() + 1)]
        boundary = np.concatenate(boundary) if boundary else np.empty((0, 3))
        if len(pts) and len(boundary):
            dist, _ = cKDTree(boundary).query(pts)
            pts = pts[dist >= clearance]
        log.debug("face %d: %d interior nodes", k, len(pts))
        face_pts.append(pts)
        face_idx.append(np.full(len(pts), k))

    points = np.concatenate([vertices, *edge_nodes, *face_pts]) if face_pts else np.concatenate(
        [vertices, *edge_nodes])
    n_boundary = len(vertices) + sum(len(e) for e in edge_nodes)
    face_index = np.concatenate([np.full(n_boundary, -1), *face_idx]).astype(int)
    log.debug("fe_surface_nodes: %d vertex, %d edge, %d face nodes", len(vertices),
              n_boundary - len(vertices), len(points) - n_boundary)
    return points, face_index


def _skin(shape: TopoDS_Shape, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Face samples ``(m, 3)`` about ``spacing`` apart over all faces and their outward unit normals
    ``(m, 3)`` (the surface normal, flipped on reversed faces)."""
    points, normals = [], []
    for face in face_list(shape):
        grid = _FaceGrid.build(face, spacing)
        uv, pts = grid.samples()
        flip = -1.0 if face.Orientation() == TopAbs_REVERSED else 1.0
        nrm = np.empty_like(pts)
        for i, (u, v) in enumerate(uv.tolist()):
            props = GeomLProp_SLProps(grid.surface, u, v, 1, Precision.Confusion_s())
            nrm[i] = _pnt(props.Normal()) if props.IsNormalDefined() else (np.nan, np.nan, np.nan)
        points.append(pts)
        normals.append(flip * nrm)
    return np.concatenate(points), np.concatenate(normals)


def volume_nodes(shape: TopoDS_Shape, n: int, seed: int = 0, margin: float = 0.5,
                 max_candidates: int = 2_000_000) -> np.ndarray:
    """Random points strictly inside the solid ``shape``, at least ``margin`` mm from its surface.

    They mimic the volume nodes of a tetrahedral mesh.  Candidates are uniform in the bounding box shrunk by
    ``margin``; a candidate is kept when ``BRepClass3d_SolidClassifier`` says ``TopAbs_IN`` and its distance
    to the faces of the shape (``BRepExtrema_DistShapeShape`` against a vertex) is at least ``margin``.

    Two cheap numpy tests against dense face samples skip most kernel calls: a candidate closer than
    ``margin`` to a sample is closer than that to the surface (exact rejection), and one on the outer side
    of its nearest sample's tangent plane is taken as outside.  The latter may wrongly drop a few inside
    points near concave regions (a slight bias of the distribution, never a wrong point): every kept point
    passed both kernel tests.

    Returns
    -------
    (n, 3) float array of points in mm, deterministic for a given seed.

    Raises
    ------
    ValueError : fewer than ``n`` points found among ``max_candidates`` candidates (margin too large for a
        thin part, or not a solid).
    """
    if n < 0:
        raise ValueError(f"n must be non-negative, got {n!r}")
    if not margin > 0:
        raise ValueError(f"margin must be positive, got {margin!r}")
    rng = np.random.default_rng(seed)
    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(shape, box, False, False)
    lo = np.array(box.CornerMin().Coord()) + margin
    hi = np.array(box.CornerMax().Coord()) - margin
    if np.any(hi <= lo):
        raise ValueError(f"margin {margin} mm leaves no room inside the bounding box")
    diagonal = float(np.linalg.norm(hi - lo)) + 2.0 * math.sqrt(3.0) * margin
    skin_points, skin_normals = _skin(shape, max(margin, diagonal / 200.0))
    tree = cKDTree(skin_points)
    classifier = BRepClass3d_SolidClassifier(shape)
    tol = Precision.Confusion_s()
    # The distance to the solid itself is 0 inside it: measure to the compound of its faces instead.
    skin = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(skin)
    for face in face_list(shape):
        builder.Add(skin, face)
    dist = BRepExtrema_DistShapeShape()
    dist.LoadS1(skin)
    found: list[np.ndarray] = []
    tried = 0
    batch = max(256, 16 * n)
    while len(found) < n:
        if tried >= max_candidates:
            raise ValueError(f"only {len(found)} of {n} volume nodes found with margin {margin} mm among "
                             f"{tried} candidates")
        cand = lo + (hi - lo) * rng.random((batch, 3))
        tried += batch
        near, idx = tree.query(cand)
        outer = np.einsum("ij,ij->i", cand - skin_points[idx], skin_normals[idx]) > 0.0
        for p in cand[(near >= margin) & ~outer]:
            gp = gp_Pnt(*p)
            classifier.Perform(gp, tol)
            if classifier.State() != TopAbs_IN:
                continue
            dist.LoadS2(BRepBuilderAPI_MakeVertex(gp).Vertex())
            dist.Perform()
            if dist.IsDone() and dist.Value() >= margin:
                found.append(p)
                if len(found) == n:
                    break
    log.debug("volume_nodes: %d points from %d candidates", n, tried)
    return np.array(found).reshape(-1, 3)
