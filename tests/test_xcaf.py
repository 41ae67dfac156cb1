"""Nothing lost: names, colours, solids, faces, their order and the assembly tree survive the morph, and the
same input gives the same cold geometry on every run.

The hot part is a two-part CadQuery assembly (the bundled twisted blade and a box placed beside it) written
by CadQuery's own STEP export, with names and colours on both parts and on three faces; the field is an
affine one (a morph reproduces it to rounding), so every cold face can be checked against its hot face.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import re
import subprocess
import sys

import cadquery as cq
import numpy as np
import pytest
from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

from hot2cold import morph
from hot2cold.cli import main
from hot2cold.errors import StepReadError
from hot2cold.kernel.sampling import fe_surface_nodes
from hot2cold.kernel.step import read_step
from hot2cold.kernel.topology import decompose
from hot2cold.kernel.xcaf import read_step_styles
from hot2cold.testing.synthetic import AffineField

FIELD = AffineField.thermal(contraction=-0.004, rotation_deg=0.3, translation=(0.1, -0.2, 0.05))

RED, BLUE, GREEN, YELLOW = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (1.0, 1.0, 0.0)


def _write_field(path, points):
    np.savetxt(path, np.column_stack([points, FIELD(points)]), delimiter=",", header="x,y,z,dx,dy,dz",
               comments="", fmt="%.12g")
    return path


@pytest.fixture(scope="module")
def parts(blade_step):
    blade = cq.Shape.cast(read_step(blade_step))
    box = cq.Workplane().box(10, 20, 30).val()
    return blade, box


@pytest.fixture(scope="module")
def assembly(tmp_path_factory, parts):
    """``(hot STEP, field CSV)``: blade (red) and block (blue, 60 mm along x); blade face 1 named and yellow,
    block face 0 named and green, block face 3 named only."""
    folder = tmp_path_factory.mktemp("xcaf")
    blade, box = parts
    assy = cq.Assembly(name="rig")
    assy.add(blade, name="blade", color=cq.Color(*RED))
    assy.add(box, name="block", color=cq.Color(*BLUE), loc=cq.Location((60, 0, 0)))
    assy["blade"].addSubshape(blade.Faces()[1], name="blade_face1", color=cq.Color(*YELLOW))
    assy["block"].addSubshape(box.Faces()[0], name="block_face0", color=cq.Color(*GREEN))
    assy["block"].addSubshape(box.Faces()[3], name="block_face3")
    hot = folder / "rig.step"
    assy.export(str(hot))
    nodes = fe_surface_nodes(read_step(hot), 1.5, seed=4)[0]
    return hot, _write_field(folder / "rig_field.csv", nodes)


@pytest.fixture(scope="module")
def cli_run(assembly, tmp_path_factory):
    """``hot2cold morph`` on the assembly: (exit code, printed table, cold STEP, report dict)."""
    hot, field = assembly
    folder = tmp_path_factory.mktemp("cold")
    cold, report = folder / "rig_cold.step", folder / "rig_cold.json"
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["morph", str(hot), str(field), "-o", str(cold), "--report", str(report)])
    return code, out.getvalue(), cold, json.loads(report.read_text())


@pytest.mark.heavy
def test_quiet_run_with_names_and_colours_prints_nothing(assembly, tmp_path):
    """The names-and-colours writer (XCAF) is held quiet as the plain one: ``-q`` prints nothing, in a process
    of its own (the kernel prints past Python's streams)."""
    hot, field = assembly
    proc = subprocess.run([sys.executable, "-m", "hot2cold", "morph", str(hot), str(field), "-o",
                           str(tmp_path / "rig_cold.step"), "-q"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "" and proc.stderr == ""
    assert read_step_styles(tmp_path / "rig_cold.step")[1].solids[0].name


def _rgb(style):
    return None if style.colour is None else tuple(round(c, 6) for c in style.colour[:3])


def _tree(instance):
    """The document tree below a free shape or component: names, colours, placement, parts' solids and
    labelled sub-shapes."""
    node = instance.node
    trsf = instance.location.Transformation()
    return (instance.style, node.style, tuple(round(trsf.Value(r, 4), 9) for r in (1, 2, 3)),
            node.solids, tuple((s.path, s.kind, s.index, s.style) for s in node.subshapes),
            tuple(_tree(c) for c in node.children))


@pytest.mark.heavy
def test_names_and_colours_survive_the_round_trip(cli_run, assembly):
    code, _, cold, _ = cli_run
    assert code == 0
    _, hot_styles = read_step_styles(assembly[0])
    _, cold_styles = read_step_styles(cold)
    # what the hot file carries (CadQuery's export: names on the instances and parts, colours on the parts)
    assert [s.name for s in hot_styles.solids] == ["blade", "block"]
    assert [_rgb(s) for s in hot_styles.solids] == [RED, BLUE]
    named = {k: (f.name, _rgb(f)) for k, f in enumerate(hot_styles.faces) if f}
    assert sorted(named.values(), key=str) == sorted([("blade_face1", YELLOW), ("block_face0", GREEN),
                                                      ("block_face3", None)], key=str)
    # ... and the cold file the same, solid for solid and face for face
    assert cold_styles.solids == hot_styles.solids
    assert cold_styles.faces == hot_styles.faces
    assert [_tree(r) for r in cold_styles.roots] == [_tree(r) for r in hot_styles.roots]
    root = cold_styles.roots[0].node
    assert root.style.name == "rig" and [c.style.name for c in root.children] == ["blade", "block"]


def test_report_names_each_solid(cli_run):
    code, table, _, report = cli_run
    assert code == 0
    assert [s["name"] for s in report["solids"]] == ["blade", "block"]
    assert [s["faces"] for s in report["solids"]] == [6, 6]
    assert all(s["valid"] and s["free_edges"] == 0 for s in report["solids"])
    assert "solid 0 'blade': valid, closed" in table and "solid 1 'block': valid, closed" in table


@pytest.mark.heavy
def test_report_names_each_face(cli_run):
    """Issue 17: faces are named in the table and the JSON: by the STEP's name where it gives one, else by their
    surface kind and place (the blade's aerofoil faces are B-splines between planes at z = 0 and 100, the
    block's faces planes 5, 10 and 15 mm from its centre at x = 60)."""
    code, table, _, report = cli_run
    names = [f["name"] for f in report["faces"]]
    assert names[1] == "blade_face1" and names[6] == "block_face0" and names[9] == "block_face3"
    assert all(n.startswith("B-spline surface near (") for n in (names[0], names[2], names[3]))
    assert names[4:6] == ["plane z = 0", "plane z = 100"]                  # the blade's root and tip
    planes = {n for k, n in enumerate(names[6:], 6) if k not in (6, 9)}
    assert planes <= {"plane x = 55", "plane x = 65", "plane y = -10", "plane y = 10", "plane z = -15",
                      "plane z = 15"} and len(planes) == 4, names
    lines = table.splitlines()
    assert lines[0] == report["verdict"]["text"] and lines[1].split()[0] == "face"      # the verdict, the header
    rows = [line.split() for line in lines[2:14]]
    assert [" ".join(r[5:]) for r in rows] == names


def test_solid_and_face_order_kept(cli_run, assembly):
    _, _, cold, report = cli_run
    hot = decompose(read_step(assembly[0]))
    back = decompose(read_step(cold))
    assert back.solids == hot.solids                      # same solids, same faces each, same order
    assert len(back.faces) == len(hot.faces) == len(report["faces"]) == 12
    for h, c in zip(hot.faces, back.faces):               # cold face k is hot face k, moved by the field
        assert c.surface.poles.shape == h.surface.poles.shape
        np.testing.assert_allclose(c.surface.poles, FIELD.exact_map(h.surface.poles.reshape(-1, 3))
                                   .reshape(h.surface.poles.shape), atol=1e-7)
    # the named faces are where the hot ones went
    _, styles = read_step_styles(cold)
    block_face0 = next(k for k, f in enumerate(styles.faces) if f.name == "block_face0")
    assert hot.faces[block_face0].solid == 1
    x = FIELD.exact_map(hot.faces[block_face0].surface.poles.reshape(-1, 3))
    np.testing.assert_allclose(back.faces[block_face0].surface.poles.reshape(-1, 3), x, atol=1e-7)


@pytest.mark.heavy
def test_same_input_same_cold_geometry(assembly, cli_run, tmp_path):
    """Two morphs in this process give bit-identical poles; the cold STEP of a third one, in a fresh process
    with another hash seed, holds bit-identical geometry."""
    hot, field = assembly
    first, second = morph(hot, field), morph(hot, field)
    for a, b in zip(first.faces, second.faces):
        assert np.array_equal(a.surface.poles, b.surface.poles)
    for a, b in zip(first.edges, second.edges):
        assert (a.curve is None and b.curve is None) or np.array_equal(a.curve.poles, b.curve.poles)
    assert np.array_equal(first.node_errors, second.node_errors, equal_nan=True)
    first.write_step(tmp_path / "a.step")
    second.write_step(tmp_path / "b.step")
    env = dict(os.environ, PYTHONHASHSEED="12345")
    run = subprocess.run([sys.executable, "-m", "hot2cold", "morph", str(hot), str(field), "-o",
                          str(tmp_path / "c.step"), "-q"], env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    files = [tmp_path / "a.step", tmp_path / "b.step", tmp_path / "c.step", cli_run[2]]
    parts = [decompose(read_step(f)) for f in files]
    for other in parts[1:]:
        for a, b in zip(parts[0].faces, other.faces):
            assert np.array_equal(a.surface.poles, b.surface.poles)
            assert np.array_equal(a.surface.u_knots, b.surface.u_knots)
        for a, b in zip(parts[0].edges, other.edges):
            assert (a.curve is None and b.curve is None) or np.array_equal(a.curve.poles, b.curve.poles)
        assert np.array_equal(parts[0].vertices, other.vertices)


def _nameless_step(path, shape):
    """``shape`` written by the plain STEP writer, then every product and instance name blanked."""
    writer = STEPControl_Writer()
    writer.Transfer(shape, STEPControl_AsIs)
    writer.Write(str(path))
    text = path.read_text()
    text = re.sub(r"PRODUCT\(\s*'[^']*'\s*,\s*'[^']*'", "PRODUCT('',''", text)
    text = re.sub(r"NEXT_ASSEMBLY_USAGE_OCCURRENCE\(\s*'[^']*'\s*,\s*'[^']*'", "NEXT_ASSEMBLY_USAGE_OCCURRENCE('',''",
                  text)
    path.write_text(text)
    return path


@pytest.mark.heavy
def test_step_without_names_still_works(tmp_path, parts, capsys):
    blade, box = parts
    hot = _nameless_step(tmp_path / "plain.step",
                         cq.Compound.makeCompound([blade, box.moved(cq.Location((60, 0, 0)))]).wrapped)
    shape, styles = read_step_styles(hot)
    assert not styles.carried and [s.name for s in styles.solids] == ["", ""]
    field = _write_field(tmp_path / "field.csv", fe_surface_nodes(shape, 2.0, seed=5)[0])
    cold, report = tmp_path / "cold.step", tmp_path / "cold.json"
    assert main(["morph", str(hot), str(field), "-o", str(cold), "--report", str(report), "-q"]) == 0
    data = json.loads(report.read_text())
    assert [s["name"] for s in data["solids"]] == ["", ""]
    assert data["valid"] and data["closed"] and data["delta_max"] < 1e-7
    back = decompose(read_step(cold))
    assert len(back.solids) == 2 and len(back.faces) == 12


def test_styles_reader_reads_the_shape_of_the_plain_reader(blade_step):
    plain = decompose(read_step(blade_step))
    shape, styles = read_step_styles(blade_step)
    styled = decompose(shape)
    assert [s.name for s in styles.solids] == ["twisted_blade 1"]
    assert len(styled.faces) == len(plain.faces) and styled.solids == plain.solids
    for a, b in zip(plain.faces, styled.faces):
        assert np.array_equal(a.surface.poles, b.surface.poles)


def _no_solid(path):
    writer = STEPControl_Writer()
    writer.Transfer(cq.Workplane().rect(3, 4).val().wrapped, STEPControl_AsIs)
    writer.Write(str(path))
    return path


@pytest.mark.parametrize("make, words", [
    (lambda p: p, "not found"),
    (lambda p: (p.write_text(""), p)[1], "empty"),
    (lambda p: (p.write_text("this is not STEP\n"), p)[1], "cannot read"),
    (_no_solid, "no solid"),
])
def test_styles_reader_refuses_as_the_plain_reader(tmp_path, make, words):
    path = make(tmp_path / "bad.step")
    with pytest.raises(StepReadError, match=words) as styled:
        read_step_styles(path)
    with pytest.raises(StepReadError) as plain:
        read_step(path)
    assert str(styled.value) == str(plain.value)


@pytest.mark.heavy
def test_nested_assembly_with_a_part_placed_twice(tmp_path, capsys):
    """A sub-assembly (placed, with a half-transparent box and a cylinder with a coloured face) and one box
    placed twice from the same part: every solid morphed, the tree, names and colours kept."""
    box = cq.Workplane().box(10, 20, 30).val()
    cylinder = cq.Workplane().cylinder(20, 5).val()
    sub = cq.Assembly(name="sub", loc=cq.Location((0, 50, 0)))
    sub.add(box, name="inner_box", color=cq.Color(0.2, 0.4, 0.6, 0.5))
    sub.add(cylinder, name="inner_cyl", loc=cq.Location((30, 0, 0)))
    sub["inner_cyl"].addSubshape(cylinder.Faces()[0], name="cyl_face", color=cq.Color(*GREEN))
    top = cq.Assembly(name="top")
    top.add(sub, name="sub")
    top.add(box, name="twin_a", loc=cq.Location((-40, 0, 0), (0, 0, 1), 30))
    top.add(box, name="twin_b", loc=cq.Location((-80, 0, 0)))
    hot = tmp_path / "nested.step"
    top.export(str(hot))
    shape, hot_styles = read_step_styles(hot)
    assert [s.name for s in hot_styles.solids] == ["inner_box", "inner_cyl", "twin_a", "twin_b"]
    field = _write_field(tmp_path / "field.csv", fe_surface_nodes(shape, 1.5, seed=6)[0])
    cold, report = tmp_path / "cold.step", tmp_path / "cold.json"
    assert main(["morph", str(hot), str(field), "-o", str(cold), "--report", str(report), "-q"]) == 0
    assert [s["name"] for s in json.loads(report.read_text())["solids"]] == [s.name for s in hot_styles.solids]
    _, cold_styles = read_step_styles(cold)
    assert cold_styles.solids == hot_styles.solids and cold_styles.faces == hot_styles.faces
    assert [_tree(r) for r in cold_styles.roots] == [_tree(r) for r in hot_styles.roots]
    assert hot_styles.solids[0].colour[3] == 0.5
    hot_part, back = decompose(shape), decompose(read_step(cold))
    assert back.solids == hot_part.solids
    for h, c in zip(hot_part.faces, back.faces):
        np.testing.assert_allclose(c.surface.poles.reshape(-1, 3), FIELD.exact_map(h.surface.poles.reshape(-1, 3)),
                                   atol=1e-7)


@pytest.mark.quick
def test_sub_shapes_are_found_by_their_paths_once_their_parents_children_are_listed():
    """The sub-shapes of a located solid at the paths the hot document's sub-shapes are found by (its faces,
    edges and vertices, the first path to a shared one): each the shape at that path, in place; a path
    through a child that is not there is the kernel's error."""
    from hot2cold.errors import KernelError
    from hot2cold.kernel.xcaf import _Follower, _Paths

    solid = cq.Workplane().box(10, 20, 30).val().moved(cq.Location((5, -3, 2), (1, 1, 0), 30)).wrapped
    paths = _Paths(solid)
    follow = _Follower(solid)
    assert len(paths.paths) > 26                       # the solid, its shell, 6 faces, 12 edges, 8 vertices, wires
    for path in paths.paths:
        found = follow(path)
        assert paths.path(found) == path and paths.map.FindKey(paths.map.FindIndex(found)).IsEqual(found)
    with pytest.raises(KernelError, match="no child 6"):
        follow((0, 6))


@pytest.mark.quick
def test_a_cold_document_of_two_placed_free_shapes_holds_both():
    """Two free shapes of the document, each placed (a reference label): the cold document holds both, with their
    names, each where the shape has it."""
    from OCP.BRep import BRep_Builder
    from OCP.TDF import TDF_LabelSequence
    from OCP.TopLoc import TopLoc_Location
    from OCP.TopoDS import TopoDS_Compound
    from OCP.XCAFDoc import XCAFDoc_DocumentTool, XCAFDoc_ShapeTool

    from hot2cold.kernel.xcaf import Instance, Node, Style, Styles, _style, cold_document

    boxes = [cq.Workplane().box(10, 10, 10).val().moved(cq.Location((20 * k, 0, 0))).wrapped for k in range(2)]
    compound = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(compound)
    for box in boxes:
        builder.Add(compound, box)
    names = ("left", "right")
    roots = tuple(Instance(Style(name), TopLoc_Location(), Node(Style(name), path=(k,), location=TopLoc_Location(),
                                                                solids=(k,)))
                  for k, name in enumerate(names))
    styles = Styles(roots, tuple(Style(name) for name in names), (Style(),) * 12, True)

    document = cold_document(compound, styles)
    free = TDF_LabelSequence()
    XCAFDoc_DocumentTool.ShapeTool_s(document.Main()).GetFreeShapes(free)
    labels = [free.Value(i) for i in range(1, free.Length() + 1)]
    assert len(labels) == 2
    for label, box, name in zip(labels, boxes, names):
        assert XCAFDoc_ShapeTool.GetShape_s(label).IsPartner(box) and _style(label).name == name
