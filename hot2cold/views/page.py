"""The morph report as one self-contained HTML page: tables and pictures, images inlined as base64 PNG.

    write_html(result, "report.html")

The page holds an interactive 3D view (:mod:`hot2cold.views.viewer`: the cold part coloured by its
deviation from the field, the hot part as a ghost, the FE nodes, an exaggeration slider; a click on a face
picks its row of the face table), the paper-style table per face and per edge (FE nodes, control points,
Δmax, Δmean; the kink before and after the G1 correction on tangent edges), the overall checks (validity,
free edges, volumes hot and cold, nodes used and ignored), the tolerance and refinements, and the pictures
of :mod:`hot2cold.views.pictures`.  It loads nothing from anywhere: the view's scripts (three.js included)
and data are inline, the pictures are data URLs, there are no style sheets or files beside it.
"""
from __future__ import annotations

import base64
import datetime as _dt
import html
import logging
import math
import os
import time
from pathlib import Path

from .. import __version__
from . import pictures
from .scene import build_scene
from .viewer import STYLE as _VIEWER_STYLE, viewer_html
from ..io.atomic import write_atomically
from ..pipeline.report import Tone

log = logging.getLogger(__name__)

#: The report page's style sheet (CSS): also the notebook's, scoped there to the report's ``<div>``.
STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 1.5em auto;
       max-width: 1250px; padding: 0 1em; color: #222; line-height: 1.4; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; } h2 { font-size: 1.2em; margin-top: 1.6em;
     border-bottom: 1px solid #ccc; padding-bottom: 0.2em; }
