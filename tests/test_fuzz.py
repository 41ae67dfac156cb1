"""Property-based tests (hypothesis): the field readers on malformed files, and the morph on affine fields.

* Any file given to :func:`hot2cold.io.field.read_field` (a text table with random headers, missing or extra
  columns, junk tokens, NaN and inf, truncated lines; binary junk; a broken ``.npz``, ``.frd`` or ``.vtu``)
  gives a valid field or an :class:`~hot2cold.errors.InputError` with a one-line message, never another
  exception.
* A random affine field (a rotation of up to 1 degree about a random axis through a random point of the part,
  scales 0.99 to 1.01 along the axes, a translation of up to 1 mm) on the bundled twisted blade and filleted
  block and on a box, a cylinder and a sphere is reproduced to 1e-8 mm on every face.

Example counts are fixed and the examples derandomized, so a run is the same on every machine; ``pytest
--hypothesis-show-statistics tests/test_fuzz.py`` shows how many inputs were tried.
"""
from __future__ import annotations

import io

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from hot2cold.errors import InputError
from hot2cold.io.field import DUPLICATE_DISPLACEMENT_RTOL, DUPLICATE_RTOL, DisplacementField, read_field

from conftest import SAMPLES, face_deviation

pytestmark = pytest.mark.slow

FUZZ = settings(deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# ---------------------------------------------------------------------------------------------------------
# Malformed field files
# ---------------------------------------------------------------------------------------------------------
NAMES = ["x", "y", "z", "dx", "dy", "dz", "X", "Y", "Z", "DX", "DY", "DZ", "id", "node", "Node Number", "nid",
         "temp", "", "x y", "dx,dy", '"x"', "'dz'", "#x", "u", "ü", "x\t"]
JUNK = ["nan", "NaN", "inf", "-inf", "+Inf", "1e999", "-1e-999", "", " ", "abc", "1,5", "1.5.2", "--1", "0x10", "1e",
        "e5", '"1"', "'2'", '"', "#", "#1", "1#", "\t", "None", "null", "TRUE", "½", "١", "1_000", "٣.٥", "\x00",
        "9" * 400, "1d3", "1E+3", ".", "-", "+"]
TOKEN = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                  st.integers(-10 ** 20, 10 ** 20).map(str),
                  st.sampled_from(JUNK),
                  st.text(max_size=6))


@st.composite
def text_tables(draw):
    """A text table, sometimes almost right: a header of random (often the right) names, a delimiter, rows of
    numbers and junk with the right number of fields or not, comments, blank lines, a BOM, CRLF, a cut."""
    if draw(st.booleans()):
        names = draw(st.permutations(["x", "y", "z", "dx", "dy", "dz"]))
        names = names + draw(st.lists(st.sampled_from(NAMES), max_size=2))
        if draw(st.booleans()):
            del names[draw(st.integers(0, len(names) - 1))]
    else:
        names = draw(st.lists(st.sampled_from(NAMES), max_size=9))
    delim = draw(st.sampled_from([",", ";", "\t", " ", ", ", "|"]))
    lines = [delim.join(names)] if draw(st.integers(0, 9)) else []
    numeric = st.floats(-1e3, 1e3, allow_nan=False).map(lambda v: f"{v:.6g}")
    for _ in range(draw(st.integers(0, 12))):
        kind = draw(st.integers(0, 9))
        if kind == 0:
            lines.append(draw(st.sampled_from(["", "   ", "# a comment", "#", "\x0c"])))
            continue
        width = len(names) + (draw(st.integers(-2, 2)) if kind == 1 else 0)
        token = TOKEN if kind in (1, 2, 3) else numeric
        lines.append(delim.join(draw(st.lists(token, min_size=max(width, 0), max_size=max(width, 0)))))
    text = draw(st.sampled_from(["\n", "\r\n", "\r"])).join(lines) + ("\n" if draw(st.booleans()) else "")
    raw = text.encode(draw(st.sampled_from(["utf-8", "utf-8-sig", "utf-16", "latin-1"])), errors="replace")
    if draw(st.integers(0, 4)) == 0:
        raw = raw[:draw(st.integers(0, len(raw)))]
    return raw


ARRAY = hnp.arrays(dtype=st.sampled_from([np.float64, np.float32, np.int32, np.int64, np.bool_, np.complex128,
                                          np.dtype("<U3"), np.dtype("<M8[s]")]),
                   shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=5))


