"""Checks on the way through the morph: the hot part and the field on entry, the cold part after the sew.

* :func:`check_hot`: the hot part is a valid closed solid (else :class:`InputError` naming the face at fault);
* :func:`check_positions`, before the nodes are classified: the field's positions are the hot part's, not
  the cold part's (else :class:`FieldError` naming the mix-up of hot and cold);
* :func:`check_coverage`: the field lies on the part, in the part's units, and covers every face (else
  :class:`FieldError`, or a warning with ``Settings.extrapolate``); more nodes outside the part than a few is
  warned about;
* :func:`check_coverage` also refuses a field whose displacements are of the part's size
  (``Settings.max_displacement_rel``);
* :func:`check_cold`: no cold face folded over, no solid turned inside out or crossing itself, no face moved
  farther than the field moves its nodes or away from the field between them, no volume changed beyond what
  the field's strain allows (:class:`FieldScale`);
* :func:`~hot2cold.pipeline.result.check_result`: refuses a result that failed any of them or that the kernel
  finds invalid or open (:class:`MorphError`); :func:`~hot2cold.pipeline.morph.morph` calls it (unless
  ``check=False``) and so does :meth:`~hot2cold.pipeline.result.MorphResult.write_step` before it writes.
"""
from __future__ import annotations

import itertools
import logging
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from ..core.trees import kd_tree, query
from ..core.bspline import (NORMAL_RTOL, cross, evaluate_surface, surface_basis,
                            surface_derivative_bases)
from ..core.footpoint import project_to_surface, surface_distances
from ..errors import FieldError, InputError, KernelError
from .classify import Starts, curve_length, part_distances
from .face_fit import FaceMorph
from .grids import CHECK_SPACING, FaceGrid
from ..io.field import DisplacementField
from ..kernel.validity import SolidCheck, face_areas, self_intersections, with_volumes
from ..core.model import Classification, Part, Role
from ..kernel.project import Projector
from ..kernel.rebuild import ColdKernel
from ..kernel.tessellate import tessellate
from ..kernel.topology import broken_solid, solid_fault
from ..settings import Settings, option

if TYPE_CHECKING:
    pass

log = logging.getLogger(__name__)


def check_hot(part: Part, hot_checks: list[SolidCheck]) -> None:
    """Refuse a hot part that is no closed solid, or that the kernel finds invalid as given, naming the solid,
    the face, its surface type, a point on it and what BRepCheck says (:class:`InputError`); and one valid as
    given that the B-spline conversion broke, naming the face likewise (:class:`KernelError`).  ``hot_checks``
    holds one :class:`SolidCheck` per solid of the converted part (``part.kernel.hot``): its BRepCheck is the
    one run on the converted part."""
    for s, check in enumerate(hot_checks):
        if check.free_edges:
            raise InputError(
                f"hot solid {s} is not closed: {check.free_edges} of its edges bound only one face (an open shell, "
                f"a missing or unsewn face); hot2cold morphs closed solids: sew or repair the part in CAD")
    broken = broken_solid(part.kernel.source)
    if broken:
        raise InputError(f"{broken}; repair the part in CAD")
    for s, check in enumerate(hot_checks):      # valid as given, invalid as converted: the conversion broke it
        if not check.valid:
            raise KernelError(f"B-spline conversion made solid {s} invalid: {solid_fault(part.kernel.hot, s)}")


#: Length ratios (field extent / part extent) that betray a unit mix-up, and what to tell the user of a text
#: table (:func:`_unit_hint` says it for the other files).
_UNIT_HINTS = ((1e-3, f"the field looks like metres: use {option('field_units', 'm')}"),
               (1 / 25.4, "the field looks like inches: convert it to mm"),
               (1e3, "the field is 1000 times larger than the part: is the part in metres or the field in µm?"),
               (25.4, "the field is 25.4 times larger than the part: is the part modelled in inches but written "
                      "as mm?"))
#: A ratio within this share of a unit factor is taken for that factor: a field over the whole part spans a
#: little less than the part's bounding box (which the kernel takes from the B-spline poles), and one that spans
#: a twentieth of it is not in inches but off the part.
_UNIT_MATCH = 0.1


def _file_kind(source: str | None) -> str:
    """What a field was read from, by its name: ``text`` (a table, whose columns can be written again),
    ``npz``, ``rst`` (an ANSYS result, which states its unit system), ``solver`` (other solver results) or
    ``other`` (a mesh file, arrays)."""
    suffix = os.path.splitext(str(source or "").lower())[1]
    kinds = {".csv": "text", ".txt": "text", ".dat": "text", ".tsv": "text", ".npz": "npz", ".rst": "rst",
             ".rth": "rst", ".frd": "solver", ".op2": "solver", ".pch": "solver", ".punch": "solver"}
    return kinds.get(suffix, "other")


def _unit_hint(factor: float, kind: str) -> str:
    """What to tell the user of a field of ``kind`` (:func:`_file_kind`) whose extent is ``factor`` times the
    part's: a solver's results cannot be converted by hand, and ``--field-units`` takes mm and m only."""
    text = dict(_UNIT_HINTS)[factor]
    if kind == "text" or factor > 1:
        return text
    if factor == 1e-3:
        if kind == "rst":
            return (f"the field looks like metres: use {option('field_units', 'm')} where the .rst "
                    "states no length unit; where it states one, the model's unit system (/UNITS) is not the one "
                    "its numbers are in")
        return f"the field looks like metres: use {option('field_units', 'm')}"
    if kind == "npz":
        return (f"the field looks like inches, which {option('field_units')} (mm or m) does not take: save its "
                "points and "
                "displacements in mm")
    return (f"the field looks like inches, which {option('field_units')} (mm or m) does not take: export its "
            "nodes and "
            "displacements as a CSV whose column headers state the unit, e.g. 'x (in)'"
            + (", or give the model the inch unit system (/UNITS,BIN), which the .rst then states" if kind == "rst"
               else ""))


#: Nodes of a field sampled (seeded: the same ones every run) where the checks before the morph ask where
#: the nodes lie.
_SAMPLE = 2000
#: A point lies on the part rather than another where it is this many times nearer to it, and within this
#: share of the node distance.
_NEARER, _ON_SHARE = 10.0, 0.1
#: Distances below this share of the part's diagonal are rounding (a node on a face): nothing is nearer.
_ROUNDING = 1e-6
#: Hot and cold are mixed up where the nodes moved by their displacements (or against them) lie on the part
#: rather than where they are for this share of the sampled nodes at least, and ``_MIXED_LEAST`` of them, and
#: for ``_MIXED_ODDS`` times as many as the other way round and as moved the other way.
_MIXED_SHARE, _MIXED_LEAST, _MIXED_ODDS = 0.05, 10, 4


