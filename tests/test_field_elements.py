"""The field readers keep the FE model's elements: ``DisplacementField.triangles`` from ``.npz``, mesh files
(meshio) and CalculiX ``.frd`` files (its element block, :attr:`hot2cold.io.frd.FrdFile.elements`).

The ``.frd`` files are written by CalculiX itself (``ccx``, a few seconds on a coarse mesh of a box), and
rewritten here into the short format or damaged; small synthetic ones cover the element types ccx does not
write for a solid (shell triangles, bricks).
"""
from __future__ import annotations

import logging
from pathlib import Path

import cadquery as cq
import meshio
import numpy as np
import pytest

from hot2cold.core.elements import GMSH_TO_TET10, boundary_triangles
from hot2cold.errors import FieldError
from hot2cold.fe import mesh_step, read_hot_to_cold, run_ccx, write_deck
from hot2cold.io.frd import FrdFile
from hot2cold.io.cells import element_triangles
from hot2cold.io.field import DisplacementField, read_field

BOX = (20.0, 8.0, 6.0)
BOX_AREA = 2 * (BOX[0] * BOX[1] + BOX[1] * BOX[2] + BOX[0] * BOX[2])


# ---------------------------------------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------------------------------------
def edge_uses(triangles: np.ndarray) -> np.ndarray:
    """How many triangles use each (corner) edge of ``triangles``."""
    t = triangles[:, :3]
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    return np.unique(edges, axis=0, return_counts=True)[1]


def area(points: np.ndarray, triangles: np.ndarray) -> float:
    p = points[triangles[:, :3]]
    return float(0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum())


def faces(triangles: np.ndarray) -> set:
    """The triangles as a set of sorted corner triples."""
    return {tuple(sorted(t)) for t in np.asarray(triangles)[:, :3].tolist()}


def assert_midside_at_midpoints(points: np.ndarray, triangles: np.ndarray) -> None:
    """Nodes 3, 4, 5 of each 6-node triangle are the midpoints of its edges 0-1, 1-2, 2-0 (straight edges)."""
    p = points[triangles]
    for mid, (a, b) in zip((3, 4, 5), ((0, 1), (1, 2), (2, 0))):
        np.testing.assert_allclose(p[:, mid], 0.5 * (p[:, a] + p[:, b]), atol=1e-9)


# ---------------------------------------------------------------------------------------------------------
# Real CalculiX results
# ---------------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A box meshed with 10-node (rotating: two DISP blocks) and 4-node tetrahedra, each run through ccx:
    ``{order: (mesh, frd path)}``."""
    folder = tmp_path_factory.mktemp("ccx")
    step = folder / "box.step"
    cq.exporters.export(cq.Workplane().box(*BOX, centered=False), str(step))
    out = {}
    for order, omega in ((2, 1000.0), (1, 0.0)):
        mesh = mesh_step(step, 4.0, order=order)
        fixed = {a: np.flatnonzero(np.abs(mesh.nodes[:, a]) < 1e-9) for a in range(3)}
        deck = write_deck(mesh, folder / f"order{order}.inp", fixed_nodes=fixed, hot_temperature=493.0,
                          omega=omega, axis_direction=(1.0, 0.0, 0.0), axis_point=(0.0, -50.0, 0.0))
        out[order] = (mesh, run_ccx(deck, timeout=120))
    return out


def mesh_tets(mesh) -> np.ndarray:
    """The mesh's tetrahedra (rows of its nodes) in the VTK / CalculiX node order."""
    return mesh.tets[:, GMSH_TO_TET10] if mesh.tets.shape[1] == 10 else mesh.tets


@pytest.mark.gmsh
@pytest.mark.calculix
@pytest.mark.parametrize("order", [2, 1])
def test_frd_elements_are_the_decks(runs, order):
    mesh, frd = runs[order]
    elements = FrdFile.read(frd).elements
    etype = 6 if order == 2 else 3
    assert list(elements) == [etype]
    np.testing.assert_array_equal(elements[etype], mesh.node_tags[mesh_tets(mesh)])


