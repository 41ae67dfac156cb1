"""The report's interactive 3D view: an HTML section that needs nothing outside the page and draws before the
page's ``load`` event (a print or a headless screenshot taken at load shows it).

:func:`viewer_html` turns a :class:`~hot2cold.views.scene.Scene` into a ``<section>`` holding

* an import map whose entries are three.js and its OrbitControls (files of this folder, see ``README.md`` here
  for version and licence) as base64 ``data:`` URLs, their imports of each other named by bare specifiers
  (:data:`MODULES`): the browser loads the module graph from the page itself, before the page's script runs;
* the geometry as JSON of base64 strings, each a little-endian typed array (float32 positions, uint16 or uint32
  indices), decoded synchronously (``atob``);
* ``viewer.js`` (this folder), the page's own module script, inline: a module script runs before the page's
  ``DOMContentLoaded`` and ``load`` events, and it draws without awaiting anything.

The colour bars are plain HTML drawn here from matplotlib's viridis, which the script uses for the surface too.
"""
from __future__ import annotations

import base64
import functools
import html
import json
import logging
from importlib import resources

import numpy as np
from matplotlib import colormaps

from .. import scene as _scene

log = logging.getLogger(__name__)

#: three.js as bundled here (``README.md``).
THREE_VERSION = "0.185.1"

#: The bundled modules by the bare specifier the page's import map gives each (file, specifier), and the
#: relative imports of the files rewritten to those specifiers (file, import as written, specifier).
MODULES = (("three.core.min.js", "three-core"), ("three.module.min.js", "three"),
           ("OrbitControls.js", "three-orbit-controls"))
LINKS = (("three.module.min.js", '"./three.core.min.js"', '"three-core"'),)

#: Colour map of the deviation (matplotlib's name) and how many steps the page gets.
COLOUR_MAP = "viridis"
_STEPS = 256

STYLE = """
.v3 { margin: 0.5em 0 1.5em 0; }
.v3-stage { position: relative; height: 560px; border: 1px solid #d0d0d0; background: #fff; }
.v3-stage canvas { display: block; width: 100%; height: 100%; }
.v3-status { position: absolute; left: 0.8em; top: 0.6em; color: #777; font-size: 0.9em; }
.v3-info { position: absolute; left: 0.8em; bottom: 0.8em; max-width: 55%; background: rgba(255,255,255,0.92);
           border: 1px solid #c8c8c8; border-radius: 4px; padding: 0.4em 0.7em; font-size: 0.88em; }
.v3-bar { position: absolute; right: 0.6em; top: 0.6em; bottom: 0.6em; width: 11em; font-size: 0.78em;
          background: rgba(255,255,255,0.85); }
.v3-bar .title { position: absolute; left: 0.4em; top: 0.3em; white-space: nowrap; font-weight: 600; }
.v3-bar .ramp { position: absolute; left: 0.5em; top: 2.2em; bottom: 4.2em; width: 14px; border: 1px solid #888; }
.v3-bar .tick, .v3-bar .tol { position: absolute; left: 22px; transform: translateY(50%); white-space: nowrap; }
.v3-bar .tick::before { content: ""; position: absolute; left: -8px; width: 5px; top: 50%; border-top: 1px solid #555; }
.v3-bar .tol { color: #c62828; font-weight: 600; }
.v3-bar .tol::before { content: ""; position: absolute; left: -24px; width: 22px; top: 50%;
                       border-top: 2px solid #c62828; }
.v3-bar .notes { position: absolute; left: 0.4em; right: 0.2em; bottom: 0.3em; line-height: 1.25; }
.v3-bar .notes i { display: inline-block; width: 14px; height: 10px; background: #b4b4b4; margin-right: 4px;
                   border: 1px solid #888; vertical-align: middle; }
.v3-controls { display: flex; flex-wrap: wrap; gap: 0.4em 1.4em; align-items: center; margin: 0.5em 0;
               font-size: 0.9em; }
.v3-controls input[type=range] { width: 12em; vertical-align: middle; }
tr.picked td { background: #ffe08a !important; }
"""


