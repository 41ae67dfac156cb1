"""Classifying FE nodes: which face, edge or vertex each node feeds, with its foot point (eq. 4, 27).

A node belongs to the face whose trimmed domain holds its foot point, within ``node_distance``.  A node
within ``edge_distance`` of an edge feeds that edge instead of the face interior (the sets K_u0, K_u1, K_0v,
K_1v of eq. 33-37, taken in 3D so that trimmed faces and shared edges are handled alike), and a node on a
vertex fixes that vertex.  Everything else (volume nodes, other parts) is left out and counted.

Not every node is projected onto every face: a k-d tree over points sampled inside every face's trimmed
domain names the few candidate faces of each node, and only those are asked of the kernel.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .bspline import evaluate_curve, evaluate_surface
from .field import DisplacementField
from .kernel.project import OUTSIDE, Projector
from .model import Part
from .settings import Settings

log = logging.getLogger(__name__)

#: Node roles.
IGNORED, FACE, EDGE, VERTEX = -1, 0, 1, 2


@dataclass(frozen=True, eq=False)
class Classification:
    """Where each of the N field nodes takes part.

    Attributes
    ----------
    role : (N,) int, IGNORED, FACE, EDGE or VERTEX.
    owner : (N,) int, index of the face, edge or vertex (-1 when ignored).
    uv : (N, 2) float, foot-point parameters on the owning face (NaN unless role is FACE).
    t : (N,) float, foot-point parameter on the owning edge (NaN unless role is EDGE).
    foot : (N, 3) float, the foot point S(u, v), C(t) or the vertex (NaN when ignored).
    distance : (N,) float, distance from node to its foot point (inf when ignored).
    node_distance, edge_distance : the lengths (mm) used.
    """

    role: np.ndarray
    owner: np.ndarray
    uv: np.ndarray
    t: np.ndarray
    foot: np.ndarray
    distance: np.ndarray
    node_distance: float
    edge_distance: float

    def nodes_of(self, role: int, index: int) -> np.ndarray:
        """Indices of the nodes of ``role`` owned by face, edge or vertex ``index``."""
        return np.flatnonzero((self.role == role) & (self.owner == index))

    @property
    def used(self) -> np.ndarray:
        """Mask ``(N,)`` of the nodes that take part."""
        return self.role != IGNORED


def _face_cloud(part: Part, projector: Projector, spacing: float):
    """Points ``(m, 3)`` inside every face's trimmed domain and on its edges, and their face ``(m,)``."""
    points, owners = [], []
    for face in part.faces:
        u0, u1, v0, v1 = face.uv_box
        gu, gv = np.meshgrid(np.linspace(u0, u1, 9), np.linspace(v0, v1, 9), indexing="ij")
        coarse = evaluate_surface(face.surface, gu.ravel(), gv.ravel()).reshape(9, 9, 3)
        length_u = np.linalg.norm(np.diff(coarse, axis=0), axis=2).sum(axis=0).max()
        length_v = np.linalg.norm(np.diff(coarse, axis=1), axis=2).sum(axis=1).max()
        nu = int(np.clip(np.ceil(length_u / spacing), 2, 200)) + 1
        nv = int(np.clip(np.ceil(length_v / spacing), 2, 200)) + 1
        uu, vv = np.meshgrid(np.linspace(u0, u1, nu), np.linspace(v0, v1, nv), indexing="ij")
        uv = np.column_stack([uu.ravel(), vv.ravel()])
        keep = projector.classify(face.index, uv) != OUTSIDE
        points.append(evaluate_surface(face.surface, uv[keep, 0], uv[keep, 1]))
        owners.append(np.full(int(keep.sum()), face.index))
        for use in face.uses:
            curve = part.edges[use.edge].curve
            if curve is not None:
                t = np.linspace(use.t[0], use.t[-1], max(2, int(np.ceil(_length(curve) / spacing)) + 1))
                points.append(evaluate_curve(curve, t))
                owners.append(np.full(len(t), face.index))
    return np.concatenate(points), np.concatenate(owners)


def _length(curve) -> float:
    p = evaluate_curve(curve, np.linspace(*curve.domain, 33))
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def _candidates(tree: cKDTree, owner: np.ndarray, points: np.ndarray, reach: float, margin: float,
                k: int = 24) -> dict[int, np.ndarray]:
    """Candidate owners of ``points (n, 3)``: for each owner index, the points that may lie within ``reach``
    of it.

    ``tree`` holds sample points of every owner (``owner (m,)``), at most ``margin`` apart on each owner.  A
    point whose nearest sample is ``d0`` away cannot be nearer than ``d0 - margin`` to an owner whose
    samples are all farther than ``d0 + margin``; the ``k`` nearest samples name the owners within that
    radius (samples on an edge belong to both of its faces, so both are among them near the edge).
    """
    dist, idx = tree.query(points, k=min(k, tree.n))
    dist, idx = dist.reshape(len(points), -1), idx.reshape(len(points), -1)
    keep = (dist <= dist[:, :1] + margin) & (dist[:, :1] <= reach + margin)
    node = np.repeat(np.arange(len(points)), dist.shape[1])[keep.ravel()]
    pairs = np.unique(np.column_stack([owner[idx.ravel()[keep.ravel()]], node]), axis=0)
    split = np.flatnonzero(np.diff(pairs[:, 0])) + 1
    return {int(group[0, 0]): group[:, 1] for group in np.split(pairs, split) if len(group)}


