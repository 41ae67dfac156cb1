"""The HTML report's interactive 3D view (twisted blade), checked in headless Chromium.

The page is opened from file:// with every request outside file:, blob: and data: aborted (and none may be
made): the WebGL canvas must draw the part in several colours by the page's load event, the exaggeration
slider, the colour switch and the FE nodes checkbox must change the picture, a click on the part must name one
of its faces and mark its table row, and nothing may be logged as an error.  Chromium (Debian's ``chromium``)
and the ``playwright`` package are required: without them the browser tests fail, saying what to install.
"""
from __future__ import annotations

import base64
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from hot2cold.core.model import Role
from hot2cold.views import page as html_report
from hot2cold.views import pictures, scene as scene_mod, viewer

LOCAL = ("file:", "blob:", "data:")


# ------------------------------------------------------------------------------------------ the data
@pytest.fixture(scope="module")
def mesh(blade):
    return pictures.mesh_of(blade)


@pytest.fixture(scope="module")
def scene(blade, mesh):
    return scene_mod.build_scene(blade, mesh)


@pytest.fixture(scope="module")
def html_path(blade, mesh, tmp_path_factory, monkeypatch_module):
    """The page written once, the pictures drawn on the fixture's mesh."""
    monkeypatch_module.setattr(pictures, "mesh_of", lambda result, deflection=None: mesh)
    path = tmp_path_factory.mktemp("html3d") / "report.html"
    html_report.write_html(blade, path)
    return path


@pytest.fixture(scope="module")
def monkeypatch_module():
    with pytest.MonkeyPatch.context() as mp:
        yield mp


def _unpack(entry: dict) -> np.ndarray:
    return np.frombuffer(base64.b64decode(entry["data"]), dtype={
        "float32": "<f4", "uint16": "<u2", "uint32": "<u4"}[entry["type"]])


def _payload(text: str) -> dict:
    m = re.search(r'<script type="application/json" id="v3-data">(.*?)</script>', text, re.S)
    assert m, "the page has no 3D view data"
    return json.loads(m.group(1))


def test_scene_moves_each_vertex_from_hot_to_cold(blade, mesh, scene):
    cold = pictures.cold_vertices(blade, mesh)
    assert scene.hot.dtype == np.float32 and scene.hot.shape == mesh.vertices.shape
    np.testing.assert_allclose(scene.hot + scene.origin, mesh.vertices, atol=1e-4)
    np.testing.assert_allclose(scene.hot + scene.displacement + scene.origin, cold, atol=1e-4)
    assert np.array_equal(scene.triangles, mesh.triangles) and np.array_equal(scene.triangle_face, mesh.face)
    # outlines: vertex pairs of one face each, along the face's border
    faces_of = np.full(len(mesh.vertices), -1)
    faces_of[mesh.triangles] = mesh.face[:, None]
    assert len(scene.outlines) and np.array_equal(faces_of[scene.outlines[:, 0]], faces_of[scene.outlines[:, 1]])


def test_deviation_interpolates_the_node_errors_of_each_face(blade, mesh, scene):
    """Within the range of the errors of each face's nodes (and its edges'); exact at a node's target."""
    err = blade.node_errors
    dev = scene.deviation
    for k in range(len(blade.part.faces)):
        verts = np.unique(mesh.triangles[mesh.face == k])
        nodes = scene_mod._face_nodes(blade, k)
        vals = err[nodes][np.isfinite(err[nodes])]
        if not len(vals):
            assert np.isnan(dev[verts]).all()
            continue
        assert np.isfinite(dev[verts]).all()
        assert vals.min() * (1 - 1e-5) <= dev[verts].min() and dev[verts].max() <= vals.max() * (1 + 1e-5)
    # a vertex placed on a node's cold target takes that node's error
    k = int(np.argmax([f.nodes for f in blade.report.faces]))
    node = blade.classification.nodes_of(Role.FACE, k)[0]
    vertex = mesh.triangles[mesh.face == k][0, 0]
    cold = pictures.cold_vertices(blade, mesh)
    cold[vertex] = blade.field.points[node] + blade.field.displacements[node]
    assert scene_mod.surface_deviation(blade, mesh, cold)[vertex] == pytest.approx(err[node], rel=1e-6)
    assert scene.scale_top >= np.nanmax(err[blade.classification.used])


def test_nodes_are_subsampled_to_the_limit(blade, mesh):
    few = scene_mod.build_scene(blade, mesh, max_nodes=1000)
    assert len(few.node_hot) == 1000 and few.nodes_total == len(blade.field.points)
    again = scene_mod.build_scene(blade, mesh, max_nodes=1000)
    assert np.array_equal(few.node_hot, again.node_hot)                      # the same sample every time


