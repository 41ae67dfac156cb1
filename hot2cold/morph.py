"""The hot-to-cold morph, end to end, in the order of the paper.

load -> classify nodes -> edges (one tangent plane at the corners of tangent edges) -> faces (with
artificial nodes; refined to a tolerance if one is set) -> G1 -> rebuild -> sew -> report

The input is checked on the way (an open hot solid, a field that misses the part or some of its faces) and
so is the cold part after the sew (a face folded over, a solid turned inside out or crossing itself):
:func:`check_result` refuses what the morph has found wrong.
"""
from __future__ import annotations

import logging
import os
import time
from contextlib import nullcontext
from dataclasses import asdict, dataclass, replace
from typing import Callable

import numpy as np
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from .artificial import FieldEstimator
from .bspline import NORMAL_RTOL, evaluate_surface, surface_basis, surface_derivative_bases
from .classify import EDGE, FACE, Classification, classify_nodes
from .edges import EdgeMorph, morph_edge, morph_edges, vertex_displacements
from .errors import FieldError, InputError, MorphError
from .faces import FaceMorph, morph_face, morph_faces
from .field import DisplacementField, as_field
from .g1 import (correct_corners, correct_g1, edge_decided, kink_added, surface_corner_normals, tangent_edges,
                 with_corners)
from .invert import invert_field
from .kernel.check import SolidCheck, check_solids, face_areas, self_intersections
from .kernel.project import OUTSIDE, Projector
from .kernel.rebuild import rebuild
from .kernel.sew import sew
from .kernel.shapes import to_cadquery
from .kernel.step import write_step
from .load import load_part
from .model import Part
from .refine import refine
from .report import Report, build_report, node_errors
from .settings import Settings

log = logging.getLogger(__name__)

#: A kink (degrees) the morph adds below this is rounding: such edges are left as they are.
_KINK_NOISE_DEG = 1e-6

#: ``progress(stage, done, total)``: called as the morph goes on (stage names as in the module docstring).
Progress = Callable[[str, int, int], None]


@dataclass(eq=False)
class MorphResult:
    """What a morph gives back.

    Attributes
    ----------
    cold : cadquery.Shape, the cold part (a Solid, or a Compound of solids), same topology as the hot one.
    hot : cadquery.Shape, the hot part in B-spline form, parameterised as the cold one.
    report : Report, accuracy and checks.
    part, classification, faces, edges : the intermediate records, for inspection.
    field : DisplacementField, the field used (hot positions and hot-to-cold displacements, inverted if
        asked).
    node_errors : (N,) float array, each node's distance (mm) to the cold part (eq. 21); NaN where ignored.
    problems : tuple of str, what the checks after the sew found wrong with the cold part (a face folded
        over, a solid turned inside out or crossing itself; such solids are reported invalid), one line each;
        :func:`check_result` raises on them.
    """

    cold: object
    hot: object
    report: Report
    part: Part
    classification: Classification
    faces: list[FaceMorph]
    edges: list[EdgeMorph]
    field: DisplacementField
    node_errors: np.ndarray
    problems: tuple[str, ...] = ()

    def write_step(self, path: str | os.PathLike) -> None:
        """Write the cold part to a STEP file (atomically).

        When the hot STEP carried names or colours, the cold file is written through XCAF with the hot
        file's assembly tree and the names and colours of its solids and faces (hot solid i is cold
        solid i, hot face k cold face k); otherwise as a plain shape.
        """
        from .kernel.xcaf import write_step_styles

        styles = self.part.styles
        if styles is not None and styles.placed:
            write_step_styles(self.cold.wrapped, styles, path)
            return
        if styles is not None:
            log.warning("the hot STEP's names and colours could not be placed on the cold part; "
                        "writing %s without them", path)
        write_step(self.cold.wrapped, path)


