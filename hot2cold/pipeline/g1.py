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
  (:func:`~hot2cold.core.bspline.surface_derivative_bases`) is used as it is, so the system is exact for
  rational surfaces too (weights are kept, so the derivative is linear in the poles).  It is solved in the
  least-squares sense over about ``n_points_factor`` times as many equidistant edge points ``u_q`` as poles
  in the row, by truncated SVD (eq. 19-20).

Both faces move, each towards the common plane.  The cross derivative at a side of a clamped surface depends
only on the side row and the second row, so nothing else of the face's boundary changes; poles of the second
row that lie on a side held by an edge (its two ends, in an untrimmed face) stay fixed.  A face with several
corrected edges solves for all its second rows at once (a corner pole may belong to two of them).  The sides
are :class:`hot2cold.core.model.Side` (u0, u1, v0, v1); indices number from 0 and angles are in degrees.
"""
from __future__ import annotations

import functools
import logging
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import sparse

from ..core.bspline import (BSplineCurve, BSplineSurface, cross, evaluated, knot_breaks, normals_and_rounding,
                            surface_derivative_bases, surface_normals)
from ..core.lstsq import solve_tsvd
from ..core.model import EdgeUse, Face, Part, Side, side_along

log = logging.getLogger(__name__)

#: Reason given for an edge that is not a whole side of both faces' surfaces (trimmed faces, split sides), where
#: the second rows cannot turn the faces (:func:`correct_g1`; the morph turns them in their fits, :func:`turn_rows`).
NOT_ISO_SIDE = "the edge is not on a side of the surface"
#: How an edge was corrected: the second rows of poles of faces that have it on a side (eq. 56-75) ...
SECOND_ROWS = "second rows (eq. 56-75)"
#: ... or the fit of a face that has it inside its domain, its tangents there turned (:func:`turn_rows`).
ALONG_CURVE = "fit turned along the trimming curve"
#: Added to a method where the faces were refined (knots inserted) before it: their nets could not remove
#: the kink to 0.01 degrees.
REFINED = "faces refined first"


@dataclass(frozen=True, eq=False)
class TangentEdge:
    """An edge along which two faces of the hot part meet tangentially.

    Attributes
    ----------
    edge : int, index of the edge.
    faces : (int, int), its two faces.
    sides : pair of ``(side, backwards)`` or None per face: the :class:`~hot2cold.core.model.Side` of the
        face's surface the edge runs along as a whole and whether it runs against the side's direction (see
        :func:`hot2cold.core.model.side_along`); None when the edge is not a whole side.
    hot_angle_max : float, largest angle in degrees between the two faces' normal lines along the edge.
    measurable : ``(m,)`` bool or None, :func:`hot_defined` at the edge's own samples (the matched parameters
        of its two uses), found once for the hot faces that every later measure of the edge compares; None:
        found at each measure.
    """

    edge: int
    faces: tuple[int, int]
    sides: tuple[tuple[Side, bool] | None, tuple[Side, bool] | None]
    hot_angle_max: float
    measurable: np.ndarray | None = None


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
    corrected : bool, whether the faces were turned.
    reason : str, why not (empty when corrected).
    method : str, how (empty when not corrected): :data:`SECOND_ROWS` where the faces that turned have the
        edge on a side, :data:`ALONG_CURVE` where a face has it inside its domain (a trimming curve).
    jump_hot, jump_before, jump_after : float, the largest jump of the normal curvature across the edge on
        the hot faces, on the morphed ones before the G2 correction (after G1) and after it, each as a share
        of the curvature where it happens (:func:`hot2cold.pipeline.g2.edge_jumps`; NaN where not measured).
    g2 : bool, whether the hot faces were curvature-continuous there (``jump_hot`` within the G2 tolerance).
    g2_reason : str, for such an edge, how its curvature was corrected, or why not; empty when it was not
        asked for (``Settings.continuity`` G1) or not needed.
    """

    edge: int
    faces: tuple[int, int]
    hot_angle_max: float
    kink_before_max: float
    kink_after_max: float
    corrected: bool
    reason: str
    method: str = ""
    jump_hot: float = float("nan")
    jump_before: float = float("nan")
    jump_after: float = float("nan")
    g2: bool = False
    g2_reason: str = ""


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
    return _line_angles(surface_normals(surface_a, uv_a[:, 0], uv_a[:, 1]),
                        surface_normals(surface_b, uv_b[:, 0], uv_b[:, 1]))


