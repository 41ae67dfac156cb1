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
import os
import time
from contextlib import nullcontext
from dataclasses import asdict, dataclass, replace
from dataclasses import field as dataclass_field
from typing import Callable

import numpy as np
from scipy import sparse
from threadpoolctl import threadpool_limits

from .artificial import GAP_SHARE, ElementField, FieldEstimator, carry_to_feet
from .checks import (FaceGrid, FaceGridder, FaceNodes, FieldScale, check_cold, check_coverage, check_hot,
                     check_positions, edge_grids, with_slack)
from .classify import Starts, classify_nodes
from .edge_fit import EdgeMorph, end_displacements, morph_edge, morph_edges, vertex_displacements
from .fit_inputs import FitInputs
from .face_fit import FaceMorph, face_problem, morph_face, morph_faces, solve_face
from ..io.field import DisplacementField, as_field
from .g1 import (ALONG_CURVE, REFINED, TURN_WEIGHT, CornerReport, G1Report, TangentEdge, correct_corners,
                 correct_g1, edge_decided, kink_bound, kink_maxima, kink_misses, surface_corner_normals,
                 tangent_edges, turn_rows, with_corners)
from .g2 import BEND_WEIGHTS, BENT, TANGENT_WEIGHT, bend_rows, edge_jump
from .invert import invert_field
from ..kernel.validity import check_solids
from ..kernel.project import Projector
from ..kernel.rebuild import ColdKernel, rebuild
from ..kernel.tolerances import fit_tolerances
from .load import element_points, load_part
from ..core.bspline import BSplineCurve, BSplineSurface, clip_uv, evaluate_surface
from ..core.footpoint import surface_distances_above
from ..core.domain import Trim
from ..core.localfit import scatter
from ..core.model import Classification, Face, Part, Role
from ..core.threads import map_threads
from .refine import (TARGET_SHARE, Refitter, Regrid, Targets, edge_errors, noise_allowance, refine,
                     refine_patches)
from .report import Checks, ColdGeometry, Fits, RunFacts, build_report, node_errors
from .result import MorphResult, check_result
from ..settings import Continuity, Settings

__all__ = ["MorphContext", "MorphResult", "Progress", "check_result", "morph"]

log = logging.getLogger(__name__)

#: A kink (degrees) the morph adds below this is rounding: such edges are left as they are.
_KINK_NOISE_DEG = 1e-6

#: An edge's curve on a face is projected again from the cold edge where it misses it by more than this share
#: of the part's diagonal (:func:`~hot2cold.kernel.tolerances.fit_tolerances`): the faces' parameters slid
#: against the edges', which an affine field never does.
_REPROJECT_SHARE = 1e-7
#: A vertex two wires of a face share may widen to hold where the wires meet beside it up to this share of the
#: part's diagonal (:func:`~hot2cold.kernel.tolerances.fit_tolerances`'s ``touch_bound``).
_TOUCH_SHARE = 1e-4

#: Rounds of the G1 correction at the most: each round freezes the faces the last one moved off their nodes.
_G1_ROUNDS = 3
#: A face fitted again with its tangents turned along a trimming curve may be this share farther from the field
#: than its plain fit, or this share of the tolerance (:meth:`MorphContext._moved_off`): Handle_SO101 under a
#: smooth field went from 2.75e-4 to 7.06e-4 mm off the exact cold geometry when turned within the tolerance.
_TURN_SHARE = 0.1
#: The largest kink (degrees) above its hot angle a correction may leave on a tangent edge that it finds less
#: kinked (issue 15's promise): the second rows (G1) and a face bent to a common curvature (G2).
_KINK_PROMISE_DEG = 0.01
#: Rounds of refinement for G1 at the most (:func:`_g1`), each halving the patches along the edges still kinked.
_G1_REFINEMENTS = 2
#: A refinement for G1 adds poles to the faces along the edges: it is taken where it leaves at most this share
#: of what those edges were above the promise in all.  NIST FTC-08's and the filleted block's leave none; on
#: Rotor 37 at 1 M nodes the first left 0.0336 of 0.0386 deg for 690 -> 960 and 609 -> 783 poles, and a
#: second trial (16 s) found 0.117.
_G1_GAIN = 0.5

#: ``progress(stage, done, total)``: called as the morph goes on (stage names as in the module docstring).
Progress = Callable[[str, int, int], None]