def _percent(share: float) -> str:
    """``share`` (0 to 1) in whole per cent, never 0 or 100 unless it is."""
    return f"{min(max(round(100 * share), 1 if share > 0 else 0), 99 if share < 1 else 100)}"


def _sample(n: int, most: int) -> np.ndarray:
    """Up to ``most`` of ``n`` rows, sorted, the same every run."""
    return np.sort(np.random.default_rng(0).choice(n, most, replace=False)) if n > most else np.arange(n)


def check_positions(part: Part, field: DisplacementField, projector: Projector, settings: Settings,
                    inverted: bool = False, starts: Starts | None = None) -> None:
    """Raise :class:`FieldError` when hot and cold are mixed up in ``field``: its nodes moved by their
    displacements (the cold part's positions given with cold-to-hot displacements), or moved against them
    (displaced positions: the cold part's, given with hot-to-cold displacements), lie on the hot part rather
    than where they are.  A hot-to-cold field has its nodes on the hot part and the moved ones off it by the
    displacement across the surface.

    On :data:`_SAMPLE` nodes at the most, before they are classified (which takes long for nodes off the part);
    a point lies on the part rather than another where it is ``_NEARER`` times nearer to it and within
    ``_ON_SHARE`` of the node distance (:func:`~hot2cold.pipeline.classify.part_distances`).  The nodes moved
    are looked at only where enough nodes lie off the part as they are given (a hot-to-cold field's lie on
    it): no other node can lie nearer it moved.  ``inverted``: the
    field is a cold-to-hot one, inverted (``--invert``), whose displacements are about the given ones negated;
    the message speaks of the field as given.  ``starts``: Newton's starts on the part's faces
    (:class:`~hot2cold.pipeline.classify.Starts`, kept for the classification), None: made here.
    """
    rows = _sample(len(field), _SAMPLE)
    m = len(rows)
    if m < _MIXED_LEAST:
        return
    points, moves = field.points[rows], field.displacements[rows]
    rounding = _ROUNDING * part.diagonal
    if not np.any(np.linalg.norm(moves, axis=1) > _NEARER * rounding):
        return              # moved or not, the nodes lie where they lie: nothing to tell
    node_distance = settings.lengths(part.diagonal)[0]
    given = part_distances(part, points, projector, node_distance, settings.threads, starts, asked=3 * m)
    here = np.maximum(given, rounding)
    # a node lies nearer the part moved than where it is only where it lies more than _NEARER times the rounding
    # off the part as given (no point comes nearer than the rounding): with too few such nodes, the nodes moved
    # need not be looked at
    off = int(np.count_nonzero(here > _NEARER * rounding))
    if off < max(_MIXED_LEAST, _MIXED_SHARE * m):
        log.debug("of %d nodes sampled, %d lie off the part as given: hot and cold are not mixed up", m, off)
        return
    moved = part_distances(part, np.concatenate([points + moves, points - moves]), projector, node_distance,
                           settings.threads, starts, asked=3 * m)
    raw = np.concatenate([given[None], moved.reshape(2, m)])
    there = np.maximum(raw[1:], rounding)
    on = _ON_SHARE * node_distance
    nearer = np.sum(there * _NEARER < np.minimum(here, on), axis=1)
    farther = np.sum(here * _NEARER < np.minimum(there, on), axis=1)
    log.debug("of %d nodes sampled, moved with / against their displacements, %s lie on the part rather than "
              "where they are, %s the other way round", m, nearer.tolist(), farther.tolist())
    k = int(np.argmax(nearer))
    if nearer[k] < max(_MIXED_LEAST, _MIXED_SHARE * m) or nearer[k] < _MIXED_ODDS * max(farther[k], nearer[1 - k]):
        return
    plus = (k == 0) != inverted                      # the given positions plus the given displacements
    both = np.isfinite(raw[0]) & np.isfinite(raw[1 + k])
    medians = (f" (median distance {np.median(raw[1 + k][both]):.2g} mm against {np.median(raw[0][both]):.2g} mm)"
               if np.count_nonzero(both) >= _MIXED_LEAST else "")
    raise FieldError(
        f"{field.source or 'the field'} mixes up hot and cold: its positions {'plus' if plus else 'minus'} its "
        f"displacements lie on the hot part, its positions do not: of {m} nodes sampled, "
        f"{_percent(np.mean(np.isfinite(raw[1 + k])))} % lie within the node distance ({node_distance:.3g} mm) "
        f"of it so and {_percent(np.mean(np.isfinite(raw[0])))} % as given, {_percent(nearer[k] / m)} % are "
        f"{_NEARER:.0f} times nearer so{medians}; " + _mix_up_fix(plus, inverted, _file_kind(field.source)))


def _mix_up_fix(plus: bool, inverted: bool, kind: str) -> str:
    """What hot and cold mixed up means and how to give the field instead (:func:`check_positions`): ``plus``,
    the given positions plus the given displacements lie on the hot part (else minus); ``inverted``, the field
    was given with --invert; ``kind``, :func:`_file_kind`."""
    invert = option("invert", True)
    if plus:
        how = {"text": "write x+dx, y+dy, z+dz in its x, y, z columns and -dx, -dy, -dz in its dx, dy, dz columns",
               "npz": "save points + displacements as its points and -displacements as its displacements"}.get(
            kind, "export its nodes at x+dx, y+dy, z+dz with the displacements -dx, -dy, -dz as a CSV with the "
                  "columns x,y,z,dx,dy,dz")
        return ("the positions are the cold part's and the displacements go from cold to hot, where hot2cold takes "
                "the hot part's positions and displacements from hot to cold: " + how
                + " (the same field, seen from the hot part)"
                + (f", and drop {invert}: it takes a cold-to-hot field at the hot part's nodes, not at the cold "
                   f"part's" if inverted else
                   f"; {invert} is not for this: it takes a cold-to-hot field at the hot part's nodes"))
    how = {"text": "write x-dx, y-dy, z-dz in its x, y, z columns",
           "npz": "save points - displacements as its points"}.get(
        kind, "export the undeformed node positions, x-dx, y-dy, z-dz, as a CSV with the columns x,y,z,dx,dy,dz")
    return ("the positions are displaced ones (the cold part's, where the displacements go from hot to cold), where "
            "hot2cold takes the hot part's: " + how + ", the displacements as they are"
            + (f", and keep {invert} only if they go from cold to hot" if inverted else
               f", and give {invert} if they go from cold to hot"))