def _line_angles(na: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """Angles in degrees ``(m,)`` between the lines of unit normals ``na``, ``nb`` (m, 3) (:func:`kink_angles`)."""
    sin = np.linalg.norm(cross(na, nb), axis=1)
    cos = np.abs(np.sum(na * nb, axis=1))
    return np.degrees(np.arctan2(sin, cos))


def _evaluate_by_face(surfaces: list[BSplineSurface], asked: list[tuple[int, np.ndarray]],
                      evaluate: Callable[[BSplineSurface, np.ndarray, np.ndarray], np.ndarray] = surface_normals
                      ) -> list[np.ndarray]:
    """``evaluate`` (default :func:`~hot2cold.core.bspline.surface_normals`, rows ``(m, ...)``) of
    ``surfaces[k_i]`` at ``uv_i (m_i, 2)`` for each ``(k_i, uv_i)`` of ``asked``: one evaluation per face for all
    that is asked of it (a call's cost is mostly its own, not its points')."""
    rows: dict[int, list[int]] = {}
    for i, (k, _) in enumerate(asked):
        rows.setdefault(k, []).append(i)
    out: list[np.ndarray] = [np.zeros((0, 3))] * len(asked)
    for k, these in rows.items():
        uv = np.concatenate([asked[i][1] for i in these])
        found = evaluated(evaluate, surfaces[k], uv[:, 0], uv[:, 1])
        for i, n in zip(these, np.split(found, np.cumsum([len(asked[i][1]) for i in these])[:-1])):
            out[i] = n
    return out


def _normals_rounding(surface: BSplineSurface, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """:func:`~hot2cold.core.bspline.normals_and_rounding` as one array ``(m, 4)``: the unit normals, then the
    rounding."""
    return np.column_stack(normals_and_rounding(surface, u, v))


def hot_measurable(part: Part, asked_a: list[tuple[int, np.ndarray]], asked_b: list[tuple[int, np.ndarray]]
                   ) -> list[np.ndarray]:
    """:func:`hot_defined` for many pairs of faces at once: per pair ``i`` the ``(m_i,)`` bool at the matching
    parameters ``asked_a[i] = (face a, uv_a (m_i, 2))`` and ``asked_b[i] = (face b, uv_b (m_i, 2))``, each hot
    face evaluated once for all that is asked of it."""
    hot = [face.surface for face in part.faces]
    found = _evaluate_by_face(hot, list(asked_a) + list(asked_b), _normals_rounding)
    bound = np.radians(MEASURABLE_DEG)
    n = len(asked_a)
    return [np.isfinite(_line_angles(a[:, :3], b[:, :3])) & (a[:, 3] <= bound) & (b[:, 3] <= bound)
            for a, b in zip(found[:n], found[n:])]


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


#: Points where rounding may turn a hot normal by more than this (degrees, a tenth of the 0.01 deg G1 keeps
#: to) are not measured (:func:`hot_defined`).
MEASURABLE_DEG = 1e-3


def hot_defined(part: Part, faces: tuple[int, int], uv_a: np.ndarray, uv_b: np.ndarray) -> np.ndarray:
    """``(m,)`` bool: where both hot faces have a normal at the matching points ``uv_a``, ``uv_b`` (m, 2) that
    rounding turns by at most :data:`MEASURABLE_DEG` (:func:`~hot2cold.core.bspline.normal_rounding`).  A
    collapsed side (a sphere's pole, a cone's apex) stays collapsed after the morph only to rounding, where a
    cold normal is noise and tangent faces can read any angle; so is one collapsed all but to rounding (a
    sliver face's corner, one first derivative vanishingly short against the other), where the noise reads as
    a kink far above what G1 keeps to.  Measures of the morphed faces leave those points out."""
    uv_a, uv_b = (np.asarray(uv, dtype=float).reshape(-1, 2) for uv in (uv_a, uv_b))
    return hot_measurable(part, [(faces[0], uv_a)], [(faces[1], uv_b)])[0]


def edge_kinks(part: Part, surfaces: list[BSplineSurface], edge: TangentEdge, uv: tuple | None = None
               ) -> np.ndarray:
    """The kink angles (degrees, (m,)) between the morphed ``surfaces`` of a tangent ``edge``'s faces at its
    samples (``uv``: the matching parameters, default the edges' own samples), NaN where a hot normal is
    undefined (:func:`hot_defined`)."""
    fa, fb = edge.faces
    own = uv is None
    uv_a, uv_b = _matched_uv(_use_of(part.faces[fa], edge.edge), _use_of(part.faces[fb], edge.edge)) if own else uv
    angles = kink_angles(surfaces[fa], uv_a, surfaces[fb], uv_b)
    measurable = edge.measurable if own and edge.measurable is not None else hot_defined(part, edge.faces, uv_a, uv_b)
    return np.where(measurable, angles, np.nan)


def kink_added(part: Part, surfaces: list[BSplineSurface], edge: TangentEdge) -> float:
    """How much the morph opened the angle (degrees) between the faces of a tangent ``edge``: the largest
    kink between the morphed ``surfaces`` along it (:func:`edge_kinks`), less the hot one."""
    return _max(edge_kinks(part, surfaces, edge)) - edge.hot_angle_max


def kink_maxima(part: Part, surfaces: list[BSplineSurface], edges: list[TangentEdge]) -> np.ndarray:
    """The largest kink (degrees) ``(len(edges),)`` between the morphed ``surfaces`` along each tangent edge of
    ``edges`` (:func:`edge_kinks` at the edges' own samples), all at once: the normals of each face at all its
    edges' samples in one evaluation."""
    uvs = [_matched_uv(_use_of(part.faces[te.faces[0]], te.edge), _use_of(part.faces[te.faces[1]], te.edge))
           for te in edges]
    normals = _evaluate_by_face(surfaces, [(te.faces[side], uv[side]) for side in (0, 1)
                                           for te, uv in zip(edges, uvs)])
    out = np.empty(len(edges))
    for r, (te, (uv_a, uv_b)) in enumerate(zip(edges, uvs)):
        angles = _line_angles(normals[r], normals[len(edges) + r])
        measurable = te.measurable if te.measurable is not None else hot_defined(part, te.faces, uv_a, uv_b)
        out[r] = _max(np.where(measurable, angles, np.nan))
    return out


#: A kink (degrees) the morph adds below this is rounding: such edges are left as they are.
KINK_NOISE_DEG = 1e-6


def kink_bound(hot_angle: float, noise_deg: float, strain: float) -> float:
    """The largest angle (degrees) the morph may add to a hot angle ``hot_angle`` between tangent faces (along an
    edge or at a corner) and leave alone: rounding (``noise_deg``) plus what a field of largest strain
    ``strain`` does to an angle that is not quite zero when hot (an affine map changes angles, by up to about
    twice its strain in proportion)."""
    return noise_deg + 2.0 * strain * hot_angle


def _max(angles: np.ndarray) -> float:
    finite = angles[np.isfinite(angles)]
    return float(finite.max()) if finite.size else float("nan")


def tangent_edges(part: Part, angle_tol_deg: float = 1.0) -> list[TangentEdge]:
    """Edges shared by two faces whose hot surfaces meet tangentially.

    The normals of both faces are evaluated at the edge's samples on each face (the EdgeUse ``uv``); an edge
    is tangent when the angle between the normal lines stays below ``angle_tol_deg`` at every sample where
    both normals are defined (and at least one is).  Returns the edges in index order.  Each face is
    evaluated once for all its edges (:func:`_evaluate_by_face`, :func:`hot_measurable`).
    """
    shared = []
    for edge in part.edges:
        faces = tuple(dict.fromkeys(edge.faces))
        if edge.degenerate or len(faces) != 2:
            continue
        uses = _use_of(part.faces[faces[0]], edge.index), _use_of(part.faces[faces[1]], edge.index)
        shared.append((edge, faces, uses, _matched_uv(*uses)))
    hot = [face.surface for face in part.faces]
    normals = _evaluate_by_face(hot, [(faces[side], uv[side]) for side in (0, 1) for _, faces, _, uv in shared])
    tangent = []
    for r, (edge, faces, uses, uv) in enumerate(shared):
        angle = _max(_line_angles(normals[r], normals[len(shared) + r]))
        if np.isfinite(angle) and angle < angle_tol_deg:
            tangent.append((edge, faces, uses, uv, angle))
    measurable = hot_measurable(part, [(faces[0], uv[0]) for _, faces, _, uv, _ in tangent],
                                [(faces[1], uv[1]) for _, faces, _, uv, _ in tangent])
    out = [TangentEdge(edge.index, (faces[0], faces[1]),
                       (side_along(hot[faces[0]], uses[0]), side_along(hot[faces[1]], uses[1])), angle, defined)
           for (edge, faces, uses, _, angle), defined in zip(tangent, measurable)]
    log.info("%d of %d edges are tangent (normals within %.3g deg)", len(out), len(part.edges), angle_tol_deg)
    return out


def _row_mask(shape: tuple[int, int], side: Side, second: bool = False) -> np.ndarray:
    """Boolean ``(nu, nv)`` mask of a side's row of poles, or of the row next to it if ``second``."""
    axis, end = side.axis, side.end
    k = (1 if second else 0) if end == 0 else (shape[axis] - 2 if second else shape[axis] - 1)
    mask = np.zeros(shape, bool)
    if axis == 0:
        mask[k, :] = True
    else:
        mask[:, k] = True
    return mask


def _side_row(poles: np.ndarray, side: Side, backwards: bool) -> tuple:
    """Index expression of a side's row in a ``(nu, nv, ...)`` array, ordered along the edge."""
    i = 0 if side.end == 0 else -1
    along = slice(None, None, -1) if backwards else slice(None)
    return (i, along) if side.axis == 0 else (along, i)


def _share_side_row(part: Part, surfaces: list[BSplineSurface], faces: tuple[Face, Face],
                    sides: tuple[tuple[Side, bool], tuple[Side, bool]], tied_sides: list[tuple[Side, ...]]) -> None:
    """Make the two faces' side rows along an edge one row again (the paper's common row, eq. 74).

    Faces that are trimmed are fitted each on its own, so their side rows, equal when hot, drift apart by
    the fit's error; then the tangents along the edge differ and no second row can close the kink.  When
    the two hot rows are the same row (same length, degree, knots and weights along the edge, same poles),
    both take the mean of their displacements, or a row tied to the edge is kept and the other takes it.
    """
    rows, hot_rows, knots, weights = [], [], [], []
    for face, (side, backwards) in zip(faces, sides):
        axis = side.axis
        index = _side_row(face.surface.poles, side, backwards)
        rows.append(surfaces[face.index].poles[index])
        hot_rows.append(face.surface.poles[index])
        k = face.surface.v_knots if axis == 0 else face.surface.u_knots
        k = (k - k[0]) / (k[-1] - k[0])
        knots.append(1.0 - k[::-1] if backwards else k)
        w = face.surface.weights
        weights.append(None if w is None else w[index])
        if (face.surface.v_degree if axis == 0 else face.surface.u_degree) != \
                (faces[0].surface.v_degree if sides[0][0].axis == 0 else faces[0].surface.u_degree):
            return
    if (rows[0].shape != rows[1].shape or knots[0].shape != knots[1].shape
            or not np.allclose(knots[0], knots[1], rtol=0, atol=1e-9)
            or np.abs(hot_rows[0] - hot_rows[1]).max() > 1e-9 * part.diagonal):
        return
    if weights[0] is not None or weights[1] is not None:
        wa = np.ones(len(rows[0])) if weights[0] is None else weights[0]
        wb = np.ones(len(rows[1])) if weights[1] is None else weights[1]
        if not np.allclose(wa / wb, (wa / wb)[0], rtol=1e-9, atol=0):
            return
    tied = [side in tied_sides[face.index] for face, (side, _) in zip(faces, sides)]
    if all(tied):
        return
    shared = rows[0] if tied[0] else rows[1] if tied[1] else 0.5 * (rows[0] + rows[1])
    for face, (side, backwards), is_tied in zip(faces, sides, tied):
        if is_tied:
            continue
        poles = surfaces[face.index].poles.copy()
        poles[_side_row(poles, side, backwards)] = shared
        surfaces[face.index] = surfaces[face.index].with_poles(poles)


def _fixed_reason(face: Face, found: tuple[Side, bool] | None, tied: tuple[Side, ...]) -> str:
    """Why ``face`` cannot turn about an edge that runs along or lies on its side ``found``
    (``side_along(..., whole=False)``; None when the edge is not on a side), or "" when its second row there
    has poles free to move."""
    if found is None:
        return NOT_ISO_SIDE
    side = found[0]
    if face.surface.shape[side.axis] < 3:
        return f"the second row of face {face.index} at side {side} is its opposite boundary row"
    if not (_row_mask(face.surface.shape, side, True) & ~_held_poles(face, tied)).any():
        return f"every pole of the second row of face {face.index} at side {side} is held"
    return ""


def _held_poles(face: Face, tied: tuple[Side, ...]) -> np.ndarray:
    """Boolean ``(nu, nv)`` mask of the poles on the face's tied sides and on sides that are whole edges."""
    shape = face.surface.shape
    held = np.zeros(shape, bool)
    sides = {Side(s) for s in tied}                 # a caller may name the sides by value ("u0")
    for use in face.uses:
        found = side_along(face.surface, use)
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
    side: Side
    uv: np.ndarray        # (m, 2) points u_q on this face
    normal_t: np.ndarray  # (m, 3) n_T, eq. (63), NaN rows dropped
    keep: np.ndarray      # (m,) bool, rows where both normals are defined


def correct_g1(part: Part, face_surfaces: list[BSplineSurface], tied_sides: list[tuple[Side, ...]],  # noqa: PLR0913
               edges: list[TangentEdge] | None = None,
               n_points_factor: int = 2, frozen: dict[int, str] | None = None, *, before: np.ndarray | None = None
               ) -> tuple[list[BSplineSurface], list[G1Report]]:
    """Remove the kinks the morph left along the hot part's tangent edges.

    Parameters
    ----------
    part : the hot part (its faces' surfaces give the sides and the hot angles).
    face_surfaces : the morphed surface of every face, same degrees, knots and weights as the hot ones.
    tied_sides : per face, the sides whose rows of poles are held by edges (``FaceMorph.tied_sides``; a
        :class:`~hot2cold.core.model.Side` or its value, "u0" ...).
    edges : the tangent edges to treat; default :func:`tangent_edges` of ``part``.
    n_points_factor : equidistant edge points per pole of a second row (the paper takes about two).
    frozen : faces that must not turn (face index -> why), e.g. because turning would take them off their
        nodes by more than the tolerance; the other face of such an edge turns into their tangent plane.
    before : ``(len(edges),)`` the edges' largest kinks on ``face_surfaces`` (:func:`kink_maxima`) where the
        caller knows them (it corrects the same surfaces again with other faces frozen); None: measured here.

    Returns
    -------
    The surfaces (a new list; faces left alone keep their surface object) and one :class:`G1Report` per
    edge of ``edges``.  A face can turn about an edge when the edge is a whole side of it and its second row
    there is not its opposite boundary row and has poles that no edge holds.  When both faces can, both turn
    to the common plane (eq. 63); when one can, it turns into the other's tangent plane; when neither can,
    the edge is only measured.  A face's second rows for all its edges are solved at once, so a row that is
    the second row of two edges (a face three poles deep) serves both in the least-squares sense.
    """
    if len(face_surfaces) != len(part.faces) or len(tied_sides) != len(part.faces):
        raise ValueError(f"{len(part.faces)} faces but {len(face_surfaces)} surfaces and "
                         f"{len(tied_sides)} tied-side tuples")
    if edges is None:
        edges = tangent_edges(part)
    n_points_factor = max(int(n_points_factor), 1)
    surfaces = list(face_surfaces)

    if before is None:
        before = kink_maxima(part, surfaces, edges)      # as the edges come, before any face turns
    reasons: list[str] = []
    planned: list[_Plan] = []
    for r, te in enumerate(edges):
        plan = _plan(part, surfaces, te, tied_sides, frozen or {}, n_points_factor)
        if isinstance(plan, str):
            log.info("G1: edge %d (faces %d, %d) not corrected: %s", te.edge, *te.faces, plan)
            reasons.append(plan)
            continue
        reasons.append("")
        planned.append(replace(plan, report=r))
    tasks = _tasks(part, surfaces, planned)
    for k in sorted({task.face for task in tasks}):
        _solve_face(part.faces[k], surfaces, tied_sides[k], [t for t in tasks if t.face == k])

    reports = []
    # measured on the final surfaces for every edge: a face's other corrections may touch this one too
    afters = kink_maxima(part, surfaces, edges)
    for te, kb, reason, after in zip(edges, before, reasons, afters):
        after = float(after)
        reports.append(G1Report(te.edge, te.faces, te.hot_angle_max, kb, after, not reason, reason,
                                "" if reason else SECOND_ROWS))
        if not reason:
            log.info("G1: edge %d (faces %d, %d): kink %.3g -> %.3g deg", te.edge, *te.faces, kb, after)
    return surfaces, reports


@dataclass(frozen=True, eq=False)
class _Plan:
    """How :func:`correct_g1` treats one tangent edge.

    Attributes
    ----------
    faces : the edge's two faces.
    sides : per face, the side of its surface the edge lies along and whether backwards (``side_along``), or
        None along a trimming curve.
    why : per face, why it may not move ("" where it may).
    uvs : per face, the parameters ``(m, 2)`` of the equidistant edge points ``u_q`` (eq. 75).
    report : int, the edge's index in :func:`correct_g1`'s ``edges`` (that of its report).
    """

    faces: tuple[Face, Face]
    sides: tuple
    why: tuple[str, str]
    uvs: tuple[np.ndarray, np.ndarray]
    report: int = -1


def _plan(part: Part, surfaces: list[BSplineSurface], te: TangentEdge, tied_sides: list[tuple[Side, ...]],
          frozen: dict[int, str], n_points_factor: int) -> _Plan | str:
    """How :func:`correct_g1` treats tangent edge ``te``: its faces, their sides along it, why either may not
    move and the points ``u_q`` along it; or why it is not corrected (neither face may move).  Where the edge
    is a side of both faces their side rows are made one (``surfaces`` changes)."""
    fa, fb = (part.faces[k] for k in te.faces)
    use_a, use_b = _use_of(fa, te.edge), _use_of(fb, te.edge)
    # A trimmed face's edge may cover only part of a side: the cross derivative along a side depends on
    # the side row and the second row only, whatever part of the side the edge covers.
    sides = (side_along(fa.surface, use_a, whole=False), side_along(fb.surface, use_b, whole=False))
    why = tuple(frozen.get(face.index) or _fixed_reason(face, found, tied_sides[face.index])
                for face, found in zip((fa, fb), sides))
    if all(why):
        return why[0] if why[0] == why[1] else "; ".join(why)
    if any(why):
        log.info("G1: edge %d (faces %d, %d): one face moves (%s)", te.edge, *te.faces, why[0] or why[1])
    if None not in sides:
        _share_side_row(part, surfaces, (fa, fb), sides, tied_sides)
    # Equidistant points u_q along the edge (eq. 75), about n_points_factor per pole of the longer row.
    n_row = max(face.surface.shape[1 - found[0].axis] for face, found in zip((fa, fb), sides) if found)
    m = max(n_points_factor * n_row, 2)
    t = np.linspace(min(use_a.t[0], use_a.t[-1]), max(use_a.t[0], use_a.t[-1]), m)
    uvs = []
    for face, use, found in zip((fa, fb), (use_a, use_b), sides):
        uv = _uv_at(use, t)
        if found is not None:
            axis, end = found[0].axis, found[0].end
            uv[:, axis] = face.surface.domain[2 * axis + end]   # exactly on the side
        uvs.append(uv)
    return _Plan((fa, fb), sides, why, tuple(uvs))


def _tasks(part: Part, surfaces: list[BSplineSurface], planned: list[_Plan]) -> list[_Task]:
    """Each face's share of the ``planned`` edges' corrections: the common plane's normal ``n_T`` at the points
    ``u_q`` (eq. 63; the fixed face's own normal where one face may not move).  The normals of every edge's
    points at once, face by face, on ``surfaces`` (their side rows shared: the surfaces the second rows are
    solved on), and only where the hot ones are defined."""
    asked = [(plan.faces[side].index, plan.uvs[side]) for side in (0, 1) for plan in planned]
    normals = _evaluate_by_face(surfaces, asked)
    measurable = hot_measurable(part, asked[:len(planned)], asked[len(planned):])
    tasks: list[_Task] = []
    for i, plan in enumerate(planned):
        na, nb = normals[i], normals[len(planned) + i]
        keep = np.isfinite(na).all(axis=1) & np.isfinite(nb).all(axis=1) & measurable[i]
        sign = np.where(np.sum(na * nb, axis=1) < 0, -1.0, 1.0)
        if plan.why[0]:
            normal_t = na                          # face a cannot move: b turns into its tangent plane
        elif plan.why[1]:
            normal_t = nb
        else:
            normal_t = na + sign[:, None] * nb                                  # eq. (63)
        for face, uv, found, fixed in zip(plan.faces, plan.uvs, plan.sides, plan.why):
            if not fixed:
                tasks.append(_Task(plan.report, face.index, found[0], uv, normal_t, keep))
    return tasks


def _solve_face(face: Face, surfaces: list[BSplineSurface], tied: tuple[Side, ...], tasks: list[_Task]) -> None:
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
        basis = du if task.side.axis == 0 else dv          # derivative across the edge, eq. (58)/(61)
        tangent = basis @ flat                                   # t_v (m, 3)
        n_t = task.normal_t[task.keep]
        delta = -(np.sum(tangent * n_t, axis=1) / np.sum(n_t * n_t, axis=1))[:, None] * n_t   # eq. (65)
        scale = 1.0 / max(float(np.mean(np.linalg.norm(tangent, axis=1))), np.finfo(float).tiny)
        rows.append(scale * basis.toarray()[:, cols])            # eq. (70)-(75), dp_i0 = 0 (eq. 74)
        rhs.append(scale * delta)
    if not rows:
        return
    sol = solve_tsvd(np.concatenate(rows), np.concatenate(rhs))
    if sol.rank_deficient:
        log.info("G1: face %d: rank %d of %d second-row poles", face.index, sol.rank, sol.n_unknowns)
    poles = surface.poles.copy()
    poles.reshape(-1, 3)[cols] += sol.x
    surfaces[face.index] = surface.with_poles(poles)


def mean_spans(surface: BSplineSurface) -> list[float]:
    """The mean knot span ``[h_u, h_v]`` of ``surface`` in each parameter direction."""
    return [float(np.diff(knot_breaks(knots, p)).mean())
            for knots, p in ((surface.u_knots, surface.u_degree), (surface.v_knots, surface.v_degree))]


def edge_points(part: Part, edge: TangentEdge, k: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """``m`` equidistant points of a tangent ``edge`` (in its parameter) as ``(uv, uv_other)``, each (m, 2):
    on face ``k`` and on the edge's other face."""
    other = edge.faces[1 - edge.faces.index(k)]
    use, use_o = _use_of(part.faces[k], edge.edge), _use_of(part.faces[other], edge.edge)
    t = np.linspace(min(use.t[0], use.t[-1]), max(use.t[0], use.t[-1]), m)
    return _uv_at(use, t), _uv_at(use_o, t)


def hot_edge_points(part: Part, edge: TangentEdge, k: int, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`edge_points` ``(uv, uv_other)`` and :func:`hot_defined` there ``(m,)``, kept on the tangent ``edge``
    per face, point count and the two hot faces (the objects: a refined part's are others), read-only: the
    rows that steer a face's fit (:func:`turn_rows`, :func:`~hot2cold.pipeline.g2.bend_rows`) ask for the
    same points of the hot faces in every round of G1 and G2 and every trial."""
    other = edge.faces[1 - edge.faces.index(k)]
    key = (k, m, part.faces[k], part.faces[other])
    known = edge.__dict__.setdefault("_hot_points", {})     # (a frozen dataclass: its __dict__ takes a cache)
    if key not in known:
        uv, uv_o = edge_points(part, edge, k, m)
        found = (uv, uv_o, hot_defined(part, (k, other), uv, uv_o))
        for a in found:
            a.flags.writeable = False
        known[key] = found
    return known[key]


def kink_misses(part: Part, surfaces: list[BSplineSurface], edges: list[TangentEdge], limit_deg: float,
                n_points_factor: int = 2) -> dict[int, np.ndarray]:
    """Where the morphed ``surfaces`` kink a tangent edge of ``edges`` more than ``limit_deg`` beyond the hot
    faces: per face, the parameters ``(m, 2)`` of those edge points (the edge's own samples, where the
    report measures it, and ``n_points_factor * (nu + nv)`` equidistant points, ``nu x nv`` the larger
    face's net); faces without such points are left out."""
    hot = [face.surface for face in part.faces]
    found: dict[int, list[np.ndarray]] = {}
    for te in edges:
        fa, fb = te.faces
        m = max(n_points_factor * max(sum(hot[fa].shape), sum(hot[fb].shape)), 2)
        own = _matched_uv(_use_of(part.faces[fa], te.edge), _use_of(part.faces[fb], te.edge))
        uv_a, uv_b = (np.concatenate(pair) for pair in zip(own, edge_points(part, te, fa, m)))
        added = kink_angles(surfaces[fa], uv_a, surfaces[fb], uv_b) - kink_angles(hot[fa], uv_a, hot[fb], uv_b)
        bad = np.isfinite(added) & (added > limit_deg)
        if bad.any():
            found.setdefault(fa, []).append(uv_a[bad])
            found.setdefault(fb, []).append(uv_b[bad])
    return {k: np.concatenate(uv) for k, uv in found.items()}


#: Weight of the rows of :func:`turn_rows` in a face's fit, against the FE nodes' (1 each; rows in mm).
TURN_WEIGHT = 10.0


@dataclass(frozen=True, eq=False)
class Neighbours:
    """What the rows that steer one face's fit towards its neighbours' read (:func:`turn_rows`,
    :func:`~hot2cold.pipeline.g2.bend_rows`).

    Attributes
    ----------
    part : Part, the hot part.
    surfaces : list of BSplineSurface, the morphed surface of every face.
    kept : frozenset of int, faces that keep their fits: a face next to one turns (or bends) to it instead of
        to the common plane (curvature).
    n_points_factor : int, points along an edge per pole of the face's net, ``nu + nv`` (the paper takes about
        two).
    """

    part: Part
    surfaces: list[BSplineSurface]
    kept: frozenset = frozenset()
    n_points_factor: int = 2


def turn_rows(near: Neighbours, edges: list[TangentEdge], k: int, weight: float, sides: bool = False
              ) -> tuple[np.ndarray, np.ndarray]:
    """Rows for the fit of face ``k`` (:func:`hot2cold.pipeline.face_fit.morph_face`'s ``turn``) that turn its
    tangents along those of ``edges`` that lie inside its domain (with ``sides``, along all of them) into the
    common planes.

    At ``near.n_points_factor * (nu + nv)`` points ``(u_q, v_q)`` along each such edge, with ``n`` the unit
    normal of the common plane of the two morphed ``near.surfaces`` there (eq. 63) and ``S_u``, ``S_v`` the
    face's tangents, the fit is asked for ``S_u - (S_u . n) n`` and ``S_v - (S_v . n) n`` (eq. 64-65, per
    parameter direction; where the other face is in ``near.kept``, faces that do not turn, its own tangent
    plane instead):
    rows ``weight * h * dR_i/du(u_q, v_q)`` (``h``: the mean knot span, so that the rows are
    lengths, mm) against the pole displacements from the hot face, the targets less the hot tangents.  In
    the fit itself, next to the face's nodes, the face turns where its nodes let it.  Returns the rows
    ``(r, nu * nv)`` (sparse) and targets ``(r, 3)`` (none: ``(0, nu * nv)``, ``(0, 3)``).
    """
    part, surfaces, kept = near.part, near.surfaces, near.kept
    hot, cold = part.faces[k].surface, surfaces[k]
    spans = mean_spans(hot)
    rows, scales, targets = [], [], []
    for te in edges:
        if k not in te.faces or (te.sides[te.faces.index(k)] is not None and not sides):
            continue
        other = te.faces[1 - te.faces.index(k)]
        uv, uv_o, measurable = hot_edge_points(part, te, k, max(near.n_points_factor * sum(hot.shape), 2))
        # (the same neighbours' normals at the same points in every round and trial: kept by content)
        n = evaluated(surface_normals, cold, uv[:, 0], uv[:, 1])
        n_o = evaluated(surface_normals, surfaces[other], uv_o[:, 0], uv_o[:, 1])
        keep = np.isfinite(n).all(axis=1) & np.isfinite(n_o).all(axis=1) & measurable
        n_t = n_o if other in kept else n + np.where(np.sum(n * n_o, axis=1) < 0, -1.0, 1.0)[:, None] * n_o
        n_t = n_t[keep] / np.linalg.norm(n_t[keep], axis=1, keepdims=True)
        bases = surface_derivative_bases(hot, uv[keep, 0], uv[keep, 1])
        for basis, step in zip(bases, spans):
            tangent = basis @ cold.poles.reshape(-1, 3)
            wanted = tangent - np.sum(tangent * n_t, axis=1)[:, None] * n_t                 # eq. (65)
            rows.append(basis)
            scales.append(np.full(basis.nnz, weight * step))
            targets.append(weight * step * (wanted - basis @ hot.poles.reshape(-1, 3)))
    if not rows:
        return sparse.csr_array((0, hot.shape[0] * hot.shape[1])), np.zeros((0, 3))
    stacked = sparse.vstack(rows, format="csr")
    stacked.data *= np.concatenate(scales)          # each basis times its weight and span, as one product
    return stacked, np.concatenate(targets)


# ------------------------------------------------------------------------------------------------------
# Corners: the ends of tangent edges (beyond the paper).
#
# At a vertex the cross derivative of a face is the tangent of its other edge there (for an untrimmed face
# the second row's end pole is that edge's pole next to the vertex), so the second-row correction above
# cannot remove a kink at the ends of a tangent edge: the edges, each fitted on its own, decide it.  Faces
# that are tangent at a vertex have one tangent plane there exactly when all their edges' tangents at the
# vertex lie in one plane; this is restored on the morphed edges, before the faces are fitted to them.
# ------------------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class CornerReport:
    """What :func:`correct_corners` did at one vertex where tangent faces meet (angles in degrees).

    Attributes
    ----------
    vertex : int.
    faces : tuple of int, the faces that meet tangentially there (joined by tangent edges at the vertex).
    hot_angle, angle_before, angle_after : float, the largest angle between two of those faces' normal lines
        at the vertex (estimated from the tangents of each face's two edges there) on the hot part, on the
        morphed edges, and after the correction.
    edges : tuple of int, edges whose pole next to the vertex moved.
    reason : str, why nothing moved (empty when corrected).
    """

    vertex: int
    faces: tuple[int, ...]
    hot_angle: float
    angle_before: float
    angle_after: float
    edges: tuple[int, ...]
    reason: str


def _end_tangent(curve: BSplineCurve, at_start: bool) -> np.ndarray:
    """Direction ``(3,)`` of ``curve`` at an end, pointing into the curve: ``P_1 - P_0`` or ``P_n-2 - P_n-1``
    (parallel to the end derivative of a clamped curve, rational or not)."""
    poles = curve.poles
    return poles[1] - poles[0] if at_start else poles[-2] - poles[-1]


def _unit(x: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(x)
    return x / norm if norm > 0 else np.full_like(x, np.nan)


def _line_angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arctan2(np.linalg.norm(cross(a, b)), abs(np.dot(a, b)))))


#: A face whose two edges meet at a vertex at less than this angle (degrees, hot) has a smooth boundary
#: there: its edges do not decide its normal.
_MIN_CORNER_DEG = 5.0


def _edges_at(part: Part, face: int, vertex: int) -> list:
    return [e for e in map(part.edges.__getitem__, part.vertex_edges[vertex])
            if face in e.faces and not e.degenerate and e.vertices[0] != e.vertices[1]]


def _corner_edges(part: Part, face: int, vertex: int) -> tuple | None:
    """The two edges of ``face`` at ``vertex`` where they meet at a corner of the hot part (not tangent to each
    other: at :data:`_MIN_CORNER_DEG` or more), and whether each starts there; None where the face has not
    exactly two edges there or they meet tangentially.  Kept on the part per face and vertex (a hot part's,
    asked at every corner correction and every G1 round and trial)."""
    known = part.__dict__.setdefault("_corner_edges", {})   # (a frozen dataclass: its __dict__ takes a cache)
    key = (face, vertex)
    if key not in known:
        at = _edges_at(part, face, vertex)
        found = None
        if len(at) == 2:
            starts = tuple(e.vertices[0] == vertex for e in at)
            if _line_angle(*(_end_tangent(e.curve, start) for e, start in zip(at, starts))) >= _MIN_CORNER_DEG:
                found = (at[0], at[1], starts)
        known[key] = found
    return known[key]


def _corner_normals(part: Part, faces: list[int], vertex: int, curves: list[BSplineCurve | None]) -> dict:
    """Per face of ``faces`` with exactly two edges at ``vertex`` meeting at a corner (not tangent to each
    other on the hot part, :func:`_corner_edges`): the unit normal ``(3,)`` from the cross product of their
    tangents there on ``curves`` (orientation arbitrary)."""
    out = {}
    for k in faces:
        found = _corner_edges(part, k, vertex)
        if found is None:
            continue
        a, b, (start_a, start_b) = found
        n = _unit(cross(_end_tangent(curves[a.index], start_a), _end_tangent(curves[b.index], start_b)))
        if np.isfinite(n).all():
            out[k] = n
    return out


def _cluster_normals(part: Part, faces: list[int], vertex: int, curves: list[BSplineCurve | None],
                     fixed: dict, decided: set | None) -> dict:
    """Normals at ``vertex`` of the faces of a cluster: ``fixed`` ones (anchors) as given, the others from
    their edges' tangents on ``curves`` where ``decided`` (None: wherever two edges meet at a corner)."""
    out = _corner_normals(part, faces, vertex, curves)
    if decided is not None:
        out = {k: n for k, n in out.items() if (vertex, k) in decided}
    out.update(fixed)
    return out


def edge_decided(part: Part, tied_sides: list[tuple[Side, ...]] | None = None) -> set[tuple[int, int]]:
    """The ``(vertex, face)`` pairs where the face's normal at the vertex is the cross product of its two
    edges' tangents: the vertex is a corner of the face's surface and both edges there are whole sides,
    tied to the face's rows (``FaceMorph.tied_sides``; None: before the fit, every whole side counts), so
    the poles next to the corner are those edges' poles."""
    out = set()
    for face in part.faces:
        sides = {}
        for use in face.uses:
            found = side_along(face.surface, use)
            if found is not None:
                sides[use.edge] = found[0]
        for v in {v for e in sides for v in part.edges[e].vertices}:
            at = _edges_at(part, face.index, v)
            tied = sides.values() if tied_sides is None else tied_sides[face.index]
            if len(at) == 2 and all(sides.get(e.index) in tied for e in at) \
                    and len({sides[e.index].axis for e in at}) == 2:
                out.add((v, face.index))
    return out


def surface_corner_normals(part: Part, surfaces: list[BSplineSurface], pairs) -> dict:
    """Unit normals ``(3,)`` of ``surfaces[face]`` at ``vertex`` for each ``(vertex, face)`` of ``pairs``
    (taken at the end of the face's pcurve of an edge at the vertex)."""
    out = {}
    for v, k in pairs:
        face = part.faces[k]
        for use in face.uses:
            edge = part.edges[use.edge]
            if edge.degenerate or v not in edge.vertices or edge.vertices[0] == edge.vertices[1]:
                continue
            t_end = edge.curve.knots[0] if edge.vertices[0] == v else edge.curve.knots[-1]
            uv = use.uv[int(np.argmin(np.abs(use.t - t_end)))]
            n = surface_normals(surfaces[k], uv[:1], uv[1:])[0]
            if np.isfinite(n).all():
                out[(v, k)] = n
            break
    return out


def _spread(normals: dict) -> float:
    """Largest angle (degrees) between two of the normal lines in ``normals``."""
    vals = list(normals.values())
    return max((_line_angle(a, b) for i, a in enumerate(vals) for b in vals[i + 1:]), default=0.0)


def correct_corners(part: Part, curves: list[BSplineCurve | None], edges: list[TangentEdge],  # noqa: PLR0913
                    anchors: dict | None = None, decided: set[tuple[int, int]] | None = None, strain: float = 0.0,
                    *, vertices: set[int] | None = None) -> tuple[list[BSplineCurve | None], list[CornerReport]]:
    """Give the morphed edges at each vertex of a tangent edge one common tangent plane.

    Parameters
    ----------
    part : the hot part.
    curves : the morphed curve of every edge (None for degenerate edges), same degrees, knots and weights.
    edges : the hot part's tangent edges (:func:`tangent_edges`).
    anchors : ``{(vertex, face): unit normal (3,)}`` of faces whose normal at the vertex their edges do not
        decide (a trimmed face, a face with a smooth boundary there), measured on their fitted surfaces:
        the common plane is then theirs (their mean), and only the edges of faces in ``decided`` move.
    decided : the ``(vertex, face)`` pairs whose normal the edges decide (:func:`edge_decided`); default:
        every face with two edges meeting at a corner there.
    strain : the field's largest strain (:class:`~hot2cold.pipeline.checks.FieldScale`).  A field turns the
        faces at a corner that is not quite one plane when hot by up to about twice its strain times their
        angle (an affine map changes angles); that is the field's, not a kink the morph added.  Corners where
        the morph opened the angle between the faces by less than :data:`KINK_NOISE_DEG` plus that are left
        alone (:func:`kink_bound`).
    vertices : the vertices whose corners to correct (default: every vertex of a tangent edge); the others'
        edges keep their curves there.  The correction is not a projection (on its own output it can move an
        edge again, by a fraction of its first move), so corners already corrected are best left alone:
        :func:`corners_touched` gives the vertices whose corners a refit of some edges changed.

    At a vertex, the faces joined by tangent edges there form a cluster.  Its common plane has the normal
    ``n_T``, the mean of the faces' normals (each the cross product of its two edges' tangents, oriented
    alike), as eq. (63) averages two; tangents that cannot turn (an edge with two poles, a line) are removed
    from ``n_T`` first.  Each edge that bounds a face of the cluster then has its pole next to the vertex
    moved, by the least change, so that ``n_T . (P_1 - P_0) = 0``; an edge constrained at both ends solves
    both conditions at once.  The end poles (the vertices) never move, so positions change by about the
    kink angle times the first pole spacing.

    Returns the curves (a new list; edges left alone keep their curve object) and one report per corrected
    or examined vertex.
    """
    if len(curves) != len(part.edges):
        raise ValueError(f"{len(part.edges)} edges but {len(curves)} curves")
    corners = _Corners(part, curves, anchors or {}, decided, strain)
    by_vertex: dict[int, list[TangentEdge]] = {}
    for te in edges:
        for v in set(part.edges[te.edge].vertices):
            if vertices is None or v in vertices:
                by_vertex.setdefault(v, []).append(te)
    pending = [corners.plan(v, faces) for v in sorted(by_vertex) for faces in _clusters(by_vertex[v])]
    curves = corners.moved()
    reports = []
    for corner in pending:
        after_n = _cluster_normals(part, list(corner.faces), corner.vertex, curves, corner.anchors, decided)
        after = _spread(after_n) if len(after_n) > 1 else corner.angle_before
        reports.append(CornerReport(corner.vertex, corner.faces, corner.hot_angle, corner.angle_before, after,
                                    corner.edges, corner.reason))
        if not corner.reason:
            log.info("G1: vertex %d (faces %s): corner angle %.3g -> %.3g deg", corner.vertex, corner.faces,
                     corner.angle_before, after)
    return curves, reports


def corners_touched(part: Part, curves: list[BSplineCurve | None], edges: set[int]) -> set[int]:
    """The vertices whose corners :func:`correct_corners` must put right after the ``edges`` were fitted again:
    their ends, and the far end of every edge there whose pole next to one end is next to the other too (an
    edge of three poles or fewer: moving it at one corner turns it at the other), until no more are added."""
    touched = {v for e in edges for v in part.edges[e].vertices}
    todo = list(touched)
    while todo:
        for e in part.vertex_edges[todo.pop()]:
            curve = curves[e]
            if curve is None or curve.n_poles > 3:
                continue
            for w in part.edges[e].vertices:
                if w not in touched:
                    touched.add(w)
                    todo.append(w)
    return touched


def _clusters(at_vertex: list[TangentEdge]) -> list[list[int]]:
    """The faces joined by the tangent edges ``at_vertex`` (those at one vertex), in clusters of sorted face
    indices (a union-find over the edges' face pairs)."""
    parent: dict[int, int] = {}

    def root(k: int) -> int:
        while parent.setdefault(k, k) != k:
            k = parent[k]
        return k

    for te in at_vertex:
        parent[root(te.faces[0])] = root(te.faces[1])
    clusters: dict[int, list[int]] = {}
    for k in list(parent):
        clusters.setdefault(root(k), []).append(k)
    return [sorted(faces) for faces in clusters.values()]


@dataclass(frozen=True)
class _Corner:
    """One cluster of faces at one vertex as :func:`correct_corners` found it: the fields of its
    :class:`CornerReport` but the angle after, and the anchors' normals there (to measure it after)."""

    vertex: int
    faces: tuple[int, ...]
    hot_angle: float
    angle_before: float
    anchors: dict
    edges: tuple[int, ...] = ()
    reason: str = ""


@dataclass(frozen=True, eq=False)
class _Corners:
    """The corner planes of one :func:`correct_corners`: its inputs, and the conditions on the edges' poles next
    to the vertices that :meth:`plan` collects (edge -> ``(pole, n_T (3,), rhs)``), solved by :meth:`moved`."""

    part: Part
    curves: list[BSplineCurve | None]
    anchors: dict
    decided: set[tuple[int, int]] | None
    strain: float
    constraints: dict = field(default_factory=dict)

    @functools.cached_property
    def hot_curves(self) -> list[BSplineCurve | None]:
        """The hot part's edge curves, once for every cluster."""
        return [e.curve for e in self.part.edges]

    def plan(self, v: int, faces: list[int]) -> _Corner:
        """The cluster ``faces`` at vertex ``v``: its angles and, where the morph kinked it, the conditions that
        turn the edges bounding its faces into one common plane (kept in :attr:`constraints`)."""
        part, curves = self.part, self.curves
        hot_n = _corner_normals(part, faces, v, self.hot_curves)
        fixed_n = {k: self.anchors[(v, k)] for k in faces if (v, k) in self.anchors}
        cold_n = _cluster_normals(part, faces, v, curves, fixed_n, self.decided)
        for k, n in fixed_n.items():                  # hot normal of an anchored face, for orientation
            hot_n.setdefault(k, n)
        usable = sorted(set(hot_n) & set(cold_n))
        hot_angle = _spread({k: hot_n[k] for k in usable})
        corner = _Corner(v, tuple(faces), hot_angle, _spread({k: cold_n[k] for k in usable}), fixed_n)
        movable = [k for k in usable if k not in fixed_n]
        if len(usable) < 2:
            return replace(corner, reason="fewer than two faces with two edges at the vertex")
        if corner.angle_before - hot_angle <= kink_bound(hot_angle, KINK_NOISE_DEG, self.strain):
            return replace(corner, reason="no kink added")
        if not movable:
            return replace(corner, reason="no face's normal there is decided by its edges")
        ref = hot_n[usable[0]]
        n_t = sum(np.sign(np.dot(hot_n[k], ref)) * np.sign(np.dot(cold_n[k], hot_n[k])) * cold_n[k]
                  for k in (sorted(fixed_n) or usable))
        bounding = [e for e in map(part.edges.__getitem__, part.vertex_edges[v]) if not e.degenerate
                    and e.vertices[0] != e.vertices[1] and set(e.faces) & set(movable)]
        # an edge of an anchored face stays (the face was fitted to it); a line cannot turn
        stays = [e for e in bounding if curves[e.index].n_poles < 3 or set(e.faces) & set(fixed_n)]
        n_t, reason = _free_normal(n_t, [_unit(_end_tangent(curves[e.index], e.vertices[0] == v)) for e in stays])
        if reason:
            return replace(corner, reason=reason)
        moved = []
        for e in bounding:
            if e in stays:
                continue
            curve, start = curves[e.index], e.vertices[0] == v
            pole = 1 if start else curve.n_poles - 2
            self.constraints.setdefault(e.index, []).append(
                (pole, n_t, -float(np.dot(n_t, _end_tangent(curve, start)))))
            moved.append(e.index)
        return replace(corner, edges=tuple(moved))

    def moved(self) -> list[BSplineCurve | None]:
        """The curves with the poles next to the vertices moved by the least change that meets every condition
        :meth:`plan` collected (:func:`_least_change`); edges left alone keep their curve object."""
        curves = list(self.curves)
        for e, rows in self.constraints.items():
            poles_at, delta = _least_change(rows)
            poles = curves[e].poles.copy()
            poles[poles_at] += delta
            curves[e] = curves[e].with_poles(poles)
        return curves


def _free_normal(n_t: np.ndarray, fixed: list[np.ndarray]) -> tuple[np.ndarray, str]:
    """The common plane's normal ``n_T (3,)`` with the directions of the ``fixed`` unit tangents (edges that
    cannot turn) removed, as a unit vector; and why there is none ("" where there is)."""
    if fixed:
        basis, sing, _ = np.linalg.svd(np.array(fixed).T, full_matrices=False)
        basis = basis[:, sing > np.sin(np.radians(_MIN_CORNER_DEG)) * sing[0]]
        if basis.shape[1] >= 3:
            return n_t, "the edges' tangents at the vertex cannot turn"
        n_t = n_t - basis @ (basis.T @ n_t)
    n_t = _unit(n_t)
    if not np.isfinite(n_t).all():
        return n_t, "no common plane"
    return n_t, ""


def _least_change(rows: list[tuple[int, np.ndarray, float]]) -> tuple[list[int], np.ndarray]:
    """The least moves ``(m, 3)`` of the poles ``poles_at`` (m,) of one edge that meet the rows ``(pole, n_T
    (3,), rhs)``: ``n_T . delta_pole = rhs`` (a corner plane at each end the pole is next to).

    Two rows on one pole (an edge of three poles constrained at both ends) whose planes are nearly one plane
    are one condition: their small singular value (ratio ``tan(angle / 2)``) is dropped below
    ``_MIN_CORNER_DEG``, or the pole would move by their small disagreement over that small angle: far, and
    the faces fold."""
    poles_at = sorted({pole for pole, _, _ in rows})
    a = np.zeros((len(rows), 3 * len(poles_at)))
    b = np.array([rhs for _, _, rhs in rows])
    for r, (pole, n_t, _) in enumerate(rows):
        j = poles_at.index(pole)
        a[r, 3 * j:3 * j + 3] = n_t
    rcond = np.tan(np.radians(_MIN_CORNER_DEG) / 2)
    return poles_at, np.linalg.lstsq(a, b, rcond=rcond)[0].reshape(-1, 3)


def with_corners(part: Part, reports: list[G1Report], corners: list[CornerReport]) -> list[G1Report]:
    """The edge reports with each edge's kink before correction raised to the corner angles measured at its
    vertices before :func:`correct_corners` (the kink at an edge's ends is the angle at its corners)."""
    before: dict[int, float] = {}
    for c in corners:
        before[c.vertex] = max(before.get(c.vertex, 0.0), c.angle_before)
    out = []
    for r in reports:
        at_ends = [before[v] for v in part.edges[r.edge].vertices if v in before]
        kb = max([r.kink_before_max, *at_ends]) if at_ends else r.kink_before_max
        out.append(replace(r, kink_before_max=kb))
    return out
