"""Bad input: one test per row of the "Bad input" table (``docs/guide/bad_input.md``), through the command line.

Each refusal is checked as a user meets it: ``hot2cold.cli.main([...])``, its exit code, one line on stderr
that starts ``hot2cold: error:`` and says what is wrong (the regular expressions are the table's messages),
no traceback, nothing on stdout (``-q``), and no output file or temporary file left behind.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hot2cold.cli import commands
from hot2cold.cli import main
from hot2cold.kernel.sampling import fe_surface_nodes
from hot2cold.testing.synthetic import AffineField
from hot2cold.io import inputs

FIELD = AffineField.thermal(contraction=-0.004, rotation_deg=0.3, translation=(0.1, -0.2, 0.05))


def _box():
    import cadquery as cq
    return cq.Workplane().box(10, 10, 10).val()


def _write_field(path, points, disp, ids=False):
    header = "id,x,y,z,dx,dy,dz" if ids else "x,y,z,dx,dy,dz"
    rows = np.column_stack(([np.arange(len(points))] if ids else []) + [points, disp])
    np.savetxt(path, rows, delimiter=",", header=header, comments="", fmt="%.12g")
    return path


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    """A 10 mm box as STEP, its FE-like surface nodes (1 mm apart) and a thermal field on them."""
    folder = tmp_path_factory.mktemp("box")
    shape = _box()
    step = folder / "box.step"
    shape.exportStep(str(step))
    nodes = fe_surface_nodes(shape.wrapped, 1.0, seed=1)[0]
    return step, nodes, _write_field(folder / "box_field.csv", nodes, FIELD(nodes))


@pytest.fixture
def out(tmp_path):
    folder = tmp_path / "out"
    folder.mkdir()
    return folder / "cold.step"


def _left(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def _refused(capsys, argv, code, pattern, out=None):
    """Run ``hot2cold argv`` (quiet); check the exit code, that stderr is the one line ``hot2cold: error: ``
    + a match of ``pattern``, that stdout is empty and that ``out``'s folder holds nothing new."""
    before = _left(out.parent) if out is not None else None
    assert main([*argv, "-q"]) == code
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert "Traceback" not in captured.err and captured.out == ""
    assert lines[0].startswith("hot2cold: error: "), lines[0]
    message = lines[0][len("hot2cold: error: "):]
    assert re.match(pattern, message), message
    if out is not None:
        assert _left(out.parent) == before          # no output, no temporary file
    return message


def _morph(hot, field, out, *more):
    return ["morph", str(hot), str(field), "-o", str(out), *more]


# ---------------------------------------------------------------------------------------------------------
# The STEP file
# ---------------------------------------------------------------------------------------------------------
def test_step_missing(tmp_path, box, out, capsys):
    _refused(capsys, _morph(tmp_path / "nope.step", box[2], out), 2,
             r"STEP file not found: .*nope\.step; check the path$", out)


def test_step_is_a_folder(tmp_path, box, out, capsys):
    _refused(capsys, _morph(tmp_path, box[2], out), 2, r"STEP file .* is a folder: give the file itself$", out)


def test_step_unreadable(tmp_path, box, out, capsys, monkeypatch):
    hot = tmp_path / "locked.step"
    hot.write_bytes(box[0].read_bytes())
    hot.chmod(0)
    real = os.access
    # (root may read any file: the permission test itself is what is simulated)
    monkeypatch.setattr(inputs.os, "access", lambda p, mode, *a, **k:
                        False if mode == os.R_OK and Path(p) == hot else real(p, mode, *a, **k))
    _refused(capsys, _morph(hot, box[2], out), 2,
             r"cannot read STEP file .*locked\.step: permission denied; check its permissions$", out)


def test_step_empty(tmp_path, box, out, capsys):
    hot = tmp_path / "empty.step"
    hot.write_bytes(b"")
    _refused(capsys, _morph(hot, box[2], out), 2, r"STEP file is empty: .*empty\.step$", out)


@pytest.mark.parametrize("content, why", [
    ("this is not STEP\n", r"line 1 is 'this is not STEP', where a STEP file begins with 'ISO-10303-21;'"),
    ("s", r"line 1 is 'sISO-10303-21;', where a STEP file begins with 'ISO-10303-21;'"),   # a stray byte first
    ("truncated", r"not a valid STEP file")])
