"""The report's pictures (issue 17): one error colour scale per result with the tolerance on it, a pass/fail
mark and a named worst node on every error map, curvature noise drawn flat, views along named axes
(twisted blade; its two planar end caps, faces with errors of 1e-12 mm and rounding-noise curvature)."""
from __future__ import annotations

import dataclasses
import io

import numpy as np
import pytest
from matplotlib import colormaps
from matplotlib.image import AxesImage, imread

from hot2cold.core.model import Role
from hot2cold.views import pictures as visual

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
COLOURBAR_LABEL = "distance to cold part [mm]"


@pytest.fixture(scope="module")
def mesh(blade):
    return visual.mesh_of(blade)


@pytest.fixture(scope="module")
def caps(blade) -> list[int]:
    """The blade's two planar end caps (2x2 nets), whose nodes are within 1e-11 mm of the cold part."""
    found = [f.index for f in blade.part.faces if f.surface.shape == (2, 2)]
    assert len(found) == 2 and all(blade.report.faces[k].delta_max < 1e-10 for k in found)
    return found


def _with(blade, *, tolerance=..., errors=None, allowance=None):
    """``blade`` with another tolerance (and scatter allowance) in its report and/or other node errors (the
    morph left as it is)."""
    result = blade
    if tolerance is not ...:
        result = dataclasses.replace(result, report=dataclasses.replace(result.report, tolerance=tolerance))
    if allowance is not None:
        result = dataclasses.replace(result, report=dataclasses.replace(result.report, allowance=allowance))
    if errors is not None:
        result = dataclasses.replace(result, node_errors=errors)
    return result


def _map_axes(fig):
    """The panels of an error map figure (not its colour bar, nor the empty grid cells)."""
    return [ax for ax in fig.axes if ax.axison and ax.get_ylabel() != COLOURBAR_LABEL]


def _colourbar_axes(fig):
    (cb,) = [ax for ax in fig.axes if ax.get_ylabel() == COLOURBAR_LABEL]
    return cb


def _panel_pixels(fig, ax) -> np.ndarray:
    """RGB ``(h, w, 3)`` of the figure drawn, inside ``ax``'s frame (a pixel in from its spines)."""
    fig.canvas.draw()
    rgb = np.asarray(fig.canvas.buffer_rgba(), dtype=float)[..., :3] / 255.0
    box = ax.get_window_extent()
    height = rgb.shape[0]
    x0, x1 = int(np.ceil(box.x0)) + 2, int(np.floor(box.x1)) - 2
    y0, y1 = height - int(np.floor(box.y1)) + 2, height - int(np.ceil(box.y0)) - 2
    return rgb[y0:y1, x0:x1]


def _colour_positions(pixels: np.ndarray, cmap) -> np.ndarray:
    """Where on the colour map (0 to 1) each clearly coloured pixel of ``pixels (h, w, 3)`` lies: the nearest
    of 512 samples; greys (the face, the ring, the legend) left out."""
    rgb = pixels.reshape(-1, 3)
    coloured = rgb[rgb.max(axis=1) - rgb.min(axis=1) > 0.25]
    samples = cmap(np.linspace(0.0, 1.0, 512))[:, :3]
    nearest = np.argmin(((coloured[:, None, :] - samples[None, :, :]) ** 2).sum(axis=2), axis=1)
    return nearest / 511.0


def _face_and_edge_nodes(result, k: int) -> np.ndarray:
    cls = result.classification
    edge_nodes, _ = visual._edge_node_uv(result, k)
    return np.concatenate([cls.nodes_of(Role.FACE, k), edge_nodes])


