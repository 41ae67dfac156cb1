"""hot2cold.io.ansys: ANSYS MAPDL ``.rst`` results, checked on real solver files against ansys-mapdl-reader.

The files: ``corpus/solver_results/ansys/`` (see its SOURCE.md) and the reader's own ``examples.rstfile``.
"""
from __future__ import annotations

import logging
import subprocess
import sys
import warnings
from pathlib import Path

import ansys.mapdl.reader as mapdl_reader      # the test extra's: a missing one fails, not skips
import numpy as np
import pytest
from ansys.mapdl.reader import examples

from hot2cold.errors import FieldError
from hot2cold.io.ansys import UNIT_SYSTEMS, read_rst

ROOT = Path(__file__).resolve().parent.parent
CORPUS = ROOT / "corpus" / "solver_results" / "ansys"


#: name -> (path, unit, result sets, solid volume in its units (outer triangles), bounds (lo, hi))
FILES = {
    "beam_modal": (Path(examples.rstfile), None, 6, 5.0, ((0, 0, 0), (1, 1, 5))),
    "box_si": (CORPUS / "shell281.rst", "m", 1, 250.0, ((0, 0, 0), (5, 5, 10))),
    "quarter_ring_mpa": (CORPUS / "cyc_stress.rst", "mm", 1, None, ((0, 0, 0), (10, 10, 10))),
}


