"""G1 and G2 along the tangent edges of a morph: what is tried, in what rounds, and what is refused.

The rows and measures are :mod:`hot2cold.pipeline.g1`'s (section 5, eq. 56-75) and
:mod:`hot2cold.pipeline.g2`'s; this module decides with them, on the fits of a :class:`MorphContext`:

* corners of tangent edges on trimmed faces anchored in the face's fitted tangent plane (:func:`anchor_corners`);
* kinks along trimming curves removed by fitting the faces again with their tangents turned, kinks along
  iso-sides by the second rows (eq. 56-75), each face refused that would leave the field
  (:meth:`~hot2cold.pipeline.distance.FieldDistance.moved_off`) or kink an edge more, the other face then turning
  to it (:func:`correct_g1`);
* faces refined along the edges their nets cannot bring to 0.01 deg, where it pays (:class:`G1Refinement`);
* the curvature jumps measured, and with ``Continuity.G2`` removed by bend rows (:func:`correct_g2`).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
from scipy import sparse

from ..core.bspline import BSplineSurface
from ..core.model import Part, Role
from ..settings import Continuity
from .grids import FaceGrid
from .context import MorphContext
from .distance import Allowance
from .edge_fit import EdgeMorph
from .face_fit import FaceMorph
from .g1 import (ALONG_CURVE, KINK_NOISE_DEG, REFINED, TURN_WEIGHT, CornerReport, G1Report, Neighbours, TangentEdge,
                 correct_corners, edge_decided, kink_bound, kink_maxima, kink_misses, surface_corner_normals,
                 turn_rows, with_corners)
from .g1 import correct_g1 as second_rows
from .g2 import BEND_WEIGHTS, BENT, TANGENT_WEIGHT, bend_rows, edge_jumps
from .refine import Refitter, Regrid, refine_patches

__all__ = ["G1Refinement", "anchor_corners", "correct_g1", "correct_g2", "smooth_g1"]

log = logging.getLogger(__name__)

#: Rounds of the G1 correction at the most: each round freezes the faces the last one moved off their nodes.
_G1_ROUNDS = 3
#: A face fitted again with its tangents turned along a trimming curve may be this share farther from the field
#: than its plain fit, or this share of the tolerance: G1 may cost the fit only a small part of its accuracy,
#: and a face allowed to turn as far as the tolerance alone goes several times farther off the exact cold
#: geometry.
_TURN_SHARE = 0.1
#: How far a face turned by G1, or its second rows moved, may go from the field.
_TURNING = Allowance("turning", _TURN_SHARE)
#: How far a face bent by G2 (which the user asks for) may go from the field: up to the tolerance.
_BENDING = Allowance("bending", _TURN_SHARE, 1.0)
#: The largest kink (degrees) above its hot angle a correction may leave on a tangent edge that it finds less
#: kinked (the G1 accuracy the morph promises): the second rows (G1) and a face bent to a common curvature (G2).
_KINK_PROMISE_DEG = 0.01
#: Rounds of refinement for G1 at the most (:func:`smooth_g1`), each halving the patches along the edges still
#: kinked.
_G1_REFINEMENTS = 2
#: A refinement for G1 adds poles to the faces along the edges: it is taken where it leaves at most this share
#: of what those edges were above the promise in all (a second trial costs as much as the first, and finds
#: less).
_G1_GAIN = 0.5


def anchor_corners(context: MorphContext, edge_morphs: list[EdgeMorph], face_morphs: list[FaceMorph]
                   ) -> tuple[list[EdgeMorph], list[FaceMorph], list[CornerReport]]:
    """Corners of tangent edges where a face's normal is not decided by its edges (a trimmed face, a
    smooth boundary): the other faces' edges there turn into that face's fitted tangent plane, and the
    faces of the edges that moved are fitted again.  An edge that would leave its nodes
    (:meth:`~hot2cold.pipeline.distance.FieldDistance.edge_moved_off`) keeps its fit.  Returns the edge morphs,
    the face morphs and the corner reports."""
    part = context.part
    decided = edge_decided(part, [f.tied_sides for f in face_morphs])
    pairs = {(v, k) for te in context.tangent for v in part.edges[te.edge].vertices for k in te.faces} - decided
    anchors = surface_corner_normals(part, [f.surface for f in face_morphs], pairs)
    if not anchors:
        return edge_morphs, face_morphs, []
    curves, corners = correct_corners(part, [e.curve for e in edge_morphs], context.tangent, anchors,
                                      decided, context.strain)
    moved = {e for c in corners for e in c.edges}
    off = {e: why for e in sorted(moved)
           if (why := context.distances.edge_moved_off(e, edge_morphs[e], curves[e]))}
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
    for k, morph in zip(again, context.refit_faces(again, edge_morphs)):
        faces[k] = morph
    return edge_morphs, faces, corners


def correct_g1(context: MorphContext, face_morphs: list[FaceMorph], corners: list[CornerReport],
               grids: list[FaceGrid], edge_morphs: list[EdgeMorph]) -> tuple[list[FaceMorph], list[G1Report]]:
    """The kinks the morph added along tangent edges (and at their corners) removed from the faces
    (eq. 56-75; along trimming curves by fitting the faces again with their tangents turned there,
    :func:`~hot2cold.pipeline.g1.turn_rows`); returns the face morphs and one report per tangent edge."""
    part = context.part
    face_morphs = list(face_morphs)
    surfaces = [f.surface for f in face_morphs]
    largest = dict(zip((e.edge for e in context.tangent), kink_maxima(part, surfaces, context.tangent)))
    kinked = [e for e in context.tangent
              if largest[e.edge] - e.hot_angle_max > kink_bound(e.hot_angle_max, KINK_NOISE_DEG, context.strain)
              or any(c.edges for c in corners if c.vertex in part.edges[e.edge].vertices)]
    # faces with kinked trimming curves: fitted again, their tangents there turned into the common plane
    along = [e for e in kinked if None in e.sides]
    plain = {e.edge: largest[e.edge] for e in along}
    turned, refused = _turn_along_curves(context, surfaces, along, plain, grids, edge_morphs)
    for k, refit in turned.items():
        face_morphs[k] = refit
    surfaces = [f.surface for f in face_morphs]
    corrected, reports = _second_rows(context, surfaces, [f.tied_sides for f in face_morphs], kinked, grids)
    reports = _with_turns(reports, plain, set(turned), refused)
    return ([replace(f, surface=surface) for f, surface in zip(face_morphs, corrected)],
            with_corners(part, reports, corners))


def _turn_along_curves(context: MorphContext, surfaces: list[BSplineSurface], along: list[TangentEdge],
                       plain: dict[int, float], grids: list[FaceGrid], edge_morphs: list[EdgeMorph]
                       ) -> tuple[dict[int, FaceMorph], dict[int, str]]:
    """The faces of the trimming curves ``along`` (their kinks ``plain`` on the plain fits ``surfaces``) fitted
    again with their tangents there turned into the common plane; a face that may not turn (it would leave the
    field, :data:`_TURNING`, or kink one of the edges more than the plain fits) keeps its fit, and the other
    turns to it, in up to :data:`_G1_ROUNDS` rounds (a face none of whose neighbours across the curves came to
    keep its fit turns as it did).  Returns the refits taken and the faces refused (why)."""
    part = context.part
    turning = {f for e in along for f, side in zip(e.faces, e.sides) if side is None}
    across: dict[int, set[int]] = {}                         # face -> the faces across its curves
    for e in along:
        for k in e.faces:
            across.setdefault(k, set()).update(set(e.faces) - {k})
    kept: set[int] = set(range(len(part.faces))) - turning    # faces that keep their fits along the curves
    refits: dict[int, FaceMorph] = {}
    refused: dict[int, str] = {}
    off: dict[int, str] = {}
    for _ in range(_G1_ROUNDS):       # both faces turn to the common plane; a face that may not turn (it
        order = sorted(turning - kept)  # would leave the field) keeps its fit, and the other turns to it
        near = Neighbours(part, surfaces, frozenset(kept))
        again = [k for k in order if k not in refits or across[k] & set(off)]
        turns = [turn_rows(near, along, k, TURN_WEIGHT) for k in again]
        refits.update(zip(again, context.refit_faces(again, edge_morphs, turns)))
        refits = {k: refits[k] for k in order}
        off = context.distances.all_moved_off({k: (surfaces[k], refit.surface) for k, refit in refits.items()},
                                              grids, _TURNING)
        # a turn that leaves one of its edges more kinked than the plain fits is no correction (next to a
        # sharp corner a turn can kink the curve far more than it was)
        trial = [refits[k].surface if k in refits else s for k, s in enumerate(surfaces)]
        for e, now in zip(along, kink_maxima(part, trial, along)):
            if now > plain[e.edge] + KINK_NOISE_DEG:
                for k in set(e.faces) & set(refits) - set(off):
                    off[k] = (f"turning face {k} would kink edge {e.edge} more ({plain[e.edge]:.3g} -> "
                              f"{now:.3g} deg)")
        for k, why in off.items():
            log.info("G1: face %d not turned along its trimming curves: %s", k, why)
        if not off:
            break
        kept |= set(off)
        refused.update(off)
    return {k: refits[k] for k in set(refits) - kept}, refused


def _second_rows(context: MorphContext, surfaces: list[BSplineSurface], tied: list[tuple], kinked: list[TangentEdge],
                 grids: list[FaceGrid]) -> tuple[list[BSplineSurface], list[G1Report]]:
    """The second rows of the faces of the ``kinked`` edges moved into the common tangent plane
    (:func:`~hot2cold.pipeline.g1.correct_g1`, eq. 56-75); a face they would take off the field, or whose rows
    would leave an edge more kinked than they found it and beyond the promise, is frozen and the rest corrected
    again, in up to :data:`_G1_ROUNDS` rounds.  Returns the surfaces and one report per kinked edge."""
    part = context.part
    frozen: dict[int, str] = {}
    before = kink_maxima(part, surfaces, kinked)            # the same surfaces in every round
    for _ in range(_G1_ROUNDS):
        corrected, reports = second_rows(part, surfaces, tied, kinked, frozen=frozen, before=before)
        off = context.distances.all_moved_off({k: (surfaces[k], corrected[k]) for k in range(len(surfaces))
                                               if corrected[k] is not surfaces[k]}, grids)
        # second rows that leave an edge more kinked than they found it, and beyond the promise, are no
        # correction there (a curve turned in the fit can be kinked again by its neighbour's rows)
        for r in reports:
            if r.kink_after_max > max(r.kink_before_max, r.hot_angle_max + _KINK_PROMISE_DEG) + KINK_NOISE_DEG:
                for k in r.faces:
                    if corrected[k] is not surfaces[k] and k not in off:
                        off[k] = (f"the second rows of face {k} would kink edge {r.edge} more "
                                  f"({r.kink_before_max:.3g} -> {r.kink_after_max:.3g} deg)")
        if not off:
            return corrected, reports
        frozen.update(off)
    # still moving faces off: those keep their fits
    log.warning("G1: faces %s keep their fits: %s", sorted(off), "; ".join(off.values()))
    corrected = [surfaces[k] if k in off else c for k, c in enumerate(corrected)]
    return corrected, _measured_again(part, corrected, reports, kinked, set(off))


def _with_turns(reports: list[G1Report], plain: dict[int, float], turned: set[int], refused: dict[int, str]
                ) -> list[G1Report]:
    """``reports`` of the trimming curves (their kinks ``plain`` on the plain fits) saying what the turns did:
    corrected where one of its faces ``turned``, else why its faces were ``refused``."""
    reports = list(reports)
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
    return reports


def _measured_again(part: Part, surfaces: list[BSplineSurface], reports: list[G1Report], edges: list[TangentEdge],
                    faces: set[int]) -> list[G1Report]:
    """``reports`` with the largest kink after the correction measured again on ``surfaces`` for the edges
    (of ``edges``, the tangent edges the reports are of) on one of ``faces``."""
    by_edge = {te.edge: te for te in edges}
    again = [r for r in reports if faces & set(r.faces)]
    now = dict(zip((r.edge for r in again), kink_maxima(part, surfaces, [by_edge[r.edge] for r in again])))
    return [replace(r, kink_after_max=float(now[r.edge])) if r.edge in now else r for r in reports]


@dataclass(frozen=True, eq=False)
class G1Refinement:
    """How G1 may refine the faces along the edges it leaves kinked.

    Attributes
    ----------
    shortest : (n_faces,) float array, the refinement's shortest half span per face (mm): G1 refines no finer.
    regrid : ``regrid(part, faces, slack)``, the grids of refined faces (made without their slack here: a trial's
        decision reads their distances only).
    """

    shortest: np.ndarray
    regrid: Regrid


def _over_promise(report: G1Report) -> float:
    """How far (degrees) a tangent edge's kink after G1 lies above its hot angle plus the promised 0.01."""
    return float(np.nan_to_num(max(report.kink_after_max - report.hot_angle_max - _KINK_PROMISE_DEG, 0.0)))