@dataclass(frozen=True, eq=False)
class MorphContext:
    """What every fit of one morph reads (METHOD steps 3-6), and the fits as methods.

    Attributes
    ----------
    part : Part, the hot part; after the refinement to a tolerance the refined one (same shape).
    classification : Classification of the field's nodes (roles, owners, foot points, eq. 4, 27).
    field : DisplacementField, hot positions ``(N, 3)`` and hot-to-cold displacements ``(N, 3)``.
    vertex_displacements : (nv, 3) float array, each vertex's displacement, the fixed ends of its edges
        (eq. 10).
    estimator : FieldEstimator, the displacements of artificial nodes (eq. 39).
    settings : Settings.
    projector : Projector onto the hot faces and edges; tells which parameters a face's trim cuts away.
    tangent : list of TangentEdge, the edges along which the hot faces meet tangentially (empty without G1
        correction, ``Settings.g1_angle`` None).
    strain : float, the field's largest strain (:class:`~hot2cold.pipeline.checks.FieldScale`): a kink the
        morph adds counts beyond ``_KINK_NOISE_DEG`` plus twice this times the hot angle (what the field itself
        does to an angle that is not quite zero when hot).
    noise : float, the scatter (mm per component) the fits smooth away (:func:`smoothing_noise`).
    """

    part: Part
    classification: Classification
    field: DisplacementField
    vertex_displacements: np.ndarray
    estimator: FieldEstimator
    settings: Settings
    projector: Projector
    tangent: list[TangentEdge]
    strain: float = 0.0
    noise: float = 0.0
    #: :meth:`field_distance` of each (face, surface, grid) asked for: G1 and G2 ask for a face's fit against
    #: every trial, and a fit's distance costs as much as a trial's (keys hold the objects, so no id is
    #: reused while the context lives).
    _distances: dict = dataclass_field(default_factory=dict, init=False, repr=False)
    #: The parameters where :meth:`field_distance` found the distances of a fit G1 or G2 may replace (by the
    #: same keys), for :meth:`_distance_bound`; only for those, since each holds a pair per node.
    _feet: dict = dataclass_field(default_factory=dict, init=False, repr=False)
    #: The last fit of each face on a tangent edge, its rows reduced (face -> (what it was fitted on, its
    #: FaceProblem)): G1 and G2 fit such a face again and again with other turning and bending rows only.
    _problems: dict = dataclass_field(default_factory=dict, init=False, repr=False)

    @classmethod
    def of(cls, part: Part, classification: Classification, field: DisplacementField, settings: Settings,  # noqa: PLR0913
           projector: Projector, strain: float = 0.0, noise: float = 0.0) -> MorphContext:
        """The context of a classified field: the vertex displacements (eq. 10) from the nodes on or near
        the vertices, an estimator over the used nodes' foot points, the tangent edges."""
        used = classification.used
        estimator = FieldEstimator(classification.foot[used], field.displacements[used],
                                   settings.vertex_neighbours)
        vertex_disp = vertex_displacements(part, classification, field, estimator)
        tangent = [] if settings.g1_angle is None else tangent_edges(part, settings.g1_angle)
        return cls(part, classification, field, vertex_disp, estimator, settings, projector, tangent, strain,
                   noise)

    def with_part(self, part: Part) -> MorphContext:
        """This context on ``part`` (a refined part: the same faces, edges and parameters), its fits' caches
        shared: their keys hold the faces, edges, morphs, surfaces and grids they were made for, so an entry
        is found only for those (on Rotor 37 with 1 M nodes, G1 reduced the rows of the refinement's last fits
        again, and of its trial's refits, 2.7 s in all)."""
        other = replace(self, part=part)
        for cache in ("_distances", "_feet", "_problems"):
            object.__setattr__(other, cache, getattr(self, cache))
        return other

    def trimmed_away(self, k: int, uv: np.ndarray) -> np.ndarray:
        """``(m,)`` bool: which of the parameters ``uv (m, 2)`` lie outside face ``k``'s trimmed domain."""
        return self.projector.classify(k, uv) == Trim.OUTSIDE

    def fit_edges(self) -> tuple[list[EdgeMorph], list[CornerReport]]:
        """Every edge morphed (eq. 10-20), and at the ends of tangent edges given one tangent plane per corner
        (paper section 5); returns the edge morphs and the corner reports."""
        edge_morphs = morph_edges(self.part, self.fit_inputs)
        if not self.tangent:
            return edge_morphs, []
        curves, corners = correct_corners(self.part, [e.curve for e in edge_morphs], self.tangent,
                                          _KINK_NOISE_DEG, decided=edge_decided(self.part), strain=self.strain)
        return [replace(e, curve=c) for e, c in zip(edge_morphs, curves)], corners

    def fit_faces(self, edge_morphs: list[EdgeMorph], progress: Callable[[int, int], None] | None = None
                  ) -> list[FaceMorph]:
        """Every face morphed against the morphed edges (eq. 23-38, artificial nodes eq. 39)."""
        return morph_faces(self.part, edge_morphs, self.fit_inputs, progress)

    @property
    def fit_inputs(self) -> FitInputs:
        """What every edge and face fit reads of this context (:class:`~hot2cold.pipeline.fit_inputs.FitInputs`)."""
        return FitInputs(self.classification, self.field, self.vertex_displacements, self.estimator, self.settings,
                         self.trimmed_away, self.noise)

    def fit_face(self, part: Part, face: Face, edge_morphs: list[EdgeMorph], turn: tuple | None = None
                 ) -> FaceMorph:
        """One face of ``part`` (this context's part, or a refined one) morphed against ``edge_morphs``
        (eq. 23-38); :func:`~hot2cold.pipeline.refine.refine`'s ``fit_face``; ``turn``: rows that turn it
        along trimming curves (:func:`~hot2cold.pipeline.g1.turn_rows`).  A face on a tangent edge keeps its
        rows reduced (:func:`~hot2cold.pipeline.face_fit.face_problem`) while it, its edges and their morphs
        stay the same objects: G1 and G2 fit it again with other turning or bending rows only, at the cost of
        those rows."""
        if not any(face.index in te.faces for te in self.tangent):
            return morph_face(face, part, edge_morphs, self.fit_inputs, turn)
        # what the fit reads besides the context: the face, its edges and their morphs (objects, compared by
        # identity: a refined part or a moved edge is a new object)
        basis = (face, *(part.edges[u.edge] for u in face.uses), *(edge_morphs[u.edge] for u in face.uses))
        kept = self._problems.get(face.index)
        if kept is None or len(kept[0]) != len(basis) or any(a is not b for a, b in zip(kept[0], basis)):
            kept = basis, face_problem(face, part, edge_morphs, self.fit_inputs, reduce=True)
            self._problems[face.index] = kept
        return solve_face(kept[1], self.settings, self.noise, turn)

    def _fit_faces(self, part: Part, faces: list[int], edge_morphs: list[EdgeMorph],
                   turns: list[tuple | None] | None = None) -> list[FaceMorph]:
        """:meth:`fit_face` of each of ``faces`` (indices into ``part.faces``), with the ``turns`` given per
        face, in up to ``settings.threads`` threads."""
        turns = [None] * len(faces) if turns is None else turns
        nodes = self.classification.counts(Role.FACE, len(part.faces))
        return map_threads(lambda job: self.fit_face(part, part.faces[job[0]], edge_morphs, job[1]),
                           list(zip(faces, turns)), self.settings.threads, cost=nodes[faces])

    def _all_moved_off(self, changes: dict[int, tuple[BSplineSurface, BSplineSurface]], grids: list[FaceGrid],
                       share: float | None = None) -> dict[int, str]:
        """:meth:`_moved_off` of each face ``k: (before, after)`` of ``changes`` (in up to ``settings.threads``
        threads): the faces that may not take ``after``, and why."""
        faces = list(changes)
        nodes = self.classification.counts(Role.FACE, len(self.part.faces))
        why = map_threads(lambda k: self._moved_off(k, *changes[k], grids[k], share), faces, self.settings.threads,
                          cost=[len(grids[k].uv) + nodes[k] for k in faces])
        return {k: text for k, text in zip(faces, why) if text}

    def refit_edges(self, part: Part, edge_morphs: list[EdgeMorph], refined: set[int]) -> list[EdgeMorph]:
        """The edges in ``refined`` of the refined ``part`` morphed again (eq. 10-20) and the corners of
        tangent edges put right again; returns every edge's morph
        (:func:`~hot2cold.pipeline.refine.refine`'s ``fit_edges``)."""
        cls, settings = self.classification, self.settings
        edge_morphs = list(edge_morphs)
        for e in refined:
            edge, nodes = part.edges[e], cls.nodes_of(Role.EDGE, e)
            edge_morphs[e] = morph_edge(edge.curve, cls.t[nodes], self.field.displacements[nodes],
                                        end_displacements(part, edge, self.vertex_displacements, self.estimator),
                                        self.estimator, settings.svd_epsilon, e, settings.artificial_weight,
                                        self.noise)
        if self.tangent:
            curves, _ = correct_corners(part, [m.curve for m in edge_morphs], self.tangent, _KINK_NOISE_DEG,
                                        decided=edge_decided(part), strain=self.strain)
            edge_morphs = [m if m.curve is c else replace(m, curve=c) for m, c in zip(edge_morphs, curves)]
        return edge_morphs

    def anchor_corners(self, edge_morphs: list[EdgeMorph], face_morphs: list[FaceMorph]
                       ) -> tuple[list[EdgeMorph], list[FaceMorph], list[CornerReport]]:
        """Corners of tangent edges where a face's normal is not decided by its edges (a trimmed face, a
        smooth boundary): the other faces' edges there turn into that face's fitted tangent plane, and the
        faces of the edges that moved are fitted again.  Returns the edge morphs, the face morphs and the
        corner reports."""
        part = self.part
        decided = edge_decided(part, [f.tied_sides for f in face_morphs])
        pairs = {(v, k) for te in self.tangent for v in part.edges[te.edge].vertices for k in te.faces} - decided
        anchors = surface_corner_normals(part, [f.surface for f in face_morphs], pairs)
        if not anchors:
            return edge_morphs, face_morphs, []
        curves, corners = correct_corners(part, [e.curve for e in edge_morphs], self.tangent, _KINK_NOISE_DEG,
                                          anchors, decided, self.strain)
        moved = {e for c in corners for e in c.edges}
        off = {e: why for e in sorted(moved) if (why := self._edge_moved_off(e, edge_morphs[e], curves[e]))}
        if off:
            log.warning("G1: edges %s keep their fits at their corners: %s", sorted(off), "; ".join(off.values()))
            moved -= set(off)
            corners = [c if not set(c.edges) & set(off) else replace(
                c, edges=tuple(e for e in c.edges if e not in off),
                reason="; ".join([c.reason] * bool(c.reason) + [off[e] for e in c.edges if e in off]))
                for c in corners]
        edge_morphs = [replace(m, curve=curves[e]) if e in moved else m for e, m in enumerate(edge_morphs)]
        # (a face refined to a tolerance keeps its fit: refitting would need its refined hot surface)
        again = [k for k, face in enumerate(part.faces)
                 if moved & {u.edge for u in face.uses} and face_morphs[k].surface.shape == face.surface.shape]
        faces = list(face_morphs)
        for k, morph in zip(again, self._fit_faces(part, again, edge_morphs)):
            faces[k] = morph
        return edge_morphs, faces, corners

    def correct_g1(self, face_morphs: list[FaceMorph], corners: list[CornerReport], grids: list[FaceGrid],  # noqa: C901
                   edge_morphs: list[EdgeMorph]) -> tuple[list[FaceMorph], list[G1Report]]:
        """The kinks the morph added along tangent edges (and at their corners) removed from the faces
        (eq. 56-75; along trimming curves by fitting the faces again with their tangents turned there,
        :func:`~hot2cold.pipeline.g1.turn_rows`); returns the face morphs and one report per tangent edge."""
        part = self.part
        face_morphs = list(face_morphs)
        surfaces = [f.surface for f in face_morphs]
        largest = dict(zip((e.edge for e in self.tangent), kink_maxima(part, surfaces, self.tangent)))
        kinked = [e for e in self.tangent
                  if largest[e.edge] - e.hot_angle_max > kink_bound(e.hot_angle_max, _KINK_NOISE_DEG, self.strain)
                  or any(c.edges for c in corners if c.vertex in part.edges[e.edge].vertices)]
        # faces with kinked trimming curves: fitted again, their tangents there turned into the common plane
        along = [e for e in kinked if None in e.sides]
        plain = {e.edge: largest[e.edge] for e in along}
        turning = {f for e in along for f, side in zip(e.faces, e.sides) if side is None}
        kept: set[int] = set(range(len(part.faces))) - turning    # faces that keep their fits along the curves
        refits: dict[int, FaceMorph] = {}
        refused: dict[int, str] = {}
        for _ in range(_G1_ROUNDS):       # both faces turn to the common plane; a face that may not turn (it
            order = sorted(turning - kept)  # would leave the field) keeps its fit, and the other turns to it
            turns = [turn_rows(part, surfaces, along, k, TURN_WEIGHT, kept=frozenset(kept)) for k in order]
            refits = dict(zip(order, self._fit_faces(part, order, edge_morphs, turns)))
            off = self._all_moved_off({k: (surfaces[k], refit.surface) for k, refit in refits.items()}, grids,
                                      _TURN_SHARE)
            # a turn that leaves one of its edges more kinked than the plain fits is no correction (on the
            # vise of the real corpus, next to a corner of 4.8 deg: 36 deg after)
            trial = [refits[k].surface if k in refits else s for k, s in enumerate(surfaces)]
            for e, now in zip(along, kink_maxima(part, trial, along)):
                if now > plain[e.edge] + _KINK_NOISE_DEG:
                    for k in set(e.faces) & set(refits) - set(off):
                        off[k] = (f"turning face {k} would kink edge {e.edge} more ({plain[e.edge]:.3g} -> "
                                  f"{now:.3g} deg)")
            for k, why in off.items():
                log.info("G1: face %d not turned along its trimming curves: %s", k, why)
            if not off:
                break
            kept |= set(off)
            refused.update(off)
        turned = set(refits) - kept
        for k in turned:
            face_morphs[k] = refits[k]
        surfaces = [f.surface for f in face_morphs]
        tied = [f.tied_sides for f in face_morphs]
        frozen: dict[int, str] = {}
        for _ in range(_G1_ROUNDS):
            corrected, reports = correct_g1(part, surfaces, tied, kinked, frozen=frozen)
            off = self._all_moved_off({k: (surfaces[k], corrected[k]) for k in range(len(surfaces))
                                       if corrected[k] is not surfaces[k]}, grids)
            # second rows that leave an edge more kinked than they found it, and beyond the promise, are no
            # correction there (Rotor 37's bundled field: a curve turned in the fit to 0.0039 deg, 0.0117 after)
            for r in reports:
                if r.kink_after_max > max(r.kink_before_max, r.hot_angle_max + _KINK_PROMISE_DEG) + _KINK_NOISE_DEG:
                    for k in r.faces:
                        if corrected[k] is not surfaces[k] and k not in off:
                            off[k] = (f"the second rows of face {k} would kink edge {r.edge} more "
                                      f"({r.kink_before_max:.3g} -> {r.kink_after_max:.3g} deg)")
            if not off:
                break
            frozen.update(off)
        else:                           # still moving faces off: those keep their fits
            log.warning("G1: faces %s keep their fits: %s", sorted(off), "; ".join(off.values()))
            corrected = [surfaces[k] if k in off else c for k, c in enumerate(corrected)]
            reports = _measured_again(part, corrected, reports, kinked, set(off))
        for r, report in enumerate(reports):
            if report.edge not in plain:
                continue
            if turned & set(report.faces):
                method = f"{report.method}; {ALONG_CURVE}" if report.corrected else ALONG_CURVE
                reports[r] = replace(report, kink_before_max=plain[report.edge], corrected=True, reason="",
                                     method=method)
            elif not report.corrected and refused.keys() & set(report.faces):
                reports[r] = replace(report, kink_before_max=plain[report.edge], reason="; ".join(
                    refused[f] for f in report.faces if f in refused))
        return ([replace(f, surface=surface) for f, surface in zip(face_morphs, corrected)],
                with_corners(part, reports, corners))

    def correct_g2(self, face_morphs: list[FaceMorph], reports: list[G1Report], grids: list[FaceGrid],
                   edge_morphs: list[EdgeMorph]) -> tuple[list[FaceMorph], list[G1Report]]:
        """The jump of the normal curvature across each tangent edge of ``reports`` (those G1 examined: the
        morph kinked them) measured on the hot faces, on ``face_morphs`` (after G1) and, with
        ``Settings.continuity`` G2, removed where the hot faces were
        curvature-continuous: both faces fitted again with rows that give them the common curvature across
        the edge and keep their tangents in the common plane (:func:`~hot2cold.pipeline.g2.bend_rows`,
        :func:`~hot2cold.pipeline.g1.turn_rows`), with bend rows stiffer in turn (``BEND_WEIGHTS``) while the
        jumps stay.  A face keeps its fit, and the other bends to it, where the new one would go farther from
        the field than the tolerance and 10 % beyond its plain fit, or leave one of its tangent edges more
        kinked than both now and 0.01 degrees above its hot angle.  Returns the face morphs and the
        reports with their G2 fields."""
        part, settings = self.part, self.settings
        face_morphs = list(face_morphs)
        hot = [face.surface for face in part.faces]
        surfaces = [f.surface for f in face_morphs]
        by_edge = {te.edge: te for te in self.tangent}
        jumps = {r.edge: (edge_jump(part, hot, by_edge[r.edge]), edge_jump(part, surfaces, by_edge[r.edge]))
                 for r in reports}
        smooth = [by_edge[e] for e, (hot_jump, _) in jumps.items() if hot_jump <= settings.g2_tolerance]
        bent_faces: set[int] = set()
        refused: dict[int, str] = {}
        if settings.continuity is Continuity.G2:
            kinks = dict(zip((te.edge for te in self.tangent), kink_maxima(part, surfaces, self.tangent)))
            current = list(surfaces)
            for weight in BEND_WEIGHTS:   # stiffer bend rows while the jumps stay and every face may bend
                bend = [te for te in smooth if edge_jump(part, current, te) > settings.g2_tolerance]
                if not bend:
                    break
                refits, off = self._bend(current, surfaces, bend, weight, kinks, grids, edge_morphs, set(refused))
                refused.update(off)
                for k, refit in refits.items():
                    face_morphs[k] = refit
                    current[k] = refit.surface
                bent_faces |= set(refits)
                if not refits:
                    break
            # the G1 reports are measured again where a face bent
            reports = _measured_again(part, current, reports, self.tangent, bent_faces)
            surfaces_after = current
        else:
            surfaces_after = surfaces
        out = []
        for r in reports:
            hot_jump, before = jumps[r.edge]
            is_g2 = hot_jump <= settings.g2_tolerance
            now = before
            why = ""
            if is_g2 and settings.continuity is Continuity.G2:
                now = edge_jump(part, surfaces_after, by_edge[r.edge])
                if bent_faces & set(r.faces):
                    why = BENT
                if now > settings.g2_tolerance:       # what kept it above the tolerance
                    cause = ("; ".join(refused[f] for f in r.faces if f in refused)
                             or ("the stiffest bend rows leave it there" if why else "no face could bend"))
                    why = (f"{why}; " if why else "") + \
                        f"still {100 * now:.2g} %, above the {100 * settings.g2_tolerance:.2g} % tolerance: {cause}"
            out.append(replace(r, jump_hot=hot_jump, jump_before=before, jump_after=now, g2=is_g2,
                               g2_reason=why))
            if is_g2 and settings.continuity is Continuity.G2:
                log.info("G2: edge %d (faces %d, %d): curvature jump %.3g -> %.3g of the curvature (%s)", r.edge,
                         *r.faces, before, now, why or "within the tolerance")
        return face_morphs, out

    def _bend(self, current: list[BSplineSurface], plain: list[BSplineSurface], bend: list[TangentEdge],  # noqa: PLR0913
              weight: float, kinks: dict[int, float], grids: list[FaceGrid], edge_morphs: list[EdgeMorph],
              refused_before: set[int]) -> tuple[dict[int, FaceMorph], dict[int, str]]:
        """The faces of the ``bend`` edges fitted again with bend rows of ``weight`` towards the common
        curvature of the ``current`` surfaces; a face that would go farther from the field than the
        tolerance and 10 % beyond its ``plain`` fit (after G1), or kink a tangent edge beyond ``kinks`` (its
        kink after G1) and 0.01 deg above its hot angle, keeps its surface and the other face bends to it.
        Faces in ``refused_before`` (refused at a softer weight) keep their surfaces from the start.  Returns
        the refits taken and the faces refused (index -> why)."""
        part = self.part
        faces = {k for te in bend for k in te.faces}
        kept = set(range(len(part.faces))) - faces | refused_before
        refused: dict[int, str] = {}
        refits: dict[int, FaceMorph] = {}
        for _ in range(_G1_ROUNDS):
            refits = {}
            for k in sorted(faces - kept):
                turn = turn_rows(part, current, self.tangent, k, TANGENT_WEIGHT, kept=frozenset(kept), sides=True)
                bent = bend_rows(part, current, bend, k, weight, kept=frozenset(kept))
                refits[k] = self.fit_face(part, part.faces[k], edge_morphs,
                                          (sparse.vstack([turn[0], bent[0]], format="csr"),
                                           np.concatenate([turn[1], bent[1]])))
            off = {k: self._moved_off(k, plain[k], refit.surface, grids[k], _TURN_SHARE, "bending", 1.0)
                   for k, refit in refits.items()}
            off = {k: why for k, why in off.items() if why}
            trial = [refits[k].surface if k in refits and k not in off else s for k, s in enumerate(current)]
            for te, now in zip(self.tangent, kink_maxima(part, trial, self.tangent)):
                if now > max(kinks[te.edge], te.hot_angle_max + _KINK_PROMISE_DEG) + _KINK_NOISE_DEG:
                    for k in set(te.faces) & set(refits) - set(off):
                        off[k] = (f"bending face {k} would kink edge {te.edge} to {now:.3g} deg "
                                  f"({kinks[te.edge]:.3g} before)")
            for k, why in off.items():
                log.info("G2: face %d not bent (bend rows' weight %g): %s", k, weight, why)
            if not off:
                return refits, refused
            kept |= set(off)
            refused.update(off)
        return {}, refused           # still refusing after the rounds: nothing bent at this weight

    def _edge_moved_off(self, e: int, before: EdgeMorph, after: BSplineCurve) -> str:
        """Why edge ``e`` may not take the corner-corrected curve ``after`` in place of its fit ``before``: its
        largest distance to its nodes' cold targets (eq. 21) would exceed the tolerance, and what it was
        before; "" if it may.  On NIST CTC-04 edges refined to 9.7e-4 mm turned into a fillet's tangent
        plane at their corners went 1.6e-3 mm off their nodes."""
        limit = self.settings.tolerance
        edge = self.part.edges[e]
        if limit is None:
            return ""
        was = edge_errors(edge, before, self.classification, self.field)[1]
        now = edge_errors(edge, replace(before, curve=after), self.classification, self.field)[1]
        if not len(now) or now.max() <= max(limit, was.max()):
            return ""
        return f"turning edge {e} would take it {now.max():.2g} mm off its nodes (tolerance {limit:g} mm, " \
               f"{was.max():.2g} before)"

    def _targets(self, k: int, grid: FaceGrid) -> tuple[np.ndarray, np.ndarray]:
        """Where face ``k`` should pass, ``(m, 3)``: its nodes' cold targets (eq. 21) and the field's estimate
        over its ``grid``; and the hot parameters ``(m, 2)`` of those points."""
        nodes = self.classification.nodes_of(Role.FACE, k)
        return (np.concatenate([self.classification.foot[nodes] + self.field.displacements[nodes], grid.expected]),
                np.concatenate([self.classification.uv[nodes], grid.uv]))

    def field_distance(self, k: int, surface: BSplineSurface, grid: FaceGrid, keep_feet: bool = False) -> float:
        """The largest distance (mm) from a morphed ``surface`` of face ``k`` to its nodes' cold targets
        (eq. 21) and to the field's estimate over its ``grid`` (0 where it has neither), each point projected
        only where its distance at its hot parameters does not bound it below the largest
        (:func:`~hot2cold.core.footpoint.surface_distances_above`).  ``keep_feet``: the parameters where the
        distances were found (or bounded) are kept for :meth:`_distance_bound`."""
        key = (k, surface, grid)
        if key in self._distances and (not keep_feet or key in self._feet):
            return self._distances[key]
        targets, uv = self._targets(k, grid)
        distance, feet = 0.0, uv
        if len(uv):
            found, feet = surface_distances_above(surface, targets, uv, self.part.faces[k].uv_box, return_uv=True)
            distance = float(found.max())
        self._distances[key] = distance
        if keep_feet:
            self._feet[key] = feet
        return distance

    def _distance_bound(self, k: int, before: BSplineSurface, after: BSplineSurface, grid: FaceGrid) -> float:
        """An upper bound (mm) of the distance of ``after`` from the points of :meth:`field_distance`: the
        largest distance of each point from ``after`` at the parameters where it was found on ``before``
        (a point on the surface is no nearer than its foot).  One evaluation per point instead of a
        projection; ``inf`` where ``before``'s parameters were not kept."""
        feet = self._feet.get((k, before, grid))
        if feet is None or not len(feet):
            return np.inf if feet is None else 0.0
        targets, _ = self._targets(k, grid)
        feet = clip_uv(after, feet)
        return float(np.linalg.norm(targets - evaluate_surface(after, feet[:, 0], feet[:, 1]), axis=1).max())

    def _moved_off(self, k: int, before: BSplineSurface, after: BSplineSurface, grid: FaceGrid,  # noqa: PLR0913
                   share: float | None = None, verb: str = "turning", floor: float | None = None) -> str:
        """Why face ``k`` may not take the G1-corrected surface ``after`` in place of ``before`` (its fit): its
        largest distance to its nodes' cold targets (eq. 21) or to the field's estimate over its ``grid``
        would exceed the tolerance, and what it was before; "" if it may.  A plane raised to cubic over a
        large box turned its second row over most of its trimmed part, 0.075 mm off its nodes where the fit
        was 8e-5; a refined fillet without nodes of a NIST part went 4e-3 mm off the exact cold geometry,
        the fit 1e-7.  With ``share``, the face may go no farther than ``1 + share`` times what it was, or
        ``share`` times the tolerance (issue 15: G1 at no more than 10 % of the plain fit's error), or
        ``floor`` times the tolerance where given (G2, which the user asks for: up to the tolerance)."""
        limit = self.settings.tolerance
        if limit is None:
            return ""
        was = self.field_distance(k, before, grid, keep_feet=True)
        allowed = max(limit, was) if share is None else \
            max((1.0 + share) * was, (share if floor is None else floor) * limit)
        if self._distance_bound(k, before, after, grid) <= allowed:
            return ""                   # within reach for certain, without projecting every point again
        now = self.field_distance(k, after, grid)
        if now <= allowed:
            return ""
        return (f"{verb} face {k} would take it {now:.2g} mm off the field ({allowed:.2g} mm allowed, "
                f"{was:.2g} before)")