def reference(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return mapdl_reader.read_binary(str(path))


def one_line_error(path, match=None) -> str:
    with pytest.raises(FieldError, match=match) as info:
        read_rst(str(path))
    text = str(info.value)
    assert "\n" not in text and "Traceback" not in text, text
    return text


@pytest.mark.parametrize("name", FILES)
def test_every_result_set_matches_the_reader(name):
    path, unit, nsets, _, _ = FILES[name]
    rst = reference(path)
    assert rst.nsets == nsets
    worst = 0.0
    for i in range(nsets):
        got = read_rst(str(path), step=i)
        nnum, disp = rst.nodal_displacement(i)
        keep = ~np.isnan(disp[:, :3]).any(axis=1)
        assert keep.all()                                   # these files have a displacement at every node
        np.testing.assert_array_equal(got.node_ids, nnum)
        assert got.node_ids.dtype == np.int64 and got.points.shape == got.displacements.shape == (len(nnum), 3)
        np.testing.assert_array_equal(got.displacements, disp[:, :3])
        order = np.searchsorted(rst.mesh.nnum, got.node_ids)
        np.testing.assert_array_equal(got.points, rst.mesh.nodes[order, :3])
        worst = max(worst, float(np.abs(got.displacements - disp[:, :3]).max()))
        assert np.abs(got.displacements).max() > 0          # a real, non-zero field
        assert got.unit == unit
        assert got.available == tuple(f"{ls},{sub}" for ls, sub, _ in rst._resultheader["ls_table"])
        assert got.name.startswith(f"{i} (load step ")
    assert worst == 0.0


def test_unit_codes_documented():
    assert {code: unit for code, (_, unit) in UNIT_SYSTEMS.items()} == {
        -1: None, 0: None, 1: "m", 2: "cm", 3: "ft", 4: "in", 5: "m", 6: "mm", 7: "um"}


def test_unit_from_the_result_header_not_the_readers_units_entry():
    # ansys-mapdl-reader's own "units" entry says "User Defined" for all of these; the files say SI and MPA.
    assert reference(FILES["box_si"][0])._resultheader["units"] == "User Defined"
    assert read_rst(str(FILES["box_si"][0])).unit == "m"
    assert read_rst(str(FILES["quarter_ring_mpa"][0])).unit == "mm"


def test_unknown_unit_code_gives_none(tmp_path, caplog):
    raw = bytearray(FILES["box_si"][0].read_bytes())
    words = np.frombuffer(raw, "<i4").copy()
    assert words[105 + 19] == 1 and words[6] == 1
    words[105 + 19] = 42
    path = tmp_path / "odd_units.rst"
    path.write_bytes(words.tobytes())
    with caplog.at_level(logging.INFO, logger="hot2cold.io.ansys"):
        assert read_rst(str(path)).unit is None
    assert "unknown MAPDL unit system code 42" in caplog.text
    assert "standard header says unit system 1, the result header 42" in caplog.text


def test_result_set_selection():
    path = str(FILES["beam_modal"][0])
    rst = reference(path)
    last = read_rst(path)
    np.testing.assert_array_equal(last.displacements, rst.nodal_displacement(5)[1])
    assert last.name == "5 (load step 1, substep 6, time 20137.2)"
    np.testing.assert_array_equal(read_rst(path, step=-6).displacements, rst.nodal_displacement(0)[1])
    by_name = read_rst(path, "1,3")
    np.testing.assert_array_equal(by_name.displacements, rst.nodal_displacement(2)[1])
    assert read_rst(path, " 1 ; 3 ").name == by_name.name
    by_time = read_rst(path, "11504.89523664")                  # a modal file's time is the frequency
    assert by_time.name == by_name.name
    np.testing.assert_array_equal(read_rst(path, "20137.19").displacements, last.displacements)


def test_result_set_errors():
    path = str(FILES["beam_modal"][0])
    with pytest.raises(FieldError, match=r"has no result set 2,1 \(load step, substep\); its sets: 1,1 \(time "
                                         r"7366\.5\), 1,2 .* 1,6 \(time 20137\.2\)$"):
        read_rst(path, "2,1")
    with pytest.raises(FieldError, match=r"result set 'UX' is neither LS,SUB \(e\.g\. 1,2\) nor a time value; "
                                         r"its sets: 1,1"):
        read_rst(path, "UX")
    with pytest.raises(FieldError, match=r"no result set at time 99; its sets: 1,1"):
        read_rst(path, "99")
    with pytest.raises(FieldError, match=r"time 7366\.5 is that of several result sets \(1,1, 1,2\); name one "
                                         r"as LS,SUB"):
        read_rst(path, "7366.49503969")
    with pytest.raises(FieldError, match=r"has 6 result set\(s\): step 6 is not among 0\.\.5 \(or -6\.\.-1"):
        read_rst(path, step=6)
    with pytest.raises(FieldError, match=r"give the result set by step or by field_name, not both"):
        read_rst(path, "1,1", step=0)
    with pytest.raises(FieldError, match=r"step must be an integer"):
        read_rst(path, step=1.5)


@pytest.mark.parametrize("name", FILES)
def test_outer_triangles(name):
    path, _, _, volume, (lo, hi) = FILES[name]
    got = read_rst(str(path))
    tri = got.triangles
    assert tri is not None and tri.ndim == 2 and tri.shape[1] == 3 and tri.dtype == np.int64
    assert tri.min() >= 0 and tri.max() < len(got.points)
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    assert (uses == 2).all()                                    # a closed surface
    p = got.points[tri]
    signed = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])).sum() / 6
    area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    assert area.min() > 0
    if volume is not None:                                      # the boxes: outward, exact volume, on the faces
        assert signed == pytest.approx(volume, rel=1e-9)
        on = np.isclose(got.points[np.unique(tri)], lo).any(axis=1) | np.isclose(got.points[np.unique(tri)],
                                                                                  hi).any(axis=1)
        assert on.all()
        inner = np.setdiff1d(np.arange(len(got.points)), np.unique(tri))
        assert not (np.isclose(got.points[inner], lo) | np.isclose(got.points[inner], hi)).any()
    else:                                                       # the quarter ring, radii 5..10: faceted
        assert 0.95 * np.pi / 4 * 75 * 10 < signed < np.pi / 4 * 75 * 10
        r = np.hypot(got.points[:, 0], got.points[:, 1])
        used = got.points[np.unique(tri)]
        ru = np.hypot(used[:, 0], used[:, 1])
        on = (np.isclose(ru, 5) | np.isclose(ru, 10) | np.isclose(used[:, 0], 0) | np.isclose(used[:, 1], 0)
              | np.isclose(used[:, 2], 0) | np.isclose(used[:, 2], 10))
        assert on.all() and r.min() == pytest.approx(5) and r.max() == pytest.approx(10)


def test_rotated_nodal_coordinate_systems_match_the_reader():
    """cyc12.rst has 216 nodes in rotated nodal systems: the displacements are turned to global here."""
    from hot2cold.io.ansys import _nodal_displacements

    path = CORPUS / "cyc12.rst"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rst = mapdl_reader.read_binary(str(path), ignore_cyclic=True)
    assert (rst.mesh.node_angles != 0).any(axis=1).sum() == 216
    for i in range(rst.nsets):
        ids, _, disp = _nodal_displacements(rst, i, str(path))
        nnum, ref = rst.nodal_displacement(i)
        local = rst.nodal_displacement(i, in_nodal_coord_sys=True)[1]
        np.testing.assert_array_equal(ids, nnum)
        np.testing.assert_allclose(disp, ref[:, :3], rtol=0, atol=1e-15)
        assert np.abs(disp - local[:, :3]).max() > 1e-3           # the rotation did something