@functools.lru_cache(maxsize=1)
def import_map() -> str:
    """The ``<script type="importmap">`` of the bundled modules: each as a base64 ``data:`` URL under its
    specifier (:data:`MODULES`), its relative imports rewritten (:data:`LINKS`)."""
    folder = resources.files(__name__)
    imports = {}
    for name, specifier in MODULES:
        text = folder.joinpath(name).read_text(encoding="utf-8")
        for file, written, bare in LINKS:
            if file == name:
                if written not in text:
                    raise RuntimeError(f"the bundled {name} does not import {written}: the 3D view cannot link it")
                text = text.replace(written, bare)
        imports[specifier] = "data:text/javascript;base64," + base64.b64encode(text.encode("utf-8")).decode("ascii")
    return f'<script type="importmap">{_json({"imports": imports})}</script>'


def _script() -> str:
    text = resources.files(__name__).joinpath("viewer.js").read_text(encoding="utf-8")
    if "</script" in text.lower():
        raise RuntimeError("viewer.js must not contain '</script'")
    return text


def _pack(array: np.ndarray, kind: str) -> dict:
    """A typed array for the page: ``{"type": "float32" | "uint16" | "uint32", "data": base64(bytes)}``;
    ``kind`` "float" or "index" (uint16 when every value fits)."""
    if kind == "float":
        dtype, name = "<f4", "float32"
    elif len(array) == 0 or int(array.max()) < 65536:
        dtype, name = "<u2", "uint16"
    else:
        dtype, name = "<u4", "uint32"
    raw = np.ascontiguousarray(array, dtype=dtype).tobytes()
    return {"type": name, "data": base64.b64encode(raw).decode("ascii")}


def _lut() -> np.ndarray:
    """The colour map as ``(256, 3)`` uint8 sRGB."""
    return np.round(colormaps[COLOUR_MAP](np.linspace(0.0, 1.0, _STEPS))[:, :3] * 255).astype(np.uint8)


