"""A tolerance that holds: refinement of the faces and edges whose fit misses it (beyond the paper).

The paper keeps every knot vector.  Where a control net is too coarse for the field (a plane's 2x2 bilinear
net under a temperature gradient, an edge with few poles), no choice of poles meets a tolerance.  Refining
the net adds poles without changing the hot shape at all, so the morph is refined where its error is and
fitted again, round after round, until every face's and edge's Δmax holds or ``Settings.max_refinements``
rounds are done:

* The error is the report's (eq. 21): the distance from each node's cold target point to the morphed face
  or edge, found by Gauss-Newton from the node's own foot point (a local distance, never smaller than the
  report's global one).
* A knot span holding a point whose error exceeds the tolerance is halved (knot insertion).  A direction of
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
* Refinement never makes a knot span finer than its nodes can determine: a span (an edge's) or patch (a
  face's) holding a bad node is halved only if each half keeps at least ``degree + 1`` (a face:
  ``(p + 1)(q + 1)``) FE nodes, the count below which :mod:`hot2cold.pipeline.edge_fit` and
  :mod:`hot2cold.pipeline.face_fit` hand it to artificial nodes.  Finer spans would meet the tolerance at
  the nodes by bending between them (more poles than data; the artificial nodes, local linear estimates of
  the field, would decide the shape there).  A face or edge that misses where no span may be halved is
  reported as not refinable.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from enum import Enum
from typing import Callable, NamedTuple

import numpy as np

from ..core.bspline import (BSplineCurve, BSplineSurface, evaluate_surface, knot_breaks, refine_curve,
                            refine_surface, surface_derivatives)
from ..core.footpoint import curve_distances
from .edge_fit import EdgeMorph
from .face_fit import FaceMorph
from ..io.field import DisplacementField
from ..core.model import Classification, Edge, Face, Part, Role, side_along

log = logging.getLogger(__name__)

#: Degree a refined direction is raised to when it is lower.
REFINED_DEGREE = 3

#: Gauss-Newton steps of the local projections.
_NEWTON_STEPS = 8


@dataclass(frozen=True)
class Refinement:
    """What the refinement did to one face (lengths in mm).

    ``missed``: the face missed the tolerance itself (a face may also be refined only because it shares a
    refined edge); ``delta_max_before``/``delta_max_after``: its largest error at its nodes before and after
    (Gauss-Newton distances, see the module docstring); ``residual``: its largest fit residual
    ``|S_cold(u_k, v_k) - d_k|`` at the nodes at the end; ``refinable`` is False when the face still misses
    and its knot spans there hold too few nodes to be halved (see the module docstring).
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


@dataclass(eq=False)
class RefineResult:
    """The refined part (hot geometry, refined faces and edges), the new morphs and what was done."""

    part: Part
    faces: list[FaceMorph]
    edges: list[EdgeMorph]
    face_refinements: list[Refinement]
    edge_refinements: list[EdgeRefinement]
    rounds: int


# ----------------------------------------------------------------------------------------------------------
# Errors: local projections (eq. 21) and edge gaps.
# ----------------------------------------------------------------------------------------------------------

def face_distances(surface: BSplineSurface, points: np.ndarray, uv: np.ndarray, box=None) -> np.ndarray:
    """Distances ``(m,)`` of ``points`` to ``surface`` by Gauss-Newton from the parameters ``uv (m, 2)``, kept
    within ``box`` ``(u0, u1, v0, v1)`` (and the domain): the smallest distance met on the way, an upper
    bound of the distance to the surface."""
    points = np.asarray(points, float)
    uv = np.array(uv, float).reshape(-1, 2)
    u0, u1, v0, v1 = surface.domain
    lo, hi = np.array([u0, v0]), np.array([u1, v1])
    if box is not None:
        lo, hi = np.maximum(lo, [box[0], box[2]]), np.minimum(hi, [box[1], box[3]])
    uv = np.clip(uv, lo, hi)
    best = np.full(len(points), np.inf)
    for step in range(_NEWTON_STEPS + 1):
        r = points - evaluate_surface(surface, uv[:, 0], uv[:, 1])
        best = np.minimum(best, np.linalg.norm(r, axis=1))
        if step == _NEWTON_STEPS:
            break
        su, sv = surface_derivatives(surface, uv[:, 0], uv[:, 1])
        a, b, c = np.sum(su * su, 1), np.sum(su * sv, 1), np.sum(sv * sv, 1)
        det = a * c - b * b
        ok = det > 1e-300
        det = np.where(ok, det, 1.0)
        ru, rv = np.sum(su * r, 1), np.sum(sv * r, 1)
        step_uv = np.column_stack([(c * ru - b * rv) / det, (a * rv - b * ru) / det]) * ok[:, None]
        uv = np.clip(uv + step_uv, lo, hi)
    return best