def test_cyclic_result_refused():
    one_line_error(CORPUS / "cyc12.rst", r"cyc12\.rst is a cyclic-symmetry result \(one sector of 18\); expand it")


def test_nodes_without_displacement_dropped(monkeypatch, caplog):
    path = str(FILES["box_si"][0])
    full = read_rst(path)
    real = mapdl_reader.rst.Result.nodal_displacement
    gone = full.node_ids[[0, 5]]

    def partial(self, *args, **kwargs):
        nnum, values = real(self, *args, **kwargs)
        values = values.copy()
        values[np.isin(nnum, gone)] = np.nan
        return nnum, values

    monkeypatch.setattr(mapdl_reader.rst.Result, "nodal_displacement", partial)
    with caplog.at_level(logging.INFO, logger="hot2cold.io.ansys"):
        got = read_rst(path)
    assert "2 of 141 nodes have no displacement" in caplog.text
    assert len(got.node_ids) == 139 and not np.isin(gone, got.node_ids).any()
    assert np.isfinite(got.displacements).all()
    np.testing.assert_array_equal(got.displacements, full.displacements[~np.isin(full.node_ids, gone)])
    assert got.triangles.max() < 139 and len(got.triangles) < len(full.triangles)

    def nothing(self, *args, **kwargs):
        nnum, values = real(self, *args, **kwargs)
        return nnum, np.full_like(values, np.nan)

    monkeypatch.setattr(mapdl_reader.rst.Result, "nodal_displacement", nothing)
    one_line_error(path, r"no node has a displacement in set 1")


@pytest.mark.parametrize("name", FILES)
def test_truncated_copies_refused(name, tmp_path):
    path = FILES[name][0]
    raw = path.read_bytes()
    end = 4 * int(np.frombuffer(raw, "<i4")[105 + 9])            # the header's end-of-data pointer, in bytes
    assert end <= len(raw)
    for cut in (3, 100, 400, 411, 420, 1000, 5000, 20000, len(raw) // 3, len(raw) // 2, end - 4096, end - 4):
        copy = tmp_path / f"cut_{cut}.rst"
        copy.write_bytes(raw[:cut])
        text = one_line_error(copy)
        assert str(copy) in text and ("truncated" in text or "corrupt" in text), text


def test_bad_files_refused(tmp_path):
    empty = tmp_path / "empty.rst"
    empty.write_bytes(b"")
    one_line_error(empty, r"ANSYS result file .*empty\.rst is empty")
    text = tmp_path / "table.rst"
    text.write_text("x,y,z,dx,dy,dz\n0,0,0,0.1,0,0\n")
    one_line_error(text, r".*table\.rst is not an ANSYS binary result file")
    noise = tmp_path / "noise.rst"
    noise.write_bytes(np.random.default_rng(1).bytes(50_000))
    one_line_error(noise, r"noise\.rst is not an ANSYS binary result file")
    one_line_error(examples.fullfile, r"file\.full is an MAPDL full matrix \(\.full\) file, not a result file")
    one_line_error(tmp_path / "missing.rst", r"^ANSYS result file not found: .*missing\.rst; check the path$")
    raw = bytearray(FILES["box_si"][0].read_bytes())
    words = np.frombuffer(raw, "<i4").copy()
    words[105 + 15] = words[105 + 9] + 10                       # the geometry pointer past the end of the data
    bad = tmp_path / "bad_pointer.rst"
    bad.write_bytes(words.tobytes())
    one_line_error(bad, r"bad_pointer\.rst is corrupt: its geometry table pointer")


def test_2d_model_refused(tmp_path, monkeypatch):
    real = mapdl_reader.rst.Result.result_dof
    monkeypatch.setattr(mapdl_reader.rst.Result, "result_dof", lambda self, i: [d for d in real(self, i) if d != "UZ"])
    one_line_error(FILES["box_si"][0], r"has no UZ degree of freedom \(its DOFs: UX, UY, ROTX")


def test_missing_reader_message(monkeypatch):
    monkeypatch.setitem(sys.modules, "ansys.mapdl.reader", None)
    with pytest.raises(FieldError) as info:
        read_rst(str(FILES["box_si"][0]))
    assert str(info.value) == "reading ANSYS .rst files needs ansys-mapdl-reader: pip install 'hot2cold[solvers]'"


def test_import_does_not_load_vtk():
    code = ("import hot2cold.io.ansys, sys; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('vtk', 'vtkmodules', 'pyvista', 'ansys')]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)
