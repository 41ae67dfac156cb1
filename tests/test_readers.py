"""Tests of the FE result readers: CalculiX ``.frd`` (hot2cold.io.frd) and meshio formats, via read_field.

The ``.frd`` files here are written record by record in the exact fixed-column layout CalculiX 2.20 writes
(``tests/test_fe.py`` reads files written by ccx itself); the mesh files are written by meshio.
"""
from __future__ import annotations

import logging

import meshio
import numpy as np
import pytest

from hot2cold.errors import FieldError
from hot2cold.io.frd import FrdFile, read_frd
from hot2cold.io.field import DisplacementField, as_field, read_field

IDS = np.array([1, 2, 3, 10, 11, 12345])
XYZ = np.array([[0.0, 0.0, 0.0], [40.0, -8.0, 0.5], [-123.456, 7.25, 1e-3],
                [251.1234, -25.0625, 43.04], [0.1, 0.2, -0.3], [1e4, -2e3, 3.5]])
U1 = np.array([[0.0, 0.0, -1.44e-2], [-7.2e-2, 1.44e-2, -9.0e-4], [-0.123456, -0.234567, -0.345678],
               [-1.5e-1, 3.25e-3, -4.75e-5], [1.0e-6, -2.0e-6, 3.0e-6], [-9.87654e-1, -1.0, -1.0e-10]])
U2 = -0.5 * U1 + 1e-3


# ---------------------------------------------------------------------------------------------------------
# Writing .frd files as CalculiX does
# ---------------------------------------------------------------------------------------------------------
def _e(v: float) -> str:
    return f"{v:12.5E}"


def node_block(ids, xyz, fmt=1) -> list[str]:
    w = 10 if fmt == 1 else 5
    lines = [f"    2C{'':18s}{len(ids):12d}{'':37s}{fmt:1d}"]
    lines += [f" -1{i:{w}d}" + "".join(map(_e, p)) for i, p in zip(ids, xyz)]
    return lines + [" -3"]


def element_block(fmt=1) -> list[str]:
    w = 10 if fmt == 1 else 5
    return [f"    3C{'':18s}{1:12d}{'':37s}{fmt:1d}",
            f" -1{1:{w}d}{6:5d}{0:5d}{1:5d}",
            " -2" + "".join(f"{n:{w}d}" for n in [1, 2, 3, 10, 11, 12345, 1, 2, 3, 10]),
            " -3"]


def result_block(name, comps, ids, values, step=1, fmt=1, exist_all=True) -> list[str]:
    w = 10 if fmt == 1 else 5
    lines = [f"    1PSTEP{'':25s}{step:1d}{'':11s}1{'':11s}{step:1d}",
             f"  100CL{100 + step:5d}{float(step):12.9f}{len(ids):12d}{'':20s}{0:2d}{step:5d}{'':10s}{fmt:2d}",
             f" -4  {name:8s}{len(comps) + (1 if exist_all else 0):5d}{1:5d}"]
    lines += [f" -5  {c:8s}{1:5d}{2:5d}{k + 1:5d}{0:5d}" for k, c in enumerate(comps)]
    if exist_all:
        lines.append(f" -5  {'ALL':8s}{1:5d}{2:5d}{0:5d}{0:5d}{1:5d}ALL")
    for i, row in zip(ids, values):
        lines.append(f" -1{i:{w}d}" + "".join(map(_e, row[:6])))
        for k in range(6, len(row), 6):
            lines.append(f" -2{'':{w}s}" + "".join(map(_e, row[k:k + 6])))
    return lines + [" -3"]


def frd_text(*results, fmt=1, nodes=True, end=True, heading="hot2cold test") -> str:
    lines = ["    1C", f"    1U{heading}".ljust(70), "    1UPGM               CalculiX".ljust(70)]
    if nodes:
        lines += node_block(IDS, XYZ, fmt) + element_block(fmt)
    for r in results:
        lines += r
    if end:
        lines.append(" 9999")
    return "\n".join(lines) + "\n"


def disp(values=U1, step=1, fmt=1, ids=IDS):
    return result_block("DISP", ["D1", "D2", "D3"], ids, values, step, fmt)


def write(tmp_path, text, name="job.frd"):
    path = tmp_path / name
    path.write_text(text)
    return path


def rounded(a):
    return np.array([[float(_e(v)) for v in row] for row in a])


