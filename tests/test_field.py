"""Tests of hot2cold.io.field: reading and validating the FE displacement field."""
from __future__ import annotations

import logging
import pathlib

import numpy as np
import pytest

from hot2cold.errors import FieldError, InputError
from hot2cold.io.field import UNITS, DisplacementField, as_field, read_field

P = np.array([[0.0, 1.0, 2.0], [10.5, -3.25, 7.0], [1e3, 2e-3, -4.5]])
D = np.array([[0.1, -0.2, 0.3], [1.5e-3, 0.0, -2.0], [-0.05, 0.25, 1e-4]])


def write(tmp_path, text, name="field.csv", encoding="utf-8"):
    path = tmp_path / name
    path.write_bytes(text.encode(encoding))
    return path


def rows(fmt, p=P, d=D, ids=None, sep=","):
    """Lines for the test arrays; fmt names the order with keys x y z dx dy dz id."""
    cols = {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2], "dx": d[:, 0], "dy": d[:, 1], "dz": d[:, 2]}
    if ids is not None:
        cols["id"] = ids
    return [sep.join(repr(float(cols[k][i])) if k != "id" else str(int(cols[k][i])) for k in fmt)
            for i in range(len(p))]


def assert_field(f, p=P, d=D):
    assert isinstance(f, DisplacementField)
    assert len(f) == len(p)
    np.testing.assert_array_equal(f.points, p)
    np.testing.assert_array_equal(f.displacements, d)
    assert f.points.dtype == np.float64 and f.points.flags.c_contiguous
    assert f.displacements.dtype == np.float64 and f.displacements.flags.c_contiguous


# ---------------------------------------------------------------------------------------------------------
# Formats
# ---------------------------------------------------------------------------------------------------------
def test_comma_file(tmp_path):
    path = write(tmp_path, "\n".join(["x,y,z,dx,dy,dz"] + rows("x y z dx dy dz".split())) + "\n")
    f = read_field(path)
    assert_field(f)
    assert f.node_ids is None
    assert f.source == str(path)


def test_whitespace_file_with_tabs_and_spaces(tmp_path):
    lines = rows("x y z dx dy dz".split(), sep="   ")
    lines[1] = lines[1].replace("   ", "\t")
    path = write(tmp_path, "x y\tz  dx dy dz\n" + "\n".join("  " + ln + "  " for ln in lines), "field.txt")
    assert_field(read_field(path))


def test_columns_any_order_with_id_and_extra_column(tmp_path):
    order = ["dz", "id", "x", "dy", "z", "temp", "y", "dx"]
    ids = np.array([101, 7, 123456789])
    cols = {"temp": np.array([20.0, 21.0, 22.0])}
    lines = []
    for i, ln in enumerate(rows([k for k in order if k != "temp"], ids=ids)):
        fields = ln.split(",")
        fields.insert(order.index("temp"), f"{cols['temp'][i]}")
        lines.append(",".join(fields))
    path = write(tmp_path, ",".join(order) + "\n" + "\n".join(lines) + "\n")
    f = read_field(path)
    assert_field(f)
    np.testing.assert_array_equal(f.node_ids, ids)
    assert f.node_ids.dtype == np.int64


def test_text_in_ignored_column_is_fine(tmp_path):
    lines = [f"{ln},{name}" for ln, name in zip(rows("x y z dx dy dz".split()), ["hub", "tip", "rim"])]
    path = write(tmp_path, "x,y,z,dx,dy,dz,region\n" + "\n".join(lines))
    assert_field(read_field(path))


@pytest.mark.parametrize("id_name", ["id", "NODE", "node_id", "NID", "Node Number"])
def test_id_column_names(tmp_path, id_name):
    ids = np.array([3, 1, 2])
    lines = rows("id x y z dx dy dz".split(), ids=ids)
    path = write(tmp_path, f"{id_name},x,y,z,dx,dy,dz\n" + "\n".join(lines))
    f = read_field(path)
    assert_field(f)
    np.testing.assert_array_equal(f.node_ids, ids)


def test_text_node_ids_are_dropped_not_fatal(tmp_path, caplog):
    lines = [f"N{i}," + ln for i, ln in enumerate(rows("x y z dx dy dz".split()))]
    path = write(tmp_path, "id,x,y,z,dx,dy,dz\n" + "\n".join(lines))
    with caplog.at_level(logging.WARNING, logger="hot2cold.io.field"):
        f = read_field(path)
    assert_field(f)
    assert f.node_ids is None
    assert "node ids ignored" in caplog.text