#: Nodes off the part beyond this share of the field's are looked at: are they inside the solid (volume
#: nodes) or outside it?  More outside than this share is warned about.
_OUTSIDE_SHARE = 0.05
#: Off-part nodes sampled at the most to tell inside from outside.
_OUTSIDE_SAMPLE = 500
#: Outside nodes within this many node distances of the part lie near it (a geometry a little off the part's).
_NEAR_OUTSIDE = 10.0


@dataclass(frozen=True)
class _Outside:
    """Where the nodes off the part lie: ``share``, of the field's nodes, outside every solid (farther than the
    node distance from every face); ``near``, the share of those within ``_NEAR_OUTSIDE`` node distances."""

    share: float
    near: float

    @classmethod
    def of(cls, part: Part, classification: Classification, field: DisplacementField, projector: Projector,
           threads: int = 1) -> _Outside | None:
        """Of a sample of the off-part nodes (:data:`_OUTSIDE_SAMPLE`); None where the kernel gives no
        triangles to tell inside from outside."""
        off = np.flatnonzero(~classification.used)
        if not len(off):
            return cls(0.0, 0.0)
        rows = off[_sample(len(off), _OUTSIDE_SAMPLE)]
        out = _outside(part, field.points[rows])
        if out is None:
            return None
        reach = _NEAR_OUTSIDE * classification.node_distance
        near = (np.mean(np.isfinite(part_distances(part, field.points[rows[out]], projector, reach, threads)))
                if out.any() else 0.0)
        return cls(float(np.mean(out)) * len(off) / len(classification.used), float(near))