table { border-collapse: collapse; margin: 0.5em 0 1em 0; font-size: 0.9em; }
th, td { border: 1px solid #d0d0d0; padding: 0.2em 0.6em; text-align: right; }
th { background: #f0f0f0; } td.l, th.l { text-align: left; }
tr:nth-child(even) td { background: #fafafa; }
.ok { color: #1a7f37; font-weight: 600; } .bad { color: #c62828; font-weight: 600; }
.warn { color: #9a6700; font-weight: 600; } .plain { font-weight: 600; }
p.verdict { font-size: 1.15em; padding: 0.55em 0.9em; margin: 0.5em 0 0.6em 0; border-left: 6px solid;
            border-radius: 3px; }
p.verdict.v-good { color: #14532d; background: #e7f5ec; border-color: #1a7f37; }
p.verdict.v-warning { color: #6b4200; background: #fff3d1; border-color: #d39e00; }
p.verdict.v-bad { color: #8e1b1b; background: #fdecea; border-color: #c62828; }
p.verdict.v-neutral { color: #333; background: #f0f0f0; border-color: #999; }
.muted { color: #777; } figure { margin: 1em 0 2em 0; } figure img { max-width: 100%; height: auto;
border: 1px solid #e0e0e0; } figcaption { font-size: 0.9em; color: #444; margin-top: 0.3em; }
dl.summary { display: grid; grid-template-columns: max-content auto; gap: 0.15em 1.2em; }
dl.summary dt { font-weight: 600; } dl.summary dd { margin: 0; }
"""


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _mm(x, fmt: str = ".2e") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return format(x, fmt)


def _deg(x) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return f"{x:.3g}°"


def _flag(ok: bool, yes: str, no: str, green: bool = True) -> str:
    """``yes`` (green where ``green``, else plain) or ``no`` in red: a page green only where its verdict is
    (:data:`_TONE_CLASS`), so that a valid part that misses its tolerance shows no green at all."""
    if not ok:
        return f'<span class="bad">{_e(no)}</span>'
    return f'<span class="{"ok" if green else "plain"}">{_e(yes)}</span>'


#: The CSS class of each :class:`~hot2cold.pipeline.report.Tone` of a verdict, for the verdict's words.
_TONE_CLASS = {Tone.GOOD: "ok", Tone.WARNING: "warn", Tone.BAD: "bad", Tone.NEUTRAL: "plain"}


def _green(report) -> bool:
    """Whether the page may show anything in green: only when the verdict is met and fully measured."""
    return report.verdict.tone is Tone.GOOD


def _verdict(report) -> str:
    """The verdict, the page's headline (:attr:`~hot2cold.pipeline.report.Report.verdict`): the same sentence
    as the command's first line, coloured by the verdict alone (green met, amber partly measured, red NOT met,
    grey no tolerance)."""
    verdict = report.verdict
    head, dash, rest = verdict.text.partition(" — ")
    return (f'<p class="verdict v-{verdict.tone.value}" id="verdict" data-state="{_e(verdict.state.name)}">'
            f"<strong>{_e(head)}</strong>{_e(dash)}{_e(rest)}</p>")


def _state(report) -> str:
    """The verdict's state in its colour, for the summary and the tolerance section."""
    verdict = report.verdict
    return f'<span class="{_TONE_CLASS[verdict.tone]}">{_e(verdict.state.words)}</span>'


def _table(head: list[str], rows: list[list[str]], left: set[int] = frozenset(), cls: str = "",
           row_attrs: list[str] | None = None) -> str:
    """Cells are HTML already (escape before); ``row_attrs`` one attribute string per row (HTML too)."""
    th = "".join(f'<th{" class=l" if i in left else ""}>{h}</th>' for i, h in enumerate(head))
    attrs = row_attrs if row_attrs is not None else [""] * len(rows)
    body = "\n".join(f"<tr{' ' + a if a else ''}>"
                     + "".join(f'<td{" class=l" if i in left else ""}>{c}</td>' for i, c in enumerate(r))
                     + "</tr>" for r, a in zip(rows, attrs))
    return f'<table class="{cls}"><thead><tr>{th}</tr></thead>\n<tbody>\n{body}\n</tbody></table>'


def _img(png: bytes, alt: str) -> str:
    return f'<img alt="{_e(alt)}" src="data:image/png;base64,{base64.b64encode(png).decode("ascii")}">'


def _summary(report) -> str:
    verdict, green = report.verdict, _green(report)
    items = []
    if report.tolerance is not None:
        items.append(("tolerance", f"{report.tolerance:.3g} mm{_widened(report)}: " + _state(report)))
    unmeasured = len(verdict.unmeasured_faces)
    items += [
        ("area measured", _e(verdict.measured_text) + (f" ({unmeasured} {'face' if unmeasured == 1 else 'faces'} "
                                                       f"partly unmeasured)" if unmeasured else "")),
        ("hot part", _e(report.hot or "–")),
        ("field", _e(report.field or "–") + (f" ({_e(report.result_set)})" if report.result_set else "")),
        ("cold part", _flag(report.valid, "valid", "INVALID", green) + ", "
         + _flag(report.free_edges == 0, "closed", f"{report.free_edges} free edges", green)),
        ("Δmax / Δmean", f"{_mm(report.delta_max)} mm / {_mm(report.delta_mean)} mm"),
        ("largest displacement", f"{report.max_displacement:.4g} mm"),
    ]
    return '<dl class="summary">' + "".join(f"<dt>{k}</dt><dd>{v}</dd>" for k, v in items) + "</dl>"


def head_sections(report) -> str:
    """The first sections of the page of ``report``: its verdict, its figures and the face table (HTML without
    script; a report in a notebook is these, :func:`hot2cold.views.notebook.report_html`)."""
    return f"{_verdict(report)}{_summary(report)}{_face_table(report)}"


def _face_table(report) -> str:
    """One row per face, ``id="face-row-K"`` (the 3D view highlights the row of the face picked)."""
    several = len(report.solids) > 1                    # the solid column only when there is a choice
    names = [getattr(f, "name", "") or "" for f in report.faces]
    named = any(names)                                  # the name column only when a face has one
    rows = []
    for f, name in zip(report.faces, names):
        rows.append([str(f.index), *([_e(name or "–")] if named else []), *([str(f.solid)] if several else []),
                     str(f.nodes), _e(f.control_points), _mm(f.delta_max), _mm(f.delta_mean),
                     str(f.artificial_nodes), f"{f.rank}/{f.unknowns}", _mm(f.condition, ".2g"),
                     _e(" ".join(f.tied_sides) or "–")])
    head = ["face", *(["name"] if named else []), *(["solid"] if several else []), "FE nodes", "control points",
            "Δmax [mm]", "Δmean [mm]", "artificial nodes", "rank / unknowns", "condition", "sides tied to edges"]
    left = {len(head) - 1, *({1} if named else set())}
    attrs = [f'id="face-row-{f.index}" data-face="{f.index}"' for f in report.faces]
    return _table(head, rows, left=left, cls="faces", row_attrs=attrs)


def _edge_table(report) -> str:
    g1 = {g["edge"]: g for g in report.g1}
    rows = []
    for e in report.edges:
        g = g1.get(e.index)
        if g is None:
            kink = ["–", "–", "–"]
        else:
            kink = [_deg(g["kink_before_max"]), _deg(g["kink_after_max"]),
                    _e(g.get("method") or "corrected") if g["corrected"] else _e(g["reason"] or "not corrected")]
        rows.append([str(e.index), _e(" ".join(map(str, e.faces))), str(e.nodes), str(e.control_points),
                     _mm(e.delta_max), _mm(e.delta_mean), _mm(e.gap), *kink])
    return _table(["edge", "faces", "FE nodes", "control points", "Δmax [mm]", "Δmean [mm]",
                   "gap to faces [mm]", "kink before", "kink after", "G1"], rows, left={1, 9}, cls="edges")


def _checks(report) -> str:
    rows = []
    for s in report.solids:
        change = (s.volume_cold - s.volume_hot) / s.volume_hot * 100 if s.volume_hot else float("nan")
        rows.append([str(s.index), str(s.faces), _flag(s.valid, "valid", "INVALID", _green(report)),
                     _flag(s.closed, "0", str(s.free_edges), _green(report)), f"{s.volume_hot:.6g}",
                     f"{s.volume_cold:.6g}",
                     _mm(change, "+.4f")])
    solids = _table(["solid", "faces", "validity", "free edges", "volume hot [mm³]", "volume cold [mm³]",
                     "change [%]"], rows)
    nodes = _table(["FE nodes", "used", "on faces", "on edges", "on vertices", "ignored"],
                   [[str(report.nodes_total), str(report.nodes_used), str(report.nodes_on_faces),
                     str(report.nodes_on_edges), str(report.nodes_on_vertices), str(report.nodes_ignored)]])
    notes = [f"Nodes farther than {report.node_distance:.3g} mm from every face are ignored; nodes within "
             f"{report.edge_distance:.3g} mm of an edge feed the edge.",
             f"Largest error at a vertex: {_mm(report.vertex_delta_max)} mm."]
    if report.inversion:
        notes.append(f"The field was inverted (cold to hot) in {report.inversion['iterations']} fixed-point "
                     f"iterations, residual {report.inversion['residual']:.2e} mm.")
    return solids + nodes + "".join(f"<p>{_e(n)}</p>" for n in notes)


def _widened(report) -> str:
    """`` + A mm for the field's scatter (S mm)`` where the scatter widens the tolerance noticeably, else ""."""
    if report.tolerance is None or report.allowance <= 0.1 * report.tolerance:
        return ""
    return f" + {report.allowance:.3g} mm for the field's scatter ({report.scatter:.3g} mm about a smooth field)"


def _tolerance(report) -> str:
    parts = []
    if report.tolerance is None:
        parts.append("<p>No tolerance was set: faces keep their hot control nets (no refinement).</p>")
    else:
        strict = " Knots kept (<code>--keep-knots</code>): nothing refined." if report.keep_knots else ""
        parts.append(f"<p>Tolerance {report.tolerance:.3g} mm{_widened(report)}: {_state(report)} "
                     f"(largest Δmax {_mm(report.delta_max)} mm).{strict}</p>")
    if report.unsupported_faces():
        parts.append(f"<p>Not measured: {_e(report.unsupported_text(most=10))}.</p>")
    if report.refinements:
        rows = []
        for r in report.refinements:
            if r["rounds"] == 0:
                rows.append([str(r["face"]), _e(r["net_before"]), _e(r["net_after"]), "0", "0", "0",
                             _mm(r["residual"]), "cannot be refined: the rows to lengthen are tied to edges"])
            else:
                rows.append([str(r["face"]), _e(r["net_before"]), _e(r["net_after"]), str(r["knots_added_u"]),
                             str(r["knots_added_v"]), str(r["rounds"]), _mm(r.get("residual")), "refined"])
        parts.append(_table(["face", "net before", "net after", "knots +u", "knots +v", "rounds",
                             "fit residual [mm]", ""], rows, left={7}))
    return "".join(parts)


def _g1(report) -> str:
    if not report.g1:
        return "<p>No tangent (G1) edges, or the G1 correction was switched off.</p>"
    before = max((g["kink_before_max"] for g in report.g1), default=0.0)
    after = max((g["kink_after_max"] for g in report.g1), default=0.0)
    fixed = sum(bool(g["corrected"]) for g in report.g1)
    rows = [[str(g["edge"]), _e(" ".join(map(str, g["faces"]))), _deg(g["hot_angle_max"]),
             _deg(g["kink_before_max"]), _deg(g["kink_after_max"]),
             _e(g.get("method") or "yes") if g["corrected"] else _e(g["reason"] or "no"),
             *(_share(g.get(k)) if g.get("g2") else "–" for k in ("jump_before", "jump_after")),
             _e(g.get("g2_reason") or "") if g.get("g2") else "not curvature-continuous when hot"]
            for g in report.g1]
    return (f"<p>{len(report.g1)} tangent edges, {fixed} corrected; largest kink before "
            f"{_deg(before)}, after {_deg(after)} (the angle between the two faces' normals along the edge, "
            f"paper section 5).  The curvature jump is the largest difference of the two faces' normal "
            f"curvatures across the edge, as a share of the curvature there, on edges where it was within the "
            f"G2 tolerance when hot (G2 corrected with <code>--continuity g2</code>).</p>"
            + _table(["edge", "faces", "hot angle", "kink before", "kink after", "corrected (how)",
                      "curvature jump before", "after", "G2"], rows, left={1, 5, 8}))


def _share(value) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{100 * value:.2g} %"


def _timings(report) -> str:
    if not report.timings:
        return ""
    cells = ", ".join(f"{_e(k)} {v:.2f} s" for k, v in report.timings.items())
    return f'<p class="muted">Morph timings: {cells}.</p>'


def render_html(result, scale: float | None = None, *, interactive: bool = True, figures: bool = True,
                colour: str = "deviation") -> str:
    """The report page of ``result`` (a :class:`~hot2cold.morph.MorphResult`) as a string.

    ``scale`` exaggerates the displacement in the overlay picture and starts the 3D view's slider there
    (default :func:`hot2cold.pictures.displacement_scale`: the largest displacement drawn as 5 % of the part's
    size).  ``interactive`` False leaves the 3D view out (a page without scripts, a few MB smaller); ``figures``
    False the pictures (drawn by matplotlib, the page's slowest part); ``colour`` is what the 3D view colours
    first, "deviation" (from the field) or "displacement".
    """
    report = result.report
    scale = pictures.displacement_scale(result) if scale is None else pictures.check_scale(scale)
    mesh = pictures.mesh_of(result)
    view = []
    if interactive:
        clock = time.perf_counter()
        view = ["<h2>3D view</h2>", viewer_html(build_scene(result, mesh, exaggeration=scale), colour),
                '<p class="muted">The cold part coloured by its deviation from the field (the nodes\' distances '
                "to it, eq. 21, interpolated over each face from the nodes of the face and its edges; grey: a face "
                "without nodes) or, switched, by the length of its displacement from hot to cold; the hot part as "
                "a red ghost. Drag to turn, right-drag to pan, wheel to zoom; "
                "click a face (or a row of the face table) for its figures. The slider exaggerates the "
                "displacement: vertices at hot + s × (cold − hot).</p>"]
        log.info("3D view built in %.2f s", time.perf_counter() - clock)

    pictures_part = ["<h2>Pictures</h2>", *_figures(result, scale, mesh)] if figures else []
    now = _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    title = f"hot2cold report: {Path(report.hot).name if report.hot else 'morph'}"
    body = [
        f"<h1>{_e(title)}</h1>",
        _verdict(report),
        f'<p class="muted">hot2cold {_e(__version__)}, {_e(now)}. Method: GT2014-26683 (hot-to-cold '
        f"B-spline morphing; only control points move).</p>",
        _summary(report),
        *view,
        "<h2>Faces</h2>", _face_table(report),
        "<h2>Edges</h2>", _edge_table(report),
        "<h2>Checks</h2>", _checks(report),
        "<h2>Tolerance and refinement</h2>", _tolerance(report),
        "<h2>G1 continuity</h2>", _g1(report),
        *pictures_part,
        _timings(report),
    ]
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<title>{_e(title)}: {_e(report.verdict.state.value)}</title>\n"
            f"<style>{STYLE}{_VIEWER_STYLE if interactive else ''}</style>\n"
            "</head>\n<body>\n"
            + "\n".join(body) + "\n</body>\n</html>\n")


def _figures(result, scale: float, mesh) -> list[str]:
    """The report's pictures (matplotlib, on ``mesh``), each a ``<figure>`` with its caption."""
    report = result.report
    clock = time.perf_counter()
    overlay = pictures.overlay_png(result, scale, mesh=mesh)
    error_faces = pictures.error_faces(result)
    errors = pictures.error_maps_png(result, error_faces, mesh=mesh) if error_faces else None
    curv_faces = pictures.curvature_faces(result, mesh=mesh)
    curvature = pictures.curvature_png(result, curv_faces, mesh=mesh) if curv_faces else None
    numbers = pictures.face_numbers_png(result, mesh=mesh)
    log.info("pictures drawn in %.2f s", time.perf_counter() - clock)
    largest = report.max_displacement
    figures = [
        f'<figure>{_img(numbers, "the faces and their numbers")}<figcaption>Figure 0. The hot part with the '
        f"number of each face, as the tables name them (a colour per face).</figcaption></figure>",
        f'<figure>{_img(overlay, "hot and cold part overlaid")}<figcaption>Figure 1. Hot part (red) and cold '
        f'part (blue) overlaid, as in the paper\'s Fig. 8 and 10. The displacement is drawn '
        f'<b>{scale:.3g} times</b> its size: the largest displacement, {largest:.4g} mm, appears as '
        f'{largest * scale:.4g} mm (part diagonal {result.part.diagonal:.4g} mm). Faces are translucent, '
        f'edges drawn as lines.</figcaption></figure>']
    if errors is not None:
        left_out = len([f for f in report.faces if f.nodes > 0]) - len(error_faces)
        more = f" {left_out} faces with fewer nodes are not drawn." if left_out > 0 else ""
        figures.append(
            f'<figure>{_img(errors, "per-face error maps")}<figcaption>Figure 2. Per face, each FE node '
            f"coloured by its distance to the cold part (eq. 21, mm); circles are the face's nodes, diamonds "
            f"the nodes of its edges, the grey area is the trimmed face, in its parameters scaled to mm along "
            f"the surface. All maps share one colour scale, from 0 to the larger of the largest error and the "
            f"tolerance (marked on the colour bar); errors above the tolerance are drawn in reds. Each title "
            f"compares the largest error drawn with the tolerance (✓ within, ✗ beyond); a black ring marks the "
            f"face's worst node.{_e(more)}</figcaption></figure>")
    if curvature is not None:
        figures.append(
            f'<figure>{_img(curvature, "mean curvature hot and cold")}<figcaption>Figure 3. Mean curvature '
            f"H (1/mm) of the hot and the morphed surface of the largest faces "
            f"({_e(', '.join(map(str, curv_faces)))}), "
            f"as in the paper's Fig. 9 and 11, and their difference; hot and cold share one colour scale "
            f"symmetric about zero up to the 99th percentile of |H| (red convex, blue concave); curvatures "
            f"below a noise floor (10⁻⁹ of the larger of 1/diagonal and the face's largest |H|) are drawn as "
            f"zero, and a panel all below it is titled flat (no change for the difference). A smooth difference "
            f"means the morph added no wiggles."
            f"</figcaption></figure>")
    return figures


def write_html(result, path: str | os.PathLike, scale: float | None = None, *, interactive: bool = True) -> None:
    """Write the report page of ``result`` to ``path`` atomically (a temporary file in the same folder,
    then ``os.replace``): a reader sees the old file or the whole new one, never a part.

    Raises ValueError for a non-positive ``scale``; :class:`~hot2cold.errors.OutputError` (an OSError)
    when the folder cannot be written.
    """
    path = Path(path)
    text = render_html(result, scale, interactive=interactive)
    write_atomically([(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))])
    log.info("wrote %s (%.0f kB)", path, len(text.encode("utf-8")) / 1024)