# ---------------------------------------------------------------------------------------------------------
# .frd
# ---------------------------------------------------------------------------------------------------------
def test_frd_touching_values_long_format(tmp_path):
    text = frd_text(disp())
    assert "-1.23456E-01-2.34567E-01-3.45678E-01" in text  # the values touch: no blank between them
    f = read_field(write(tmp_path, text))
    assert isinstance(f, DisplacementField)
    np.testing.assert_array_equal(f.node_ids, IDS)
    np.testing.assert_array_equal(f.points, rounded(XYZ))
    np.testing.assert_array_equal(f.displacements, rounded(U1))
    assert f.source.endswith("job.frd")


def test_frd_short_format(tmp_path):
    f = read_field(write(tmp_path, frd_text(disp(fmt=0), fmt=0)))
    np.testing.assert_array_equal(f.node_ids, IDS)
    np.testing.assert_array_equal(f.displacements, rounded(U1))
    np.testing.assert_array_equal(f.points, rounded(XYZ))


def test_frd_node_ids_beyond_short_width_touch_values(tmp_path):
    ids = np.array([1, 99999])
    text = "\n".join(["    1C"] + node_block(ids, XYZ[:2], 0) + disp(U1[:2], ids=ids, fmt=0) + [" 9999"])
    assert " -199999-7.20000E-02" in text
    f = read_field(write(tmp_path, text))
    np.testing.assert_array_equal(f.node_ids, ids)
    np.testing.assert_array_equal(f.displacements, rounded(U1[:2]))


def test_frd_results_for_a_subset_in_another_order(tmp_path, caplog):
    order = [5, 0, 3]
    with caplog.at_level(logging.INFO, logger="hot2cold.io.frd"):
        f = read_field(write(tmp_path, frd_text(disp(U1[order], ids=IDS[order]))))
    assert "3 of the file's 6 nodes have no value in the DISP block on line" in caplog.text
    np.testing.assert_array_equal(f.node_ids, IDS[order])
    np.testing.assert_array_equal(f.points, rounded(XYZ[order]))
    np.testing.assert_array_equal(f.displacements, rounded(U1[order]))


def test_frd_last_block_by_default_and_step_choice(tmp_path):
    stress = result_block("STRESS", ["SXX", "SYY", "SZZ", "SXY", "SYZ", "SZX", "XTRA"], IDS,
                          np.arange(len(IDS) * 7.0).reshape(-1, 7) - 20.0, 1, exist_all=False)
    path = write(tmp_path, frd_text(disp(U1, 1), stress, disp(U2, 2)))
    np.testing.assert_array_equal(read_field(path).displacements, rounded(U2))
    np.testing.assert_array_equal(read_field(path, step=0).displacements, rounded(U1))
    np.testing.assert_array_equal(read_field(path, step=-2).displacements, rounded(U1))
    np.testing.assert_array_equal(read_field(path, step=1).displacements, rounded(U2))
    with pytest.raises(FieldError, match=r"has 2 DISP block\(s\); step must lie in -2\.\.1"):
        read_field(path, step=2)
    r = read_frd(path, step=0)
    assert (r.name, r.components, r.step, r.index, r.count) == ("DISP", ("D1", "D2", "D3"), 1, 0, 2)
    assert r.value == 1.0
    # the set taken is named as CGX lists it: its place among the DISP blocks, the header's step and time
    assert read_field(path).result_set == "DISP block 2 of 2: step 2, time 2"
    assert read_field(path, step=0).result_set == "DISP block 1 of 2: step 1, time 1"
    # and is taken by that step number as the user reads it there
    np.testing.assert_array_equal(read_field(path, field_name="step 1").displacements, rounded(U1))
    np.testing.assert_array_equal(read_field(path, field_name="disp  Step 2").displacements, rounded(U2))
    with pytest.raises(FieldError, match=r"has no DISP block of step 3; its DISP blocks are of steps 1-2"):
        read_field(path, field_name="step 3")
    with pytest.raises(FieldError, match="by its step number .* or by its index .*, not both"):
        read_field(path, field_name="step 1", step=0)
    frd = FrdFile.read(path)
    assert frd.datasets() == ["DISP", "STRESS", "DISP"]
    assert frd.count("disp") == 2
    # A dataset that is not a 3-vector is not a displacement.
    with pytest.raises(FieldError, match="STRESS .* stores 7 component"):
        read_field(path, field_name="stress")


