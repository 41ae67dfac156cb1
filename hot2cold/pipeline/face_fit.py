"""Morphing the face interiors (paper section 3, eq. 23-38; METHOD step 4).

A face's boundary rows of poles come from its morphed edges wherever an edge runs along a whole side of
the surface's domain with the same degree, knots and weights as that row (for an untrimmed face the four
sides u=0, u=1, v=0, v=1 are its edges, eq. 32-36): those rows take the edge's pole displacements
exactly, so the two faces of an edge meet as they met when hot (the rows and the edge's poles agree to
rounding in a B-spline-converted part; a zero field leaves every pole bit for bit where it was).  The
remaining poles solve eq. (38),

    sum_{i,j free} N_i(u_k) N_j(v_k) dp_ij = dd_k - sum_{i,j fixed} N_i(u_k) N_j(v_k) dp_ij,

over the face's own nodes (not those already used by its edges, eq. 37), by truncated SVD (eq. 19-20); the
combinations of poles the SVD drops keep the field's local estimate carried onto the poles (the solver's
``prior``, :func:`_field_prior`) rather than zero, so that an affine field moves every pole exactly even where
the cut-off drops some.
Edges that are not a whole side (trimmed faces, split sides) add rows that hold the surface to the morphed
edge at points along the edge's curve on the face, and knot-span patches with too few data get artificial
nodes (eq. 39) so that no pole is left undetermined.  Artificial rows carry the weight
``Settings.artificial_weight`` (< 1): they settle what the FE nodes leave open and yield where FE nodes speak.
"""
from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .artificial import GAP_SHARE, PRIOR_EPSILON, FieldEstimator, carried, carried_together, estimated
from ..core.bspline import (BSplineSurface, evaluate_curve, evaluate_surface, knot_breaks, span_cells,
                            surface_basis)
from .edge_fit import EdgeMorph
from .fit_inputs import FitInputs
from ..core.lstsq import ReducedRows, reduce_rows, solve_tsvd
from ..core.model import EdgeUse, Face, Part, Role, Side, side_along
from ..core.threads import map_threads
from ..settings import Settings

log = logging.getLogger(__name__)

@dataclass(frozen=True, eq=False)
class FaceMorph:
    """The morph of one face.

    Attributes
    ----------
    index : int, the face.
    surface : BSplineSurface, the morphed surface (same degrees, knots and weights).
    nodes : int, FE nodes in the face interior.
    edge_rows : int, rows that hold the surface to edges that are not whole sides.
    artificial : int, artificial nodes added in knot-span patches with too few data, in the empty cells of
        the others and over the trimmed-away part of the surface (:func:`_artificial_parameters`).
    tied_sides : tuple of Side, sides whose poles moved with a morphed edge (in the order u0, u1, v0, v1).
    unknowns : int, poles solved for.
    rank : int, rank kept by the truncated SVD.
    condition : float, condition number of the kept part of the design matrix (NaN if nothing solved).
    """

    index: int
    surface: BSplineSurface
    nodes: int
    edge_rows: int
    artificial: int
    tied_sides: tuple[Side, ...]
    unknowns: int
    rank: int
    condition: float


def _row(array: np.ndarray, side: Side) -> tuple:
    """Index expression of a side's row of poles in an ``(nu, nv, ...)`` array."""
    i = 0 if side.end == 0 else -1
    return (i, slice(None)) if side.axis == 0 else (slice(None), i)


def _normalised(knots: np.ndarray) -> np.ndarray:
    return (knots - knots[0]) / (knots[-1] - knots[0])


#: A side row of a surface and its edge's poles may be this share of the part's diagonal apart and still be tied.
_TIE_SHARE = 1e-7


