"""The hot-to-cold morph, end to end, in the order of the paper.

load -> classify nodes -> edges (one tangent plane at the corners of tangent edges) -> faces (with
artificial nodes; refined to the tolerance, 1e-3 mm by default, unless the knots are kept) -> G1 -> G2
(measured; corrected on request) -> rebuild -> sew -> check -> report

The input is checked on the way (an open hot solid, a field that misses the part or some of its faces) and
so is the cold part after the sew (a face folded over, a solid turned inside out or crossing itself):
:mod:`hot2cold.pipeline.checks`.  :func:`morph` raises :class:`~hot2cold.errors.MorphError` on a cold part
that fails them (:func:`check_result`, re-exported here), unless asked not to (``check=False``, for
inspection); :meth:`MorphResult.write_step` never writes such a part.

The hot part stays as it was loaded: the rebuild writes the cold geometry into a copy of its kernel shape
(:class:`~hot2cold.kernel.rebuild.ColdKernel`), which the result holds.
"""
from __future__ import annotations

import logging
import time
from contextlib import nullcontext
from dataclasses import asdict, dataclass, replace
from typing import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from ..core.bspline import BasisMemo
from ..core.localfit import scatter
from ..core.model import Classification, Part, Role
from ..io.field import DisplacementField, as_field
from ..kernel.project import Projector
from ..kernel.rebuild import ColdKernel, rebuild
from ..kernel.side import KernelSide, Volumes
from ..kernel.tolerances import fit_tolerances
from ..kernel.validity import check_solids
from ..settings import Settings
from .artificial import GAP_SHARE, ElementField, carry_to_feet
from .checks import FieldScale, Rebuilt, check_cold, check_coverage, check_positions
from .classify import Starts, classify_nodes
from .context import MorphContext
from .continuity import G1Refinement, correct_g2, smooth_g1
from .edge_fit import EdgeMorph
from .face_fit import FaceMorph
from .g1 import CornerReport
from .grids import FaceGrid, FaceGridder, FaceNodes, edge_grids, with_slack
from .invert import invert_field
from .load import LoadedPart, element_points, load
from .refine import TARGET_SHARE, Refitter, Targets, noise_allowance, refine
from .report import Checks, ColdGeometry, Fits, RunFacts, build_report, node_errors
from .result import MorphResult, check_result

__all__ = ["MorphResult", "Progress", "check_result", "morph"]

log = logging.getLogger(__name__)

#: An edge's curve on a face is projected again from the cold edge where it misses it by more than this share
#: of the part's diagonal (:func:`~hot2cold.kernel.tolerances.fit_tolerances`): the faces' parameters slid
#: against the edges', which an affine field never does.
_REPROJECT_SHARE = 1e-7
#: A vertex two wires of a face share may widen to hold where the wires meet beside it up to this share of the
#: part's diagonal (:func:`~hot2cold.kernel.tolerances.fit_tolerances`'s ``touch_bound``).
_TOUCH_SHARE = 1e-4

#: ``progress(stage, done, total)``: called as the morph goes on (stage names as in the module docstring).
Progress = Callable[[str, int, int], None]


class _Stages:
    """The wall time (s) of each stage of a morph, logged, and the caller's progress callback: ``(stage, 0,
    total)`` when a stage begins, ``(stage, done, total)`` as it goes, ``(stage, total, total)`` when it ends."""

    def __init__(self, progress: Progress | None):
        self.timings: dict[str, float] = {}
        self._progress = progress
        self._clock = time.perf_counter()
        self._total = 1

    def begin(self, stage: str, total: int = 1) -> None:
        """``stage`` begins (its time runs from the last lap)."""
        self._total = max(int(total), 1)
        self.progress(stage, 0, self._total)

    def count(self, stage: str, done: int, total: int) -> None:
        """``done`` of ``total`` items of ``stage`` are done (the end is :meth:`lap`'s to say)."""
        self._total = max(int(total), 1)
        if done < total:
            self.progress(stage, done, total)

    def lap(self, stage: str) -> None:
        """Close ``stage``: the time since the last lap is its time."""
        now = time.perf_counter()
        self.timings[stage] = round(now - self._clock, 4)
        self._clock = now
        log.info("%s done in %.2f s", stage, self.timings[stage])
        self.progress(stage, self._total, self._total)
        self._total = 1

    def progress(self, stage: str, done: int = 1, total: int = 1) -> None:
        if self._progress is not None:
            self._progress(stage, done, total)