def _json(payload) -> str:
    """JSON safe inside a ``<script>`` element."""
    return json.dumps(payload, separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")


def _fmt(x: float) -> str:
    return f"{x:.3g}"


def _ramp() -> str:
    """The colour map as a CSS gradient from the bottom up."""
    lut = _lut()
    stops = ", ".join(f"rgb({r},{g},{b}) {100 * i / 15:.1f}%" for i, (r, g, b) in
                      enumerate(lut[np.linspace(0, _STEPS - 1, 16).astype(int)]))
    return f"linear-gradient(to top, {stops})"


def _displacement_bar(scene: _scene.Scene, hidden: bool) -> str:
    """The colour bar of the displacement magnitude, from 0 to ``scene.displacement_top`` mm (``hidden`` while
    the view is coloured by the deviation)."""
    top = scene.displacement_top
    parts = ['<div class="title">displacement [mm]</div>', f'<div class="ramp" style="background: {_ramp()}">']
    parts += [f'<span class="tick" style="bottom: {100 * t / top:.2f}%">{_fmt(t)}</span>'
              for t in _scene.ticks(top)]
    parts.append('</div><div class="notes"><div>hot to cold, true size</div></div>')
    return f'<div class="v3-bar" id="v3-bar-displacement"{" hidden" * hidden}>' + "".join(parts) + "</div>"


def _colour_bar(scene: _scene.Scene, hidden: bool = False) -> str:
    """The colour bar: viridis from 0 (bottom) to ``scene.scale_top`` (top) in mm, the tolerance marked
    (``hidden`` while the view is coloured by the displacement)."""
    top = scene.scale_top
    parts = ['<div class="title">deviation [mm]</div>',
             f'<div class="ramp" style="background: {_ramp()}">']
    tol = scene.tolerance
    for t in _scene.ticks(top):
        if tol is None or abs(t - tol) > 0.06 * top:              # no tick label under the tolerance's
            parts.append(f'<span class="tick" style="bottom: {100 * t / top:.2f}%">{_fmt(t)}</span>')
    if tol is not None and tol <= top:
        parts.append(f'<span class="tol" style="bottom: {100 * tol / top:.2f}%">tolerance {_fmt(tol)}</span>')
    parts.append("</div>")
    notes = []
    if tol is None:
        notes.append("<div>no tolerance set</div>")
    elif tol > top:        # every deviation within the tolerance: a fact, not an alarm (the verdict has the colours)
        notes.append(f"<div>tolerance {_fmt(tol)} mm, above the scale</div>")
    if not np.isfinite(scene.deviation).all():
        notes.append("<div><i></i>no FE nodes</div>")
    parts.append('<div class="notes">' + "".join(notes) + "</div>")
    return f'<div class="v3-bar" id="v3-bar-deviation"{" hidden" * hidden}>' + "".join(parts) + "</div>"


#: What the 3D view can colour the part by (the first: the default), with the words of its switch.
COLOURS = {"deviation": "deviation from the field", "displacement": "displacement (hot to cold)"}


def viewer_html(scene: _scene.Scene, colour: str = "deviation") -> str:
    """The 3D view's ``<section>`` (canvas, controls, colour bars, data and scripts) for the report page;
    ``colour``: what it colours the part by first (a key of :data:`COLOURS`)."""
    if colour not in COLOURS:
        raise ValueError(f"colour must be one of {', '.join(COLOURS)}, got {colour!r}")
    s = scene
    data = {
        "hot": _pack(s.hot, "float"), "displacement": _pack(s.displacement, "float"),
        "deviation": _pack(s.deviation, "float"),
        "triangles": _pack(s.triangles, "index"), "triangleFace": _pack(s.triangle_face, "index"),
        "outlines": _pack(s.outlines, "index"),
        "nodeHot": _pack(s.node_hot, "float"), "nodeDisplacement": _pack(s.node_displacement, "float"),
        "nodeDeviation": _pack(s.node_deviation, "float"),
        "lut": base64.b64encode(_lut().tobytes()).decode("ascii"),
        "scaleTop": s.scale_top, "displacementTop": s.displacement_top, "tolerance": s.tolerance,
        "exaggeration": s.exaggeration,
        "view": s.view.tolist(), "origin": s.origin.tolist(), "faces": s.faces,
    }
    shown, total = len(s.node_hot), s.nodes_total
    nodes_label = (f"FE nodes ({shown:,} of {total:,}, a random sample)" if shown < total
                   else f"FE nodes ({total:,})")
    top = max(1.0, 4.0 * s.exaggeration)
    options = "".join(f'<option value="{key}"{" selected" if key == colour else ""}>{words}</option>'
                      for key, words in COLOURS.items())
    return f"""<section class="v3" id="v3">
<div class="v3-stage" id="v3-stage"><canvas id="v3-canvas" aria-label="3D view of the cold part"></canvas>
<div class="v3-status" id="v3-status">Loading the 3D view…</div>
{_colour_bar(s, hidden=colour != "deviation")}
{_displacement_bar(s, hidden=colour != "displacement")}
<div class="v3-info" id="v3-info" hidden></div></div>
<div class="v3-controls">
<label>colour <select id="v3-colour">{options}</select></label>
<label>displacement × <input type="range" id="v3-scale" min="0" max="{top:.6g}" step="{top / 1000:.6g}"
 value="{s.exaggeration:.6g}"> <output id="v3-scale-value">{s.exaggeration:.3g}</output></label>
<button type="button" id="v3-true">true size (× 1)</button>
<label><input type="checkbox" id="v3-ghost" checked> hot part (ghost)</label>
<label><input type="checkbox" id="v3-outlines" checked> face outlines</label>
<label><input type="checkbox" id="v3-nodes"> {html.escape(nodes_label)}</label>
<button type="button" id="v3-reset">reset view</button>
</div>
<script type="application/json" id="v3-data">{_json(data)}</script>
{import_map()}
<script type="module">
{_script()}
</script>
</section>"""
