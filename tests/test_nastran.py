"""The native Nastran readers (hot2cold.io.nastran) on real NX and MSC files, against pyNastran.

``corpus/solver_results/nastran/reference.npz`` holds what pyNastran 1.4.1 reads from the same files
(written by ``benchmarks/nastran_reference.py``, see its docstring to regenerate it).
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from hot2cold.errors import FieldError
from hot2cold.io.nastran import NastranResult, read_bdf_grids, read_op2, read_punch

CORPUS = Path(__file__).resolve().parents[1] / "corpus" / "solver_results" / "nastran"
REFERENCE = np.load(CORPUS / "reference.npz")
OP2_FILES = sorted(p.name for p in CORPUS.glob("*.op2"))
CD_RUN, BASIC_RUN = "static_solid_shell_bar_global_radial_cd.op2", "static_solid_shell_bar.op2"
CTETRA_SETS = tuple(f"subcase {i}" for i in range(1, 13))

# (file, subcase) pairs of the reference, e.g. ("ctetra.op2", "subcase 7").
REFERENCE_SETS = sorted({tuple(k.split("/")[:2]) for k in REFERENCE.files if k.split("/")[0].endswith(".op2")})


def reference(name: str, subcase: str) -> dict[str, np.ndarray]:
    prefix = f"{name}/{subcase}/"
    return {k[len(prefix):]: REFERENCE[k] for k in REFERENCE.files if k.startswith(prefix)}


def assert_float32_close(actual: np.ndarray, expected: np.ndarray):
    """Equal to float32 rounding: 1e-6 of the largest magnitude (the file holds 6-7 significant digits)."""
    assert actual.shape == expected.shape
    scale = max(float(np.abs(expected).max()), 1e-30)
    np.testing.assert_allclose(actual, expected, rtol=0, atol=1e-6 * scale)


def one_line_error(call, *words: str) -> str:
    with pytest.raises(FieldError) as info:
        call()
    message = str(info.value)
    assert "\n" not in message and message.strip() == message
    for word in words:
        assert word in message, message
    return message


# --------------------------------------------------------------------------------------------------------
# OP2 against pyNastran
# --------------------------------------------------------------------------------------------------------
def test_corpus_and_reference_cover_every_op2():
    assert len(OP2_FILES) == 6
    assert {name for name, _ in REFERENCE_SETS} == set(OP2_FILES)
    assert len(REFERENCE_SETS) == 17                 # ctetra has 12 subcases, the others one


@pytest.mark.parametrize("name,subcase", REFERENCE_SETS, ids=[f"{n}:{s}" for n, s in REFERENCE_SETS])
def test_op2_matches_pynastran(name, subcase):
    ref = reference(name, subcase)
    result = read_op2(CORPUS / name, field_name=subcase)
    assert isinstance(result, NastranResult) and result.name == subcase
    np.testing.assert_array_equal(result.node_ids, ref["node_ids"])
    assert result.node_ids.dtype == np.int64 and result.displacements.dtype == np.float64
    assert_float32_close(result.points, ref["points"])
    if (ref["cd"] == 0).all():
        assert_float32_close(result.displacements, ref["displacements"])
    else:   # the basic-frame vectors of a run in CD systems: Nastran's own run of the model with CD 0
        basic = reference(BASIC_RUN, subcase)
        np.testing.assert_array_equal(result.node_ids, basic["node_ids"])
        assert_float32_close(result.displacements, basic["displacements"])


def test_cd_run_is_transformed_to_the_basic_frame():
    raw = reference(CD_RUN, "subcase 1")
    assert (raw["cd"] == 1).all()
    result = read_op2(CORPUS / CD_RUN)
    # the file's own (r, theta, z) components are not the basic ones: the transform does something
    assert np.abs(result.displacements - raw["displacements"]).max() > 1e-4
    np.testing.assert_allclose(result.displacements[:, 2], raw["displacements"][:, 2], rtol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(result.displacements, axis=1),
                               np.linalg.norm(raw["displacements"], axis=1), rtol=1e-6)


def test_known_values_of_the_msc_solid():
    result = read_op2(CORPUS / "solid_bending.op2")
    assert len(result.node_ids) == 72 and result.available == ("subcase 1",)
    np.testing.assert_allclose(result.points[0], [0.513061, 1.49287, 0.811943], rtol=1e-6)
    np.testing.assert_allclose(result.displacements[0], [7.64469383e-03, 4.01388970e-05, 1.11136607e-04],
                               rtol=1e-6)
    assert float(np.abs(result.displacements).max()) == pytest.approx(0.0121, rel=0.01)


def test_msc_2020_double_precision_grids():
    result = read_op2(CORPUS / "static.op2")
    assert len(result.node_ids) == 20
    np.testing.assert_array_equal(result.points[:2], [[0.0025, 0.0, 0.01], [0.0025, 0.005, 0.01]])


def test_results_are_read_only():
    result = read_op2(CORPUS / "ctetra.op2")
    for a in (result.node_ids, result.displacements, result.points):
        assert not a.flags.writeable


# --------------------------------------------------------------------------------------------------------
# Choosing the result set
# --------------------------------------------------------------------------------------------------------
def test_every_subcase_by_step_and_by_name():
    path = CORPUS / "ctetra.op2"
    assert read_op2(path).available == CTETRA_SETS
    assert read_op2(path).name == "subcase 12"
    for i, name in enumerate(CTETRA_SETS):
        by_step, by_name, by_id = read_op2(path, step=i), read_op2(path, field_name=name), \
            read_op2(path, field_name=name.split()[1])
        negative = read_op2(path, step=i - len(CTETRA_SETS))
        for r in (by_step, by_name, by_id, negative):
            assert r.name == name
            assert_float32_close(r.displacements, reference("ctetra.op2", name)["displacements"])
    assert read_op2(path, field_name="SUBCASE 3").name == "subcase 3"


def test_subcases_differ():
    path = CORPUS / "ctetra.op2"
    d4, d12 = read_op2(path, step=3).displacements, read_op2(path, step=11).displacements
    assert np.abs(d4).max() > 0 and np.abs(d12).max() > 0 and not np.allclose(d4, d12)


@pytest.mark.parametrize("step", [12, -13, 100])
def test_step_out_of_range(step):
    one_line_error(lambda: read_op2(CORPUS / "ctetra.op2", step=step), "ctetra.op2", "no step", "subcase 12")


def test_bad_field_name_lists_the_available_sets():
    message = one_line_error(lambda: read_op2(CORPUS / "ctetra.op2", field_name="subcase 99"),
                             "ctetra.op2", "'subcase 99'")
    assert message.endswith(", ".join(CTETRA_SETS))


def test_field_name_and_step_together():
    one_line_error(lambda: read_op2(CORPUS / "ctetra.op2", field_name="subcase 1", step=0), "not both")


# --------------------------------------------------------------------------------------------------------
# Bad files
# --------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", OP2_FILES)
def test_truncated_copies(tmp_path, name):
    raw = (CORPUS / name).read_bytes()
    cuts = sorted({1, 3, 4, 8, 20, 60, 100, len(raw) // 3, len(raw) // 2, 2 * len(raw) // 3, len(raw) - 40,
                   len(raw) - 12, len(raw) - 4, len(raw) - 1})
    for cut in cuts:
        path = tmp_path / f"cut{cut}_{name}"
        path.write_bytes(raw[:cut])
        one_line_error(lambda: read_op2(path), path.name)


def test_truncated_message_names_table_and_byte(tmp_path):
    raw = (CORPUS / "solid_bending.op2").read_bytes()
    at = raw.index(b"OUGV1   ") + 200
    path = tmp_path / "cut.op2"
    path.write_bytes(raw[:at])
    message = one_line_error(lambda: read_op2(path), "cut.op2 is truncated in table OUGV1 at byte", "write it again")
    assert int(message.split("at byte ")[1].split(";")[0]) < at


def _records(*payloads: bytes) -> bytes:
    return b"".join(struct.pack("<i", len(p)) + p + struct.pack("<i", len(p)) for p in payloads)


def _marker(m: int) -> bytes:
    return struct.pack("<i", m)


def test_a_table_of_another_structure_before_any_displacement_is_named(tmp_path):
    """A matrix table (written by OUTPUT2: 18 of pyNastran's models) does not read as a table of result records;
    with no displacements before it, the file lacks displacements: said so, naming the table, not "corrupt"."""
    head = [_marker(2), b"DSCM2   ", _marker(-1), _marker(7), bytes(28), _marker(-2)]
    path = tmp_path / "matrix.op2"
    path.write_bytes(_records(*head, _marker(1), _marker(1), _marker(0)))
    message = one_line_error(lambda: read_op2(path), "holds no static real SORT1 displacements before table DSCM2")
    assert "a matrix or another table of its own structure: marker 1 where 0 belongs at byte" in message
    assert "write it again" not in message
    # a file cut inside a table is still a damaged file
    path.write_bytes(_records(*head, _marker(1)))
    assert "is truncated" in one_line_error(lambda: read_op2(path))


def test_empty_file(tmp_path):
    path = tmp_path / "empty.op2"
    path.write_bytes(b"")
    one_line_error(lambda: read_op2(path), "empty.op2 is empty")


def test_text_renamed_op2(tmp_path):
    path = tmp_path / "deck.op2"
    path.write_text((CORPUS / "ctetra.bdf").read_text())
    one_line_error(lambda: read_op2(path), "deck.op2 is not a Nastran OP2 file")


def test_punch_renamed_op2(tmp_path):
    path = tmp_path / "results.op2"
    path.write_bytes((CORPUS / "cbush.pch").read_bytes())
    one_line_error(lambda: read_op2(path), "not a Nastran OP2")


def test_missing_file(tmp_path):
    one_line_error(lambda: read_op2(tmp_path / "none.op2"), "Nastran OP2 file not found:", "none.op2")


@pytest.mark.parametrize("head,word", [(struct.pack("<i", 8), "64-bit"), (struct.pack(">i", 4), "big-endian")])
def test_64_bit_and_big_endian_refused(tmp_path, head, word):
    path = tmp_path / "other.op2"
    path.write_bytes(head + (CORPUS / "cbush.op2").read_bytes()[4:])
    one_line_error(lambda: read_op2(path), "other.op2", word)


def test_corrupt_record_length(tmp_path):
    raw = bytearray((CORPUS / "solid_bending.op2").read_bytes())
    at = raw.index(b"OUGV1   ") - 4
    raw[at:at + 4] = struct.pack("<i", 12)
    path = tmp_path / "corrupt.op2"
    path.write_bytes(bytes(raw))
    one_line_error(lambda: read_op2(path), "corrupt.op2")


def test_non_finite_displacement_is_refused(tmp_path):
    raw = (CORPUS / "solid_bending.op2").read_bytes()
    value = struct.pack("<f", 7.64469383e-03)        # T1 of grid 1
    assert raw.count(value) == 1
    path = tmp_path / "nan.op2"
    path.write_bytes(raw.replace(value, struct.pack("<f", float("nan"))))
    one_line_error(lambda: read_op2(path), "nan.op2: grid 1 has a non-finite displacement in subcase 1")


def _ident_positions(raw: bytes) -> list[int]:
    """Byte offsets of the payloads of the 146-word IDENT records in an OP2."""
    length = struct.pack("<i", 584)
    out, start = [], 0
    while (i := raw.find(length, start)) >= 0:
        if raw[i + 588:i + 592] == length:
            out.append(i + 4)
        start = i + 4
    return out


@pytest.mark.parametrize("word,value,expected", [(0, 63, "transient displacements in OUGV1"),
                                                 (1, 7, "eigenvectors in OUGV1"),
                                                 (1, 1001, "statics displacements in OUGV1 (not real SORT1)")])
def test_other_kinds_of_results_are_named(tmp_path, word, value, expected):
    raw = bytearray((CORPUS / "ctetra.op2").read_bytes())
    idents = [i for i in _ident_positions(bytes(raw)) if struct.unpack_from("<i", raw, i + 4)[0] == 1]
    assert len(idents) == 12
    for i in idents:
        struct.pack_into("<i", raw, i + 4 * word, value)
    path = tmp_path / "other.op2"
    path.write_bytes(bytes(raw))
    one_line_error(lambda: read_op2(path), "other.op2 holds no static real SORT1 displacements", expected)


def test_grid_in_an_unsupported_system_is_refused(tmp_path):
    raw = (CORPUS / CD_RUN).read_bytes()
    cord2c = struct.pack("<3i", 2001, 20, 9)
    assert raw.count(cord2c) == 1
    path = tmp_path / "cord1c.op2"
    path.write_bytes(raw.replace(cord2c, struct.pack("<3i", 1701, 17, 6)))
    one_line_error(lambda: read_op2(path), "cord1c.op2: grid 1 uses coordinate system 1", "CORD1C")


# The CORD2 systems of static_solid_shell_bar.op2 (its .bdf): cid -> kind, A (origin), B (on z), C (in xz).
SYSTEMS = {2: ("C", (0, 0, 0), (0, 0, 1), (1, 0, 0)), 3: ("S", (0, 0, 0), (0, 0, 1), (1, 0, 0)),
           11: ("R", (1, 2, 3), (0, 0, 1), (0, 1, 0)), 12: ("C", (1, 2, 3), (0, 0, 1), (0, 1, 0)),
           13: ("S", (1, 2, 3), (0, 0, 1), (0, 1, 0))}


def local_coordinates(cid: int, basic: np.ndarray) -> np.ndarray:
    """Coordinates (M, 3) in system ``cid`` of basic positions (M, 3): x y z, r theta z or r theta phi (deg)."""
    kind, a, b, c = (SYSTEMS[cid][0], *map(np.asarray, SYSTEMS[cid][1:]))
    ez = (b - a) / np.linalg.norm(b - a)
    ey = np.cross(ez, c - a) / np.linalg.norm(np.cross(ez, c - a))
    x, y, z = ((basic - a) @ np.column_stack([np.cross(ey, ez), ey, ez])).T
    if kind == "R":
        return np.column_stack([x, y, z])
    if kind == "C":
        return np.column_stack([np.hypot(x, y), np.degrees(np.arctan2(y, x)), z])
    r = np.sqrt(x * x + y * y + z * z)
    return np.column_stack([r, np.degrees(np.arccos(z / np.where(r > 0, r, 1))), np.degrees(np.arctan2(y, x))])


@pytest.mark.parametrize("cid", sorted(SYSTEMS))
def test_grids_given_in_local_systems(tmp_path, cid):
    """The real NX file with its GRIDs rewritten in system ``cid`` (CP) gives the same basic positions."""
    raw = bytearray((CORPUS / BASIC_RUN).read_bytes())
    at = raw.index(struct.pack("<3i", 4501, 45, 1)) + 12
    count = (struct.unpack_from("<i", raw, at - 16)[0] - 12) // 32       # the record's length, less the key
    grids = np.frombuffer(bytes(raw[at:at + 32 * count]), [("id", "<i4"), ("cp", "<i4"), ("x", "<f4", 3),
                                                           ("rest", "<i4", 3)]).copy()
    expected = read_op2(CORPUS / BASIC_RUN)
    assert count == 25 and (grids["cp"] == 0).all()
    grids["cp"] = cid
    grids["x"] = local_coordinates(cid, grids["x"].astype(np.float64))
    raw[at:at + 32 * count] = grids.tobytes()
    path = tmp_path / f"cp{cid}.op2"
    path.write_bytes(bytes(raw))
    result = read_op2(path)
    np.testing.assert_allclose(result.points, expected.points, rtol=0, atol=2e-6 * 4)
    np.testing.assert_array_equal(result.displacements, expected.displacements)


def test_op2_without_geometry_has_no_points(tmp_path):
    raw = bytearray((CORPUS / "solid_bending.op2").read_bytes())
    at = raw.index(b"GEOM1   ")
    raw[at:at + 8] = b"XEOM1   "           # the table is then skipped as unknown
    path = tmp_path / "nogeom.op2"
    path.write_bytes(bytes(raw))
    result = read_op2(path)
    assert result.points is None
    assert_float32_close(result.displacements, reference("solid_bending.op2", "subcase 1")["displacements"])


# --------------------------------------------------------------------------------------------------------
# Punch
# --------------------------------------------------------------------------------------------------------
def test_punch_matches_the_op2_of_the_same_run():
    result = read_punch(CORPUS / "cbush.pch")
    ref = reference("cbush.op2", "subcase 1")
    assert result.points is None and result.name == "subcase 1" and result.available == ("subcase 1",)
    np.testing.assert_array_equal(result.node_ids, ref["node_ids"])
    assert_float32_close(result.displacements, ref["displacements"])
    np.testing.assert_array_equal(result.displacements, [[0, 0, 0], [1e-6, 0, 0]])


def _two_subcase_punch(tmp_path) -> Path:
    text = (CORPUS / "cbush.pch").read_text()
    lines = text.splitlines()
    block = lines[:10]            # $TITLE ... the two grids of the displacement block
    second = [ln.replace("SUBCASE ID =           1", "SUBCASE ID =           7").replace("1.000000E-06",
                                                                                          "2.500000E-03")
              for ln in block]
    path = tmp_path / "two.pch"
    path.write_text("\n".join(lines + second) + "\n")
    return path


def test_punch_subcase_selection(tmp_path):
    path = _two_subcase_punch(tmp_path)
    assert read_punch(path).available == ("subcase 1", "subcase 7")
    assert read_punch(path).displacements[1, 0] == pytest.approx(2.5e-3)
    for selected in (read_punch(path, step=0), read_punch(path, field_name="1"), read_punch(path, step=-2)):
        assert selected.name == "subcase 1" and selected.displacements[1, 0] == pytest.approx(1e-6)
    assert read_punch(path, field_name="subcase 7").displacements[1, 0] == pytest.approx(2.5e-3)
    one_line_error(lambda: read_punch(path, field_name="3"), "two.pch has no result set '3'",
                   "subcase 1, subcase 7")
    one_line_error(lambda: read_punch(path, step=2), "no step 2")


def test_punch_without_displacements(tmp_path):
    lines = (CORPUS / "cbush.pch").read_text().splitlines()
    path = tmp_path / "spcf.pch"
    path.write_text("\n".join(lines[10:]) + "\n")     # SPC forces and element results only
    one_line_error(lambda: read_punch(path), "spcf.pch holds no static real displacements")


def test_punch_of_eigenvectors_is_refused(tmp_path):
    text = (CORPUS / "cbush.pch").read_text().replace("$DISPLACEMENTS ", "$EIGENVECTOR  ").replace(
        "$SUBCASE ID =           1   ", "$EIGENVALUE = 1.0 MODE = 1  ")
    path = tmp_path / "modes.pch"
    path.write_text(text)
    one_line_error(lambda: read_punch(path), "modes.pch holds no static real displacements")


def test_bad_punch_files(tmp_path):
    empty = tmp_path / "empty.pch"
    empty.write_text("\n  \n")
    one_line_error(lambda: read_punch(empty), "empty.pch is empty")
    binary = tmp_path / "binary.pch"
    binary.write_bytes((CORPUS / "cbush.op2").read_bytes())
    one_line_error(lambda: read_punch(binary), "binary.pch is a binary file")
    bad = tmp_path / "bad.pch"
    bad.write_text((CORPUS / "cbush.pch").read_text().replace("1.000000E-06", "1.0000x0E-06", 1))
    one_line_error(lambda: read_punch(bad), "bad.pch line 9", "unreadable number")
    short = tmp_path / "short.pch"
    lines = (CORPUS / "cbush.pch").read_text().splitlines()
    short.write_text("\n".join(lines[:8] + [lines[8][:40]] + lines[9:]) + "\n")
    one_line_error(lambda: read_punch(short), "short.pch line 9", "expected 'grid-id type T1 T2 T3'")


# --------------------------------------------------------------------------------------------------------
# Bulk data GRIDs
# --------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["solid_bending", "ctetra", "static"])
def test_bdf_grids_match_pynastran_and_the_op2(name):
    ids, points = read_bdf_grids(CORPUS / f"{name}.bdf")
    order = np.argsort(ids)
    np.testing.assert_array_equal(ids[order], REFERENCE[f"{name}.bdf/node_ids"])
    np.testing.assert_array_equal(points[order], REFERENCE[f"{name}.bdf/points"])
    op2 = read_op2(CORPUS / f"{name}.op2")
    rows = np.searchsorted(ids[order], op2.node_ids)
    assert_float32_close(points[order][rows], op2.points)


def test_bdf_grids_in_local_systems_are_refused():
    one_line_error(lambda: read_bdf_grids(CORPUS / "static_solid_shell_bar_global_radial_cd.bdf"),
                   "line 28: grid 13 has CP 0 and CD 1")


def small(*fields: str) -> str:
    """A small-field bulk data line: 8 columns a field."""
    return "".join(f"{f:8s}" for f in fields) + "\n"


def test_bdf_card_formats(tmp_path):
    (tmp_path / "more.inc").write_text("GRID,5,,1.5-3,-2.+2,.25D1\n")
    path = tmp_path / "model.bdf"
    path.write_text(
        "SOL 101\nCEND\nBEGIN BULK\n"
        "$ small field, tabs, large field, free field, an include\n"
        + small("GRID", "1", "", "1.", "2.", "3.")
        + "GRID\t2\t\t-4.5\t0.\t1.+1\n"
        + "GRID*   " + "".join(f"{f:16s}" for f in ("3", "", "1.25", "-2.5")) + "\n"
        + "*       " + f"{'7.0':>16s}" + "\n"
        + "grid,4,0,7.,8.,9. $ comment\n"
        + "INCLUDE 'more.inc'\n"
        + "ENDDATA\n" + small("GRID", "9", "", "1.", "2.", "3."))
    ids, points = read_bdf_grids(path)
    np.testing.assert_array_equal(ids, [1, 2, 3, 4, 5])
    np.testing.assert_array_equal(points, [[1, 2, 3], [-4.5, 0, 10], [1.25, -2.5, 7], [7, 8, 9],
                                           [1.5e-3, -200, 2.5]])


@pytest.mark.parametrize("text,words", [
    (small("GRID", "1", "", "1.", "2.", "3.") + small("GRID", "1", "", "1."), ("grid 1 is defined more than once",)),
    (small("GRID", "1", "2", "1.", "2.", "3."), ("grid 1 has CP 2 and CD 0",)),
    (small("GRDSET", "", "", "", "", "", "3") + small("GRID", "1", "", "1."), ("GRDSET",)),
    (small("GRID", "1", "", "1.x", "2.", "3."), ("line 1", "'1.x' is not a number")),
    (small("GRID", "1.5", "", "1.", "2.", "3."), ("line 1", "'1.5' is not an integer")),
    (small("CTETRA", "1", "1", "1", "2", "3", "4"), ("holds no GRID cards",)),
    ("GRID*   " + "".join(f"{f:16s}" for f in ("3", "", "1.25", "-2.5")) + "\n", ("continuation",)),
])
def test_bad_bdf(tmp_path, text, words):
    path = tmp_path / "bad.bdf"
    path.write_text(text)
    one_line_error(lambda: read_bdf_grids(path), "bad.bdf", *words)


# --------------------------------------------------------------------------------------------------------
# Points without position, heat transfer tables, grids on a system's axis (issue 39: pyNastran's models/)
# --------------------------------------------------------------------------------------------------------
def _data_rows(raw: bytes, ident: int) -> tuple[int, int]:
    """Byte offset and row count of the data record after the IDENT whose payload starts at ``ident``."""
    at = ident + 584 + 4
    for _ in range(4):            # the markers -k, 1, 0 and n (n words of data follow)
        (length,) = struct.unpack_from("<i", raw, at)
        (value,) = struct.unpack_from("<i", raw, at + 4)
        at += length + 8
    return at + 4, value // 8


def _with_point_kind(tmp_path, rows: slice, kind: int) -> tuple[Path, int]:
    raw = bytearray((CORPUS / "solid_bending.op2").read_bytes())
    idents = [i for i in _ident_positions(bytes(raw)) if struct.unpack_from("<i", raw, i + 4)[0] == 1]
    start, count = _data_rows(bytes(raw), idents[-1])
    picked = range(count)[rows]
    for r in picked:
        struct.pack_into("<i", raw, start + 32 * r + 4, kind)
    path = tmp_path / "points.op2"
    path.write_bytes(bytes(raw))
    return path, len(picked)


@pytest.mark.parametrize("kind,name", [(2, "scalar point(s)"), (3, "extra point(s)")])
def test_scalar_and_extra_points_are_left_out_and_said(tmp_path, caplog, kind, name):
    full = read_op2(CORPUS / "solid_bending.op2")
    path, n = _with_point_kind(tmp_path, slice(0, 3), kind)
    with caplog.at_level("INFO", logger="hot2cold.io.nastran"):
        result = read_op2(path)
    np.testing.assert_array_equal(result.node_ids, full.node_ids[n:])
    said = [r for r in caplog.records if r.levelname == "WARNING"]
    assert [r.getMessage() for r in said] == [f"{path}: 3 {name} of subcase 1 left out (no position)"]


def test_a_set_of_scalar_points_only_is_refused(tmp_path):
    path, n = _with_point_kind(tmp_path, slice(None), 2)
    one_line_error(lambda: read_op2(path), "points.op2: subcase 1 holds the displacements of",
                   f"{n} scalar point(s) only, no GRID")


def test_punch_scalar_points_are_left_out_and_said(tmp_path, caplog):
    lines = (CORPUS / "cbush.pch").read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.split()[1:2] == ["G"])
    lines[k] = lines[k].replace(" G ", " S ", 1)
    path = tmp_path / "spoint.pch"
    path.write_text("\n".join(lines) + "\n")
    with caplog.at_level("INFO", logger="hot2cold.io.nastran"):
        result = read_punch(path)
    assert len(result.node_ids) == 1
    assert f"{path}: 1 scalar point(s) of subcase 1 left out (no position)" in caplog.messages


def test_heat_transfer_tables_are_not_displacements(tmp_path):
    raw = bytearray((CORPUS / "ctetra.op2").read_bytes())
    idents = [i for i in _ident_positions(bytes(raw)) if struct.unpack_from("<i", raw, i + 4)[0] == 1]
    for i in idents:
        struct.pack_into("<i", raw, i + 4 * 22, 1)      # IDENT word 23: thermal flag
    path = tmp_path / "thermal.op2"
    path.write_bytes(bytes(raw))
    one_line_error(lambda: read_op2(path), "thermal.op2 holds no static real SORT1 displacements",
                   "temperatures in OUGV1")


@pytest.mark.parametrize("kind", ["C", "S"])
def test_grid_on_the_axis_of_a_cylindrical_or_spherical_system(kind):
    from hot2cold.io.nastran import _local_axes

    noisy = np.array([[1e-16, -3e-17, 3.0], [0.0, 0.0, 3.0]])    # r = 0 but for rounding of the position
    axes = _local_axes(kind, noisy)
    np.testing.assert_allclose(axes[0], axes[1], atol=1e-12)
    # phi = 0: e_theta is the system's y axis (C); e_theta at theta = 0 is its x axis (S)
    np.testing.assert_allclose(axes[1][:, 1], [0, 1, 0] if kind == "C" else [1, 0, 0], atol=1e-12)