# ------------------------------------------------------------------------------------------------ error maps
@pytest.mark.heavy
def test_one_error_scale_for_every_map_of_a_result(blade, mesh, caps):
    """0 to max(largest error, tolerance) on every panel and colour bar, whichever faces a picture shows."""
    report = blade.report
    scale = visual.error_scale(blade)
    largest = np.nanmax(blade.node_errors)
    assert scale.tolerance == report.tolerance == 1e-3 and largest < 1e-4
    assert scale.top == pytest.approx(max(largest, report.tolerance + report.allowance))
    limits = set()
    for faces in ([1], caps, [0, 1, 3]):
        fig = visual.error_maps_figure(blade, faces, mesh=mesh)
        for ax in _map_axes(fig):
            for coll in ax.collections:
                if coll.get_array() is not None:
                    limits.add((coll.norm.vmin, coll.norm.vmax))
        limits.add(tuple(_colourbar_axes(fig).get_ylim()))
        assert len(_map_axes(fig)) == len(faces)
    assert limits == {(0.0, scale.top)}


def test_tiny_errors_render_in_the_low_colour_and_near_tolerance_in_the_top_one(blade, mesh, caps):
    """A cap with errors of 1e-12 mm is drawn all in the bottom of the scale; the same cap with errors just
    under the tolerance all in its top: the colour says how close to the tolerance, not to the face's own
    largest error."""
    k = caps[0]
    fig = visual.error_maps_figure(blade, [k], mesh=mesh)
    low = _colour_positions(_panel_pixels(fig, _map_axes(fig)[0]), visual.error_scale(blade).cmap)
    # antialiased marker edges blend with the grey face into colours a little up the map; none near the top
    assert len(low) > 500 and np.median(low) < 0.02 and np.quantile(low, 0.99) < 0.2

    errors = np.array(blade.node_errors, float)
    nodes = _face_and_edge_nodes(blade, k)
    errors[nodes] = np.linspace(0.9, 0.99, len(nodes)) * blade.report.tolerance
    near = _with(blade, errors=errors)
    fig = visual.error_maps_figure(near, [k], mesh=mesh)
    high = _colour_positions(_panel_pixels(fig, _map_axes(fig)[0]), visual.error_scale(near).cmap)
    assert len(high) > 500 and np.median(high) > 0.85 and np.quantile(high, 0.01) > 0.5


def test_errors_above_the_tolerance_take_the_red_over_colours(blade, mesh, caps):
    k = caps[0]
    tol = blade.report.tolerance
    errors = np.array(blade.node_errors, float)
    errors[_face_and_edge_nodes(blade, k)] = 3.0 * tol
    over = _with(blade, errors=errors)
    scale = visual.error_scale(over)
    assert scale.top == pytest.approx(3.0 * tol) and scale.limit == pytest.approx(tol + blade.report.allowance)
    red = scale.cmap(1.0)
    assert red[0] > 0.3 and red[0] > 2 * red[1] and red[0] > 2 * red[2]             # a red, not viridis
    assert scale.cmap(0.99 * scale.limit / scale.top)[:3] == pytest.approx(
        colormaps["viridis"](1.0)[:3], abs=0.02)                              # viridis up to the limit
    fig = visual.error_maps_figure(over, [k], mesh=mesh)
    pixels = _panel_pixels(fig, _map_axes(fig)[0]).reshape(-1, 3)
    reddish = (pixels[:, 0] > 0.35) & (pixels[:, 0] > 2 * pixels[:, 1]) & (pixels[:, 0] > 2 * pixels[:, 2])
    assert reddish.sum() > 500


def test_the_tolerance_is_marked_on_the_colour_bar(blade, mesh, caps):
    fig = visual.error_maps_figure(blade, caps, mesh=mesh)
    cb = _colourbar_axes(fig)
    limit = visual.error_scale(blade).limit
    labels = {t.get_text(): y for t, y in zip(cb.get_yticklabels(), cb.get_yticks())}
    assert labels["tolerance\n0.001 mm"] == pytest.approx(limit)
    assert any(np.allclose(line.get_ydata(), limit) for line in cb.get_lines())      # the line across it


def _marks(fig) -> list[tuple[str, tuple]]:
    out = []
    for ax in _map_axes(fig):
        (mark,) = [t for t in ax.texts if "Δmax" in t.get_text()]
        out.append((mark.get_text(), mark.get_color()))
    return out