@pytest.mark.gmsh
@pytest.mark.calculix
@pytest.mark.parametrize("order", [2, 1])
def test_frd_triangles_are_the_mesh_boundary(runs, order):
    mesh, frd = runs[order]
    field = read_field(frd, points_from=mesh)
    tri = field.triangles
    assert tri is not None and tri.shape[1] == (6 if order == 2 else 3)
    # The same nodes as the boundary of the mesh's own tetrahedra, triangle by triangle, node by node.
    expected = boundary_triangles(mesh_tets(mesh))
    np.testing.assert_array_equal(field.node_ids[tri], mesh.node_tags[expected])
    # ... hence at the same positions (the full-precision ones of the mesh).
    np.testing.assert_array_equal(field.points[tri], mesh.nodes[expected])
    # A closed surface: every edge in exactly two triangles; it covers the box, and uses every boundary node.
    assert np.all(edge_uses(tri) == 2)
    assert area(field.points, tri) == pytest.approx(BOX_AREA, rel=1e-12)
    np.testing.assert_array_equal(np.unique(field.node_ids[tri]), np.sort(mesh.node_tags[mesh.boundary_nodes()]))
    if order == 2:
        assert_midside_at_midpoints(field.points, tri)
    # The .frd's own (6-digit) coordinates: the same triangles, the positions to 6 digits.
    own = read_field(frd)
    np.testing.assert_array_equal(own.triangles, tri)
    np.testing.assert_allclose(own.points[own.triangles], mesh.nodes[expected], rtol=1e-5, atol=1e-9)
    # read_hot_to_cold (two DISP blocks for order 2) brings them too.
    h2c = read_hot_to_cold(frd, points_from=mesh)
    np.testing.assert_array_equal(h2c.triangles, tri)
    np.testing.assert_array_equal(h2c.points[h2c.triangles], mesh.nodes[expected])


def short_format(text: str) -> str:
    """A long-format (indicator 1) ``.frd`` rewritten in the short format (0): numbers in I5."""
    out, block = [], None
    for ln in text.splitlines():
        if ln[:6] in ("    2C", "    3C", "  100C"):
            assert ln[73:75].strip() == "1"                  # I1 (node, element blocks) or I2 (results)
            ln, block = ln[:73] + ln[73:75].replace("1", "0") + ln[75:], ln[:6]
        elif ln.startswith(" -1") and block:
            ln = f" -1{int(ln[3:13]):5d}{ln[13:]}"
        elif ln.startswith(" -2") and block == "    3C":
            ln = " -2" + "".join(f"{int(ln[k:k + 10]):5d}" for k in range(3, len(ln), 10))
        elif ln.startswith(" -3"):
            block = None
        out.append(ln)
    return "\n".join(out) + "\n"


@pytest.mark.gmsh
@pytest.mark.calculix
def test_frd_short_format(runs, tmp_path):
    mesh, frd = runs[2]
    text = short_format(frd.read_text())
    assert " -1    1    6    0    1\n -2" in text
    short = tmp_path / "short.frd"
    short.write_text(text)
    np.testing.assert_array_equal(FrdFile.read(short).elements[6], FrdFile.read(frd).elements[6])
    field, long = read_field(short, points_from=mesh), read_field(frd, points_from=mesh)
    np.testing.assert_array_equal(field.triangles, long.triangles)
    np.testing.assert_array_equal(field.displacements, long.displacements)


def _element_lines(text: str) -> tuple[list[str], int]:
    """The lines of ``text`` and the index of its element block header."""
    lines = text.splitlines()
    return lines, next(i for i, ln in enumerate(lines) if ln.startswith("    3C"))


def _damage(text: str, how: str) -> tuple[str, str]:
    """``text`` with its element block damaged ``how``, and the message expected (naming the line)."""
    lines, h = _element_lines(text)
    e5 = next(i for i in range(h, len(lines)) if lines[i].startswith(" -1         5    6"))
    e3 = next(i for i in range(h, len(lines)) if lines[i].startswith(" -1         3    6"))
    head = rf"line {h + 1}"
    if how == "node record missing":
        del lines[e5 + 1]
        match = rf"line {e5 + 1}: element 5 of the element block starting on {head} has 0 node numbers .* " \
                rf"type 6 \(te10\) has 10 nodes; the file is truncated or malformed"
    elif how == "node record cut at a field":
        lines[e3 + 1] = lines[e3 + 1][:-10]
        match = rf"line {e3 + 1}: element 3 .* has 9 node numbers"
    elif how == "node record cut inside a field":
        lines[e3 + 1] = lines[e3 + 1][:-2]
        match = rf"line {e3 + 2}: the node record in the element block starting on {head} ends inside a field"
    elif how == "element record cut":
        lines[e5] = lines[e5][:20]
        match = rf"line {e5 + 1}: the element record in the element block .* is cut short \(20 columns, needs 28\)"
    elif how == "element missing":
        del lines[e5:e5 + 2]
        count = int(lines[h][24:36])
        match = rf"the element block starting on {head} announces {count} elements but holds {count - 1}"
    elif how == "not a number":
        lines[e3 + 1] = lines[e3 + 1][:15] + "x" + lines[e3 + 1][16:]
        match = rf"line {e3 + 2}, columns 14-23: '.*x.*' is not a node number \(the element block"
    elif how == "file ends":
        lines = lines[:e5 + 1]
        match = rf"ends inside the element block starting on {head} \(no ' -3' end record\): the file is truncated"
    else:  # a ' -2' record first
        del lines[h + 1]
        match = rf"line {h + 2}: a ' -2' node record before any ' -1' element record"
    return "\n".join(lines) + "\n", match