def morph(hot, field, settings: Settings | None = None, *, units: str | None = None, field_name: str | None = None,  # noqa: PLR0913
          field_step: int | None = None, columns=None, field_points=None, invert: bool = False,
          progress: Progress | None = None, check: bool = True) -> MorphResult:
    """Morph the hot part with an FE displacement field into the cold part.

    The library's entry point: its keywords are the user's options of the field (as the command line's
    flags), so it takes more than six parameters; :class:`~hot2cold.settings.Settings` holds the rest.

    Parameters
    ----------
    hot : a STEP path, a CadQuery Shape/Workplane/Assembly, a build123d Solid/Part/Compound/BuildPart or a
        ``TopoDS_Shape``; its solids are morphed (``result.cold`` comes back in build123d's class for its objects).
        Or a :class:`~hot2cold.pipeline.load.LoadedPart` (:func:`~hot2cold.pipeline.load.load`): a part loaded once
        for several fields, morphed without reading and converting it again.
    field : a field file path, a :class:`~hot2cold.io.field.DisplacementField`, or a pair
        ``(points (N, 3), displacements (N, 3))``; hot positions and hot-to-cold displacements.
    settings : tolerances (default :class:`Settings()`).  With ``settings.blas_threads`` set, the BLAS
        library is held to that many threads while the morph runs, for the whole process.
    units : length unit of ``field`` when it is read or given as arrays ("mm" or "m"); None: the unit the file
        states, else mm.
    field_name, field_step, columns, field_points : which data of a field file to take
        (:func:`~hot2cold.io.field.read_field`'s ``field_name``, ``step``, ``columns`` and ``points_from``):
        the displacement dataset or result set by name or number, a text table's columns, where the node
        positions of a result file without them come from.
    invert : the field goes cold to hot (given at the nodes of the hot mesh); it is inverted by fixed-point
        iteration first (:mod:`hot2cold.pipeline.invert`) and the iteration's residual is reported.
    progress : optional callback ``progress(stage, done, total)``.
    check : refuse a cold part that fails the checks (:func:`check_result`); False returns it as it is, for
        inspection (its report says what is wrong; :meth:`MorphResult.write_step` still refuses it).

    Raises
    ------
    StepReadError, FieldError, InputError : unusable input.
    MorphError : the cold part is not a valid closed solid, or it folds, is turned inside out or crosses
        itself (unless ``check=False``).
    """
    settings = settings or Settings()
    limit = nullcontext() if settings.blas_threads is None else threadpool_limits(settings.blas_threads, "blas")
    alone = hot.morphing(settings) if isinstance(hot, LoadedPart) else nullcontext()
    with alone, limit, KernelSide(start=False) as side:       # started once the part is loaded, if it is worth it
        result = _morph(hot, field, settings, dict(units=units, field_name=field_name, step=field_step,
                                                   columns=columns, points_from=field_points), invert, progress,
                        side)
    if check:
        check_result(result)
    return result


#: A part of fewer faces integrates its volumes in the morph's own process (``Settings.kernel_process``): there
#: they take far less than the second process takes to start, and its import would take a core from a morph of
#: many nodes (measured: the speed page's twenty-fourth round).
KERNEL_PROCESS_FACES = 100

#: Scatter below this share of the tolerance is not smoothed: it cannot carry a fit out of the tolerance, and
#: smoothing towards the field's estimate is not free (a second fit per face).
_SMOOTH_SHARE = 0.01


def smoothing_noise(scatter: float, settings: Settings) -> float:
    """The scatter (mm) the fits smooth away (:func:`~hot2cold.core.lstsq.solve_tsvd`'s ``noise``): the
    field's own, where it is above ``_SMOOTH_SHARE`` of the tolerance and ``settings.smooth`` is set, else 0."""
    if not settings.smooth or settings.tolerance is None or scatter <= _SMOOTH_SHARE * settings.tolerance:
        return 0.0
    return scatter