def _measured_again(part: Part, surfaces: list[BSplineSurface], reports: list[G1Report], edges: list[TangentEdge],
                    faces: set[int]) -> list[G1Report]:
    """``reports`` with the largest kink after the correction measured again on ``surfaces`` for the edges
    (of ``edges``, the tangent edges the reports are of) on one of ``faces``."""
    by_edge = {te.edge: te for te in edges}
    again = [r for r in reports if faces & set(r.faces)]
    now = dict(zip((r.edge for r in again), kink_maxima(part, surfaces, [by_edge[r.edge] for r in again])))
    return [replace(r, kink_after_max=float(now[r.edge])) if r.edge in now else r for r in reports]


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
    hot : a STEP path, a CadQuery Shape/Workplane/Assembly or a ``TopoDS_Shape``; its solids are morphed.
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
    with limit:
        result = _morph(hot, field, settings, dict(units=units, field_name=field_name, step=field_step,
                                                   columns=columns, points_from=field_points), invert, progress)
    if check:
        check_result(result)
    return result


#: Scatter below this share of the tolerance is not smoothed: it cannot carry a fit out of the tolerance, and
#: smoothing towards the field's estimate is not free (a second fit per face).
_SMOOTH_SHARE = 0.01


def _over_promise(report: G1Report) -> float:
    """How far (degrees) a tangent edge's kink after G1 lies above its hot angle plus the promised 0.01."""
    return float(np.nan_to_num(max(report.kink_after_max - report.hot_angle_max - _KINK_PROMISE_DEG, 0.0)))