def _refined_off(context: MorphContext, before: list[FaceMorph], after: list[FaceMorph], grids: list[FaceGrid]
                 ) -> dict[int, str]:
    """The faces (index -> why) that a refinement for G1 takes too far from the field (nodes and ``grids``,
    :meth:`~hot2cold.pipeline.distance.FieldDistance.distance`): beyond 10 % above the largest distance of the
    faces it changes (so the part's Δmax grows by 10 % at the most, as G1 may) and beyond 10 % of the
    tolerance, or beyond the tolerance where the face was within it."""
    limit = context.settings.tolerance
    changed = [k for k, (a, b) in enumerate(zip(before, after)) if a.surface is not b.surface]
    if limit is None or not changed:
        return {}
    was = {k: context.distances.distance(k, before[k].surface, grids[k]) for k in changed}
    allowed = max((1.0 + _TURN_SHARE) * max(was.values()), _TURN_SHARE * limit)
    off = {}
    for k in changed:
        now = context.distances.distance(k, after[k].surface, grids[k])
        if now > allowed or now > limit >= was[k]:
            off[k] = (f"refining would take face {k} {now:.2g} mm off the field ({was[k]:.2g} before, "
                      f"{min(allowed, max(limit, was[k])):.2g} allowed)")
    return off


#: One state of :func:`smooth_g1`: the context, the grids, the edge and face morphs, the reports.
_G1State = tuple[MorphContext, list[FaceGrid], list[EdgeMorph], list[FaceMorph], list[G1Report]]