def test_pass_and_fail_marks_against_the_tolerance(blade, mesh, caps):
    faces = [1, *caps]
    marks = _marks(visual.error_maps_figure(blade, faces, mesh=mesh))
    for k, (text, colour) in zip(faces, marks):
        shown = np.nanmax(blade.node_errors[_face_and_edge_nodes(blade, k)])
        assert text == f"Δmax {shown:.2g} mm ≤ tolerance 0.001 mm ✓" and colour == visual.PASS_COLOUR

    # face 1 misses it, the caps do not; a field that scatters widens the limit, and the mark names it
    tight = _with(blade, tolerance=1e-5, allowance=2e-6)
    marks = _marks(visual.error_maps_figure(tight, faces, mesh=mesh))
    assert marks[0][0].endswith("✗") and "> tolerance 1e-05 + 2e-06 mm" in marks[0][0]
    assert marks[0][1] == visual.FAIL_COLOUR
    assert all(t.endswith("✓") and c == visual.PASS_COLOUR for t, c in marks[1:])

    none = _with(blade, tolerance=None)
    marks = _marks(visual.error_maps_figure(none, caps, mesh=mesh))
    assert all(t.endswith("no tolerance set") and "✓" not in t and "✗" not in t for t, _ in marks)
    assert visual.error_scale(none).top == pytest.approx(np.nanmax(blade.node_errors))


def test_the_worst_node_is_named_in_a_legend(blade, mesh, caps):
    faces = [0, caps[1]]
    fig = visual.error_maps_figure(blade, faces, mesh=mesh)
    for k, ax in zip(faces, _map_axes(fig)):
        worst = np.nanmax(blade.node_errors[_face_and_edge_nodes(blade, k)])
        (text,) = ax.get_legend().get_texts()
        assert text.get_text() == f"worst node: {worst:.2e} mm"


def test_error_maps_png_is_a_png(blade, mesh, caps):
    png = visual.error_maps_png(blade, caps[:1], mesh=mesh, dpi=40)
    assert png[:8] == PNG_SIGNATURE and imread(io.BytesIO(png), format="png").shape[2] in (3, 4)


# ------------------------------------------------------------------------------------------------ curvature
def _images(fig) -> list[AxesImage]:
    return [im for ax in fig.axes for im in ax.images]


@pytest.mark.heavy
def test_a_plane_is_drawn_flat_with_a_symmetric_scale(blade, mesh, caps):
    """The cap's hot curvature is 0 and its cold one rounding noise (about 1e-21 1/mm): below the floor,
    so every panel is uniform and says so; the scales are symmetric about 0."""
    k = caps[0]
    fc = visual.face_curvature(blade, k, mesh, grid_points=3000)
    floor = visual.curvature_floor(blade, fc)
    assert floor == pytest.approx(visual.CURVATURE_NOISE / blade.part.diagonal)
    assert 0 < np.nanmax(np.abs(fc.cold[fc.inside])) < floor                   # noise there, not flat data

    fig = visual.curvature_figure(blade, [k], mesh=mesh, grid_points=3000)
    panels = [ax for ax in fig.axes if ax.images]
    assert len(panels) == 3
    titles = [ax.get_title() for ax in panels]
    assert "flat" in titles[0] and "flat" in titles[1] and "no change" in titles[2]
    for ax in panels:
        (im,) = ax.images
        data = np.ma.filled(im.get_array(), np.nan)[fc.inside]
        assert np.array_equal(data, np.zeros_like(data))
        assert im.norm.vmax > 0 and im.norm.vmin == -im.norm.vmax
        pixels = _panel_pixels(fig, ax)
        assert np.ptp(pixels.reshape(-1, 3), axis=0).max() < 0.05                   # one colour (white)


