"""Classifying FE nodes: which face, edge or vertex each node feeds, with its foot point (eq. 4, 27).

A node belongs to the face whose trimmed domain holds its foot point, within ``node_distance``.  A node
within ``edge_distance`` of an edge feeds that edge instead of the face interior (the sets K_u0, K_u1, K_0v,
K_1v of eq. 33-37, taken in 3D so that trimmed faces and shared edges are handled alike), and a node on a
vertex fixes that vertex.  Everything else (volume nodes, other parts) is left out and counted.

Not every node is projected onto every face: a k-d tree over points sampled inside every face's trimmed
domain names the few candidate faces of each node.  On those, the foot points are found by Newton's method
for all nodes of a face at once (:mod:`hot2cold.core.footpoint`), each node started at the nearest point of a
grid dense only where the face bends (knot span by knot span, :func:`start_grid`), and again from the far
side of a thin edge where a start there is among its nearest and the node did not settle on the face
(:func:`_foot_points`); the kernel's ``GeomAPI_ProjectPointOnSurf`` settles what Newton leaves open (a few per
thousand nodes, near the faces' borders).  The nodes near an edge are projected onto its curve the same way,
from the nearest of the edge's samples (:meth:`_Boundary.edge_feet`), the kernel's
``GeomAPI_ProjectPointOnCurve`` only where Newton does not settle (a foot point at the curve's end).  The
result is the kernel's: the same faces, distances and parameters to 1e-9 as every node projected onto every
face (``tests/test_footpoint.py``, ``benchmarks/scale.py``; ``docs/benchmarks/speed.md`` gives how much faster,
on Rotor 37 and the thin blade of ``sample_parts/thin_blade.step``).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from ..core.threads import map_threads
from ..core.trees import kd_tree, query
from ..core.bspline import (bend_parameters, cut_intervals, evaluate_curve, evaluate_surface, grid_points,
                            polyline_length, surface_normals)
from ..io.field import DisplacementField
from ..core.footpoint import FootPoints, project_to_curve, project_to_surface
from ..core.domain import Trim
from ..core.arrays import distinct, runs
from ..core.model import Classification, Part, Role
from ..settings import Settings

if TYPE_CHECKING:                              # the kernel's projector is passed in, not built here
    from ..kernel.project import Projector

log = logging.getLogger(__name__)

#: Most points of a face's start grid along one parameter direction.
_MOST = 2000
#: The spacing of the start grids, times the part's diagonal.
START_SPACING = 1 / 150
#: The sample points that name each node's candidate faces (:func:`_face_cloud`) lie about the spacing of the
#: start grids apart, or closer, down to ``CLOUD_FINEST`` of the diagonal, where the nodes are more than
#: ``CLOUD_NODES`` times as many as the samples would be: a node's candidates are the faces with a sample
#: within two spacings of its nearest sample, and each pair of node and face costs a projection.  On a thin
#: blade under many nodes, samples at the start grids' spacing name both sides of the blade for many nodes,
#: and finer ones save more projections than they cost.  With fewer nodes the samples' own cost (each one's
#: trim state asked of the kernel) outweighs what they save, hence the finer spacing only past ``CLOUD_NODES``.
CLOUD_FINEST, CLOUD_NODES = 1 / 300, 10
#: Most sample points of the cloud along a face's parameter direction.
_CLOUD_MOST = 400


def _lengths(face, n: int = 9) -> tuple[float, float]:
    """Longest u and v parameter lines of ``face`` (mm) on an ``n x n`` grid over its box."""
    u0, u1, v0, v1 = face.uv_box
    points = grid_points(face.surface, np.linspace(u0, u1, n), np.linspace(v0, v1, n))       # (n, n, 3)
    length_u = float(np.linalg.norm(np.diff(points, axis=0), axis=2).sum(axis=0).max())
    length_v = float(np.linalg.norm(np.diff(points, axis=1), axis=2).sum(axis=1).max())
    return length_u, length_v


def cloud_spacing(lengths: list[tuple[float, float]], nodes: int, diagonal: float) -> float:
    """The spacing (mm) of :func:`_face_cloud`'s samples on faces whose longest parameter lines are ``lengths``
    (mm, per face), for ``nodes`` nodes: ``START_SPACING`` of the ``diagonal``, or closer, down to
    ``CLOUD_FINEST`` of it, where the samples would be fewer than ``1 / CLOUD_NODES`` of the nodes."""
    area = sum(length_u * length_v for length_u, length_v in lengths)
    wanted = np.sqrt(CLOUD_NODES * area / max(nodes, 1))
    return float(np.clip(wanted, CLOUD_FINEST * diagonal, START_SPACING * diagonal))


def _face_cloud(part: Part, projector: Projector, lengths: list[tuple[float, float]], spacing: float
                ) -> tuple[np.ndarray, np.ndarray, float]:
    """Points ``(m, 3)`` about ``spacing`` (mm, :func:`cloud_spacing`) apart inside every face's trimmed domain
    and on its boundary (the face's surface at its pcurves), their face ``(m,)`` and that spacing: they name
    each node's candidate faces.  ``lengths``: the faces' :func:`_lengths`."""
    points, owners = [], []
    for face, (length_u, length_v) in zip(part.faces, lengths):
        u0, u1, v0, v1 = face.uv_box
        nu = int(np.clip(np.ceil(length_u / spacing), 2, _CLOUD_MOST)) + 1
        nv = int(np.clip(np.ceil(length_v / spacing), 2, _CLOUD_MOST)) + 1
        uu, vv = np.meshgrid(np.linspace(u0, u1, nu), np.linspace(v0, v1, nv), indexing="ij")
        uv = np.column_stack([uu.ravel(), vv.ravel()])
        uv = np.concatenate([uv[projector.classify(face.index, uv) != Trim.OUTSIDE]] +
                            [_dense(use.uv, spacing, face) for use in face.uses])
        uv = np.clip(uv, face.surface.domain[::2], face.surface.domain[1::2])
        points.append(evaluate_surface(face.surface, uv[:, 0], uv[:, 1]))
        owners.append(np.full(len(uv), face.index))
    return np.concatenate(points), np.concatenate(owners), spacing


def start_grid(face, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Newton's starts on ``face``: grid points ``(m, 3)`` over its parameter box and their ``uv (m, 2)``, at
    most about ``spacing`` apart, and closer where the face bends: about its radius of curvature apart
    across a bend, knot span by knot span and direction by direction (:func:`~hot2cold.core.bspline.
    bend_parameters`), so that a thin edge makes only the spans round it dense; evaluated as a tensor
    product (:func:`~hot2cold.core.bspline.grid_points`).

    A node starts at the nearest of them, which must lie on the node's own side of a thin trailing edge:
    with a trailing edge sampled more coarsely than it is thick, a node's nearest start can be on the far
    side, and Newton settles there, on a foot point several times farther than its own.  (These grids are not
    used to name the candidate faces: a densely sampled face would crowd its neighbours out of a node's nearest
    samples.)
    """
    surface = face.surface
    d = surface.domain
    box = np.clip(face.uv_box, [d[0], d[0], d[2], d[2]], [d[1], d[1], d[3], d[3]])
    u, v = bend_parameters(surface, box, spacing, _MOST)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    return grid_points(surface, u, v).reshape(-1, 3), np.column_stack([uu.ravel(), vv.ravel()])


class Starts:
    """Newton's starts on every face of a part (:func:`start_grid`, ``START_SPACING`` of its diagonal apart) and
    a k-d tree over each face's, made for a face when first asked and kept, and the clouds that name each
    node's candidate faces (:meth:`cloud`): the check of a field's positions (:func:`part_distances`) and the
    classification of its nodes (:func:`classify_nodes`) start from the same.  Faces may be asked for from
    several threads at once (each face by one)."""

    def __init__(self, part: Part):
        self.spacing = START_SPACING * part.diagonal
        self._part = part
        self._faces: dict[int, tuple[np.ndarray, np.ndarray, cKDTree]] = {}
        self._lengths: list[tuple[float, float]] | None = None
        self._clouds: dict[float, tuple[np.ndarray, np.ndarray, float]] = {}

    def cloud(self, projector: Projector, nodes: int) -> tuple[np.ndarray, np.ndarray, float]:
        """:func:`_face_cloud` for ``nodes`` nodes, kept by its spacing: a check of a sample of the nodes and
        the classification of them all share it where their numbers give the same spacing (the coarsest, for
        most parts)."""
        if self._lengths is None:
            self._lengths = [_lengths(face) for face in self._part.faces]
        spacing = cloud_spacing(self._lengths, nodes, self._part.diagonal)
        if spacing not in self._clouds:
            self._clouds[spacing] = _face_cloud(self._part, projector, self._lengths, spacing)
        return self._clouds[spacing]

    def of(self, k: int) -> tuple[np.ndarray, np.ndarray, cKDTree]:
        """Face ``k``'s start points ``(m, 3)``, their ``uv (m, 2)`` and a k-d tree over the points."""
        found = self._faces.get(k)
        if found is None:
            grid, grid_uv = start_grid(self._part.faces[k], self.spacing)
            found = self._faces[k] = (grid, grid_uv, kd_tree(grid))
        return found


def _dense(uv: np.ndarray, spacing: float, face) -> np.ndarray:
    """The pcurve polyline ``uv (m, 2)`` with points added so that they lie at most about ``spacing`` apart
    on the surface."""
    pts = evaluate_surface(face.surface, *np.clip(uv, face.surface.domain[::2], face.surface.domain[1::2]).T)
    steps = np.maximum(1, np.ceil(np.linalg.norm(np.diff(pts, axis=0), axis=1) / spacing)).astype(int)
    return cut_intervals(uv, steps)


def curve_length(curve) -> float:
    """Length (mm) of ``curve``, as a polyline of 33 points."""
    return polyline_length(evaluate_curve(curve, np.linspace(*curve.domain, 33)))


#: A sample's clearance (:func:`_clearance`) is looked for among this many of its nearest samples: the
#: more, the farther it reaches where a face's own samples surround the sample, and the more nodes
#: :func:`_candidates` finds alone (each node not alone is asked for its ``k`` nearest samples).
CLEARANCE_NEIGHBOURS = 48


def _clearance(tree: cKDTree, owner: np.ndarray, samples: np.ndarray, k: int) -> np.ndarray:
    """Per sample of ``samples (s,)`` (rows of ``tree``): how far at least (mm, ``(s,)``) the nearest sample of
    another owner lies, the distance to it among the sample's ``k`` nearest, or to the ``k``-th nearest where
    none of them is another owner's."""
    k = min(k, tree.n)
    dist, idx = query(tree, tree.data[samples], k=k)
    dist, idx = dist.reshape(len(samples), k), idx.reshape(len(samples), k)
    other = owner[idx] != owner[samples, None]
    first = other.argmax(axis=1)
    return np.where(other.any(axis=1), dist[np.arange(len(samples)), first], dist[:, -1])


def _candidates(tree: cKDTree, owner: np.ndarray, points: np.ndarray, reach: float, margin: float,
                k: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Candidate owners of ``points (n, 3)``: the pairs (point, owner) where the point may lie within
    ``reach`` of the owner.

    ``tree`` holds sample points of every owner (``owner (m,)``), at most ``margin`` apart on each owner.  A
    point whose nearest sample is ``d0`` away cannot be nearer than ``d0 - margin`` to an owner whose
    samples are all farther than ``d0 + margin``; the ``k`` nearest samples name the owners within that
    radius (samples on an edge belong to both of its faces, so both are among them near the edge).

    Most points see one owner only, and need not be asked for ``k`` samples: every sample within
    ``d0 + margin`` of a point lies within ``2 d0 + margin`` of its nearest sample, so where that sample's
    :func:`_clearance` is larger, its owner is the point's only one (the same pair as from its ``k``
    nearest).  The clearance is found for the samples nearest to some point only (a part of many faces has
    many more samples than a field of a few thousand nodes has nearest ones).

    Returns ``point (c,)`` and ``owner (c,)``, sorted by owner and then point.
    """
    k = min(k, tree.n)
    d0, i0 = query(tree, points)
    nearest, at = np.unique(i0, return_inverse=True)
    clearance = _clearance(tree, owner, nearest, CLEARANCE_NEIGHBOURS)[at]
    alone = (clearance > 2.0 * d0 + margin) & (d0 <= reach + margin)
    one = np.flatnonzero(alone)
    keys = [owner[i0[one]].astype(np.int64) * len(points) + one]
    rest = np.flatnonzero(~alone)
    dist, idx = query(tree, points[rest], k=k)
    dist, idx = dist.reshape(len(rest), k), idx.reshape(len(rest), k)
    keep = (dist <= dist[:, :1] + margin) & (dist[:, :1] <= reach + margin)
    own = np.where(keep, owner[idx], -1)
    own.sort(axis=1)                                 # each point's owners in a row, once each: where they change
    rows, cols = np.nonzero((own >= 0) & np.concatenate([np.ones((len(rest), 1), bool), np.diff(own, axis=1) != 0],
                                                        axis=1))
    keys.append(own[rows, cols].astype(np.int64) * len(points) + rest[rows])
    key = np.sort(np.concatenate(keys))
    return key % len(points), key // len(points)


def classify_nodes(part: Part, field: DisplacementField, settings: Settings,
                   projector: Projector, starts: Starts | None = None) -> Classification:
    """Classify the nodes of ``field`` on ``part`` (see the module docstring), Newton started from ``starts``
    (None: made here).

    Each solid (and the free faces beside them, as one more group) classifies the nodes on its own: a node
    on two coincident faces of touching solids feeds both.  Row i < N of the result is field node i, in the
    group where it lies nearest; a node that feeds further solids gets one more row each, after the N
    (``Classification.node`` names its field row; :meth:`DisplacementField.take` gives the field of the rows).
    """
    node_distance, edge_distance = settings.lengths(part.diagonal)
    points = field.points
    n = len(points)
    starts = starts if starts is not None else Starts(part)
    cloud, cloud_face, apart = starts.cloud(projector, n)
    pair_node, pair_face = _candidates(cKDTree(cloud), cloud_face, points, node_distance, 2.0 * apart)
    reach = _Reach(part, _Boundary.of(part), projector, node_distance, edge_distance)
    group_of_face = np.array([face.solid for face in part.faces], int)
    groups = distinct(group_of_face)
    records = []
    for g in groups:
        keep = group_of_face[pair_face] == g if len(groups) > 1 else slice(None)
        records.append(_classify_group(reach, points, (pair_node[keep], pair_face[keep]), starts,
                                       settings.threads).arrays())
    if len(records) == 1:
        role, owner, uv, t, foot, distance = records[0]
        node = np.arange(n)
    else:
        dist = np.stack([r[5] for r in records])                  # (G, N), inf where a group leaves the node
        first = np.argmin(dist, axis=0)
        rows = [np.arange(n)]
        picks = [(first, np.arange(n))]
        for g in range(len(records)):
            also = np.flatnonzero(np.isfinite(dist[g]) & (first != g))
            rows.append(also)
            picks.append((np.full(len(also), g), also))
        node = np.concatenate(rows)
        role, owner, uv, t, foot, distance = (
            np.concatenate([np.stack([r[a] for r in records])[w, i] for w, i in picks]) for a in range(6))
        if len(node) > n:
            log.info("%d nodes lie on faces of two or more solids (or free faces): each feeds them all",
                     len(distinct(node[n:])))
    counts = {name: int(np.sum(role == r)) for name, r in
              (("face", Role.FACE), ("edge", Role.EDGE), ("vertex", Role.VERTEX), ("ignored", Role.IGNORED))}
    log.info("classified %d nodes: %s", n, counts)
    return Classification(role, owner, uv, t, foot, distance, node_distance, edge_distance, node=node)


def part_distances(part: Part, points: np.ndarray, projector: Projector, reach: float,  # noqa: PLR0913
                   threads: int = 1, starts: Starts | None = None, *, asked: int | None = None) -> np.ndarray:
    """The distance ``(n,)`` (mm) of each of ``points (n, 3)`` to the nearest face of ``part`` where it is within
    ``reach``, inf elsewhere: a quick look at where points lie, for the checks of a field before the morph.

    The candidate faces and Newton's foot points are :func:`classify_nodes`' (foot points inside the face's
    trimmed domain or on its border); nothing is asked of the kernel, so a point Newton leaves open, or whose
    nearest point is on an edge that its faces' foot points miss, comes back farther (inf) than it is.
    ``asked``: the number of points the candidate clouds are made for (:meth:`Starts.cloud`; None: ``n``), so
    that points asked about in several calls are looked at as in one.
    """
    points = np.asarray(points, float).reshape(-1, 3)
    best = np.full(len(points), np.inf)
    if not len(points):
        return best
    starts = starts if starts is not None else Starts(part)
    cloud, cloud_face, apart = starts.cloud(projector, len(points) if asked is None else asked)
    pair_node, pair_face = _candidates(cKDTree(cloud), cloud_face, points, reach, 2.0 * apart)
    faces = [(k, pair_node[group]) for k, group in runs(pair_face)]
    on_surface = ON_SURFACE * part.diagonal
    feet = map_threads(lambda job: _foot_points(part.faces[job[0]], points[job[1]], starts.of(job[0]),
                                                projector.face_box(job[0]), on_surface), faces, threads,
                       cost=[len(nodes) for _, nodes in faces])
    for (k, nodes), fp in zip(faces, feet):
        inside = _inside(projector, k, fp.uv, fp.settled & (fp.distance <= reach) & (fp.distance < best[nodes]))
        best[nodes[inside]] = fp.distance[inside]
    return best


def _inside(projector: Projector, k: int, uv: np.ndarray, near: np.ndarray) -> np.ndarray:
    """Which of the foot points ``uv (m, 2)`` on face ``k`` lie in its trimmed domain (or on its border),
    ``(m,)`` bool: those of ``near (m,)`` asked of the projector, the rest not inside."""
    inside = np.zeros(len(uv), bool)
    inside[near] = projector.classify(k, uv[near]) != Trim.OUTSIDE
    return inside


#: Starts a node looks among for one on the far side of a thin edge (:func:`_foot_points`).
_FAR_SIDE_STARTS = 16
#: A node whose foot point from its nearest start lies within this share of the part's diagonal lies on the
#: face: no foot point on the far side of a thin edge is nearer (the surface would have to pass within it
#: twice, a wall thinner than any kernel tolerance), and none is looked for (:func:`_foot_points`).
ON_SURFACE = 1e-9


def _foot_points(face, points: np.ndarray, start: tuple[np.ndarray, np.ndarray, cKDTree], box,
                 on_surface: float) -> FootPoints:
    """Foot points of ``points (m, 3)`` on ``face`` by Newton's method (:func:`project_to_surface` within
    ``box``), each started at the nearest point of the face's :func:`start_grid` (``start``: its points, their
    uv and a k-d tree over the points, :meth:`Starts.of`), and again at the nearest
    of its ``_FAR_SIDE_STARTS`` nearest starts whose normal points the other way, where there is one: the
    far side of a thin edge.  Where both settle, the nearer foot point is kept.  A point that settles within
    ``on_surface`` (mm) of the face from its nearest start lies on it, and is not started again (a negative
    ``on_surface``: every point is).

    The start grid is dense across a bend but not along it (a trailing edge's spacing across is its radius,
    along it the plain spacing): a node well off the surface next to a thin edge, nearer to a grid line
    of the far side than to one of its own, started there and settled on the far side's minimum (nodes off a
    trailing edge by more than its thickness, as in ``tests/test_g1_trimmed.py``: foot points farther than the
    nearest)."""
    surface = face.surface
    grid, grid_uv, tree = start
    k = min(_FAR_SIDE_STARTS, len(grid))
    _, first = query(tree, points)
    fp = project_to_surface(surface, points, grid_uv[first], box)
    ask = np.flatnonzero(~(fp.settled & (fp.distance <= on_surface)))
    if k < 2 or not len(ask):
        return fp
    _, near = query(tree, points[ask], k=k)
    near = near.reshape(len(ask), k)
    used = np.zeros(len(grid), bool)                          # the normals of those starts only
    used[near.ravel()] = used[first[ask]] = True
    asked = np.flatnonzero(used)
    at = np.cumsum(used) - 1                                  # a start's row among the asked ones
    normal = surface_normals(surface, grid_uv[asked, 0], grid_uv[asked, 1])               # (asked, 3)
    nearest = normal[at[first[ask]]]                                                        # (a, 3)
    opposed = np.zeros(near.shape, bool)     # a column at a time: (a, k, 3) normals were 384 MB at 1 M nodes
    with np.errstate(invalid="ignore"):
        for j in range(1, k):
            opposed[:, j] = np.einsum("mc,mc->m", normal[at[near[:, j]]], nearest) < 0.0    # NaN compares False
    hit = opposed.any(axis=1)
    if not hit.any():
        return fp
    again = ask[hit]
    other = project_to_surface(surface, points[again], grid_uv[near[hit, opposed[hit].argmax(axis=1)]], box)
    # a node Newton left open from its nearest start stays open: the kernel finds its nearest foot point
    better = other.settled & fp.settled[again] & (other.distance < fp.distance[again])
    rows = again[better]
    uv, distance = fp.uv.copy(), fp.distance.copy()
    uv[rows], distance[rows] = other.uv[better], other.distance[better]
    return FootPoints(uv, distance, fp.settled)


@dataclass(frozen=True, eq=False)
class _Reach:
    """How a group of faces classifies: the part, its boundary's trees, the projector, and the distances (mm)
    within which a node belongs to a face (``node``) or to an edge or vertex (``edge``)."""

    part: Part
    boundary: _Boundary
    projector: Projector
    node: float
    edge: float


@dataclass(frozen=True, eq=False)
class _FaceFeet:
    """Foot points of ``m`` nodes on one face, as offered to the nodes (:func:`_classify_group`).

    Attributes
    ----------
    uv : (m, 2) float, the foot points' parameters.
    distance : (m,) float, node to foot point (mm).
    inside : (m,) bool, the foot point was asked about (near enough) and lies in the face's trimmed domain.
    foot : (m, 3) float, the foot point on the surface where ``inside``, NaN elsewhere.
    """

    uv: np.ndarray
    distance: np.ndarray
    inside: np.ndarray
    foot: np.ndarray

    @classmethod
    def of(cls, face, projector: Projector, feet: FootPoints, near: np.ndarray) -> _FaceFeet:
        """The foot points ``feet`` on ``face``, those of ``near (m,)`` classified in its trimmed domain (the rest
        are not inside) and evaluated where inside: the per-node work of a face, done in the face's thread."""
        inside = _inside(projector, face.index, feet.uv, near)
        foot = np.full((len(near), 3), np.nan)
        foot[inside] = evaluate_surface(face.surface, feet.uv[inside, 0], feet.uv[inside, 1])
        return cls(feet.uv, feet.distance, inside, foot)