def morph(hot, field, settings: Settings | None = None, *, units: str = "mm", field_name: str | None = None,
          invert: bool = False, progress: Progress | None = None) -> MorphResult:
    """Morph the hot part with an FE displacement field into the cold part.

    Parameters
    ----------
    hot : a STEP path, a CadQuery Shape/Workplane/Assembly or a ``TopoDS_Shape``; its solids are morphed.
    field : a field file path, a :class:`~hot2cold.field.DisplacementField`, or a pair
        ``(points (N, 3), displacements (N, 3))``; hot positions and hot-to-cold displacements.
    settings : tolerances (default :class:`Settings()`).
    units : length unit of ``field`` when it is read or given as arrays ("mm" or "m").
    field_name : name of the displacement point field in a VTK/VTU (or other meshio) file.
    invert : the field goes cold to hot (given at the nodes of the hot mesh); it is inverted by fixed-point
        iteration first (:mod:`hot2cold.invert`) and the iteration's residual is reported.
    progress : optional callback ``progress(stage, done, total)``.

    Raises
    ------
    StepReadError, FieldError : unusable input.
    MorphError : the cold part is not a valid closed solid.
    """
    settings = settings or Settings()
    limit = nullcontext() if settings.blas_threads is None else threadpool_limits(settings.blas_threads, "blas")
    with limit:
        return _morph(hot, field, settings, units, field_name, invert, progress)