def _face_errors(face: Face, morph: FaceMorph, cls: Classification, field: DisplacementField):
    """Errors of a face at its nodes: ``(uv (m, 2), error (m,))``, the distances of eq. (21)."""
    nodes = cls.nodes_of(Role.FACE, face.index)
    target = cls.foot[nodes] + field.displacements[nodes]
    return cls.uv[nodes], face_distances(morph.surface, target, cls.uv[nodes], face.uv_box)


def _edge_errors(edge: Edge, morph: EdgeMorph, cls: Classification, field: DisplacementField):
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


def _edge_marks(curve: BSplineCurve, t: np.ndarray, bad: np.ndarray) -> tuple[np.ndarray, bool]:
    """Where an edge is refined: the midpoints of the knot spans holding a bad node whose halves each keep
    at least ``degree + 1`` nodes, and whether it is raised to ``REFINED_DEGREE`` (its bad spans hold
    that many nodes).  A span with fewer nodes than that is not determined by its nodes (its artificial
    nodes would decide it, :func:`hot2cold.pipeline.edge_fit.morph_edge`), so it is not made any finer."""
    degree = max(curve.degree, REFINED_DEGREE)
    need = degree + 1
    breaks = knot_breaks(curve.knots, curve.degree)
    spans = _spans(breaks, t)
    mids, up = [], curve.degree < REFINED_DEGREE
    for r in np.unique(spans[bad]):
        here = t[spans == r]
        mid = 0.5 * (breaks[r] + breaks[r + 1])
        up &= len(here) >= need
        if np.sum(here < mid) >= need and np.sum(here >= mid) >= need:
            mids.append(mid)
    return np.array(mids), bool(up)


def _face_marks(surface: BSplineSurface, uv: np.ndarray, bad: np.ndarray) -> list[tuple[np.ndarray, bool]]:
    """Where a face is refined, per direction (u, v): the midpoints of the knot spans of the patches holding
    a bad node, where both halves of the patch keep at least ``(p + 1)(q + 1)`` nodes (degrees after any
    elevation), and whether the direction is raised to ``REFINED_DEGREE`` (its bad patches hold that many
    nodes).  Patches with fewer nodes are decided by artificial nodes (:mod:`hot2cold.pipeline.face_fit`), not by the
    FE nodes the tolerance is about, so they are not made any finer."""
    degrees = (surface.u_degree, surface.v_degree)
    need = int(np.prod([max(d, REFINED_DEGREE) + 1 for d in degrees]))
    breaks = [knot_breaks(surface.u_knots, degrees[0]), knot_breaks(surface.v_knots, degrees[1])]
    spans = np.column_stack([_spans(breaks[0], uv[:, 0]), _spans(breaks[1], uv[:, 1])])
    out = []
    for axis in (0, 1):
        mids, up = set(), degrees[axis] < REFINED_DEGREE
        for r, s in {tuple(x) for x in spans[bad]}:
            here = uv[(spans[:, 0] == r) & (spans[:, 1] == s), axis]
            lo, hi = breaks[axis][(r, s)[axis]], breaks[axis][(r, s)[axis] + 1]
            mid = 0.5 * (lo + hi)
            up &= len(here) >= need
            if np.sum(here < mid) >= need and np.sum(here >= mid) >= need:
                mids.add(mid)
        out.append((np.array(sorted(mids)), bool(up)))
    return out


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
# The refinement loop.
# ----------------------------------------------------------------------------------------------------------

FitFace = Callable[[Part, Face, list[EdgeMorph]], FaceMorph]
FitEdges = Callable[[Part, list[EdgeMorph], set[int]], list[EdgeMorph]]