#: A field that scatters about a smooth field by more than this share of the tolerance is noisy: it is said
#: (an info line), and it is not taken inside its FE elements (:func:`~.load.element_points`): the points
#: would carry its noise, and their rows cost what the smoothed fits cannot use (a noisy field of every node,
#: volume nodes included, runs out of memory or time with them).
NOISY_SHARE = 0.1


@dataclass(frozen=True, eq=False)
class _Classifier:
    """Classifies fields on one part (METHOD step 2): the projector onto its faces and edges and Newton's
    starts, made once for the check and the classification of the nodes and again of the points inside their
    elements."""

    part: Part
    settings: Settings
    projector: Projector
    starts: Starts

    def __call__(self, field: DisplacementField, check: bool = True, inverted: bool = False
                 ) -> tuple[Classification, DisplacementField, float]:
        """Classify ``field`` and, with ``check``, check first that hot and cold are not mixed up in it
        (``inverted``: it was inverted, ``--invert``) and then that it covers the part: the classification,
        the field as classified (a row per solid a node feeds; displacements carried to the foot points of
        nodes off the surface) and its scatter about a smooth field (mm, :func:`~hot2cold.core.localfit.scatter`)."""
        part, settings, projector = self.part, self.settings, self.projector
        if check:
            check_positions(part, field, projector, settings, inverted, self.starts)
        cls = classify_nodes(part, field, settings, projector, self.starts)
        if len(cls.node) > len(field):      # nodes that feed two solids: one row per solid they feed
            field = field.take(cls.node)
        if check:
            check_coverage(part, cls, field, settings, projector)
        field = replace(field, displacements=carry_to_feet(field.points, cls.foot, field.displacements, cls.used,
                                                           settings.vertex_neighbours, GAP_SHARE * part.diagonal))
        noise = scatter(cls.foot, field.displacements, [nodes for _, nodes in cls.groups(Role.FACE)])
        return cls, field, noise


@dataclass(frozen=True, eq=False)
class _Classified:
    """The field's nodes on the part (METHOD step 2) and what they tell of the field.

    Attributes
    ----------
    projector : Projector onto the hot faces and edges.
    classification : Classification of the rows of ``field``.
    field : DisplacementField as classified (a row per solid a node feeds, displacements carried to the foot
        points; with the points inside the FE elements where they were taken).
    fe_field : DisplacementField as read (and inverted): its nodes and elements.
    noise : float, its scatter about a smooth field (mm per component).
    allowance : float, what the scatter adds to the tolerance at the nodes (mm).
    element_points : int, how many rows of ``field`` are points inside the FE elements (0: none taken).
    scale : FieldScale, how far and with what strain the field moves the part.
    """

    projector: Projector
    classification: Classification
    field: DisplacementField
    fe_field: DisplacementField
    noise: float
    allowance: float
    element_points: int
    scale: FieldScale


def _classify(part: Part, field: DisplacementField, settings: Settings, inverted: bool) -> _Classified:
    """Classify ``field`` on ``part`` (checked: hot and cold not mixed up, every face covered) and, where it is
    smooth, again with the points inside its FE elements (:func:`~hot2cold.pipeline.load.element_points`)."""
    projector = Projector(part.kernel.faces, part.kernel.edges)
    classifier = _Classifier(part, settings, projector, Starts(part))
    cls, classified, noise = classifier(field, inverted=inverted)
    added = 0
    if noise <= NOISY_SHARE * (settings.tolerance or np.inf):      # a smooth field: taken inside its elements
        dense, added = element_points(field, settings)
        if added:
            # its nodes covered the part (checked, warned once); the points inside the elements add to them
            cls, classified, noise = classifier(dense, check=False)
    allowance = noise_allowance(noise, int(cls.used.sum()))
    if noise > NOISY_SHARE * (settings.tolerance or np.inf):
        log.info("the field scatters by %.3g mm about a smooth field (per component): the fits are smoothed "
                 "and the tolerance at the nodes is widened by %.3g mm", noise, allowance)
    return _Classified(projector, cls, classified, field, noise, allowance, added, FieldScale.of(cls, classified))


