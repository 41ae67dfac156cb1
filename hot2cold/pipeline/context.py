"""What every fit of one morph reads, and the fits of edges and faces against it (METHOD steps 3-5).

:class:`MorphContext` is made once the field is classified; the refinement to the tolerance and G1 put it on
their refined part (:meth:`MorphContext.with_part`), the caches of its fits shared.  The G1 and G2 policy that
fits faces again through it lives in :mod:`hot2cold.pipeline.continuity`.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from dataclasses import field as dataclass_field
from typing import Callable

import numpy as np

from ..core.domain import Trim
from ..core.lstsq import ReducedRows
from ..core.model import Classification, Face, Part, Role
from ..core.threads import map_threads
from ..io.field import DisplacementField
from ..kernel.project import Projector
from ..settings import Settings
from .artificial import FieldEstimator
from .distance import FieldDistance
from .edge_fit import EdgeMorph, fit_edge, morph_edges, vertex_displacements
from .face_fit import FaceMorph, face_problem, morph_face, morph_faces, solve_face
from .fit_inputs import FitInputs
from .g1 import CornerReport, TangentEdge, correct_corners, corners_touched, edge_decided, tangent_edges

__all__ = ["MorphContext"]

#: Reduced fits kept per face (:meth:`MorphContext.fit_face`): its plain fit and its fit at anchored corners, on
#: the part and on a refinement trial's; the older ones go while a face's kept factors hold more than
#: ``_PROBLEM_BYTES`` (the newest always stays, as one fit of a face was kept before the others were).
_PROBLEMS_KEPT, _PROBLEM_BYTES = 4, 16 * 2 ** 20


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
    distances : FieldDistance, how far fits are from the field (cached; G1 and G2 ask for a face's plain fit
        against every trial).
    strain : float, the field's largest strain (:class:`~hot2cold.pipeline.checks.FieldScale`): a kink the
        morph adds counts beyond :data:`~hot2cold.pipeline.g1.KINK_NOISE_DEG` plus twice this times the hot
        angle (what the field itself does to an angle that is not quite zero when hot).
    noise : float, the scatter (mm per component) the fits smooth away
        (:func:`~hot2cold.pipeline.morph.smoothing_noise`).
    """

    part: Part
    classification: Classification
    field: DisplacementField
    vertex_displacements: np.ndarray
    estimator: FieldEstimator
    settings: Settings
    projector: Projector
    tangent: list[TangentEdge]
    distances: FieldDistance
    strain: float = 0.0
    noise: float = 0.0
    #: The last fits of each face on a tangent edge, their rows reduced (face -> its edges' morphed curves'
    #: digests -> (its face and edges, its FaceProblem); :data:`_PROBLEMS_KEPT` and :data:`_PROBLEM_BYTES` a
    #: face): G1 and G2 fit such a face again and again with other turning and bending rows only.
    _problems: dict = dataclass_field(default_factory=dict, init=False, repr=False)

    @classmethod
    def of(cls, part: Part, classification: Classification, field: DisplacementField, settings: Settings,
           projector: Projector) -> MorphContext:
        """The context of a classified field: the vertex displacements (eq. 10) from the nodes on or near
        the vertices, an estimator over the used nodes' foot points, the tangent edges; no strain and no
        smoothing (``dataclasses.replace`` sets them)."""
        used = classification.used
        estimator = FieldEstimator(classification.foot[used], field.displacements[used],
                                   settings.vertex_neighbours)
        vertex_disp = vertex_displacements(part, classification, field, estimator)
        tangent = [] if settings.g1_angle is None else tangent_edges(part, settings.g1_angle)
        distances = FieldDistance(part, classification, field, settings.tolerance, settings.threads)
        return cls(part, classification, field, vertex_disp, estimator, settings, projector, tangent, distances)

    def with_part(self, part: Part) -> MorphContext:
        """This context on ``part`` (a refined part: the same faces, edges and parameters), its fits' caches
        shared: their keys hold the faces, edges, morphs, surfaces and grids they were made for, so an entry
        is found only for those (G1 reduces the rows of the refinement's last fits once)."""
        other = replace(self, part=part, distances=self.distances.on(part))
        object.__setattr__(other, "_problems", self._problems)
        return other

    def trimmed_away(self, k: int, uv: np.ndarray) -> np.ndarray:
        """``(m,)`` bool: which of the parameters ``uv (m, 2)`` lie outside face ``k``'s trimmed domain."""
        return self.projector.classify(k, uv) == Trim.OUTSIDE

    @property
    def fit_inputs(self) -> FitInputs:
        """What every edge and face fit reads of this context (:class:`~hot2cold.pipeline.fit_inputs.FitInputs`)."""
        return FitInputs(self.classification, self.field, self.vertex_displacements, self.estimator, self.settings,
                         self.trimmed_away, self.noise)

    def fit_edges(self) -> tuple[list[EdgeMorph], list[CornerReport]]:
        """Every edge morphed (eq. 10-20), and at the ends of tangent edges given one tangent plane per corner
        (paper section 5); returns the edge morphs and the corner reports."""
        edge_morphs = morph_edges(self.part, self.fit_inputs)
        if not self.tangent:
            return edge_morphs, []
        curves, corners = correct_corners(self.part, [e.curve for e in edge_morphs], self.tangent,
                                          decided=edge_decided(self.part), strain=self.strain)
        return [replace(e, curve=c) for e, c in zip(edge_morphs, curves)], corners

    def fit_faces(self, edge_morphs: list[EdgeMorph], progress: Callable[[int, int], None] | None = None
                  ) -> list[FaceMorph]:
        """Every face morphed against the morphed edges (eq. 23-38, artificial nodes eq. 39)."""
        return morph_faces(self.part, edge_morphs, self.fit_inputs, progress)

    def fit_face(self, part: Part, face: Face, edge_morphs: list[EdgeMorph], turn: tuple | None = None
                 ) -> FaceMorph:
        """One face of ``part`` (this context's part, or a refined one) morphed against ``edge_morphs``
        (eq. 23-38); :func:`~hot2cold.pipeline.refine.refine`'s ``fit_face``; ``turn``: rows that turn it
        along trimming curves (:func:`~hot2cold.pipeline.g1.turn_rows`).  A face on a tangent edge keeps its
        rows reduced (:func:`~hot2cold.pipeline.face_fit.face_problem`) while it, its edges and their morphs
        stay the same: G1 and G2 fit it again with other turning or bending rows only, at the cost of those
        rows."""
        if not any(face.index in te.faces for te in self.tangent):
            return morph_face(face, part, edge_morphs, self.fit_inputs, turn)
        # what the fit reads besides the context: the face and its edges (objects, compared by identity: a
        # refined part's are new objects) and their morphed curves (by content: G1's refinement trials anchor
        # the corners of the plain fits again, into the same curves as other objects)
        basis = (face, *(part.edges[u.edge] for u in face.uses))
        curves = tuple(b"" if (curve := edge_morphs[u.edge].curve) is None else curve.digest() for u in face.uses)
        kept = self._problems.setdefault(face.index, {})
        found = kept.get(curves)
        if found is None or len(found[0]) != len(basis) or any(a is not b for a, b in zip(found[0], basis)):
            found = kept[curves] = basis, face_problem(face, part, edge_morphs, self.fit_inputs, reduce=True)
            while len(kept) > 1 and (len(kept) > _PROBLEMS_KEPT or _factor_bytes(kept) > _PROBLEM_BYTES):
                del kept[next(iter(kept))]          # the oldest
        return solve_face(found[1], self.settings, self.noise, turn)

    def refit_faces(self, faces: list[int], edge_morphs: list[EdgeMorph], turns: list[tuple | None] | None = None
                    ) -> list[FaceMorph]:
        """:meth:`fit_face` of each of ``faces`` (indices into ``part.faces``), with the ``turns`` given per
        face, in up to ``settings.threads`` threads."""
        part = self.part
        turns = [None] * len(faces) if turns is None else turns
        nodes = self.classification.counts(Role.FACE, len(part.faces))
        return map_threads(lambda job: self.fit_face(part, part.faces[job[0]], edge_morphs, job[1]),
                           list(zip(faces, turns)), self.settings.threads, cost=nodes[faces])

    def refit_edges(self, part: Part, edge_morphs: list[EdgeMorph], refined: set[int]) -> list[EdgeMorph]:
        """The edges in ``refined`` of the refined ``part`` morphed again (eq. 10-20) and the corners of
        tangent edges they touch put right again (:func:`~hot2cold.pipeline.g1.corners_touched`; the others
        keep their curves); returns every edge's morph (:func:`~hot2cold.pipeline.refine.refine`'s
        ``fit_edges``)."""
        inputs = self.fit_inputs
        edge_morphs = list(edge_morphs)
        for e in refined:
            edge_morphs[e] = fit_edge(part, part.edges[e], inputs)
        if self.tangent and refined:
            curves = [m.curve for m in edge_morphs]
            curves, _ = correct_corners(part, curves, self.tangent, decided=edge_decided(part), strain=self.strain,
                                        vertices=corners_touched(part, curves, refined))
            edge_morphs = [m if m.curve is c else replace(m, curve=c) for m, c in zip(edge_morphs, curves)]
        return edge_morphs


def _factor_bytes(kept: dict) -> int:
    """The bytes of the reduced rows' factors among the fits ``kept`` of one face (:meth:`MorphContext.fit_face`)."""
    return sum(problem.rows.factor.nbytes for _, problem in kept.values() if isinstance(problem.rows, ReducedRows))