@pytest.mark.gmsh
@pytest.mark.calculix
@pytest.mark.parametrize("how", ["node record missing", "node record cut at a field", "node record cut inside a field",
                                 "element record cut", "element missing", "not a number", "file ends",
                                 "node record first"])
def test_frd_damaged_element_block_refused_naming_the_line(runs, tmp_path, how):
    _, frd = runs[2]
    text, match = _damage(frd.read_text(), how)
    path = tmp_path / "damaged.frd"
    path.write_text(text)
    with pytest.raises(FieldError, match=match) as info:
        read_field(path)
    assert "\n" not in str(info.value)
    with pytest.raises(FieldError, match=match):
        read_hot_to_cold(path)


# ---------------------------------------------------------------------------------------------------------
# Synthetic .frd files: element types ccx does not write for a solid
# ---------------------------------------------------------------------------------------------------------
PTS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]) * 10.0
TETS = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
TET_BOUNDARY = {(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 4), (1, 3, 4), (2, 3, 4)}
IDS = np.array([7, 3, 12, 40, 41])               # CalculiX node numbers of the rows of PTS


def frd_text(elements, ids=IDS, points=PTS, result_ids=IDS) -> str:
    """An .frd (long format, as ccx writes it) with ``elements`` [(type, node numbers), ...] and one DISP
    block for the nodes ``result_ids``."""
    lines = ["    1C", "    1UPGM               CalculiX".ljust(70),
             f"    2C{'':18s}{len(ids):12d}{'':37s}1"]
    lines += [f" -1{i:10d}" + "".join(f"{v:12.5E}" for v in p) for i, p in zip(ids, points)]
    lines += [" -3", f"    3C{'':18s}{len(elements):12d}{'':37s}1"]
    for k, (etype, nodes) in enumerate(elements):
        lines.append(f" -1{k + 1:10d}{etype:5d}{0:5d}{1:5d}")
        lines += [" -2" + "".join(f"{n:10d}" for n in nodes[j:j + 10]) for j in range(0, len(nodes), 10)]
    lines += [" -3", f"  100CL  101 1.000000000{len(result_ids):12d}{'':20s} 0    1{'':10s} 1",
              " -4  DISP        4    1"]
    lines += [f" -5  D{c}          1    2    {c}    0" for c in (1, 2, 3)]
    lines += [" -5  ALL         1    2    0    0    1ALL"]
    lines += [f" -1{i:10d}" + "".join(f"{v:12.5E}" for v in (1e-3 * i, 0.0, -2e-3)) for i in result_ids]
    return "\n".join(lines + [" -3", " 9999"]) + "\n"


def write(tmp_path, text, name="f.frd") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_frd_tetrahedra_on_node_numbers_and_other_types_skipped(tmp_path, caplog):
    hexa = (1, [7, 3, 12, 40, 41, 7, 3, 12])     # an 8-node brick (its nodes do not matter)
    beam = (11, [7, 3])
    text = frd_text([hexa, (3, IDS[TETS[0]].tolist()), beam, (3, IDS[TETS[1]].tolist())])
    with caplog.at_level(logging.INFO, logger="hot2cold.io.frd"):
        field = read_field(write(tmp_path, text))
    assert "element type(s) 1 (he8, 1 element), 11 (be2, 1 element) not used" in caplog.text
    np.testing.assert_array_equal(field.node_ids, IDS)
    assert field.triangles.shape == (6, 3)
    assert faces(field.triangles) == TET_BOUNDARY
    assert np.all(edge_uses(field.triangles) == 2)
    # Nothing but bricks: no triangles.
    assert read_field(write(tmp_path, frd_text([hexa]), "hexa.frd")).triangles is None


