"""The HTML report: one self-contained page with the paper-style tables and the pictures (twisted blade)."""
from __future__ import annotations

import base64
import io
import os
import re
import struct
import sys
from html.parser import HTMLParser
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from matplotlib.image import imread

from hot2cold.views import page as html_report
from hot2cold.views import pictures as visual
from hot2cold.core.bspline import evaluate_surface

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def mesh(blade):
    return visual.mesh_of(blade)


@pytest.fixture(scope="module")
def page(blade, tmp_path_factory):
    """The page written once (default scale), its text, and the global matplotlib state before and after."""
    before = (matplotlib.get_backend(), dict(matplotlib.rcParams), "matplotlib.pyplot" in sys.modules)
    path = tmp_path_factory.mktemp("html") / "report.html"
    html_report.write_html(blade, path)
    after = (matplotlib.get_backend(), dict(matplotlib.rcParams), "matplotlib.pyplot" in sys.modules)
    return path, path.read_text(encoding="utf-8"), before, after


class _Tables(HTMLParser):
    """Rows (lists of cell texts) of every table, by the table's class; and every img src."""

    def __init__(self):
        super().__init__()
        self.tables: dict[str, list[list[str]]] = {}
        self.images: list[str] = []
        self._table = None
        self._row = None
        self._cell = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "table":
            self._table = self.tables.setdefault(attrs.get("class") or f"table{len(self.tables)}", [])
        elif tag == "tr" and self._table is not None:
            self._row = []
        elif tag in ("td", "th") and self._row is not None:
            self._cell = []
        elif tag == "img":
            self.images.append(attrs.get("src", ""))

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self._table.append(self._row)
            self._row = None
        elif tag == "table":
            self._table = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def _parse(text: str) -> _Tables:
    parser = _Tables()
    parser.feed(text)
    return parser


def _png_size(png: bytes) -> tuple[int, int]:
    assert png[:8] == PNG_SIGNATURE
    length, kind = struct.unpack(">I4s", png[8:16])
    assert kind == b"IHDR" and length == 13
    return struct.unpack(">II", png[16:24])


@pytest.mark.heavy
def test_page_has_a_row_per_face_and_edge_matching_the_report(blade, page):
    _, text, _, _ = page
    tables = _parse(text).tables
    faces, edges = tables["faces"], tables["edges"]
    report = blade.report
    assert len(faces) == len(report.faces) + 1 and len(edges) == len(report.edges) + 1   # + header
    head = faces[0]
    assert {"face", "FE nodes", "control points", "Δmax [mm]", "Δmean [mm]"} <= set(head)
    col = {name: head.index(name) for name in head}
    for row, f in zip(faces[1:], report.faces):
        assert row[col["face"]] == str(f.index)
        assert row[col["FE nodes"]] == str(f.nodes)
        assert row[col["control points"]] == f.control_points
        assert float(row[col["Δmax [mm]"]]) == pytest.approx(f.delta_max, rel=1e-2)
        assert float(row[col["Δmean [mm]"]]) == pytest.approx(f.delta_mean, rel=1e-2)
    ecol = {name: edges[0].index(name) for name in edges[0]}
    tangent = {g["edge"]: g for g in report.g1}
    assert tangent, "the blade has tangent edges"
    for row, e in zip(edges[1:], report.edges):
        assert row[ecol["edge"]] == str(e.index)
        assert row[ecol["FE nodes"]] == str(e.nodes)
        if e.index in tangent:
            assert float(row[ecol["kink before"]].rstrip("°")) == pytest.approx(
                tangent[e.index]["kink_before_max"], rel=1e-2)
            assert float(row[ecol["kink after"]].rstrip("°")) == pytest.approx(
                tangent[e.index]["kink_after_max"], rel=1e-2)
        else:
            assert row[ecol["kink before"]] == "–"


