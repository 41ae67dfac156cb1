"""The grids of the morph's faces and edges: where the checks between the nodes, the refinement and G1 measure.

* :func:`face_grid`: parameters over a face's trimmed domain, :data:`CHECK_SPACING` x the part's diagonal apart;
* :class:`FaceGridder` makes one :class:`FaceGrid` per face: the grid, where the field's local estimate puts it
  (the FE model's own field between its nodes where its elements are taken), how far from the nodes and how
  sure (:class:`FaceNodes` holds each face's nodes across the rounds); :func:`with_slack` adds the slack the
  grids of a refinement for G1 were made without;
* :func:`edge_grids`: the same along the edges (:class:`EdgeGrid`).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..core.arrays import distinct
from ..core.threads import map_threads
from ..core.trees import kd_tree, query
from ..core.bspline import evaluate_curve, evaluate_surface, knot_breaks
from .artificial import estimated
from .classify import curve_length
from ..io.field import DisplacementField
from ..core.domain import Trim
from ..core.model import Classification, Face, Part, Role
from ..kernel.project import Projector

if TYPE_CHECKING:
    from .artificial import ElementField

log = logging.getLogger(__name__)


#: Sample spacing of the checks of the cold part, times the part's diagonal, and samples per face direction
#: at the most.
CHECK_SPACING, _CHECK_MOST = 1 / 150, 200


#: A grid point is vouched for as within the limit where its error, doubt included, is within this share of
#: it: the error peaks between the grid's points, a few per cent above the largest on them where a face that
#: may be refined no further ends just within the limit (docs: the hard cases' benchmark).
VOUCH_SHARE = 0.95


@dataclass(frozen=True, eq=False)
class FaceGrid:
    """A grid over a face's trimmed domain (:func:`face_grid`) and where the field puts it.

    Attributes
    ----------
    uv : (m, 2) float array, the grid's parameters on the face.
    hot : (m, 3) float array, the hot surface there (mm).
    expected : (m, 3) float array, ``hot`` moved by the field's local estimate: where the cold face should
        pass, as far as the nodes tell.
    near : (m,) bool array, the points near the face's own nodes (:class:`FaceGridder`), where the nodes tell
        the field on the face.
    node_distance : (m,) float array, each point's distance (mm) to the nearest node of the face, its edges
        and its vertices (inf where they have none).
    support : float, the distance (mm) within which those nodes tell the field at a point: ``GRID_REACH``
        times the larger of their spacing and the spacing of all nodes (a small face's nodes crowd along its
        edges, closer than the mesh's spacing: on a face narrower than the node spacing, a point a spacing
        from a node would be "far" by their own measure).
    slack : (m,) float array, how far (mm) the estimate misses the displacements of the nearest
        ``_SLACK_NODES`` nodes at the most (0 where not ``near``): where
        the field has a kink the local fits cannot follow (next to a clamped face) or scatters, the estimate
        between the nodes is no better than that.
    uncertainty : (m,) float array or None, how far (mm) the estimate may be off the field there: the largest
        miss of the estimate over the other nodes at each of the ``_SLACK_NODES`` nearest nodes, left out in
        turn (:meth:`~hot2cold.pipeline.artificial.FieldEstimator.left_out`); 0 where not ``near`` and where
        the field's elements tell it.  The slack is the estimate's miss at nodes it was fitted to, and bounds
        the error between the nodes from below; this bounds it from above, at a node's spacing from the others
        (where the field changes faster than the nodes resolve, a sharp thermal front across a thin blade's
        edge, the estimate misses the field between the nodes by far more than the nodes it was fitted to).
        None: zeros.
    """

    uv: np.ndarray
    hot: np.ndarray
    expected: np.ndarray
    slack: np.ndarray
    near: np.ndarray
    node_distance: np.ndarray
    support: float = np.inf
    uncertainty: np.ndarray | None = None

    def __post_init__(self):
        if self.uncertainty is None:
            object.__setattr__(self, "uncertainty", np.zeros(len(self.uv)))

    def take(self, keep: np.ndarray) -> FaceGrid:
        """The grid points ``keep`` (a mask or indices) only."""
        return FaceGrid(self.uv[keep], self.hot[keep], self.expected[keep], self.slack[keep], self.near[keep],
                        self.node_distance[keep], self.support, self.uncertainty[keep])

    def unmeasured(self, off: np.ndarray, limit: float) -> np.ndarray:
        """Which points ``(m,)`` bool the grid does not vouch for as within ``limit`` (mm) when the cold face is
        ``off (m,)`` mm from :attr:`expected`: those out of the nodes' reach (:attr:`unsupported`), and those
        near them where the error may exceed :data:`VOUCH_SHARE` of the limit (``off`` plus the larger of the
        slack and the uncertainty): the nodes do not tell that the cold face is within it there, or the error
        is so near the limit that it may exceed it between the grid's points.  Where the refinement
        measured a face between its nodes, a miss beyond doubt counts against the tolerance there
        (:meth:`~hot2cold.pipeline.report.Report.misses`); here it is only not vouched for."""
        far = self.node_distance > self.support
        return far | (self.near & (off + np.maximum(self.slack, self.uncertainty) > VOUCH_SHARE * limit))

    @property
    def unsupported(self) -> float:
        """The share (0 to 1) of the grid's points farther than ``support`` from the nodes: where the face's
        shape comes from its edges and the field's estimate alone, unmeasured (NaN for an empty grid)."""
        if not len(self.node_distance):
            return float("nan")
        return float(np.count_nonzero(self.node_distance > self.support) / len(self.node_distance))

    @property
    def farthest_node(self) -> float:
        """The largest distance (mm) of a grid point to the nodes (inf without nodes, NaN for an empty grid)."""
        return float(self.node_distance.max()) if len(self.node_distance) else float("nan")


