"""Accuracy and the report (eq. 21-22; METHOD step 8).

The fit residual is not the error: each cold target point ``d_k = S(u_k, v_k) + dd_k`` (eq. 5, 28) is
projected onto the *morphed* face or edge it belongs to, and the distance of that projection is the error
``Delta_k`` of eq. (21); ``Delta_max`` and ``Delta_mean`` (eq. 22) are reported per face and per edge.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from enum import Enum
from typing import Protocol

import numpy as np

from .edge_fit import EdgeMorph
from .face_fit import FaceMorph
from ..io.field import DisplacementField
from ..core.footpoint import curve_distances, project_to_curve, project_to_surface
from ..kernel.validity import SolidCheck, face_areas
from ..kernel.project import Projector
from ..core.model import Classification, Part, Role
from ..core.threads import map_threads
from ..settings import Settings, option
from .grids import GRID_REACH


class Morphed(Protocol):
    """What :func:`build_report` reads of a morph (:class:`~hot2cold.pipeline.context.MorphContext` has it): the
    (refined) part, the classification of the field's nodes, the field and the settings."""

    part: Part
    classification: Classification
    field: DisplacementField
    settings: Settings


@dataclass(frozen=True)
class FaceReport:
    """One face: FE nodes, control net, errors (mm), and how the fit went.

    ``delta_max`` and ``delta_mean`` are the errors at the face's nodes (eq. 21-22); ``delta_between`` is the
    largest distance of the cold face from the field's local estimate on a grid over its trimmed domain, the
    error between the nodes as far as the nodes tell (:func:`~.checks.check_cold`).  ``unsupported`` is the
    share (0 to 1) of that grid the check does not vouch for (:meth:`~.checks.FaceGrid.unmeasured`): farther
    than :data:`~.checks.GRID_REACH` node spacings (theirs or all nodes', the larger: ``FaceGrid.support``)
    from the nodes of the face, its edges and vertices, where nothing measures the face (its shape there
    comes from its edges and the field's estimate), or near them where the cold face with the estimate's
    doubt may be beyond the limit; ``farthest_node`` the largest distance to a node (mm); NaN where not
    checked.  ``name``: the face's name in the hot
    STEP, else one from its surface kind and place (:meth:`~hot2cold.core.model.Part.face_title`).  ``area``:
    the hot face's trimmed area (mm²; NaN where not known), what weighs ``unsupported`` in the share of the
    part's area measured (:attr:`Verdict.measured`)."""

    index: int
    solid: int
    nodes: int
    control_points: str
    delta_max: float
    delta_mean: float
    unknowns: int
    rank: int
    condition: float
    tied_sides: list[str]
    edge_rows: int
    artificial_nodes: int
    delta_between: float = float("nan")
    unsupported: float = float("nan")
    farthest_node: float = float("nan")
    name: str = ""
    area: float = float("nan")


#: A face is named as not told by its nodes when more than this share of its grid lies out of their reach.
UNSUPPORTED_SHARE = 0.1


@dataclass(frozen=True)
class EdgeReport:
    """One edge: FE nodes, control points, errors (mm), and the gap to its faces (mm)."""

    index: int
    faces: list[int]
    nodes: int
    control_points: int
    delta_max: float
    delta_mean: float
    gap: float
    artificial_nodes: int


@dataclass(frozen=True)
class SolidReport:
    """One solid: kernel validity, free edges, face count, volumes hot and cold (mm^3) and its name in the
    hot STEP ("" where it had none)."""

    index: int
    faces: int
    valid: bool
    free_edges: int
    volume_hot: float
    volume_cold: float
    name: str = ""

    @property
    def closed(self) -> bool:
        return self.free_edges == 0


class VerdictState(Enum):
    """What a morph's verdict says of the tolerance: ``MET`` (at every node and between them where measured,
    and the part measured all over: no face more than :data:`UNSUPPORTED_SHARE` unmeasured,
    :attr:`FaceReport.unsupported`), ``PARTLY_MEASURED`` (met where measured, but some face more than that
    unmeasured: nothing says how far the part is off there), ``NOT_MET`` (:attr:`Report.tolerance_met` False:
    exit code 5) and ``NO_TOLERANCE`` (none was set).  The value is the word the report shows."""

    MET = "met"
    PARTLY_MEASURED = "partly measured"
    NOT_MET = "NOT met"
    NO_TOLERANCE = "no tolerance"

    @property
    def words(self) -> str:
        """How the verdict's sentence says it after the tolerance."""
        return {VerdictState.PARTLY_MEASURED: "met where measured, PARTLY measured",
                VerdictState.NO_TOLERANCE: "no tolerance set"}.get(self, self.value)

    @property
    def tone(self) -> Tone:
        """How a view colours it: only a met, fully measured part is good (green)."""
        return {VerdictState.MET: Tone.GOOD, VerdictState.PARTLY_MEASURED: Tone.WARNING,
                VerdictState.NOT_MET: Tone.BAD, VerdictState.NO_TOLERANCE: Tone.NEUTRAL}[self]