@st.composite
def npz_files(draw):
    """An ``.npz`` with random arrays under the names the reader looks for (and others), maybe cut or with a
    byte changed."""
    keys = draw(st.lists(st.sampled_from(["points", "displacements", "node_ids", "U", "junk"]), unique=True,
                         max_size=4))
    arrays = {}
    for key in keys:
        if draw(st.booleans()):       # the right shape, random content
            n = draw(st.integers(0, 5))
            arrays[key] = draw(hnp.arrays(np.float64, (n,) if key == "node_ids" else (n, 3)))
        else:
            arrays[key] = draw(ARRAY)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    raw = buffer.getvalue()
    damage = draw(st.integers(0, 3))
    if damage == 1 and raw:
        raw = raw[:draw(st.integers(0, len(raw) - 1))]
    elif damage == 2 and raw:
        at = draw(st.integers(0, len(raw) - 1))
        raw = raw[:at] + bytes([raw[at] ^ draw(st.integers(1, 255))]) + raw[at + 1:]
    return raw


def _frd_text() -> str:
    from test_readers import disp, frd_text
    return frd_text(disp())


def _vtu_bytes() -> bytes:
    import tempfile
    from pathlib import Path

    import meshio
    from test_readers import CELLS, DSP, PTS
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "f.vtu"
        meshio.write(path, meshio.Mesh(PTS, CELLS, point_data={"U": DSP}), binary=False)
        return path.read_bytes()


@st.composite
def damaged(draw, original: bytes):
    """``original`` cut short, with bytes changed, lines dropped or doubled."""
    raw = original
    for _ in range(draw(st.integers(1, 3))):
        what = draw(st.integers(0, 3))
        if what == 0:
            raw = raw[:draw(st.integers(0, len(raw)))]
        elif what == 1 and raw:
            at = draw(st.integers(0, len(raw) - 1))
            raw = raw[:at] + draw(st.binary(min_size=1, max_size=4)) + raw[at + 1:]
        else:
            lines = raw.split(b"\n")
            k = draw(st.integers(0, len(lines) - 1))
            lines = lines[:k] + ([lines[k]] * 2 if what == 2 else []) + lines[k + 1:]
            raw = b"\n".join(lines)
    return raw


FRD = _frd_text().encode()
VTU = _vtu_bytes()
FILES = st.one_of(
    st.tuples(st.sampled_from([".csv", ".txt", ".dat", ".tsv", "", ".out"]), text_tables()),
    st.tuples(st.sampled_from([".csv", ".npz", ".frd", ".vtu", ".bin"]), st.binary(max_size=600)),
    st.tuples(st.sampled_from([".npz", ".dat"]), npz_files()),
    st.tuples(st.sampled_from([".frd", ".res"]), damaged(FRD)),
    st.tuples(st.just(".vtu"), damaged(VTU)),
)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


def _read_or_refuse(path):
    """``read_field(path)``: a valid field, or an InputError of one line; anything else fails the test."""
    try:
        field = read_field(path)
    except InputError as exc:
        message = str(exc)
        assert message and "\n" not in message and "\r" not in message, repr(message)
        return None
    assert isinstance(field, DisplacementField) and len(field) >= 1
    assert field.points.shape == field.displacements.shape == (len(field), 3)
    assert np.isfinite(field.points).all() and np.isfinite(field.displacements).all()
    return field


@settings(FUZZ, max_examples=1000)
@given(FILES)
def test_malformed_field_files_give_a_field_or_a_clear_error(folder, file):
    suffix, raw = file
    path = folder / f"field{suffix}"
    path.write_bytes(raw)
    field = _read_or_refuse(path)
    event("a field" if field is not None else "refused")


@settings(FUZZ, max_examples=200)
@given(rows=st.lists(st.tuples(*[st.integers(-1000, 1000)] * 3, *[st.floats(-1e3, 1e3)] * 3), min_size=1,
                     max_size=30),
       copies=st.lists(st.tuples(st.integers(0, 29), st.booleans()), max_size=4),
       delim=st.sampled_from([",", ";", "\t", " "]), order=st.permutations(range(6)))
