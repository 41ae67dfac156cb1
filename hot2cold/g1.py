"""Restoring tangent (G1) continuity between morphed faces (paper section 5, eq. 56-75; METHOD step 7).

Two faces that met tangentially when hot generally meet with a small kink after the morph, because each face
was fitted to the field on its own.  Where the common edge is a whole side of both surfaces (an iso-side, so
the edge's row of poles is the side row and stays fixed, ``dp_i0 = 0``, eq. 74) the kink is removed by moving
only the *second* row of poles of each face, the row next to the edge:

* at points ``Q`` of the edge the unit normals ``n`` (eq. 59) and ``n*`` (eq. 62) of the two faces, oriented
  alike (a solid's faces may point either way relative to each other), are averaged into
  ``n_T = n + n*`` (eq. 63), the normal of the common tangent plane;
* the tangent ``t_v`` across the edge (eq. 58, 61) is projected onto that plane,
  ``t_T = t_v + dt_v``, ``dt_v = -(t_v . n_T) / (n_T . n_T) n_T`` (eq. 64-65);
* the second-row displacements ``dp_i1`` make the cross derivative equal ``t_T`` (eq. 70):
  ``sum_i dR_i1/dv(u_q, 0) dp_i1 = dt_v(u_q)``, which for a non-rational clamped surface is eq. (75),
  ``sum_i N_i(u_q) dp_i1 = (V_{q+1} / q) dt_v(u_q)``.  Here the row of the derivative basis
  (:func:`~hot2cold.bspline.surface_derivative_bases`) is used as it is, so the system is exact for
  rational surfaces too (weights are kept, so the derivative is linear in the poles).  It is solved in the
  least-squares sense over about ``n_points_factor`` times as many equidistant edge points ``u_q`` as poles
  in the row, by truncated SVD (eq. 19-20).

Both faces move, each towards the common plane.  The cross derivative at a side of a clamped surface depends
only on the side row and the second row, so nothing else of the face's boundary changes; poles of the second
row that lie on a side held by an edge (its two ends, in an untrimmed face) stay fixed.  A face with several
corrected edges solves for all its second rows at once (a corner pole may belong to two of them).  The sides
are named as in :mod:`hot2cold.faces` (``"u0"``, ``"u1"``, ``"v0"``, ``"v1"``); indices number from 0 and
angles are in degrees.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from .bspline import BSplineSurface, surface_derivative_bases, surface_normals
from .faces import SIDES, _side_of
from .lstsq import solve_tsvd
from .model import EdgeUse, Face, Part

log = logging.getLogger(__name__)

#: Reason given for an edge that is not a whole side of both faces' surfaces (trimmed faces, split sides).
NOT_ISO_SIDE = "not an iso-side of both faces"


@dataclass(frozen=True, eq=False)
class TangentEdge:
    """An edge along which two faces of the hot part meet tangentially.

    Attributes
    ----------
    edge : int, index of the edge.
    faces : (int, int), its two faces.
    sides : pair of ``(side, backwards)`` or None per face: the side (``"u0"``, ``"u1"``, ``"v0"``, ``"v1"``)
        of the face's surface the edge runs along as a whole and whether it runs against the side's
        direction (see :func:`hot2cold.faces._side_of`); None when the edge is not a whole side.
    hot_angle_max : float, largest angle in degrees between the two faces' normal lines along the edge.
    """

    edge: int
    faces: tuple[int, int]
    sides: tuple[tuple[str, bool] | None, tuple[str, bool] | None]
    hot_angle_max: float


@dataclass(frozen=True, eq=False)
class G1Report:
    """What :func:`correct_g1` did at one tangent edge (angles in degrees).

    Attributes
    ----------
    edge : int.
    faces : (int, int).
    hot_angle_max : float, largest angle between the normal lines of the hot faces along the edge.
    kink_before_max, kink_after_max : float, the same on the morphed surfaces before and after the
        correction (equal when nothing was corrected; NaN where no normal is defined).
    corrected : bool, whether second rows of poles were moved.
    reason : str, why not (empty when corrected).
    """

    edge: int
    faces: tuple[int, int]
    hot_angle_max: float
    kink_before_max: float
    kink_after_max: float
    corrected: bool
    reason: str


def kink_angles(surface_a: BSplineSurface, uv_a: np.ndarray, surface_b: BSplineSurface,
                uv_b: np.ndarray) -> np.ndarray:
    """Angles in degrees ``(m,)`` between the normal lines of two surfaces at matching points.

    ``uv_a``, ``uv_b`` are (m, 2) parameters of the same m edge points on ``surface_a`` and ``surface_b``.
    The normals (eq. 59, 62) are compared as lines, so the result lies in [0, 90] whichever way each
    surface's normal points: ``atan2(|n x n*|, |n . n*|)``, accurate for small angles.  NaN where a normal is
    undefined (a collapsed side).
    """
    uv_a = np.asarray(uv_a, dtype=float).reshape(-1, 2)
    uv_b = np.asarray(uv_b, dtype=float).reshape(-1, 2)
    if uv_a.shape != uv_b.shape:
        raise ValueError(f"uv_a {uv_a.shape} and uv_b {uv_b.shape} must both be (m, 2)")
    na = surface_normals(surface_a, uv_a[:, 0], uv_a[:, 1])
    nb = surface_normals(surface_b, uv_b[:, 0], uv_b[:, 1])
    sin = np.linalg.norm(np.cross(na, nb), axis=1)
    cos = np.abs(np.sum(na * nb, axis=1))
    return np.degrees(np.arctan2(sin, cos))


def _use_of(face: Face, edge: int) -> EdgeUse:
    for use in face.uses:
        if use.edge == edge:
            return use
    raise ValueError(f"edge {edge} is not in the boundary of face {face.index}")


def _uv_at(use: EdgeUse, t: np.ndarray) -> np.ndarray:
    """The use's pcurve ``(m, 2)`` at edge parameters ``t`` (m,), linearly interpolated between samples."""
    ts, uv = use.t, use.uv
    if len(ts) > 1 and ts[0] > ts[-1]:
        ts, uv = ts[::-1], uv[::-1]
    return np.column_stack([np.interp(t, ts, uv[:, 0]), np.interp(t, ts, uv[:, 1])])


