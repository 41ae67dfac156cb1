"""Morphing the edges first (paper section 2, eq. 1-22; METHOD step 3).

Every edge is morphed once, and both of its faces later take it as it is.  The end poles of a clamped edge
curve are its vertices, and they move with the vertex displacements (eq. 10); the inner poles solve the
least-squares problem of eq. (11)-(18) by truncated SVD (eq. 19-20):

    sum_{i=1..n-1} N_i(u_k) dp_i = dd_k - N_0(u_k) dp_0 - N_n(u_k) dp_n,   k over the edge's nodes.

Where the cut-off drops combinations of inner poles, they keep the field's local estimate carried onto the
poles (the solver's ``prior``, :func:`_field_prior`) rather than zero.  A vertex may sit up to its tolerance
off the ends of its edges: the end poles take the vertex displacement carried across that gap
(:func:`end_displacements`).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from .artificial import GAP_SHARE, PRIOR_EPSILON, FieldEstimator, carried, estimated
from ..core.bspline import BSplineCurve, curve_basis, evaluate_curve, knot_breaks, span_cells
from ..io.field import DisplacementField
from ..core.lstsq import solve_tsvd
from ..core.model import Classification, Edge, Part, Role
from .fit_inputs import FitInputs
from ..settings import FLT_EPSILON

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class EdgeMorph:
    """The morph of one edge.

    Attributes
    ----------
    index : int, the edge.
    curve : BSplineCurve or None, the morphed curve (None for a degenerate edge).
    nodes : int, FE nodes that fed the edge.
    artificial : int, artificial nodes added in knot spans with fewer than degree + 1 nodes and in the empty
        cells of the others (:func:`_artificial_parameters`).
    unknowns : int, inner poles solved for (3 coordinates each).
    rank : int, rank kept by the truncated SVD.
    condition : float, condition number of the kept part of the design matrix (NaN if nothing solved).
    """

    index: int
    curve: BSplineCurve | None
    nodes: int
    artificial: int
    unknowns: int
    rank: int
    condition: float


def vertex_displacements(part: Part, cls: Classification, field: DisplacementField,
                         estimator: FieldEstimator) -> np.ndarray:
    """Displacements ``(nv, 3)`` of the vertices: the mean of the nodes on a vertex, else the local
    linear estimate from the nearest foot points (an artificial node)."""
    disp = estimator(part.vertices) if len(part.vertices) else np.zeros((0, 3))
    for v in range(len(part.vertices)):
        nodes = cls.nodes_of(Role.VERTEX, v)
        if len(nodes):
            disp[v] = field.displacements[nodes].mean(axis=0)
    return disp


def end_displacements(part: Part, edge: Edge, vertex_disp: np.ndarray, estimator: FieldEstimator) -> np.ndarray:
    """The displacements ``(2, 3)`` of the end poles of ``edge``'s curve: its vertices' (eq. 10), carried from
    the vertex to the curve's end by the field's change over the gap between them (a vertex may sit up to its
    tolerance off the ends of its edges; :func:`hot2cold.pipeline.artificial.carried`)."""
    vertices = list(edge.vertices)
    return carried(vertex_disp[vertices], part.vertices[vertices], edge.curve.poles[[0, -1]], estimator,
                   GAP_SHARE * part.diagonal)


def _artificial_parameters(curve: BSplineCurve, t: np.ndarray) -> np.ndarray:
    """Parameters ``(m,)`` of artificial nodes of ``curve`` given its nodes' parameters ``t``: every knot span
    is cut into ``degree + 1`` equal cells (:func:`~hot2cold.core.bspline.span_cells`); a span holding fewer
    than ``degree + 1`` of the ``t`` gets a node at the centre of each of its cells, any other span at the
    centre of each cell that holds none.

    A span's polynomial piece has ``degree + 1`` coefficients; with fewer data it is not determined by the
    nodes (an empty span is the paper's case, a span with a node or two is the same problem on thin
    faces such as a trailing edge), and nodes bunched in one end of a span leave the other end free.
    """
    breaks = knot_breaks(curve.knots, curve.degree)
    candidates, span, cell, edges = span_cells(breaks, curve.degree)
    candidates, span, cell = candidates[1:-1], span[1:-1], cell[1:-1]      # the ends are the vertices'
    counts = np.histogram(t, bins=breaks)[0]
    cells = np.histogram(t, bins=edges)[0]
    return candidates[(counts[span] < curve.degree + 1) | (cells[cell] == 0)]


def _field_prior(curve: BSplineCurve, end_disp: np.ndarray, estimator: FieldEstimator) -> np.ndarray:
    """Displacements ``(n - 2, 3)`` of the inner poles (the ends at ``end_disp (2, 3)``) that carry the field's
    local estimate along the whole curve: the least-squares fit of ``estimator`` at the centre of every cell
    of :func:`_artificial_parameters` and at the ends.  The truncated SVD keeps this in the directions it drops
    (the estimate at the poles themselves is one for an affine field only: see
    :func:`hot2cold.pipeline.face_fit._field_prior`)."""
    t = span_cells(knot_breaks(curve.knots, curve.degree), curve.degree)[0]
    basis = curve_basis(curve, t).toarray()
    at_cells, at_poles = estimated(estimator, evaluate_curve(curve, t), curve.poles[1:-1])
    rhs = at_cells - basis[:, [0, -1]] @ end_disp
    return solve_tsvd(basis[:, 1:-1], rhs, PRIOR_EPSILON, prior=at_poles).x


@dataclass(frozen=True)
class EdgeFitOptions:
    """How an edge is fitted (:func:`morph_edge`).

    Attributes
    ----------
    estimator : FieldEstimator or None, gives artificial nodes in knot spans with too few nodes (None: none are
        added, and the fit has no prior).
    epsilon : float, machine-precision factor of the SVD cut-off (eq. 20).
    artificial_weight : float, weight of the artificial nodes' rows against the FE nodes' (1).
    noise : float, the field's scatter (mm per component, :func:`hot2cold.core.localfit.scatter`): the fit is
        smoothed towards the field's estimate until it leaves that much at the nodes
        (:func:`~hot2cold.core.lstsq.solve_tsvd`).
    """

    estimator: FieldEstimator | None = None
    epsilon: float = FLT_EPSILON
    artificial_weight: float = 1.0
    noise: float = 0.0

    @classmethod
    def of(cls, inputs: FitInputs) -> EdgeFitOptions:
        """The options of a morph's edge fits: its estimator, settings and noise."""
        return cls(inputs.estimator, inputs.settings.svd_epsilon, inputs.settings.artificial_weight, inputs.noise)