def test_well_formed_tables_read_exactly(folder, rows, copies, delim, order):
    """A well-formed table (any column order, any delimiter) reads back to its numbers; a node repeated with
    the same displacement is merged, with another one refused."""
    values = np.array(rows, dtype=float)
    for k, same in copies:                 # repeat a row, with its displacement or another
        row = values[k % len(values)].copy()
        if not same:
            row[3] += 1.0
        values = np.vstack([values, row])
    names = np.array(["x", "y", "z", "dx", "dy", "dz"])[list(order)]
    text = delim.join(names) + "\n" + "\n".join(delim.join(repr(float(v)) for v in row[list(order)])
                                                 for row in values) + "\n"
    path = folder / "good.csv"
    path.write_text(text)
    field = _read_or_refuse(path)
    # expected: one node per position (the first), its displacement the mean of the group's, refused where they
    # differ by more than hot2cold.io.field's tolerance
    positions, group = np.unique(values[:, :3], axis=0, return_inverse=True)
    group = group.ravel()
    first = np.sort(np.unique(group, return_index=True)[1])
    mean = np.array([values[group == group[i], 3:].mean(axis=0) for i in first])
    spread = max(np.linalg.norm(values[group == group[i], 3:] - m, axis=1).max() for i, m in zip(first, mean))
    extent = np.linalg.norm(np.ptp(values[:, :3], axis=0))
    agree = max(DUPLICATE_DISPLACEMENT_RTOL * np.linalg.norm(values[:, 3:], axis=1).max(),
                DUPLICATE_RTOL * extent, 1e-12)
    event("refused: one position, two displacements" if field is None else
          "merged" if len(field) < len(values) else "read as it is")
    assert (field is None) == (spread > agree)
    if field is not None:
        np.testing.assert_array_equal(field.points, values[first, :3])
        np.testing.assert_allclose(field.displacements, mean, rtol=1e-12, atol=1e-12)


# ---------------------------------------------------------------------------------------------------------
# Affine fields are reproduced
# ---------------------------------------------------------------------------------------------------------
_PARTS: dict = {}


def _part(name: str):
    """(shape, FE-like surface nodes) of a sample part, made once."""
    if name not in _PARTS:
        import cadquery as cq

        from hot2cold.kernel.sampling import fe_surface_nodes
        from hot2cold.kernel.step import read_step
        shape = {"twisted blade": lambda: read_step(SAMPLES / "twisted_blade.step"),
                 "filleted block": lambda: read_step(SAMPLES / "filleted_block.step"),
                 "box": lambda: cq.Workplane().box(20, 12, 8).val().wrapped,
                 "cylinder": lambda: cq.Workplane().cylinder(20, 8).val().wrapped,
                 "sphere": lambda: cq.Workplane().sphere(10).val().wrapped}[name]()
        _PARTS[name] = shape, fe_surface_nodes(shape, 1.0, seed=1)[0]
    return _PARTS[name]


UNIT = st.floats(-1.0, 1.0)


@settings(FUZZ, max_examples=80)
@given(name=st.sampled_from(["twisted blade", "filleted block", "box", "cylinder", "sphere"]),
       axis=st.tuples(UNIT, UNIT, UNIT), angle=st.floats(-1.0, 1.0),
       scale=st.tuples(*[st.floats(0.99, 1.01)] * 3), shift=st.tuples(UNIT, UNIT, UNIT),
       where=st.tuples(*[st.floats(0.0, 1.0)] * 3), keep=st.floats(0.3, 1.0), seed=st.integers(0, 2 ** 16))
def test_random_affine_fields_are_reproduced(name, axis, angle, scale, shift, where, keep, seed):
    from hot2cold.pipeline.morph import check_result, morph
    from hot2cold.testing.synthetic import AffineField, rotation_matrix

    assume(np.linalg.norm(axis) > 1e-3)
    shape, nodes = _part(name)
    rng = np.random.default_rng(seed)
    nodes = nodes[rng.random(len(nodes)) < keep]            # a random share of the nodes
    lo, hi = nodes.min(axis=0), nodes.max(axis=0)
    centre = lo + np.array(where) * (hi - lo)
    matrix = rotation_matrix(axis, angle) @ np.diag(scale)
    field = AffineField(matrix, centre - matrix @ centre + np.array(shift))
    result = morph(shape, (nodes, field(nodes)))
    check_result(result)
    deviation = face_deviation(result, field.exact_map, spacing=1.0)
    assert all(len(d) for d in deviation)
    assert max(float(d.max()) for d in deviation) <= 1e-8