def _matched_uv(use_a: EdgeUse, use_b: EdgeUse) -> tuple[np.ndarray, np.ndarray]:
    """Parameters ``(m, 2)`` on both faces of the edge points sampled by ``use_a``."""
    if use_a.t.shape == use_b.t.shape and np.array_equal(use_a.t, use_b.t):
        return use_a.uv, use_b.uv
    return use_a.uv, _uv_at(use_b, use_a.t)


def kink_added(part: Part, surfaces: list[BSplineSurface], edge: TangentEdge) -> float:
    """How much the morph opened the angle (degrees) between the faces of a tangent ``edge``: the largest
    kink between the morphed ``surfaces`` along it, less the hot one."""
    fa, fb = edge.faces
    uv_a, uv_b = _matched_uv(_use_of(part.faces[fa], edge.edge), _use_of(part.faces[fb], edge.edge))
    return _max(kink_angles(surfaces[fa], uv_a, surfaces[fb], uv_b)) - edge.hot_angle_max


def _max(angles: np.ndarray) -> float:
    finite = angles[np.isfinite(angles)]
    return float(finite.max()) if finite.size else float("nan")


def tangent_edges(part: Part, angle_tol_deg: float = 1.0) -> list[TangentEdge]:
    """Edges shared by two faces whose hot surfaces meet tangentially.

    The normals of both faces are evaluated at the edge's samples on each face (the EdgeUse ``uv``); an edge
    is tangent when the angle between the normal lines stays below ``angle_tol_deg`` at every sample where
    both normals are defined (and at least one is).  Returns the edges in index order.
    """
    out = []
    for edge in part.edges:
        faces = tuple(dict.fromkeys(edge.faces))
        if edge.degenerate or len(faces) != 2:
            continue
        fa, fb = (part.faces[k] for k in faces)
        use_a, use_b = _use_of(fa, edge.index), _use_of(fb, edge.index)
        uv_a, uv_b = _matched_uv(use_a, use_b)
        angle = _max(kink_angles(fa.surface, uv_a, fb.surface, uv_b))
        if np.isfinite(angle) and angle < angle_tol_deg:
            out.append(TangentEdge(edge.index, (faces[0], faces[1]),
                                   (_side_of(fa.surface, use_a), _side_of(fb.surface, use_b)), angle))
    log.info("%d of %d edges are tangent (normals within %.3g deg)", len(out), len(part.edges), angle_tol_deg)
    return out