def morph_edge(curve: BSplineCurve, t: np.ndarray, disp: np.ndarray, end_disp: np.ndarray,
               options: EdgeFitOptions = EdgeFitOptions(), index: int = -1) -> EdgeMorph:
    """Morph one clamped curve (eq. 10-20).

    Parameters
    ----------
    curve : the hot curve, n poles.
    t : (s,) foot-point parameters of the edge's nodes; disp : (s, 3) their displacements.
    end_disp : (2, 3) displacements of the start and end vertex (eq. 10).
    options : EdgeFitOptions, the estimator of artificial nodes, the SVD cut-off, their weight, the noise.
    index : the edge's index, for the record.
    """
    estimator, epsilon, artificial_weight, noise = (options.estimator, options.epsilon, options.artificial_weight,
                                                    options.noise)
    n = curve.n_poles
    delta = np.zeros((n, 3))
    delta[0], delta[-1] = end_disp
    artificial = 0
    weight = np.ones(len(t))
    if estimator is not None and n > 2:
        t_art = _artificial_parameters(curve, t)
        if len(t_art):
            artificial = len(t_art)
            t = np.concatenate([t, t_art])
            disp = np.concatenate([disp, estimator(evaluate_curve(curve, t_art))])
            weight = np.concatenate([weight, np.full(len(t_art), artificial_weight)])
    rank, condition = 0, float("nan")
    if n > 2 and len(t):
        basis = weight[:, None] * curve_basis(curve, t).toarray()
        rhs = weight[:, None] * disp - basis[:, [0, -1]] @ delta[[0, -1]]        # eq. (11)-(12)
        prior = None if estimator is None else (lambda: _field_prior(curve, end_disp, estimator))
        sol = solve_tsvd(basis[:, 1:-1], rhs, epsilon, prior=prior,         # eq. (13)-(20)
                         noise=noise if prior is not None else 0.0, noisy_rows=len(t) - artificial)
        delta[1:-1] = sol.x
        rank, condition = sol.rank, sol.condition
    elif n > 2:
        # No data at all: move the inner poles with the chord between the end displacements.
        w = np.linspace(0.0, 1.0, n)[1:-1, None]
        delta[1:-1] = (1 - w) * end_disp[0] + w * end_disp[1]
    return EdgeMorph(index, curve.with_poles(curve.poles + delta), len(t) - artificial, artificial,
                     max(n - 2, 0), rank, condition)


def fit_edge(part: Part, edge: Edge, inputs: FitInputs) -> EdgeMorph:
    """Morph ``edge`` of ``part`` (:func:`morph_edge`) from its nodes, its ends' displacements and the estimate,
    settings and noise of ``inputs``; a degenerate edge is carried as a None curve."""
    if edge.degenerate:
        return EdgeMorph(edge.index, None, 0, 0, 0, 0, float("nan"))
    nodes = inputs.cls.nodes_of(Role.EDGE, edge.index)
    return morph_edge(edge.curve, inputs.cls.t[nodes], inputs.field.displacements[nodes],
                      end_displacements(part, edge, inputs.vertex_disp, inputs.estimator), EdgeFitOptions.of(inputs),
                      edge.index)


def morph_edges(part: Part, inputs: FitInputs) -> list[EdgeMorph]:
    """Morph every edge of ``part`` once (degenerate edges are carried as None curves), from the nodes,
    estimate, settings and noise of ``inputs`` (:func:`fit_edge`)."""
    out = [fit_edge(part, edge, inputs) for edge in part.edges]
    log.info("morphed %d edges", len(out))
    return out