def _gridder(context: MorphContext, classified: _Classified) -> FaceGridder:
    """The grids of a morph's faces (:class:`~hot2cold.pipeline.grids.FaceGridder`), for the refinement, G1
    and the checks: the faces' nodes and estimates kept across the rounds, and the FE model's own field between
    its nodes where it brings its elements and they were taken."""
    fe, cls, settings = classified.fe_field, classified.classification, context.settings
    elements = (ElementField(fe.points, fe.triangles, fe.displacements, cls.node_distance, classified.scale.strain)
                if classified.element_points else None)
    return FaceGridder(classified.projector, FaceNodes(cls, classified.field, settings.vertex_neighbours),
                       context.estimator, elements, settings.threads)


@dataclass(frozen=True, eq=False)
class _Refined:
    """The fits after the refinement to the tolerance (as they were where it does not run).

    Attributes
    ----------
    context : MorphContext on the refined hot part (same shape, same parameters).
    faces, edges : the fits.
    grids : one FaceGrid per face, on its final knots.
    face_refinements, edge_refinements : what the refinement did, for the report.
    shortest : (n_faces,) float array, the refinement's shortest half span per face (mm), or None when it did
        not run: G1 refines no finer.
    """

    context: MorphContext
    faces: list[FaceMorph]
    edges: list[EdgeMorph]
    grids: list[FaceGrid]
    face_refinements: tuple = ()
    edge_refinements: tuple = ()
    shortest: np.ndarray | None = None


def _refine(context: MorphContext, classified: _Classified, faces: list[FaceMorph], edges: list[EdgeMorph],
            regrid: FaceGridder, stages: _Stages) -> _Refined:
    """Refine the fits to the tolerance (beyond the paper; not with ``keep_knots``): knots and cubic degree
    where the error at the nodes or between them misses it (:func:`~hot2cold.pipeline.refine.refine`); then
    the grids of every face on its final knots (a face refined without them never needed one before); the
    stage ``refine`` timed where the refinement runs."""
    settings, cls, field = context.settings, classified.classification, classified.field
    made: dict[int, FaceGrid] = {}      # grids of the faces the refinement measures on them, then of every face
    refined = None
    refining = settings.tolerance is not None and not settings.keep_knots
    if refining:
        stages.begin("refine")
        measured = Targets.measured_faces(context.part, cls)
        made.update(zip(measured, regrid(context.part, measured)))
        targets = Targets.of(context.part, cls, TARGET_SHARE * settings.tolerance + classified.allowance, made,
                             edge_grids(context.part, cls, field, context.estimator), classified.element_points > 0)
        refitter = Refitter(context.fit_face, context.refit_edges, regrid, settings.threads, settings.max_refinements)
        refined = refine(context.part, cls, field, (faces, edges), targets, refitter)
        context = context.with_part(refined.part)
        made.update(refined.grids)
        faces, edges = refined.faces, refined.edges
        spans = targets.min_span_spacings           # in node spacings (0: nothing refined)
        shortest = spans * targets.face_spacing if spans else None
    missing = [k for k in range(len(context.part.faces)) if k not in made]
    made.update(zip(missing, regrid(context.part, missing) if missing else []))
    grids = [made[k] for k in range(len(context.part.faces))]
    if refining:
        stages.lap("refine")
    if refined is None:
        return _Refined(context, faces, edges, grids)
    return _Refined(context, faces, edges, grids, tuple(refined.face_refinements),
                    tuple(refined.edge_refinements), shortest)


@dataclass(frozen=True, eq=False)
class _Cold:
    """The cold part rebuilt, sewn and checked.

    Attributes
    ----------
    kernel : ColdKernel, the cold geometry in a copy of the hot part's kernel shape.
    vertices : (nv, 3) float array, the cold vertices.
    gaps : the tolerances fitted to its gaps (:func:`~hot2cold.kernel.tolerances.fit_tolerances`).
    hot_checks, solid_checks : one SolidCheck per hot and per cold solid, a cold one invalid where the checks
        after the sew found a problem.
    check : what :func:`~hot2cold.pipeline.checks.check_cold` found.
    farthest_node : (n_faces,) float array, per face the farthest point of its grid from the nodes (mm).
    """

    kernel: ColdKernel
    vertices: np.ndarray
    gaps: object
    hot_checks: list
    solid_checks: list
    check: object
    farthest_node: np.ndarray

    def checks(self) -> Checks:
        """The checks of the hot and the cold part, for the report."""
        return Checks(self.hot_checks, self.solid_checks, self.gaps, self.check.between, self.check.unmeasured,
                      self.farthest_node)