def _refined_off(context: MorphContext, before: list[FaceMorph], after: list[FaceMorph], grids: list[FaceGrid]
                 ) -> dict[int, str]:
    """The faces (index -> why) that a refinement for G1 takes too far from the field (nodes and ``grids``,
    :meth:`MorphContext.field_distance`): beyond 10 % above the largest distance of the faces it changes
    (so the part's Δmax grows by 10 % at the most, as G1 may) and beyond 10 % of the tolerance, or beyond the
    tolerance where the face was within it."""
    limit = context.settings.tolerance
    changed = [k for k, (a, b) in enumerate(zip(before, after)) if a.surface is not b.surface]
    if limit is None or not changed:
        return {}
    was = {k: context.field_distance(k, before[k].surface, grids[k]) for k in changed}
    allowed = max((1.0 + _TURN_SHARE) * max(was.values()), _TURN_SHARE * limit)
    off = {}
    for k in changed:
        now = context.field_distance(k, after[k].surface, grids[k])
        if now > allowed or now > limit >= was[k]:
            off[k] = (f"refining would take face {k} {now:.2g} mm off the field ({was[k]:.2g} before, "
                      f"{min(allowed, max(limit, was[k])):.2g} allowed)")
    return off


def _g1(context: MorphContext, edge_morphs: list[EdgeMorph], face_morphs: list[FaceMorph],  # noqa: PLR0913
        corners: list[CornerReport], grids: list[FaceGrid], shortest: np.ndarray | None, regrid: Regrid
        ) -> tuple[MorphContext, list[FaceGrid], list[EdgeMorph], list[FaceMorph], list[G1Report]]:
    """G1 on the fits ``edge_morphs``, ``face_morphs``: the corners of tangent edges anchored on trimmed
    faces, then the kinks along the edges removed (:meth:`MorphContext.correct_g1`).

    Where an edge stays more than 0.01 deg above its hot angle and ``shortest`` ((n_faces,) mm, the
    refinement's shortest half span per face) is given, the knot-span patches of its faces that hold the
    kinked points are halved (:func:`~hot2cold.pipeline.refine.refine_patches`; a face's net may have too few
    poles next to the edge: NIST FTC-08's 3x3 patches have one free pole in a second row), everything fitted
    and corrected again, and the refined part taken if it leaves at most ``_G1_GAIN`` of the kink above
    0.01 deg in all and takes no face farther from the field than G1 may (:func:`_refined_off`); up to
    :data:`_G1_REFINEMENTS` rounds.  ``regrid(part, faces, slack)`` gives the grids of refined faces (made
    without their slack here: a trial's decision reads their distances only).  Returns the
    context (its part refined where taken), the grids, the edge and face morphs and one report per tangent
    edge."""
    def corrected(ctx: MorphContext, edges: list[EdgeMorph], faces: list[FaceMorph], grids: list[FaceGrid]):
        edges, faces, more = ctx.anchor_corners(edges, faces)
        faces, reports = ctx.correct_g1(faces, corners + more, grids, edges)
        return edges, faces, reports

    best = (context, grids, *corrected(context, edge_morphs, face_morphs, grids))
    refined: set[int] = set()
    for _ in range(_G1_REFINEMENTS if shortest is not None else 0):
        ctx, grids_now, _, faces_now, reports = best
        over = {r.edge for r in reports if _over_promise(r) > 0}
        misses = kink_misses(ctx.part, [f.surface for f in faces_now], [te for te in ctx.tangent if te.edge in over],
                             _KINK_PROMISE_DEG)
        if not misses:
            break
        refitter = Refitter(ctx.fit_face, ctx.refit_edges, lambda part, faces: regrid(part, faces, slack=False),
                            ctx.settings.threads)
        patch = refine_patches(ctx.part, (face_morphs, edge_morphs), misses, shortest, refitter,
                               ctx.classification.counts(Role.FACE, len(ctx.part.faces)))
        if patch is None:
            log.info("G1: %d edges above %g deg; no patch of their faces may be halved", len(over),
                     _KINK_PROMISE_DEG)
            break
        trial_ctx = ctx.with_part(patch.part)
        trial_grids = [patch.grids.get(k, g) for k, g in enumerate(grids_now)]
        trial = corrected(trial_ctx, patch.edges, patch.faces, trial_grids)
        before, after = (sum(map(_over_promise, r)) for r in (reports, trial[2]))
        off = _refined_off(trial_ctx, faces_now, trial[1], trial_grids)
        why = "; ".join(off.values()) or (f"it leaves more than {_G1_GAIN:g} of it" if after > _G1_GAIN * before
                                          else "")
        log.info("G1: faces %s refined along %d edges above %g deg: %.3g -> %.3g deg above it in all%s",
                 sorted(patch.knots_added), len(over), _KINK_PROMISE_DEG, before, after,
                 f"; not taken: {why}" if why else "")
        if why:
            break
        best = (trial_ctx, trial_grids, *trial)
        face_morphs, edge_morphs = patch.faces, patch.edges
        refined |= set(patch.knots_added)
    ctx, grids, edges, faces, reports = best
    reports = [replace(r, method=f"{r.method}; {REFINED}") if r.method and refined & set(r.faces) else r
               for r in reports]
    return ctx, grids, edges, faces, reports