def test_page_has_the_overall_checks(blade, page):
    _, text, _, _ = page
    report = blade.report
    solid = report.solids[0]
    assert "valid" in text and "free edges" in text
    assert f"{solid.volume_hot:.6g}" in text and f"{solid.volume_cold:.6g}" in text
    nodes = next(t for t in _parse(text).tables.values() if t[0][0] == "FE nodes")
    assert nodes[1][:2] == [str(report.nodes_total), str(report.nodes_used)]
    assert nodes[1][-1] == str(report.nodes_ignored) and report.nodes_ignored > 0
    assert "G1 continuity" in text and "Tolerance" in text


def test_page_is_self_contained_with_four_valid_pngs(page):
    """The face numbers (issue 17), the overlay, the error maps and the curvature maps."""
    _, text, _, _ = page
    assert "<link" not in text.lower()
    # the only scripts are the 3D view's, inline: its data, the import map of three.js (data: URLs) and its module
    assert re.findall(r"<script\b[^>]*>", text, re.I) == ['<script type="application/json" id="v3-data">',
                                                         '<script type="importmap">', '<script type="module">']
    assert not re.search(r"""(src|href)\s*=\s*["'](?!data:image/png;base64,)""", text)
    images = _parse(text).images
    assert len(images) == 4
    for src in images:
        png = base64.b64decode(src.removeprefix("data:image/png;base64,"), validate=True)
        w, h = _png_size(png)
        assert 600 <= w <= 3000 and 250 <= h <= 3000, (w, h)
        pixels = imread(io.BytesIO(png), format="png")
        assert pixels.shape[:2] == (h, w)
        assert pixels[..., :3].std() > 0.05                          # not a blank picture


def test_overlay_shows_hot_red_and_cold_blue_with_the_scale_in_the_caption(blade, page):
    _, text, _, _ = page
    scale = visual.displacement_scale(blade)
    assert scale * blade.report.max_displacement == pytest.approx(0.05 * blade.part.diagonal)
    assert f"{scale:.3g} times" in text
    png = base64.b64decode(_parse(text).images[1].removeprefix("data:image/png;base64,"))      # after the numbers
    rgb = imread(io.BytesIO(png), format="png")[..., :3]
    reddish = (rgb[..., 0] > rgb[..., 2] + 0.2).sum()
    bluish = (rgb[..., 2] > rgb[..., 0] + 0.2).sum()
    assert reddish > 500 and bluish > 500          # hot alone and exaggerated cold alone both visible


def test_rendering_leaves_matplotlib_global_state_alone(page):
    _, _, before, after = page
    assert before[0] == after[0]                 # backend
    assert before[1] == after[1]                 # rcParams
    assert after[2] == before[2]                 # pyplot not imported by the report


@pytest.mark.heavy
def test_written_atomically_over_an_old_file(blade, mesh, tmp_path, monkeypatch):
    """The page goes to a temporary file in the same folder, then os.replace; nothing is left behind, and
    when drawing fails the old file stays as it was."""
    path = tmp_path / "report.html"
    path.write_text("old")
    replaced = []
    real_replace = os.replace

    def spy(src, dst):
        replaced.append((Path(src), Path(dst), Path(src).read_text(encoding="utf-8")[:15]))
        real_replace(src, dst)

    monkeypatch.setattr(html_report.os, "replace", spy)
    # cheap stand-ins for the pictures (they are checked above): 1x1 PNGs
    tiny = _tiny_png()
    scales = []
    monkeypatch.setattr(visual, "overlay_png", lambda result, scale, **kw: scales.append(scale) or tiny)
    monkeypatch.setattr(visual, "error_maps_png", lambda *a, **kw: tiny)
    monkeypatch.setattr(visual, "curvature_png", lambda *a, **kw: tiny)
    monkeypatch.setattr(visual, "mesh_of", lambda result, deflection=None: mesh)
    html_report.write_html(blade, path, scale=25.0)
    assert len(replaced) == 1
    src, dst, head = replaced[0]
    assert dst == path and src.parent == path.parent and src != path and head.startswith("<!DOCTYPE html>")
    assert scales == [25.0] and "<b>25 times</b>" in path.read_text(encoding="utf-8")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.html"]
    umask = os.umask(0o022)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask           # as any new file, not mkstemp's 0o600

    def broken(*a, **kw):
        raise RuntimeError("drawing failed")

    monkeypatch.setattr(visual, "curvature_png", broken)
    path.write_text("old")
    with pytest.raises(RuntimeError):
        html_report.write_html(blade, path)
    assert path.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["report.html"]
    for bad in (0.0, -2.0, float("nan")):
        with pytest.raises(ValueError):
            html_report.write_html(blade, path, scale=bad)
    assert path.read_text() == "old"


