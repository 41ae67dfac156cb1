"""How far a morphed face or edge is from the field, and whether a correction may take it farther.

G1, G2 and the refinement for G1 replace fits by corrected ones (turned, bent, refined); a correction is taken
only where it leaves the fit within reach of the field (its nodes' cold targets, eq. 21, and the field's
estimate between them): :meth:`FieldDistance.moved_off` says why not where it does not.  The distances are
cached per (face, surface's content, grid), and so are the verdicts of :meth:`FieldDistance.moved_off`: G1 and G2 ask
for a face's plain fit against every trial, and G1's refinement trials correct the faces away from the refined ones
again into the same surfaces (other objects).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from dataclasses import field as dataclass_field

import numpy as np

from ..core.bspline import BSplineCurve, BSplineSurface, clip_uv, evaluate_surface
from ..core.footpoint import surface_distances_above
from ..core.model import Classification, Part, Role
from ..core.threads import map_threads
from ..io.field import DisplacementField
from .grids import FaceGrid
from .edge_fit import EdgeMorph
from .refine import edge_errors

__all__ = ["Allowance", "FieldDistance"]


@dataclass(frozen=True)
class Allowance:
    """How far from the field (mm) a corrected face may go.

    Attributes
    ----------
    verb : str, what the correction does, for the message ("turning", "bending").
    share : float or None; None: up to the tolerance, or what the face was if more.  Else up to ``1 + share``
        times what it was, or ``share`` times the tolerance (G1 at no more than 10 % of the plain fit's error).
    floor : float or None, with ``share``: up to this many times the tolerance instead of ``share`` times it
        (G2, which the user asks for: up to the tolerance).
    """

    verb: str = "turning"
    share: float | None = None
    floor: float | None = None

    def allowed(self, was: float, tolerance: float) -> float:
        """The largest distance (mm) allowed to a face that was ``was`` mm from the field."""
        if self.share is None:
            return max(tolerance, was)
        return max((1.0 + self.share) * was, (self.share if self.floor is None else self.floor) * tolerance)


@dataclass(frozen=True, eq=False)
class FieldDistance:
    """The distance of fits from the field of one morph.

    Attributes
    ----------
    part : Part, the hot part (a refined one: the same faces and parameters).
    classification : Classification of the field's nodes.
    field : DisplacementField, hot positions ``(N, 3)`` and hot-to-cold displacements ``(N, 3)``.
    tolerance : float or None, the morph's tolerance (mm); None: every correction may be taken.
    threads : int, for :meth:`all_moved_off`.
    """

    part: Part
    classification: Classification
    field: DisplacementField
    tolerance: float | None
    threads: int = 1
    #: :meth:`distance` of each (face, surface's :meth:`~hot2cold.core.bspline.BSplineSurface.digest`, grid) asked
    #: for (keys hold the grids, so no id is reused while the record lives; :meth:`on` shares them).
    _distances: dict = dataclass_field(default_factory=dict, repr=False)
    #: The parameters where :meth:`distance` found the distances of a fit a correction may replace (by the same
    #: keys), for :meth:`_bound`; only for those, since each holds a pair per node.
    _feet: dict = dataclass_field(default_factory=dict, repr=False)
    #: :meth:`moved_off`'s answer for each (face, the two surfaces' digests, grid, allowance) asked: G1's rounds
    #: and refinement trials ask again of the faces they leave as they were.
    _verdicts: dict = dataclass_field(default_factory=dict, repr=False)

    def on(self, part: Part) -> FieldDistance:
        """This record on ``part`` (a refined part: the same faces and parameters), its caches shared."""
        return replace(self, part=part)

    def _targets(self, k: int, grid: FaceGrid) -> tuple[np.ndarray, np.ndarray]:
        """Where face ``k`` should pass, ``(m, 3)``: its nodes' cold targets (eq. 21) and the field's estimate
        over its ``grid``; and the hot parameters ``(m, 2)`` of those points."""
        nodes = self.classification.nodes_of(Role.FACE, k)
        return (np.concatenate([self.classification.foot[nodes] + self.field.displacements[nodes], grid.expected]),
                np.concatenate([self.classification.uv[nodes], grid.uv]))

    def distance(self, k: int, surface: BSplineSurface, grid: FaceGrid, keep_feet: bool = False) -> float:
        """The largest distance (mm) from a morphed ``surface`` of face ``k`` to its nodes' cold targets
        (eq. 21) and to the field's estimate over its ``grid`` (0 where it has neither), each point projected
        only where its distance at its hot parameters does not bound it below the largest
        (:func:`~hot2cold.core.footpoint.surface_distances_above`).  ``keep_feet``: the parameters where the
        distances were found (or bounded) are kept for :meth:`_bound`."""
        key = (k, surface.digest(), grid)
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

    def _bound(self, k: int, before: BSplineSurface, after: BSplineSurface, grid: FaceGrid) -> float:
        """An upper bound (mm) of the distance of ``after`` from the points of :meth:`distance`: the largest
        distance of each point from ``after`` at the parameters where it was found on ``before`` (a point on the
        surface is no nearer than its foot).  One evaluation per point instead of a projection; ``inf`` where
        ``before``'s parameters were not kept."""
        feet = self._feet.get((k, before.digest(), grid))
        if feet is None or not len(feet):
            return np.inf if feet is None else 0.0
        targets, _ = self._targets(k, grid)
        feet = clip_uv(after, feet)
        return float(np.linalg.norm(targets - evaluate_surface(after, feet[:, 0], feet[:, 1]), axis=1).max())

    def moved_off(self, k: int, before: BSplineSurface, after: BSplineSurface, grid: FaceGrid,
                  allowance: Allowance = Allowance()) -> str:
        """Why face ``k`` may not take the corrected surface ``after`` in place of ``before`` (its fit):
        its largest distance to its nodes' cold targets (eq. 21) or to the field's estimate over its ``grid``
        would exceed what ``allowance`` allows against the tolerance and what it was before; "" if it may.
        (A plane raised to cubic over a large box turned its second row over most of its trimmed part, far off
        its nodes; a refined fillet without nodes went far off the exact cold geometry.)"""
        if self.tolerance is None:
            return ""
        key = (k, before.digest(), after.digest(), grid, allowance)
        if key not in self._verdicts:
            self._verdicts[key] = self._moved_off(k, before, after, grid, allowance)
        return self._verdicts[key]

    def _moved_off(self, k: int, before: BSplineSurface, after: BSplineSurface, grid: FaceGrid,
                   allowance: Allowance) -> str:
        """:meth:`moved_off` worked out."""
        was = self.distance(k, before, grid, keep_feet=True)
        allowed = allowance.allowed(was, self.tolerance)
        if self._bound(k, before, after, grid) <= allowed:
            return ""                   # within reach for certain, without projecting every point again
        now = self.distance(k, after, grid)
        if now <= allowed:
            return ""
        return (f"{allowance.verb} face {k} would take it {now:.2g} mm off the field ({allowed:.2g} mm allowed, "
                f"{was:.2g} before)")

    def all_moved_off(self, changes: dict[int, tuple[BSplineSurface, BSplineSurface]], grids: list[FaceGrid],
                      allowance: Allowance = Allowance()) -> dict[int, str]:
        """:meth:`moved_off` of each face ``k: (before, after)`` of ``changes`` (in up to ``threads`` threads):
        the faces that may not take ``after``, and why."""
        faces = list(changes)
        nodes = self.classification.counts(Role.FACE, len(self.part.faces))
        why = map_threads(lambda k: self.moved_off(k, *changes[k], grids[k], allowance), faces, self.threads,
                          cost=[len(grids[k].uv) + nodes[k] for k in faces])
        return {k: text for k, text in zip(faces, why) if text}

    def edge_moved_off(self, e: int, before: EdgeMorph, after: BSplineCurve) -> str:
        """Why edge ``e`` may not take the corner-corrected curve ``after`` in place of its fit ``before``: its
        largest distance to its nodes' cold targets (eq. 21) would exceed the tolerance, and what it was
        before; "" if it may."""
        if self.tolerance is None:
            return ""
        edge = self.part.edges[e]
        was = edge_errors(edge, before, self.classification, self.field)[1]
        now = edge_errors(edge, replace(before, curve=after), self.classification, self.field)[1]
        if not len(now) or now.max() <= max(self.tolerance, was.max()):
            return ""
        return f"turning edge {e} would take it {now.max():.2g} mm off its nodes (tolerance {self.tolerance:g} mm, " \
               f"{was.max():.2g} before)"
