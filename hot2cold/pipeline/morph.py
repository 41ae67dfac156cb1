"""The hot-to-cold morph, end to end, in the order of the paper.

load -> classify nodes -> edges (one tangent plane at the corners of tangent edges) -> faces (with
artificial nodes; refined to a tolerance if one is set) -> G1 -> rebuild -> sew -> report

The input is checked on the way (an open hot solid, a field that misses the part or some of its faces) and
so is the cold part after the sew (a face folded over, a solid turned inside out or crossing itself):
:mod:`hot2cold.checks`; :func:`check_result` (re-exported here) refuses what the morph has found wrong.
"""
from __future__ import annotations

import logging
import os
import time
from contextlib import nullcontext
from dataclasses import asdict, dataclass, replace
from typing import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from .artificial import FieldEstimator
from .checks import check_cold, check_coverage, check_hot, check_result
from .classify import classify_nodes
from .edge_fit import EdgeMorph, morph_edge, morph_edges, vertex_displacements
from .face_fit import FaceMorph, morph_face, morph_faces
from ..io.field import DisplacementField, as_field
from .g1 import (correct_corners, correct_g1, edge_decided, kink_added, surface_corner_normals, tangent_edges,
                 with_corners)
from .invert import invert_field
from ..kernel.validity import check_solids
from ..kernel.project import Projector
from ..kernel.rebuild import rebuild
from ..kernel.tolerances import fit_tolerances
from ..kernel.shapes import to_cadquery
from ..kernel.step import write_step
from .load import load_part
from ..core.domain import Trim
from ..core.model import Classification, Part, Role
from .refine import refine
from .report import Report, build_report, node_errors
from ..settings import Settings

__all__ = ["MorphResult", "Progress", "check_result", "morph"]

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
        from ..kernel.xcaf import write_step_styles

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
    check_hot(hot_checks)
    lap("load")
    report_progress("load")

    projector = Projector(part.kernel.faces, part.kernel.edges)
    cls = classify_nodes(part, field, settings, projector)
    check_coverage(part, cls, field, settings)
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
        return projector.classify(k, uv) == Trim.OUTSIDE

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
                edge, nodes = part_.edges[e], cls.nodes_of(Role.EDGE, e)
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
    gaps = fit_tolerances(part.kernel)
    cold_checks = check_solids(part.kernel.work)
    lap("sew")
    problems = check_cold(part, face_morphs, projector, hot_checks, cold_checks)
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