def _tiny_png() -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(1, 1), dpi=10)
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def test_mesh_parameters_put_hot_and_cold_on_their_surfaces(blade, mesh):
    """The pictures' premise: a mesh vertex at (u, v) of face k is S_hot(u, v), and the cold surfaces at the
    same parameters are within the largest displacement of it."""
    cold = visual.cold_vertices(blade, mesh)
    for k, face in enumerate(blade.part.faces):
        verts = np.unique(mesh.triangles[mesh.face == k])
        hot = evaluate_surface(face.surface, mesh.uv[verts, 0], mesh.uv[verts, 1])
        np.testing.assert_allclose(hot, mesh.vertices[verts], atol=1e-6)
    moved = np.linalg.norm(cold - mesh.vertices, axis=1)
    assert 0.5 * blade.report.max_displacement < moved.max() <= 1.05 * blade.report.max_displacement


def test_default_faces_of_the_maps(blade, mesh):
    assert visual.error_faces(blade) == sorted(f.index for f in blade.report.faces if f.nodes > 0)
    assert visual.error_faces(blade, max_faces=2) == sorted(
        f.index for f in sorted(blade.report.faces, key=lambda f: -f.nodes)[:2])
    v = mesh.vertices[mesh.triangles]
    area = np.bincount(mesh.face, weights=0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]),
                                                                 axis=1))
    largest = visual.curvature_faces(blade, mesh=mesh)
    assert largest == list(np.argsort(-area)[:4])
    # the two end caps (planar, 2x2 nets) are the smallest faces and left out
    caps = {f.index for f in blade.part.faces if f.surface.shape == (2, 2)}
    assert len(caps) == 2 and not caps & set(largest)


def test_inside_mask_is_the_triangles_up_to_a_third_of_a_grid_step():
    # an L-shaped domain: the unit square without its upper-right quarter, in four triangles
    xy = np.array([[0, 0], [1, 0], [1, 0.5], [0.5, 0.5], [0.5, 1], [0, 1]], float)
    tris = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]])
    gx, gy = np.linspace(0, 1, 61), np.linspace(0, 1, 41)
    mask = visual._inside_mask(xy, tris, gx, gy)
    assert mask.shape == (41, 61)
    px, py = np.meshgrid(gx, gy)
    exact = ~((px > 0.5) & (py > 0.5))
    # distance to the L's boundary inside the square (the notch's two sides)
    near = ((np.abs(px - 0.5) < (gx[1] - gx[0]) / 3) & (py >= 0.5)) | \
           ((np.abs(py - 0.5) < (gy[1] - gy[0]) / 3) & (px >= 0.5))
    assert np.array_equal(mask[~near], exact[~near])
    assert mask[exact & ~near].all() and 0.70 < mask.mean() < 0.80


def test_curvature_is_positive_on_the_round_leading_and_trailing_edges(blade, mesh):
    """The blade's two edge strips (the faces with the largest curvature) are convex everywhere: H > 0
    with the sign the pictures use; the morph changes H there by a few per cent at most."""
    strips = [f.index for f in blade.part.faces if f.surface.shape != (2, 2)]
    curv = {k: visual.face_curvature(blade, k, mesh, grid_points=5000) for k in strips}
    peak = {k: np.nanmax(c.hot) for k, c in curv.items()}
    rounds = sorted(peak, key=peak.get)[-2:]
    for k in rounds:
        c = curv[k]
        h = c.hot[c.inside]
        assert c.inside.mean() > 0.9 and np.isfinite(h).all()
        assert (h > 0).all() and peak[k] > 1.0                   # radius below 0.5 mm
        assert np.abs(c.cold - c.hot)[c.inside].max() < 0.05 * peak[k]
