"""Curvature (G2) continuity across tangent edges (the paper's outlook, section 7; beyond METHOD step 7).

Two faces that meet tangentially along an edge share their normals there; they are curvature-continuous
when, in addition, their normal curvatures agree.  Along the edge they agree once the normals do (both
faces contain the edge curve), so what is left is the normal curvature *across* the edge,

    kappa = n . S_cc,   S_cc = a^2 S_uu + 2 a b S_uv + b^2 S_vv,

with ``n`` the unit normal, ``c = a S_u + b S_v`` the unit vector of the tangent plane at right angles to the
edge, and ``(a, b)`` its parameter direction.  The *jump* across the edge is ``|kappa - kappa*|`` with the
other face's normal oriented alike (the sign of ``c`` does not matter, ``kappa`` is even in it).  It is
measured in 1/mm and, to be read on any part, as a share of the curvature where it happens: the larger
``|kappa|`` of the two faces at that point, or one over the part's diagonal where both are nearly flat (a
blade's trailing edge bends 1000 times more than its flanks; a jump is judged against its own place).

An edge was curvature-continuous when hot when its relative jump there is within the G2 tolerance
(``Settings.g2_tolerance``).  With ``Settings.continuity`` ``Continuity.G2`` the morph fits the two faces
again with rows (:func:`bend_rows`) that ask, at points along the edge, for ``S_cc`` to take the common
normal curvature ``kappa_T`` (the mean of the two, as eq. 63 averages the normals), beside the rows that
keep the tangents in the common plane (:func:`hot2cold.pipeline.g1.turn_rows`, eq. 65).  Indices number
from 0.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ..core.bspline import (BSplineSurface, cross, evaluate_surface, surface_derivatives, surface_jet,
                            surface_normals, surface_second_derivative_bases)
from ..core.model import Part
from .g1 import (Neighbours, TangentEdge, _evaluate_by_face, _matched_uv, _use_of, hot_defined, hot_edge_points,
                 mean_spans)

log = logging.getLogger(__name__)


#: How an edge's curvature jump was corrected (``G1Report.g2_reason``).
BENT = "faces fitted again with a common curvature across the edge"
#: Weights of the rows of :func:`bend_rows` in a face's fit, against the FE nodes' (1 each; rows in mm), tried in
#: turn while the jumps stay above the tolerance and the faces may bend.  The lightest comes first: a heavy weight
#: from the start kinks faces bent at a thin trailing edge far beyond the 0.01 deg G1 keeps to, where a light one
#: already meets the tolerance.
BEND_WEIGHTS = (0.1, 1.0, 10.0)
#: Weight of the tangent rows (:func:`hot2cold.pipeline.g1.turn_rows`) beside them in the same fit, above G1's
#: own (:data:`hot2cold.pipeline.g1.TURN_WEIGHT`): at G1's weight the faces bent to a common curvature kink beyond
#: the 0.01 deg G1 keeps to; at this one both the kink and the curvature jump stay within their tolerances.
TANGENT_WEIGHT = 100.0


@dataclass(frozen=True)
class CurvatureJump:
    """The normal curvatures across one edge, sampled at m points.

    Attributes
    ----------
    kappa_a, kappa_b : (m,) float, normal curvature (1/mm) across the edge of each face, against face a's
        normal (face b's normal flipped where it points the other way); NaN where a normal is undefined.
    normal : (m, 3) float, face a's unit normal.
    """

    kappa_a: np.ndarray
    kappa_b: np.ndarray
    normal: np.ndarray

    @property
    def jump(self) -> np.ndarray:
        """``|kappa_a - kappa_b|`` (m,), 1/mm."""
        return np.abs(self.kappa_a - self.kappa_b)

    def relative(self, floor: float) -> float:
        """The largest jump as a share of the curvature where it happens: ``max |kappa_a - kappa_b| /
        max(|kappa_a|, |kappa_b|, floor)`` over the points (``floor`` in 1/mm, for nearly flat faces); NaN
        where no point has both curvatures."""
        scale = np.maximum(np.maximum(np.abs(self.kappa_a), np.abs(self.kappa_b)), floor)
        share = self.jump / scale
        share = share[np.isfinite(share)]
        return float(share.max()) if share.size else float("nan")


def cross_curvature(surface: BSplineSurface, uv: np.ndarray, tangent: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normal curvature of ``surface`` across a curve on it.

    ``uv`` (m, 2) are the curve's points on the surface, ``tangent`` (m, 3) its direction there (any
    length).  Returns ``kappa`` (m,) in 1/mm against the unit normal, the normal ``n`` (m, 3) and the
    parameter direction ``ab`` (m, 2) of the unit cross vector ``c = n x t / |n x t|`` (``a S_u + b S_v = c``,
    from the first fundamental form).  NaN where the normal is undefined.
    """
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    _, s_u, s_v, s_uu, s_uv, s_vv = surface_jet(surface, uv[:, 0], uv[:, 1])
    return _curvature_across((s_u, s_v, s_uu, s_uv, s_vv), surface_normals(surface, uv[:, 0], uv[:, 1]), tangent)


def _curvature_across(jet: tuple[np.ndarray, ...], n: np.ndarray, tangent: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`cross_curvature` from the surface's derivatives ``jet = (S_u, S_v, S_uu, S_uv, S_vv)`` and unit
    normals ``n`` at the points, each (m, 3)."""
    s_u, s_v, s_uu, s_uv, s_vv = jet
    c = cross(n, tangent)
    with np.errstate(divide="ignore", invalid="ignore"):
        c /= np.linalg.norm(c, axis=1, keepdims=True)
        e, f, g = (np.einsum("ij,ij->i", x, y) for x, y in ((s_u, s_u), (s_u, s_v), (s_v, s_v)))
        cu, cv = np.einsum("ij,ij->i", c, s_u), np.einsum("ij,ij->i", c, s_v)
        det = e * g - f * f
        a, b = (g * cu - f * cv) / det, (e * cv - f * cu) / det
    kappa = np.einsum("ij,ij->i", n, a[:, None] ** 2 * s_uu + 2.0 * (a * b)[:, None] * s_uv
                      + b[:, None] ** 2 * s_vv)
    return kappa, n, np.column_stack([a, b])


def _edge_tangents(surface: BSplineSurface, uv: np.ndarray) -> np.ndarray:
    """Directions ``(m, 3)`` of the curve through the points ``surface(uv)`` (m >= 2), by differences."""
    points = evaluate_surface(surface, uv[:, 0], uv[:, 1])
    return np.gradient(points, axis=0)


def curvature_jump(surface_a: BSplineSurface, uv_a: np.ndarray, surface_b: BSplineSurface, uv_b: np.ndarray
                   ) -> CurvatureJump:
    """Normal curvatures across an edge of the two surfaces that meet along it, at matching points
    ``uv_a``, ``uv_b`` (m, 2) ordered along the edge (m >= 2)."""
    uv_a = np.asarray(uv_a, dtype=float).reshape(-1, 2)
    uv_b = np.asarray(uv_b, dtype=float).reshape(-1, 2)
    if uv_a.shape != uv_b.shape or len(uv_a) < 2:
        raise ValueError(f"uv_a {uv_a.shape} and uv_b {uv_b.shape} must both be (m, 2), m >= 2")
    return _jump(_points_jets_normals(surface_a, uv_a[:, 0], uv_a[:, 1]),
                 _points_jets_normals(surface_b, uv_b[:, 0], uv_b[:, 1]))


def _points_jets_normals(surface: BSplineSurface, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``S``, ``S_u``, ``S_v``, ``S_uu``, ``S_uv``, ``S_vv`` and the unit normal of ``surface`` at ``u``, ``v``
    (m,), side by side: ``(m, 21)``."""
    return np.column_stack([evaluate_surface(surface, u, v), *surface_jet(surface, u, v)[1:],
                            surface_normals(surface, u, v)])


def _jump(a: np.ndarray, b: np.ndarray) -> CurvatureJump:
    """:func:`curvature_jump` from :func:`_points_jets_normals` of both surfaces at the matching points, each
    ``(m, 21)``: the edge's direction by differences of face a's points."""
    tangent = np.gradient(a[:, :3], axis=0)
    kappa_a, n_a, _ = _curvature_across(tuple(a[:, 3 * i:3 * i + 3] for i in range(1, 6)), a[:, 18:], tangent)
    kappa_b, n_b, _ = _curvature_across(tuple(b[:, 3 * i:3 * i + 3] for i in range(1, 6)), b[:, 18:], tangent)
    sign = np.where(np.einsum("ij,ij->i", n_a, n_b) < 0, -1.0, 1.0)
    return CurvatureJump(kappa_a, sign * kappa_b, n_a)


def edge_jumps(part: Part, surfaces: list[BSplineSurface], edges: list[TangentEdge]) -> np.ndarray:
    """The largest jump of the normal curvature across each tangent edge of ``edges`` ``(len(edges),)`` on
    ``surfaces`` (one per face of ``part``), at the edge's samples, as a share of the curvature there
    (:meth:`CurvatureJump.relative`, the floor one over the part's diagonal); NaN where not measurable (where
    the hot normals are not, :attr:`~hot2cold.pipeline.g1.TangentEdge.measurable`).  All at once: each face
    evaluated once for the samples of every edge asked of it (a call's cost is mostly its own, not its
    points')."""
    uvs = [_matched_uv(_use_of(part.faces[te.faces[0]], te.edge), _use_of(part.faces[te.faces[1]], te.edge))
           for te in edges]
    asked = [(te.faces[side], uv[side]) for side in (0, 1) for te, uv in zip(edges, uvs)]
    found = _evaluate_by_face(surfaces, asked, _points_jets_normals)
    out = np.full(len(edges), np.nan)
    for r, (te, (uv_a, uv_b)) in enumerate(zip(edges, uvs)):
        if len(uv_a) < 2:
            continue
        jump = _jump(found[r], found[len(edges) + r])
        # not where a collapsed side's normal is noise
        keep = te.measurable if te.measurable is not None else hot_defined(part, te.faces, uv_a, uv_b)
        out[r] = CurvatureJump(np.where(keep, jump.kappa_a, np.nan), np.where(keep, jump.kappa_b, np.nan),
                               jump.normal).relative(1.0 / part.diagonal)
    return out


def bend_rows(near: Neighbours, edges: list[TangentEdge], k: int, weight: float
              ) -> tuple[sparse.csr_array, np.ndarray]:
    """Rows for the fit of face ``k`` (:func:`hot2cold.pipeline.face_fit.morph_face`'s ``turn``) that give its
    normal curvature across each of ``edges`` it bounds the common value.

    At ``near.n_points_factor * (nu + nv)`` points along each edge, with ``kappa``, ``kappa*`` the normal
    curvatures across it of the two morphed ``near.surfaces`` (:func:`curvature_jump`) and ``kappa_T`` their
    mean (the other face's where it is in ``near.kept``, faces that keep their fits), the fit is asked for
    ``S_cc + (kappa_T - kappa) n``: the face's second derivative across the edge, its normal part moved to
    the common curvature.  Rows ``weight * l^2 * B_cc`` (``B_cc = a^2 B_uu + 2 a b B_uv + b^2 B_vv`` of the
    hot face, :func:`~hot2cold.core.bspline.surface_second_derivative_bases`; ``l`` the face's mean knot span
    in mm, so that the rows are lengths) against the pole displacements from the hot face.  Returns the rows
    ``(r, nu * nv)`` (sparse) and targets ``(r, 3)``.
    """
    part, surfaces, kept = near.part, near.surfaces, near.kept
    hot, cold = part.faces[k].surface, surfaces[k]
    spans = mean_spans(hot)
    rows, targets = [], []
    for te in edges:
        if k not in te.faces:
            continue
        other = te.faces[1 - te.faces.index(k)]
        uv, uv_o, measurable = hot_edge_points(part, te, k, max(near.n_points_factor * sum(hot.shape), 3))
        tangent = _edge_tangents(cold, uv)
        kappa, n, ab = cross_curvature(cold, uv, tangent)
        kappa_o, n_o, _ = cross_curvature(surfaces[other], uv_o, tangent)
        kappa_o = np.where(np.einsum("ij,ij->i", n, n_o) < 0, -kappa_o, kappa_o)
        keep = np.isfinite(kappa) & np.isfinite(kappa_o) & np.isfinite(ab).all(axis=1) & measurable
        if not keep.any():
            continue
        wanted_kappa = kappa_o if other in kept else 0.5 * (kappa + kappa_o)
        uv, ab, n = uv[keep], ab[keep], n[keep]
        b_uu, b_uv, b_vv = surface_second_derivative_bases(hot, uv[:, 0], uv[:, 1])
        a, b = ab[:, :1], ab[:, 1:]
        basis = sparse.csr_array(b_uu.multiply(a ** 2) + b_uv.multiply(2.0 * a * b) + b_vv.multiply(b ** 2))
        s_u, s_v = surface_derivatives(hot, uv[:, 0], uv[:, 1])
        length = float(np.mean(spans[0] * np.linalg.norm(s_u, axis=1) + spans[1] * np.linalg.norm(s_v, axis=1))) / 2
        wanted = basis @ cold.poles.reshape(-1, 3) + (wanted_kappa[keep] - kappa[keep])[:, None] * n
        scale = weight * length ** 2
        rows.append(scale * basis)
        targets.append(scale * (wanted - basis @ hot.poles.reshape(-1, 3)))
    if not rows:
        return sparse.csr_array((0, hot.shape[0] * hot.shape[1])), np.zeros((0, 3))
    return sparse.vstack(rows, format="csr"), np.concatenate(targets)