def test_page_embeds_the_scene_and_three_js_packed(scene, html_path):
    text = html_path.read_text(encoding="utf-8")
    data = _payload(text)
    np.testing.assert_array_equal(_unpack(data["hot"]).reshape(-1, 3), scene.hot)
    np.testing.assert_array_equal(_unpack(data["triangles"]).reshape(-1, 3), scene.triangles)
    assert data["triangles"]["type"] == "uint16"                    # fewer than 65 536 vertices
    found = re.search(r'<script type="importmap">(.*?)</script>', text, re.S)
    assert found and text.index('<script type="importmap">') < text.index('<script type="module">')
    imports = json.loads(found.group(1))["imports"]
    assert set(imports) == {"three-core", "three", "three-orbit-controls"}
    module = base64.b64decode(imports["three"].removeprefix("data:text/javascript;base64,")).decode()
    assert '"./three.core.min.js"' not in module and '"three-core"' in module
    readme = (Path(viewer.__file__).parent / "README.md").read_text(encoding="utf-8")
    assert viewer.THREE_VERSION in readme and "MIT" in readme
    assert (Path(viewer.__file__).parent / "LICENSE.three").read_text().startswith("The MIT License")
    # nothing to load: no src or href attributes but the pictures' data URLs, no http(s) anywhere in the markup
    assert not re.search(r"""(src|href)\s*=\s*["'](?!data:image/png;base64,)""", text)
    assert "<link" not in text.lower()
    rows = re.findall(r'<tr id="face-row-(\d+)" data-face="\1">', text)
    assert [int(r) for r in rows] == [f["index"] for f in scene.faces]
    assert "tolerance" in text and "deviation [mm]" in text and "displacement [mm]" in text


def test_colour_bar_marks_the_tolerance():
    tol = 1e-3
    assert scene_mod.scale_top(np.array([4e-4, np.nan]), tol) == tol       # raised to show the tolerance
    assert scene_mod.scale_top(np.array([4e-3]), tol) == 4e-3
    assert scene_mod.scale_top(np.array([1e-6]), tol) == 1e-6               # far below: the tolerance is named
    assert scene_mod.scale_top(np.array([np.nan]), None) == 1.0


def test_page_without_the_view_has_no_script(blade, mesh, monkeypatch):
    monkeypatch.setattr(pictures, "mesh_of", lambda result, deflection=None: mesh)
    text = html_report.render_html(blade, interactive=False)
    assert "<script" not in text and "v3-data" not in text


# ----------------------------------------------------------------------------------------- the browser
class _Session:
    """One opened page with what it asked the network for and what it logged."""

    def __init__(self, browser, path: Path):
        self.context = browser.new_context(viewport={"width": 1200, "height": 900})
        self.requests, self.blocked, self.errors = [], [], []
        self.context.route("**/*", self._route)
        self.page = self.context.new_page()
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.on("console", lambda m: self.errors.append(m.text) if m.type == "error" else None)
        self.page.on("pageerror", lambda e: self.errors.append(f"page error: {e}"))
        self.page.goto(path.as_uri())
        self.page.wait_for_selector("#v3-stage[data-ready]", timeout=60_000)

    def _route(self, route):
        if route.request.url.startswith(LOCAL):
            route.continue_()
        else:
            self.blocked.append(route.request.url)
            route.abort()

    def pixels(self) -> np.ndarray:
        """The canvas as shown: RGB floats ``(h, w, 3)``."""
        self.page.wait_for_timeout(150)                     # let a frame reach the screen
        png = self.page.locator("#v3-canvas").screenshot()
        return imread(io.BytesIO(png), format="png")[..., :3]

    def set_slider(self, value: float) -> None:
        self.page.eval_on_selector("#v3-scale", "(el, v) => { el.value = String(v); "
                                   "el.dispatchEvent(new Event('input', { bubbles: true })); }", value)


@pytest.fixture(scope="module")
def session(browser, html_path):
    s = _Session(browser, html_path)
    yield s
    s.context.close()


def _part_mask(rgb: np.ndarray) -> np.ndarray:
    """Pixels of the coloured part: clearly not white or grey (the background, the ghost's pale red
    excepted by asking for a green or blue channel above red, as viridis has)."""
    return (rgb.max(axis=2) - rgb.min(axis=2) > 0.15) & (np.maximum(rgb[..., 1], rgb[..., 2]) > rgb[..., 0])