def _corrected(context: MorphContext, fits: tuple[list[FaceMorph], list[EdgeMorph]], corners: list[CornerReport],
               grids: list[FaceGrid]) -> _G1State:
    """G1 once on ``fits`` (face and edge morphs): the corners anchored, then the kinks removed."""
    edges, faces, more = anchor_corners(context, fits[1], fits[0])
    faces, reports = correct_g1(context, faces, corners + more, grids, edges)
    return context, grids, edges, faces, reports


def smooth_g1(context: MorphContext, fits: tuple[list[FaceMorph], list[EdgeMorph]], corners: list[CornerReport],
              grids: list[FaceGrid], refinement: G1Refinement | None) -> _G1State:
    """G1 on the fits ``(face_morphs, edge_morphs)``: the corners of tangent edges anchored on trimmed faces,
    then the kinks along the edges removed (:func:`correct_g1`).

    With a ``refinement``, where an edge stays more than 0.01 deg above its hot angle the knot-span patches of
    its faces that hold the kinked points are halved (:func:`~hot2cold.pipeline.refine.refine_patches`; a face's
    net may have too few poles next to the edge: a 3x3 patch has one free pole in a second row), everything
    fitted and corrected again, and the refined part taken if it leaves at most :data:`_G1_GAIN` of the kink
    above 0.01 deg in all and takes no face farther from the field than G1 may (:func:`_refined_off`); up to
    :data:`_G1_REFINEMENTS` rounds.  Returns the context (its part refined where taken), the grids, the edge and
    face morphs and one report per tangent edge."""
    best = _corrected(context, fits, corners, grids)
    refined: set[int] = set()
    for _ in range(_G1_REFINEMENTS if refinement is not None else 0):
        trial = _refined_trial(best, fits, corners, refinement)
        if trial is None:
            break
        best, fits, knots_added = trial
        refined |= knots_added
    ctx, grids, edges, faces, reports = best
    reports = [replace(r, method=f"{r.method}; {REFINED}") if r.method and refined & set(r.faces) else r
               for r in reports]
    return ctx, grids, edges, faces, reports