def classify_nodes(part: Part, field: DisplacementField, settings: Settings,
                   projector: Projector) -> Classification:
    """Classify the nodes of ``field`` on ``part`` (see the module docstring)."""
    node_distance, edge_distance = settings.lengths(part.diagonal)
    points = field.points
    n = len(points)
    role = np.full(n, IGNORED)
    owner = np.full(n, -1)
    uv = np.full((n, 2), np.nan)
    t = np.full(n, np.nan)
    foot = np.full((n, 3), np.nan)
    distance = np.full(n, np.inf)

    spacing = part.diagonal / 150.0
    cloud, cloud_face = _face_cloud(part, projector, spacing)
    candidates = _candidates(cKDTree(cloud), cloud_face, points, node_distance, 2.0 * spacing)

    best = np.full(n, np.inf)
    for k, nodes in candidates.items():
        nodes = np.asarray(nodes)
        f_uv, f_dist = projector.to_face(k, points[nodes])
        inside = projector.classify(k, f_uv) != OUTSIDE
        better = inside & (f_dist <= node_distance) & (f_dist < best[nodes])
        chosen = nodes[better]
        best[chosen] = f_dist[better]
        role[chosen] = FACE
        owner[chosen] = k
        uv[chosen] = f_uv[better]
    on_face = np.flatnonzero(role == FACE)
    for k in np.unique(owner[on_face]):
        idx = on_face[owner[on_face] == k]
        foot[idx] = evaluate_surface(part.faces[k].surface, uv[idx, 0], uv[idx, 1])
        distance[idx] = best[idx]

    _claim_vertices_and_edges(part, points, role, owner, uv, t, foot, distance, edge_distance, projector)
    counts = {name: int(np.sum(role == r)) for name, r in
              (("face", FACE), ("edge", EDGE), ("vertex", VERTEX), ("ignored", IGNORED))}
    log.info("classified %d nodes: %s", n, counts)
    return Classification(role, owner, uv, t, foot, distance, node_distance, edge_distance)


def _claim_vertices_and_edges(part, points, role, owner, uv, t, foot, distance, edge_distance, projector):
    """Re-assign face nodes that lie on a vertex or an edge of their face (in place)."""
    used = np.flatnonzero(role == FACE)
    if len(used) == 0:
        return
    if len(part.vertices):
        d_v, v_idx = cKDTree(part.vertices).query(points[used])
        at_vertex = d_v <= edge_distance
        idx = used[at_vertex]
        role[idx], owner[idx] = VERTEX, v_idx[at_vertex]
        foot[idx], distance[idx] = part.vertices[v_idx[at_vertex]], d_v[at_vertex]
        uv[idx] = np.nan
        used = used[~at_vertex]
    edge_ids = [e.index for e in part.edges if not e.degenerate]
    if not edge_ids or len(used) == 0:
        return
    # Edge points at spacing h: a node within edge_distance of a curve is within edge_distance + h of them.
    samples, sample_edge, h = [], [], part.diagonal / 400.0
    for e in edge_ids:
        curve = part.edges[e].curve
        s = np.linspace(*curve.domain, max(2, int(np.ceil(_length(curve) / h)) + 1))
        samples.append(evaluate_curve(curve, s))
        sample_edge.append(np.full(len(s), e))
    samples, sample_edge = np.concatenate(samples), np.concatenate(sample_edge)
    tree = cKDTree(samples)
    near, _ = tree.query(points[used])
    close = near <= edge_distance + h
    per_edge: dict[int, list[int]] = {}
    for e, nodes in _candidates(tree, sample_edge, points[used[close]], edge_distance, h).items():
        nodes = used[close][nodes]
        nodes = nodes[np.isin(owner[nodes], part.edges[e].faces)]
        if len(nodes):
            per_edge[e] = list(nodes)
    best = np.full(len(points), np.inf)
    for e, nodes in per_edge.items():
        nodes = np.asarray(nodes)
        e_t, e_dist = projector.to_edge(e, points[nodes])
        hit = (e_dist <= edge_distance) & (e_dist < best[nodes])
        idx = nodes[hit]
        best[idx] = e_dist[hit]
        role[idx], owner[idx], t[idx], uv[idx] = EDGE, e, e_t[hit], np.nan
    on_edge = np.flatnonzero(np.isfinite(best))
    for e in np.unique(owner[on_edge]):
        idx = on_edge[owner[on_edge] == e]
        foot[idx] = evaluate_curve(part.edges[e].curve, t[idx])
        distance[idx] = best[idx]