class Tone(Enum):
    """The role of a verdict's colour in a view: green, amber, red, or none."""

    GOOD = "good"
    WARNING = "warning"
    BAD = "bad"
    NEUTRAL = "neutral"


class Feature(Enum):
    """What kind of place of the part an error is found at."""

    FACE = "face"
    EDGE = "edge"
    VERTEX = "vertex"


@dataclass(frozen=True)
class Place:
    """A face, an edge or a vertex of the part (``index`` None: one not named, as the vertices' largest error
    is reported over all of them)."""

    feature: Feature
    index: int | None = None

    def __str__(self) -> str:
        return f"{self.feature.value} {self.index}" if self.index is not None else f"a {self.feature.value}"


@dataclass(frozen=True)
class Verdict:
    """The one verdict of a morph, as the command's first line, the HTML page's header and the JSON's
    ``verdict`` give it (:attr:`Report.verdict`).

    ``state``: :class:`VerdictState`; ``tolerance`` and ``limit`` (the tolerance plus the field's scatter
    allowance), mm, None when no tolerance was set; ``at_nodes``: the largest error at the nodes (mm, eq. 21:
    face, edge and vertex nodes; NaN where no node is used) and ``at_nodes_where`` its place;
    ``between``: the largest error found between the nodes (mm: the cold faces against the field's local
    estimate on a grid over every face, and what the refinement measured there on faces and edges their nodes
    do not determine; NaN where nothing was measured) and ``between_where``, the largest of those the tolerance
    counts or within its limit (:meth:`Report._between_figures`); ``uncounted`` and ``uncounted_where``: a
    larger one beyond the limit that the tolerance does not count (the cold check's grid against the field's
    local estimate; NaN and None where there is none); ``measured``: the share (0 to 1) of the part's area
    measured (1 less the area-weighted :attr:`FaceReport.unsupported`; None where not checked);
    ``unmeasured_faces``: the faces :meth:`Report.unsupported_faces` names, most unmeasured first;
    ``text``: all of it in one sentence."""

    state: VerdictState
    tolerance: float | None
    limit: float | None
    at_nodes: float
    at_nodes_where: Place | None
    between: float
    between_where: Place | None
    uncounted: float
    uncounted_where: Place | None
    measured: float | None
    unmeasured_faces: tuple[int, ...]
    text: str

    @property
    def tone(self) -> Tone:
        return self.state.tone

    @property
    def measured_text(self) -> str:
        """:attr:`measured` as the report writes it: "97 %", never rounded up to "100 %"; "not checked"."""
        return "not checked" if self.measured is None else _percent(self.measured)

    def to_dict(self) -> dict:
        """JSON-ready (NaN as null); the sentence first."""
        return _no_nan({"text": self.text, "state": self.state.value, "tolerance": self.tolerance,
                        "limit": self.limit, "at_nodes": self.at_nodes,
                        "at_nodes_where": None if self.at_nodes_where is None else str(self.at_nodes_where),
                        "between": self.between,
                        "between_where": None if self.between_where is None else str(self.between_where),
                        "uncounted": self.uncounted,
                        "uncounted_where": None if self.uncounted_where is None else str(self.uncounted_where),
                        "measured": self.measured, "unmeasured_faces": list(self.unmeasured_faces)})


def _mm(x: float) -> str:
    return f"{x:.3g} mm"


def _percent(share: float, up: bool = False) -> str:
    """A share as a percentage never rounded to "100 %" or "0 %" unless it is all or nothing: rounded down
    (a share measured: never more than there is), or ``up`` (a share unmeasured: never less)."""
    p = 100.0 * share
    if p >= 100.0:
        return "100 %"
    if p <= 0.0:
        return "0 %"
    if p < 0.1 and not up:
        return "under 0.1 %"
    step = 0.1 if p < 1.0 or p >= 99.0 else 1.0
    cut = (math.ceil if up else math.floor)(p / step - (1e-9 if up else -1e-9)) * step
    cut = min(max(cut, 0.1), 99.9)
    return f"{round(cut, 1):g} %"


def _g2_words(g: dict) -> str:
    """What a tangent edge's report says of its curvature jump (G2): ", curvature jump a % -> b % (how)" on an
    edge that was curvature-continuous when hot, "" on another."""
    if not g.get("g2"):
        return ""
    change = (f"{100 * g['jump_before']:.2g} %" if g["jump_after"] == g["jump_before"]
              else f"{100 * g['jump_before']:.2g} % -> {100 * g['jump_after']:.2g} %")
    return f", curvature jump {change}" + (f" ({g['g2_reason']})" if g.get("g2_reason") else "")