def test_frd_of_a_hot2cold_deck_is_the_difference_of_its_steps(tmp_path):
    """A hot2cold deck of a rotating part: step 1 spins, step 2 cools at rest; hot -> cold = U2 - U1."""
    text = frd_text(disp(U1, 1), disp(U2, 2), heading="hot2cold hot-to-cold: U = U(last step) - U(first step)")
    path = write(tmp_path, text)
    frd = FrdFile.read(path)
    assert frd.is_hot_to_cold() and frd.heading.startswith("hot2cold hot-to-cold")
    np.testing.assert_array_equal(read_field(path).displacements, rounded(U2) - rounded(U1))
    np.testing.assert_array_equal(frd.hot_to_cold().values, rounded(U2) - rounded(U1))
    assert read_field(path).result_set == "DISP block 2 of 2: step 2, time 2, minus block 1 (step 1, time 1)"
    np.testing.assert_array_equal(read_field(path, step=-1).displacements, rounded(U2))  # raw blocks on request
    one = write(tmp_path, frd_text(disp(U2, 1), heading="hot2cold hot-to-cold"), "one.frd")
    np.testing.assert_array_equal(read_field(one).displacements, rounded(U2))
    three = write(tmp_path, frd_text(disp(U1, 1), disp(U2, 2), disp(U1, 3), heading="hot2cold hot-to-cold"),
                  "three.frd")
    with pytest.raises(FieldError, match="has 3 DISP blocks; a hot-to-cold deck written by hot2cold gives 1 or 2"):
        read_field(three)


def test_frd_displacements_beside_rotations_are_the_first_three(tmp_path, caplog):
    """Shells and beams with rotational freedoms store D1-D6 (CalculiX's own test ``lin_stat_cooks_beam_128``), an
    electromagnetic run D1-D5: the displacements are D1-D3, the rest is said and not used."""
    rotations = np.column_stack([U1, U2])
    six = result_block("DISP", ["D1", "D2", "D3", "D4", "D5", "D6"], IDS, rotations)
    path = write(tmp_path, frd_text(six))
    with caplog.at_level(logging.INFO, logger="hot2cold.io.frd"):
        f = read_field(path)
    np.testing.assert_array_equal(f.displacements, rounded(U1))
    assert "holds D4, D5, D6 besides the displacements D1-D3: not used" in caplog.text
    # a block of six that does not begin with D1-D3 is not a displacement
    other = result_block("DISP", ["R1", "R2", "R3", "R4", "R5", "R6"], IDS, rotations)
    with pytest.raises(FieldError, match=r"stores 6 component\(s\) \(R1, R2"):
        read_field(write(tmp_path, frd_text(other), "other.frd"))


def test_frd_element_block_with_more_elements_than_its_header_counts(tmp_path):
    """CalculiX counts a deck's beams and shells in the element header and writes the solid elements it expanded
    them into as well (its tests ``concretebeam``, ``shell3``): more elements than counted are read; fewer are
    refused (``test_field_elements``)."""
    block = element_block()
    second = [block[1].replace(f"{1:10d}", f"{2:10d}", 1), block[2]]
    text = frd_text(disp()).replace("\n".join(block), "\n".join(block[:3] + second + block[3:]))
    assert text.count("    3C") == 1 and f"{1:12d}" in text.splitlines()[text.splitlines().index(block[0])]
    frd = FrdFile.read(write(tmp_path, text))
    assert frd.element_kinds() == {"te10": 2}
    np.testing.assert_array_equal(read_field(write(tmp_path, text, "again.frd")).displacements, rounded(U1))


def test_frd_field_name_picks_another_vector_dataset(tmp_path):
    forc = result_block("FORC", ["F1", "F2", "F3"], IDS, U2 * 1000, 1)
    path = write(tmp_path, frd_text(forc, disp(U1, 1)))
    np.testing.assert_array_equal(read_field(path, field_name="FORC").displacements, rounded(U2 * 1000))
    np.testing.assert_array_equal(read_field(path).displacements, rounded(U1))


def test_frd_units_m(tmp_path):
    f = read_field(write(tmp_path, frd_text(disp())), units="m")
    np.testing.assert_allclose(f.displacements, rounded(U1) * 1000, rtol=1e-15)
    np.testing.assert_allclose(f.points, rounded(XYZ) * 1000, rtol=1e-15)


def test_frd_recognised_by_content(tmp_path):
    f = read_field(write(tmp_path, frd_text(disp()), name="results.out"))
    np.testing.assert_array_equal(f.displacements, rounded(U1))