def _outside(part: Part, points: np.ndarray) -> np.ndarray | None:
    """Which of ``points (m, 3)`` lie outside every solid of ``part``: the winding number of the solids'
    faces, triangulated to 2e-3 of the part's diagonal, about each point is below one half (right for a point
    farther from the faces than the triangles are).  None where the kernel gives no triangles."""
    try:
        mesh = tessellate(part.kernel.hot, deflection=2e-3 * part.diagonal, angle_deg=20.0)
    except KernelError as exc:
        log.debug("no inside test of the nodes off the part: %s", exc)
        return None
    in_solid = np.array([face.solid >= 0 for face in part.faces], bool)
    triangles = mesh.triangles[in_solid[mesh.face]] if len(in_solid) > mesh.face.max() else mesh.triangles
    if not len(triangles):
        return None
    corners = [mesh.vertices[triangles[:, i]] for i in range(3)]
    winding = np.zeros(len(points))
    step = max(1, 1_000_000 // len(triangles))
    for at in range(0, len(points), step):
        a, b, c = (x[None, :, :] - points[at:at + step, None, :] for x in corners)
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("ijk,ijk->ij", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("ijk,ijk->ij", a, b) * lc + np.einsum("ijk,ijk->ij", b, c) * la
               + np.einsum("ijk,ijk->ij", c, a) * lb)
        winding[at:at + step] = np.arctan2(det, den).sum(axis=1) / (2.0 * np.pi)    # solid angle / 4 pi
    return winding < 0.5


#: Faces named in a message at the most.
_NAMED = 6

#: A face without FE nodes where the node density of the faces with nodes would put at least this many is
#: not covered by the field (with fewer, it is a small face or a sparse field: its nodes are artificial).
_EXPECTED_NODES = 10
#: ... and so is one that holds at least this share of the part's surface, however sparse the field (a field
#: of a handful of nodes can leave a large face without one, and the density rule alone lets it through).
_LARGE_SHARE = 0.1


def face_coverage(part: Part, cls: Classification) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the FE nodes of ``cls`` put on each of the part's F faces: the nodes inside it (role FACE), the
    nodes on its boundary (role EDGE on its edges, VERTEX on its vertices), each ``(F,)`` int, and whether
    its boundary is covered ``(F,)`` bool: every edge of it (degenerate ones aside) carries a node, on the
    edge or at both its vertices.

    A node on a face's edge is a node of that face: the edge fit (eq. 33-37) takes it, and the face's
    boundary rows come from the morphed edges.  A vertex holds a node when one is classified to it, or when the
    foot point of an edge or vertex node lies within the edge distance of it: a node at the end of one edge is
    at the vertex of the next, and a part may hold two vertices at one point (two half-cylinders, whose
    straight seam edges a triangulation puts no node along, end at vertices that coincide with others, which
    take the nodes there).
    """
    n_faces = len(part.faces)
    inner = np.bincount(cls.owner[cls.role == Role.FACE], minlength=n_faces)
    on_edge = np.bincount(cls.owner[cls.role == Role.EDGE], minlength=len(part.edges))
    on_vertex = np.bincount(cls.owner[cls.role == Role.VERTEX], minlength=len(part.vertices))
    at_vertex = on_vertex > 0
    feet = cls.foot[(cls.role == Role.EDGE) | (cls.role == Role.VERTEX)]
    if len(feet) and len(part.vertices):
        d, _ = cKDTree(feet).query(part.vertices, distance_upper_bound=cls.edge_distance)
        at_vertex |= np.isfinite(d)
    boundary = np.zeros(n_faces, int)
    covered = np.ones(n_faces, bool)
    for edge in part.edges:
        faces = list(edge.faces)
        ends = set(edge.vertices) - {-1}
        boundary[faces] += on_edge[edge.index]
        if not edge.degenerate and not (on_edge[edge.index] or (ends and all(at_vertex[v] for v in ends))):
            covered[faces] = False
    for face in part.faces:
        vertices = {part.edges[use.edge].vertices[i] for use in face.uses for i in (0, 1)} - {-1}
        boundary[face.index] += int(sum(on_vertex[v] for v in vertices))
    return inner, boundary, covered


def check_coverage(part: Part, cls: Classification, field: DisplacementField, settings: Settings,
                   projector: Projector | None = None) -> None:
    """Raise :class:`FieldError` when the field and the part clearly disagree: no node on the part, most
    nodes off the part with a field whose extent is the part's times a unit factor (to within
    ``_UNIT_MATCH``), or faces of a solid that the field leaves bare (unless ``settings.extrapolate``: then a
    warning); the last names a field whose nodes do not lie on this part as such.  Warn where more than
    ``_OUTSIDE_SHARE`` of the nodes lie outside the part (volume nodes lie inside it).

    A face is covered when an FE node lies inside it or when every edge of its boundary carries one
    (:func:`face_coverage`: narrow faces an FE element spans, the planes of a tessellation).  A face that is
    not counts as bare where the density of the nodes used (per mm^2) would put ``_EXPECTED_NODES`` or more
    inside it (in the part of it farther than the node spacing h from its boundary: a face of area A and
    perimeter P, width w = 2A/P, expects ``density * A * (1 - h / w)``, none when w <= h), or where it holds
    ``_LARGE_SHARE`` or more of the part's surface; a face smaller than that, or a sparse field, leaves faces
    without nodes that the artificial nodes take care of (logged).

    Free faces (in no solid: construction surfaces beside a solid) are not faces of a solid: they are
    morphed with the nodes on them, and those without any are named in a warning, not refused.
    """
    extent = float(np.linalg.norm(np.ptp(field.points, axis=0))) if len(field) > 1 else 0.0
    ratio = extent / part.diagonal
    used = float(np.mean(cls.used))
    factor = next((f for f, _ in _UNIT_HINTS if abs(ratio / f - 1.0) <= _UNIT_MATCH), None)
    hint = _unit_hint(factor, _file_kind(field.source)) if factor is not None else None
    source = field.source or "the field"
    if hint and used < 0.5:
        raise FieldError(f"{source} spans {extent:.4g} mm but the part {part.diagonal:.4g} mm "
                         f"and {100 * (1 - used):.0f} % of its nodes are off the part: {hint}")
    if hint and factor < 1:
        # a field a unit factor smaller than the part cannot cover it, however many of its nodes are "on" it:
        # in metres, on a part whose face touches the origin, the nodes crowd onto the part there
        centre = field.points.mean(axis=0)
        raise FieldError(f"{source} spans {extent:.4g} mm but the part {part.diagonal:.4g} mm: its nodes crowd "
                         f"around ({', '.join(f'{x:.3g}' for x in centre)}) mm, {100 * used:.0f} % of them "
                         f"on the part there: {hint}")
    if used == 0:
        centre = part.vertices.mean(axis=0) if len(part.vertices) else np.zeros(3)
        spread = np.linalg.norm(field.points - centre, axis=1)
        if not 0.8 <= ratio <= 1.25:        # of another size than the part, and of no unit factor
            raise FieldError(
                f"no FE node of {source} lies within {cls.node_distance:.3g} mm of the part: the nodes do not lie on "
                f"this part (they are {spread.min():.4g} to {spread.max():.4g} mm from its centre; the field spans "
                f"{extent:.4g} mm, the part {part.diagonal:.4g} mm): give this part's field ({option('field')})")
        raise FieldError(
            f"no FE node of {source} lies within {cls.node_distance:.3g} mm of the part "
            f"(nodes are {spread.min():.4g} to {spread.max():.4g} mm from its centre, the part is "
            f"{part.diagonal:.4g} mm across): check the field's units ({option('field_units')}) and that it "
            f"belongs to this part, or raise {option('node_distance')}")
    _check_displacements(part, cls, field, settings)
    outside = None
    if 1.0 - used > _OUTSIDE_SHARE:
        projector = projector or Projector(part.kernel.faces, part.kernel.edges)
        outside = _Outside.of(part, cls, field, projector, settings.threads)
    foreign = ""
    if 1.0 - used > 0.5 and outside is not None and (outside.share > 0.5 or not 0.8 <= ratio <= 1.25):
        # most nodes off the part, outside it or in a field of another size than the part's: no volume nodes
        out = f"{_percent(outside.share)} % outside it; " if outside.share else ""
        foreign = (f"the nodes do not lie on this part: {_percent(1 - used)} % of them are farther than "
                   f"{cls.node_distance:.3g} mm from it ({out}the field spans {extent:.4g} mm, the part "
                   f"{part.diagonal:.4g} mm)")
    _check_faces(part, cls, field, settings, foreign)
    if outside is not None and outside.share > _OUTSIDE_SHARE:
        why = (f"most of them within {_NEAR_OUTSIDE * cls.node_distance:.3g} mm of it: the FE model's geometry is "
               f"not this part's to within the node distance (another version of the part?); check the field, or "
               f"raise {option('node_distance')} where the difference is accepted"
               if outside.near >= 0.5 else
               "nodes of other parts, or another part's field: check that the field is this part's")
        log.warning("%s: %s %% of its nodes lie outside the part, farther than %.3g mm from every face, more "
                    "than volume nodes explain (they lie inside it): %s; they are ignored", source,
                    _percent(outside.share), cls.node_distance, why)


def _check_faces(part: Part, cls: Classification, field: DisplacementField, settings: Settings,
                 foreign: str = "") -> None:
    """The faces of :func:`check_coverage`: :class:`FieldError` where a face of a solid gets no node (with
    ``foreign``, why the nodes do not lie on this part, the refusal says so), a warning with
    ``settings.extrapolate``."""
    source = field.source or "the field"
    inner, boundary, edges_covered = face_coverage(part, cls)
    free = np.array([face.solid < 0 for face in part.faces], bool)
    bare_free = np.flatnonzero(free & (inner + boundary == 0))
    if len(bare_free):
        log.warning("%d free face(s) beside the solid(s), in no solid, get no FE node: %s; they are morphed "
                    "from the field of the faces nearby (artificial nodes)", len(bare_free),
                    _listed([_face_at(part, k) for k in bare_free]))
    covered = (inner > 0) | edges_covered | free
    if covered.all():
        return
    areas = face_areas(part.kernel.faces)
    in_solid = ~free
    density = np.count_nonzero(cls.used) / max(float(areas[in_solid & (inner + boundary > 0)].sum()), 1e-300)
    spacing = cls.spacing()
    perimeter = np.array([sum(curve_length(part.edges[use.edge].curve) for use in face.uses
                              if not part.edges[use.edge].degenerate) for face in part.faces])
    width = 2.0 * areas / np.maximum(perimeter, 1e-300)
    expected = density * areas * np.clip(1.0 - spacing / np.maximum(width, 1e-300), 0.0, 1.0)
    large = areas >= _LARGE_SHARE * float(areas[in_solid].sum())
    sparse = np.flatnonzero(~covered & (expected < _EXPECTED_NODES) & ~large)
    if len(sparse):
        log.info("face(s) %s get no FE node (%s expected from the node density): their nodes are artificial",
                 ", ".join(map(str, sparse)), ", ".join(f"{x:.2g}" for x in expected[sparse]))
    empty = np.flatnonzero(~covered & ((expected >= _EXPECTED_NODES) | large))
    if not len(empty):
        return
    # a solid of several without a node is named as a whole, other faces one by one with a point on them
    bare = [s for s, faces in enumerate(part.solids)
            if len(part.solids) > 1 and len(faces) > 1 and set(faces) <= set(empty.tolist())]
    names = [f"solid {s} (faces {min(part.solids[s])}-{max(part.solids[s])}, "
             f"{expected[list(part.solids[s])].sum():.0f})" for s in bare]
    names += [f"{_face_at(part, k)} ({expected[k]:.0f})" for k in empty if part.faces[k].solid not in bare]
    large_too = ("" if np.all(expected[empty] >= _EXPECTED_NODES) else
                 f", or on a face that holds {100 * _LARGE_SHARE:.0f} % or more of the part's surface")
    n_solid = int(np.count_nonzero(in_solid))
    what = (f"{len(empty)} of its {n_solid} faces get{'s' if len(empty) == 1 else ''} no FE node within "
            f"{cls.node_distance:.3g} mm where the node density of the other faces "
            f"would put {_EXPECTED_NODES} or more{large_too}: {_listed(names)}")
    if settings.extrapolate:
        poles = np.concatenate([face.surface.poles.reshape(-1, 3) for face in part.faces])
        reach = cls.node_distance
        outside = np.any((field.points < poles.min(axis=0) - reach) | (field.points > poles.max(axis=0) + reach),
                         axis=1)
        share = float(np.mean(outside))
        if share > _FOREIGN_SHARE:
            raise FieldError(
                f"{source} covers only part of the solid: {what}; and {int(outside.sum())} of its {len(field)} "
                f"nodes ({100 * share:.0f} %) lie outside the part's bounding box: it looks like another part's "
                f"field, and {option('extrapolate', True)} would morph the part from the few nodes on it; "
                f"give this part's field")
        log.warning("%s covers only part of the solid: %s; they are morphed from the field of the other faces, "
                    "extrapolated (%s)", source, what, option("extrapolate", True))
        return
    if foreign:
        raise FieldError(f"{source} covers only part of the solid: {what}; {foreign}: give this part's field "
                         f"({option('field')})")
    raise FieldError(f"{source} covers only part of the solid: {what}; give a field over the whole part, or "
                     f"{option('extrapolate', True)} to morph such faces from the field of the others")


def _check_displacements(part: Part, cls: Classification, field: DisplacementField, settings: Settings) -> None:
    """Raise :class:`FieldError` when a node on the part moves farther than ``settings.max_displacement_rel``
    times the part's diagonal: a field whose displacements are of the part's size is no hot-to-cold field
    (cold positions given as displacements, another part's field, displacements in µm written as mm)."""
    moved = np.where(cls.used, np.linalg.norm(field.displacements, axis=1), -1.0)
    k = int(np.argmax(moved))
    share = moved[k] / part.diagonal
    log.info("largest displacement %.4g mm (node at row %d), %.3g %% of the part's %.4g mm diagonal", moved[k],
             cls.node[k], 100 * share, part.diagonal)
    if share <= settings.max_displacement_rel:
        return
    raise FieldError(
        f"{field.source or 'the field'} moves the node at ({', '.join(f'{x:.4g}' for x in field.points[k])}) mm "
        f"(row {cls.node[k]} from 0) by {moved[k]:.4g} mm, {100 * share:.3g} % of the part's {part.diagonal:.4g} mm "
        f"diagonal, more than the {100 * settings.max_displacement_rel:.3g} % a hot-to-cold field moves a part: "
        f"are the columns dx,dy,dz cold positions rather than displacements, or is it another part's field? "
        f"If it is right, raise {option('max_displacement_rel')}")


#: The cold part may move a face up to this many times the field's largest displacement (plus the node
#: distance): the fit of a face between its nodes overshoots a little, never by half the largest displacement.
_MOVE_MARGIN = 1.5
#: A cold solid's volume may change by up to this many times what the field's largest strain allows ...
_VOLUME_MARGIN = 3.0
#: ... plus this share of the hot volume (the fit, and the kernel's volume integration, for a field that
#: hardly strains the part: a rigid motion).
_VOLUME_FLOOR = 1e-3
#: Between the nodes a cold face may be up to ``_BETWEEN_MARGIN`` times the field's largest displacement from
#: the field's local estimate, plus ``_BETWEEN_FLOOR`` times the node distance (:attr:`FieldScale.between_bound`).
#: A face that misses the field between its nodes by a share of the displacement is inaccurate, and the report
#: says by how much: a plane kept bilinear misses a bending field by a large share of the displacement, and a
#: box's face bent by a field quadratic along it (its edges straight lines between the moved corners) by the
#: whole displacement.  A fit of displacements no larger than the field's does not go twice as far; a face that
#: does follows no field (without this bound, ``--extrapolate`` could write parts far off with exit 0).
_BETWEEN_MARGIN, _BETWEEN_FLOOR = 2.0, 1e-3
#: With ``--extrapolate``, a field that leaves faces bare and has more than this share of its nodes outside the
#: part's bounding box (enlarged by the node distance) is refused as another part's field: one part's field
#: given with another part has most of its nodes outside and only a few on it.  (A field with its volume nodes
#: has them inside; one of a whole assembly, given for one of its parts, covers that part.)
_FOREIGN_SHARE = 0.5
#: Nearest neighbours of each node whose displacements estimate the field's strain.
_STRAIN_NEIGHBOURS = 8
#: Nodes whose neighbours' differences are held at once in the strain estimate (bounds its memory).
_STRAIN_CHUNK = 65_536


@dataclass(frozen=True)
class FieldScale:
    """How far and how much the field moves and strains the part: the bounds of the checks of the cold part.

    Attributes
    ----------
    largest : float, the largest displacement (mm) of a node on the part.
    strain : float, the field's largest strain, estimated as the largest ``|Δu_i - Δu_j| / |x_i - x_j|``
        over the used nodes and their ``_STRAIN_NEIGHBOURS`` nearest neighbours (a Lipschitz constant L of
        the displacement: a map ``x + u(x)`` with it changes a volume by a factor between ``(1 - L)^3`` and
        ``(1 + L)^3``).  The tangent planes of a closed surface take every direction, so the nodes on it see
        every component of the gradient somewhere; nodes on both sides of a gap narrower than the node
        spacing make it larger, never smaller (a looser bound).
    reach : float, the node distance (mm), the slack of the move bound.
    """

    largest: float
    strain: float
    reach: float

    @classmethod
    def of(cls, classification: Classification, field: DisplacementField) -> FieldScale:
        """The scale of the nodes of ``field`` that ``classification`` uses (one row each)."""
        used = classification.used
        points, disp = field.points[used], field.displacements[used]
        largest = float(np.linalg.norm(disp, axis=1).max()) if len(disp) else 0.0
        strain = _strain(points, disp) if len(points) > 1 else 0.0
        return cls(largest, strain, classification.node_distance)

    @property
    def move_bound(self) -> float:
        """The farthest (mm) a cold face may be from the hot one: ``_MOVE_MARGIN`` x largest + reach."""
        return _MOVE_MARGIN * self.largest + self.reach

    @property
    def between_bound(self) -> float:
        """The farthest (mm) a cold face may be from the field's local estimate between the nodes:
        ``_BETWEEN_MARGIN`` x largest, plus ``_BETWEEN_FLOOR`` x reach for a field that hardly moves the part."""
        return _BETWEEN_MARGIN * self.largest + _BETWEEN_FLOOR * self.reach

    @property
    def volume_bound(self) -> float:
        """The largest ``|V_cold / V_hot - 1|`` accepted: ``_VOLUME_MARGIN ((1 + strain)^3 - 1) +
        _VOLUME_FLOOR``."""
        return _VOLUME_MARGIN * ((1.0 + self.strain) ** 3 - 1.0) + _VOLUME_FLOOR


def _strain(points: np.ndarray, disp: np.ndarray) -> float:
    """:attr:`FieldScale.strain` of the nodes ``points (n, 3)``, ``n >= 2``, moving by ``disp (n, 3)``: the largest
    ``|du| / |dx|`` to their ``_STRAIN_NEIGHBOURS`` nearest, ``_STRAIN_CHUNK`` nodes at a time."""
    k = min(_STRAIN_NEIGHBOURS, len(points) - 1) + 1
    tree = kd_tree(points)
    best, strain = -1.0, 0.0
    for start in range(0, len(points), _STRAIN_CHUNK):
        these = slice(start, start + _STRAIN_CHUNK)
        d, j = query(tree, points[these], k=k)
        d, j = d[:, 1:], j[:, 1:]
        du = disp[j] - disp[these, None, :]                                        # (c, k - 1, 3)
        # the largest ratio found on the squares (no square root per pair), then taken as it is
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.einsum("nkc,nkc->nk", du, du) / (d * d)
        ratio[d <= 0] = -1.0           # the rows of one node that feeds two solids are one point
        i, m = np.unravel_index(np.argmax(ratio), ratio.shape)
        if ratio[i, m] > best:         # the first of equal ratios, as over all nodes at once
            best = ratio[i, m]
            strain = float(np.linalg.norm(du[i, m]) / d[i, m]) if best >= 0 else 0.0
    return strain


def _face_at(part: Part, k: int) -> str:
    """``face k near (x, y, z) mm``: a point of face ``k`` at the middle of its parameter box."""
    u0, u1, v0, v1 = part.faces[k].uv_box
    at = evaluate_surface(part.faces[k].surface, [(u0 + u1) / 2], [(v0 + v1) / 2])[0]
    return f"face {k} near ({', '.join(f'{x:.4g}' for x in at)}) mm"


def _listed(names: list[str]) -> str:
    """The first ``_NAMED`` of ``names``, comma-separated, and how many more."""
    return ", ".join(names[:_NAMED]) + (f" and {len(names) - _NAMED} more" if len(names) > _NAMED else "")


@dataclass(frozen=True, eq=False)
class ColdCheck:
    """What :func:`check_cold` found.

    Attributes
    ----------
    problems : dict, per solid index the list of what is wrong with it (one sentence each); empty if nothing.
    between : (n_faces,) float array, per face the largest distance (mm) of the cold face from where the
        field's local estimate puts the points of a grid over its trimmed domain near its nodes
        (``FaceGrid.near``), less the estimate's own miss at the nearest nodes (``FaceGrid.slack``): the
        error between the nodes, as far as the nodes tell (NaN for a face without such points).  Farther
        from the nodes the estimate extrapolates (in the middle of a large plane whose nodes lie at its
        corners it is far worse than the cold face itself); there it only bounds how far a face may wander
        (``FieldScale.between_bound``).
    unmeasured : (n_faces,) float array, per face the share (0 to 1) of its grid the check does not measure
        against the tolerance (:meth:`FaceGrid.unmeasured`; NaN for an empty grid).
    uncertain : (n_faces,) float array, the share of it that is near the nodes, where the nodes do not tell
        the field to within the tolerance.
    """

    problems: dict[int, list[str]]
    between: np.ndarray
    unmeasured: np.ndarray | None = None
    uncertain: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Rebuilt:
    """A cold part as rebuilt, what :func:`check_cold` reads of it.

    Attributes
    ----------
    kernel : ColdKernel, the cold geometry in a copy of the hot part's kernel shape.
    faces : list of FaceMorph, one per face of the hot part, the cold surfaces.
    hot_checks, cold_checks : one :class:`SolidCheck` per hot and per cold solid (their volumes None where
        ``volumes`` brings them).
    volumes : the hot and the cold solids' volumes still being integrated (two
        :class:`~hot2cold.kernel.side.Volumes`), or None: the checks hold them.
    """

    kernel: ColdKernel
    faces: list[FaceMorph]
    hot_checks: list[SolidCheck]
    cold_checks: list[SolidCheck]
    volumes: tuple | None = None

    def solid_checks(self) -> tuple[list[SolidCheck], list[SolidCheck]]:
        """The hot and the cold checks with their volumes, waited for where :attr:`volumes` brings them."""
        if self.volumes is None:
            return self.hot_checks, self.cold_checks
        hot, cold = self.volumes
        return with_volumes(self.hot_checks, hot.result()), with_volumes(self.cold_checks, cold.result())


def check_cold(part: Part, rebuilt: Rebuilt, projector: Projector, scale: FieldScale, grids: list[FaceGrid],
               limit: float = np.inf) -> ColdCheck:
    """What is wrong with the cold part (the hot ``part`` ``rebuilt`` with its faces' morphs), per
    solid: turned inside out (its volume changed sign), its volume changed by more than the field's strain
    allows (``scale.volume_bound``), a face folded over (somewhere on a grid over its trimmed domain the
    normal ``S_u x S_v`` of the cold surface points against the hot one's), a face moved farther than the
    field moves any node (a point of that grid farther than ``scale.move_bound`` from its hot position), a
    face away from the field between the nodes (a point of that grid farther from the cold face than
    ``scale.between_bound`` from where the field's local estimate puts it: the nodes say where the part goes,
    and a face that wanders off between them is wrong however close it passes the nodes), or crossing itself.
    ``grids`` are the
    grids of ``part`` (:class:`FaceGridder`); ``limit`` (mm), the tolerance plus the field's scatter allowance, against
    which the share of each face's grid left unmeasured is found (:meth:`FaceGrid.unmeasured`).

    The last is the kernel's self-interference test (:func:`~hot2cold.kernel.validity.self_intersections`),
    slow on real parts, so it is run only where a gap of the part may have closed: two points of the grids
    closer than two sample spacings in the cold part that were more than twice as far apart, and a sample
    spacing farther, in the hot one.  A field moves a part as the FE solution says, and nearby points of a part
    stay about as far apart as they were; where two sides of a gap come together, their points do not.

    The volumes are asked for last (:meth:`Rebuilt.solid_checks`): a second process may integrate them while
    the grids are checked here (``Settings.kernel_process``).
    """
    found: dict[int, list[str]] = {}         # what the grids find, after what the volumes say
    spacing = CHECK_SPACING * part.diagonal
    hot_points, cold_points = [], []
    farthest = (0.0, -1)
    between = np.full(len(part.faces), np.nan)
    unmeasured, uncertain = np.full(len(part.faces), np.nan), np.full(len(part.faces), np.nan)
    for face, fm, grid in zip(part.faces, rebuilt.faces, grids):
        uv = grid.uv
        (hot, hot_n), (cold, cold_n) = _points_and_normals(face.surface, fm.surface, uv)
        hot_points.append(hot)
        cold_points.append(cold)
        if len(uv):
            off, k = _between(fm, grid.expected, uv, projector.face_box(face.index))
            if grid.near.any():
                between[face.index] = float(np.maximum(off[grid.near] - grid.slack[grid.near], 0.0).max())
            left = grid.unmeasured(off, limit)
            unmeasured[face.index] = float(np.mean(left))
            uncertain[face.index] = float(np.mean(left & grid.near))
            if off[k] > scale.between_bound:
                found.setdefault(face.solid, []).append(
                    f"leaves the field between the nodes: face {face.index} is {off[k]:.4g} mm from where the "
                    f"field's local estimate puts it near ({', '.join(f'{x:.4g}' for x in hot[k])}) mm, more "
                    f"than {_BETWEEN_MARGIN:g} x the field's largest displacement ({scale.largest:.4g} mm)")
        moves = np.linalg.norm(cold - hot, axis=1)
        farthest = max(farthest, (float(moves.max()) if len(moves) else 0.0, face.index))
        for text in _grid_problems(face, (hot, hot_n), (cold, cold_n), scale, part.diagonal):
            found.setdefault(face.solid, []).append(text)
    problems = _volume_problems(*rebuilt.solid_checks(), scale)
    for solid, texts in found.items():
        problems.setdefault(solid, []).extend(texts)
    log.info("the cold part moves face %d farthest, by %.4g mm (%.4g mm accepted: the field's largest "
             "displacement %.4g mm)", farthest[1], farthest[0], scale.move_bound, scale.largest)
    closing = closing_pairs(np.concatenate(hot_points), np.concatenate(cold_points), spacing)
    if closing:
        log.info("%d pairs of points came closer than half their hot distance: checking the cold part for "
                 "self-intersection", closing)
        _check_crossing(part, rebuilt.kernel, problems)
    if np.isfinite(between).any():
        k = int(np.nanargmax(between))
        log.info("between the nodes the cold part is at most %.3g mm (face %d) from the field's local estimate",
                 between[k], k)
    for s in sorted(problems):
        for text in problems[s]:
            log.warning("cold solid %d %s", s, text)
    if np.nansum(uncertain) > 0:
        k = int(np.nanargmax(uncertain))
        log.info("between the nodes of %d face(s) the field's estimate may be off by more than the tolerance "
                 "allows: unmeasured there (most on face %d, %.2g %% of it)", int(np.sum(uncertain > 0)), k,
                 100 * uncertain[k])
    return ColdCheck(problems, between, unmeasured, uncertain)

def _volume_problems(hot_checks: list[SolidCheck], cold_checks: list[SolidCheck], scale: FieldScale
                     ) -> dict[int, list[str]]:
    """Per solid, what its volume says: turned inside out, or changed by more than the field's strain allows."""
    problems: dict[int, list[str]] = {}
    for s, (hot, cold) in enumerate(zip(hot_checks, cold_checks)):
        if hot.volume > 0 and not cold.volume > 0:
            problems.setdefault(s, []).append(
                f"is turned inside out (volume hot {hot.volume:.6g} mm³, cold {cold.volume:.6g} mm³)")
        elif hot.volume > 0:
            change = cold.volume / hot.volume - 1.0
            log.info("solid %d: volume hot %.6g mm³, cold %.6g mm³ (%+.3g %%; %.3g %% allowed by the field's "
                     "largest strain %.3g)", s, hot.volume, cold.volume, 100 * change, 100 * scale.volume_bound,
                     scale.strain)
            if abs(change) > scale.volume_bound:
                problems.setdefault(s, []).append(
                    f"changes its volume from {hot.volume:.6g} mm³ to {cold.volume:.6g} mm³ ({100 * change:+.3g} %), "
                    f"more than the {100 * scale.volume_bound:.3g} % the field's largest strain "
                    f"({scale.strain:.3g}) allows")
    return problems


def _grid_problems(face, hot_grid: tuple[np.ndarray, np.ndarray], cold_grid: tuple[np.ndarray, np.ndarray],
                   scale: FieldScale, diagonal: float) -> list[str]:
    """What the grid points of ``face``, hot and cold, say (each a pair of points and normals, ``(m, 3)``): the
    face moved farther than the field moves any node, or folded over (a cold normal against the hot one)."""
    (hot, hot_n), (cold, cold_n) = hot_grid, cold_grid
    problems = []
    over = np.flatnonzero(np.einsum("ij,ij->i", hot_n, cold_n) < 0)    # NaN (no normal) compares False
    moves = np.linalg.norm(cold - hot, axis=1)
    if len(moves) and moves.max() > scale.move_bound:
        k = int(np.argmax(moves))
        problems.append(
            f"moves face {face.index} by up to {moves[k]:.4g} mm near "
            f"({', '.join(f'{x:.4g}' for x in hot[k])}) mm, farther than the field moves any node "
            f"({scale.largest:.4g} mm; up to {_MOVE_MARGIN:g} x that + {scale.reach:.3g} mm accepted)")
    if len(over):
        k = over[0]
        problems.append(
            f"folds: face {face.index} turns over at {len(over)} of {len(hot)} points, e.g. near "
            f"({', '.join(f'{x:.4g}' for x in hot[k])}) mm, the field moving it by up to {moves.max():.3g} mm "
            f"(the part is {diagonal:.4g} mm across)")
    return problems


def _between(fm: FaceMorph, expected: np.ndarray, uv: np.ndarray, box: np.ndarray) -> tuple[np.ndarray, int]:
    """Distances ``(m,)`` (mm) of the estimated cold positions ``expected (m, 3)`` of the grid points at
    ``uv (m, 2)`` to the cold face, and the index of the largest.  Foot points by Newton's method from ``uv``
    within ``box``; where that does not settle, the smallest distance met by Gauss-Newton steps from ``uv``,
    from the tangent plane where the point has slid past the box's border
    (:func:`~hot2cold.core.footpoint.surface_distances`; the distance to the cold point at the same parameters
    reads the slide along the face, many times the true distance, wherever the face's parameters slid)."""
    fp = project_to_surface(fm.surface, expected, uv, box)
    off = fp.distance.copy()
    if not fp.settled.all():
        rest = ~fp.settled
        off[rest] = surface_distances(fm.surface, expected[rest], uv[rest], box, past_border=True)
    return off, int(np.argmax(off))


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
        normal = cross(su, sv)
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


#: :func:`closing_pairs` takes one point for all points within this share of the spacing of each other, hot
#: and cold.
_SAME_SHARE = 1 / 8


def closing_pairs(hot: np.ndarray, cold: np.ndarray, spacing: float) -> int:
    """How many pairs of the points ``hot (m, 3)``, moved to ``cold (m, 3)``, are less than ``2 spacing`` apart
    cold and were more than twice as far apart, and ``spacing`` farther, hot (``d_hot > 2 d_cold + spacing``):
    where a gap of the part may have closed.  0 means none.

    Points less than ``eps = _SAME_SHARE x spacing`` from another one both hot and cold count as one: a small
    face's grid (at least ``degree + 1`` points a knot span whatever its size) puts hundreds of points within
    reach of each other, and their pairs grew with the square of its points.
    Pairs of the points kept are counted with the margins widened by ``eps`` on each point (either distance
    changes by up to ``2 eps``: ``d_hot > 2 d_cold + spacing - 6 eps`` within ``2 spacing + 2 eps``), so a pair
    of the whole set that qualifies has a pair of kept points that does: the count may grow, a closing gap is
    not missed.  Pairs are listed only among the points :func:`_may_close` finds may be in one (none, most times:
    a smooth field's moves differ too little over the reach)."""
    eps = _SAME_SHARE * spacing
    cell = eps / np.sqrt(3.0)                                # one cell: within eps of each other hot and cold
    keys = np.floor(np.column_stack([hot, cold]) / cell).astype(np.int64)
    keep = np.unique(keys, axis=0, return_index=True)[1]
    hot, cold = hot[keep], cold[keep]
    reach, margin = 2.0 * spacing + 2.0 * eps, spacing - 6.0 * eps
    if margin > 0.0 and len(cold) > 1:
        may = _may_close(cold, cold - hot, reach, margin)
        hot, cold = hot[may], cold[may]
    pairs = cKDTree(cold).query_pairs(reach, output_type="ndarray")
    if not len(pairs):
        return 0
    if margin > 0.0:                # d_hot > 2 d_cold + margin needs d_hot^2 > 4 d_cold^2 + margin^2: no root for most
        dh, dc = hot[pairs[:, 0]] - hot[pairs[:, 1]], cold[pairs[:, 0]] - cold[pairs[:, 1]]
        pairs = pairs[np.einsum("ij,ij->i", dh, dh) > 4.0 * np.einsum("ij,ij->i", dc, dc) + margin * margin]
    d_hot = np.linalg.norm(hot[pairs[:, 0]] - hot[pairs[:, 1]], axis=1)
    d_cold = np.linalg.norm(cold[pairs[:, 0]] - cold[pairs[:, 1]], axis=1)
    return int(np.count_nonzero(d_hot > 2.0 * d_cold + margin))


def _may_close(cold: np.ndarray, moves: np.ndarray, reach: float, margin: float) -> np.ndarray:
    """``(m,)`` bool: the points of ``cold (m, 3)``, moved by ``moves (m, 3)`` from hot, that may be in a pair less
    than ``reach`` apart cold with ``d_hot > 2 d_cold + margin`` (``margin > 0``), a necessary condition checked
    cell by cell so that the pairs of the others are never listed.

    With the moves split into an affine part and the rest, ``m = A x + c + r`` (``x`` cold, ``A`` the least-squares
    fit over all points, taken where its 2-norm is below 1, else ``A = 0``): ``d_hot <= d_cold + |m_i - m_j|`` and
    ``|m_i - m_j| <= |A| d_cold + |r_i - r_j|``, so such a pair has ``|r_i - r_j| > (1 - |A|) d_cold + margin``,
    more than ``margin``.  Its points lie in the same or neighbouring cubes of side ``reach`` (cold), and the
    diagonal of the box of two cubes' ``r`` bounds how much any two of them differ: only points of cubes with a
    neighbour (or themselves) whose joint box is wider than ``margin`` are kept.  What the affine part leaves of
    a smooth field (its rotation and strain, which turn a blade by degrees) differs far less than ``margin`` over
    two cubes, so most parts keep few points or none."""
    centre = cold.mean(axis=0)
    design = np.column_stack([cold - centre, np.ones(len(cold))])
    fit = np.linalg.lstsq(design, moves, rcond=None)[0]                      # (4, 3)
    rest = moves - design @ fit if np.linalg.norm(fit[:3], 2) < 1.0 else moves
    keys = np.floor(cold / reach).astype(np.int64)
    keys -= keys.min(axis=0) - 1                             # from 1, so that every neighbour's key is >= 0
    size = keys.max(axis=0) + 2
    codes = (keys[:, 0] * size[1] + keys[:, 1]) * size[2] + keys[:, 2]
    cells, of = np.unique(codes, return_inverse=True)
    order = np.argsort(of, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(of[order]) != 0])
    low = np.minimum.reduceat(rest[order], starts, axis=0)   # (cells, 3): the box of each cube's r
    high = np.maximum.reduceat(rest[order], starts, axis=0)
    wide = np.zeros(len(cells), bool)
    limit = margin * margin * (1.0 - 1e-9)                   # (rounding may keep more, never fewer)
    for di, dj, dk in itertools.product((-1, 0, 1), repeat=3):           # the cube itself and its 26 neighbours
        wanted = cells + (di * size[1] + dj) * size[2] + dk
        there = np.minimum(np.searchsorted(cells, wanted), len(cells) - 1)
        found = np.flatnonzero(cells[there] == wanted)
        span = np.maximum(high[found], high[there[found]]) - np.minimum(low[found], low[there[found]])
        wide[found[np.einsum("ij,ij->i", span, span) > limit]] = True
    return wide[of]


def _check_crossing(part: Part, cold_kernel: ColdKernel, problems: dict[int, list[str]]) -> None:
    """Add to ``problems`` the crossings the kernel finds in the cold part and not in the hot one (where the
    hot part has them too, e.g. two solids of an assembly that touch, they are the input's: a warning)."""
    touch = 1e-6 * part.diagonal
    found = self_intersections(cold_kernel.shape, touch)
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