def _row_mask(shape: tuple[int, int], side: str, second: bool = False) -> np.ndarray:
    """Boolean ``(nu, nv)`` mask of a side's row of poles, or of the row next to it if ``second``."""
    axis, end = SIDES[side]
    k = (1 if second else 0) if end == 0 else (shape[axis] - 2 if second else shape[axis] - 1)
    mask = np.zeros(shape, bool)
    if axis == 0:
        mask[k, :] = True
    else:
        mask[:, k] = True
    return mask


def _held_poles(face: Face, tied: tuple[str, ...]) -> np.ndarray:
    """Boolean ``(nu, nv)`` mask of the poles on the face's tied sides and on sides that are whole edges."""
    shape = face.surface.shape
    held = np.zeros(shape, bool)
    sides = set(tied)
    for use in face.uses:
        found = _side_of(face.surface, use)
        if found is not None:
            sides.add(found[0])
    for side in sides:
        held |= _row_mask(shape, side)
    return held


@dataclass(eq=False)
class _Task:
    """One face's share of one edge's correction."""

    report: int           # index into the reports
    face: int
    side: str
    uv: np.ndarray        # (m, 2) points u_q on this face
    normal_t: np.ndarray  # (m, 3) n_T, eq. (63), NaN rows dropped
    keep: np.ndarray      # (m,) bool, rows where both normals are defined


def correct_g1(part: Part, face_surfaces: list[BSplineSurface], tied_sides: list[tuple[str, ...]],
               edges: list[TangentEdge] | None = None,
               n_points_factor: int = 2) -> tuple[list[BSplineSurface], list[G1Report]]:
    """Remove the kinks the morph left along the hot part's tangent edges.

    Parameters
    ----------
    part : the hot part (its faces' surfaces give the sides and the hot angles).
    face_surfaces : the morphed surface of every face, same degrees, knots and weights as the hot ones.
    tied_sides : per face, the sides whose rows of poles are held by edges (``FaceMorph.tied_sides``).
    edges : the tangent edges to treat; default :func:`tangent_edges` of ``part``.
    n_points_factor : equidistant edge points per pole of a second row (the paper takes about two).

    Returns
    -------
    The surfaces (a new list; faces left alone keep their surface object) and one :class:`G1Report` per
    edge of ``edges``.  An edge is corrected when it is a whole side of both faces, each face has a second
    row that is not a boundary row of its own, and no other edge claims the same second row.
    """
    if len(face_surfaces) != len(part.faces) or len(tied_sides) != len(part.faces):
        raise ValueError(f"{len(part.faces)} faces but {len(face_surfaces)} surfaces and "
                         f"{len(tied_sides)} tied-side tuples")
    if edges is None:
        edges = tangent_edges(part)
    n_points_factor = max(int(n_points_factor), 1)
    surfaces = list(face_surfaces)

    matched, before, reasons = [], [], []
    claimed: dict[tuple[int, str], int] = {}   # (face, second-row key) -> edge that claimed it
    tasks: list[_Task] = []
    for r, te in enumerate(edges):
        fa, fb = (part.faces[k] for k in te.faces)
        use_a, use_b = _use_of(fa, te.edge), _use_of(fb, te.edge)
        uv_a, uv_b = _matched_uv(use_a, use_b)
        matched.append((uv_a, uv_b))
        before.append(_max(kink_angles(surfaces[fa.index], uv_a, surfaces[fb.index], uv_b)))
        sides = (_side_of(fa.surface, use_a), _side_of(fb.surface, use_b))
        reason = ""
        if sides[0] is None or sides[1] is None:
            reason = NOT_ISO_SIDE
        else:
            for face, (side, _) in zip((fa, fb), sides):
                axis, end = SIDES[side]
                n_cross = face.surface.shape[axis]
                key = (face.index, f"{'uv'[axis]}{1 if end == 0 else n_cross - 2}")
                if n_cross < 3:
                    reason = f"the second row of face {face.index} at side {side} is its opposite boundary row"
                elif key in claimed:
                    reason = (f"the second row of face {face.index} at side {side} is also the second row of "
                              f"edge {claimed[key]}")
                elif not (_row_mask(face.surface.shape, side, True)
                          & ~_held_poles(face, tied_sides[face.index])).any():
                    reason = f"every pole of the second row of face {face.index} at side {side} is held"
                if reason:
                    break
        if reason:
            log.info("G1: edge %d (faces %d, %d) not corrected: %s", te.edge, *te.faces, reason)
            reasons.append(reason)
            continue
        reasons.append("")
        for face, (side, _) in zip((fa, fb), sides):
            axis, end = SIDES[side]
            claimed[(face.index, f"{'uv'[axis]}{1 if end == 0 else face.surface.shape[axis] - 2}")] = te.edge
        # Equidistant points u_q along the edge (eq. 75), about n_points_factor per pole of the longer row.
        n_row = max(fa.surface.shape[1 - SIDES[sides[0][0]][0]], fb.surface.shape[1 - SIDES[sides[1][0]][0]])
        m = max(n_points_factor * n_row, 2)
        t = np.linspace(min(use_a.t[0], use_a.t[-1]), max(use_a.t[0], use_a.t[-1]), m)
        uvs = []
        for face, use, (side, _) in zip((fa, fb), (use_a, use_b), sides):
            uv = _uv_at(use, t)
            axis, end = SIDES[side]
            uv[:, axis] = face.surface.domain[2 * axis + end]   # exactly on the side
            uvs.append(uv)
        na = surface_normals(surfaces[fa.index], uvs[0][:, 0], uvs[0][:, 1])
        nb = surface_normals(surfaces[fb.index], uvs[1][:, 0], uvs[1][:, 1])
        keep = np.isfinite(na).all(axis=1) & np.isfinite(nb).all(axis=1)
        sign = np.where(np.sum(na * nb, axis=1) < 0, -1.0, 1.0)
        normal_t = na + sign[:, None] * nb                                      # eq. (63)
        for face, uv, (side, _) in zip((fa, fb), uvs, sides):
            tasks.append(_Task(r, face.index, side, uv, normal_t, keep))

    for k in sorted({task.face for task in tasks}):
        _solve_face(part.faces[k], surfaces, tied_sides[k], [t for t in tasks if t.face == k])

    reports = []
    for te, (uv_a, uv_b), kb, reason in zip(edges, matched, before, reasons):
        # measured on the final surfaces for every edge: a face's other corrections may touch this one too
        after = _max(kink_angles(surfaces[te.faces[0]], uv_a, surfaces[te.faces[1]], uv_b))
        reports.append(G1Report(te.edge, te.faces, te.hot_angle_max, kb, after, not reason, reason))
        if not reason:
            log.info("G1: edge %d (faces %d, %d): kink %.3g -> %.3g deg", te.edge, *te.faces, kb, after)
    return surfaces, reports