def test_frd_logs(tmp_path, caplog):
    path = write(tmp_path, frd_text(disp()))
    with caplog.at_level(logging.INFO, logger="hot2cold.io.field"):
        read_field(path)
    assert f"read 6 nodes from {path} (frd, units mm)" in caplog.text


class _Mesh:
    """Stands for a TetMesh: full-precision nodes and their CalculiX numbers."""

    def __init__(self, nodes, node_tags):
        self.nodes = nodes
        self.node_tags = node_tags


def test_frd_points_from_mesh_field_and_file(tmp_path):
    path = write(tmp_path, frd_text(disp()))
    perm = np.array([3, 1, 5, 0, 2, 4])
    mesh = _Mesh(XYZ[perm], IDS[perm])
    f = read_field(path, points_from=mesh)
    np.testing.assert_array_equal(f.points, XYZ)  # full precision, matched by node number
    np.testing.assert_array_equal(f.displacements, rounded(U1))
    g = read_field(path, points_from=DisplacementField(XYZ, np.zeros_like(XYZ), IDS))
    np.testing.assert_array_equal(g.points, XYZ)
    npz = tmp_path / "mesh.npz"
    np.savez(npz, points=XYZ[perm], displacements=np.zeros_like(XYZ), node_ids=IDS[perm])
    np.testing.assert_array_equal(read_field(path, points_from=npz).points, XYZ)
    # In metres both: the positions are scaled with the rest.
    np.testing.assert_allclose(read_field(path, units="m", points_from=mesh).points, XYZ * 1000, rtol=1e-15)


def test_frd_points_from_errors(tmp_path):
    path = write(tmp_path, frd_text(disp()))
    with pytest.raises(FieldError, match=r"1 node\(s\) of .* \(first: node 12345\) are not in points_from"):
        read_field(path, points_from=_Mesh(XYZ[:5], IDS[:5]))
    moved = XYZ.copy()
    moved[2, 1] += 0.01
    with pytest.raises(FieldError, match=r"does not match .*node 3 is at .* in the results \(1 node\(s\) differ\)"):
        read_field(path, points_from=_Mesh(moved, IDS))
    with pytest.raises(FieldError, match="has no node ids"):
        read_field(path, points_from=DisplacementField(XYZ, XYZ))
    with pytest.raises(FieldError, match="points_from must be a TetMesh"):
        read_field(path, points_from=42)


@pytest.mark.parametrize("cut, match", [
    (lambda t: t[: t.index("-3.45678E-01") + 5], r"ends inside the result block DISP .*truncated"),
    (lambda t: t[: t.rindex("-1.00000E-10") + 5] + "\n -3\n 9999\n",
     r"line 28: the record of node 12345 in the DISP block is cut short \(42 columns, needs 49\)"),
    (lambda t: t[: t.rindex(" -1        10")], r"ends inside the result block DISP .*truncated"),
    (lambda t: t[: t.rindex(" 9999")], "no ' 9999' end record .*truncated"),
    (lambda t: t[: t.index(" -1         3")], "ends inside the node block .*truncated"),
    (lambda t: t[: t.index(" -5  D2")], r"dataset DISP .* announces 4 components but has 1 ' -5' record"),
])
def test_frd_truncated(tmp_path, cut, match):
    text = cut(frd_text(disp()))
    with pytest.raises(FieldError, match=match) as info:
        read_field(write(tmp_path, text))
    assert "\n" not in str(info.value)


def test_frd_without_disp_block(tmp_path):
    stress = result_block("STRESS", ["SXX", "SYY", "SZZ", "SXY", "SYZ", "SZX"], IDS, np.ones((6, 6)), 1,
                          exist_all=False)
    with pytest.raises(FieldError, match=r"has no DISP result block \(found: STRESS\).*\*NODE FILE"):
        read_field(write(tmp_path, frd_text(stress)))
    with pytest.raises(FieldError, match=r"no DISP result block \(found: no result block\)"):
        read_field(write(tmp_path, frd_text()))


