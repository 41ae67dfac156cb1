"""A tolerance that holds: refinement of the faces and edges whose fit misses it (beyond the paper).

The paper keeps every knot vector.  Where a control net is too coarse for the field (a plane's 2x2 bilinear
net under a temperature gradient, an edge with few poles), no choice of poles meets a tolerance.  Refining
the net adds poles without changing the hot shape at all, so the morph is refined where its error is and
fitted again, round after round, until every face's and edge's error is within the limit or
``Settings.max_refinements`` rounds are done.  It is the default (``Settings.tolerance``, 1e-3 mm);
``Settings.keep_knots`` keeps the paper's structure.

* The limit is :data:`TARGET_SHARE` of the tolerance plus what the field's scatter allows
  (:func:`noise_allowance`), the share leaving room for the error between the points; a field with
  noise (a few um of scatter, volume nodes beside the surface) cannot be met closer than its noise at its
  nodes, and a refinement that tried would fit the noise and fold the face.
* The errors (:class:`Targets`): at the nodes, the report's (eq. 21): the distance from each node's cold
  target point to the morphed face or edge, found by Gauss-Newton from the node's own foot point (a local
  distance, never smaller than the report's global one).  Between the nodes, on each face: the distance of
  the face's cold edges at their pcurves' points beyond the hot edges' own; and on a face whose own nodes
  do not determine its shape between them (:func:`nodes_determine`: fewer than a patch's polynomial piece
  needs, on average over its knot-span patches; a narrow band, a small plane with nodes only on its edges, a
  leading edge of a small radius under a coarse mesh), the field's local estimate at the points of a grid
  over the face that lie near nodes (where the nodes tell the field).
* A knot span holding a point whose error exceeds the limit is halved (knot insertion).  A direction of
  degree below 3 is first raised to cubic (degree elevation): a bilinear plane refined by knots alone can
  only follow a curved field piecewise linearly, with an error that falls as the square of the span.
  Both keep the hot geometry exactly (to rounding; the operator is found by collocation at the Greville
  points of the refined knots, exact since the old spline space lies in the new one).
* Shared edges stay shared.  A face's side row tied to an edge (:mod:`hot2cold.pipeline.face_fit`) must keep the
  edge's degree and knots, so refinement goes by *parameter classes*: a face's u or v direction, the
  edges tied to its sides along that direction, the directions of the other faces tied to those edges,
  and so on.  Every member of a class gets the same knots (in its own parameterisation, through the
  affine, possibly reversed, map between normalised parameters) and the same degree.  The two faces of an
  edge therefore go on sharing it pole for pole, and the cold solid stays watertight.
* Refinement never makes a knot span finer than its nodes can determine: a span is halved only while each
  half stays :data:`MIN_SPAN_SPACINGS` node spacings long (the spacing of the nodes on and around the face or
  edge).  Finer spans would meet the tolerance at the nodes by bending between them, with the artificial
  nodes (local estimates of the field, :mod:`hot2cold.pipeline.artificial`) deciding the shape there.  Spans
  between those lengths get artificial nodes in their empty cells, so every fit stays determined.  A face or
  edge that misses where no span may be halved is reported as not refinable.  A field sampled inside its FE
  elements tells the field between its points by the elements' shape functions: there the limit is
  :data:`MIN_SPAN_SPACINGS_ELEMENTS` spacings.
* A node is chased only while a finer net brings the face closer to it: a node whose error, after a round
  that refined its face for it, is still above :data:`STALL_SHARE` of what it was is left (``unresolved``).
  A field's node that its neighbours do not follow (a resampling or export slip, an outlier) is met by no
  smooth face through them, and halving spans next to it changes nothing there but the cost.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from enum import Enum
from typing import Callable, NamedTuple

import numpy as np

from ..core.arrays import distinct
from ..core.bspline import (BSplineCurve, BSplineSurface, evaluate_curve, evaluate_surface, knot_breaks,
                            polyline_length, refine_curve, refine_surface)
from ..core.footpoint import curve_distances, surface_distances, surface_distances_above
from ..core.model import Classification, Edge, Face, Part, Role, side_along
from ..core.threads import map_threads
from ..io.field import DisplacementField
from .grids import EdgeGrid, FaceGrid
from .edge_fit import EdgeMorph
from .face_fit import FaceMorph

log = logging.getLogger(__name__)

#: Degree a refined direction is raised to when it is lower.
REFINED_DEGREE = 3

#: A knot span is halved only while each half stays at least this many node spacings long on the part: finer
#: spans would be decided by the artificial nodes (the field's local estimate) rather than by the nodes.
MIN_SPAN_SPACINGS = 1.0

#: Refinement aims at this share of the tolerance (plus the noise allowance) at the nodes, so that the cold part
#: keeps within the tolerance between them too: a face refined until it just meets the tolerance at the points
#: of its field can still miss it slightly between them.  The tolerance itself is what the report checks.
TARGET_SHARE = 0.9

#: The same for a field sampled inside its FE elements (:func:`hot2cold.pipeline.load.element_points`): the
#: elements' shape functions tell the field between the points, and the points' spacing, about a quarter
#: of an element's edge, is no limit of what is known.  Spans down to a quarter of it let the faces next to a
#: clamped face follow the steep field there: with spans no shorter than one spacing, or half of one, such a
#: face can stop above the tolerance next to a vertex on the clamped face, where spans of a quarter meet it.
MIN_SPAN_SPACINGS_ELEMENTS = 0.25

#: A node that misses the limit is chased no more once a round that refined its face for it left its error
#: above this share of what it was (halving the span at a miss of a smooth field cuts it by up to 16, the
#: fourth power of the span for a cubic; at a kink of the field by half, in proportion to the span).  A node
#: that lies off the smooth field of its neighbours (a slip of a resampled field) gains little from each round,
#: and chasing it bends large faces towards it and kinks their tangent edges by degrees.
STALL_SHARE = 0.9


@dataclass(frozen=True)
class Refinement:
    """What the refinement did to one face (lengths in mm).

    ``missed``: the face missed the refinement's limit itself (:data:`TARGET_SHARE` of the tolerance plus the
    noise allowance; a face may also be refined only because it shares a refined edge);
    ``delta_max_before``/``delta_max_after``: its largest error at its nodes before and after (Gauss-Newton
    distances, see the module docstring); ``between_before``/``between_after``: its largest error between
    the nodes (grid points near nodes against the field's local estimate, and its edges);
    ``residual``: its largest fit residual ``|S_cold(u_k, v_k) - d_k|`` at the nodes at the end;
    ``refinable`` is False when the face still misses and its knot spans there are already as short as the
    nodes allow (:data:`MIN_SPAN_SPACINGS`), or where it misses only at nodes a finer net did not bring closer;
    ``unresolved``: those nodes, above the refinement's limit at the end (:data:`STALL_SHARE`).
    """

    face: int
    missed: bool
    refinable: bool
    knots_added_u: int
    knots_added_v: int
    degree_before: str
    degree_after: str
    net_before: str
    net_after: str
    rounds: int
    delta_max_before: float
    delta_max_after: float
    residual: float
    between_before: float = 0.0
    between_after: float = 0.0
    unresolved: int = 0


@dataclass(frozen=True)
class EdgeRefinement:
    """What the refinement did to one edge: knots added, degree and poles before and after, errors (mm)."""

    edge: int
    missed: bool
    refinable: bool
    knots_added: int
    degree_before: int
    degree_after: int
    poles_before: int
    poles_after: int
    rounds: int
    delta_max_before: float
    delta_max_after: float
    between_before: float = 0.0
    between_after: float = 0.0


@dataclass(eq=False)
class RefineResult:
    """The refined part (hot geometry, refined faces and edges), the new morphs, what was done, and the grids
    of the refined faces the refinement measures on their grids (``Targets.between``; index ->
    :class:`FaceGrid` over the refined surface): the others' grids are the caller's to make, on their final
    knots."""

    part: Part
    faces: list[FaceMorph]
    edges: list[EdgeMorph]
    face_refinements: list[Refinement]
    edge_refinements: list[EdgeRefinement]
    rounds: int
    grids: dict[int, FaceGrid]


# ----------------------------------------------------------------------------------------------------------
# Errors: local projections (eq. 21) and edge gaps.
# ----------------------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Targets:
    """Where the refinement measures each face and edge, besides the nodes (lengths in mm).

    Attributes
    ----------
    limit : float, the error accepted: the tolerance plus what the field's scatter allows
        (:func:`noise_allowance`).
    face_spacing : (n_faces,) float array, the node spacing on and around each face (its own nodes and its
        edges'); ``min_span_spacings`` of it is the shortest half span a refinement makes.
    edge_spacing : (n_edges,) float array, the same for each edge.
    grids : list of :class:`~hot2cold.pipeline.grids.FaceGrid`, per face whose own nodes do not determine
        it (``between``; a face with nodes only on its edges has none) the grid points near its nodes
        (``FaceGrid.near``), with the field's local estimate there, less the estimate's own miss at the
        nearest nodes (its ``slack``): the error between the nodes as far as the nodes tell.  Other faces are
        measured at their nodes: the estimate, a local quadratic, is no better than the fit where the nodes
        determine the face, and worse where it reaches past the nodes (into a hole in the nodes it is off by
        several times the tolerance, and a face refined after it ends worse there than the fit of the hot
        knots).
    between : (n_faces,) bool array, the faces measured on their grids: those whose nodes do not determine
        them with their hot knots (:func:`nodes_determine`), decided once, so that a face refined into more
        patches than its nodes fill is not measured against the estimate for that alone.
    edge_grids : list of :class:`~hot2cold.pipeline.grids.EdgeGrid`, per edge the points along it near the
        nodes around it where its own nodes do not outnumber its poles twice, with the field's estimate there.
    min_span_spacings : float, :data:`MIN_SPAN_SPACINGS`, or :data:`MIN_SPAN_SPACINGS_ELEMENTS` for a field
        sampled inside its elements.
    """

    limit: float
    face_spacing: np.ndarray
    edge_spacing: np.ndarray
    grids: list[FaceGrid]
    edge_grids: list[EdgeGrid]
    between: np.ndarray
    min_span_spacings: float = MIN_SPAN_SPACINGS

    @classmethod
    def of(cls, part: Part, classification: Classification, limit: float, grids: dict[int, FaceGrid],
           edge_grids: list[EdgeGrid], inside_elements: bool = False) -> Targets:
        """The targets of a classified field: node spacings (:meth:`Classification.spacing` of the nodes of a
        face and its edges, or of an edge; of all nodes where there are none) and the grid points of
        ``grids`` (face index -> its grid; at least the :meth:`measured_faces`) near the nodes of faces their
        own nodes do not determine, and ``edge_grids`` (one per edge,
        :func:`~hot2cold.pipeline.grids.edge_grids`); ``inside_elements``: the field is sampled inside its FE
        elements (its spans may be shorter, :data:`MIN_SPAN_SPACINGS_ELEMENTS`)."""
        overall = classification.spacing()

        def median(nodes: np.ndarray) -> float:
            spacing = classification.spacing(nodes)
            return spacing if np.isfinite(spacing) else overall

        edge_spacing = np.array([median(classification.nodes_of(Role.EDGE, e.index)) for e in part.edges])
        face_spacing = np.array([median(np.concatenate(
            [classification.nodes_of(Role.FACE, f.index)]
            + [classification.nodes_of(Role.EDGE, use.edge) for use in f.uses])) for f in part.faces])
        between = np.zeros(len(part.faces), bool)
        between[cls.measured_faces(part, classification)] = True
        missing = [k for k in np.flatnonzero(between) if k not in grids]
        if missing:
            raise ValueError(f"faces {missing} are measured on their grids, and have none")
        return cls(limit, face_spacing, edge_spacing,
                   [_measured(grids[k], True) if b else _UNMEASURED for k, b in enumerate(between)],
                   list(edge_grids), between, MIN_SPAN_SPACINGS_ELEMENTS if inside_elements else MIN_SPAN_SPACINGS)

    @staticmethod
    def measured_faces(part: Part, classification: Classification) -> list[int]:
        """The faces measured on their grids (``between``): those whose own nodes do not determine them with
        their hot knots (:func:`nodes_determine`), decided once."""
        return [f.index for f in part.faces if not nodes_determine(f, classification)]

    def with_grids(self, grids: dict[int, FaceGrid]) -> Targets:
        """The same targets with the grids of the faces ``grids`` (index -> the :class:`FaceGrid` of the
        refined face) in place of theirs."""
        measured = list(self.grids)
        for k, grid in grids.items():
            measured[k] = _measured(grid, self.between[k])
        return replace(self, grids=measured)


def nodes_determine(face: Face, classification: Classification) -> bool:
    """Whether the face's own nodes determine its shape between them: at least ``(p + 1)(q + 1)`` of them per
    knot-span patch on average, what a patch's polynomial piece needs (the rule by which a patch takes
    artificial nodes, :func:`hot2cold.pipeline.face_fit._artificial_parameters`).  With fewer the artificial
    nodes, the field's estimate, set the shape between the nodes: a face with more nodes than poles but fewer
    than its patches need can meet the tolerance at its nodes and miss it against the exact cold geometry
    between them.  Counting per patch also covers a face with fewer
    nodes than poles (a patch's piece has ``(p + 1)(q + 1)`` poles)."""
    surface = face.surface
    patches = ((len(knot_breaks(surface.u_knots, surface.u_degree)) - 1)
               * (len(knot_breaks(surface.v_knots, surface.v_degree)) - 1))
    need = patches * (surface.u_degree + 1) * (surface.v_degree + 1)
    return len(classification.nodes_of(Role.FACE, face.index)) >= need


#: The grid of a face the refinement measures at its nodes only.
_UNMEASURED = FaceGrid(np.zeros((0, 2)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, bool),
                       np.zeros(0))


def _measured(grid: FaceGrid, between: bool) -> FaceGrid:
    """The points of ``grid`` the refinement measures its face at: those near its nodes where ``between``
    (its nodes do not determine it), none else (:class:`Targets`)."""
    return grid.take(grid.near if between else np.zeros(len(grid.uv), bool))


def noise_allowance(scatter: float, nodes: int) -> float:
    """The error (mm) a node may show beyond the tolerance because the field scatters: the largest of
    ``nodes`` normal distances drawn with standard deviation ``scatter`` (mm) is about ``scatter`` times the
    normal quantile of ``1 - 1/(4 nodes)`` (4.06 for 10 000 nodes), and no fit of the signal comes closer to
    the nodes than their noise."""
    if scatter <= 0 or nodes <= 0:
        return 0.0
    from scipy.special import ndtri          # the normal quantile (scipy.stats is slow to import)

    return float(-scatter * ndtri(0.25 / nodes))


class FaceErrors(NamedTuple):
    """A face's errors (mm) and where they are: at its nodes (eq. 21), and between them (its grid points near
    nodes, and its edges' cold points).  ``uv`` and ``error`` hold all of them, for the marks (at a node within
    the limit, an upper bound of its error,
    :func:`~hot2cold.core.footpoint.surface_distances_above`); ``nodes`` and ``between`` the largest of
    each kind (0 where there are none)."""

    uv: np.ndarray
    error: np.ndarray
    nodes: float
    between: float


def _largest(err: np.ndarray) -> float:
    """The largest of ``err`` (0 when empty)."""
    return float(err.max()) if len(err) else 0.0


class EdgeErrors(NamedTuple):
    """An edge's errors (mm) and where they are: at its nodes (eq. 21) and at the points of its
    :class:`EdgeGrid` (less their slack).  ``t`` and ``error`` hold all of them, for the marks; ``nodes`` and
    ``between`` the largest of each kind (0 where there are none)."""

    t: np.ndarray
    error: np.ndarray
    nodes: float
    between: float


def _curves_off(surface: BSplineSurface, curves: list[BSplineCurve], uses: list, uv: np.ndarray, box) -> np.ndarray:
    """The distances ``(m,)`` from ``surface`` of the points of ``curves`` at each of the edge ``uses``'
    parameters ``use.t``, each projected from its pcurve's point, ``uv (m, 2)`` (the uses' ``uv`` in turn, in face
    ``box``), all in one projection."""
    if not uses:
        return np.zeros(0)
    points = np.concatenate([evaluate_curve(curve, use.t) for curve, use in zip(curves, uses)])
    return surface_distances(surface, points, uv, box)


def _edge_errors(edge: Edge, morph: EdgeMorph, cls: Classification, field: DisplacementField,
                 grid: EdgeGrid) -> EdgeErrors:
    t, at_nodes = edge_errors(edge, morph, cls, field)
    if edge.degenerate or not len(grid.t):
        return EdgeErrors(t, at_nodes, _largest(at_nodes), 0.0)
    off = np.maximum(curve_distances(morph.curve, grid.expected, grid.t) - grid.slack, 0.0)
    return EdgeErrors(np.concatenate([t, grid.t]), np.concatenate([at_nodes, off]), _largest(at_nodes),
                      _largest(off))


def edge_errors(edge: Edge, morph: EdgeMorph, cls: Classification, field: DisplacementField
                ) -> tuple[np.ndarray, np.ndarray]:
    """An edge's nodes' hot parameters ``(m,)`` and the distances ``(m,)`` (mm) of their cold targets to the
    morphed curve (eq. 21, a local projection from the hot parameters); empty for a degenerate edge."""
    nodes = cls.nodes_of(Role.EDGE, edge.index)
    if edge.degenerate or not len(nodes):
        return np.zeros(0), np.zeros(0)
    return cls.t[nodes], curve_distances(morph.curve, cls.foot[nodes] + field.displacements[nodes], cls.t[nodes])


def node_residuals(face: Face, morph: FaceMorph, cls: Classification, field: DisplacementField) -> np.ndarray:
    """Fit residuals ``(m,)`` (mm) at the face's nodes: ``|S_cold(u_k, v_k) - S_hot(u_k, v_k) - dd_k|``."""
    nodes = cls.nodes_of(Role.FACE, face.index)
    u, v = cls.uv[nodes, 0], cls.uv[nodes, 1]
    target = evaluate_surface(face.surface, u, v) + field.displacements[nodes]
    return np.linalg.norm(evaluate_surface(morph.surface, u, v) - target, axis=1)


# ----------------------------------------------------------------------------------------------------------
# Parameter classes: directions of faces and edges that must keep one knot vector.
# ----------------------------------------------------------------------------------------------------------

def _ends(knots: np.ndarray) -> tuple[float, float]:
    return float(knots[0]), float(knots[-1])


class Kind(Enum):
    """What a member of a parameter class is: a parameter direction of a face, or an edge."""

    FACE = "face"
    EDGE = "edge"


class Member(NamedTuple):
    """A member of a parameter class: the ``axis`` (0: u, 1: v) direction of face ``index``, or edge
    ``index`` (``axis`` None).  Build one with :meth:`face` or :meth:`edge`."""

    kind: Kind
    index: int
    axis: int | None = None

    @classmethod
    def face(cls, index: int, axis: int) -> "Member":
        return cls(Kind.FACE, index, axis)

    @classmethod
    def edge(cls, index: int) -> "Member":
        return cls(Kind.EDGE, index)


class _Classes:
    """Union-find over the members (:class:`Member`: face directions and edges), each with the map from its own
    parameter to the normalised parameter of its class's root: ``s = flip(x) `` with ``flip`` reversing
    when ``reversed``.  A class reached both ways (a member tied forwards along one path and backwards along
    another) is ``symmetric``: its knots are inserted mirrored too."""

    def __init__(self):
        self.parent: dict = {}
        self.flip: dict = {}           # member -> reversed relative to parent
        self.symmetric: set = set()    # roots

    def add(self, m: Member):
        if m not in self.parent:
            self.parent[m] = m
            self.flip[m] = False

    def find(self, m: Member) -> tuple[Member, bool]:
        """The root of ``m`` and whether ``m`` runs reversed to it."""
        flip = False
        while self.parent[m] != m:
            flip ^= self.flip[m]
            m = self.parent[m]
        return m, flip

    def union(self, a: Member, b: Member, reversed_: bool):
        self.add(a)
        self.add(b)
        ra, fa = self.find(a)
        rb, fb = self.find(b)
        if ra == rb:
            if fa ^ fb != reversed_:
                self.symmetric.add(ra)
            return
        self.parent[rb] = ra
        self.flip[rb] = fa ^ fb ^ reversed_
        if rb in self.symmetric:
            self.symmetric.add(ra)

    def members(self):
        groups: dict = {}
        for m in self.parent:
            root, flip = self.find(m)
            groups.setdefault(root, []).append((m, flip))
        return groups


def _classes(part: Part, face_morphs: list[FaceMorph]) -> _Classes:
    classes = _Classes()
    for face, morph in zip(part.faces, face_morphs):
        for axis in (0, 1):
            classes.add(Member.face(face.index, axis))
        for use in face.uses:
            edge = part.edges[use.edge]
            found = side_along(face.surface, use)
            if edge.degenerate or found is None or found[0] not in morph.tied_sides:
                continue
            side, backwards = found
            along = 1 - side.axis
            classes.union(Member.face(face.index, along), Member.edge(edge.index), backwards)
    for edge in part.edges:
        if not edge.degenerate:
            classes.add(Member.edge(edge.index))
    return classes


def _knots_degree(part: Part, member: Member) -> tuple[np.ndarray, int]:
    if member.kind is Kind.EDGE:
        curve = part.edges[member.index].curve
        return curve.knots, curve.degree
    surface = part.faces[member.index].surface
    return (surface.u_knots, surface.u_degree) if member.axis == 0 else (surface.v_knots, surface.v_degree)


def _spans(breaks: np.ndarray, x: np.ndarray) -> np.ndarray:
    return np.clip(np.searchsorted(breaks, x, side="right") - 1, 0, len(breaks) - 2)


def _edge_marks(curve: BSplineCurve, t: np.ndarray, bad: np.ndarray, shortest: float) -> tuple[np.ndarray, bool]:
    """Where an edge is refined: the midpoints of the knot spans holding a bad node whose halves stay at least
    ``shortest`` (mm) long, and whether it is raised to ``REFINED_DEGREE`` (it has a bad
    node and a lower degree)."""
    breaks = knot_breaks(curve.knots, curve.degree)
    mids = []
    for r in distinct(_spans(breaks, t[bad])):
        lo, hi = breaks[r], breaks[r + 1]
        mid = 0.5 * (lo + hi)
        if polyline_length(evaluate_curve(curve, np.linspace(lo, mid, 9))) >= shortest:
            mids.append(mid)
    return np.array(mids), bool(bad.any() and curve.degree < REFINED_DEGREE)


def _face_marks(surface: BSplineSurface, uv: np.ndarray, bad: np.ndarray, shortest: float
                ) -> list[tuple[np.ndarray, bool]]:
    """Where a face is refined, per direction (u, v): the midpoints of the knot spans of the patches holding
    a bad point, and whether the direction is raised to ``REFINED_DEGREE`` (the face has a bad point and the
    direction a lower degree).

    A patch is halved along its longer direction on the part, and along the other too where that is at least
    half as long (longest-edge bisection: a patch long along a steep change of the field and short across it,
    next to a clamped face, is cut where the change is, rather than in both directions), and only where the
    halves stay at least ``shortest`` (mm) long.  Lengths are measured along the patch's
    middle iso-curves."""
    degrees = (surface.u_degree, surface.v_degree)
    breaks = [knot_breaks(surface.u_knots, degrees[0]), knot_breaks(surface.v_knots, degrees[1])]
    patches = {tuple(x) for x in np.column_stack([_spans(breaks[0], uv[bad, 0]), _spans(breaks[1], uv[bad, 1])])}
    mids: list[set] = [set(), set()]
    for patch in patches:
        ends = [breaks[axis][patch[axis]:patch[axis] + 2] for axis in (0, 1)]
        lengths = []
        for axis in (0, 1):
            along, across = np.linspace(*ends[axis], 17), np.full(17, ends[1 - axis].mean())
            lengths.append(polyline_length(evaluate_surface(surface, *((along, across) if axis == 0
                                                                        else (across, along)))))
        for axis in (0, 1):
            if lengths[axis] >= 0.5 * max(lengths) and lengths[axis] / 2 >= shortest:
                mids[axis].add(float(ends[axis].mean()))
    return [(np.array(sorted(mids[axis])), bool(bad.any() and degrees[axis] < REFINED_DEGREE)) for axis in (0, 1)]


def _to_class(x: np.ndarray, knots: np.ndarray, flip: bool) -> np.ndarray:
    a, b = _ends(knots)
    s = (np.asarray(x, float) - a) / (b - a)
    return 1.0 - s if flip else s


def _from_class(s: np.ndarray, knots: np.ndarray, flip: bool) -> np.ndarray:
    a, b = _ends(knots)
    s = np.asarray(s, float)
    return a + (1.0 - s if flip else s) * (b - a)


def _dedupe(s: np.ndarray, tol: float = 1e-12) -> np.ndarray:
    s = np.sort(np.asarray(s, float))
    if len(s) == 0:
        return s
    keep = np.concatenate([[True], np.diff(s) > tol])
    return s[keep]


# ----------------------------------------------------------------------------------------------------------
# Knot insertion by parameter classes, and the fits again.
# ----------------------------------------------------------------------------------------------------------

FitFace = Callable[[Part, Face, list[EdgeMorph]], FaceMorph]
FitEdges = Callable[[Part, list[EdgeMorph], set[int]], list[EdgeMorph]]
Regrid = Callable[[Part, list[int]], list[FaceGrid]]


@dataclass(frozen=True, eq=False)
class Refitter:
    """How a refined part is fitted again, for :func:`refine` and :func:`refine_patches`.

    ``fit_face(part, face, edge_morphs) -> FaceMorph`` fits a face of a (refined) part against the given edge
    morphs; ``fit_edges(part, edge_morphs, refined) -> edge_morphs`` fits the edges in the set ``refined``
    again and returns every edge's morph (it may touch others, e.g. at corners of tangent edges: an edge whose
    curve object changes counts as changed); ``regrid(part, faces) -> grids`` gives the :class:`FaceGrid` of
    each of the (refined) ``faces`` of ``part`` (:class:`~hot2cold.pipeline.grids.FaceGridder`); the faces of a
    round are fitted in up to ``threads`` threads; :func:`refine` runs ``max_rounds`` rounds at the most.
    """

    fit_face: FitFace
    fit_edges: FitEdges
    regrid: Regrid
    threads: int = 1
    max_rounds: int = 1

    def refit(self, inserted: _Inserted, face_morphs: list[FaceMorph], edge_morphs: list[EdgeMorph],
              gridded: set[int] | None = None, nodes: np.ndarray | None = None) -> _Refitted:
        """The refined edges fitted again, then the refined faces and every face on an edge that moved (for
        faces of ``nodes`` ``(n_faces,)`` nodes: the cost of each in the threads); the grids of the refined
        faces (of those in ``gridded`` only, where given)."""
        part = inserted.part
        changed = sorted(inserted.faces if gridded is None else inserted.faces & gridded)
        grids = dict(zip(changed, self.regrid(part, changed))) if changed else {}
        fitted = self.fit_edges(part, edge_morphs, inserted.edges)
        moved = inserted.edges | {e for e, (a, b) in enumerate(zip(edge_morphs, fitted)) if a.curve is not b.curve}
        refit = set(inserted.faces) | {k for k, f in enumerate(part.faces) for use in f.uses if use.edge in moved}
        faces = list(face_morphs)
        order = sorted(refit)
        for k, morph in zip(order, map_threads(lambda k: self.fit_face(part, part.faces[k], fitted), order,
                                               self.threads, cost=None if nodes is None else nodes[order])):
            faces[k] = morph
        return _Refitted(faces, list(fitted), grids, refit, moved)


def _mark(part: Part, classes: _Classes, k: int, wanted: list[tuple[np.ndarray, bool]], marks: dict,
          elevate: set) -> bool:
    """Face ``k``'s ``wanted`` refinement (:func:`_face_marks`) added to ``marks`` (class root -> list of
    normalised knots to insert) and ``elevate`` (class roots to raise to :data:`REFINED_DEGREE`); whether it
    asks for anything."""
    for axis, (mids, up) in enumerate(wanted):
        member = Member.face(k, axis)
        knots, _ = _knots_degree(part, member)
        root, flip = classes.find(member)
        marks.setdefault(root, []).append(_to_class(mids, knots, flip))
        if up:
            elevate.add(root)
    return any(len(mids) or up for mids, up in wanted)


@dataclass(eq=False)
class _Inserted:
    """A part with knots inserted: the refined part, the faces and edges whose geometry record changed, and
    the knots added to each (``face_added`` (n_faces, 2) per direction, ``edge_added`` (n_edges,))."""

    part: Part
    faces: set[int]
    edges: set[int]
    face_added: np.ndarray
    edge_added: np.ndarray


def _insert(part: Part, classes: _Classes, marks: dict, elevate: set) -> _Inserted:
    """The knots ``marks`` (class root -> list of arrays of normalised parameters) inserted into every member
    of their class, each member raised to :data:`REFINED_DEGREE` first where its root is in ``elevate``."""
    groups = classes.members()
    new_faces, new_edges = list(part.faces), list(part.edges)
    face_added = np.zeros((len(part.faces), 2), int)
    edge_added = np.zeros(len(part.edges), int)
    changed_faces, changed_edges = set(), set()
    for root, pieces in marks.items():
        s = np.concatenate(pieces) if pieces else np.zeros(0)
        if root in classes.symmetric:
            s = np.concatenate([s, 1.0 - s])
        s = _dedupe(s)
        for member, flip in groups[root]:
            knots, degree = _knots_degree(part, member)
            inserted = _from_class(s, knots, flip)
            lo, hi = knots[degree], knots[len(knots) - degree - 1]
            inserted = inserted[(inserted > lo) & (inserted < hi)]
            target = max(degree, REFINED_DEGREE) if root in elevate else degree
            if member.kind is Kind.EDGE:
                e = member.index
                new_edges[e] = replace(new_edges[e], curve=refine_curve(new_edges[e].curve, inserted, target))
                if new_edges[e].curve is not part.edges[e].curve:
                    changed_edges.add(e)
                    edge_added[e] += len(inserted)
            else:
                k, axis = member.index, member.axis
                surface = refine_surface(new_faces[k].surface, axis, inserted, target)
                if surface is not new_faces[k].surface:
                    new_faces[k] = replace(new_faces[k], surface=surface)
                    changed_faces.add(k)
                    face_added[k, axis] += len(inserted)
    if changed_faces or changed_edges:
        part = replace(part, faces=new_faces, edges=new_edges)
    return _Inserted(part, changed_faces, changed_edges, face_added, edge_added)


@dataclass(eq=False)
class _Refitted:
    """The morphs after a knot insertion: every face's and edge's, the grids of the refined faces (index ->
    :class:`FaceGrid`), the faces fitted again (``refit``) and the edges whose morph changed (``moved``)."""

    faces: list[FaceMorph]
    edges: list[EdgeMorph]
    grids: dict[int, FaceGrid]
    refit: set[int]
    moved: set[int]


# ----------------------------------------------------------------------------------------------------------
# The refinement loop.
# ----------------------------------------------------------------------------------------------------------

def refine(part: Part, cls: Classification, field: DisplacementField,
           morphs: tuple[list[FaceMorph], list[EdgeMorph]], targets: Targets, refitter: Refitter) -> RefineResult:
    """Refine faces and edges until every error is within ``targets.limit`` mm or ``refitter.max_rounds`` are
    done; ``morphs`` are the fits of the faces and edges of ``part`` to the nodes ``cls`` of ``field``.  The
    faces measured on their grids (``targets.between``) are gridded again after each round, the others are the
    caller's to grid once their knots are final.  Returns the refined part (hot geometry, same shape), the final
    morphs and one record per face and edge that was refined or missed."""
    loop = _Refining(part, cls, field, morphs, targets, refitter)
    while loop.rounds < refitter.max_rounds and loop.missing():
        if not loop.round():
            break
    return loop.result()


class _Refining:
    """The state of one refinement (:func:`refine`): the part and its fits as refined so far, their errors,
    what was added to each face and edge, and the nodes chased and given up."""

    def __init__(self, part: Part, cls: Classification, field: DisplacementField,
                 morphs: tuple[list[FaceMorph], list[EdgeMorph]], targets: Targets, refitter: Refitter):
        self.part, self.cls, self.field, self.targets, self.refitter = part, cls, field, targets, refitter
        self.faces, self.edges = list(morphs[0]), list(morphs[1])
        self.hot_faces, self.hot_edges = list(part.faces), list(part.edges)
        self.face_added = np.zeros((len(part.faces), 2), int)
        self.edge_added = np.zeros(len(part.edges), int)
        self.face_rounds = np.zeros(len(part.faces), int)
        self.edge_rounds = np.zeros(len(part.edges), int)
        self.grids: dict[int, FaceGrid] = {}
        self.hot_gaps: dict[int, np.ndarray] = {}   # face -> distances of its hot edges' points from it
        self.sizes = cls.counts(Role.FACE, len(part.faces))        # each face's nodes: its work's cost in threads
        self.face_err = map_threads(self._face_errors, range(len(part.faces)), refitter.threads, cost=self.sizes)
        self.edge_err = [self._edge_errors(e) for e in range(len(part.edges))]
        self.face_before = [(e.nodes, e.between) for e in self.face_err]
        self.edge_before = [(e.nodes, e.between) for e in self.edge_err]
        self.stuck_faces: set[int] = set()         # faces and edges that miss where no span may be halved
        self.stuck_edges: set[int] = set()
        self.measured = set(np.flatnonzero(targets.between).tolist())       # faces measured on their grids
        self.chased = [np.full(len(cls.nodes_of(Role.FACE, f.index)), np.nan) for f in part.faces]
        self.stalled = [np.zeros(len(c), bool) for c in self.chased]   # nodes a finer net did not bring closer
        self.rounds = 0

    def _face_errors(self, k: int) -> FaceErrors:
        """Errors of face ``k``: the distances of eq. (21) at its nodes, of the field's local estimate at its
        grid points, and of its cold edges at their pcurves' points beyond the hot edges' own (the gap the
        morph opened, which the sew would have to close; a hot part's gaps are its own)."""
        face, morph, cls, field = self.part.faces[k], self.faces[k], self.cls, self.field
        grid = self.targets.grids[k]
        nodes = cls.nodes_of(Role.FACE, face.index)
        target = cls.foot[nodes] + field.displacements[nodes]
        at_nodes = surface_distances_above(morph.surface, target, cls.uv[nodes], face.uv_box, self.targets.limit)
        off = surface_distances(morph.surface, grid.expected, grid.uv, face.uv_box, past_border=True)
        uses = [use for use in face.uses if not self.part.edges[use.edge].degenerate]
        uv_edges = np.concatenate([use.uv for use in uses]) if uses else np.zeros((0, 2))
        cold = _curves_off(morph.surface, [self.edges[use.edge].curve for use in uses], uses, uv_edges, face.uv_box)
        if k not in self.hot_gaps:          # the hot edges' own gaps: the knots refinement inserts keep them
            self.hot_gaps[k] = _curves_off(self.hot_faces[k].surface, [self.hot_edges[use.edge].curve for use in uses],
                                           uses, uv_edges, face.uv_box)
        between = np.concatenate([np.maximum(off - grid.slack, 0.0), np.maximum(cold - self.hot_gaps[k], 0.0)])
        return FaceErrors(np.concatenate([cls.uv[nodes], grid.uv, uv_edges]), np.concatenate([at_nodes, between]),
                          _largest(at_nodes), _largest(between))

    def _edge_errors(self, e: int) -> EdgeErrors:
        return _edge_errors(self.part.edges[e], self.edges[e], self.cls, self.field, self.targets.edge_grids[e])

    def _bad(self) -> tuple[list[int], list[int]]:
        limit = self.targets.limit
        return ([k for k, e in enumerate(self.face_err) if _largest(e.error) > limit],
                [k for k, e in enumerate(self.edge_err) if _largest(e.error) > limit])

    def missing(self) -> bool:
        """Whether a face or an edge still misses the limit (if none does, none is stuck either)."""
        bad_faces, bad_edges = self._bad()
        if not bad_faces and not bad_edges:
            self.stuck_faces, self.stuck_edges = set(), set()
            return False
        return True

    def round(self) -> bool:
        """One round: the spans that miss marked in their classes, halved (and raised to cubic), everything
        they touch fitted again and measured again.  False when no span may be halved any more."""
        bad_faces, bad_edges = self._bad()
        classes = _classes(self.part, self.faces)
        marks: dict = {}                          # class root -> list of normalised knots to insert
        elevate: set = set()                      # class roots to raise to REFINED_DEGREE
        self.stuck_faces = {k for k in bad_faces if not self._mark_face(k, classes, marks, elevate)}
        self.stuck_edges = {e for e in bad_edges if not self._mark_edge(e, classes, marks, elevate)}
        inserted = _insert(self.part, classes, marks, elevate)
        if not inserted.faces and not inserted.edges:
            return False
        self._take(inserted)
        return True

    def _mark_face(self, k: int, classes, marks: dict, elevate: set) -> bool:
        """Mark the spans of face ``k`` that hold its misses, but for nodes a finer net did not bring closer
        (:data:`STALL_SHARE`); False where none may be halved."""
        err, targets = self.face_err[k], self.targets
        bad = err.error > targets.limit
        n = len(self.chased[k])                   # the face's nodes come first in its errors
        self.stalled[k] |= bad[:n] & (err.error[:n] > STALL_SHARE * self.chased[k])
        bad[:n] &= ~self.stalled[k]               # a stalled node is chased no more: no marks for it
        wanted = _face_marks(self.part.faces[k].surface, err.uv, bad,
                             targets.min_span_spacings * targets.face_spacing[k])
        if not _mark(self.part, classes, k, wanted, marks, elevate):
            return False
        nodes = bad[:n]
        self.chased[k][nodes] = err.error[:n][nodes]
        return True

    def _mark_edge(self, e: int, classes, marks: dict, elevate: set) -> bool:
        """Mark the spans of edge ``e`` that hold its misses (or its degree to raise); False where none may be."""
        t, err = self.edge_err[e].t, self.edge_err[e].error
        mids, up = _edge_marks(self.part.edges[e].curve, t, err > self.targets.limit,
                               self.targets.min_span_spacings * self.targets.edge_spacing[e])
        member = Member.edge(e)
        knots, _ = _knots_degree(self.part, member)
        root, flip = classes.find(member)
        marks.setdefault(root, []).append(_to_class(mids, knots, flip))
        if up:
            elevate.add(root)
        return bool(len(mids) or up)

    def _take(self, inserted: _Inserted) -> None:
        """The refined part of ``inserted`` fitted again (only the faces measured on their grids need them each
        round) and measured again where its fits changed: the others' errors stand, a face's depend on it and
        its edges only."""
        self.part = inserted.part
        self.face_added += inserted.face_added
        self.edge_added += inserted.edge_added
        refitted = self.refitter.refit(inserted, self.faces, self.edges, self.measured, self.sizes)
        self.grids.update(refitted.grids)
        self.targets = self.targets.with_grids(refitted.grids)
        self.faces, self.edges = refitted.faces, refitted.edges
        self.edge_rounds[list(inserted.edges)] += 1
        self.face_rounds[list(inserted.faces)] += 1
        self.rounds += 1
        again = sorted(refitted.refit)
        for k, err in zip(again, map_threads(self._face_errors, again, self.refitter.threads,
                                             cost=self.sizes[again])):
            self.face_err[k] = err
        for e in refitted.moved:
            self.edge_err[e] = self._edge_errors(e)
        log.info("refinement round %d: %d faces and %d edges refined; largest error %.3g mm", self.rounds,
                 len(inserted.faces), len(inserted.edges),
                 max([_largest(e.error) for e in self.face_err] + [_largest(e.error) for e in self.edge_err] + [0.0]))

    def result(self) -> RefineResult:
        return RefineResult(self.part, self.faces, self.edges, self._face_reports(), self._edge_reports(),
                            self.rounds, self.grids)

    def _face_reports(self) -> list[Refinement]:
        """A record per face that missed the limit or was refined."""
        part, limit = self.part, self.targets.limit
        reported = [k for k in range(len(part.faces)) if max(self.face_before[k]) > limit or self.face_rounds[k]]
        residual = dict(zip(reported, map_threads(
            lambda k: _largest(node_residuals(part.faces[k], self.faces[k], self.cls, self.field)), reported,
            self.refitter.threads, cost=self.sizes[reported])))
        out = []
        for k in reported:
            s0, s1 = self.hot_faces[k].surface, part.faces[k].surface
            err = self.face_err[k]
            unresolved = int(np.count_nonzero(self.stalled[k] & (err.error[:len(self.stalled[k])] > limit)))
            out.append(Refinement(
                face=k, missed=max(self.face_before[k]) > limit,
                refinable=not ((k in self.stuck_faces or unresolved) and _largest(err.error) > limit),
                knots_added_u=int(self.face_added[k, 0]), knots_added_v=int(self.face_added[k, 1]),
                degree_before=f"{s0.u_degree}x{s0.v_degree}", degree_after=f"{s1.u_degree}x{s1.v_degree}",
                net_before="x".join(map(str, s0.shape)), net_after="x".join(map(str, s1.shape)),
                rounds=int(self.face_rounds[k]), delta_max_before=self.face_before[k][0],
                delta_max_after=err.nodes, residual=residual[k], between_before=self.face_before[k][1],
                between_after=err.between, unresolved=unresolved))
        return out

    def _edge_reports(self) -> list[EdgeRefinement]:
        """A record per edge (not degenerate) that missed the limit or was refined."""
        limit = self.targets.limit
        out = []
        for e, (edge, hot) in enumerate(zip(self.part.edges, self.hot_edges)):
            missed = max(self.edge_before[e]) > limit
            if edge.degenerate or (not missed and not self.edge_rounds[e]):
                continue
            err = self.edge_err[e]
            out.append(EdgeRefinement(
                edge=e, missed=missed, refinable=not (e in self.stuck_edges and _largest(err.error) > limit),
                knots_added=int(self.edge_added[e]), degree_before=hot.curve.degree,
                degree_after=edge.curve.degree, poles_before=hot.curve.n_poles, poles_after=edge.curve.n_poles,
                rounds=int(self.edge_rounds[e]), delta_max_before=self.edge_before[e][0],
                delta_max_after=err.nodes, between_before=self.edge_before[e][1], between_after=err.between))
        return out


@dataclass(eq=False)
class PatchRefinement:
    """What :func:`refine_patches` made: the refined part, every face's and edge's morph, the grids of the
    refined faces (index -> :class:`FaceGrid`), and the knots added per refined face (index -> (u, v))."""

    part: Part
    faces: list[FaceMorph]
    edges: list[EdgeMorph]
    grids: dict[int, FaceGrid]
    knots_added: dict[int, tuple[int, int]]


def refine_patches(part: Part, morphs: tuple[list[FaceMorph], list[EdgeMorph]], points: dict[int, np.ndarray],
                   shortest: np.ndarray, refitter: Refitter, nodes: np.ndarray | None = None
                   ) -> PatchRefinement | None:
    """The knot-span patches of each face ``k`` that hold one of ``points[k]`` ((m, 2) parameters) halved as
    :func:`refine` halves a patch that misses the tolerance (longest-edge bisection, halves at least
    ``shortest[k]`` mm long, a direction below :data:`REFINED_DEGREE` raised to it), in their parameter
    classes so that shared edges stay shared, and the morphs (of the faces and edges) fitted again by
    ``refitter`` (``nodes`` ``(n_faces,)``, each face's nodes, the cost of its refit).  None where no such patch
    may be halved."""
    face_morphs, edge_morphs = morphs
    classes = _classes(part, face_morphs)
    marks: dict = {}
    elevate: set = set()
    for k, uv in points.items():
        if len(uv):
            _mark(part, classes, k, _face_marks(part.faces[k].surface, uv, np.ones(len(uv), bool), shortest[k]),
                  marks, elevate)
    inserted = _insert(part, classes, marks, elevate)
    if not inserted.faces and not inserted.edges:
        return None
    refitted = refitter.refit(inserted, face_morphs, edge_morphs, nodes=nodes)
    return PatchRefinement(inserted.part, refitted.faces, refitted.edges, refitted.grids,
                           {k: tuple(int(n) for n in inserted.face_added[k]) for k in sorted(inserted.faces)})