def test_frd_shell_triangles_taken_as_they_are(tmp_path):
    tr6 = [(8, [7, 3, 12, 40, 41, 7]), (8, [3, 12, 40, 7, 41, 3])]   # the numbers need not make sense
    field = read_field(write(tmp_path, frd_text(tr6)))
    np.testing.assert_array_equal(field.node_ids[field.triangles], [n for _, n in tr6])
    tr3 = [(7, [40, 7, 12])]
    np.testing.assert_array_equal(read_field(write(tmp_path, frd_text(tr3), "tr3.frd")).triangles, [[3, 0, 2]])
    # Beside tetrahedra, triangles are not used: the tetrahedra's boundary is.
    mixed = frd_text([(3, IDS[TETS[0]].tolist()), (7, [40, 7, 12]), (3, IDS[TETS[1]].tolist())])
    assert faces(read_field(write(tmp_path, mixed, "mixed.frd")).triangles) == TET_BOUNDARY


def test_frd_triangles_of_nodes_without_results_are_dropped(tmp_path, caplog):
    text = frd_text([(3, IDS[TETS[0]].tolist()), (3, IDS[TETS[1]].tolist())], result_ids=IDS[[4, 0, 1, 2]])
    with caplog.at_level(logging.INFO, logger="hot2cold.io.frd"):
        field = read_field(write(tmp_path, text))
    assert "4 of 6 boundary triangles name nodes without results; dropped" in caplog.text
    np.testing.assert_array_equal(field.node_ids, IDS[[4, 0, 1, 2]])
    # Rows of this field: (0, 1, 2) and (1, 2, 4) of PTS are rows (1, 2, 3) and (2, 3, 0) here.
    assert faces(field.triangles) == {(1, 2, 3), (0, 2, 3)}
    assert faces(field.node_ids[field.triangles]) == faces(IDS[[[0, 1, 2], [1, 2, 4]]])
    # No triangle left: None.
    text = frd_text([(3, IDS[TETS[0]].tolist())], result_ids=IDS[[4]])
    assert read_field(write(tmp_path, text, "one.frd")).triangles is None


# ---------------------------------------------------------------------------------------------------------
# .npz
# ---------------------------------------------------------------------------------------------------------
def test_npz_triangles(tmp_path):
    dsp = 1e-3 * PTS
    with_key, without = tmp_path / "with.npz", tmp_path / "without.npz"
    tri6 = np.array([[0, 1, 2, 3, 4, 0], [1, 2, 4, 3, 0, 1]], dtype=np.int32)
    np.savez(with_key, points=PTS, displacements=dsp, triangles=tri6)
    np.savez(without, points=PTS, displacements=dsp)
    field = read_field(with_key)
    np.testing.assert_array_equal(field.triangles, tri6)
    assert field.triangles.dtype == np.int64
    assert read_field(without).triangles is None
    np.savez(with_key, points=PTS, displacements=dsp, triangles=tri6[:, :3])
    np.testing.assert_array_equal(read_field(with_key).triangles, tri6[:, :3])
    for bad, match in [(tri6.astype(float), "triangles must be integer node rows"),
                       (tri6[:, :4], r"triangles must have shape \(T, 3\) or \(T, 6\), got shape \(2, 4\)"),
                       (tri6 + 3, r"triangles refer to node rows outside 0\.\.4 \(found 3\.\.7\)")]:
        np.savez(with_key, points=PTS, displacements=dsp, triangles=bad)
        with pytest.raises(FieldError, match=match) as info:
            read_field(with_key)
        assert "\n" not in str(info.value) and "with.npz" in str(info.value)


# ---------------------------------------------------------------------------------------------------------
# meshio
# ---------------------------------------------------------------------------------------------------------
def quadratic(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """10-node tetrahedra (VTK order) made of 4-node ones: a new node at the middle of every edge."""
    edges = [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)]
    mid: dict[tuple[int, int], int] = {}
    pts = list(points)
    tets10 = []
    for t in tets.tolist():
        row = list(t)
        for a, b in edges:
            key = tuple(sorted((t[a], t[b])))
            if key not in mid:
                mid[key] = len(pts)
                pts.append(0.5 * (points[t[a]] + points[t[b]]))
            row.append(mid[key])
        tets10.append(row)
    return np.array(pts), np.array(tets10)