def _tie(face: Face, use: EdgeUse, part: Part, edge_morphs: list[EdgeMorph], inputs: FitInputs
         ) -> tuple[Side, np.ndarray] | None:
    """If ``use`` is a whole side compatible with the surface's row there, the side and the displacements
    ``(row length, 3)`` of that row's poles; else None.

    The row and the edge's poles may be up to ``_TIE_SHARE`` of the part's diagonal apart (its own gaps): the
    edge's pole displacements are carried across by the field's change over that gap (``inputs.estimator``), as
    a node's is to its foot point, so that an affine field moves the row exactly."""
    tol, estimator = _TIE_SHARE * part.diagonal, inputs.estimator
    found = side_along(face.surface, use)
    if found is None:
        return None
    side, backwards = found
    surface = face.surface
    row = surface.poles[_row(surface.poles, side)]
    edge = part.edges[use.edge]
    if edge.degenerate:
        if np.ptp(row, axis=0).max() > tol:
            return None
        at = part.vertices[edge.vertices[0]]
        moved = np.broadcast_to(inputs.vertex_disp[edge.vertices[0]], row.shape)
        return side, carried(moved, np.broadcast_to(at, row.shape), row, estimator, GAP_SHARE * part.diagonal)
    curve = edge.curve
    knots = surface.v_knots if side.axis == 0 else surface.u_knots
    degree = surface.v_degree if side.axis == 0 else surface.u_degree
    poles, morphed = curve.poles, edge_morphs[use.edge].curve.poles
    curve_knots = _normalised(curve.knots)
    weights = curve.weights
    if backwards:
        poles, morphed = poles[::-1], morphed[::-1]
        curve_knots = 1.0 - curve_knots[::-1]
        weights = None if weights is None else weights[::-1]
    if (curve.degree != degree or len(poles) != len(row)
            or not np.allclose(curve_knots, _normalised(knots), rtol=0, atol=1e-9)
            or np.abs(poles - row).max() > tol):
        return None
    row_w = np.ones(len(row)) if surface.weights is None else surface.weights[_row(surface.weights, side)]
    ratio = row_w / (np.ones(len(row)) if weights is None else weights)
    if not np.allclose(ratio, ratio[0], rtol=1e-9, atol=0):
        return None
    return side, carried(morphed - poles, poles, row, estimator, GAP_SHARE * part.diagonal)