def _rebuild_and_check(context: MorphContext, fits: Fits, classified: _Classified,  # noqa: PLR0913
                       hot: tuple[list, Volumes], grids: list[FaceGrid], stages: _Stages, side: KernelSide) -> _Cold:
    """Rebuild the cold part (the cold geometry in a copy of the kernel shape), sew it (tolerances fitted to its
    gaps) and check it (:func:`~hot2cold.pipeline.checks.check_cold`); ``hot``, the hot solids' checks without
    their volumes and the volumes as asked for, and the cold solids' volumes asked of ``side``, are waited for
    once the cold part's grids are checked."""
    part, settings = context.part, context.settings
    vertices = part.vertices + context.vertex_displacements
    stages.begin("rebuild")
    cold = rebuild(part.kernel, [f.surface for f in fits.faces], [e.curve for e in fits.edges], vertices)
    stages.lap("rebuild")
    stages.begin("sew")
    gaps = fit_tolerances(cold, reproject_above=_REPROJECT_SHARE * part.diagonal,
                          touch_bound=_TOUCH_SHARE * part.diagonal)
    cold_checks = check_solids(cold.shape, volumes=False)
    rebuilt = Rebuilt(cold, fits.faces, hot[0], cold_checks, (hot[1], side.volumes(cold.shape)))
    stages.lap("sew")
    stages.begin("check")
    tolerance = (settings.tolerance if settings.tolerance is not None else np.inf) + classified.allowance
    check = check_cold(part, rebuilt, classified.projector, classified.scale, grids, tolerance)
    hot_checks, cold_checks = rebuilt.solid_checks()
    cold_checks = [replace(c, valid=False) if s in check.problems else c for s, c in enumerate(cold_checks)]
    stages.lap("check")
    return _Cold(cold, vertices, gaps, hot_checks, cold_checks, check, np.array([g.farthest_node for g in grids]))


def _smooth_edges(context: MorphContext, refined: _Refined, corners: list[CornerReport], regrid: FaceGridder,
                  stages: _Stages) -> tuple[MorphContext, list[FaceGrid], Fits]:
    """G1 (section 5, eq. 56-75): corners anchored on trimmed faces, then the kinks along tangent edges; faces
    refined along the edges their nets cannot bring to 0.01 deg (beyond the paper; with the refinement, no
    finer than it went); then G2 (the paper's outlook): the curvature jumps across them measured, and removed
    if asked.  Returns the context (on the part G1 refined, if it did), the grids and the fits."""
    grids, face_morphs, edge_morphs, g1_reports = refined.grids, refined.faces, refined.edges, ()
    if context.tangent:
        stages.begin("g1", len(context.tangent))
        refinement = None if refined.shortest is None else G1Refinement(refined.shortest, regrid)
        context, grids, edge_morphs, face_morphs, g1_reports = smooth_g1(context, (face_morphs, edge_morphs),
                                                                         corners, grids, refinement)
        # the checks between the nodes need the slack the grids of a refinement G1 took were made without
        grids = with_slack(context.part, grids, regrid.face_nodes, context.settings.threads)
        stages.lap("g1")
        stages.begin("g2")
        face_morphs, g1_reports = correct_g2(context, face_morphs, g1_reports, grids, edge_morphs)
        stages.lap("g2")
    return context, grids, Fits(face_morphs, edge_morphs, refined.face_refinements, refined.edge_refinements,
                                tuple(g1_reports))