#: A point of a face's grid is near the face's nodes within this many of their node spacings.
GRID_REACH = 2.0
#: The slack of a grid point is the estimate's largest miss at this many nearest nodes.
_SLACK_NODES = 8
#: A face with fewer nodes of its own than this is estimated from every node: the nodes of its edges alone lie
#: along curves (an arc, a line), and an estimate over them extrapolates across the face (on a cylinder strip
#: without nodes of its own, far off the field away from the arc that holds them).
_FACE_ESTIMATE_MIN = 10


class _FaceNodes:
    """The nodes of one face, its edges and its vertices (``nodes`` (n,) classification rows), their foot
    points' k-d tree, whether the face has ``_FACE_ESTIMATE_MIN`` nodes of its own (``own``), the field's
    local estimate over the nodes (``local``) and its misses (mm) at them, the last two made as asked for."""

    def __init__(self, part: Part, face: Face, classification: Classification, field: DisplacementField,
                 neighbours: int):
        edges = {use.edge for use in face.uses}
        vertices = {v for e in edges for v in part.edges[e].vertices}
        self.nodes = np.concatenate([classification.nodes_of(Role.FACE, face.index)]
                                    + [classification.nodes_of(Role.EDGE, e) for e in sorted(edges)]
                                    + [classification.nodes_of(Role.VERTEX, v) for v in sorted(vertices)])
        self.reach = GRID_REACH * classification.spacing(self.nodes)
        self._foot = classification.foot[self.nodes]
        self.tree = kd_tree(self._foot) if len(self.nodes) else None
        self.own = len(classification.nodes_of(Role.FACE, face.index)) >= _FACE_ESTIMATE_MIN
        self._displacements = field.displacements[self.nodes]
        self._neighbours = neighbours
        self._local = None
        self._misses = np.full(len(self.nodes), np.nan)
        self._left_out = np.full(len(self.nodes), np.nan)

    @property
    def local(self):
        """The :class:`~hot2cold.pipeline.artificial.FieldEstimator` over the nodes (made when first asked)."""
        if self._local is None:
            from .artificial import FieldEstimator

            self._local = FieldEstimator(self._foot, self._displacements, self._neighbours, tree=self.tree)
        return self._local

    def slack_and_uncertainty(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """At ``points (m, 3)`` near the nodes, the slack ``(m,)`` (mm): the largest miss of :attr:`local` at their
        ``_SLACK_NODES`` nearest nodes (:attr:`FaceGrid.slack`), and the uncertainty ``(m,)`` (mm) of the estimate:
        the largest miss at those nodes, each left out of it (:attr:`FaceGrid.uncertainty`).  The misses are
        asked for those nodes only (a face's grid is sparser than its nodes)."""
        if not len(points):
            return np.zeros(0), np.zeros(0)
        closest = query(self.tree, points, k=min(_SLACK_NODES, len(self.nodes)))[1]
        closest = closest.reshape(len(points), -1)
        asked, at = np.unique(closest, return_inverse=True)
        at = at.reshape(closest.shape)
        misses, left_out = self.misses(asked)
        return misses[at].max(axis=1), left_out[at].max(axis=1)

    def misses(self, asked: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """How far (mm) ``local`` misses the displacements of the nodes ``asked`` (positions in ``nodes``), ``(m,)``,
        and how far it misses them with each left out of it ``(m,)``
        (:meth:`~hot2cold.pipeline.artificial.FieldEstimator.at_own`)."""
        new = asked[np.isnan(self._misses[asked])]
        if len(new):
            own, left_out = self.local.at_own(new)
            self._misses[new] = np.linalg.norm(own - self._displacements[new], axis=1)
            self._left_out[new] = np.linalg.norm(left_out - self._displacements[new], axis=1)
        return self._misses[asked], self._left_out[asked]


class FaceNodes:
    """What :class:`FaceGridder` finds of each face's nodes, kept for one classification and field across its
    calls: the refinement asks for the grids of a face again after every round, and the nodes, their tree, the
    local estimate and its misses at the nodes do not depend on the face's knots."""

    def __init__(self, classification: Classification, field: DisplacementField, neighbours: int):
        self.classification = classification
        self.field = field
        self.neighbours = neighbours
        self._faces: dict[int, _FaceNodes] = {}

    def of(self, part: Part, face: Face) -> _FaceNodes:
        """The nodes of ``face`` of ``part`` (or of a refined ``part``: same faces, edges and vertices)."""
        if face.index not in self._faces:
            self._faces[face.index] = _FaceNodes(part, face, self.classification, self.field, self.neighbours)
        return self._faces[face.index]


@dataclass(frozen=True, eq=False)
class FaceGridder:
    """Makes the :class:`FaceGrid` of a part's faces (calling it: ``gridder(part, faces=None, slack=True)``).

    Attributes
    ----------
    projector : Projector onto the hot faces (their trims).
    face_nodes : FaceNodes, the classification, the field, the neighbour count of the estimates, and each
        face's nodes and estimate, kept across calls (the refinement asks for a face's grid after every round).
    estimator : ``estimator(points (m, 3)) -> (m, 3)``, the field's estimate over every node.
    elements : ElementField or None, the FE model's own field between its nodes, where the field brings its
        elements and they were taken.
    threads : the faces are gridded in up to that many threads (:func:`~hot2cold.core.threads.map_threads`).
    """

    projector: Projector
    face_nodes: FaceNodes
    estimator: Callable[[np.ndarray], np.ndarray]
    elements: ElementField | None = None
    threads: int = 1

    def __call__(self, part: Part, faces: list[int] | None = None, slack: bool = True) -> list[FaceGrid]:
        """One :class:`FaceGrid` per face of ``part`` (of ``faces``, indices, if given), ``CHECK_SPACING`` x the part's
        diagonal apart and at least ``degree + 1`` per knot span (:func:`face_grid`): a refined face needs its own
        grid, or its new spans are checked only where its hot spans were (a refined plane can meet the tolerance on
        the grid of its bilinear hot surface and miss it between those points).

        On a face with at least ``_FACE_ESTIMATE_MIN`` nodes of its own, the points near its nodes (those of the face,
        its edges and its vertices; within ``GRID_REACH`` times their spacing, ``Classification.spacing``, which is
        that of the field around them: a plane with nodes only at its corners is near them only next to the corners,
        not across its whole extent, where the estimate extrapolates) are moved by a
        :class:`~hot2cold.pipeline.artificial.FieldEstimator` over those nodes (the gridder's ``face_nodes``); the
        others by the gridder's ``estimator`` (over every node).  A thin wall's two sides are nearer each other than
        the nodes' spacing, and an estimate over every node mixes the field of the far side in, off the face's own
        nodes by several times the tolerance.  Away from its own nodes, and where its nodes lie only along its
        edges (an arc, a line), a face's own estimate extrapolates, and the estimate over
        every node, which has nodes all around, is the better one.  With ``elements`` (the gridder's: a field that
        brings its FE elements, :class:`~hot2cold.pipeline.artificial.ElementField`), the points on the FE model's
        boundary take the elements' own field instead, and all of them are near the nodes: the elements say where the
        part goes between them (the slack there: their distance off the boundary times the strain). The hot surfaces'
        parameters stay valid through the refinement to a tolerance (knot insertion and degree elevation keep the
        surface), so one set of grids serves it and the checks of the cold part. The faces are gridded in up to the
        gridder's ``threads`` threads.  ``slack=False``: the slack of the points near the face's own nodes is left NaN
        (G1's trial refinement measures distances from ``expected`` only, and most trials are not taken;
        :func:`with_slack` finds it later): the slack is most of the time of a large face's grid."""
        face_nodes, projector = self.face_nodes, self.projector
        estimator, elements = self.estimator, self.elements
        find_slack = slack                   # (the grid's ``slack`` array below is another thing)
        spacing = CHECK_SPACING * part.diagonal
        overall = GRID_REACH * face_nodes.classification.spacing()

        def near_own(face) -> tuple[FaceGrid, np.ndarray, tuple | None]:
            """The face's grid as its own nodes tell it, the points they moved ``own`` and what the field's
            elements say there (or None); the other points are left to the estimate over every node, asked for
            every face's at once below (a call's cost)."""
            uv = face_grid(face, spacing, projector)
            hot = evaluate_surface(face.surface, uv[:, 0], uv[:, 1]) if len(uv) else np.zeros((0, 3))
            expected, slack, near = hot.copy(), np.zeros(len(uv)), np.zeros(len(uv), bool)
            uncertainty = np.zeros(len(uv))
            node_distance = np.full(len(uv), np.inf)
            own = np.zeros(len(uv), bool)                    # the points the face's own estimate moves
            mine = face_nodes.of(part, face)
            reach = mine.reach
            if len(uv) and len(mine.nodes) and np.isfinite(reach):
                node_distance = query(mine.tree, hot)[0]
                near = node_distance <= reach
                if near.any() and mine.own:
                    own = near
                    expected[near] += mine.local(hot[near])
                    if find_slack:
                        slack[near], uncertainty[near] = mine.slack_and_uncertainty(hot[near])
                    else:
                        slack[near] = uncertainty[near] = np.nan
            support = max(reach, overall) if np.isfinite(reach) else overall
            on_elements = elements(hot) if elements is not None and len(uv) else None
            return (FaceGrid(uv, hot, expected, slack, near, node_distance, support, uncertainty), own,
                    on_elements)

        def grid(found: tuple[FaceGrid, np.ndarray, tuple | None], moved: np.ndarray) -> FaceGrid:
            made, own, on_elements = found
            made.expected[~own] += moved
            if on_elements is None:
                return made
            on, disp, slack_on = on_elements            # the elements' own field where they tell it
            made.expected[on], made.slack[on], made.uncertainty[on] = made.hot[on] + disp, slack_on, slack_on
            return replace(made, near=made.near | on)

        chosen = part.faces if faces is None else [part.faces[k] for k in faces]
        mine = [face_nodes.of(part, face) for face in chosen]     # each face's nodes found here: the threads read them
        found = map_threads(near_own, chosen, self.threads, cost=[len(m.nodes) for m in mine])
        moved = estimated(estimator, *(made.hot[~own] for made, own, _ in found))
        return [grid(f, m) for f, m in zip(found, moved)]




def with_slack(part: Part, grids: list[FaceGrid], face_nodes: FaceNodes, threads: int = 1) -> list[FaceGrid]:
    """``grids`` (one per face of ``part``) with the slack a :class:`FaceGridder` left out (``slack=False``,
    NaN) found, from the same ``face_nodes``; the others as they are."""
    def fill(k: int) -> FaceGrid:
        grid = grids[k]
        missing = np.isnan(grid.slack)
        slack, uncertainty = grid.slack.copy(), grid.uncertainty.copy()
        nodes = face_nodes.of(part, part.faces[k])
        slack[missing], uncertainty[missing] = nodes.slack_and_uncertainty(grid.hot[missing])
        return replace(grid, slack=slack, uncertainty=uncertainty)

    todo = [k for k, grid in enumerate(grids) if np.isnan(grid.slack).any()]
    out = list(grids)
    for k, grid in zip(todo, map_threads(fill, todo, threads, cost=[np.isnan(grids[k].slack).sum() for k in todo])):
        out[k] = grid
    return out


@dataclass(frozen=True, eq=False)
class EdgeGrid:
    """Points along an edge near the nodes around it, and where the field's estimate puts them.

    Attributes
    ----------
    t : (m,) float array, the points' parameters on the edge's curve.
    expected : (m, 3) float array, the hot points moved by the field's local estimate (mm).
    slack : (m,) float array, how far (mm) the estimate misses the displacements of the nearest
        ``_SLACK_NODES`` nodes at the most (as :attr:`FaceGrid.slack`).
    """

    t: np.ndarray
    expected: np.ndarray
    slack: np.ndarray


#: An edge is measured between its nodes where its own nodes are fewer than this many times its poles: an edge
#: its nodes just determine interpolates them and may wander between (a long circle with as many nodes as
#: poles, off the field between them by more than the tolerance, and its face with it).
EDGE_REDUNDANCY = 2


def edge_grids(part: Part, classification: Classification, field: DisplacementField,
               estimator: Callable[[np.ndarray], np.ndarray]) -> list[EdgeGrid]:
    """One :class:`EdgeGrid` per edge of ``part``: points
    ``CHECK_SPACING`` x the part's diagonal apart, at least ``degree + 1`` per knot span, on edges whose own
    nodes are fewer than ``EDGE_REDUNDANCY`` times their poles, kept within ``GRID_REACH`` node spacings of
    the nodes of the edge, its faces and its vertices (the estimate over every node, ``estimator``, is
    informed there); none on the others and on degenerate edges.  The estimate is asked once for every edge's
    points and the nodes next to them (a call's cost is mostly its own on a part of many edges)."""
    spacing = CHECK_SPACING * part.diagonal
    empty = EdgeGrid(np.zeros(0), np.zeros((0, 3)), np.zeros(0))
    found: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}     # edge -> t, hot points, closest nodes
    for edge in part.edges:
        own = classification.nodes_of(Role.EDGE, edge.index)
        if edge.degenerate or len(own) >= EDGE_REDUNDANCY * edge.curve.n_poles:
            continue
        nodes = np.concatenate([own] + [classification.nodes_of(Role.FACE, k) for k in edge.faces]
                               + [classification.nodes_of(Role.VERTEX, v) for v in edge.vertices])
        reach = GRID_REACH * classification.spacing(nodes)
        if not len(nodes) or not np.isfinite(reach):
            continue
        curve = edge.curve
        breaks = knot_breaks(curve.knots, curve.degree)
        length = curve_length(curve)
        per_span = max(curve.degree + 1, int(np.ceil(length / spacing / (len(breaks) - 1))))
        t = np.unique(np.concatenate([np.linspace(a, b, min(per_span, _CHECK_MOST) + 1)
                                      for a, b in zip(breaks[:-1], breaks[1:])]))
        hot = evaluate_curve(curve, t)
        tree = kd_tree(classification.foot[nodes])
        near = tree.query(hot, distance_upper_bound=reach)[0] < np.inf
        if near.any():
            t, hot = t[near], hot[near]
            found[edge.index] = (t, hot, nodes[tree.query(hot, k=min(_SLACK_NODES, len(nodes)))[1].reshape(len(t), -1)])
    if not found:
        return [empty] * len(part.edges)
    asked = distinct(np.concatenate([closest.ravel() for _, _, closest in found.values()]))
    estimate = estimator(np.concatenate([classification.foot[asked]] + [hot for _, hot, _ in found.values()]))
    misses = np.zeros(len(classification.role))
    misses[asked] = np.linalg.norm(estimate[:len(asked)] - field.displacements[asked], axis=1)
    at = np.cumsum([len(asked)] + [len(t) for t, _, _ in found.values()])
    moved = dict(zip(found, np.split(estimate, at[:-1])[1:]))
    return [EdgeGrid(found[e][0], found[e][1] + moved[e], misses[found[e][2]].max(axis=1)) if e in found else empty
            for e in range(len(part.edges))]


def face_grid(face, spacing: float, projector: Projector) -> np.ndarray:
    """Parameters ``(m, 2)`` of a grid over ``face``'s trimmed domain: about ``spacing`` apart on the surface
    and at least ``degree + 1`` per knot span (at most ``_CHECK_MOST`` along a direction)."""
    surface = face.surface
    u0, u1, v0, v1 = face.uv_box
    uu, vv = np.meshgrid(np.linspace(u0, u1, 9), np.linspace(v0, v1, 9), indexing="ij")
    coarse = evaluate_surface(surface, uu.ravel(), vv.ravel()).reshape(9, 9, 3)
    sizes = []
    for axis, (lo, hi, knots, degree) in enumerate(((u0, u1, surface.u_knots, surface.u_degree),
                                                    (v0, v1, surface.v_knots, surface.v_degree))):
        length = float(np.linalg.norm(np.diff(coarse, axis=axis), axis=2).sum(axis=axis).max())
        breaks = np.unique(knots)
        spans = max(1, int(np.count_nonzero((breaks[1:] > lo) & (breaks[:-1] < hi))))
        sizes.append(int(np.clip(max(np.ceil(length / spacing), spans * (degree + 1)), 2, _CHECK_MOST - 1)) + 1)
    uu, vv = np.meshgrid(np.linspace(u0, u1, sizes[0]), np.linspace(v0, v1, sizes[1]), indexing="ij")
    uv = np.column_stack([uu.ravel(), vv.ravel()])
    # A face bounded by the sides of its surface's domain is all of it; others are trimmed: keep what is in.
    a0, a1, b0, b1 = surface.domain
    tol = 1e-9 * max(a1 - a0, b1 - b0)
    whole = all(np.all((np.abs(use.uv[:, 0] - a0) <= tol) | (np.abs(use.uv[:, 0] - a1) <= tol)
                       | (np.abs(use.uv[:, 1] - b0) <= tol) | (np.abs(use.uv[:, 1] - b1) <= tol))
                for use in face.uses)
    return uv if whole else uv[projector.classify(face.index, uv) != Trim.OUTSIDE]