def test_frd_malformed(tmp_path):
    text = frd_text(disp())
    bad = text.replace("-2.34567E-01", "-2.3456xE-01")
    with pytest.raises(FieldError, match=r"line \d+, columns 26-37: '-2.3456xE-01' is not a number \(node 3"):
        read_field(write(tmp_path, bad))
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith(" -1         2") and "-7.2" in ln)
    lines.insert(k, " -7 garbage")
    with pytest.raises(FieldError, match=rf"line {k + 1}: result block DISP .* unexpected record ' -7 garbage'"):
        read_field(write(tmp_path, "\n".join(lines)))
    with pytest.raises(FieldError, match="node block .* announces 6 nodes but holds 5"):
        text2 = frd_text(disp()).replace(node_block(IDS, XYZ)[2] + "\n", "", 1)
        read_field(write(tmp_path, text2))
    with pytest.raises(FieldError, match=r"node\(s\) of the DISP block \(first: node 99\) have no coordinates"):
        read_field(write(tmp_path, frd_text(disp(U1[:1], ids=np.array([99])))))
    with pytest.raises(FieldError, match="is empty"):
        read_field(write(tmp_path, ""))


def test_frd_binary_refused(tmp_path):
    text = frd_text(disp()).replace(node_block(IDS, XYZ)[0], node_block(IDS, XYZ)[0][:-1] + "3")
    with pytest.raises(FieldError, match=r"binary \.frd \(format indicator 3"):
        read_field(write(tmp_path, text))


def test_frd_only_options(tmp_path):
    path = tmp_path / "f.csv"
    path.write_text("x,y,z,dx,dy,dz\n0,0,0,1,1,1\n")
    with pytest.raises(FieldError, match=r"step applies to solver results \(\.frd, \.rst, \.op2, \.pch\) only; "
                                         r".*f\.csv is read as text"):
        read_field(path, step=0)
    with pytest.raises(FieldError, match=r"points_from applies to \.frd, \.op2 and \.pch files only"):
        read_field(path, points_from=path)
    with pytest.raises(FieldError, match=r"field_name applies to \.frd, \.npz, solver result and mesh files"):
        read_field(path, field_name="U")


# ---------------------------------------------------------------------------------------------------------
# meshio formats
# ---------------------------------------------------------------------------------------------------------
PTS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]) * 10.0
DSP = np.array([[0.0, 0.0, 0.0], [-1e-3, 2e-3, 0.0], [0.1, -0.2, 0.3], [1e-5, 0.0, -4e-4], [0.5, 0.25, -0.125]])
CELLS = [("tetra", np.array([[0, 1, 2, 3], [1, 2, 3, 4]]))]


def mesh_file(tmp_path, name, point_data, cell_data=None, **kw):
    path = tmp_path / name
    meshio.write(path, meshio.Mesh(PTS, CELLS, point_data=point_data, cell_data=cell_data or {}), **kw)
    return path


@pytest.mark.parametrize("name", ["U", "displacement", "Displacements", "DISP"])
def test_vtu_default_names(tmp_path, name):
    path = mesh_file(tmp_path, "f.vtu", {"temperature": np.arange(5.0), name: DSP})
    f = read_field(path)
    np.testing.assert_array_equal(f.points, PTS)
    np.testing.assert_array_equal(f.displacements, DSP)
    assert f.node_ids is None and f.source == str(path)


def test_vtu_preference_order(tmp_path):
    path = mesh_file(tmp_path, "f.vtu", {"displacement": -DSP, "u": DSP})
    np.testing.assert_array_equal(read_field(path).displacements, DSP)


def test_vtu_field_name_and_as_field(tmp_path):
    path = mesh_file(tmp_path, "f.vtu", {"hot_to_cold": DSP, "U": -DSP})
    np.testing.assert_array_equal(read_field(path, field_name="hot_to_cold").displacements, DSP)
    np.testing.assert_array_equal(read_field(path, field_name="HOT_TO_COLD").displacements, DSP)
    np.testing.assert_array_equal(as_field(path, field_name="hot_to_cold").displacements, DSP)
    np.testing.assert_array_equal(as_field(str(path)).displacements, -DSP)
    np.testing.assert_allclose(read_field(path, units="m", field_name="hot_to_cold").displacements, DSP * 1000)


def test_vtu_missing_field_lists_point_fields(tmp_path):
    path = mesh_file(tmp_path, "f.vtu", {"temperature": np.arange(5.0), "velocity": DSP})
    with pytest.raises(FieldError, match=r"no displacement point field .* \(point fields: 'temperature' \(5,\), "
                                         r"'velocity' \(5, 3\)\); name the field with morph\(field_name=\.\.\.\)"):
        read_field(path)
    with pytest.raises(FieldError, match=r"no point field 'U2' \(point fields: 'temperature'"):
        read_field(path, field_name="U2")