def test_header_case_quotes_spaces_bom_comments_blank_lines_crlf(tmp_path):
    lines = rows("x y z dx dy dz".split(), sep=" , ")
    text = ("# exported by some FE code\n\n"
            ' "X" , "Y", "Z" ,DX, dY ,Dz  \r\n'
            f"{lines[0]}\r\n"
            "\r\n"
            "# a comment in the middle\r\n"
            f"{lines[1]}   # and one at the end of a line\r\n"
            f"   {lines[2]}\r\n\r\n")
    path = write(tmp_path, text, encoding="utf-8-sig")
    assert path.read_bytes().startswith(b"\xef\xbb\xbf")
    assert_field(read_field(path))


def test_semicolon_with_decimal_comma(tmp_path):
    text = "x;y;z;dx;dy;dz\n1,5;2;-3,25;0,001;0;-0,5\n0;0;0;0;0;0\n"
    f = read_field(write(tmp_path, text))
    np.testing.assert_array_equal(f.points, [[1.5, 2.0, -3.25], [0, 0, 0]])
    np.testing.assert_array_equal(f.displacements, [[0.001, 0.0, -0.5], [0, 0, 0]])


def test_utf16_file(tmp_path):
    text = "x\ty\tz\tdx\tdy\tdz\r\n" + "\r\n".join(rows("x y z dx dy dz".split(), sep="\t"))
    path = write(tmp_path, text, encoding="utf-16")
    assert_field(read_field(path))


def test_savetxt_comment_header(tmp_path):
    path = tmp_path / "field.csv"
    np.savetxt(path, np.hstack([P, D]), delimiter=",", header="x,y,z,dx,dy,dz", fmt="%.17g")
    assert path.read_text().startswith("# x,y,z")
    assert_field(read_field(path))


def test_single_node(tmp_path):
    f = read_field(write(tmp_path, "x,y,z,dx,dy,dz\n1,2,3,4,5,6"))
    np.testing.assert_array_equal(f.points, [[1, 2, 3]])
    np.testing.assert_array_equal(f.displacements, [[4, 5, 6]])