def _classify_group(reach: _Reach, points: np.ndarray, pairs: tuple[np.ndarray, np.ndarray], starts: Starts,
                    threads: int = 1) -> Classification:
    """Classify ``points (N, 3)`` on the faces of the candidate ``pairs`` ``(pair_node, pair_face)`` (each
    ``(c,)``, sorted by face): their :class:`Classification`, its arrays filled in place.  The faces' foot points
    are found in up to ``threads`` threads (:func:`~hot2cold.core.threads.map_threads`), then offered to the
    nodes face by face."""
    part, projector, node_distance = reach.part, reach.projector, reach.node
    pair_node, pair_face = pairs
    n = len(points)
    rows = Classification.unclaimed(n, reach.node, reach.edge)
    role, owner, uv, foot, distance = rows.role, rows.owner, rows.uv, rows.foot, rows.distance
    best = np.full(n, np.inf)

    def offer(k: int, nodes: np.ndarray, feet: _FaceFeet) -> None:
        """Face ``k`` takes those of ``nodes`` whose foot point on it (``feet``, one row per node) is inside, near
        and nearest so far."""
        chosen = feet.inside & (feet.distance < best[nodes])
        idx = nodes[chosen]
        best[idx] = feet.distance[chosen]
        role[idx] = Role.FACE
        owner[idx] = k
        uv[idx] = feet.uv[chosen]
        foot[idx] = feet.foot[chosen]

    # Newton's method on every candidate pair first, its foot points' trim states and points on the surface in
    # the same thread; the kernel then settles the pairs it did not give to the face (a foot point on the border
    # of the face's box, mostly a node of the neighbouring face; a foot point too far or trimmed away), unless
    # the node already has a foot point elsewhere nearer than Newton's last iterate on this face (which has no
    # foot point inside the box nearer still: that would be a second local minimum within ``node_distance``).
    unsettled = []
    faces = [(k, pair_node[group], projector.face_box(k)) for k, group in runs(pair_face)]
    on_surface = ON_SURFACE * part.diagonal

    def newton(job) -> tuple[FootPoints, _FaceFeet]:
        k, nodes, box = job
        fp = _foot_points(part.faces[k], points[nodes], starts.of(k), box, on_surface)
        return fp, _FaceFeet.of(part.faces[k], projector, fp, fp.settled & (fp.distance <= node_distance))

    found = map_threads(newton, faces, threads, cost=[len(nodes) for _, nodes, _ in faces])
    for (k, nodes, _), (fp, feet) in zip(faces, found):
        offer(k, nodes, feet)
        taken = fp.settled & (owner[nodes] == k) & (best[nodes] == fp.distance)
        unsettled.append((k, nodes[~taken], fp.distance[~taken]))
    for k, nodes, last in unsettled:
        nodes = nodes[last < best[nodes]]
        if len(nodes):
            fp = FootPoints(*projector.to_face(k, points[nodes]), np.ones(len(nodes), bool))
            offer(k, nodes, _FaceFeet.of(part.faces[k], projector, fp,
                                         (fp.distance <= node_distance) & (fp.distance < best[nodes])))
        log.debug("face %d: %d foot points by the kernel", k, len(nodes))
    on_face = role == Role.FACE
    distance[on_face] = best[on_face]

    _claim_vertices_and_edges(reach, points, rows, distinct(pair_node), distinct(pair_face))
    return rows