def test_real_curvature_and_its_change_are_kept(blade, mesh):
    """A curved side of the blade keeps its ramp, and so does its small change by the morph (1e-5 1/mm, far
    above the floor); the scales stay symmetric."""
    fig = visual.curvature_figure(blade, [3], mesh=mesh, grid_points=3000)
    panels = [ax for ax in fig.axes if ax.images]
    for ax in panels:
        assert "flat" not in ax.get_title() and "no change" not in ax.get_title()
        (im,) = ax.images
        assert im.norm.vmax > 0 and im.norm.vmin == -im.norm.vmax
        assert np.ptp(_panel_pixels(fig, ax).reshape(-1, 3), axis=0).max() > 0.3
    assert panels[0].images[0].norm.vmax == panels[1].images[0].norm.vmax                # hot, cold: one scale


def test_curvature_png_is_a_png(blade, mesh, caps):
    assert visual.curvature_png(blade, caps[:1], mesh=mesh, dpi=40, grid_points=2000)[:8] == PNG_SIGNATURE


# ---------------------------------------------------------------------------------------------------- views
def test_default_views_are_along_named_axes_largest_outline_first():
    rng = np.random.default_rng(0)
    points = rng.uniform(0.0, 1.0, (500, 3)) * [10.0, 1.0, 100.0] + [5.0, -3.0, 0.0]
    views = visual.default_views(points)
    assert [v.name for v in views] == ["front", "right", "top"]           # thinnest along Y, then X, longest along Z
    expect = {"front": ("+X", "+Z", "+Y"), "right": ("+Y", "+Z", "−X"), "top": ("+X", "+Y", "−Z")}
    for v in views:
        right, up, towards = (visual._axis_text(b) for b in v.basis())
        assert (right, up, visual._axis_text(v.direction)) == expect[v.name]
        assert towards == visual._axis_text(-np.asarray(v.direction))
    assert visual._axis_text([0.0, 0.6, 0.8]) == "(+0.00, +0.60, +0.80)"


@pytest.mark.heavy
def test_overlay_titles_name_the_axes(blade, mesh):
    fig = visual.overlay_figure(blade, mesh=mesh, width_in=8.0, dpi=30)
    panels = [ax for ax in fig.axes if ax.images]
    titles = [ax.get_title() for ax in panels]
    assert titles == ["view along +Y (front)\n+X right, +Z up, −Y towards you",
                      "view along −X (right)\n+Y right, +Z up, +X towards you",
                      "view along −Z (top)\n+X right, +Y up, +Z towards you"]
    assert [(ax.get_xlabel(), ax.get_ylabel()) for ax in panels] == [
        ("+X [mm]", "+Z [mm]"), ("+Y [mm]", "+Z [mm]"), ("+X [mm]", "+Y [mm]")]
    # the tick values are the part's coordinates: the front view spans the part's X and Z
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    x0, x1 = panels[0].get_xlim()
    assert x0 < lo[0] < hi[0] < x1 and x1 - x0 < 1.5 * (hi[0] - lo[0])


def test_face_numbers_on_the_part(blade, mesh):
    """Issue 17: a picture of the part with its face numbers, so the report's rows can be found on it.  The
    blade's tip cap (plane z = 100) is numbered in the view from the top (along -Z), its root cap (z = 0)
    faces away from every view and is named under the figure instead; every other face is numbered in some
    view; the PNG is a PNG."""
    labels = blade.part.face_labels
    tip, root = labels.index("plane z = 100"), labels.index("plane z = 0")
    fig = visual.face_numbers_figure(blade, mesh=mesh)
    shown = {ax.get_title().splitlines()[0]: {int(t.get_text()) for t in ax.texts} for ax in fig.axes}
    top = shown["view along −Z (top)"]
    assert tip in top and root not in top
    assert set().union(*shown.values()) == set(range(len(blade.part.faces))) - {root}
    assert fig.get_supxlabel() == f"turned away from these views: face {root} (plane z = 0)"
    assert visual.face_numbers_png(blade, mesh=mesh).startswith(PNG_SIGNATURE)