def test_step_corrupt(tmp_path, box, out, capsys, content, why):
    hot = tmp_path / "corrupt.step"
    text = box[0].read_text()
    hot.write_text(text[: len(text) // 2] if content == "truncated" else content + text if content == "s" else content)
    _refused(capsys, _morph(hot, box[2], out), 2,
             rf"cannot read STEP file .*corrupt\.step: {why} \(reader status IFSelect_RetFail\)$", out)


def test_step_with_faces_but_no_solid(tmp_path, box, out, capsys):
    import cadquery as cq
    hot = tmp_path / "face.step"
    cq.Face.makePlane(10, 10).exportStep(str(hot))
    _refused(capsys, _morph(hot, box[2], out), 2,
             r"STEP file .*face\.step holds no solid, only 1 shell of 1 face, open \(4 free edges\): hot2cold "
             r"morphs closed solids; close it \(sew it, add the missing faces\) and make a solid of it in CAD$", out)


def test_step_open_shell(tmp_path, box, out, capsys):
    import cadquery as cq
    hot = tmp_path / "open.step"
    cq.Shell.makeShell([f for f in _box().Faces() if f.Center().z < 4.9]).exportStep(str(hot))
    _refused(capsys, _morph(hot, box[2], out), 2,
             r"STEP file .*open\.step holds no solid, only 1 shell of 5 faces, open \(4 free edges\): hot2cold "
             r"morphs closed solids; close it .* and make a solid of it in CAD$", out)


def test_step_closed_shell_without_solid(tmp_path, box, out, capsys):
    import cadquery as cq
    hot = tmp_path / "shell.step"
    cq.Shell.makeShell(_box().Faces()).exportStep(str(hot))
    _refused(capsys, _morph(hot, box[2], out), 2,
             r"STEP file .*shell\.step holds no solid, only 1 shell of 6 faces, closed: hot2cold morphs closed "
             r"solids; make a solid of it in CAD$", out)


def test_solid_that_is_not_closed(box):
    """A STEP reader makes a shell of an open solid; from Python an open solid is refused before the morph."""
    import cadquery as cq
    from OCP.BRep import BRep_Builder
    from OCP.TopoDS import TopoDS_Solid

    from hot2cold.errors import InputError
    from hot2cold.pipeline.morph import morph
    solid = TopoDS_Solid()
    builder = BRep_Builder()
    builder.MakeSolid(solid)
    builder.Add(solid, cq.Shell.makeShell([f for f in _box().Faces() if f.Center().z < 4.9]).wrapped)
    nodes = box[1][box[1][:, 2] < 4.9]
    with pytest.raises(InputError, match=r"^hot solid 0 is not closed: 4 of its edges bound only one face \(an "
                                         r"open shell, a missing or unsewn face\); hot2cold morphs closed solids: "
                                         r"sew or repair the part in CAD$") as info:
        morph(solid, (nodes, FIELD(nodes)))
    assert info.value.exit_code == 2


@pytest.mark.heavy
@pytest.mark.parametrize("kind", ["compound", "assembly"])
def test_several_solids_and_assemblies_are_all_morphed(tmp_path, out, capsys, kind):
    import cadquery as cq
    shape = _box()
    other = shape.translate(cq.Vector(30, 0, 0))
    hot = tmp_path / f"{kind}.step"
    if kind == "compound":
        cq.Compound.makeCompound([shape, other]).exportStep(str(hot))
    else:
        cq.Assembly().add(shape, name="left").add(other, name="right").export(str(hot))
    nodes = fe_surface_nodes(cq.Compound.makeCompound([shape, other]).wrapped, 1.0, seed=1)[0]
    field = _write_field(tmp_path / "field.csv", nodes, FIELD(nodes))
    report = tmp_path / "report.json"
    assert main(_morph(hot, field, out, "--report", str(report), "-q")) == 0
    data = json.loads(report.read_text())
    assert len(data["solids"]) == 2 and all(s["valid"] and s["free_edges"] == 0 for s in data["solids"])
    assert data["delta_max"] < 1e-9 and out.exists()


# ---------------------------------------------------------------------------------------------------------
# The field file
# ---------------------------------------------------------------------------------------------------------
def test_field_missing(tmp_path, box, out, capsys):
    _refused(capsys, _morph(box[0], tmp_path / "nope.csv", out), 2,
             r"field file not found: .*nope\.csv; check the path$", out)


def test_field_is_a_folder(tmp_path, box, out, capsys):
    _refused(capsys, _morph(box[0], tmp_path, out), 2, r"field file .* is a folder: give the file itself$", out)


def test_field_unreadable(tmp_path, box, out, capsys, monkeypatch):
    field = tmp_path / "locked.csv"
    field.write_bytes(box[2].read_bytes())
    real = os.access
    monkeypatch.setattr(inputs.os, "access", lambda p, mode, *a, **k:
                        False if mode == os.R_OK and Path(p) == field else real(p, mode, *a, **k))
    _refused(capsys, _morph(box[0], field, out), 2,
             r"cannot read field file .*locked\.csv: permission denied; check its permissions$", out)


@pytest.mark.parametrize("content, pattern", [
    ("", r"field file .*f\.csv is empty; it needs a header line naming x,y,z,dx,dy,dz and one line per FE node$"),
    ("x,y,z,dx,dy\n1,2,3,4,5\n",
     r"field file .*f\.csv lacks column\(s\) dz \(header found: 'x', 'y', 'z', 'dx', 'dy', comma-separated\); the "
     r"header must name the columns x,y,z,dx,dy,dz \(any order, any case; ux,uy,uz, U1,U2,U3, 'X Location \(mm\)' "
     r"and the like also do\), or map them with --columns x=NAME,\.\.\.,dz=NAME$"),
    ("x,y,z,dx,dy,dz\n",
     r"field file .*f\.csv has a header but no data lines; add one line per FE node \(x, y, z, dx, dy, dz\)$"),
    ("x,y,z,dx,dy,dz\n1,2,abc,0,0,0\n",
     r"field file .*f\.csv line 2, column 'z' has 'abc', which is not a number; fix or remove that line$"),
    ("x,y,z,dx,dy,dz\n1,2,3,0,0,0\n1,2,3,0,0\n",
     r"field file .*f\.csv line 3 has 5 fields but the header has 6 \(comma-separated\); give every line one "
     r"value per header column$"),
    ("x,y,z,dx,dy,dz\n1,2,3,nan,0,0\n",
     r"field file .*f\.csv has 1 NaN or inf value\(s\), the first on line 2 \(column 'dx': nan\); the field must "
     r"be finite: fix or remove those lines$"),
    ("x,y,z,dx,dy,dz\n1,2,3,0,-inf,0\n", r"field file .*f\.csv has 1 NaN or inf value\(s\), the first on line 2 "
                                         r"\(column 'dy': -inf\)"),
    ("1,2,3,0,0,0\n", r"field file .*f\.csv has no header line: line 1 \('1,2,3,0,0,0'\) holds numbers; add a first "
                      r"line naming the columns, e\.g\. x,y,z,dx,dy,dz$"),
], ids=["empty", "missing column", "no rows", "text", "short line", "nan", "inf", "no header"])
def test_malformed_text_field(tmp_path, box, out, capsys, content, pattern):
    field = tmp_path / "f.csv"
    field.write_text(content)
    _refused(capsys, _morph(box[0], field, out), 2, pattern, out)


def test_binary_field(tmp_path, box, out, capsys):
    field = tmp_path / "f.csv"
    field.write_bytes(bytes(range(256)) * 4)
    _refused(capsys, _morph(box[0], field, out), 2,
             r"field file .*f\.csv is binary, neither a text table nor an \.npz file; export the field as CSV with "
             r"columns x,y,z,dx,dy,dz$", out)


def test_truncated_npz_field(tmp_path, box, out, capsys):
    good = tmp_path / "good.npz"
    np.savez(good, points=box[1], displacements=FIELD(box[1]))
    field = tmp_path / "f.npz"
    field.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    _refused(capsys, _morph(box[0], field, out), 2,
             r"cannot read field file .*f\.npz as \.npz: .*; save it with np\.savez\(path, points=\.\.\., "
             r"displacements=\.\.\.\)$", out)


def test_duplicate_nodes_with_different_displacements(tmp_path, box, out, capsys):
    nodes = box[1]
    disp = FIELD(nodes)
    points = np.concatenate([nodes, nodes[[3, 7]]])
    moved = np.concatenate([disp, disp[[3, 7]] + [0.05, 0.0, 0.0]])
    field = _write_field(tmp_path / "dup.csv", points, moved, ids=True)
    n = len(nodes)
    _refused(capsys, _morph(box[0], field, out), 2,
             rf"field .*dup\.csv has 2 positions with duplicate nodes of different displacements, e\.g\. \(.*\) mm: "
             rf"rows 3 and {n} \(from 0, node ids 3 and {n}\) move by \(.*\) and \(.*\) mm; a position takes one "
             rf"displacement: merge the coincident nodes in the FE model or drop one of them$", out)


def test_duplicate_nodes_with_the_same_displacement_are_merged(tmp_path, box, out, capsys, caplog):
    nodes = box[1]
    points = np.concatenate([nodes, nodes[:10]])
    field = _write_field(tmp_path / "dup.csv", points, FIELD(points))
    report = tmp_path / "r.json"
    with caplog.at_level("INFO", logger="hot2cold.io.field"):
        assert main(_morph(box[0], field, out, "--report", str(report), "-q")) == 0
    assert "10 duplicate nodes at the same position as another with the same displacement merged" in caplog.text
    assert json.loads(report.read_text())["nodes_total"] == len(nodes)


@pytest.mark.heavy
@pytest.mark.parametrize("scale, pattern", [
    (1e-3, r"the field looks like metres: use --field-units m$"),
    (1 / 25.4, r"the field looks like inches: convert it to mm$"),
    (1e3, r"the field is 1000 times larger than the part: is the part in metres or the field in µm\?$"),
    (25.4, r"the field is 25\.4 times larger than the part: is the part modelled in inches but written as mm\?$"),
], ids=["metres", "inches", "x1000", "x25.4"])
def test_field_in_the_wrong_units(tmp_path, box, out, capsys, scale, pattern):
    nodes = box[1]
    field = _write_field(tmp_path / "units.csv", nodes * scale, FIELD(nodes) * scale)
    _refused(capsys, _morph(box[0], field, out), 2,
             r".*units\.csv spans [\d.e+]+ mm but the part 17\.32 mm and 100 % of its nodes are off the part: "
             + pattern, out)


def test_field_in_metres_on_a_part_at_the_origin(tmp_path, out, capsys):
    """A box with a corner at the origin and its field in metres: every node lies "on" the part, near the
    origin, yet the field spans a thousandth of it."""
    import cadquery as cq
    corner = cq.Workplane().box(10, 10, 10, centered=False).val()
    hot = tmp_path / "corner.step"
    corner.exportStep(str(hot))
    nodes = fe_surface_nodes(corner.wrapped, 1.0, seed=1)[0]
    field = _write_field(tmp_path / "metres.csv", nodes * 1e-3, FIELD(nodes) * 1e-3)
    _refused(capsys, _morph(hot, field, out), 2,
             r".*metres\.csv spans 0\.01732 mm but the part 17\.32 mm: its nodes crowd around \(0\.00\d+, 0\.00\d+, "
             r"0\.00\d+\) mm, \d+ % of them on the part there: the field looks like metres: use --field-units m$",
             out)


@pytest.mark.heavy
def test_displacements_of_the_parts_size(tmp_path, box, out, capsys):
    """Cold positions given in the displacement columns: the box's nodes move by half its diagonal."""
    nodes = box[1]
    field = _write_field(tmp_path / "cold_positions.csv", nodes, nodes + FIELD(nodes))
    _refused(capsys, _morph(box[0], field, out), 2,
             r".*cold_positions\.csv moves the node at \(.*\) mm \(row \d+ from 0\) by 8\.8\d+ mm, 51 % of the "
             r"part's 17\.32 mm diagonal, more than the 10 % a hot-to-cold field moves a part: are the columns "
             r"dx,dy,dz cold positions rather than displacements, or is it another part's field\? If it is right, "
             r"raise --max-displacement-rel$", out)
    # the override, for the rare honest field: the box doubled in size, as the field says
    report = tmp_path / "r.json"
    assert main(_morph(box[0], field, out, "--max-displacement-rel", "0.6", "--report", str(report), "-q")) == 0
    assert capsys.readouterr().err == ""
    volume = json.loads(report.read_text())["solids"][0]
    assert volume["volume_cold"] == pytest.approx(1.996 ** 3 * volume["volume_hot"], rel=1e-3)


def test_nodes_far_from_the_part(tmp_path, box, out, capsys):
    nodes = box[1]
    field = _write_field(tmp_path / "far.csv", nodes + 500.0, FIELD(nodes))
    _refused(capsys, _morph(box[0], field, out), 2,
             r"no FE node of .*far\.csv lies within 0\.0173 mm of the part \(nodes are [\d.]+ to [\d.]+ mm from its "
             r"centre, the part is 17\.32 mm across\): check the field's units \(--field-units\) and that it belongs "
             r"to this part, or raise --node-distance$", out)


@pytest.mark.heavy
def test_some_nodes_far_from_the_part_are_ignored_and_counted(tmp_path, box, out, capsys):
    nodes = box[1]
    far = nodes[:50] + 500.0
    points = np.concatenate([nodes, far])
    field = _write_field(tmp_path / "some.csv", points, FIELD(points))
    report = tmp_path / "r.json"
    assert main(_morph(box[0], field, out, "--report", str(report), "-q")) == 0
    assert json.loads(report.read_text())["nodes_ignored"] == 50
    assert capsys.readouterr().err == ""


def _top_missing(box, tmp_path):
    nodes = box[1][box[1][:, 2] < 4.99]
    return _write_field(tmp_path / "partial.csv", nodes, FIELD(nodes))


def test_field_that_misses_a_face(tmp_path, box, out, capsys):
    _refused(capsys, _morph(box[0], _top_missing(box, tmp_path), out), 2,
             r".*partial\.csv covers only part of the solid: 1 of its 6 faces gets no FE node within 0\.0173 mm where "
             r"the node density of the other faces would put 10 or more: face \d near \(0, 0, 5\) mm \(\d+\); give a "
             r"field over the whole part, or --extrapolate to morph such faces from the "
             r"field of the others$", out)


def test_very_sparse_field_that_leaves_a_large_face_bare(tmp_path, out, capsys):
    """Three nodes on the bundled blade: the node density is too low for the density rule, but a side of the
    blade (10 % or more of its surface) without a node is still a field that misses the part."""
    blade = Path(__file__).resolve().parents[1] / "sample_parts" / "twisted_blade.step"
    rows = (blade.parent / "twisted_blade_field.csv").read_text().splitlines()[:4]
    field = tmp_path / "three.csv"
    field.write_text("\n".join(rows) + "\n")
    _refused(capsys, _morph(blade, field, out), 2,
             r".*three\.csv covers only part of the solid: \d of its 6 faces gets? no FE node within 0\.109 mm where "
             r"the node density of the other faces would put 10 or more, or on a face that holds 10 % or more of "
             r"the part's surface: face 0 near .* mm \(0\).*; give a field over the whole part, or --extrapolate",
             out)


@pytest.mark.heavy
def test_field_that_misses_a_face_with_extrapolate(tmp_path, box, out, capsys):
    report = tmp_path / "r.json"
    assert main(_morph(box[0], _top_missing(box, tmp_path), out, "--extrapolate", "--report", str(report))) == 0
    err = capsys.readouterr().err
    warnings = [line for line in err.splitlines() if line.startswith("WARNING")]
    assert len(warnings) == 1 and "Traceback" not in err
    assert re.match(r"WARNING hot2cold\.pipeline\.checks: .*partial\.csv covers only part of the solid: 1 of its 6 "
                    r"faces gets no FE node .*; they are morphed from the field of the other faces, extrapolated "
                    r"\(--extrapolate\)$",
                    warnings[0])
    data = json.loads(report.read_text())
    assert out.exists() and data["valid"] and data["delta_max"] < 1e-9
    # an affine field's continuation is the field itself: the top face lands where the field takes it
    assert max(f["artificial_nodes"] for f in data["faces"]) > 0


#: The fields that turn a part inside out, fold a face or make a part cross itself move it by 11 to 58 % of
#: its diagonal, beyond what a hot-to-cold field does (they are refused as such by default,
#: test_displacements_of_the_parts_size): the checks of the cold part are reached past that bound.
_LARGE = ("--max-displacement-rel", "1")


def test_displacements_that_turn_the_part_inside_out(tmp_path, box, out, capsys):
    """x -> -x: every face turns over, the volume changes sign; the report is written, the STEP is not."""
    nodes = box[1]
    field = _write_field(tmp_path / "mirror.csv", nodes, np.column_stack([-2.0 * nodes[:, 0], 0 * nodes[:, :2]]))
    report = tmp_path / "r.json"
    _refused(capsys, _morph(box[0], field, out, "--report", str(report), *_LARGE), 4,
             r"cold solid 0 is turned inside out \(volume hot 1000 mm³, cold -1000 mm³\) \(and 4 more problems, see "
             r"the log\): the displacements are too large for this part \(check the field's units and scale, and that "
             r"it belongs to this part\); not written$", out)
    data = json.loads(report.read_text())
    assert not data["valid"] and not data["solids"][0]["valid"]


@pytest.mark.heavy
def test_displacements_that_fold_a_face(tmp_path, out, capsys):
    """The middle of a plate's top face (a 12 x 12 B-spline patch) squeezed past itself, x -> -1.5 x at the
    centre: the face folds over there, and the check says where."""
    import cadquery as cq
    top = cq.Face.makeSplineApprox([[cq.Vector(x, y, 2.0 + 0.3 * np.sin(x / 3) * np.cos(y / 3))
                                     for y in np.linspace(-10, 10, 12)] for x in np.linspace(-10, 10, 12)],
                                   tol=1e-6, minDeg=3, maxDeg=3)
    plate = cq.Solid.extrudeLinear(top, cq.Vector(0, 0, -4.0))
    hot = tmp_path / "plate.step"
    plate.exportStep(str(hot))
    nodes = fe_surface_nodes(plate.wrapped, 0.5, seed=1)[0]
    squeeze = -2.5 * np.exp(-np.hypot(nodes[:, 0], nodes[:, 1]) ** 2 / 8.0) * (nodes[:, 2] > 1.0)
    field = _write_field(tmp_path / "fold.csv", nodes,
                         np.column_stack([squeeze * nodes[:, 0], squeeze * nodes[:, 1], 0 * squeeze]))
    _refused(capsys, _morph(hot, field, out, *_LARGE), 4,
             r"cold solid 0 folds: face \d+ turns over at \d+ of \d+ points, e\.g\. near \(.*\) mm, the "
             r"field moving it by up to [\d.]+ mm \(the part is 28\.66 mm across\): the displacements are too large "
             r"for this part "
             r"\(check the field's units and scale, and that it belongs to this part\); not written$", out)


def test_field_of_another_part_with_extrapolate(tmp_path, out, capsys):
    """The bundled blade's field on the bundled filleted block, with --extrapolate: 13 of its nodes fall on the
    block, 89 % lie outside the block's bounding box (enlarged by the node distance).  Refused before the
    morph as another part's field.  (The morph from those 13 nodes follows their local estimate, since the fits
    keep it where the nodes leave poles open, so the cold-part checks that once caught the wandering faces
    would not fire.)"""
    samples = Path(__file__).resolve().parents[1] / "sample_parts"
    _refused(capsys, _morph(samples / "filleted_block.step", samples / "twisted_blade_field.csv", out,
                            "--extrapolate"), 2,
             r".*twisted_blade_field\.csv covers only part of the solid: \d+ of its 18 faces get no FE node .*; and "
             r"1699\d of its 19182 nodes \(89 %\) lie outside the part's bounding box: it looks like another part's "
             r"field, and --extrapolate would morph the part from the few nodes on it; give "
             r"this part's field$", out)


def test_volume_change_beyond_the_fields_strain(box, out, capsys, monkeypatch):
    """A cold solid whose volume changed by more than the field's strain allows.  No honest morph does that
    (the check guards against a fit gone wrong), so the bound is simulated: the box's thermal field shrinks
    it by 1.2 %, against a bound cut to 0.01 %."""
    from hot2cold.pipeline import checks
    monkeypatch.setattr(checks, "_VOLUME_MARGIN", 0.0)
    monkeypatch.setattr(checks, "_VOLUME_FLOOR", 1e-4)
    _refused(capsys, _morph(box[0], box[2], out), 4,
             r"cold solid 0 changes its volume from 1000 mm³ to 988\.\d+ mm³ \(-1\.2 %\), more than the 0\.01 % "
             r"the field's largest strain \(0\.00\d+\) allows: the displacements are too large for this part .*; "
             r"not written$", out)


def _bent_fork(tmp_path, strength: float):
    """A fork (STEP) and a field (CSV) that bends its two tines towards each other, the more the larger
    ``strength`` (1/mm)."""
    import cadquery as cq
    fork = cq.Workplane().box(20, 30, 10).cut(cq.Workplane().box(4, 20, 10).translate((0, 5, 0))).val()
    hot = tmp_path / "fork.step"
    fork.exportStep(str(hot))
    nodes = fe_surface_nodes(fork.wrapped, 1.0, seed=1)[0]
    bend = np.where(nodes[:, 1] > -5.0, strength * (nodes[:, 1] + 5.0) ** 2, 0.0) * -np.sign(nodes[:, 0])
    return hot, _write_field(tmp_path / "squeeze.csv", nodes, np.column_stack([bend, 0 * bend, 0 * bend]))


@pytest.mark.heavy
def test_displacements_that_make_the_part_cross_itself(tmp_path, out, capsys):
    """A fork whose two tines are bent towards each other until they pass through each other."""
    hot, field = _bent_fork(tmp_path, 0.012)
    _refused(capsys, _morph(hot, field, out, *_LARGE), 4,
             r"cold solid 0 crosses itself: (edges|faces|edge \d+ and face) \d+ and \d+ intersect near \(.*\) mm.*: "
             r"the displacements are too large for this part .*; not written$", out)


def _mirrored(box):
    """The box's nodes and a field that takes x to -x: the box turned inside out."""
    nodes = box[1]
    return nodes, np.column_stack([-2.0 * nodes[:, 0], 0 * nodes[:, :2]])


@pytest.mark.heavy
@pytest.mark.parametrize("case", ["inside out", "crossing"])
def test_morph_from_python_refuses_an_invalid_part(case, tmp_path, box, out):
    """From Python as from the command line: ``morph`` raises MorphError on a cold part that fails the
    checks; with ``check=False`` it returns the part, whose report says so, and ``write_step`` refuses it
    and leaves no file."""
    from hot2cold import MorphError, Settings, morph

    large = Settings(max_displacement_rel=1.0)
    hot, field = (box[0], _mirrored(box)) if case == "inside out" else _bent_fork(tmp_path, 0.012)
    what = (r"is turned inside out \(volume hot 1000 mm³, cold -1000 mm³\) \(and 4 more problems, see the log\)"
            if case == "inside out" else r"crosses itself: .*")
    refused = rf"^cold solid 0 {what}: the displacements are too large for this part .*; not written$"
    with pytest.raises(MorphError, match=refused):
        morph(hot, field, large)
    result = morph(hot, field, large, check=False)
    assert not result.report.valid and result.problems
    with pytest.raises(MorphError, match=refused):
        result.write_step(out)
    assert _left(out.parent) == []


@pytest.mark.heavy
def test_bent_fork_that_does_not_cross_is_written(tmp_path, out, capsys):
    """The same fork bent less: the gap closes by more than half, the kernel is asked, and it is fine."""
    hot, field = _bent_fork(tmp_path, 0.004)
    assert main(_morph(hot, field, out, "-q")) == 0 and out.exists()


# ---------------------------------------------------------------------------------------------------------
# Outputs
# ---------------------------------------------------------------------------------------------------------
def test_output_equal_to_the_input(tmp_path, box, capsys):
    hot = tmp_path / "hot.step"
    hot.write_bytes(box[0].read_bytes())
    _refused(capsys, _morph(hot, box[2], hot), 2, r"output .*hot\.step is the input file: choose another name$")
    assert hot.read_bytes() == box[0].read_bytes()
    _refused(capsys, _morph(box[0], box[2], tmp_path / "c.step", "--report", str(box[2])), 2,
             r"report .*box_field\.csv is the input file: choose another name$")


def test_output_folder_missing(tmp_path, box, capsys):
    _refused(capsys, _morph(box[0], box[2], tmp_path / "no" / "c.step"), 2,
             r"folder for output .*c\.step does not exist: create it first$")
    assert not (tmp_path / "no").exists()


def test_output_folder_not_writable(box, out, capsys, monkeypatch):
    real = os.access
    monkeypatch.setattr(commands.os, "access", lambda p, mode, *a, **k:
                        False if mode == os.W_OK and Path(p) == out.parent else real(p, mode, *a, **k))
    _refused(capsys, _morph(box[0], box[2], out), 2,
             r"folder for output .*cold\.step is not writable: choose another folder or fix its permissions$", out)


def test_output_is_a_folder(tmp_path, box, out, capsys):
    _refused(capsys, _morph(box[0], box[2], out.parent), 2, r"output .*out is a folder: give a file name$", out)


def test_two_outputs_to_one_file(box, out, capsys):
    _refused(capsys, _morph(box[0], box[2], out, "--stl", str(out)), 2,
             r"--stl and output are the same file .*cold\.step: choose another name$", out)


def test_output_that_cannot_be_written(box, out, capsys, monkeypatch):
    """The disk fills up while the STEP is written: exit 6, the report (written first) named, no STEP and no
    temporary file."""
    import errno

    import hot2cold.kernel.step as step
    real = step.write_atomically

    def failing(jobs):
        def write(tmp):
            Path(tmp).write_bytes(b"ISO-10303-21;\n")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real([(path, write) for path, _ in jobs])

    monkeypatch.setattr(step, "write_atomically", failing)
    report = out.with_name("r.json")
    message = _refused(capsys, _morph(box[0], box[2], out, "--report", str(report)), 6,
                       r"cannot write .*cold\.step: No space left on device \(.*r\.json written\)$")
    assert _left(out.parent) == ["r.json"], message


# ---------------------------------------------------------------------------------------------------------
# Interrupted runs
# ---------------------------------------------------------------------------------------------------------
@pytest.mark.heavy
@pytest.mark.parametrize("with_report", [False, True])
def test_interrupt_while_the_step_is_written(box, out, capsys, monkeypatch, with_report):
    """Ctrl-C while the kernel writes the cold STEP (its temporary file complete, not yet renamed): exit 130,
    no STEP and no temporary file; the message names what was written."""
    import hot2cold.kernel.step as step
    real = step.write_atomically
    seen = []

    def interrupted(jobs):
        def wrap(write):
            def write_then_stop(tmp):
                write(tmp)
                seen.append(os.path.getsize(tmp))
                raise KeyboardInterrupt
            return write_then_stop
        return real([(path, wrap(write)) for path, write in jobs])

    monkeypatch.setattr(step, "write_atomically", interrupted)
    report = out.with_name("r.json")
    argv = _morph(box[0], box[2], out, "-q", *(["--report", str(report)] if with_report else []))
    assert main(argv) == 130
    err = capsys.readouterr().err
    assert seen and seen[0] > 0                       # the interrupt came with a whole temporary STEP on disk
    written = str(report) if with_report else "nothing"
    assert err == f"hot2cold: interrupted; {written} written\n"
    assert _left(out.parent) == (["r.json"] if with_report else [])


#: ``python -m hot2cold`` whose classification first waits a minute: the box's whole morph after its load takes
#: about 2 s, and on a loaded machine a SIGINT sent on the "load" line once came after it had finished (exit 0); it
#: is sent once "classify ..." is printed.
_SLOW_CLASSIFY = """
import runpy, time
import hot2cold.pipeline.morph as morph
classify = morph.classify_nodes
def slow(*args, **kwargs):
    time.sleep(60)
    return classify(*args, **kwargs)
morph.classify_nodes = slow
runpy.run_module("hot2cold", run_name="__main__")
"""


@pytest.mark.heavy
def test_ctrl_c_in_a_running_morph(tmp_path, box):
    """A real SIGINT during the morph of the console script (its classification held up, so the signal comes
    while the morph runs however loaded the machine): exit 130, one line, no file left."""
    out = tmp_path / "cold.step"
    # A terminal's Ctrl-C reaches a process whose SIGINT is handled; a shell's background job (a CI step run
    # with &) starts its children with SIGINT ignored, which Python then leaves ignored: reset it, as a
    # terminal would have it.
    proc = subprocess.Popen([sys.executable, "-c", _SLOW_CLASSIFY, "morph", str(box[0]), str(box[2]), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        lines = [proc.stderr.readline() for _ in range(4)]     # "read: done ...", ..., "classify ...": under way
        assert lines[-1].startswith("classify ..."), lines
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130
    assert err.splitlines()[-1] == "hot2cold: interrupted; nothing written" and "Traceback" not in err
    assert _left(tmp_path) == []


def _bending(nodes: np.ndarray, c: float = 0.004) -> np.ndarray:
    """A field that bends the box along x: ``dz = c x^2`` (0.1 mm at its sides x = ±5 mm for c = 0.004)."""
    return np.column_stack([0 * nodes[:, 0], 0 * nodes[:, 0], c * nodes[:, 0] ** 2])


@pytest.mark.heavy
def test_a_field_the_faces_cannot_follow_is_reported_between_the_nodes(tmp_path, box, out, capsys):
    """The box's faces are bilinear patches between straight edges: with their knots kept (``--keep-knots``)
    they stay flat under a field that bends them, the top and bottom faces 0.1 mm (the whole displacement)
    off it in their middle, between the nodes.  The report says so per face; the part is written (it is
    inaccurate, not wrong) with exit code 5, the tolerance missed.  By default the faces are refined and
    follow the field."""
    field = _write_field(tmp_path / "bend.csv", box[1], _bending(box[1]))
    report = tmp_path / "report.json"
    assert main(_morph(box[0], field, out, "--report", str(report), "-q", "--keep-knots")) == 5
    assert re.match(r"hot2cold: tolerance 0\.001 mm not met \((face|edge) \d+ at its nodes: 0\.\d+ mm",
                    capsys.readouterr().err)
    data = json.loads(report.read_text())
    between = sorted(f["delta_between"] for f in data["faces"])
    assert between[-1] == pytest.approx(0.1, abs=2e-3)
    assert data["delta_between"] == between[-1]
    assert data["max_displacement"] == pytest.approx(0.1, abs=1e-3)
    assert data["keep_knots"] and not data["refinements"]

    assert main(_morph(box[0], field, out, "--report", str(report), "-q")) == 0
    data = json.loads(report.read_text())
    assert data["delta_between"] < 1e-3 and data["delta_max"] < 1e-3 and data["tolerance_met"]
    assert {r["face"] for r in data["refinements"]} >= {f["index"] for f in data["faces"] if f["nodes"]}


@pytest.mark.heavy
def test_face_grids_take_a_field_with_elements_from_its_elements(box):
    """For a field that brings its FE elements, the grids that measure the faces between the nodes move their
    points by the elements' own field (:class:`~hot2cold.pipeline.artificial.ElementField`), all of them
    near the nodes: here a triangulation of the box whose nodal values are the field plus 0.01 mm along x,
    against the nodes' local estimate of the field alone."""
    from hot2cold import morph
    from hot2cold.kernel.project import Projector
    from hot2cold.kernel.tessellate import tessellate
    from hot2cold.pipeline.artificial import ElementField, FieldEstimator
    from hot2cold.pipeline.grids import FaceGridder, FaceNodes

    nodes = box[1]
    result = morph(str(box[0]), (nodes, FIELD(nodes)))
    part, cls = result.part, result.classification
    estimator = FieldEstimator(cls.foot[cls.used], result.field.displacements[cls.used])
    projector = Projector(part.kernel.faces, part.kernel.edges)
    mesh = tessellate(part.kernel.hot)
    offset = np.array([0.01, 0.0, 0.0])
    elements = ElementField(mesh.vertices, mesh.triangles, FIELD(mesh.vertices) + offset, reach=0.01, strain=0.1)
    plain = FaceGridder(projector, FaceNodes(cls, result.field, 20), estimator)(part)
    taken = FaceGridder(projector, FaceNodes(cls, result.field, 20), estimator, elements)(part)
    for p, t in zip(plain, taken):
        assert np.abs(p.expected - p.hot - FIELD(p.hot)).max() < 1e-9
        assert np.abs(t.expected - t.hot - FIELD(t.hot) - offset).max() < 1e-9
        assert t.near.all() and t.slack.max() < 1e-9


@pytest.mark.heavy
def test_face_grids_from_kept_face_nodes_are_the_same(box):
    """The faces' nodes and estimates kept across calls (:class:`~hot2cold.pipeline.grids.FaceNodes`, as the
    refinement keeps them) give the grids found anew, point for point, and so do grids made without their
    slack and given it later (:func:`~hot2cold.pipeline.grids.with_slack`).  (The gridder takes the
    classification and the field from its kept nodes, so none can be kept for another field.)"""
    from hot2cold import morph
    from hot2cold.kernel.project import Projector
    from hot2cold.pipeline.artificial import FieldEstimator
    from hot2cold.pipeline.grids import FaceGridder, FaceNodes, with_slack

    nodes = box[1]
    result = morph(str(box[0]), (nodes, FIELD(nodes)))
    part, cls, field = result.part, result.classification, result.field
    estimator = FieldEstimator(cls.foot[cls.used], field.displacements[cls.used])
    projector = Projector(part.kernel.faces, part.kernel.edges)
    kept = FaceNodes(cls, field, 20)
    anew = FaceGridder(projector, FaceNodes(cls, field, 20), estimator)(part)
    kept_gridder = FaceGridder(projector, kept, estimator)
    for _ in range(2):                                   # building the kept nodes, then reusing them
        again = kept_gridder(part)
        for a, g in zip(anew, again):
            np.testing.assert_array_equal(g.expected, a.expected)
            np.testing.assert_array_equal(g.slack, a.slack)
            np.testing.assert_array_equal(g.node_distance, a.node_distance)
    # made without their slack (G1's trials) and given it afterwards: the same grids, in threads too
    lean = FaceGridder(projector, FaceNodes(cls, field, 20), estimator)(part, slack=False)
    assert any(np.isnan(g.slack).any() for g in lean)
    for a, g in zip(anew, with_slack(part, lean, FaceNodes(cls, field, 20), threads=2)):
        np.testing.assert_array_equal(g.slack, a.slack)
        np.testing.assert_array_equal(g.expected, a.expected)


def test_cold_face_away_from_the_field_between_the_nodes(tmp_path, box, out, capsys, monkeypatch):
    """A face more than twice the field's largest displacement from the field's local estimate somewhere on
    it is refused.  An honest morph of the box does not get there (the check guards against a fit gone
    wrong), so the bound is cut to a tenth of the displacement, which the bent box's flat faces miss with
    their knots kept."""
    from hot2cold.pipeline import checks
    monkeypatch.setattr(checks, "_BETWEEN_MARGIN", 0.1)
    field = _write_field(tmp_path / "bend.csv", box[1], _bending(box[1]))
    _refused(capsys, _morph(box[0], field, out, "--keep-knots"), 4,
             r"cold solid 0 leaves the field between the nodes: face \d is 0\.\d+ mm from where the field's local "
             r"estimate puts it near \(.*\) mm, more than 0\.1 x the field's largest displacement \(0\.1 mm\)", out)


@pytest.mark.heavy
def test_check_cold_finds_a_bump_between_the_nodes(box):
    """A fit gone wrong where the report's nodes do not look: a 1 mm bump in the middle of the top face of a
    box morphed exactly.  The check over a grid of every face finds it (and only there)."""
    from dataclasses import replace

    from hot2cold import morph
    from hot2cold.core.bspline import insert_knots
    from hot2cold.kernel.project import Projector
    from hot2cold.kernel.validity import check_solids
    from hot2cold.pipeline.artificial import FieldEstimator
    from hot2cold.pipeline.checks import FieldScale, Rebuilt, check_cold
    from hot2cold.pipeline.grids import FaceGridder, FaceNodes

    nodes = box[1]
    result = morph(str(box[0]), (nodes, FIELD(nodes)))
    part, cls = result.part, result.classification
    used = cls.used
    estimator = FieldEstimator(cls.foot[used], result.field.displacements[used])
    projector = Projector(part.kernel.faces, part.kernel.edges)
    solids = (check_solids(part.kernel.hot), check_solids(result.cold_kernel.shape))
    args = (projector, FieldScale.of(cls, result.field), FaceGridder(projector, FaceNodes(cls, result.field, 20),
                                                                       estimator)(part))
    fine = check_cold(part, Rebuilt(result.cold_kernel, result.faces, *solids), *args)
    assert fine.problems == {}
    assert np.nanmax(fine.between) < 1e-9
    top = max(range(len(part.faces)), key=lambda k: part.faces[k].surface.poles[..., 2].min())
    surface = result.faces[top].surface
    for axis in (0, 1):
        lo, hi = (surface.u_knots if axis == 0 else surface.v_knots)[[0, -1]]
        surface = insert_knots(surface, axis, [(lo + hi) / 2])
    poles = surface.poles.copy()
    poles[1, 1, 2] += 1.0
    faces = list(result.faces)
    faces[top] = replace(faces[top], surface=surface.with_poles(poles))
    bumped = check_cold(part, Rebuilt(result.cold_kernel, faces, *solids), *args)
    assert 0.9 < bumped.between[top] <= 1.0       # the distance to a tent 1 mm high over 5 mm: 0.98 at its top
    assert np.nanmax(np.delete(bumped.between, top)) < 1e-9
    assert any(p.startswith(f"leaves the field between the nodes: face {top} is 0.9") for p in bumped.problems[0])
    # the bump also moves the face farther than the field moves any node (0.3 mm, 1.5 x that + the node
    # distance accepted): the README's row of that message
    scale = args[1]
    assert 0.2 < scale.largest < 0.4 and scale.move_bound < 0.9
    assert any(re.match(rf"moves face {top} by up to 1\.\d+ mm near \(.*\) mm, farther than the field moves any "
                        rf"node \(0\.\d+ mm; up to 1\.5 x that \+ 0\.\d+ mm accepted\)$", p)
               for p in bumped.problems[0]), bumped.problems[0]


def _in_unit(step: Path, target: Path, unit: str) -> Path:
    """``step`` (in mm) written again with its lengths declared in ``unit`` ("INCH" or "METRE"): the same
    numbers, so the part is 25.4 or 1000 times larger once read."""
    text = step.read_text()
    mm = re.search(r"\( LENGTH_UNIT\(\) NAMED_UNIT\(\*\) SI_UNIT\(\.MILLI\.,\.METRE\.\) \)", text)
    assert mm, "the STEP writer's millimetre unit"
    if unit == "METRE":
        declared = "( LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT($,.METRE.) )"
        target.write_text(text.replace(mm.group(0), declared))
        return target
    declared = "( CONVERSION_BASED_UNIT('INCH',#90001) LENGTH_UNIT() NAMED_UNIT(#90002) )"
    extra = ("#90001 = LENGTH_MEASURE_WITH_UNIT(LENGTH_MEASURE(25.4),#90003);\n"
             "#90002 = DIMENSIONAL_EXPONENTS(1.,0.,0.,0.,0.,0.,0.);\n"
             "#90003 = ( LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT(.MILLI.,.METRE.) );\n")
    text = text.replace(mm.group(0), declared).replace("ENDSEC;\nEND-ISO-10303-21;",
                                                       extra + "ENDSEC;\nEND-ISO-10303-21;")
    target.write_text(text)
    return target


@pytest.mark.parametrize("unit, factor, said", [("INCH", 25.4, "inch"), ("METRE", 1000.0, "metre")])
def test_a_step_in_another_unit_is_said_to_come_out_in_millimetres(tmp_path, box, out, capsys, unit, factor, said):
    """A hot STEP that states its lengths in inches or metres is read in millimetres (the kernel converts) and the
    cold part is written in millimetres: the command line says so in a warning; a millimetre STEP says nothing."""
    step = _in_unit(box[0], tmp_path / f"box_{unit}.step", unit)
    nodes = box[1] * factor
    field = _write_field(tmp_path / "f.csv", nodes, FIELD(nodes))
    code = main(_morph(step, field, out))
    err = capsys.readouterr().err
    assert code == 0
    assert f"box_{unit}.step states its lengths in {said}: hot2cold reads and writes in millimetres, so the cold " \
           f"part is in millimetres" in err
    assert main(_morph(box[0], box[2], tmp_path / "mm.step")) == 0
    assert "states its lengths" not in capsys.readouterr().err