def _morph(hot, field, settings: Settings, units: str, field_name: str | None, invert: bool,
           progress: Progress | None) -> MorphResult:
    """:func:`morph` within its BLAS thread limit."""
    timings: dict[str, float] = {}
    clock = time.perf_counter()

    def lap(stage: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[stage] = round(now - clock, 4)
        clock = now
        log.info("%s done in %.2f s", stage, timings[stage])

    def report_progress(stage: str, done: int = 1, total: int = 1) -> None:
        if progress is not None:
            progress(stage, done, total)

    field = as_field(field, units, field_name)
    inversion = None
    if invert:
        field, inversion = invert_field(field)
        lap("invert")
    part = load_part(hot, settings)
    hot_checks = check_solids(part.kernel.hot)
    _check_hot(hot_checks)
    lap("load")
    report_progress("load")

    projector = Projector(part.kernel.faces, part.kernel.edges)
    cls = classify_nodes(part, field, settings, projector)
    _check_coverage(part, cls, field, settings)
    lap("classify")
    report_progress("classify")

    used = cls.used
    estimator = FieldEstimator(cls.foot[used], field.displacements[used], settings.vertex_neighbours)
    vertex_disp = vertex_displacements(part, cls, field, estimator)
    edge_morphs = morph_edges(part, cls, field, vertex_disp, estimator, settings)
    tangent = [] if settings.g1_angle is None else tangent_edges(part, settings.g1_angle)
    corners = []
    if tangent:
        # The ends of tangent edges: one tangent plane per corner, on the edges the faces are then fitted to.
        curves, corners = correct_corners(part, [e.curve for e in edge_morphs], tangent, _KINK_NOISE_DEG,
                                          decided=edge_decided(part))
        edge_morphs = [replace(e, curve=c) for e, c in zip(edge_morphs, curves)]
    lap("edges")
    report_progress("edges")

    def trimmed_away(k, uv):
        return projector.classify(k, uv) == OUTSIDE

    face_morphs = morph_faces(part, cls, field, edge_morphs, vertex_disp, estimator, settings,
                              trimmed_away=trimmed_away,
                              progress=lambda done, total: report_progress("faces", done, total))
    lap("faces")

    def fit(face):
        return morph_face(face, part, cls, field, edge_morphs, vertex_disp, estimator, settings, trimmed_away)

    refinements, edge_refinements = [], []
    if settings.tolerance is not None:
        # Faces and edges refined (knots, cubic degree) where their error misses the tolerance; from here on
        # ``part`` is the refined hot part (same shape), which ``fit`` and every later step see.
        def fit_face(part_, face, edges_):
            return morph_face(face, part_, cls, field, edges_, vertex_disp, estimator, settings, trimmed_away)

        def fit_edges(part_, edges_, refined_edges):
            edges_ = list(edges_)
            for e in refined_edges:
                edge, nodes = part_.edges[e], cls.nodes_of(EDGE, e)
                edges_[e] = morph_edge(edge.curve, cls.t[nodes], field.displacements[nodes],
                                       vertex_disp[list(edge.vertices)], estimator, settings.svd_epsilon, e,
                                       settings.artificial_weight)
            if tangent:
                curves, _ = correct_corners(part_, [m.curve for m in edges_], tangent, _KINK_NOISE_DEG,
                                            decided=edge_decided(part_))
                edges_ = [m if m.curve is c else replace(m, curve=c) for m, c in zip(edges_, curves)]
            return edges_

        refined = refine(part, cls, field, face_morphs, edge_morphs, settings.tolerance,
                         settings.max_refinements, fit_face, fit_edges)
        part, face_morphs, edge_morphs = refined.part, refined.faces, refined.edges
        refinements, edge_refinements = refined.face_refinements, refined.edge_refinements
        lap("refine")
    g1_reports = []
    if tangent:
        face_morphs, more = _anchored_corners(part, tangent, edge_morphs, face_morphs, fit)
        corners += more
        surfaces = [f.surface for f in face_morphs]
        kinked = [e for e in tangent if kink_added(part, surfaces, e) > _KINK_NOISE_DEG
                  or any(c.edges for c in corners if c.vertex in part.edges[e.edge].vertices)]
        surfaces, g1_reports = correct_g1(part, surfaces, [f.tied_sides for f in face_morphs], kinked)
        g1_reports = with_corners(part, g1_reports, corners)
        face_morphs = [replace(f, surface=surface) for f, surface in zip(face_morphs, surfaces)]
        lap("g1")

    cold_vertices = part.vertices + vertex_disp
    rebuild(part.kernel, [f.surface for f in face_morphs], [e.curve for e in edge_morphs], cold_vertices)
    lap("rebuild")
    gaps = sew(part.kernel)
    cold_checks = check_solids(part.kernel.work)
    lap("sew")
    problems = _check_cold(part, face_morphs, projector, hot_checks, cold_checks)
    cold_checks = [replace(c, valid=False) if s in problems else c for s, c in enumerate(cold_checks)]
    lap("check")
    report_progress("sew")

    errors = node_errors(part, cls, field, cold_vertices, Projector(part.kernel.faces, part.kernel.edges),
                         [f.surface for f in face_morphs])
    lap("report")
    report = build_report(part, cls, field, face_morphs, edge_morphs, errors, gaps, hot_checks, cold_checks,
                          hot_name=str(hot) if isinstance(hot, (str, os.PathLike)) else type(hot).__name__,
                          timings=timings, inversion=None if inversion is None else asdict(inversion),
                          tolerance=settings.tolerance, refinements=[asdict(r) for r in refinements],
                          edge_refinements=[asdict(r) for r in edge_refinements],
                          g1=[asdict(r) for r in g1_reports])
    report_progress("report")
    result = MorphResult(cold=to_cadquery(part.kernel.work), hot=to_cadquery(part.kernel.hot), report=report,
                         part=part, classification=cls, faces=face_morphs, edges=edge_morphs, field=field,
                         node_errors=errors,
                         problems=tuple(f"cold solid {s} {text}" for s in sorted(problems) for text in problems[s]))
    log.info("morph: Δmax %.3g mm, Δmean %.3g mm, valid %s", report.delta_max, report.delta_mean, report.valid)
    return result


def _anchored_corners(part: Part, tangent, edge_morphs: list[EdgeMorph], face_morphs: list[FaceMorph], fit):
    """Corners of tangent edges where a face's normal is not decided by its edges (a trimmed face, a smooth
    boundary): the other faces' edges there turn into that face's fitted tangent plane, and the faces of
    the edges that moved are fitted again.  ``edge_morphs`` is updated in place; returns the face morphs
    and the corner reports."""
    decided = edge_decided(part, [f.tied_sides for f in face_morphs])
    pairs = {(v, k) for te in tangent for v in part.edges[te.edge].vertices for k in te.faces} - decided
    anchors = surface_corner_normals(part, [f.surface for f in face_morphs], pairs)
    if not anchors:
        return face_morphs, []
    curves, corners = correct_corners(part, [e.curve for e in edge_morphs], tangent, _KINK_NOISE_DEG,
                                      anchors, decided)
    moved = {e for c in corners for e in c.edges}
    for e in moved:
        edge_morphs[e] = replace(edge_morphs[e], curve=curves[e])
    # (a face refined to a tolerance keeps its fit: refitting would need its refined hot surface)
    faces = [fit(face) if moved & {u.edge for u in face.uses} and face_morphs[k].surface.shape == face.surface.shape
             else face_morphs[k] for k, face in enumerate(part.faces)]
    return faces, corners


def check_result(result: MorphResult) -> None:
    """Raise :class:`MorphError` unless every cold solid is valid, closed, has its faces and came through the
    checks after the sew (no face folded over, not inside out, not crossing itself)."""
    if result.problems:
        more = len(result.problems) - 1
        also = f" (and {more} more problem{'s' if more > 1 else ''}, see the log)" if more else ""
        raise MorphError(f"{result.problems[0]}{also}: the displacements are too large for this part (check the "
                         f"field's units and scale, and that it belongs to this part); not written")
    for s, hot_faces in zip(result.report.solids, result.part.solids):
        if not s.valid:
            raise MorphError(f"cold solid {s.index} is not valid (BRepCheck); not written")
        if not s.closed:
            raise MorphError(f"cold solid {s.index} has {s.free_edges} free edges; not written")
        if s.faces != len(hot_faces):
            raise MorphError(f"cold solid {s.index} has {s.faces} faces, the hot one {len(hot_faces)}")


def _check_hot(hot_checks: list[SolidCheck]) -> None:
    """Refuse a hot part that is no closed solid (:class:`InputError`); warn about one the kernel finds
    invalid."""
    for s, check in enumerate(hot_checks):
        if check.free_edges:
            raise InputError(
                f"hot solid {s} is not closed: {check.free_edges} of its edges bound only one face (an open shell, "
                f"a missing or unsewn face); hot2cold morphs closed solids: sew or repair the part in CAD")
        if not check.valid:
            log.warning("hot solid %d is not valid (BRepCheck); the cold one may not be either", s)


#: Length ratios (field extent / part extent) that betray a unit mix-up, and what to tell the user.
_UNIT_HINTS = ((1e-3, "the field looks like metres: use --field-units m (units='m')"),
               (1 / 25.4, "the field looks like inches: convert it to mm"),
               (1e3, "the field is 1000 times larger than the part: is the part in metres or the field in µm?"),
               (25.4, "the field is 25.4 times larger than the part: is the part modelled in inches but written "
                      "as mm?"))

#: Faces named in a message at the most.
_NAMED = 6

#: A face without FE nodes where the node density of the faces with nodes would put at least this many is
#: not covered by the field (with fewer, it is a small face or a sparse field: its nodes are artificial).
_EXPECTED_NODES = 10


def _check_coverage(part: Part, cls: Classification, field: DisplacementField, settings: Settings) -> None:
    """Raise :class:`FieldError` when the field and the part clearly disagree: no node on the part, most
    nodes off the part with a field whose extent differs from the part's by a unit factor, or faces that get
    no FE node (unless ``settings.extrapolate``: then a warning).

    A face without nodes counts as not covered where the density of the nodes used on the other faces (per
    mm^2) would put ``_EXPECTED_NODES`` or more on it; a face smaller than that, or a sparse field, leaves
    faces without nodes that the artificial nodes take care of (logged).
    """
    extent = float(np.linalg.norm(np.ptp(field.points, axis=0))) if len(field) > 1 else 0.0
    ratio = extent / part.diagonal
    used = float(np.mean(cls.used))
    hint = next((text for factor, text in _UNIT_HINTS if 0.5 * factor <= ratio <= 2.0 * factor), None)
    source = field.source or "the field"
    if hint and used < 0.5:
        raise FieldError(f"{source} spans {extent:.4g} mm but the part {part.diagonal:.4g} mm "
                         f"and {100 * (1 - used):.0f} % of its nodes are off the part: {hint}")
    if used == 0:
        centre = part.vertices.mean(axis=0) if len(part.vertices) else np.zeros(3)
        spread = np.linalg.norm(field.points - centre, axis=1)
        raise FieldError(
            f"no FE node of {source} lies within {cls.node_distance:.3g} mm of the part "
            f"(nodes are {spread.min():.4g} to {spread.max():.4g} mm from its centre, the part is "
            f"{part.diagonal:.4g} mm across): check the field's units (--field-units) and that it belongs to "
            f"this part, or raise --node-distance")
    on_face = cls.role == FACE
    counts = np.bincount(cls.owner[on_face], minlength=len(part.faces))
    if counts.all():
        return
    areas = face_areas(part.kernel.faces)
    expected = np.count_nonzero(cls.used) / max(float(areas[counts > 0].sum()), 1e-300) * areas
    sparse = np.flatnonzero((counts == 0) & (expected < _EXPECTED_NODES))
    if len(sparse):
        log.info("face(s) %s get no FE node (%s expected from the node density): their nodes are artificial",
                 ", ".join(map(str, sparse)), ", ".join(f"{x:.2g}" for x in expected[sparse]))
    empty = np.flatnonzero((counts == 0) & (expected >= _EXPECTED_NODES))
    if not len(empty):
        return
    # a solid of several without a node is named as a whole, other faces one by one with a point on them
    bare = [s for s, faces in enumerate(part.solids)
            if len(part.solids) > 1 and len(faces) > 1 and set(faces) <= set(empty.tolist())]
    names = [f"solid {s} (faces {min(part.solids[s])}-{max(part.solids[s])}, {expected[list(part.solids[s])].sum():.0f})"
             for s in bare]
    for k in empty:
        face = part.faces[k]
        if face.solid not in bare:
            u0, u1, v0, v1 = face.uv_box
            at = evaluate_surface(face.surface, [(u0 + u1) / 2], [(v0 + v1) / 2])[0]
            names.append(f"face {k} near ({', '.join(f'{x:.4g}' for x in at)}) mm ({expected[k]:.0f})")
    listed = ", ".join(names[:_NAMED]) + (f" and {len(names) - _NAMED} more" if len(names) > _NAMED else "")
    what = (f"{len(empty)} of its {len(part.faces)} faces get{'s' if len(empty) == 1 else ''} no FE node within "
            f"{cls.node_distance:.3g} mm where the node density of the other faces would put {_EXPECTED_NODES} or "
            f"more: {listed}")
    if settings.extrapolate:
        log.warning("%s covers only part of the solid: %s; they are morphed from the field of the other faces, "
                    "extrapolated (--extrapolate)", source, what)
        return
    raise FieldError(f"{source} covers only part of the solid: {what}; give a field over the whole part, or "
                     f"--extrapolate (Settings.extrapolate) to morph such faces from the field of the others")


#: Sample spacing of the checks of the cold part, times the part's diagonal, and samples per face direction
#: at the most.
_CHECK_SPACING, _CHECK_MOST = 1 / 150, 200


def _check_cold(part: Part, face_morphs: list[FaceMorph], projector: Projector, hot_checks: list[SolidCheck],
                cold_checks: list[SolidCheck]) -> dict[int, list[str]]:
    """What is wrong with the cold part, per solid: turned inside out (its volume changed sign), a face folded
    over (somewhere on a grid over its trimmed domain the normal ``S_u x S_v`` of the cold surface points
    against the hot one's), or crossing itself.

    The last is the kernel's self-interference test (:func:`~hot2cold.kernel.check.self_intersections`),
    1 to 3 s on the bundled real parts, so it is run only where a gap of the part may have closed: two
    points of the grids closer than two sample spacings in the cold part that were more than twice as far
    apart, and a sample spacing farther, in the hot one.  A field moves a part as the FE solution says, and
    nearby points of a part stay about as far apart as they were; where two sides of a gap come together,
    their points do not.
    """
    problems: dict[int, list[str]] = {}
    for s, (hot, cold) in enumerate(zip(hot_checks, cold_checks)):
        if hot.volume > 0 and not cold.volume > 0:
            problems.setdefault(s, []).append(
                f"is turned inside out (volume hot {hot.volume:.6g} mm³, cold {cold.volume:.6g} mm³)")
    spacing = _CHECK_SPACING * part.diagonal
    hot_points, cold_points = [], []
    for face, fm in zip(part.faces, face_morphs):
        uv = _check_grid(face, spacing, projector)
        (hot, hot_n), (cold, cold_n) = _points_and_normals(face.surface, fm.surface, uv)
        hot_points.append(hot)
        cold_points.append(cold)
        over = np.flatnonzero(np.einsum("ij,ij->i", hot_n, cold_n) < 0)    # NaN (no normal) compares False
        if len(over):
            k = over[0]
            moved = np.linalg.norm(cold - hot, axis=1).max()
            problems.setdefault(face.solid, []).append(
                f"folds: face {face.index} turns over at {len(over)} of {len(uv)} points, e.g. near "
                f"({', '.join(f'{x:.4g}' for x in hot[k])}) mm, the field moving it by up to {moved:.3g} mm "
                f"(the part is {part.diagonal:.4g} mm across)")
    hot, cold = np.concatenate(hot_points), np.concatenate(cold_points)
    pairs = cKDTree(cold).query_pairs(2.0 * spacing, output_type="ndarray")
    if len(pairs):
        d_hot = np.linalg.norm(hot[pairs[:, 0]] - hot[pairs[:, 1]], axis=1)
        d_cold = np.linalg.norm(cold[pairs[:, 0]] - cold[pairs[:, 1]], axis=1)
        closing = int(np.count_nonzero(d_hot > 2.0 * d_cold + spacing))
        if closing:
            log.info("%d pairs of points came closer than half their hot distance: checking the cold part for "
                     "self-intersection", closing)
            _check_crossing(part, problems)
    for s in sorted(problems):
        for text in problems[s]:
            log.warning("cold solid %d %s", s, text)
    return problems


def _check_grid(face, spacing: float, projector: Projector) -> np.ndarray:
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
    return uv if whole else uv[projector.classify(face.index, uv) != OUTSIDE]


def _points_and_normals(hot, cold, uv: np.ndarray):
    """``((points, normals), (points, normals))`` ``(m, 3)`` each of the surfaces ``hot`` and ``cold`` at
    ``uv (m, 2)``; a normal ``S_u x S_v`` is NaN where it is not defined (a collapsed side).  One basis for
    both when they share knots and weights (the morph moves poles only)."""
    def evaluate(surface, bases=None):
        if bases is None:
            du, dv = surface_derivative_bases(surface, uv[:, 0], uv[:, 1])
            bases = (surface_basis(surface, uv[:, 0], uv[:, 1]), du, dv,
                     np.asarray(abs(du).sum(axis=1)).ravel(), np.asarray(abs(dv).sum(axis=1)).ravel())
        b, du, dv, du_sum, dv_sum = bases
        flat = surface.poles.reshape(-1, 3)
        su, sv = du @ flat, dv @ flat
        normal = np.cross(su, sv)
        # undefined as in bspline.surface_normals: a derivative at the rounding noise of its sum (a collapsed
        # side, the pole of a sphere), or parallel derivatives
        size = float(np.abs(flat).max())
        lu, lv = np.linalg.norm(su, axis=1), np.linalg.norm(sv, axis=1)
        ok = ((lu > NORMAL_RTOL * size * du_sum) & (lv > NORMAL_RTOL * size * dv_sum)
              & (np.linalg.norm(normal, axis=1) > NORMAL_RTOL * lu * lv))
        normal[~ok] = np.nan
        return bases, (b @ flat, normal)

    bases, hot_out = evaluate(hot)
    same = (hot.shape == cold.shape and np.array_equal(hot.u_knots, cold.u_knots)
            and np.array_equal(hot.v_knots, cold.v_knots)
            and (hot.weights is None) == (cold.weights is None)
            and (hot.weights is None or np.array_equal(hot.weights, cold.weights)))
    return hot_out, evaluate(cold, bases if same else None)[1]


def _check_crossing(part: Part, problems: dict[int, list[str]]) -> None:
    """Add to ``problems`` the crossings the kernel finds in the cold part and not in the hot one (where the
    hot part has them too, e.g. two solids of an assembly that touch, they are the input's: a warning)."""
    touch = 1e-6 * part.diagonal
    found = self_intersections(part.kernel.work, touch)
    if not found:
        log.info("no self-intersection in the cold part")
        return
    before = {(c.kinds, c.indices) for c in self_intersections(part.kernel.hot, touch)}
    for crossing in found:
        if (crossing.kinds, crossing.indices) in before:
            log.warning("%s in the hot part already (and in the cold one)", crossing)
            continue
        problems.setdefault(_solid_of(part, crossing.kinds[0], crossing.indices[0]), []).append(
            f"crosses itself: {crossing}")


def _solid_of(part: Part, kind: str, index: int) -> int:
    """The solid a face, edge or vertex of ``part`` belongs to."""
    if kind == "face":
        return part.faces[index].solid
    edges = [e for e in part.edges if (e.index == index if kind == "edge" else index in e.vertices)]
    return next((part.faces[f].solid for e in edges for f in e.faces), 0)