@pytest.mark.parametrize("fmt", ["vtu", "msh"])
def test_meshio_tetra_and_tetra10(tmp_path, fmt):
    kw = {"file_format": "gmsh", "binary": True} if fmt == "msh" else {}
    path = tmp_path / f"tet4.{fmt}"
    meshio.write(path, meshio.Mesh(PTS, [("tetra", TETS)], point_data={"U": 1e-3 * PTS}), **kw)
    field = read_field(path)
    assert field.triangles.shape == (6, 3)
    assert faces(field.triangles) == TET_BOUNDARY      # the shared face (1, 2, 3) is not on the boundary
    assert np.all(edge_uses(field.triangles) == 2)

    pts10, tets10 = quadratic(PTS, TETS)
    path = tmp_path / f"tet10.{fmt}"
    meshio.write(path, meshio.Mesh(pts10, [("tetra10", tets10)], point_data={"U": 1e-3 * pts10}), **kw)
    field = read_field(path)
    np.testing.assert_allclose(field.points, pts10, rtol=1e-15)
    assert field.triangles.shape == (6, 6)
    assert faces(field.triangles) == TET_BOUNDARY
    assert_midside_at_midpoints(field.points, field.triangles)
    np.testing.assert_array_equal(field.triangles, boundary_triangles(tets10))


def test_meshio_triangles_other_cells_and_mixtures(tmp_path, caplog):
    u = {"U": 1e-3 * PTS}
    surface = np.array([[0, 1, 2], [1, 2, 4]])
    path = tmp_path / "surface.vtu"
    meshio.write(path, meshio.Mesh(PTS, [("triangle", surface)], point_data=u))
    np.testing.assert_array_equal(read_field(path).triangles, surface)
    # Tetrahedra beside triangles: the tetrahedra's boundary.
    meshio.write(path, meshio.Mesh(PTS, [("triangle", surface), ("tetra", TETS)], point_data=u))
    assert faces(read_field(path).triangles) == TET_BOUNDARY
    # Bricks and quads are not used, and said so.
    cube = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=float)[[0, 1, 3, 2, 4, 5, 7, 6]]
    path = tmp_path / "hexa.vtu"
    meshio.write(path, meshio.Mesh(cube, [("hexahedron", np.arange(8)[None]), ("quad", np.array([[0, 1, 2, 3]]))],
                                   point_data={"U": 1e-3 * cube}))
    with caplog.at_level(logging.INFO, logger="hot2cold.io.field"):
        field = read_field(path)
    assert field.triangles is None
    assert "cells of type hexahedron (1), quad (1) not used" in caplog.text


def test_meshio_duplicate_points_renumbered(tmp_path):
    """Two tetrahedra meshed apart (node 3 twice, same displacement): merged, the triangles follow."""
    pts = np.vstack([PTS, PTS[3]])
    tets = np.array([[0, 1, 2, 3], [1, 2, 5, 4]])
    path = tmp_path / "apart.vtu"
    meshio.write(path, meshio.Mesh(pts, [("tetra", tets)], point_data={"U": 1e-3 * pts}))
    field = read_field(path)
    assert len(field) == 5
    np.testing.assert_array_equal(field.points, PTS)
    # The triangles name the merged rows: the boundary of the two tetrahedra (and their face 1-2-3, on the
    # boundary of each before the merge).
    assert TET_BOUNDARY <= faces(field.triangles) <= TET_BOUNDARY | {(1, 2, 3)}
    np.testing.assert_array_equal(field.points[field.triangles], pts[boundary_triangles(tets)])


def test_element_triangles_mixtures_and_bad_input(caplog):
    pts10, tets10 = quadratic(PTS, TETS)
    with caplog.at_level(logging.INFO, logger="hot2cold.io.cells"):
        tri = element_triangles({"tetra": TETS[:1], "tetra10": tets10[1:]}, "m")
    assert "tetra and tetra10 elements mixed" in caplog.text
    assert tri.shape == (6, 3) and faces(tri) == TET_BOUNDARY
    assert element_triangles({"hexahedron": np.zeros((1, 8), int)}) is None
    assert element_triangles({"tetra": np.zeros((0, 4), int)}) is None
    with pytest.raises(FieldError, match=r"the tetra elements are not \(4-node\) integer node rows \(shape \(2, 5\)\)"):
        element_triangles({"tetra": np.zeros((2, 5), int)})
    with pytest.raises(FieldError, match=r"triangle elements .* \(dtype float64\)"):
        element_triangles({"triangle": np.zeros((2, 3))})
    # Triangles carried as DisplacementField.triangles as they are
    field = DisplacementField(PTS, 0 * PTS, triangles=element_triangles({"tetra": TETS}))
    assert faces(field.triangles) == TET_BOUNDARY