def test_view_renders_offline_without_errors(session):
    s = session
    assert s.page.get_attribute("#v3-stage", "data-ready") == "true", s.page.text_content("#v3-status")
    rgb = s.pixels()
    width = rgb.shape[1]
    drawn = rgb[:, : int(0.8 * width)]                                # left of the colour bar
    assert (drawn.min(axis=2) < 0.9).mean() > 0.03                    # not blank
    colours = np.unique((drawn[_part_mask(drawn)] * 15).round().astype(int), axis=0)
    assert len(colours) >= 10, len(colours)                           # several colours (viridis, shaded)
    assert _part_mask(drawn).mean() > 0.02
    assert not s.blocked, s.blocked
    assert all(url.startswith(LOCAL) for url in s.requests), s.requests
    assert not s.errors, s.errors


def test_slider_and_nodes_change_the_picture(session):
    s = session
    before = s.pixels()
    start = float(s.page.input_value("#v3-scale"))
    s.set_slider(4 * start)
    after = s.pixels()
    assert np.abs(after - before).max(axis=2).__gt__(0.1).mean() > 0.005
    assert s.page.text_content("#v3-scale-value") == f"{4 * start:.3g}" or \
        float(s.page.text_content("#v3-scale-value")) == pytest.approx(4 * start, rel=1e-2)
    s.set_slider(start)
    assert np.abs(s.pixels() - before).max() < 0.05                   # back where it was
    s.page.check("#v3-nodes")
    with_nodes = s.pixels()
    s.page.uncheck("#v3-nodes")
    assert np.abs(with_nodes - before).max(axis=2).__gt__(0.1).mean() > 0.005
    assert not s.errors, s.errors


def test_click_on_the_part_shows_the_face_row(session, blade):
    s = session
    rgb = s.pixels()
    mask = _part_mask(rgb)
    mask[:, int(0.8 * mask.shape[1]):] = False
    ys, xs = np.nonzero(mask)
    assert len(ys), "no part pixel to click on"
    centre = np.array([np.median(ys), np.median(xs)])
    pick = int(np.argmin(((np.column_stack([ys, xs]) - centre) ** 2).sum(axis=1)))
    box = s.page.locator("#v3-canvas").bounding_box()
    scale = box["width"] / rgb.shape[1]
    s.page.mouse.click(box["x"] + (xs[pick] + 0.5) * scale, box["y"] + (ys[pick] + 0.5) * scale)
    s.page.wait_for_selector("#v3-info:not([hidden])", timeout=5_000)
    k = int(s.page.get_attribute("#v3-info", "data-face"))
    indices = [f.index for f in blade.report.faces]
    assert k in indices
    text = s.page.text_content("#v3-info")
    assert text.startswith(f"face {k}") and f"{blade.report.faces[k].nodes:,} FE nodes" in text
    assert "deviation here" in text
    assert s.page.get_attribute(f"#face-row-{k}", "class") == "picked"
    assert s.page.locator("tr.picked").count() == 1
    other = next(i for i in indices if i != k)                        # a row of the table picks its face
    s.page.click(f"#face-row-{other}")
    assert s.page.get_attribute("#v3-info", "data-face") == str(other)
    assert s.page.locator("tr.picked").count() == 1
    assert not s.errors, s.errors


def test_view_is_drawn_at_load(browser, html_path):
    """The view draws while the page loads: when the load event has fired it is ready and the canvas shows the
    part (a print or a headless screenshot taken at load shows it, not "Loading")."""
    context = browser.new_context(viewport={"width": 1200, "height": 900})
    try:
        page = context.new_page()
        page.goto(html_path.as_uri(), wait_until="load")
        assert page.get_attribute("#v3-stage", "data-ready") == "true"
        assert not page.is_visible("#v3-status")
        rgb = imread(io.BytesIO(page.locator("#v3-canvas").screenshot()), format="png")[..., :3]
        assert _part_mask(rgb[:, : int(0.8 * rgb.shape[1])]).mean() > 0.02
    finally:
        context.close()


def test_colour_by_displacement(session, scene):
    """The view can colour the part by the displacement's length: the picture and the colour bar change, and
    back; the displacement bar runs from 0 to the largest displacement."""
    s = session
    before = s.pixels()
    assert s.page.is_visible("#v3-bar-deviation") and not s.page.is_visible("#v3-bar-displacement")
    s.page.select_option("#v3-colour", "displacement")
    after = s.pixels()
    assert np.abs(after - before).max(axis=2).__gt__(0.1).mean() > 0.01
    assert s.page.is_visible("#v3-bar-displacement") and not s.page.is_visible("#v3-bar-deviation")
    largest = float(np.linalg.norm(scene.displacement, axis=1).max())
    assert scene.displacement_top == pytest.approx(largest, rel=1e-6)     # the top of the bar: the largest
    s.page.select_option("#v3-colour", "deviation")
    assert np.abs(s.pixels() - before).max() < 0.05
    assert not s.errors, s.errors