def smoothing_noise(scatter: float, settings: Settings) -> float:
    """The scatter (mm) the fits smooth away (:func:`~hot2cold.core.lstsq.solve_tsvd`'s ``noise``): the
    field's own, where it is above ``_SMOOTH_SHARE`` of the tolerance and ``settings.smooth`` is set, else 0."""
    if not settings.smooth or settings.tolerance is None or scatter <= _SMOOTH_SHARE * settings.tolerance:
        return 0.0
    return scatter


#: A field that scatters about a smooth field by more than this share of the tolerance is noisy: it is said
#: (an info line), and it is not taken inside its FE elements (:func:`~.load.element_points`): the points
#: would carry its noise, and their rows cost what the smoothed fits cannot use (the bundled mixer's noisy
#: field of every node ran out of 8 GB with them; the twisted blade's took 20 minutes).
NOISY_SHARE = 0.1


def _classified(part, field: DisplacementField, settings: Settings, projector: Projector, starts: Starts,  # noqa: PLR0913
                check: bool = True, inverted: bool = False) -> tuple[Classification, DisplacementField, float]:
    """Classify ``field`` (METHOD step 2) and, with ``check``, check first that hot and cold are not mixed up
    in it (``inverted``: it was inverted, ``--invert``) and then that it covers the part: the classification,
    the field as classified (a row per solid a node feeds; displacements carried to the foot points of nodes
    off the surface) and its scatter about a smooth field (mm, :func:`~hot2cold.core.localfit.scatter`).  Newton
    starts from ``starts`` (the same grids for the check and the classification)."""
    if check:
        check_positions(part, field, projector, settings, inverted, starts)
    cls = classify_nodes(part, field, settings, projector, starts)
    if len(cls.node) > len(field):      # nodes that feed two solids: one row per solid they feed
        field = field.take(cls.node)
    if check:
        check_coverage(part, cls, field, settings, projector)
    field = DisplacementField(field.points, carry_to_feet(field.points, cls.foot, field.displacements, cls.used,
                                                          settings.vertex_neighbours, GAP_SHARE * part.diagonal),
                              field.node_ids, field.source)
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
    starts = Starts(part)
    cls, classified, noise = _classified(part, field, settings, projector, starts, inverted=inverted)
    added = 0
    if noise <= NOISY_SHARE * (settings.tolerance or np.inf):      # a smooth field: taken inside its elements
        dense, added = element_points(field, settings)
        if added:
            # its nodes covered the part (checked, warned once); the points inside the elements add to them
            cls, classified, noise = _classified(part, dense, settings, projector, starts, check=False)
    allowance = noise_allowance(noise, int(cls.used.sum()))
    if noise > NOISY_SHARE * (settings.tolerance or np.inf):
        log.info("the field scatters by %.3g mm about a smooth field (per component): the fits are smoothed "
                 "and the tolerance at the nodes is widened by %.3g mm", noise, allowance)
    return _Classified(projector, cls, classified, field, noise, allowance, added, FieldScale.of(cls, classified))


