"""The numbers behind the report's interactive 3D view (:mod:`hot2cold.views.viewer` draws them).

A :class:`Scene` holds the triangle mesh the pictures are drawn on (:func:`hot2cold.views.pictures.mesh_of`,
the hot part's faces with each vertex's ``(u, v)``), each vertex's hot position and its displacement to the
cold part at the same parameters (so any exaggeration ``hot + s * displacement`` is one multiply-add per
vertex), the deviation of the cold part from the field interpolated over the surface, the outlines of the
faces, and a subsample of the FE nodes.  Positions are relative to ``origin`` (the centre of the hot part's
bounding box), which keeps float32 precise on parts far from the global origin.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from matplotlib.ticker import MaxNLocator
from scipy.spatial import cKDTree

from ..core.arrays import distinct
from ..core.model import Role
from ..kernel.tessellate import TriangleMesh
from . import pictures

log = logging.getLogger(__name__)

#: At most this many FE nodes go into the page (a uniform random subsample, seed 0, beyond it).
MAX_NODES = 50_000

#: Nodes that interpolate the deviation at a surface vertex (inverse squared distance weights).
NEIGHBOURS = 8


@dataclass(frozen=True, eq=False)
class Scene:
    """What the 3D view shows, in mm.

    Attributes
    ----------
    origin : (3,) float array, subtracted from every position below.
    hot : (n, 3) float32 array, the mesh vertices on the hot part.
    displacement : (n, 3) float32 array, cold minus hot at each vertex (same face, same ``(u, v)``).
    deviation : (n,) float32 array, the cold part's distance from the field interpolated at each vertex from
        the errors (eq. 21) of the nodes of its face and of the face's edges; NaN on faces without nodes.
    triangles : (m, 3) int array, vertex indices, counter-clockwise seen from outside.
    triangle_face : (m,) int array, the face of each triangle.
    outlines : (e, 2) int array, vertex pairs: the boundary segments of every face.
    node_hot, node_displacement : (k, 3) float32 arrays, the FE nodes shown (k <= ``max_nodes``).
    node_deviation : (k,) float32 array, their errors (mm); NaN for ignored nodes.
    nodes_total : int, the field's nodes in all (``k`` of them are shown).
    scale_top : float, the deviation at the top of the colour scale (mm).
    displacement_top : float, the displacement magnitude at the top of its colour scale (mm): the largest of
        the vertices' and the shown nodes'.
    tolerance : float or None, the morph's tolerance (mm).
    exaggeration : float, the slider's starting factor (the report's overlay scale).
    view : (2, 3) float array, the starting view direction (towards the part) and up.
    faces : list of dict, per face its ``index``, ``name``, ``nodes``, ``delta_max``, ``delta_mean``.
    """

    origin: np.ndarray
    hot: np.ndarray
    displacement: np.ndarray
    deviation: np.ndarray
    triangles: np.ndarray
    triangle_face: np.ndarray
    outlines: np.ndarray
    node_hot: np.ndarray
    node_displacement: np.ndarray
    node_deviation: np.ndarray
    nodes_total: int
    scale_top: float
    displacement_top: float
    tolerance: float | None
    exaggeration: float
    view: np.ndarray
    faces: list[dict]


def _face_nodes(result, k: int) -> np.ndarray:
    """Entries of the classification that measure face ``k``: its own nodes and those of its edges ``(j,)``."""
    cls = result.classification
    edges = sorted({use.edge for use in result.part.faces[k].uses})
    return np.concatenate([cls.nodes_of(Role.FACE, k), *(cls.nodes_of(Role.EDGE, e) for e in edges)])


def surface_deviation(result, mesh: TriangleMesh, cold: np.ndarray, neighbours: int = NEIGHBOURS) -> np.ndarray:
    """The node errors (``result.node_errors``, eq. 21) interpolated onto the mesh vertices ``(n,)``, mm.

    Per face, each vertex's ``cold`` position ``(n, 3)`` takes the inverse-squared-distance mean of the
    errors of its ``neighbours`` nearest nodes among those of the face and its edges, placed at their cold
    targets (hot position plus displacement): a node on the other side of a thin part is never used.  NaN on
    faces without nodes and on vertices in no triangle.
    """
    field = result.field
    targets = np.asarray(field.points) + np.asarray(field.displacements)
    errors = np.asarray(result.node_errors, float)
    out = np.full(len(mesh.vertices), np.nan)
    tiny = (1e-9 * float(result.part.diagonal)) ** 2
    for k in distinct(mesh.face):
        verts = distinct(mesh.triangles[mesh.face == k])
        nodes = _face_nodes(result, int(k))
        nodes = nodes[np.isfinite(errors[nodes])]
        if not len(nodes) or not len(verts):
            continue
        j = min(neighbours, len(nodes))
        dist, near = cKDTree(targets[nodes]).query(cold[verts], k=j)
        dist, near = dist.reshape(len(verts), j), near.reshape(len(verts), j)
        weight = 1.0 / (dist ** 2 + tiny)
        out[verts] = (weight * errors[nodes][near]).sum(axis=1) / weight.sum(axis=1)
    return out


def face_outlines(mesh: TriangleMesh) -> np.ndarray:
    """Boundary segments of every face ``(e, 2)``: the triangle sides used once (each face has its own
    vertices in the mesh, so a side shared by two faces is two segments, one per face)."""
    sides = np.sort(mesh.triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, count = np.unique(sides, axis=0, return_counts=True)
    return unique[count == 1]


def scale_top(errors: np.ndarray, tolerance: float | None) -> float:
    """The top of the deviation colour scale (mm): the largest error, raised to the tolerance when that is
    less than four times higher (so the tolerance shows on the bar), and 1 mm when nothing is known."""
    finite = errors[np.isfinite(errors)]
    top = float(finite.max()) if len(finite) else 0.0
    if tolerance is not None and top < tolerance < 4.0 * max(top, 1e-300):
        top = float(tolerance)
    return top if top > 0.0 else (float(tolerance) if tolerance else 1.0)


def displacement_top(*displacements: np.ndarray) -> float:
    """The top of the displacement colour scale (mm): the largest length of the rows of ``displacements``
    (``(n, 3)`` arrays), 1 mm where all are zero or none."""
    top = max((float(np.linalg.norm(d, axis=1).max()) for d in displacements if len(d)), default=0.0)
    return top if top > 0.0 and np.isfinite(top) else 1.0


def ticks(top: float, n: int = 5) -> np.ndarray:
    """Round tick values ``(t,)`` from 0 to ``top`` for the colour bar."""
    values = MaxNLocator(n).tick_values(0.0, top)
    return values[(values >= 0.0) & (values <= top * (1 + 1e-9))]


def _subsample(n: int, most: int) -> np.ndarray:
    if n <= most:
        return np.arange(n)
    return np.sort(np.random.default_rng(0).choice(n, most, replace=False))


def _start_view(points: np.ndarray) -> np.ndarray:
    """Looking mostly along the part's thinnest axis (:func:`pictures.default_views`), turned a little
    about the other two so the part reads as a solid: direction and up ``(2, 3)``."""
    thin, middle, longest = pictures.default_views(points)
    d = thin.direction - 0.4 * middle.direction + 0.2 * longest.direction
    d = d / np.linalg.norm(d)
    return np.array([d, thin.up])


def build_scene(result, mesh: TriangleMesh | None = None, *, max_nodes: int = MAX_NODES,
                exaggeration: float | None = None) -> Scene:
    """The :class:`Scene` of ``result`` (a :class:`~hot2cold.morph.MorphResult`) on ``mesh`` (default
    :func:`pictures.mesh_of`); ``exaggeration`` starts the slider (default
    :func:`pictures.displacement_scale`)."""
    mesh = mesh if mesh is not None else pictures.mesh_of(result)
    report = result.report
    cold = pictures.cold_vertices(result, mesh)
    hot = mesh.vertices
    lo, hi = hot.min(axis=0), hot.max(axis=0)
    origin = 0.5 * (lo + hi)
    deviation = surface_deviation(result, mesh, cold)

    cls = result.classification
    first = np.flatnonzero(cls.node == np.arange(len(cls.node)))     # each field node once
    shown = first[_subsample(len(first), max_nodes)]
    errors = np.asarray(result.node_errors, float)
    tolerance = report.tolerance
    faces = [{"index": int(f.index), "name": str(getattr(f, "name", "") or ""), "nodes": int(f.nodes),
              "delta_max": _finite(f.delta_max), "delta_mean": _finite(f.delta_mean)} for f in report.faces]
    scene = Scene(
        origin=origin,
        hot=(hot - origin).astype(np.float32),
        displacement=(cold - hot).astype(np.float32),
        deviation=deviation.astype(np.float32),
        triangles=mesh.triangles,
        triangle_face=mesh.face,
        outlines=face_outlines(mesh),
        node_hot=(np.asarray(result.field.points)[shown] - origin).astype(np.float32),
        node_displacement=np.asarray(result.field.displacements)[shown].astype(np.float32),
        node_deviation=errors[shown].astype(np.float32),
        nodes_total=len(first),
        scale_top=scale_top(errors[cls.used], tolerance),
        displacement_top=displacement_top(cold - hot, np.asarray(result.field.displacements)[shown]),
        tolerance=None if tolerance is None else float(tolerance),
        exaggeration=pictures.displacement_scale(result) if exaggeration is None else float(exaggeration),
        view=_start_view(hot),
        faces=faces,
    )
    log.info("3D scene: %d vertices, %d triangles, %d of %d nodes", len(hot), len(mesh.triangles), len(shown),
             len(first))
    return scene


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None