@dataclass(frozen=True)
class Report:
    """Everything a user needs to judge a morph."""

    hot: str
    field: str
    nodes_total: int
    nodes_on_faces: int
    nodes_on_edges: int
    nodes_on_vertices: int
    nodes_ignored: int
    node_distance: float
    edge_distance: float
    max_displacement: float
    delta_max: float
    delta_mean: float
    vertex_delta_max: float
    delta_between: float
    valid: bool
    free_edges: int
    faces: list[FaceReport]
    edges: list[EdgeReport]
    solids: list[SolidReport]
    timings: dict[str, float] = field(default_factory=dict)
    inversion: dict | None = None
    tolerance: float | None = None
    keep_knots: bool = False
    scatter: float = 0.0
    allowance: float = 0.0
    refinements: list[dict] = field(default_factory=list)
    edge_refinements: list[dict] = field(default_factory=list)
    g1: list[dict] = field(default_factory=list)
    element_points: int = 0
    result_set: str = ""

    def misses(self) -> list[tuple[str, float]]:
        """Where the cold part misses the tolerance plus the field's scatter allowance, worst first: ``(where,
        error in mm)`` with ``where`` as "face 3 at its nodes" or "face 14 between its nodes".  At the nodes:
        every face's and edge's Δmax; between them: what the refinement measured there at the end (its grid
        points near the nodes of faces their nodes do not determine, its edges' gaps), for every face and edge
        it refined or found missing.  A face with no node of its own (a plane of a triangulation's vertices)
        misses only between its nodes, and counted at its nodes alone it would pass as met however far off the
        exact cold geometry it ends.  Empty when no tolerance was set."""
        if self.tolerance is None:
            return []
        limit = self.tolerance + self.allowance
        found = [(f"{kind} {x.index} at its nodes", x.delta_max) for kind, items in (("face", self.faces),
                                                                                      ("edge", self.edges))
                 for x in items if not math.isnan(x.delta_max) and x.delta_max > limit]
        found += [(f"{kind} {r[kind]} between its nodes", r["between_after"])
                  for kind, records in (("face", self.refinements), ("edge", self.edge_refinements))
                  for r in records if r.get("between_after", 0.0) > limit]
        return sorted(found, key=lambda item: -item[1])

    def unsupported_faces(self) -> list[FaceReport]:
        """The faces more than :data:`UNSUPPORTED_SHARE` of whose area lies out of their nodes' reach, most
        first: there the cold face follows its edges and the field's estimate, and neither the tolerance nor
        anything else measures it.  A plane of a triangulation's vertices has nodes only on its border: it can
        meet the tolerance where measured and miss it against the exact cold geometry in its middle."""
        found = [f for f in self.faces if not math.isnan(f.unsupported) and f.unsupported > UNSUPPORTED_SHARE]
        return sorted(found, key=lambda f: -f.unsupported)

    def unsupported_text(self, most: int = 3) -> str:
        """One sentence on :meth:`unsupported_faces` (the ``most`` worst named), "" when there are none."""
        faces = self.unsupported_faces()
        if not faces:
            return ""
        named = ", ".join(f"face {f.index} ({100 * f.unsupported:.0f} %, "
                          + (f"up to {f.farthest_node:.3g} mm)" if math.isfinite(f.farthest_node) else "no node)")
                          for f in faces[:most])
        more = f" and {len(faces) - most} more" if len(faces) > most else ""
        return (f"{named}{more} of the area unmeasured: farther than {GRID_REACH:g} node spacings from any node "
                f"(the cold face there follows its edges and the field's estimate), or near nodes that do not tell "
                f"that it is within the tolerance")

    @property
    def tolerance_met(self) -> bool | None:
        """Whether the cold part is within the tolerance plus the field's scatter allowance at every node and
        where the refinement measured it between them (:meth:`misses`); None when no tolerance was set."""
        if self.tolerance is None:
            return None
        return not self.misses()

    def measured_share(self) -> float | None:
        """The share (0 to 1) of the part's area measured: 1 less each face's
        :attr:`FaceReport.unsupported` weighted by its area, over the faces checked; None where no face was
        checked or no area is known."""
        checked = [(f.area, f.unsupported) for f in self.faces
                   if math.isfinite(f.unsupported) and math.isfinite(f.area) and f.area > 0.0]
        total = sum(a for a, _ in checked)
        if not checked or total <= 0.0:
            return None
        return max(0.0, 1.0 - sum(a * u for a, u in checked) / total)

    def _largest_at_nodes(self) -> tuple[float, Place | None]:
        found = [(x.delta_max, Place(feature, x.index)) for feature, items in ((Feature.FACE, self.faces),
                                                                               (Feature.EDGE, self.edges))
                 for x in items if math.isfinite(x.delta_max)]
        if math.isfinite(self.vertex_delta_max):
            found.append((self.vertex_delta_max, Place(Feature.VERTEX)))
        if not found:
            return float("nan"), None
        return max(found, key=lambda item: item[0])

    def _between_figures(self, limit: float | None) -> tuple[tuple[float, Place | None, bool],
                                                             tuple[float, Place | None]]:
        """The largest error found between the nodes ``(mm, place, counted)``, and ``(mm, place)`` of a larger
        one beyond ``limit`` that :meth:`misses` does not count ((NaN, None) where there is none).

        Two measures: what the refinement measured on the faces and edges it refined or found missing (counted
        against the tolerance), and the cold check's grid over every face against the field's local estimate
        (which :meth:`misses` does not count).
        The first is the largest of those counted or within the limit, so that a miss the tolerance counts is
        always the one named; where none of them is counted, the largest of all."""
        found = [(f.delta_between, False, Place(Feature.FACE, f.index)) for f in self.faces
                 if math.isfinite(f.delta_between)]
        found += [(float(r["between_after"]), True, Place(feature, r[feature.value]))
                  for feature, records in ((Feature.FACE, self.refinements), (Feature.EDGE, self.edge_refinements))
                  for r in records if r.get("between_after") is not None and math.isfinite(r["between_after"])
                  and r["between_after"] > 0.0]
        none = (float("nan"), None)
        if not found:
            return (*none, False), none
        beyond = [x for x in found if limit is not None and not x[1] and x[0] > limit]
        kept = [x for x in found if x not in beyond]
        first = max(kept, key=lambda x: x[:2]) if kept else None
        extra = max(beyond, key=lambda x: x[0]) if beyond else None
        if first is None or (extra is not None and not first[1]):     # no counted figure beside it: one figure
            first, extra = extra, None
        elif extra is not None and extra[0] <= first[0]:
            extra = None
        return (first[0], first[2], first[1]), none if extra is None else (extra[0], extra[2])

    @property
    def verdict(self) -> Verdict:
        """The morph's one verdict (:class:`Verdict`): met, partly measured, NOT met or no tolerance, with the
        largest error at the nodes and between them and the share of the area measured.  NOT met is
        :attr:`tolerance_met` False (:meth:`misses`); partly measured is met where measured with some of the
        area not vouched for: faces named by :meth:`unsupported_faces`, or else those with any share unmeasured
        (:attr:`FaceReport.unsupported`: between the nodes the check cannot tell the cold face within the
        limit there, a sharp thermal front the nodes do not resolve)."""
        met = self.tolerance_met
        unmeasured = (tuple(f.index for f in self.unsupported_faces())
                      or tuple(f.index for f in sorted((f for f in self.faces if f.unsupported > 0.0),
                                                       key=lambda f: -f.unsupported)))
        if met is None:
            state = VerdictState.NO_TOLERANCE
        elif not met:
            state = VerdictState.NOT_MET
        else:
            state = VerdictState.PARTLY_MEASURED if unmeasured else VerdictState.MET
        limit = None if self.tolerance is None else self.tolerance + self.allowance
        at_nodes, at_where = self._largest_at_nodes()
        (between, between_where, counted), (beyond, beyond_where) = self._between_figures(limit)
        measured = self.measured_share()

        if self.tolerance is None:
            head = state.words
        else:
            noise = (f" + {self.allowance:.3g} mm for the field's scatter" if self.allowance > 0.1 * self.tolerance
                     else "")
            strict = f", knots kept ({option('keep_knots', True)})" if self.keep_knots else ""
            head = f"tolerance {self.tolerance:.3g} mm{noise}{strict}: {state.words}"
        # the figures, worst first, but one beyond the limit that misses() does not count (the cold check's grid
        # against the field's local estimate between the nodes, the vertices' nodes) after those it counts, and
        # saying so: a NOT met names first what made it so
        errors = []
        if at_where is not None:
            aside = ("; not counted against the tolerance" if limit is not None and at_where.feature is Feature.VERTEX
                     and at_nodes > limit else "")
            errors.append((bool(aside), -at_nodes, f"{_mm(at_nodes)} at the nodes ({at_where}{aside})"))
        else:
            errors.append((True, 0.0, "no node used"))
        if between_where is not None:
            aside = ("" if limit is None or between <= limit or counted else
                     ", against the field's local estimate; not counted against the tolerance")
            errors.append((bool(aside), -between, f"{_mm(between)} between the nodes ({between_where}{aside})"))
        else:
            errors.append((True, 0.0, "nothing measured between the nodes"))
        errors.sort(key=lambda item: item[:2])
        if beyond_where is not None:
            errors.append((True, -beyond, f"{_mm(beyond)} off the field's local estimate between the nodes "
                                   f"({beyond_where}; not counted against the tolerance)"))
        if measured is None:
            area = "area measured not checked"
        else:
            only = "only " if state is VerdictState.PARTLY_MEASURED else ""
            area = f"{only}{_percent(measured)} of the area measured"
        if unmeasured:
            share = {f.index: f.unsupported for f in self.faces}
            named = ", ".join(f"{_percent(share[k], up=True)} of face {k}" for k in unmeasured[:3])
            more = f" and {len(unmeasured) - 3} more faces" if len(unmeasured) > 3 else ""
            area += f" (unmeasured: {named}{more})"
        text = f"{head} — {', '.join(words for *_, words in errors)}; {area}"
        return Verdict(state, self.tolerance, limit, at_nodes, at_where, between, between_where, beyond,
                       beyond_where, measured, unmeasured, text)

    @property
    def nodes_used(self) -> int:
        return self.nodes_total - self.nodes_ignored

    def to_dict(self) -> dict:
        """A JSON-ready dict (NaN written as null)."""
        data = {"verdict": self.verdict.to_dict(), **asdict(self)}      # the verdict first: what a user sees
        data["nodes_used"] = self.nodes_used
        data["closed"] = self.free_edges == 0
        data["tolerance_met"] = self.tolerance_met
        data["unsupported_faces"] = [f.index for f in self.unsupported_faces()]
        return _no_nan(data)

    def to_json(self, path) -> None:
        """Write the report as JSON to ``path``."""
        with open(path, "w", encoding="utf-8") as fh:
            json.dump(self.to_dict(), fh, indent=2, ensure_ascii=False)     # the verdict's dash as written
            fh.write("\n")

    def _misses(self, refinement: dict) -> bool:
        """Whether a face or edge refinement record still misses the tolerance (plus the noise allowance)."""
        limit = (self.tolerance or math.inf) + (self.allowance or 0.0)
        return max(refinement.get("delta_max_after", 0.0), refinement.get("between_after", 0.0)) > limit

    def _repr_html_(self) -> str:
        """How a notebook shows the report: its verdict, figures and face table
        (:func:`hot2cold.views.notebook.report_html`; the one import of the views from below them)."""
        from ..views.notebook import report_html

        return report_html(self)

    def table(self) -> str:
        """A short text table: the verdict first (:attr:`verdict`), then per face as the paper's Table 1, then
        the overall checks."""
        lines = self._counts_lines() + self._refinement_lines() + self._g1_lines() + self._closing_lines()
        return "\n".join(lines)

    def _counts_lines(self) -> list[str]:
        """The verdict, the per-face table, and the counts of edges, nodes and solids."""
        lines = [self.verdict.text,
                 f"{'face':>5} {'FE nodes':>9} {'control points':>15} {'Δmax [mm]':>10} {'Δmean [mm]':>10}  name"]
        for f in self.faces:
            lines.append(f"{f.index:>5} {f.nodes:>9} {f.control_points:>15} {_num(f.delta_max):>10} "
                         f"{_num(f.delta_mean):>10}  {f.name}".rstrip())
        edge_max = max((e.delta_max for e in self.edges if not math.isnan(e.delta_max)), default=float("nan"))
        gap = max((e.gap for e in self.edges), default=0.0)
        lines.append(f"edges: {len(self.edges)}, Δmax {_num(edge_max)} mm, largest edge-face gap {_num(gap)} mm")
        inside = (f" (of them {self.element_points} points inside the FE elements, by their shape functions)"
                  if self.element_points else "")
        if self.result_set:
            lines.append(f"field: {self.result_set} of {self.field}")
        lines.append(f"nodes: {self.nodes_total} total{inside}, {self.nodes_used} used "
                     f"({self.nodes_on_faces} inside a face, {self.nodes_on_edges} within {self.edge_distance:.3g} mm "
                     f"of an edge, {self.nodes_on_vertices} at a vertex), {self.nodes_ignored} ignored: farther than "
                     f"{self.node_distance:.3g} mm ({option('node_distance')}) from every face, e.g. volume nodes of "
                     f"a solid mesh")
        for s in self.solids:
            name = f" {s.name!r}" if s.name else ""
            lines.append(f"solid {s.index}{name}: {'valid' if s.valid else 'INVALID'}, "
                         f"{'closed' if s.closed else f'{s.free_edges} free edges'}, {s.faces} faces, "
                         f"volume hot {s.volume_hot:.6g} mm³, cold {s.volume_cold:.6g} mm³")
        return lines

    def _refinement_lines(self) -> list[str]:
        """A line per face and edge the refinement changed, or that misses the tolerance unrefined."""
        lines: list[str] = []
        short = "its knot spans there are as short as the nodes' spacing allows"
        for r in self.refinements:
            change = (f"Δmax {r['delta_max_before']:.2e} -> {r['delta_max_after']:.2e} mm"
                      if "delta_max_before" in r else f"fit residual {r['residual']:.2e} mm")
            if r.get("between_before", 0.0) > (self.tolerance or 0.0):
                change += f", between the nodes {r['between_before']:.2e} -> {r['between_after']:.2e} mm"
            if r["rounds"] == 0:
                if not self._misses(r):      # above the refinement's aim, within the tolerance: nothing to say
                    continue
                why = short if not r.get("refinable", False) else "no refinement round was run"
                lines.append(f"face {r['face']} misses the tolerance ({change}) and was not refined: {why}")
                continue
            degree = (f", degree {r['degree_before']} -> {r['degree_after']}"
                      if r.get("degree_before", "") != r.get("degree_after", "") else "")
            unresolved = r.get("unresolved", 0)
            left = (f"at {unresolved} of its nodes a finer net did not bring it closer (the field's nodes around "
                    f"them do not follow them)" if unresolved else short)
            stop = "" if not self._misses(r) else (f"; where it still misses, {left}" if not r.get("refinable", True)
                                                   else "; it still misses after the most rounds allowed "
                                                        f"({option('max_refinements')})")
            lines.append(f"face {r['face']} refined: {r['net_before']} -> {r['net_after']} poles{degree} "
                         f"(+{r['knots_added_u']} u, +{r['knots_added_v']} v knots, {r['rounds']} rounds), "
                         f"{change}{stop}")
        for r in self.edge_refinements:
            change = f"Δmax {r['delta_max_before']:.2e} -> {r['delta_max_after']:.2e} mm"
            if r.get("between_before", 0.0) > (self.tolerance or 0.0):
                change += f", between the nodes {r['between_before']:.2e} -> {r['between_after']:.2e} mm"
            if r["rounds"] == 0:
                if not self._misses(r):
                    continue
                why = short if not r["refinable"] else "no round was run"
                lines.append(f"edge {r['edge']} misses the tolerance ({change}) and was not refined: {why}")
                continue
            degree = (f", degree {r['degree_before']} -> {r['degree_after']}"
                      if r["degree_before"] != r["degree_after"] else "")
            stop = "" if not self._misses(r) else (f"; where it still misses, {short}" if not r["refinable"]
                                                   else "; it still misses after the most rounds allowed "
                                                        f"({option('max_refinements')})")
            lines.append(f"edge {r['edge']} refined: {r['poles_before']} -> {r['poles_after']} poles{degree} "
                         f"(+{r['knots_added']} knots, {r['rounds']} rounds), {change}{stop}")
        return lines

    def _g1_lines(self) -> list[str]:
        """G1's tangent edges, a line each after the count."""
        lines: list[str] = []
        if self.g1:
            before = max((g["kink_before_max"] for g in self.g1), default=0.0)
            after = max((g["kink_after_max"] for g in self.g1), default=0.0)
            fixed = sum(bool(g["corrected"]) for g in self.g1)
            lines.append(f"G1: {len(self.g1)} tangent edges ({fixed} corrected), kink before {before:.3g}°, "
                         f"after {after:.3g}°")
            for g in self.g1:
                how = (g.get("method") or "corrected") if g["corrected"] else f"not corrected: {g['reason']}"
                lines.append(f"  edge {g['edge']} (faces {g['faces'][0]}, {g['faces'][1]}): kink "
                             f"{g['kink_before_max']:.3g}° -> {g['kink_after_max']:.3g}° ({how}){_g2_words(g)}")
        return lines

    def _closing_lines(self) -> list[str]:
        """The field's scatter, what is not measured, the inversion, and the overall figures."""
        lines: list[str] = []
        if self.tolerance is not None and self.allowance > 0.1 * self.tolerance:   # the verdict says how much
            lines.append(f"field's scatter: {self.scatter:.3g} mm about a smooth field, {self.allowance:.3g} mm "
                         f"added to the tolerance at the nodes")
        if self.unsupported_faces():
            lines.append(f"not measured: {self.unsupported_text()}")
        if self.inversion:
            lines.append(f"field inverted (cold to hot): {self.inversion['iterations']} fixed-point iterations, "
                         f"residual {self.inversion['residual']:.2e} mm")
        lines.append(f"overall: Δmax {_num(self.delta_max)} mm, Δmean {_num(self.delta_mean)} mm, "
                     f"largest displacement {self.max_displacement:.4g} mm")
        if not math.isnan(self.delta_between):
            worst = max((f for f in self.faces if not math.isnan(f.delta_between)), key=lambda f: f.delta_between)
            lines.append(f"between the nodes: Δmax {_num(self.delta_between)} mm (face {worst.index}), against the "
                         f"field's local estimate on a grid over every face")
        return lines


