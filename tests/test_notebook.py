"""A morph shows itself in a notebook: IPython's ``_repr_html_`` of the result (the report page without its
pictures in a frame, the 3D view coloured by the displacement) and of the report (verdict, figures, faces)."""
from __future__ import annotations

import html
import io
import re

import numpy as np
from matplotlib.image import imread


def _page(frame: str) -> str:
    found = re.fullmatch(r'<iframe srcdoc="(.*)" title="[^"]*" style="[^"]*"></iframe>', frame, re.S)
    assert found, frame[:200]
    return html.unescape(found.group(1))


def test_a_result_shows_its_verdict_view_and_tables(blade):
    frame = blade._repr_html_()
    page = _page(frame)
    assert page.startswith("<!DOCTYPE html>") and blade.report.verdict.state.value in page
    assert '<div class="v3-stage" id="v3-stage">' in page and '<script type="importmap">' in page
    assert '<option value="displacement" selected>' in page               # coloured by displacement first
    assert '<div class="v3-bar" id="v3-bar-deviation" hidden>' in page
    assert "<h2>Faces</h2>" in page and "<h2>Pictures</h2>" not in page    # no matplotlib pictures
    assert "http:" not in page and "https:" not in page.replace("https://threejs.org", "")


def test_a_report_shows_its_verdict_and_faces_without_scripts(blade):
    text = blade.report._repr_html_()
    assert text.startswith('<div class="hot2cold-report">') and "<script" not in text
    assert blade.report.verdict.text.split(":")[0] in html.unescape(text)
    rows = re.findall(r'<tr id="face-row-(\d+)"', text)
    assert [int(r) for r in rows] == [f.index for f in blade.report.faces]
    style = re.search(r"<style>(.*?)</style>", text, re.S).group(1)
    selectors = [s.strip() for group in re.findall(r"([^{}]+)\{", style) for s in group.split(",")]
    assert selectors and all(s.startswith(".hot2cold-report") for s in selectors), selectors   # the notebook's
    # own styles stay untouched


def test_the_notebook_frame_draws_the_cold_part_coloured_by_displacement_at_load(browser, blade):
    """In a browser the frame's 3D view is drawn when the notebook page has loaded: ready, in several
    colours, without errors or requests outside the page."""
    context = browser.new_context(viewport={"width": 1200, "height": 1100})
    errors, requests = [], []
    try:
        page = context.new_page()
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.on("request", lambda r: requests.append(r.url))
        page.set_content(f"<!DOCTYPE html><html><body>{blade._repr_html_()}</body></html>", wait_until="load")
        frame = page.frames[1]
        assert frame.get_attribute("#v3-stage", "data-ready") == "true"
        assert frame.input_value("#v3-colour") == "displacement"
        assert frame.is_visible("#v3-bar-displacement") and not frame.is_visible("#v3-bar-deviation")
        rgb = imread(io.BytesIO(frame.locator("#v3-canvas").screenshot()), format="png")[..., :3]
        drawn = rgb[:, : int(0.8 * rgb.shape[1])]
        coloured = (drawn.max(axis=2) - drawn.min(axis=2) > 0.15) & (
            np.maximum(drawn[..., 1], drawn[..., 2]) > drawn[..., 0])
        assert coloured.mean() > 0.02
        assert len(np.unique((drawn[coloured] * 15).round().astype(int), axis=0)) >= 10
        assert not errors, errors
        assert all(url.startswith(("about:", "data:")) for url in requests), requests
    finally:
        context.close()