def test_units_m_scales_to_mm(tmp_path):
    lines = rows("x y z dx dy dz".split(), p=P / 1000, d=D / 1000)
    path = write(tmp_path, "x,y,z,dx,dy,dz\n" + "\n".join(lines))
    f = read_field(path, units="m")
    np.testing.assert_allclose(f.points, P, rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(f.displacements, D, rtol=1e-15, atol=1e-15)
    f_mm = read_field(path, units=" MM ")
    np.testing.assert_array_equal(f_mm.points, P / 1000)
    assert UNITS == {"mm": 1.0, "m": 1000.0}


def test_npz(tmp_path):
    path = tmp_path / "field.npz"
    np.savez(path, points=P, displacements=D)
    f = read_field(path)
    assert_field(f)
    assert f.node_ids is None
    f_m = read_field(path, units="m")
    np.testing.assert_allclose(f_m.points, P * 1000)
    np.testing.assert_allclose(f_m.displacements, D * 1000)


def test_npz_with_ids_and_other_name(tmp_path):
    path = tmp_path / "field.dat"  # recognised by content, not by name
    with open(path, "wb") as fh:
        np.savez(fh, points=P.astype(np.float32), displacements=D.tolist(), node_ids=[5, 6, 7])
    f = read_field(path)
    np.testing.assert_array_equal(f.points, P.astype(np.float32).astype(np.float64))
    np.testing.assert_array_equal(f.displacements, D)
    np.testing.assert_array_equal(f.node_ids, [5, 6, 7])


def test_pathlike_and_str(tmp_path):
    path = write(tmp_path, "x,y,z,dx,dy,dz\n" + "\n".join(rows("x y z dx dy dz".split())))
    assert_field(read_field(str(path)))
    assert_field(read_field(pathlib.Path(path)))


def test_logs_node_count(tmp_path, caplog):
    path = write(tmp_path, "x,y,z,dx,dy,dz\n" + "\n".join(rows("x y z dx dy dz".split())))
    with caplog.at_level(logging.INFO, logger="hot2cold.io.field"):
        read_field(path)
    assert f"read 3 nodes from {path}" in caplog.text


def test_large_file_reads_correctly(tmp_path):
    n = 100_000
    rng = np.random.default_rng(42)
    p = rng.uniform(-300, 300, size=(n, 3))
    d = rng.normal(scale=1.0, size=(n, 3))
    ids = np.arange(1, n + 1) * 3
    path = tmp_path / "big.csv"
    with open(path, "w") as fh:
        fh.write("NodeID, X, Y, Z, DX, DY, DZ\n")
        np.savetxt(fh, np.column_stack([ids, p, d]), delimiter=", ", fmt=["%d"] + ["%.17g"] * 6)
    f = read_field(path)
    assert len(f) == n
    np.testing.assert_array_equal(f.points, p)
    np.testing.assert_array_equal(f.displacements, d)
    np.testing.assert_array_equal(f.node_ids, ids)
    # The same in metres, whitespace separated, with an ignored text column.
    path = tmp_path / "big.txt"
    with open(path, "w") as fh:
        fh.write("x y z dx dy dz name\n")
        for i in range(0, n, 10_000):
            np.savetxt(fh, np.column_stack([p[i:i + 10_000] / 1000, d[i:i + 10_000] / 1000]), fmt="%.17g",
                       newline=" node\n")
    f = read_field(path, units="m")
    np.testing.assert_allclose(f.points, p, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(f.displacements, d, rtol=1e-14, atol=1e-15)


def test_large_file_bad_line_is_located(tmp_path):
    n = 100_000
    lines = ["x,y,z,dx,dy,dz"] + [f"{i},{-i},{i * 0.5},0.001,0.002,0.003" for i in range(n)]
    lines[87_654] = lines[87_654].replace("0.002", "0.0o2")
    lines[99_000] = lines[99_000].replace("0.003", "")
    with pytest.raises(FieldError, match=r"line 87655, column 'dy' has '0.0o2', which is not a number"):
        read_field(write(tmp_path, "\n".join(lines)))


def test_quoted_numbers(tmp_path):
    f = read_field(write(tmp_path, 'x,y,z,dx,dy,dz\n"1","2","3","0.1","0.2","0.3"\n'))
    np.testing.assert_array_equal(f.points, [[1, 2, 3]])
    np.testing.assert_array_equal(f.displacements, [[0.1, 0.2, 0.3]])


# ---------------------------------------------------------------------------------------------------------
# DisplacementField, as_field
# ---------------------------------------------------------------------------------------------------------
def test_field_copies_and_is_read_only():
    p = P.copy()
    f = DisplacementField(p, D.T.copy().T, node_ids=[1, 2, 3], source="test")  # D as a non-contiguous view
    p[0, 0] = 99.0
    assert f.points[0, 0] == 0.0
    assert f.displacements.flags.c_contiguous
    np.testing.assert_array_equal(f.displacements, D)
    with pytest.raises(ValueError):
        f.points[0, 0] = 1.0
    with pytest.raises(AttributeError):
        f.points = P  # frozen
    assert len(f) == 3
    assert "3 nodes" in repr(f) and "'test'" in repr(f)


def test_scaled():
    f = DisplacementField(P, D, node_ids=[1, 2, 3], source="s")
    g = f.scaled(1000)
    np.testing.assert_array_equal(g.points, P * 1000)
    np.testing.assert_array_equal(g.displacements, D * 1000)
    np.testing.assert_array_equal(g.node_ids, [1, 2, 3])
    assert g.source == "s"
    np.testing.assert_array_equal(f.points, P)  # unchanged
    with pytest.raises(FieldError, match="positive finite"):
        f.scaled(0)
    with pytest.raises(FieldError, match="must be a number"):
        f.scaled("big")


@pytest.mark.parametrize("p, d, match", [
    (np.zeros((4, 2)), np.zeros((4, 3)), r"points must have shape \(N, 3\), got shape \(4, 2\)"),
    (np.zeros((4, 3)), np.zeros(12), r"displacements must have shape \(N, 3\), got shape \(12,\)"),
    (np.zeros((4, 3)), np.zeros((5, 3)), r"points has shape \(4, 3\) but displacements has shape \(5, 3\)"),
    (np.zeros((0, 3)), np.zeros((0, 3)), r"has no nodes"),
    ([[0, 0, np.nan], [0, 0, 0], [np.inf, 0, 0]], np.zeros((3, 3)),
     r"points has 2 NaN or inf value\(s\) in 2 row\(s\), first in row 0"),
    (np.zeros((2, 3)), [[0, 0, 0], [0, -np.inf, 0]],
     r"displacements has 1 NaN or inf value\(s\).*first in row 1"),
    ([["a", "b", "c"]], [[0, 0, 0]], r"points is not an array of numbers"),
])
def test_field_validation(p, d, match):
    with pytest.raises(FieldError, match=match):
        DisplacementField(p, d)


def test_field_node_ids_validation():
    with pytest.raises(FieldError, match=r"node_ids must have shape \(3,\)"):
        DisplacementField(P, D, node_ids=[1, 2])
    with pytest.raises(FieldError, match="node_ids must be integers"):
        DisplacementField(P, D, node_ids=[1, 2.5, 3])


def test_as_field_tuple_list_field_and_path(tmp_path):
    f = as_field((P.tolist(), D))
    assert_field(f)
    assert f.source == "arrays"
    assert as_field(f) is f
    f_m = as_field([P / 1000, D / 1000], units="m")
    np.testing.assert_allclose(f_m.points, P, rtol=1e-15)
    np.testing.assert_allclose(f_m.displacements, D, rtol=1e-15)
    path = write(tmp_path, "x,y,z,dx,dy,dz\n" + "\n".join(rows("x y z dx dy dz".split())))
    assert_field(as_field(path))
    assert_field(as_field(str(path)))


def test_as_field_errors():
    with pytest.raises(FieldError, match="cannot make a displacement field from int"):
        as_field(42)
    with pytest.raises(FieldError, match="cannot make a displacement field from tuple"):
        as_field((P, D, D))
    with pytest.raises(FieldError, match="already in mm"):
        as_field(DisplacementField(P, D), units="m")
    with pytest.raises(FieldError, match=r"points must have shape \(N, 3\)"):
        as_field((np.zeros((3, 2)), np.zeros((3, 3))))


# ---------------------------------------------------------------------------------------------------------
# Errors: FieldError, one line, says what is wrong
# ---------------------------------------------------------------------------------------------------------
def raises(path, match, **kw):
    with pytest.raises(FieldError, match=match) as info:
        read_field(path, **kw)
    msg = str(info.value)
    assert "\n" not in msg
    assert isinstance(info.value, InputError) and info.value.exit_code == 2
    return msg


def test_missing_file(tmp_path):
    msg = raises(tmp_path / "nope.csv", "field file not found")
    assert "nope.csv" in msg and "check the path" in msg


def test_directory(tmp_path):
    raises(tmp_path, "is a folder: give the file itself")


def test_unreadable_file(tmp_path, monkeypatch):
    import hot2cold.io.inputs as inputs_module

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    path = write(tmp_path, "x,y,z,dx,dy,dz\n1,2,3,4,5,6\n")
    monkeypatch.setattr(inputs_module, "open", denied, raising=False)
    raises(path, "cannot read field file .*: permission denied")


def test_empty_file(tmp_path):
    raises(write(tmp_path, ""), "is empty")
    raises(write(tmp_path, "  \n\n \t\n"), "is empty")


def test_only_comments(tmp_path):
    raises(write(tmp_path, "# nothing\n# here\n"), "has no header and no data")


def test_binary_file(tmp_path):
    path = tmp_path / "field.bin"
    path.write_bytes(b"\x00\x01\x02garbage\x00")
    raises(path, "is binary")


def test_broken_npz(tmp_path):
    path = tmp_path / "field.npz"
    path.write_bytes(b"PK\x03\x04 this is not really a zip")
    raises(path, r"cannot read field file .* as \.npz")


def test_npz_missing_arrays(tmp_path):
    path = tmp_path / "field.npz"
    np.savez(path, pts=P, displacements=D)
    msg = raises(path, "lacks array.* points")
    assert "found: pts, displacements" in msg


def test_npz_bad_shape(tmp_path):
    path = tmp_path / "field.npz"
    np.savez(path, points=P[:, :2], displacements=D)
    raises(path, r"points must have shape \(N, 3\), got shape \(3, 2\)")


def test_missing_columns(tmp_path):
    """Issue 17: ``UX, UY, UZ`` are displacements now (they were refused); a header naming none of the three is
    still refused, with what it found and how to map the columns."""
    msg = raises(write(tmp_path, "id,X,Y,Z,VX,VY,VZ\n1,0,0,0,0,0,0\n"), r"lacks column\(s\) dx, dy, dz")
    assert "'VX', 'VY', 'VZ'" in msg and "'X'" in msg
    assert "comma-separated" in msg and "morph(columns='x=NAME,...,dz=NAME')" in msg


@pytest.mark.parametrize("header, ids", [
    ("id,X,Y,Z,UX,UY,UZ", True),                                   # the header this file's old test refused
    ("Node Label,COORD1,COORD2,COORD3,U1,U2,U3", True),             # Abaqus report
    ("Node Label,COORD.COOR1,COORD.COOR2,COORD.COOR3,U.U1,U.U2,U.U3", True),
    ("node x y z u1 u2 u3", True),
    ('"Points:0","Points:1","Points:2","U:0","U:1","U:2"', False),   # ParaView's CSV export
    ("Node Number\tX Location (mm)\tY Location (mm)\tZ Location (mm)\tDirectional Deformation X (mm)\t"
     "Directional Deformation Y (mm)\tDirectional Deformation Z (mm)", True),   # ANSYS Mechanical
    ("nid;x [mm];y [mm];z [mm];disp_x;disp_y;disp_z", True),
    # Abaqus/CAE's CSV export of a field report: a magnitude column beside the components
    ("Node Label,COORD-COORD1,COORD-COORD2,COORD-COORD3,U-Magnitude,U-U1,U-U2,U-U3", True),
    ("Node Label  COORD1  COORD2  COORD3  U1  U2  U3", True),       # a report's columns two spaces apart
    ('"Node Label" x y z u1 u2 u3', True),                         # a quoted name with a space
    ("Node Label x y z u1 u2 u3", True),                           # a known name of two words, one space apart
])
def test_other_solvers_headers(tmp_path, header, ids):
    delim = "\t" if "\t" in header else ";" if ";" in header else "," if "," in header else "  "
    magnitude = [[float(np.linalg.norm(D[k]))] if "Magnitude" in header else [] for k in range(len(P))]
    rows = [delim.join(str(v) for v in ([k + 7] if ids else []) + list(P[k]) + magnitude[k] + list(D[k]))
            for k in range(len(P))]
    f = read_field(write(tmp_path, header + "\n" + "\n".join(rows) + "\n"))
    np.testing.assert_array_equal(f.points, P)
    np.testing.assert_array_equal(f.displacements, D)
    if ids:
        np.testing.assert_array_equal(f.node_ids, np.arange(len(P)) + 7)


def test_units_stated_in_the_header(tmp_path):
    """ANSYS writes ``X Location (m)``: the file's own unit is taken; a contradicting one given is refused."""
    header = "X Location (m),Y Location (m),Z Location (m),UX (m),UY (m),UZ (m)\n"
    path = write(tmp_path, header + "\n".join(",".join(map(str, np.r_[P[k], D[k]] / 1000)) for k in range(len(P))))
    f = read_field(path)
    np.testing.assert_allclose(f.points, P, rtol=1e-15)
    np.testing.assert_allclose(f.displacements, D, rtol=1e-15)
    np.testing.assert_allclose(read_field(path, units="m").points, P, rtol=1e-15)
    msg = raises(path, r"states its points in m, but the field units were given as mm", units="mm")
    assert "\n" not in msg
    mixed = write(tmp_path, "x (mm),y (mm),z (mm),dx (um),dy (um),dz (um)\n1,2,3,4,5,6\n")
    g = read_field(mixed)
    np.testing.assert_allclose(g.points, [[1, 2, 3]])
    np.testing.assert_allclose(g.displacements, [[4e-3, 5e-3, 6e-3]])
    raises(write(tmp_path, "x (mm),y (m),z,dx,dy,dz\n1,2,3,4,5,6\n"), r"positions columns state different units")
    raises(write(tmp_path, "x (deg),y,z,dx,dy,dz\n1,2,3,4,5,6\n"), r"column 'x \(deg\)' states the unit 'deg'")


def test_columns_mapping(tmp_path):
    """``--columns``: names the table does not know, and a choice between two it does."""
    rows = "\n".join(",".join(map(str, np.r_[P[k], D[k], D[k] * 2])) for k in range(len(P)))
    path = write(tmp_path, "px,py,pz,ux,uy,uz,dx,dy,dz\n" + rows + "\n")
    raises(path, r"columns 'ux' and 'dx' both give dx; keep one, or choose with morph\(columns='dx=NAME'\)")
    f = read_field(path, columns="x=PX, y=py ,z=Pz,dx=dx,dy=dy,dz=dz")
    np.testing.assert_array_equal(f.points, P)
    np.testing.assert_array_equal(f.displacements, D * 2)
    g = read_field(path, columns={"x": "px", "y": "py", "z": "pz", "dx": "ux", "dy": "uy", "dz": "uz"})
    np.testing.assert_array_equal(g.displacements, D)
    raises(path, r"morph\(columns=\.\.\.\) maps x to 'qx', which the header does not have", columns="x=qx,y=py,z=pz")
    raises(path, r"columns unknown column key 'w'", columns="w=px")
    raises(path, r"columns 'px' is no key=name pair", columns="px")
    raises(path, r"columns column key 'x' is given twice", columns="x=px,x=py")
    np.savez(tmp_path / "f.npz", points=P, displacements=D)
    raises(tmp_path / "f.npz", r"columns applies to text tables only; .*f\.npz is read as npz", columns="x=px")


def test_magnitude_only_is_refused_with_why(tmp_path):
    msg = raises(write(tmp_path, "Node Number,X Location (mm),Y Location (mm),Z Location (mm),"
                                 "Total Deformation (mm)\n1,0,0,0,0.1\n"), r"lacks column\(s\) dx, dy, dz")
    assert "'Total Deformation (mm)' is the displacement's magnitude" in msg


def test_magnitude_is_no_hint_where_the_positions_are_missing(tmp_path):
    """A header with the displacement's components and its magnitude but positions under unknown names is told
    what is missing (the positions), not to export components it has."""
    msg = raises(write(tmp_path, "Node,PX,PY,PZ,U-Magnitude,U-U1,U-U2,U-U3\n1,0,0,0,1,1,0,0\n"),
                 r"lacks column\(s\) x, y, z \(header found")
    assert "the displacement's magnitude" not in msg and "export its three components" not in msg


def test_a_name_with_a_space_is_said_where_it_splits_the_header(tmp_path):
    """A whitespace-separated header whose name of two words hot2cold does not know counts one name too many:
    the message says why and how to write it."""
    msg = raises(write(tmp_path, "Node Tag x y z u1 u2 u3\n1 0 0 0 1 0 0\n2 1 0 0 1 0 0\n"),
                 r"line 2 has 7 fields but the header has 8 \(whitespace-separated\)")
    assert "a column name with a space in it" in msg and "quote it" in msg


def test_no_header(tmp_path):
    msg = raises(write(tmp_path, "1,2,3,4,5,6\n7,8,9,10,11,12\n"), "has no header line: line 1")
    assert "x,y,z,dx,dy,dz" in msg


def test_duplicate_column(tmp_path):
    raises(write(tmp_path, "x,y,z,dx,dy,dz,X\n1,2,3,4,5,6,7\n"), "column 'x' appears twice")


def test_no_data_rows(tmp_path):
    raises(write(tmp_path, "x,y,z,dx,dy,dz\n\n# only a comment\n"), "has a header but no data lines")


def test_text_in_number_column(tmp_path):
    lines = rows("x y z dx dy dz".split())
    lines[1] = lines[1].split(",")
    lines[1][4] = "abc"
    lines[1] = ",".join(lines[1])
    msg = raises(write(tmp_path, "# comment\nx,y,z,dx,dy,dz\n" + "\n".join(lines)),
                 r"line 4, column 'dy' has 'abc', which is not a number")
    assert "fix or remove that line" in msg


def test_text_in_number_column_whitespace(tmp_path):
    raises(write(tmp_path, "X Y Z DX DY DZ\n1 2 3 4 5 6\n\n1 2 3 4 5 6\n1 2 1.2.3 4 5 6\n"),
           r"line 5, column 'Z' has '1.2.3'")


def test_empty_value(tmp_path):
    raises(write(tmp_path, "x,y,z,dx,dy,dz\n1,2,3,4,5,6\n1,,3,4,5,6\n"), r"line 3, column 'y' is empty")


def test_nan_and_inf(tmp_path):
    text = "x,y,z,dx,dy,dz\n1,2,3,4,5,6\n1,2,3,nan,5,6\n1,2,3,4,5,6\ninf,2,3,4,-inf,6\n"
    msg = raises(write(tmp_path, text), r"has 3 NaN or inf value\(s\), the first on line 3")
    assert "column 'dx'" in msg


@pytest.mark.parametrize("text, match", [
    ("x,y,z,dx,dy,dz\n1,2,3,4,5,6\n1,2,3,4,5\n",
     r"line 3 has 5 fields but the header has 6 \(comma-separated\)"),
    ("x,y,z,dx,dy,dz\n1,2,3,4,5,6,7\n1,2,3,4,5,6\n", r"line 2 has 7 fields but the header has 6"),
    ("x y z dx dy dz\n1 2 3 4 5 6\n1 2 3 4 5 6 7 8\n", r"line 3 has 8 fields .*whitespace-separated"),
    ("x y z dx dy dz\n1,2,3,4,5,6\n", r"line 2 has 1 field but the header has 6 \(whitespace-separated\)"),
    # an ignored last column missing on one line, an extra field on another: still caught
    ("id,x,y,z,dx,dy,dz,t\n1,1,2,3,4,5,6,7\n2,1,2,3,4,5,6\n3,1,2,3,4,5,6,7,8\n",
     r"line 3 has 7 fields but the header has 8 .*\(2 lines like it\)"),
])
def test_wrong_number_of_fields(tmp_path, text, match):
    raises(write(tmp_path, text), match)


@pytest.mark.parametrize("units", ["cm", "inch", "", 1000])
def test_unknown_units(tmp_path, units):
    path = write(tmp_path, "x,y,z,dx,dy,dz\n1,2,3,4,5,6\n")
    msg = raises(path, "unknown units", units=units)
    assert "'mm', 'm'" in msg
    with pytest.raises(FieldError, match="unknown units"):
        as_field((P, D), units=units)


def test_units_none_is_the_file_s_own_else_mm(tmp_path):
    """Issue 17: ``units=None`` (the default since) takes the unit a file states, else mm (it was refused)."""
    path = write(tmp_path, "x,y,z,dx,dy,dz\n1,2,3,4,5,6\n")
    np.testing.assert_array_equal(read_field(path, units=None).points, [[1, 2, 3]])
    np.testing.assert_array_equal(as_field((P, D), units=None).points, P)


def test_bad_path_type():
    with pytest.raises(FieldError, match="field path must be a file name"):
        read_field(3.5)


@pytest.mark.parametrize("read, what, name", [
    ("hot2cold.io.nastran:read_op2", "Nastran OP2 file", "r.op2"),
    ("hot2cold.io.nastran:read_punch", "Nastran punch file", "r.pch"),
    ("hot2cold.io.nastran:read_bdf_grids", "Nastran bulk data file", "m.bdf"),
    ("hot2cold.io.frd:read_frd", "CalculiX results file", "r.frd"),
    ("hot2cold.io.ansys:read_rst", "ANSYS result file", "r.rst"),
])
def test_every_solver_reader_refuses_a_missing_file_or_a_folder_in_the_one_wording(tmp_path, read, what, name):
    """The solver readers open their files through the one input check (:mod:`hot2cold.io.inputs`): the same
    words as the STEP and field files, naming the kind of file."""
    import importlib

    module, function = read.split(":")
    reader = getattr(importlib.import_module(module), function)
    with pytest.raises(FieldError, match=rf"^{what} not found: .*{name}; check the path$"):
        reader(tmp_path / name)
    (tmp_path / "folder").mkdir()
    with pytest.raises(FieldError, match=rf"^{what} .*folder is a folder: give the file itself$"):
        reader(tmp_path / "folder")


def test_the_jobs_file_is_checked_as_every_input(tmp_path):
    from hot2cold.cli.batch import read_jobs

    with pytest.raises(InputError, match=r"^jobs file not found: .*jobs\.csv; check the path$"):
        read_jobs(tmp_path / "jobs.csv")