def _num(x: float) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.2e}"


def _no_nan(obj):
    if isinstance(obj, float):
        return None if not math.isfinite(obj) else obj
    if isinstance(obj, dict):
        return {k: _no_nan(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_no_nan(v) for v in obj]
    return obj


def _stats(d: np.ndarray) -> tuple[float, float]:
    return (float(d.max()), float(d.mean())) if len(d) else (float("nan"), float("nan"))


@dataclass(frozen=True, eq=False)
class ColdGeometry:
    """The morphed geometry the nodes are measured against (eq. 21): the cold ``vertices (nv, 3)``, a
    ``projector`` onto the cold faces and edges, and the cold ``surfaces`` (one BSplineSurface per face) and
    ``curves`` (one BSplineCurve per edge, None where degenerate)."""

    vertices: np.ndarray
    projector: Projector
    surfaces: list
    curves: list


def node_errors(cls: Classification, field: DisplacementField, cold: ColdGeometry, threads: int = 1) -> np.ndarray:
    """Distance ``(N,)`` (mm) of every used node's cold target point to the morphed geometry ``cold``
    (eq. 21); ignored nodes get NaN.

    On the cold surfaces the face nodes' foot points are found by Newton's method from their hot parameters
    (:mod:`hot2cold.core.footpoint`); the kernel (``cold.projector``) is asked only where that does not
    settle.  The edge nodes' likewise on the cold curves, from their hot parameters; where that does not settle,
    the kernel's, polished by Gauss-Newton on the cold curves (the kernel's projection stops short of the foot
    point on edges of high degree).  The faces' Newton runs in up to ``threads`` threads.
    """
    projector, cold_surfaces, cold_curves = cold.projector, cold.surfaces, cold.curves
    errors = np.full(len(cls.role), np.nan)
    target = cls.foot + field.displacements
    faces = [(k, nodes, projector.face_box(k)) for k, nodes in cls.groups(Role.FACE)]
    feet = map_threads(lambda job: project_to_surface(cold_surfaces[job[0]], target[job[1]], cls.uv[job[1]], job[2]),
                       faces, threads, cost=[len(nodes) for _, nodes, _ in faces])
    for (k, nodes, _), fp in zip(faces, feet):
        errors[nodes] = fp.distance
        open_ = nodes[~fp.settled]
        if len(open_):
            errors[open_] = projector.to_face(k, target[open_])[1]
    for k, nodes in cls.groups(Role.EDGE):
        if cold_curves[k] is not None:           # Newton from the hot parameters; the kernel where it stays open
            feet = project_to_curve(cold_curves[k], target[nodes], cls.t[nodes])
            errors[nodes] = feet.distance
            nodes = nodes[~feet.settled]
            if not len(nodes):
                continue
        t, distance = projector.to_edge(k, target[nodes])
        if cold_curves[k] is not None:
            found = np.isfinite(t)
            distance[found] = curve_distances(cold_curves[k], target[nodes][found], t[found])
        errors[nodes] = distance
    at_vertex = np.flatnonzero(cls.role == Role.VERTEX)
    errors[at_vertex] = np.linalg.norm(target[at_vertex] - cold.vertices[cls.owner[at_vertex]], axis=1)
    return errors


@dataclass(frozen=True, eq=False)
class Fits:
    """What the fits of a morph gave: one :class:`FaceMorph` per face and one :class:`EdgeMorph` per edge (in
    the part's numbering), and the records of the refinement to a tolerance (:mod:`.refine`) and of the G1
    correction (:mod:`.g1`), empty where those steps did not run."""

    faces: list[FaceMorph]
    edges: list[EdgeMorph]
    refinements: tuple = ()
    edge_refinements: tuple = ()
    g1: tuple = ()


@dataclass(frozen=True, eq=False)
class Checks:
    """The kernel's checks of a morph: one :class:`SolidCheck` per solid of the hot part and of the cold one
    (the cold ones marked invalid where :func:`~.checks.check_cold` found a problem), ``gaps (n_edges,)``,
    each edge's largest distance (mm) to the faces it bounds in the cold part, and ``between (n_faces,)``, each
    face's largest distance (mm) from the field's local estimate between the nodes (None: not checked);
    ``unsupported (n_faces,)`` and ``farthest_node (n_faces,)``, each face's share of its grid out of its
    nodes' reach and the grid's largest distance (mm) to them (:attr:`FaceReport.unsupported`)."""

    hot: list[SolidCheck]
    cold: list[SolidCheck]
    gaps: np.ndarray
    between: np.ndarray | None = None
    unsupported: np.ndarray | None = None
    farthest_node: np.ndarray | None = None


@dataclass(frozen=True)
class RunFacts:
    """What the report says of a run besides its fits and checks.

    Attributes
    ----------
    hot_name : the hot part's file (or its type when given as a shape).
    timings : seconds per stage.
    inversion : the field inversion's record as a dict (None when the field was not inverted).
    scatter : the field's scatter about a smooth field (mm, :func:`hot2cold.core.localfit.scatter`).
    allowance : what the scatter adds to the tolerance at the nodes (mm,
        :func:`hot2cold.pipeline.refine.noise_allowance`).
    element_points : how many of the field's points are inside its FE elements rather than nodes
        (:func:`hot2cold.pipeline.load.element_points`).
    """

    hot_name: str = ""
    timings: dict | None = None
    inversion: dict | None = None
    scatter: float = 0.0
    allowance: float = 0.0
    element_points: int = 0


def build_report(context: Morphed, fits: Fits, checks: Checks, errors: np.ndarray, run: RunFacts = RunFacts()
                 ) -> Report:
    """Assemble the :class:`Report` of a morph.

    ``context`` gives the (refined) part, the classification, the field and the tolerance; ``errors (N,)``
    is each node's distance (mm) to the cold part (eq. 21, :func:`node_errors`); ``run`` what else the report
    says of the run (:class:`RunFacts`).
    """
    part, cls, field = context.part, context.classification, context.field
    # the hot faces' areas weigh the share of each face out of its nodes' reach (Verdict.measured)
    areas = face_areas(part.kernel.faces) if checks.unsupported is not None else np.full(len(part.faces), np.nan)
    faces = []
    for fm in fits.faces:
        d = errors[cls.nodes_of(Role.FACE, fm.index)]
        nu, nv = fm.surface.shape
        between = float("nan") if checks.between is None else float(checks.between[fm.index])
        unsupported, farthest = ((float("nan"), float("nan")) if checks.unsupported is None else
                                 (float(checks.unsupported[fm.index]), float(checks.farthest_node[fm.index])))
        faces.append(FaceReport(fm.index, part.faces[fm.index].solid, fm.nodes, f"{nu}x{nv}", *_stats(d),
                                fm.unknowns, fm.rank, fm.condition, list(fm.tied_sides), fm.edge_rows,
                                fm.artificial, between, unsupported, farthest, part.face_title(fm.index),
                                float(areas[fm.index])))
    edges = []
    for em in fits.edges:
        d = errors[cls.nodes_of(Role.EDGE, em.index)]
        n_poles = 0 if em.curve is None else em.curve.n_poles
        edges.append(EdgeReport(em.index, list(part.edges[em.index].faces), em.nodes, n_poles, *_stats(d),
                                float(checks.gaps[em.index]), em.artificial))
    used = cls.used
    vertex_err = errors[cls.role == Role.VERTEX]
    names = tuple(getattr(part, "solid_names", ()))
    solids = [SolidReport(i, c.faces, c.valid, c.free_edges, h.volume, c.volume,
                          names[i] if i < len(names) else "")
              for i, (h, c) in enumerate(zip(checks.hot, checks.cold))]
    all_err = errors[used]
    return Report(
        hot=run.hot_name, field=field.source, result_set=field.result_set, nodes_total=cls.field_nodes,
        nodes_on_faces=int(np.sum(cls.role == Role.FACE)),
        nodes_on_edges=int(np.sum(cls.role == Role.EDGE)),
        nodes_on_vertices=int(np.sum(cls.role == Role.VERTEX)),
        nodes_ignored=int(np.sum(cls.role == Role.IGNORED)),
        node_distance=cls.node_distance, edge_distance=cls.edge_distance,
        max_displacement=float(np.linalg.norm(field.displacements[used], axis=1).max()) if used.any() else 0.0,
        delta_max=_stats(all_err)[0], delta_mean=_stats(all_err)[1],
        vertex_delta_max=_stats(vertex_err)[0],
        delta_between=max((f.delta_between for f in faces if not math.isnan(f.delta_between)), default=float("nan")),
        valid=all(s.valid for s in solids), free_edges=sum(s.free_edges for s in solids),
        faces=faces, edges=edges, solids=solids, timings=dict(run.timings or {}), inversion=run.inversion,
        tolerance=context.settings.tolerance, keep_knots=context.settings.keep_knots, scatter=run.scatter,
        allowance=run.allowance, refinements=[asdict(r) for r in fits.refinements],
        edge_refinements=[asdict(r) for r in fits.edge_refinements], g1=[asdict(r) for r in fits.g1],
        element_points=run.element_points)
