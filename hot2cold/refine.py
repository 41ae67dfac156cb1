"""A tolerance that holds: knot refinement of faces whose fit misses it (beyond the paper).

The paper keeps every knot vector.  Where a face's control net is too coarse for the field (a plane's 2x2
bilinear net under a temperature gradient, a blade with few spanwise poles), no choice of poles meets a
tolerance.  Knot insertion adds poles without changing the hot shape at all
(:func:`hot2cold.bspline.insert_knots`), so the face is refined there and fitted again: each round halves
the knot spans that hold a node whose fit residual ``|S_cold(u_k, v_k) - d_k|`` (an upper bound of the
error of eq. 21) exceeds the tolerance, until it holds or ``Settings.max_refinements`` rounds are done.

A direction is refined only where it keeps the face's ties to its edges: inserting u-knots lengthens the
v=0 and v=1 rows, so u is refined only when neither of those rows is tied to an edge (and likewise v).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from .bspline import evaluate_surface, insert_knots
from .classify import FACE, Classification
from .faces import FaceMorph
from .field import DisplacementField
from .model import Face

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Refinement:
    """What the refinement did to one face: knots added in u and v, nets before and after, rounds run,
    and the largest fit residual at the face's nodes (mm) at the end."""

    face: int
    knots_added_u: int
    knots_added_v: int
    net_before: str
    net_after: str
    rounds: int
    residual: float


def node_residuals(hot: Face, morph: FaceMorph, cls: Classification, field: DisplacementField) -> np.ndarray:
    """Fit residuals ``(m,)`` (mm) at the face's nodes: ``|S_cold(u_k, v_k) - S_hot(u_k, v_k) - dd_k|``."""
    nodes = cls.nodes_of(FACE, hot.index)
    u, v = cls.uv[nodes, 0], cls.uv[nodes, 1]
    target = evaluate_surface(hot.surface, u, v) + field.displacements[nodes]
    return np.linalg.norm(evaluate_surface(morph.surface, u, v) - target, axis=1)


def _span_midpoints(knots: np.ndarray, degree: int, n_poles: int, params: np.ndarray) -> np.ndarray:
    breaks = np.unique(knots[degree:n_poles + 1])
    spans = np.clip(np.searchsorted(breaks, params, side="right") - 1, 0, len(breaks) - 2)
    chosen = np.unique(spans)
    return 0.5 * (breaks[chosen] + breaks[chosen + 1])


def refine_face(face: Face, morph: FaceMorph, cls: Classification, field: DisplacementField, tolerance: float,
                max_rounds: int, fit: Callable[[Face], FaceMorph]) -> tuple[FaceMorph, Refinement | None]:
    """Refine and refit ``face`` (fitted as ``morph``) until its fit residuals are within ``tolerance`` mm.

    ``fit(face) -> FaceMorph`` fits a face (with its refined hot surface).  Returns the final morph and a
    :class:`Refinement`, or None when the face met the tolerance as it was.
    """
    before = "x".join(map(str, face.surface.shape))
    residual = node_residuals(face, morph, cls, field)
    if len(residual) == 0 or residual.max() <= tolerance:
        return morph, None
    nodes = cls.nodes_of(FACE, face.index)
    added = [0, 0]
    rounds = 0
    while rounds < max_rounds and len(residual) and residual.max() > tolerance:
        bad = nodes[residual > tolerance]
        surface = face.surface
        axes = [axis for axis, rows in ((0, ("v0", "v1")), (1, ("u0", "u1")))
                if not set(rows) & set(morph.tied_sides)]
        if not axes:
            break
        for axis in axes:
            knots = surface.u_knots if axis == 0 else surface.v_knots
            degree = surface.u_degree if axis == 0 else surface.v_degree
            mids = _span_midpoints(knots, degree, surface.shape[axis], cls.uv[bad, axis])
            surface = insert_knots(surface, axis, mids)
            added[axis] += len(mids)
        face = replace(face, surface=surface)
        morph = fit(face)
        residual = node_residuals(face, morph, cls, field)
        rounds += 1
        log.info("face %d: refinement round %d, net %s, largest residual %.3g mm", face.index, rounds,
                 "x".join(map(str, surface.shape)), residual.max() if len(residual) else 0.0)
    return morph, Refinement(face.index, added[0], added[1], before, "x".join(map(str, face.surface.shape)),
                             rounds, float(residual.max()) if len(residual) else 0.0)