def _refined_trial(best: _G1State, fits: tuple[list[FaceMorph], list[EdgeMorph]], corners: list[CornerReport],
                   refinement: G1Refinement) -> tuple[_G1State, tuple, set[int]] | None:
    """One round of :func:`smooth_g1`'s refinement from the state ``best`` (the plain ``fits`` it was corrected
    from): the new state, the plain fits on the refined part and the faces refined, or None where nothing was
    refined or the refinement is not taken."""
    ctx, grids_now, _, faces_now, reports = best
    over = {r.edge for r in reports if _over_promise(r) > 0}
    misses = kink_misses(ctx.part, [f.surface for f in faces_now], [te for te in ctx.tangent if te.edge in over],
                         _KINK_PROMISE_DEG)
    if not misses:
        return None
    refitter = Refitter(ctx.fit_face, ctx.refit_edges,
                        lambda part, faces: refinement.regrid(part, faces, slack=False), ctx.settings.threads)
    patch = refine_patches(ctx.part, fits, misses, refinement.shortest, refitter,
                           ctx.classification.counts(Role.FACE, len(ctx.part.faces)))
    if patch is None:
        log.info("G1: %d edges above %g deg; no patch of their faces may be halved", len(over), _KINK_PROMISE_DEG)
        return None
    trial_grids = [patch.grids.get(k, g) for k, g in enumerate(grids_now)]
    trial = _corrected(ctx.with_part(patch.part), (patch.faces, patch.edges), corners, trial_grids)
    before, after = (sum(map(_over_promise, r)) for r in (reports, trial[4]))
    off = _refined_off(trial[0], faces_now, trial[3], trial_grids)
    why = "; ".join(off.values()) or (f"it leaves more than {_G1_GAIN:g} of it" if after > _G1_GAIN * before
                                      else "")
    log.info("G1: faces %s refined along %d edges above %g deg: %.3g -> %.3g deg above it in all%s",
             sorted(patch.knots_added), len(over), _KINK_PROMISE_DEG, before, after,
             f"; not taken: {why}" if why else "")
    if why:
        return None
    return trial, (patch.faces, patch.edges), set(patch.knots_added)