def _solve_face(face: Face, surfaces: list[BSplineSurface], tied: tuple[str, ...], tasks: list[_Task]) -> None:
    """Move the second rows of ``face`` named by ``tasks`` so that its cross derivatives lie in the common
    tangent planes (eq. 64-75), all rows at once; ``surfaces[face.index]`` is replaced."""
    surface = surfaces[face.index]
    shape = surface.shape
    flat = surface.poles.reshape(-1, 3)
    free = np.zeros(shape, bool)
    for task in tasks:
        free |= _row_mask(shape, task.side, second=True)
    free &= ~_held_poles(face, tied)
    cols = np.flatnonzero(free.ravel())
    rows, rhs = [], []
    for task in tasks:
        uv = task.uv[task.keep]
        if not len(uv):
            continue
        du, dv = surface_derivative_bases(surface, uv[:, 0], uv[:, 1])
        basis = du if SIDES[task.side][0] == 0 else dv          # derivative across the edge, eq. (58)/(61)
        tangent = basis @ flat                                   # t_v (m, 3)
        n_t = task.normal_t[task.keep]
        delta = -(np.sum(tangent * n_t, axis=1) / np.sum(n_t * n_t, axis=1))[:, None] * n_t   # eq. (65)
        scale = 1.0 / max(float(np.mean(np.linalg.norm(tangent, axis=1))), np.finfo(float).tiny)
        rows.append(scale * basis[:, cols].toarray())            # eq. (70)-(75), dp_i0 = 0 (eq. 74)
        rhs.append(scale * delta)
    if not rows:
        return
    sol = solve_tsvd(np.concatenate(rows), np.concatenate(rhs))
    if sol.rank_deficient:
        log.info("G1: face %d: rank %d of %d second-row poles", face.index, sol.rank, sol.n_unknowns)
    poles = surface.poles.copy()
    poles.reshape(-1, 3)[cols] += sol.x
    surfaces[face.index] = surface.with_poles(poles)
