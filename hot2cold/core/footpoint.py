"""Foot points on a B-spline surface, vectorised (eq. 4 and 27 of GT2014-26683; eq. 21 for the report).

The foot point of a node ``P`` on a surface ``S`` is the parameter pair ``(u, v)`` that minimises
``f(u, v) = |S(u, v) - P|^2 / 2``; at an interior minimum the residual ``r = S - P`` is orthogonal to both
tangents, ``g = (S_u . r, S_v . r) = 0``.  Every node is taken from a good start (the nearest point of a
dense sample of the face) by Newton's method on ``g = 0``, all nodes of a face at once in numpy:

    H = [[S_u.S_u + S_uu.r, S_u.S_v + S_uv.r], [S_u.S_v + S_uv.r, S_v.S_v + S_vv.r]],   H d = -g.

Where ``H`` is not positive definite (far from the surface, or across a ridge) the Gauss-Newton matrix
``J^T J`` takes its place, which always points downhill.  A node *settles* when its step falls below
``SETTLE_RTOL`` of the parameter box, it lies inside the box (or past its border by no more than ``STEP_RTOL``:
a node on a face's edge, whose last step points out of the box or into it by the rounding of its zero), and its
distance is no larger than its start's.
Nodes that do not settle (the minimum lies on the box's border, Newton wanders, or it did not converge in
``MAX_ITERATIONS``) are for the caller to hand to the kernel's ``GeomAPI_ProjectPointOnSurf``, which stays
the reference.  A node whose step leaves the box in one parameter slides along that side by Newton in the
other alone, so that it ends, in a few steps, at the side's nearest point: the distance the caller weighs
against the node's foot points on other faces before asking the kernel.

A settled node is at a local minimum of the distance no farther than its start.  It is the kernel's (global)
foot point when the start lies in that minimum's basin, which the caller ensures by starting each node at
the nearest point of a sample of the face dense against its curvature: a foot point no farther than the
nearest sample, yet not the nearest one, needs a second sheet of the surface within that distance.  On the
sample parts the two agree to rounding (``tests/test_footpoint.py``, ``benchmarks/scale.py``).  From a poor
start (a few per cent of the box off, across a thin leading edge) Newton can settle in the wrong basin, on a
foot point several times farther than the nearest: the start has to be near.

The kernel needs one call per node and face; this needs two to three vectorised evaluations of the surface's
second-order jet for all nodes of a face (the start's shared among the nodes started there), a small fraction
of a kernel call's cost per node.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .bspline import (BSplineCurve, BSplineSurface, cross, curve_derivative_basis, curve_jet, evaluate_curve,
                      evaluate_surface, surface_first_jet, surface_jet)

#: A full Newton step smaller than this fraction of the parameter box settles a node (:func:`project_to_surface`,
#: :func:`project_to_curve`).  The step is taken with a correction of its own error, which is of the order of
#: its square: the gradient at the step's end, from the last evaluation's second-order expansion, and the
#: Newton step that zeroes it.  What is left is of the order of the step cubed (1e-18 of the box) and, for a
#: node off the surface, of the third derivatives times its distance (the distance, stationary at the foot
#: point, changes by the square of that).  The distance comes from the same expansion, so a settled node costs
#: no extra evaluation.  Settling on a step of 1e-9 without the correction, as before, gave the same foot
#: points one evaluation later for most nodes.
SETTLE_RTOL = 1e-6
#: A settling step's correction (see :data:`SETTLE_RTOL`) is taken where it is at most this share of the step
#: (of the order of the step squared, it is far below it); a larger one says the expansion does not hold there (a
#: Hessian near singular), and the node steps on instead.
_FIX_SHARE = 0.5
#: A node within this fraction of the parameter box of the box's border is on it (its last step pointing out of
#: the box or into it by the rounding of its zero); the Gauss-Newton distances (:func:`curve_distances`,
#: :func:`surface_distances`) settle on a step below it.
STEP_RTOL = 1e-9
#: Newton iterations at the most.
MAX_ITERATIONS = 25
#: Gauss-Newton steps of :func:`curve_distances` and :func:`surface_distances`.
LOCAL_STEPS = 8
#: Nodes evaluated together: bounds the memory of the jet (about 1 kB a node for bicubic patches) and keeps a
#: chunk's arrays in the cache.
CHUNK = 16_384


@dataclass(frozen=True, eq=False)
class FootPoints:
    """Foot points of ``n`` nodes on one surface.

    Attributes
    ----------
    uv : (n, 2) float, the parameters of the foot points.
    distance : (n,) float, node to foot point (mm).
    settled : (n,) bool, the foot point is an interior minimum found to rounding; where False, ``uv`` and
        ``distance`` are the last iterate and the caller should ask the kernel instead.
    """

    uv: np.ndarray
    distance: np.ndarray
    settled: np.ndarray


def project_to_surface(surface: BSplineSurface, points: np.ndarray, start: np.ndarray,
                       box: np.ndarray | None = None) -> FootPoints:
    """Foot points of ``points`` ``(n, 3)`` on ``surface`` within the parameter ``box`` ``(u0, u1, v0, v1)``
    (default: the surface's domain), by Newton's method from ``start`` ``(n, 2)`` (see the module docstring).
    """
    points = np.asarray(points, dtype=float)
    start = np.asarray(start, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be (n, 3), got shape {points.shape}")
    if start.shape != (len(points), 2):
        raise ValueError(f"start must be (n, 2) = ({len(points)}, 2), got shape {start.shape}")
    domain = np.asarray(surface.domain, dtype=float)
    box = domain if box is None else np.asarray(box, dtype=float)
    lo = np.maximum(box[[0, 2]], domain[[0, 2]])          # the box within the domain: (u0, v0) and (u1, v1)
    hi = np.minimum(box[[1, 3]], domain[[1, 3]])
    if not np.all(hi > lo):
        raise ValueError(f"empty parameter box {box} within the surface's domain {domain}")
    uv = np.empty((len(points), 2))
    distance = np.empty(len(points))
    settled = np.zeros(len(points), bool)
    for a in range(0, len(points), CHUNK):
        b = min(a + CHUNK, len(points))
        uv[a:b], distance[a:b], settled[a:b] = _newton(surface, points[a:b], start[a:b], lo, hi)
    return FootPoints(uv, distance, settled)


#: A chunk of at least this many nodes evaluates its starts' jets once per distinct start (:func:`_shared_jet`).
_SHARED_LEAST = 64


def _shared_jet(surface: BSplineSurface, uv: np.ndarray) -> tuple[np.ndarray, ...]:
    """:func:`~hot2cold.core.bspline.surface_jet` at ``uv (m, 2)``, each distinct parameter pair evaluated once:
    the nodes of a field denser than a face's start grid start at its points, many of them at the same one."""
    if len(uv) >= _SHARED_LEAST:
        distinct, at = np.unique(np.ascontiguousarray(uv).view(np.complex128).ravel(), return_inverse=True)
        if len(distinct) < len(uv):
            return tuple(x[at] for x in surface_jet(surface, distinct.real, distinct.imag))
    return surface_jet(surface, uv[:, 0], uv[:, 1])


def _newton(surface: BSplineSurface, p: np.ndarray, start: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Newton iteration on ``g = 0`` for one chunk; returns ``uv (m, 2)``, ``distance (m,)``, ``settled (m,)``."""
    m = len(p)
    uv = np.clip(start, lo, hi)
    settled = np.zeros(m, bool)
    distance = np.full(m, np.nan)
    start_distance = np.full(m, np.inf)
    active = np.arange(m)
    scale = hi - lo
    for iteration in range(MAX_ITERATIONS):
        if not len(active):
            break
        s, su, sv, suu, suv, svv = (_shared_jet(surface, uv) if iteration == 0
                                    else surface_jet(surface, uv[active, 0], uv[active, 1]))
        r = s - p[active]
        if iteration == 0:
            start_distance = np.linalg.norm(r, axis=1)
        g = np.column_stack([np.einsum("ij,ij->i", su, r), np.einsum("ij,ij->i", sv, r)])
        e = np.einsum("ij,ij->i", su, su)
        f = np.einsum("ij,ij->i", su, sv)
        gg = np.einsum("ij,ij->i", sv, sv)
        h00 = e + np.einsum("ij,ij->i", suu, r)
        h01 = f + np.einsum("ij,ij->i", suv, r)
        h11 = gg + np.einsum("ij,ij->i", svv, r)
        det = h00 * h11 - h01 * h01
        newton = (det > 1e-3 * (e * gg - f * f)) & (h00 > 0)
        # Gauss-Newton where the full Hessian is not safely positive definite.
        h00 = np.where(newton, h00, e)
        h01 = np.where(newton, h01, f)
        h11 = np.where(newton, h11, gg)
        det = h00 * h11 - h01 * h01
        with np.errstate(divide="ignore", invalid="ignore"):
            step = -np.column_stack([h11 * g[:, 0] - h01 * g[:, 1], h00 * g[:, 1] - h01 * g[:, 0]]) / det[:, None]
        bad = ~np.all(np.isfinite(step), axis=1)
        step[bad] = 0.0
        target = _slide_along_border(uv[active] + step, uv[active], g, (h00, h11),
                                     (lo - STEP_RTOL * scale, hi + STEP_RTOL * scale))
        new = np.clip(target, lo, hi)
        # pushed back into the box by more than a settling step (a node on the border settles either way)
        clamped = np.any(np.abs(new - target) > STEP_RTOL * scale, axis=1)
        stuck = np.all(np.abs(new - uv[active]) <= STEP_RTOL * scale, axis=1)   # at the border, pushing out
        tiny = np.all(np.abs(step) <= SETTLE_RTOL * scale, axis=1)
        uv[active] = new
        rows = np.flatnonzero(tiny & newton & ~clamped & ~bad)
        fix, feet, ok = _last_step_error(tuple(x[rows] for x in (r, su, sv, suu, suv, svv)), step[rows],
                                         (h00[rows], h01[rows], h11[rows]), scale)
        again, rows = rows[~ok], rows[ok]                        # those with no trusted correction step on
        uv[active[rows]] = np.clip(uv[active[rows]] + fix[ok], lo, hi)
        distance[active[rows]] = feet[ok]
        settled[active[rows]] = True
        going = ~(tiny | stuck | bad)
        going[again] = True
        active = active[going]
    rest = np.flatnonzero(~settled)
    if len(rest):
        distance[rest] = np.linalg.norm(evaluate_surface(surface, uv[rest, 0], uv[rest, 1]) - p[rest], axis=1)
    settled &= distance <= start_distance * (1 + 1e-12) + 1e-12
    return uv, distance, settled


def _slide_along_border(target: np.ndarray, uv: np.ndarray, g: np.ndarray, diagonal: tuple[np.ndarray, np.ndarray],
                        box: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Newton's ``target (a, 2)`` from ``uv (a, 2)`` made a step along the box's side (in place; returned) where
    it leaves ``box`` (``(lo, hi)``, each ``(2,)``) in one parameter only: the other takes the one-parameter step
    ``-g_i / H_ii`` (``g (a, 2)``, ``diagonal`` the Hessian's ``(H_00, H_11)``, each ``(a,)``, positive where
    finite).  The first parameter is then clipped to the side, and the node slides along it to the side's nearest
    point in a few steps; with the full step's other component it comes only a constant share nearer each step
    (a node of the neighbouring face, whose nearest point on this face's box lies on its border, can take up to
    :data:`MAX_ITERATIONS` steps), or stops short of it (a parametrisation askew).  A node within the box's slack
    of its border is left as it is: it settles there."""
    lo, hi = box
    out = (target < lo) | (target > hi)
    for i in (0, 1):
        rows = np.flatnonzero(out[:, 1 - i] & ~out[:, i])
        if len(rows):
            with np.errstate(divide="ignore", invalid="ignore"):
                along = uv[rows, i] - g[rows, i] / diagonal[i][rows]
            target[rows, i] = np.where(np.isfinite(along), along, target[rows, i])
    return target


def _last_step_error(jet: tuple, step: np.ndarray, hessian: tuple, scale: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The correction ``(m, 2)`` of a settling Newton step's own error, the distance ``(m,)`` at the step's end
    with it, and whether it is trusted ``(m,)``, from the jet ``(r, S_u, S_v, S_uu, S_uv, S_vv)`` (each ``(m,
    3)``, ``r = S - P``) where the step ``(m, 2)`` was taken, the Hessian ``(h00, h01, h11)`` (each ``(m,)``) that
    gave it and the box's size ``scale (2,)`` (see :data:`SETTLE_RTOL`).

    The second-order expansion at the step's end ``d`` gives the gradient ``g(x + d) = S_x . (S_xx d d) / 2 +
    (S_xx d) . (S_x d)`` per component (the Newton step zeroed the rest); the correction is the Newton step on it.
    What it leaves is of the order of the step cubed and of the third derivatives times the distance (zero for a
    node on the surface, whose distance is then its foot point's tangential error).  A correction larger than
    :data:`_FIX_SHARE` of its step (a Hessian near singular, at a degenerate point of the surface) is no
    second-order term: not trusted."""
    r, su, sv, suu, suv, svv = jet
    h00, h01, h11 = hessian
    du, dv = step[:, :1], step[:, 1:]
    along = su * du + sv * dv                                                       # S_x d
    bend = 0.5 * (suu * du * du + 2.0 * suv * du * dv + svv * dv * dv)               # S_xx d d / 2
    gu = np.einsum("ij,ij->i", su, bend) + np.einsum("ij,ij->i", suu * du + suv * dv, along)
    gv = np.einsum("ij,ij->i", sv, bend) + np.einsum("ij,ij->i", suv * du + svv * dv, along)
    det = h00 * h11 - h01 * h01
    fix_u, fix_v = -(h11 * gu - h01 * gv) / det, -(h00 * gv - h01 * gu) / det
    distance = np.linalg.norm(r + along + bend + su * fix_u[:, None] + sv * fix_v[:, None], axis=1)
    fix = np.column_stack([fix_u, fix_v])
    trusted = np.max(np.abs(fix) / scale, axis=1) <= _FIX_SHARE * np.max(np.abs(step) / scale, axis=1)
    return fix, distance, trusted


@dataclass(frozen=True, eq=False)
class CurveFeet:
    """Foot points of ``n`` points on one curve.

    Attributes
    ----------
    t : (n,) float, the parameters of the foot points.
    distance : (n,) float, point to foot point (mm).
    settled : (n,) bool, the foot point is an inner minimum found to rounding; where False, ``t`` and
        ``distance`` are the last iterate and the caller should ask the kernel instead.
    """

    t: np.ndarray
    distance: np.ndarray
    settled: np.ndarray


def project_to_curve(curve: BSplineCurve, points: np.ndarray, start: np.ndarray) -> CurveFeet:
    """Foot points of ``points (n, 3)`` on ``curve`` within its domain by Newton's method on
    ``g = C' . (C - P) = 0`` from the parameters ``start (n,)``, all points at once: the one-parameter case of
    :func:`project_to_surface`, with its rules (``H = C'.C' + C''.(C - P)``, Gauss-Newton's ``C'.C'`` where
    ``H`` is not safely positive; a point settles on a Newton step below :data:`SETTLE_RTOL` of the domain that
    stays inside it, no farther than its start).  A point whose minimum lies at an end of the domain does not
    settle."""
    points = np.asarray(points, dtype=float)
    start = np.asarray(start, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be (n, 3), got shape {points.shape}")
    if start.shape != (len(points),):
        raise ValueError(f"start must be (n,) = ({len(points)},), got shape {start.shape}")
    lo, hi = curve.domain
    settle, border = SETTLE_RTOL * (hi - lo), STEP_RTOL * (hi - lo)
    t = np.clip(start, lo, hi)
    settled = np.zeros(len(points), bool)
    distance = np.full(len(points), np.nan)
    start_distance = np.full(len(points), np.inf)
    active = np.arange(len(points))
    for iteration in range(MAX_ITERATIONS):
        if not len(active):
            break
        c, d1, d2 = curve_jet(curve, t[active])
        r = c - points[active]
        if iteration == 0:
            start_distance = np.linalg.norm(r, axis=1)
        g = np.einsum("ij,ij->i", d1, r)
        e = np.einsum("ij,ij->i", d1, d1)
        h = e + np.einsum("ij,ij->i", d2, r)
        newton = h > 1e-3 * e
        with np.errstate(divide="ignore", invalid="ignore"):
            step = -g / np.where(newton, h, e)
        bad = ~np.isfinite(step)
        step[bad] = 0.0
        target = t[active] + step
        new = np.clip(target, lo, hi)
        clamped = np.abs(new - target) > border
        stuck = np.abs(new - t[active]) <= border
        tiny = np.abs(step) <= settle
        t[active] = new
        rows = np.flatnonzero(tiny & newton & ~clamped & ~bad)
        # the last step's own error, as for a surface (:func:`_newton`): g(t + d) = 3/2 (C' . C'') d^2; a
        # correction not well below its step steps on
        fix = -1.5 * np.einsum("ij,ij->i", d1[rows], d2[rows]) * step[rows] ** 2 / h[rows]
        ok = np.abs(fix) <= _FIX_SHARE * np.abs(step[rows])
        again, rows, fix = rows[~ok], rows[ok], fix[ok]
        dt = step[rows, None]
        t[active[rows]] = np.clip(t[active[rows]] + fix, lo, hi)
        distance[active[rows]] = np.linalg.norm(r[rows] + d1[rows] * dt + 0.5 * d2[rows] * dt * dt
                                                + d1[rows] * fix[:, None], axis=1)
        settled[active[rows]] = True
        going = ~(tiny | stuck | bad)
        going[again] = True
        active = active[going]
    rest = np.flatnonzero(~settled)
    if len(rest):
        distance[rest] = np.linalg.norm(evaluate_curve(curve, t[rest]) - points[rest], axis=1)
    settled &= distance <= start_distance * (1 + 1e-12) + 1e-12
    return CurveFeet(t, distance, settled)


def curve_distances(curve: BSplineCurve, points: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Distances ``(m,)`` of ``points (m, 3)`` to ``curve`` by Gauss-Newton from the parameters ``t (m,)`` (the
    points' hot parameters, or the kernel's foot points to polish): the smallest distance met on the way, an
    upper bound of the distance to the curve, and no larger than the start's.  A point whose step is below
    :data:`STEP_RTOL` of the domain (or pushes out of it) is settled: it is evaluated once more where that
    step takes it and not again, as its next steps would find the same distance."""
    points = np.asarray(points, float)
    lo, hi = curve.domain
    t = np.clip(np.array(t, float), lo, hi)
    best = np.full(len(points), np.inf)
    active = np.arange(len(points))
    settle = STEP_RTOL * max(hi - lo, np.finfo(float).tiny)
    for step in range(LOCAL_STEPS + 1):
        ta = t[active]
        r = points[active] - evaluate_curve(curve, ta)
        best[active] = np.minimum(best[active], np.linalg.norm(r, axis=1))
        if step == LOCAL_STEPS:
            break
        d = curve_derivative_basis(curve, ta) @ curve.poles
        dd = np.sum(d * d, 1)
        new = np.clip(ta + np.where(dd > 1e-300, np.sum(d * r, 1) / np.where(dd > 1e-300, dd, 1.0), 0.0), lo, hi)
        t[active] = new
        settled = np.abs(new - ta) <= settle
        if settled.any():             # the settling step's own point: off by the step squared from here on
            rows = active[settled]
            best[rows] = np.minimum(best[rows], np.linalg.norm(points[rows] - evaluate_curve(curve, t[rows]),
                                                               axis=1))
        active = active[~settled]
        if not len(active):
            break
    return best


def surface_distances(surface: BSplineSurface, points: np.ndarray, uv: np.ndarray, box=None,
                      past_border: bool = False, return_uv: bool = False):
    """Distances ``(m,)`` of ``points (m, 3)`` to ``surface`` by Gauss-Newton from the parameters ``uv (m, 2)``,
    kept within ``box`` ``(u0, u1, v0, v1)`` (and the domain): the smallest distance met on the way, an upper
    bound of the distance to the surface, and no larger than the start's (the local projection of eq. 21,
    and where :func:`project_to_surface` does not settle, a bound tighter than the start).

    With ``past_border``, a point whose last Gauss-Newton step pushes out of the box is measured from the
    surface's tangent plane at the border instead: the distance across the surface, not the slide along it
    past a trim or a seam (the sides of a face are its edges' business): a point on the seam of a periodic
    face that the field moves along the surface across the seam is measured by how far it lies off the cold
    face, not by how far it slid.

    A point whose (clipped) step is below :data:`STEP_RTOL` of the box is settled: it is evaluated once more
    where that step takes it (on the surface, a residual of the step times ``|S_u|``, far below any tolerance
    even on high-degree faces) and not again, and its step counts as the last one.  Most
    points settle in two or three steps of the :data:`LOCAL_STEPS`.

    With ``return_uv``, also the parameters ``(m, 2)`` where each point's last step took it (in the box).
    """
    points = np.asarray(points, float)
    uv = np.array(uv, float).reshape(-1, 2)
    u0, u1, v0, v1 = surface.domain
    lo, hi = np.array([u0, v0]), np.array([u1, v1])
    if box is not None:
        lo, hi = np.maximum(lo, [box[0], box[2]]), np.minimum(hi, [box[1], box[3]])
    uv = np.clip(uv, lo, hi)
    settle = STEP_RTOL * np.maximum(hi - lo, np.finfo(float).tiny)
    best = np.full(len(points), np.inf)
    active = np.arange(len(points))
    for step in range(LOCAL_STEPS + 1):
        at = uv[active]
        if step == LOCAL_STEPS and not past_border:
            r = points[active] - evaluate_surface(surface, at[:, 0], at[:, 1])
            best[active] = np.minimum(best[active], np.linalg.norm(r, axis=1))
            break
        s, su, sv = surface_first_jet(surface, at[:, 0], at[:, 1])
        r = points[active] - s
        best[active] = np.minimum(best[active], np.linalg.norm(r, axis=1))
        a, b, c = np.sum(su * su, 1), np.sum(su * sv, 1), np.sum(sv * sv, 1)
        det = a * c - b * b
        ok = det > 1e-300
        det = np.where(ok, det, 1.0)
        ru, rv = np.sum(su * r, 1), np.sum(sv * r, 1)
        target = at + np.column_stack([(c * ru - b * rv) / det, (a * rv - b * ru) / det]) * ok[:, None]
        new = np.clip(target, lo, hi)
        last = np.full(len(at), step == LOCAL_STEPS) | np.all(np.abs(new - at) <= settle, axis=1)
        if past_border:
            out = last & np.any((target < lo) | (target > hi), axis=1) & ok
            normal = cross(su[out], sv[out])
            normal /= np.linalg.norm(normal, axis=1)[:, None]
            rows = active[out]
            best[rows] = np.minimum(best[rows], np.abs(np.sum(r[out] * normal, axis=1)))
        uv[active] = new
        settled = last & (step < LOCAL_STEPS)
        if settled.any():             # the settling step's own point: off by the step squared from here on
            rows = active[settled]
            best[rows] = np.minimum(best[rows], np.linalg.norm(
                points[rows] - evaluate_surface(surface, uv[rows, 0], uv[rows, 1]), axis=1))
        active = active[~last]
        if not len(active):
            break
    return (best, uv) if return_uv else best


def surface_distances_above(surface: BSplineSurface, points: np.ndarray, uv: np.ndarray, box, limit: float = np.inf,
                            return_uv: bool = False):
    """:func:`surface_distances` ``(m,)`` (past the border) of ``points (m, 3)`` from the parameters ``uv (m, 2)``
    where they can exceed ``limit`` or be the largest; elsewhere the distance from the surface at ``uv`` itself
    (clipped to ``box`` and the domain), which bounds the distance from above (Gauss-Newton starts there).  So
    every value above ``limit`` and the largest are the distances themselves, and no other exceeds ``limit``;
    the default ``limit`` asks for the largest alone.  One evaluation per point instead of a projection for
    most: a fit passes most of its points within a fraction of the largest distance.  With ``return_uv``, also
    the parameters ``(m, 2)`` where each was found (``uv`` clipped, where not projected)."""
    points = np.asarray(points, float)
    u0, u1, v0, v1 = surface.domain
    lo, hi = np.array([u0, v0]), np.array([u1, v1])
    if box is not None:
        lo, hi = np.maximum(lo, [box[0], box[2]]), np.minimum(hi, [box[1], box[3]])
    found = np.clip(np.array(uv, float).reshape(-1, 2), lo, hi)
    out = np.linalg.norm(points - evaluate_surface(surface, found[:, 0], found[:, 1]), axis=1) if len(points) \
        else np.zeros(0)
    order = np.argsort(out)[::-1]
    done, largest = 0, 0.0
    while done < len(order) and (out[order[done]] > limit or out[order[done]] > largest):
        step = max(1024, done)                               # the largest bounds first, in growing chunks
        take = order[done:done + step]
        take = take[(out[take] > limit) | (out[take] > largest)]
        out[take], found[take] = surface_distances(surface, points[take], found[take], box, past_border=True,
                                                   return_uv=True)
        largest = max(largest, float(out[take].max()))
        done += step
    return (out, found) if return_uv else out