def refine(part: Part, cls: Classification, field: DisplacementField, face_morphs: list[FaceMorph],
           edge_morphs: list[EdgeMorph], tolerance: float, max_rounds: int, fit_face: FitFace,
           fit_edges: FitEdges) -> RefineResult:
    """Refine faces and edges until every error is within ``tolerance`` mm or ``max_rounds`` are done.

    ``fit_face(part, face, edge_morphs) -> FaceMorph`` fits a face of a (refined) part against the given edge
    morphs;
    ``fit_edges(part, edge_morphs, refined) -> edge_morphs`` fits the edges in the set ``refined`` again and
    returns every edge's morph (it may touch others, e.g. at corners of tangent edges: an edge whose curve
    object changes counts as changed).  Returns the refined part
    (hot geometry, same shape), the final morphs and one record per face and edge that was refined or missed.
    """
    face_morphs, edge_morphs = list(face_morphs), list(edge_morphs)
    hot_faces, hot_edges = list(part.faces), list(part.edges)
    face_added = np.zeros((len(part.faces), 2), int)
    edge_added = np.zeros(len(part.edges), int)
    face_rounds = np.zeros(len(part.faces), int)
    edge_rounds = np.zeros(len(part.edges), int)

    def errors():
        fe = [_face_errors(f, m, cls, field) for f, m in zip(part.faces, face_morphs)]
        ee = [_edge_errors(e, m, cls, field) for e, m in zip(part.edges, edge_morphs)]
        return fe, ee

    def worst(err):
        return float(err.max()) if len(err) else 0.0

    face_err, edge_err = errors()
    face_before = [worst(e) for _, e in face_err]
    edge_before = [worst(e) for _, e in edge_err]
    stuck_faces: set[int] = set()                # faces and edges that miss where no span may be halved
    stuck_edges: set[int] = set()
    rounds = 0
    while rounds < max_rounds:
        bad_faces = [k for k, (_, e) in enumerate(face_err) if worst(e) > tolerance]
        bad_edges = [k for k, (_, e) in enumerate(edge_err) if worst(e) > tolerance]
        if not bad_faces and not bad_edges:
            stuck_faces, stuck_edges = set(), set()
            break
        classes = _classes(part, face_morphs)
        marks: dict = {}                          # class root -> list of normalised knots to insert
        elevate: set = set()                      # class roots to raise to REFINED_DEGREE
        unplaced_faces, unplaced_edges = set(), set()
        for k in bad_faces:
            uv, err = face_err[k]
            wanted = _face_marks(part.faces[k].surface, uv, err > tolerance)
            if not any(len(m) or up for m, up in wanted):
                unplaced_faces.add(k)
            for axis, (mids, up) in enumerate(wanted):
                member = Member.face(k, axis)
                knots, _ = _knots_degree(part, member)
                root, flip = classes.find(member)
                marks.setdefault(root, []).append(_to_class(mids, knots, flip))
                if up:
                    elevate.add(root)
        for e in bad_edges:
            t, err = edge_err[e]
            mids, up = _edge_marks(part.edges[e].curve, t, err > tolerance)
            if not len(mids) and not up:
                unplaced_edges.add(e)
            member = Member.edge(e)
            knots, _ = _knots_degree(part, member)
            root, flip = classes.find(member)
            marks.setdefault(root, []).append(_to_class(mids, knots, flip))
            if up:
                elevate.add(root)
        groups = classes.members()
        new_faces, new_edges = list(part.faces), list(part.edges)
        changed_faces, changed_edges = set(), set()
        for root, pieces in marks.items():
            s = np.concatenate(pieces)
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
        stuck_faces, stuck_edges = unplaced_faces, unplaced_edges
        if not changed_faces and not changed_edges:
            break
        part = replace(part, faces=new_faces, edges=new_edges)
        fitted = fit_edges(part, edge_morphs, changed_edges)
        moved = changed_edges | {e for e, (a, b) in enumerate(zip(edge_morphs, fitted)) if a.curve is not b.curve}
        edge_morphs = list(fitted)
        edge_rounds[list(changed_edges)] += 1
        refit = set(changed_faces) | {k for k, f in enumerate(part.faces) for use in f.uses if use.edge in moved}
        for k in sorted(refit):
            face_morphs[k] = fit_face(part, part.faces[k], edge_morphs)
            face_rounds[k] += k in changed_faces
        rounds += 1
        face_err, edge_err = errors()
        log.info("refinement round %d: %d faces and %d edges refined; largest error %.3g mm", rounds,
                 len(changed_faces), len(changed_edges),
                 max([worst(e) for _, e in face_err] + [worst(e) for _, e in edge_err] + [0.0]))

    face_reports = []
    for k, (face, hot) in enumerate(zip(part.faces, hot_faces)):
        missed = face_before[k] > tolerance
        if not missed and not face_rounds[k]:
            continue
        s0, s1 = hot.surface, face.surface
        face_reports.append(Refinement(
            k, missed, not (k in stuck_faces and worst(face_err[k][1]) > tolerance),
            int(face_added[k, 0]), int(face_added[k, 1]),
            f"{s0.u_degree}x{s0.v_degree}", f"{s1.u_degree}x{s1.v_degree}",
            "x".join(map(str, s0.shape)), "x".join(map(str, s1.shape)), int(face_rounds[k]),
            face_before[k], worst(face_err[k][1]), worst(node_residuals(face, face_morphs[k], cls, field))))
    edge_reports = []
    for e, (edge, hot) in enumerate(zip(part.edges, hot_edges)):
        missed = edge_before[e] > tolerance
        if edge.degenerate or (not missed and not edge_rounds[e]):
            continue
        edge_reports.append(EdgeRefinement(
            e, missed, not (e in stuck_edges and worst(edge_err[e][1]) > tolerance),
            int(edge_added[e]), hot.curve.degree, edge.curve.degree,
            hot.curve.n_poles, edge.curve.n_poles, int(edge_rounds[e]), edge_before[e], worst(edge_err[e][1])))
    return RefineResult(part, face_morphs, edge_morphs, face_reports, edge_reports, rounds)