def test_vtu_cell_data_is_not_point_data(tmp_path):
    path = mesh_file(tmp_path, "f.vtu", {"T": np.arange(5.0)}, cell_data={"U": [np.ones((2, 3))]})
    with pytest.raises(FieldError, match="'U' is cell data, hot2cold needs point"):
        read_field(path, field_name="U")


def test_vtu_wrong_shape(tmp_path):
    path = mesh_file(tmp_path, "f.vtu", {"U": np.arange(5.0)})
    with pytest.raises(FieldError, match=r"point field 'U' has shape \(5,\), .* shape \(5, 3\)"):
        read_field(path)
    path = mesh_file(tmp_path, "g.vtu", {"U": np.ones((5, 6))})
    with pytest.raises(FieldError, match=r"point field 'U' has shape \(5, 6\)"):
        read_field(path)


def test_vtu_nan_rejected(tmp_path):
    bad = DSP.copy()
    bad[2, 1] = np.nan
    with pytest.raises(FieldError, match="NaN or inf"):
        read_field(mesh_file(tmp_path, "f.vtu", {"U": bad}))


@pytest.mark.parametrize("binary", [False, True])
def test_vtk_legacy(tmp_path, binary):
    path = mesh_file(tmp_path, "f.vtk", {"U": DSP}, binary=binary)
    head = path.read_bytes()[:30]
    assert head.startswith(b"# vtk DataFile")
    f = read_field(path)
    np.testing.assert_allclose(f.displacements, DSP, rtol=1e-15)
    np.testing.assert_allclose(f.points, PTS, rtol=1e-15)
    # Recognised by content under another name (the text reader would take '#' for a comment).
    other = tmp_path / "field.result"
    other.write_bytes(path.read_bytes())
    np.testing.assert_allclose(read_field(other).displacements, DSP, rtol=1e-15)


def test_gmsh_msh(tmp_path):
    # (meshio 5.3 cannot read back its own ASCII .msh files: binary here)
    msh = mesh_file(tmp_path, "f.msh", {"displacement": DSP}, file_format="gmsh", binary=True)
    f = read_field(msh)
    np.testing.assert_allclose(f.displacements, DSP, rtol=1e-15)
    np.testing.assert_allclose(f.points, PTS, rtol=1e-15)


def test_broken_mesh_file(tmp_path):
    path = tmp_path / "f.vtu"
    path.write_text("<?xml version='1.0'?>\n<VTKFile type='UnstructuredGrid'><Broken")
    with pytest.raises(FieldError, match=r"cannot read mesh file .*f\.vtu with meshio") as info:
        read_field(path)
    assert "\n" not in str(info.value)


def test_npz_field_name(tmp_path):
    path = tmp_path / "f.npz"
    np.savez(path, points=PTS, U=DSP)
    np.testing.assert_array_equal(read_field(path, field_name="U").displacements, DSP)
    with pytest.raises(FieldError, match="lacks array.* displacements"):
        read_field(path)


# ---------------------------------------------------------------------------------------------------------
# Duplicate nodes, complex numbers
# ---------------------------------------------------------------------------------------------------------
def test_frd_coincident_nodes_of_unmerged_meshes(tmp_path):
    """Two node numbers at one position (two meshes never merged): the same displacement is one node, another
    is refused with both node numbers."""
    xyz = XYZ.copy()
    xyz[4] = xyz[1]                                        # node 11 sits where node 2 is
    same = U1.copy()
    same[4] = same[1]
    text = "\n".join(["    1C"] + node_block(IDS, xyz) + disp(same) + [" 9999"])
    f = read_field(write(tmp_path, text))
    assert len(f) == 5 and 11 not in f.node_ids
    other = same.copy()
    other[4, 0] += 0.01
    text = "\n".join(["    1C"] + node_block(IDS, xyz) + disp(other) + [" 9999"])
    with pytest.raises(FieldError, match=r"has 1 position with duplicate nodes of different displacements, e\.g\. "
                                         r"\(40, -8, 0\.5\) mm: rows 1 and 4 \(from 0, node ids 2 and 11\)"):
        read_field(write(tmp_path, text, "other.frd"))


def test_npz_complex_numbers_refused(tmp_path):
    path = tmp_path / "c.npz"
    np.savez(path, points=PTS.astype(complex), displacements=DSP)
    with pytest.raises(FieldError, match=r"points is not an array of numbers \(complex numbers\)"):
        read_field(path)