def _result(context: MorphContext, classified: _Classified, fits: Fits, cold: _Cold, stages: _Stages,
            about: dict) -> MorphResult:
    """The report (step 8, eq. 21-22: each node's cold target projected onto the morphed geometry) and the
    result; ``about`` holds :func:`~hot2cold.pipeline.report.build_report`'s words on the run (hot_name,
    inversion)."""
    part, cls, field, settings = context.part, classified.classification, classified.field, context.settings
    stages.begin("report", len(cls.used))
    geometry = ColdGeometry(cold.vertices, Projector(cold.kernel.faces, cold.kernel.edges),
                            [f.surface for f in fits.faces], [e.curve for e in fits.edges])
    errors = node_errors(cls, field, geometry, settings.threads)
    stages.lap("report")
    run = RunFacts(timings=stages.timings, scatter=classified.noise, allowance=classified.allowance,
                   element_points=classified.element_points, **about)
    report = build_report(context, fits, cold.checks(), errors, run)
    if report.unsupported_faces():                  # the report's text, HTML and JSON say it to the user
        log.info("not measured: %s", report.unsupported_text())
    problems = cold.check.problems
    log.info("morph: Δmax %.3g mm, Δmean %.3g mm, valid %s", report.delta_max, report.delta_mean, report.valid)
    return MorphResult(report=report, part=part, classification=cls, faces=list(fits.faces),
                       edges=list(fits.edges), field=field, node_errors=errors, cold_kernel=cold.kernel,
                       problems=tuple(f"cold solid {s} {text}" for s in sorted(problems) for text in problems[s]))


def _morph(hot, field, settings: Settings, reading: dict, invert: bool,  # noqa: PLR0913
           progress: Progress | None, side: KernelSide) -> MorphResult:
    """:func:`morph` within its BLAS thread limit, unchecked; ``reading`` holds :func:`as_field`'s keywords,
    ``side`` integrates the volumes (:class:`~hot2cold.kernel.side.KernelSide`).  The steps of METHOD in order,
    each a function of its own; the stages timed and told to ``progress``."""
    stages = _Stages(progress)
    field = as_field(field, **reading)     # no start marker: a field refused says so alone
    stages.lap("read")
    inversion = None
    if invert:
        stages.begin("invert")
        field, inversion = invert_field(field)
        stages.lap("invert")

    # load (METHOD step 1): the hot part in B-spline form, a closed solid
    stages.begin("load")
    loaded = load(hot, settings)              # a LoadedPart as it is
    part, hot_checks = loaded.part, loaded.checks
    if settings.kernel_process and len(part.faces) >= KERNEL_PROCESS_FACES:
        side.start()
    hot_volumes = loaded.volumes(side)      # needed when the cold part is checked
    stages.lap("load")
    memo = BasisMemo()         # the basis rows asked of the faces, for when they are asked again (bounded)
    for face in part.faces:
        face.surface.remember(memo)
    try:
        # classify (step 2, eq. 4, 27, 33-37): each node's foot point on a face, edge or vertex, or ignored
        stages.begin("classify", len(field))
        classified = _classify(part, field, settings, invert)
        cls, field = classified.classification, classified.field
        stages.lap("classify")

        # edges (step 3, eq. 1-22): ends at the morphed vertices, one tangent plane at the corners of tangent edges
        context = replace(MorphContext.of(part, cls, field, settings, classified.projector),
                          strain=classified.scale.strain, noise=smoothing_noise(classified.noise, settings))
        stages.begin("edges", len(part.edges))
        edge_morphs, corners = context.fit_edges()
        stages.lap("edges")

        # faces (steps 4-5, eq. 23-39): boundary rows from the edges, interior by truncated SVD
        stages.begin("faces", len(part.faces))
        face_morphs = context.fit_faces(edge_morphs, lambda done, total: stages.count("faces", done, total))
        stages.lap("faces")

        # refinement to the tolerance (beyond the paper): from here on the context's part is the refined hot part
        regrid = _gridder(context, classified)
        refined = _refine(context, classified, face_morphs, edge_morphs, regrid, stages)
        context = refined.context

        # G1 and G2 along the tangent edges, then rebuild, sew and check, then the report
        context, grids, fits = _smooth_edges(context, refined, corners, regrid, stages)
        cold = _rebuild_and_check(context, fits, classified, (hot_checks, hot_volumes), grids, stages, side)
        about = {"hot_name": loaded.name,
                 "inversion": None if inversion is None else asdict(inversion)}
        result = replace(_result(context, classified, fits, cold, stages, about), shape_type=loaded.shape_type)
    finally:
        memo.close()           # the result's surfaces hold it (and a loaded part's): nothing kept past the morph
    return result