@dataclass(frozen=True, eq=False)
class _Bending:
    """What the bends of one G2 correction read.

    Attributes
    ----------
    context : MorphContext.
    plain : one surface per face, the fits after G1: how far a bent face may go is measured from them.
    kinks : tangent edge -> its largest kink after G1 (degrees): a bend may kink no edge beyond it and 0.01 deg
        above its hot angle.
    grids : one FaceGrid per face.
    edge_morphs : the edge morphs the faces are fitted against.
    """

    context: MorphContext
    plain: list[BSplineSurface]
    kinks: dict[int, float]
    grids: list[FaceGrid]
    edge_morphs: list[EdgeMorph]

    def _refits(self, current: list[BSplineSurface], bend: list[TangentEdge], weight: float, kept: set[int]
                ) -> dict[int, FaceMorph]:
        """The faces of the ``bend`` edges but ``kept`` fitted again with their tangents held in the common plane
        and bend rows of ``weight`` towards the common curvature of the ``current`` surfaces."""
        part, tangent = self.context.part, self.context.tangent
        refits = {}
        near = Neighbours(part, current, frozenset(kept))
        for k in sorted({k for te in bend for k in te.faces} - kept):
            turn = turn_rows(near, tangent, k, TANGENT_WEIGHT, sides=True)
            bent = bend_rows(near, bend, k, weight)
            refits[k] = self.context.fit_face(part, part.faces[k], self.edge_morphs,
                                              (sparse.vstack([turn[0], bent[0]], format="csr"),
                                               np.concatenate([turn[1], bent[1]])))
        return refits

    def bend(self, current: list[BSplineSurface], bend: list[TangentEdge], weight: float, refused_before: set[int]
             ) -> tuple[dict[int, FaceMorph], dict[int, str]]:
        """The faces of the ``bend`` edges fitted again with bend rows of ``weight`` towards the common
        curvature of the ``current`` surfaces; a face that would go farther from the field than
        :data:`_BENDING` allows, or kink a tangent edge beyond its kink after G1 and 0.01 deg above its hot
        angle, keeps its surface and the other face bends to it.  Faces in ``refused_before`` (refused at a
        softer weight) keep their surfaces from the start.  Returns the refits taken and the faces refused
        (index -> why)."""
        context = self.context
        part = context.part
        kept = set(range(len(part.faces))) - {k for te in bend for k in te.faces} | refused_before
        refused: dict[int, str] = {}
        for _ in range(_G1_ROUNDS):
            refits = self._refits(current, bend, weight, kept)
            off = {k: context.distances.moved_off(k, self.plain[k], refit.surface, self.grids[k], _BENDING)
                   for k, refit in refits.items()}
            off = {k: why for k, why in off.items() if why}
            trial = [refits[k].surface if k in refits and k not in off else s for k, s in enumerate(current)]
            for te, now in zip(context.tangent, kink_maxima(part, trial, context.tangent)):
                if now > max(self.kinks[te.edge], te.hot_angle_max + _KINK_PROMISE_DEG) + KINK_NOISE_DEG:
                    for k in set(te.faces) & set(refits) - set(off):
                        off[k] = (f"bending face {k} would kink edge {te.edge} to {now:.3g} deg "
                                  f"({self.kinks[te.edge]:.3g} before)")
            for k, why in off.items():
                log.info("G2: face %d not bent (bend rows' weight %g): %s", k, weight, why)
            if not off:
                return refits, refused
            kept |= set(off)
            refused.update(off)
        return {}, refused           # still refusing after the rounds: nothing bent at this weight