def _artificial_parameters(surface: BSplineSurface, uv: np.ndarray,
                           trimmed_away: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """Parameters ``(m, 2)`` of the artificial nodes of a face (METHOD step 6, eq. 39).

    Every knot-span patch ``[U_r, U_r+1) x [V_s, V_s+1)`` is cut into ``(p + 1) x (q + 1)`` equal cells, each
    with a candidate point at its centre; the patches along the sides of the domain also carry the points of
    that grid's lines on the side (and the corner), in the cells there.  A patch holding fewer than
    ``(p + 1)(q + 1)`` of the data parameters ``uv`` takes all of its candidates: the paper puts one node at
    the centre of an empty patch, but one node cannot fix the ``(p + 1)(q + 1)`` coefficients of a patch's
    polynomial piece.  Elsewhere a candidate is taken where its cell holds no data: nodes bunched in one end
    of a patch leave the polynomial piece free at the other (as on high-degree hub and casing edges,
    :func:`hot2cold.pipeline.edge_fit._artificial_parameters`, whose error the faces take through their tied
    side rows, many times the field itself), and where ``trimmed_away(uv) -> (m,) bool`` puts it
    outside the face's trimmed domain, so the surface follows the field's continuation there instead of
    wandering.

    The points on the sides hold the outermost strip of the untrimmed surface: without them the last row of
    poles of a trimmed side is fixed only by extrapolating the polynomial piece from the cell centres inside
    the span.  Without them that strip turns a trimmed face's normals far beyond what the field turns them, and
    a thin face may lose singular values to the cut-off of eq. 20; with them the normals turn about as the
    field does.
    """
    p, q = surface.u_degree, surface.v_degree
    ub = knot_breaks(surface.u_knots, p)
    vb = knot_breaks(surface.v_knots, q)
    tu, ru, cu, eu = span_cells(ub, p)
    tv, rv, cv, ev = span_cells(vb, q)
    if len(uv):
        counts = np.histogram2d(uv[:, 0], uv[:, 1], bins=[ub, vb])[0]
        cells = np.histogram2d(uv[:, 0], uv[:, 1], bins=[eu, ev])[0]
    else:
        counts = np.zeros((len(ub) - 1, len(vb) - 1))
        cells = np.zeros((len(eu) - 1, len(ev) - 1))
    u, v = np.meshgrid(tu, tv, indexing="ij")
    r, s = np.meshgrid(ru, rv, indexing="ij")
    i, j = np.meshgrid(cu, cv, indexing="ij")
    grid = np.column_stack([u.ravel(), v.ravel()])
    take = (counts[r.ravel(), s.ravel()] < (p + 1) * (q + 1)) | (cells[i.ravel(), j.ravel()] == 0)
    if trimmed_away is not None and (~take).any():
        take[~take] = trimmed_away(grid[~take])
    return grid[take]


def _field_prior(surface: BSplineSurface, free: np.ndarray, delta: np.ndarray,
                 estimator: FieldEstimator) -> np.ndarray:
    """Displacements ``(n_free, 3)`` of the free poles (``free`` ``(nu * nv,)`` bool; the others fixed at
    ``delta`` ``(nu, nv, 3)``) that carry the field's local estimate over the whole surface: the least-squares
    fit of ``estimator`` at every candidate point of :func:`_artificial_parameters` (the centre of every cell
    and the grid's lines on the sides, at least as many per direction as poles, one in every pole's support).

    The face fit's truncated SVD keeps this in the directions it drops.  The estimate at the poles
    themselves would do for an affine field only: a high-degree surface's poles lie far off it (hundreds of mm
    in a last span), where the local estimate of a curved field is no estimate of what those poles need, many
    times off the best fit there.  The same holds for its edges (:func:`hot2cold.pipeline.edge_fit._field_prior`).
    """
    p, q = surface.u_degree, surface.v_degree
    tu = span_cells(knot_breaks(surface.u_knots, p), p)[0]
    tv = span_cells(knot_breaks(surface.v_knots, q), q)[0]
    u, v = (a.ravel() for a in np.meshgrid(tu, tv, indexing="ij"))
    basis = surface_basis(surface, u, v)
    flat = delta.reshape(-1, 3)
    at_cells, at_poles = estimated(estimator, evaluate_surface(surface, u, v), surface.poles.reshape(-1, 3)[free],
                                   remember=True)
    rhs = at_cells - basis[:, ~free] @ flat[~free]
    return solve_tsvd(basis[:, free], rhs, PRIOR_EPSILON, prior=at_poles).x


@dataclass(frozen=True, eq=False)
class FaceProblem:
    """One face's fit (eq. 38) before its solve, to be solved once or, with other steering rows each time (G1's
    turning rows, G2's bending rows), again and again (:func:`solve_face`).

    Attributes
    ----------
    face : int.
    surface : BSplineSurface, the hot surface.
    delta : (nu, nv, 3) float array, the tied rows' displacements (zero elsewhere).
    free : (nu * nv,) bool array, the poles solved for.
    rows : the design and right-hand side ``(A (s, n_free), B (s, 3))``, or their
        :class:`~hot2cold.core.lstsq.ReducedRows` where there are more rows than free poles.
    prior : callable, the field's estimate at the free poles ``(n_free, 3)`` (:func:`_field_prior`).
    nodes, edge_rows, artificial, tied : as :class:`FaceMorph` (the nodes' rows carry the field's noise).
    """

    face: int
    surface: BSplineSurface
    delta: np.ndarray
    free: np.ndarray
    rows: object
    prior: Callable[[], np.ndarray]
    nodes: int
    edge_rows: int
    artificial: int
    tied: tuple[Side, ...]


def face_problem(face: Face, part: Part, edge_morphs: list[EdgeMorph], inputs: FitInputs, reduce: bool = False
                 ) -> FaceProblem:
    """One face's fit with its boundary taken from the morphed edges (see :func:`morph_face`), before its solve;
    ``reduce``: the rows reduced to their QR factor once (:func:`~hot2cold.core.lstsq.reduce_rows`), for a face
    that will be solved again with steering rows."""
    cls, field, vertex_disp, estimator = inputs.cls, inputs.field, inputs.vertex_disp, inputs.estimator
    surface = face.surface
    nu, nv = surface.shape
    delta = np.zeros((nu, nv, 3))
    fixed = np.zeros((nu, nv), bool)
    tied = []
    uv_rows, carries = [], []          # the edge rows' parameters; their (displacement, at, to) to carry
    for use in face.uses:
        tie = _tie(face, use, part, edge_morphs, inputs)
        if tie is not None:
            side, row_disp = tie
            index = _row(delta, side)
            delta[index] = row_disp
            fixed[index] = True
            tied.append(side)
            continue
        # The surface at the edge's pcurve moves as the edge does.  (Not onto the cold edge: a trimmed face
        # of a boolean may sit up to its edge tolerance off its edge, and that hot gap is kept, not closed;
        # the edge's displacement is carried across the gap by the field's change over it, as a node's is to
        # its foot point, so that an affine field moves the face exactly.)
        edge = part.edges[use.edge]
        if edge.degenerate:
            on_edge = np.broadcast_to(part.vertices[edge.vertices[0]], (len(use.t), 3))
            moved = np.broadcast_to(vertex_disp[edge.vertices[0]], (len(use.t), 3))
        else:
            on_edge = evaluate_curve(edge.curve, use.t)
            moved = evaluate_curve(edge_morphs[use.edge].curve, use.t) - on_edge
        carries.append((moved, on_edge, evaluate_surface(surface, use.uv[:, 0], use.uv[:, 1])))
        uv_rows.append(use.uv)
    edge_rows = sum(len(r) for r in uv_rows)

    nodes = cls.nodes_of(Role.FACE, face.index)
    uv_rows.append(cls.uv[nodes])
    uv = np.concatenate(uv_rows)
    trimmed_away = inputs.trimmed_away
    outside = None if trimmed_away is None else (lambda p: trimmed_away(face.index, p))
    centres = _artificial_parameters(surface, uv, outside)
    # the edges' displacements carried to the surface at their pcurves and the artificial nodes' estimates,
    # from one call of the estimator
    target_rows, at_centres = carried_together(
        carries, estimator, GAP_SHARE * part.diagonal,
        evaluate_surface(surface, centres[:, 0], centres[:, 1]) if len(centres) else None, remember=True)
    target = np.concatenate(target_rows + [field.displacements[nodes]])
    weight = np.ones(len(uv))
    if len(centres):
        uv = np.concatenate([uv, centres])
        target = np.concatenate([target, at_centres])
        weight = np.concatenate([weight, np.full(len(centres), inputs.settings.artificial_weight)])

    free = ~fixed.ravel()
    rows = None
    if free.any():
        basis = surface_basis(surface, uv[:, 0], uv[:, 1])
        basis.data *= np.repeat(weight, np.diff(basis.indptr))                      # rows weighted in place
        flat = delta.reshape(-1, 3)
        rhs = weight[:, None] * target - basis[:, ~free] @ flat[~free]               # eq. (38)
        design = basis[:, free]
        del basis             # one design matrix held through the solve (a face's may hold millions of entries)
        rows = reduce_rows(design, rhs) if reduce and design.shape[0] > design.shape[1] else (design, rhs)
    return FaceProblem(face.index, surface, delta, free, rows, lambda: _field_prior(surface, free, delta, estimator),
                       len(nodes), edge_rows, len(centres), tuple(sorted(set(tied))))


def solve_face(problem: FaceProblem, settings: Settings, noise: float = 0.0, turn: tuple | None = None
               ) -> FaceMorph:
    """The face morph of ``problem`` (eq. 19-20), with ``turn`` rows as :func:`morph_face`'s."""
    surface, free = problem.surface, problem.free
    delta = problem.delta.copy()
    rank, condition = 0, float("nan")
    if free.any():
        flat = delta.reshape(-1, 3)
        steer = None
        if turn is not None:  # rows that steer the fit, not the cut-off (solve_tsvd's steer)
            from scipy import sparse

            extra = sparse.csr_array(turn[0])
            steer = (extra[:, free], turn[1] - extra[:, ~free] @ flat[~free])
        a, b = (problem.rows, None) if isinstance(problem.rows, ReducedRows) else problem.rows
        sol = solve_tsvd(a, b, settings.svd_epsilon, prior=problem.prior, noise=noise,       # eq. (19)-(20)
                         noisy_rows=problem.nodes, steer=steer)
        flat[free] = sol.x
        rank, condition = sol.rank, sol.condition
    return FaceMorph(problem.face, surface.with_poles(surface.poles + delta), problem.nodes, problem.edge_rows,
                     problem.artificial, problem.tied, int(free.sum()), rank, condition)


def morph_face(face: Face, part: Part, edge_morphs: list[EdgeMorph], inputs: FitInputs, turn: tuple | None = None
               ) -> FaceMorph:
    """Morph one face with its boundary taken from the morphed edges (:func:`face_problem`, :func:`solve_face`).

    ``turn``: ``(rows, targets)``, more rows of the fit in the face's pole displacements, ``rows (m, nu * nv)``
    (sparse) and ``targets (m, 3)``, weighted as given: the tangents along a trimming curve turned
    into a common plane (:func:`hot2cold.pipeline.g1.turn_rows`).  They steer the fit but leave the cut-off of
    eq. 20 to the nodes' rows (:func:`~hot2cold.core.lstsq.solve_tsvd`'s ``steer``).

    ``inputs``: what every face fit of the morph reads (:class:`FitInputs`; its ``noise`` smooths the fit).
    """
    return solve_face(face_problem(face, part, edge_morphs, inputs), inputs.settings, inputs.noise, turn)


def morph_faces(part: Part, edge_morphs: list[EdgeMorph], inputs: FitInputs,
                progress: Callable[[int, int], None] | None = None) -> list[FaceMorph]:
    """Morph every face of ``part`` (:func:`morph_face`).

    ``progress(done, total)`` is called after each face if given (from the thread that fitted it, with
    ``inputs.settings.threads`` above 1; one call at a time, ``done`` counting up).
    """
    lock, done = threading.Lock(), [0]              # counts told one at a time, in order, from any thread

    def fit(face: Face) -> FaceMorph:
        morph = morph_face(face, part, edge_morphs, inputs)
        if progress is not None:
            with lock:
                done[0] += 1
                progress(done[0], len(part.faces))
        return morph

    nodes = inputs.cls.counts(Role.FACE, len(part.faces))
    out = map_threads(fit, part.faces, inputs.settings.threads, cost=nodes[[face.index for face in part.faces]])
    log.info("morphed %d faces", len(out))
    return out