@dataclass(frozen=True, eq=False)
class _Boundary:
    """The part's vertices and edges as k-d trees, built once for every group of faces (solid) that claims
    nodes for them.

    Attributes
    ----------
    vertices : cKDTree over the part's vertices ``(nv, 3)``, or None when it has none.
    samples : cKDTree over points along every non-degenerate edge, ``h`` apart, or None when it has none.
    sample_edge : ``(m,)`` int, the edge of each sample.
    sample_t : ``(m,)`` float, the parameter of each sample on its edge's curve.
    h : float, the sample spacing (mm): a node within d of an edge curve is within d + h of its samples.
    """

    vertices: cKDTree | None
    samples: cKDTree | None
    sample_edge: np.ndarray
    sample_t: np.ndarray
    h: float

    @classmethod
    def of(cls, part: Part) -> _Boundary:
        vertices = cKDTree(part.vertices) if len(part.vertices) else None
        samples, sample_edge, sample_t, h = [], [], [], part.diagonal / 400.0
        for edge in part.edges:
            if edge.degenerate:
                continue
            s = np.linspace(*edge.curve.domain, max(2, int(np.ceil(curve_length(edge.curve) / h)) + 1))
            samples.append(evaluate_curve(edge.curve, s))
            sample_edge.append(np.full(len(s), edge.index))
            sample_t.append(s)
        if not samples:
            return cls(vertices, None, np.zeros(0, int), np.zeros(0), h)
        return cls(vertices, cKDTree(np.concatenate(samples)), np.concatenate(sample_edge), np.concatenate(sample_t), h)

    def edge_feet(self, part: Part, projector: Projector, e: int, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Foot points of ``points (n, 3)`` on edge ``e``'s curve within its range, as
        :meth:`~hot2cold.kernel.project.Projector.to_edge` gives them (``t (n,)``, ``distance (n,)``; the nearer
        end where no foot point is nearer): by Newton's method (:func:`~hot2cold.core.footpoint.project_to_curve`)
        from the nearest of the edge's samples, the kernel where it does not settle."""
        curve = part.edges[e].curve
        mine = np.flatnonzero(self.sample_edge == e)
        _, nearest = query(cKDTree(self.samples.data[mine]), points)
        feet = project_to_curve(curve, points, self.sample_t[mine][nearest])
        t, distance = feet.t.copy(), feet.distance.copy()
        domain = np.array(curve.domain)
        to_end = np.linalg.norm(points[:, None, :] - evaluate_curve(curve, domain)[None], axis=2)   # (n, 2)
        end = np.argmin(to_end, axis=1)
        end_distance = to_end[np.arange(len(points)), end]
        nearer = end_distance <= distance
        t[nearer], distance[nearer] = domain[end[nearer]], end_distance[nearer]
        open_ = np.flatnonzero(~feet.settled)
        if len(open_):
            t[open_], distance[open_] = projector.to_edge(e, points[open_])
        return t, distance


def _claim_vertices_and_edges(reach: _Reach, points: np.ndarray, rows: Classification, candidates: np.ndarray,
                              faces: np.ndarray) -> None:
    """Re-assign face nodes of ``points (N, 3)`` that lie on a vertex or an edge of their face, and give the
    ``candidates`` (node indices ``(c,)``) no face took to a vertex or edge of ``faces`` (face indices, the
    group's) they lie on (``rows``, in place).

    A node on a corner or an edge is on every face there, but its foot point on each may be classified
    outside when the face's pcurves miss the vertex by more than the classifier's tolerance (a node a rounding
    error from the vertex, yet outside both faces there).  Such a node still fixes the vertex.
    """
    part, boundary, projector, edge_distance = reach.part, reach.boundary, reach.projector, reach.edge
    role, owner, uv, t, foot, distance = rows.arrays()
    taken = role == Role.FACE
    stray = candidates[role[candidates] == Role.IGNORED]
    used = np.concatenate([np.flatnonzero(taken), stray])
    if len(used) == 0:
        return
    in_group = np.zeros(len(part.faces), bool)
    in_group[faces] = True
    if boundary.vertices is not None:
        # (only the nodes within reach are looked for: the others come back at inf, index len(vertices))
        d_v, v_idx = query(boundary.vertices, points[used],
                           distance_upper_bound=np.nextafter(edge_distance, np.inf))
        at_vertex = d_v <= edge_distance
        v_idx = np.minimum(v_idx, len(part.vertices) - 1)
        if len(stray):
            group_vertex = np.zeros(len(part.vertices), bool)
            for edge in part.edges:
                if in_group[list(edge.faces)].any():
                    group_vertex[list(edge.vertices)] = True
            at_vertex &= taken[used] | group_vertex[v_idx]
        idx = used[at_vertex]
        role[idx], owner[idx] = Role.VERTEX, v_idx[at_vertex]
        foot[idx], distance[idx] = part.vertices[v_idx[at_vertex]], d_v[at_vertex]
        uv[idx] = np.nan
        used = used[~at_vertex]
    if boundary.samples is None or len(used) == 0:
        return
    tree, sample_edge, h = boundary.samples, boundary.sample_edge, boundary.h
    near, _ = query(tree, points[used], distance_upper_bound=np.nextafter(edge_distance + h, np.inf))
    close = used[near <= edge_distance + h]
    pair_node, pair_edge = _candidates(tree, sample_edge, points[close], edge_distance, h)
    best = np.full(len(points), np.inf)
    face_of = np.where(taken, owner, -1)           # owner turns into an edge index as edges claim nodes
    for e, group in runs(pair_edge):
        nodes = close[pair_node[group]]
        mine = np.isin(face_of[nodes], part.edges[e].faces)
        if in_group[list(part.edges[e].faces)].any():
            mine |= ~taken[nodes]
        nodes = nodes[mine]
        if not len(nodes):
            continue
        e_t, e_dist = boundary.edge_feet(part, projector, e, points[nodes])
        hit = (e_dist <= edge_distance) & (e_dist < best[nodes])
        idx = nodes[hit]
        best[idx] = e_dist[hit]
        role[idx], owner[idx], t[idx], uv[idx] = Role.EDGE, e, e_t[hit], np.nan
    on_edge = np.flatnonzero(np.isfinite(best))
    for e in distinct(owner[on_edge]):
        idx = on_edge[owner[on_edge] == e]
        foot[idx] = evaluate_curve(part.edges[e].curve, t[idx])
        distance[idx] = best[idx]