def correct_g2(context: MorphContext, face_morphs: list[FaceMorph], reports: list[G1Report], grids: list[FaceGrid],
               edge_morphs: list[EdgeMorph]) -> tuple[list[FaceMorph], list[G1Report]]:
    """The jump of the normal curvature across each tangent edge of ``reports`` (those G1 examined: the
    morph kinked them) measured on the hot faces, on ``face_morphs`` (after G1) and, with
    ``Settings.continuity`` G2, removed where the hot faces were curvature-continuous: both faces fitted again
    with rows that give them the common curvature across the edge and keep their tangents in the common plane
    (:func:`~hot2cold.pipeline.g2.bend_rows`, :func:`~hot2cold.pipeline.g1.turn_rows`), with bend rows stiffer
    in turn (``BEND_WEIGHTS``) while the jumps stay (:meth:`_Bending.bend`).  Returns the face morphs and the
    reports with their G2 fields."""
    part, settings = context.part, context.settings
    hot = [face.surface for face in part.faces]
    surfaces = [f.surface for f in face_morphs]
    by_edge = {te.edge: te for te in context.tangent}
    examined = [by_edge[r.edge] for r in reports]
    jumps = {te.edge: (float(h), float(b)) for te, h, b in zip(examined, edge_jumps(part, hot, examined),
                                                                edge_jumps(part, surfaces, examined))}
    bent_faces: set[int] = set()
    refused: dict[int, str] = {}
    if settings.continuity is Continuity.G2:
        smooth = [by_edge[e] for e, (hot_jump, _) in jumps.items() if hot_jump <= settings.g2_tolerance]
        bending = _Bending(context, surfaces,
                           dict(zip((te.edge for te in context.tangent), kink_maxima(part, surfaces, context.tangent))),
                           grids, edge_morphs)
        face_morphs, surfaces, bent_faces, refused = _bend_all(bending, face_morphs, smooth)
        # the G1 reports are measured again where a face bent
        reports = _measured_again(part, surfaces, reports, context.tangent, bent_faces)
    asked = [by_edge[r.edge] for r in reports
             if jumps[r.edge][0] <= settings.g2_tolerance and settings.continuity is Continuity.G2]
    after = dict(zip((te.edge for te in asked), edge_jumps(part, surfaces, asked)))
    out = []
    for r in reports:
        hot_jump, before = jumps[r.edge]
        g2 = r.edge in after
        now = float(after[r.edge]) if g2 else before
        why = _g2_reason(r, now, bool(bent_faces & set(r.faces)), refused, settings.g2_tolerance) if g2 else ""
        out.append(replace(r, jump_hot=hot_jump, jump_before=before, jump_after=now,
                           g2=hot_jump <= settings.g2_tolerance, g2_reason=why))
        if g2:
            log.info("G2: edge %d (faces %d, %d): curvature jump %.3g -> %.3g of the curvature (%s)", r.edge,
                     *r.faces, before, now, why or "within the tolerance")
    return face_morphs, out