def _gridder(context: MorphContext, classified: _Classified) -> FaceGridder:
    """The grids of a morph's faces (:class:`~hot2cold.pipeline.checks.FaceGridder`), for the refinement, G1
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


def _rebuild_and_check(context: MorphContext, fits: Fits, classified: _Classified, hot_checks: list,
                       grids: list[FaceGrid], stages: _Stages) -> _Cold:
    """Rebuild the cold part (the cold geometry in a copy of the kernel shape), sew it (tolerances fitted to its
    gaps) and check it (:func:`~hot2cold.pipeline.checks.check_cold`)."""
    part, settings = context.part, context.settings
    vertices = part.vertices + context.vertex_displacements
    stages.begin("rebuild")
    cold = rebuild(part.kernel, [f.surface for f in fits.faces], [e.curve for e in fits.edges], vertices)
    stages.lap("rebuild")
    stages.begin("sew")
    gaps = fit_tolerances(cold, reproject_above=_REPROJECT_SHARE * part.diagonal,
                          touch_bound=_TOUCH_SHARE * part.diagonal)
    cold_checks = check_solids(cold.shape)
    stages.lap("sew")
    stages.begin("check")
    tolerance = (settings.tolerance if settings.tolerance is not None else np.inf) + classified.allowance
    check = check_cold(part, cold, fits.faces, classified.projector, hot_checks, cold_checks, classified.scale,
                       grids, tolerance)
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
        context, grids, edge_morphs, face_morphs, g1_reports = _g1(context, edge_morphs, face_morphs, corners,
                                                                   grids, refined.shortest, regrid)
        # the checks between the nodes need the slack the grids of a refinement G1 took were made without
        grids = with_slack(context.part, grids, regrid.face_nodes, context.settings.threads)
        stages.lap("g1")
        stages.begin("g2")
        face_morphs, g1_reports = context.correct_g2(face_morphs, g1_reports, grids, edge_morphs)
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


def _morph(hot, field, settings: Settings, reading: dict, invert: bool, progress: Progress | None) -> MorphResult:
    """:func:`morph` within its BLAS thread limit, unchecked; ``reading`` holds :func:`as_field`'s keywords.
    The steps of METHOD in order, each a function of its own; the stages timed and told to ``progress``."""
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
    part = load_part(hot, settings)
    hot_checks = check_solids(part.kernel.hot)
    check_hot(part, hot_checks)
    stages.lap("load")

    # classify (step 2, eq. 4, 27, 33-37): each node's foot point on a face, edge or vertex, or ignored
    stages.begin("classify", len(field))
    classified = _classify(part, field, settings, invert)
    cls, field = classified.classification, classified.field
    stages.lap("classify")

    # edges (step 3, eq. 1-22): ends at the morphed vertices, one tangent plane at the corners of tangent edges
    context = MorphContext.of(part, cls, field, settings, classified.projector, classified.scale.strain,
                              smoothing_noise(classified.noise, settings))
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
    cold = _rebuild_and_check(context, fits, classified, hot_checks, grids, stages)
    about = {"hot_name": str(hot) if isinstance(hot, (str, os.PathLike)) else type(hot).__name__,
             "inversion": None if inversion is None else asdict(inversion)}
    return _result(context, classified, fits, cold, stages, about)
