"""Whole morphs from real solver result files (issue 17): ``hot2cold morph part.step results.rst -o cold.step
--html r.html`` and the same with a Nastran ``.op2``, through the command line, on the meshes' own blocks.

The results are real (``corpus/solver_results``: an ANSYS MAPDL 19.0 static run of a 5 x 5 x 10 m block of
SOLID186 in SI units, an MSC Nastran run of a bent 1 x 2 x 3 block of CTETRA); the parts are the blocks their
meshes fill, made here.  Each morph must exit 0 with a valid closed cold solid whose corners moved as the
solver moved the corner nodes.  The readers themselves are checked against the solvers' own readers in
``test_ansys.py`` and ``test_nastran.py``.
"""
from __future__ import annotations

import contextlib
import io
import json
import re
from pathlib import Path

import cadquery as cq
import numpy as np
import pytest

from hot2cold.cli import main
from hot2cold.io.field import read_field
from hot2cold.kernel.step import read_step
from hot2cold.kernel.validity import check_solids

RESULTS = Path(__file__).resolve().parents[1] / "corpus" / "solver_results"


def _block_of(field, path: Path) -> np.ndarray:
    """Write the block the field's nodes fill as a STEP file; its 8 corners (8, 3), mm."""
    lo, hi = field.points.min(axis=0), field.points.max(axis=0)
    cq.exporters.export(cq.Workplane().box(*(hi - lo), centered=False).translate(tuple(lo)), str(path))
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def _vertices(step: Path) -> np.ndarray:
    """The distinct vertices (V, 3) of a STEP file."""
    points = [v.toTuple() for v in cq.importers.importStep(str(step)).vertices().vals()]
    return np.unique(np.round(np.array(points), 9), axis=0)


#: The real results morphed, and the factor of their length unit to mm (the .rst says SI; the .op2 says none).
SOLVED = {"ansys/shell281.rst": 1000.0, "nastran/solid_bending.op2": 1.0}


@pytest.fixture(scope="module", params=sorted(SOLVED))
def solved(request, tmp_path_factory):
    """``hot2cold morph part.step RESULTS -o cold.step --report r.json --html r.html`` on the block the
    results' mesh fills: (results path, its unit factor, the folder, the exit code, stderr)."""
    path = RESULTS / request.param
    folder = tmp_path_factory.mktemp(path.stem)
    _block_of(read_field(path), folder / "part.step")
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["morph", str(folder / "part.step"), str(path), "-o", str(folder / "cold.step"), "--report",
                     str(folder / "report.json"), "--html", str(folder / "report.html"), "-q"])
    return path, SOLVED[request.param], folder, code, err.getvalue()


@pytest.mark.heavy
def test_morph_from_solver_results(solved):
    path, unit_factor, folder, code, err = solved
    assert code == 0, err
    field = read_field(path)
    if path.suffix == ".rst":          # SI: the file says metres, so the block is 5000 x 5000 x 10000 mm
        np.testing.assert_allclose(np.ptp(field.points, axis=0), [5000, 5000, 10000], rtol=1e-12)
    corners = _block_of(field, folder / "again.step")
    report = json.loads((folder / "report.json").read_text())
    assert report["valid"] and report["delta_max"] <= 1e-3
    # the report names the result set taken as the solver's post-processor does (here each file's last)
    named = r"result set 0 \(load step 1, substep 1, time 1\)" if path.suffix == ".rst" else r"subcase 1"
    assert re.fullmatch(named, report["result_set"]), report["result_set"]
    assert report["result_set"] in (folder / "report.html").read_text()
    checks = check_solids(read_step(folder / "cold.step"))
    assert len(checks) == 1 and checks[0].valid and checks[0].closed and checks[0].faces == 6
    # each corner node's displacement moved the block's corner with it (the solver's nodes there)
    rows = [int(np.argmin(np.linalg.norm(field.points - c, axis=1))) for c in corners]
    np.testing.assert_allclose(field.points[rows], corners, atol=1e-9 * unit_factor)
    moved = corners + field.displacements[rows]
    cold = _vertices(folder / "cold.step")
    assert len(cold) == 8
    nearest = np.array([cold[np.argmin(np.linalg.norm(cold - m, axis=1))] for m in moved])
    assert np.abs(nearest - moved).max() <= 1e-6 * max(1.0, unit_factor / 1000)
    assert np.abs(field.displacements[rows]).max() > 1e-3       # the corners did move, farther than that


@pytest.mark.heavy
def test_the_report_page_renders_in_chromium(solved, browser):
    """The page of each solver morph opens offline in headless Chromium (the browser of ``conftest.py``, the
    page session of ``tests/test_html_3d.py``): its 3D view draws the block, asks the network for nothing and
    logs no error."""
    from test_html_3d import LOCAL, _Session, _part_mask

    *_, folder, code, err = solved
    assert code == 0, err
    s = _Session(browser, folder / "report.html")
    try:
        assert s.page.get_attribute("#v3-stage", "data-ready") == "true", s.page.text_content("#v3-status")
        rgb = s.pixels()
        assert _part_mask(rgb[:, : int(0.8 * rgb.shape[1])]).mean() > 0.02          # the block, coloured
        assert not s.blocked and all(url.startswith(LOCAL) for url in s.requests), s.requests
        assert not s.errors, s.errors
    finally:
        s.context.close()


def test_nastran_positions_from_the_input_deck():
    """``--field-points model.bdf``: full-precision GRID positions by node number in place of the OP2's
    single-precision ones."""
    op2 = RESULTS / "nastran" / "solid_bending.op2"
    own = read_field(op2)
    deck = read_field(op2, points_from=RESULTS / "nastran" / "solid_bending.bdf")
    np.testing.assert_array_equal(deck.node_ids, own.node_ids)
    np.testing.assert_array_equal(deck.displacements, own.displacements)
    np.testing.assert_allclose(deck.points, own.points, atol=1e-6)


@pytest.mark.parametrize("args, pattern", [
    (["nastran/cbush.pch"], r"cbush\.pch holds no node positions; pass the model they belong to \(--field-points "),
    (["nastran/ctetra.op2", "--field-name", "subcase 99"], r"subcase 99"),
    (["ansys/shell281.rst", "--field-step", "5"], r"shell281\.rst"),
    (["ansys/shell281.rst", "--field-units", "mm"], r"shell281\.rst states its points in m, but the field units "
                                                    r"were given as mm"),
    (["ansys/shell281.rst", "--columns", "x=a"], r"columns applies to text tables only"),
])
def test_solver_results_refused_in_one_line(tmp_path, capsys, args, pattern):
    _block_of(read_field(RESULTS / "nastran" / "solid_bending.op2"), tmp_path / "part.step")
    out = tmp_path / "out"
    out.mkdir()
    code = main(["morph", str(tmp_path / "part.step"), str(RESULTS / args[0]), *args[1:], "-o",
                 str(out / "cold.step"), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("hot2cold: error: "), err
    assert re.search(pattern, err[0]), err[0]
    assert not list(out.iterdir())