def _bend_all(bending: _Bending, face_morphs: list[FaceMorph], smooth: list[TangentEdge]
              ) -> tuple[list[FaceMorph], list[BSplineSurface], set[int], dict[int, str]]:
    """The faces along the curvature-continuous tangent edges ``smooth`` bent with stiffer bend rows in turn
    (``BEND_WEIGHTS``) while the jumps stay above the tolerance and some face may bend.  Returns the face morphs,
    their surfaces, the faces bent and the faces refused (index -> why)."""
    part, tolerance = bending.context.part, bending.context.settings.g2_tolerance
    face_morphs = list(face_morphs)
    current = list(bending.plain)
    bent_faces: set[int] = set()
    refused: dict[int, str] = {}
    for weight in BEND_WEIGHTS:   # stiffer bend rows while the jumps stay and every face may bend
        bend = [te for te, jump in zip(smooth, edge_jumps(part, current, smooth)) if jump > tolerance]
        if not bend:
            break
        refits, off = bending.bend(current, bend, weight, set(refused))
        refused.update(off)
        for k, refit in refits.items():
            face_morphs[k] = refit
            current[k] = refit.surface
        bent_faces |= set(refits)
        if not refits:
            break
    return face_morphs, current, bent_faces, refused


def _g2_reason(report: G1Report, now: float, bent: bool, refused: dict[int, str], tolerance: float) -> str:
    """What G2 did on the edge of ``report`` (its jump ``now`` after; ``bent``: a face of it bent) and, where the
    jump stays above the ``tolerance``, what kept it there."""
    why = BENT if bent else ""
    if now > tolerance:
        cause = ("; ".join(refused[f] for f in report.faces if f in refused)
                 or ("the stiffest bend rows leave it there" if why else "no face could bend"))
        why = (f"{why}; " if why else "") + \
            f"still {100 * now:.2g} %, above the {100 * tolerance:.2g} % tolerance: {cause}"
    return why
