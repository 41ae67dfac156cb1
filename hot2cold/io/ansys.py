"""ANSYS Mechanical APDL result files (``.rst``): the nodal displacements of one result set.

:func:`read_rst` reads a structural result file with `ansys-mapdl-reader
<https://github.com/ansys/pymapdl-reader>`_ (MIT; the ``solvers`` extra), imported only here and only when
a file is read: it imports VTK and pyvista, which the rest of hot2cold does not need.

What is taken
-------------
* ``node_ids`` ``(N,)``: the MAPDL node numbers, ascending; ``points`` ``(N, 3)``: their coordinates from
  the file's geometry (global Cartesian); ``displacements`` ``(N, 3)``: ``UX, UY, UZ`` of the chosen result
  set, rotated to the global Cartesian system (MAPDL writes them in each node's nodal coordinate system).
  Nodes for which the result set holds no displacement (nodes of no element, nodes the solution left out)
  are dropped, with a log line; a file in which no node has one, or without a ``UZ`` degree of freedom
  (a 2-D model), is refused.
* The result set: ``step`` counts the file's result sets from 0 in file order (cumulative index; negative
  from the end); ``field_name`` names one as ``"LS,SUB"`` (load step and substep, e.g. ``"1,2"``; a
  semicolon or spaces also separate them) or by its time value (a frequency for a modal analysis, compared
  to 1e-6 relative), e.g. ``"2.5"``; a time that several sets share is refused (name it as ``LS,SUB``).
  Neither given: the last set.  Both given: refused.
* ``unit``: the length unit of the file's unit system (``/UNITS``), from item 20 (``units``) of the
  result file header; item 5 of the standard file header holds the same code (a mismatch is logged).
  ansys-mapdl-reader's own ``units`` entry is not used: it reads a word past item 5 and says "User
  Defined" for every file.  The codes (MAPDL Programmer's Reference, ``fdresu.inc``):

  =====  ================================  ======
  code   /UNITS system                     unit
  =====  ================================  ======
  -1, 0  not set / USER (user-defined)     None
  1      SI (m, kg, s, K)                  ``m``
  2      CGS (cm, g, s)                    ``cm``
  3      BFT (U.S. customary, feet)        ``ft``
  4      BIN (U.S. customary, inches)      ``in``
  5      MKS (m, kg, s)                    ``m``
  6      MPA (mm, Mg, s)                   ``mm``
  7      uMKS (um, kg, s)                  ``um``
  =====  ================================  ======

  Any other code gives None (logged).  None means the file does not say: the caller decides.
* ``triangles``: the outer faces of the solid elements (tetrahedra, hexahedra, wedges, pyramids, linear
  or quadratic, as ansys-mapdl-reader maps MAPDL's element types and their degenerate forms to VTK cells):
  the faces no second solid element shares, turned to face out of their element.  A model whose outer
  faces are all 6-node triangles (quadratic tetrahedra) gives ``(T, 6)`` (corners, then the midside nodes
  of edges a-b, b-c, c-a); otherwise ``(T, 3)``: a 4-node face as two triangles, an 8-node face as six
  straight triangles through its midside nodes, a 6-node triangle beside them as four.  The straight
  pieces follow a quadratic face only at its nodes: what lies between them is linear, not the element's
  own shape functions.  Elements that lost midside nodes give their faces' corners only.  Shell, beam,
  contact and other non-solid elements give none (logged); None when the model has no solid element.
  Rows of ``points``; faces with a dropped node are left out (logged).

Refused with a one-line :class:`~hot2cold.errors.FieldError` naming the file: a missing, empty, truncated or
corrupt file, a file that is not an MAPDL binary result file (another MAPDL binary file, a text file), a
thermal result, a cyclic-symmetry result (one sector; expand it in MAPDL first), a file without nodal
displacements.  The file's structure (standard header, result header, its pointers and end-of-file
pointer) is checked before ansys-mapdl-reader opens it: its compiled reader aborts the process on a
truncated file instead of raising.
"""
from __future__ import annotations

import logging
import os
import re
from dataclasses import dataclass

import numpy as np

from ..core.arrays import distinct
from ..errors import FieldError, one_line
from .inputs import check_input_file

__all__ = ["AnsysResult", "read_rst", "UNIT_SYSTEMS"]

log = logging.getLogger(__name__)

#: MAPDL's ``/UNITS`` codes (standard file header item 5, result file header item 20) -> (system, length
#: unit as hot2cold names it, or None where the file does not fix one).
UNIT_SYSTEMS: dict[int, tuple[str, str | None]] = {
    -1: ("not set", None),
    0: ("USER", None),
    1: ("SI", "m"),
    2: ("CGS", "cm"),
    3: ("BFT", "ft"),
    4: ("BIN", "in"),
    5: ("MKS", "m"),
    6: ("MPA", "mm"),
    7: ("uMKS", "um"),
}

#: MAPDL binary file numbers (standard header item 1) of the files that are not results.
_FILE_KINDS = {2: "element matrix (.emat)", 3: "element saved data (.esav)", 4: "full matrix (.full)",
               8: "substructure matrix (.sub)", 9: "mode shape (.mode)", 10: "reduced displacement (.rdsp)",
               11: "reduced complex displacement (.rfrq)", 16: "database (.db)"}

_HELP = "give the complete .rst that MAPDL wrote"
_NEEDS_READER = "reading ANSYS .rst files needs ansys-mapdl-reader: pip install 'hot2cold[solvers]'"


@dataclass(frozen=True)
class AnsysResult:
    """One result set of an MAPDL ``.rst``, in the file's length unit.

    Attributes
    ----------
    node_ids : (N,) int64, the MAPDL node numbers (ascending).
    points : (N, 3) float64, the node coordinates (global Cartesian).
    displacements : (N, 3) float64, ``UX, UY, UZ`` of the chosen result set (global Cartesian).
    unit : the length unit of the file's unit system (``"m"``, ``"mm"``, ``"cm"``, ``"um"``, ``"in"``,
        ``"ft"``), None when the file does not state one (see :data:`UNIT_SYSTEMS`).
    name : which result set was taken, for a log line: its ``step`` index, load step, substep and time:
        ``"2 (load step 1, substep 3, time 2.5)"``.
    available : the file's result sets as ``field_name`` takes them, ``"LS,SUB"``, in file order.
    triangles : (T, 3) or (T, 6) int64 rows of ``points``, the outer faces of the solid elements, or None.
    """

    node_ids: np.ndarray
    points: np.ndarray
    displacements: np.ndarray
    unit: str | None
    name: str
    available: tuple[str, ...]
    triangles: np.ndarray | None = None


def read_rst(path: str, field_name: str | None = None, step: int | None = None) -> AnsysResult:
    """The nodal displacements of one result set of the MAPDL result file ``path`` (see the module docs).

    ``step``: the result set's cumulative index from 0 (negative from the end); ``field_name``: ``"LS,SUB"``
    or a time value.  Neither: the last set.  Raises :class:`~hot2cold.errors.FieldError` (one line naming
    the file) for anything unreadable or unsuitable.
    """
    path = os.fspath(path)
    if step is not None and field_name is not None:
        raise FieldError(f"ANSYS result file {path}: give the result set by step or by field_name, not both")
    if step is not None and (isinstance(step, bool) or not isinstance(step, (int, np.integer))):
        raise FieldError(f"ANSYS result file {path}: step must be an integer (a result set index), got {step!r}")
    check_input_file(path, "ANSYS result file", FieldError)
    unit_code = _check_structure(path)
    try:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import ansys.mapdl.reader as mapdl_reader
    except ImportError:
        raise FieldError(_NEEDS_READER) from None
    try:
        rst = _open(mapdl_reader, path)
        index, name, available = _choose(rst, path, field_name, step)
        node_ids, points, displacements = _nodal_displacements(rst, index, path)
        triangles = _triangles(rst, node_ids, path)
    except FieldError:
        raise
    except MemoryError:
        raise FieldError(f"ANSYS result file {path} is corrupt (a record size beyond memory); {_HELP}") from None
    except Exception as exc:  # the reader's own errors, whatever their class: one line at this boundary
        raise FieldError(f"ANSYS result file {path} could not be read ({_one_line(exc)}); {_HELP}") from None
    system, unit = UNIT_SYSTEMS.get(unit_code, (f"code {unit_code}", None))
    if unit_code not in UNIT_SYSTEMS:
        log.info("%s: unknown MAPDL unit system code %d: the length unit is not known", path, unit_code)
    log.info("%s: %d nodes, unit system %s (%s), result set %s of %d", path, len(node_ids), system,
             unit or "length unit not stated", name, len(available))
    return AnsysResult(node_ids, points, displacements, unit, name, available, triangles)


# --------------------------------------------------------------------------------------------------------
# The file's structure, checked before the compiled reader sees it
# --------------------------------------------------------------------------------------------------------
def _check_structure(path: str) -> int:
    """Check that ``path`` is a complete MAPDL binary result file; its ``/UNITS`` code.

    MAPDL binary files are Fortran-style records of 4-byte words: ``[n, flags, n data words, n]``.  The
    standard header is the first record (100 words; item 1 the file number, 12 for results; item 5 the
    units); the result header (at word 103) holds the record pointers (items 10-16) and the end of the
    data (item 10, ``ptrend``, in words).  A file shorter than its ``ptrend``, or a pointer or record
    beyond it, is truncated or corrupt.
    """
    try:
        size = os.path.getsize(path)
        with open(path, "rb") as f:
            head = f.read(1200 * 4)
    except OSError as exc:
        raise FieldError(f"ANSYS result file {path} cannot be read: {_one_line(exc)}") from None
    if size == 0:
        raise FieldError(f"ANSYS result file {path} is empty; {_HELP}")
    endian = next((e for e in "<>" if len(head) >= 4 and int(np.frombuffer(head[:4], e + "i4")[0]) == 100), None)
    if endian is None:
        raise FieldError(f"{path} is not an ANSYS binary result file (it does not start with MAPDL's 100-word "
                         f"file header); {_HELP}")
    words = np.frombuffer(head[: len(head) // 4 * 4], endian + "i4")
    n_words = size // 4
    if len(words) < 103 or words[102] != 100:
        raise FieldError(f"ANSYS result file {path} is truncated in its file header ({size} bytes); {_HELP}")
    file_number = int(words[2])
    if file_number != 12:
        kind = _FILE_KINDS.get(file_number, f"file number {file_number}")
        raise FieldError(f"{path} is an MAPDL {kind} file, not a result file (.rst); {_HELP}")
    if len(words) < 105 or not 0 < int(words[103]) <= 1000 or len(words) < 106 + int(words[103]):
        raise FieldError(f"ANSYS result file {path} is truncated in its result header ({size} bytes); {_HELP}")
    header = words[105:105 + int(words[103])]
    if len(header) < 24:
        raise FieldError(f"ANSYS result file {path} has a short result header ({len(header)} words); {_HELP}")
    end = int(header[9])
    if end <= 0:  # a file past 2**31 words keeps its end in items 23-24 (low, high)
        end = int(header[22]) + (int(header[23]) << 32) if header[23] >= 0 else -1
    if end <= 0:
        raise FieldError(f"ANSYS result file {path} has no valid end-of-data pointer; {_HELP}")
    if n_words < end:
        raise FieldError(f"ANSYS result file {path} is truncated: it has {size} bytes, its header says its data "
                         f"run to byte {4 * end}; {_HELP}")
    with open(path, "rb") as f:
        for item, what in ((10, "data set index"), (11, "time"), (12, "load step"), (13, "element"),
                           (14, "node"), (15, "geometry")):
            ptr = int(header[item])
            if not 0 < ptr < end:
                raise FieldError(f"ANSYS result file {path} is corrupt: its {what} table pointer ({ptr}) lies "
                                 f"outside its data (0..{end}); {_HELP}")
            f.seek(4 * ptr)
            first = np.frombuffer(f.read(8), endian + "i4")
            n = int(first[0]) if len(first) == 2 else -1
            if n < 0 or ptr + n + 3 > n_words:
                raise FieldError(f"ANSYS result file {path} is corrupt: its {what} table (word {ptr}) runs past "
                                 f"the end of the file; {_HELP}")
    code = int(header[19])
    if int(words[6]) != code:
        log.info("%s: the standard header says unit system %d, the result header %d: the result header's is "
                 "taken", path, int(words[6]), code)
    return code


def _open(mapdl_reader, path: str):
    """The reader's result object for ``path``; FieldError for files it should not be asked for."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rst = mapdl_reader.read_binary(path)
    kind = type(rst).__name__
    if "Cyclic" in kind or getattr(rst, "_is_cyclic", False):
        raise FieldError(f"ANSYS result file {path} is a cyclic-symmetry result (one sector of "
                         f"{getattr(rst, 'n_sector', '?')}); expand it to the whole part in MAPDL "
                         f"(/CYCEXPAND) and write the full model's result")
    if getattr(rst, "_is_thermal", False):
        raise FieldError(f"ANSYS result file {path} is a thermal result (temperatures, no displacements); "
                         f"give the structural .rst of the hot state")
    if not rst.available_results["NSL"]:
        raise FieldError(f"ANSYS result file {path} holds no nodal displacements; write them in MAPDL "
                         f"(OUTRES,NSOL) and give that .rst")
    if rst.nsets < 1:
        raise FieldError(f"ANSYS result file {path} holds no result set; {_HELP}")
    return rst


# --------------------------------------------------------------------------------------------------------
# The result set
# --------------------------------------------------------------------------------------------------------
def _choose(rst, path: str, field_name: str | None, step: int | None) -> tuple[int, str, tuple[str, ...]]:
    """(cumulative index, name for a log line, the ``LS,SUB`` names of all sets)."""
    nsets = int(rst.nsets)
    table = np.asarray(rst._resultheader["ls_table"], dtype=np.int64).reshape(-1, 3)[:nsets]
    times = np.asarray(rst.time_values, dtype=np.float64)[:nsets]
    available = tuple(f"{ls},{sub}" for ls, sub, _ in table)

    def listing() -> str:
        shown = [f"{a} (time {t:g})" for a, t in zip(available, times)]
        if len(shown) > 12:
            shown = shown[:8] + [f"... {len(shown) - 11} more ..."] + shown[-3:]
        return ", ".join(shown)

    if field_name is not None:
        text = str(field_name).strip()
        match = re.fullmatch(r"(\d+)\s*[,;\s]\s*(\d+)", text)
        if match:
            ls, sub = int(match.group(1)), int(match.group(2))
            hits = np.flatnonzero((table[:, 0] == ls) & (table[:, 1] == sub))
            if not len(hits):
                raise FieldError(f"ANSYS result file {path} has no result set {ls},{sub} (load step, substep); "
                                 f"its sets: {listing()}")
            index = int(hits[0])
        else:
            try:
                value = float(text.replace("d", "e").replace("D", "e"))
            except ValueError:
                raise FieldError(f"ANSYS result file {path}: result set {field_name!r} is neither LS,SUB (e.g. 1,2) "
                                 f"nor a time value; its sets: {listing()}") from None
            hits = np.flatnonzero(np.isclose(times, value, rtol=1e-6, atol=0.0) | (times == value))
            if not len(hits):
                raise FieldError(f"ANSYS result file {path} has no result set at time {value:g}; its sets: "
                                 f"{listing()}")
            if len(hits) > 1:
                raise FieldError(f"ANSYS result file {path}: time {value:g} is that of several result sets ("
                                 f"{', '.join(available[i] for i in hits)}); name one as LS,SUB")
            index = int(hits[0])
    elif step is not None:
        if not -nsets <= int(step) < nsets:
            raise FieldError(f"ANSYS result file {path} has {nsets} result set(s): step {step} is not among "
                             f"0..{nsets - 1} (or -{nsets}..-1 from the end)")
        index = int(step) % nsets
    else:
        index = nsets - 1
    ls, sub, _ = table[index]
    name = f"{index} (load step {ls}, substep {sub}, time {times[index]:g})"
    return index, name, available


# --------------------------------------------------------------------------------------------------------
# Nodes and displacements
# --------------------------------------------------------------------------------------------------------
def _nodal_displacements(rst, index: int, path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(node_ids (N,), points (N, 3), displacements (N, 3))`` of result set ``index``, nodes without a
    displacement dropped; displacements rotated to the global Cartesian system here, by the angles of
    each node matched by node number (the reader's own rotation indexes the angles by position, which is
    wrong when the set leaves nodes out)."""
    from ansys.mapdl.reader.common import rotate_to_global

    dofs = list(rst.result_dof(index))
    missing = [d for d in ("UX", "UY", "UZ") if d not in dofs]
    if missing:
        raise FieldError(f"ANSYS result file {path} has no {'/'.join(missing)} degree of freedom (its DOFs: "
                         f"{', '.join(dofs) or 'none'}); hot2cold needs a 3-D structural model")
    nnum, values = rst.nodal_displacement(index, in_nodal_coord_sys=True)
    nnum = np.asarray(nnum, dtype=np.int64)
    values = np.array(values, dtype=np.float64)
    if values.ndim != 2 or values.shape[0] != len(nnum) or values.shape[1] < len(dofs):
        raise FieldError(f"ANSYS result file {path}: the displacement record of set {index + 1} has shape "
                         f"{values.shape} for {len(nnum)} nodes and {len(dofs)} DOFs; {_HELP}")
    cols = [dofs.index(d) for d in ("UX", "UY", "UZ")]
    mesh = rst.mesh
    mesh_ids = np.asarray(mesh.nnum, dtype=np.int64)
    order = np.argsort(mesh_ids, kind="stable")
    pos = np.minimum(np.searchsorted(mesh_ids[order], nnum), max(len(mesh_ids) - 1, 0))
    if not len(mesh_ids) or np.any(mesh_ids[order][pos] != nnum):
        raise FieldError(f"ANSYS result file {path}: result nodes are missing from its geometry; {_HELP}")
    rows = order[pos]
    # rotate_to_global turns columns 0-2 (and 3-5 if present) by the nodes' ZXY Euler angles (degrees).
    vec = values[:, cols].copy()
    angles = np.asarray(mesh.node_angles, dtype=np.float64)[rows] if mesh.node_angles is not None else None
    have = ~np.isnan(vec).any(axis=1)
    if angles is not None and np.any(angles[have] != 0):
        turned = np.ascontiguousarray(vec[have])
        rotate_to_global(turned, np.ascontiguousarray(angles[have].T))
        vec[have] = turned
    points = np.asarray(mesh.nodes, dtype=np.float64)[rows, :3]
    if not have.any():
        raise FieldError(f"ANSYS result file {path}: no node has a displacement in set {index + 1}; "
                         f"{_HELP}")
    if not have.all():
        log.info("%s: %d of %d nodes have no displacement in this result set (no DOF there, e.g. nodes of no "
                 "element); dropped", path, int((~have).sum()), len(have))
    bad = ~np.isfinite(vec[have]).all(axis=1) | ~np.isfinite(points[have]).all(axis=1)
    if bad.any():
        raise FieldError(f"ANSYS result file {path}: {int(bad.sum())} node(s) have non-finite coordinates or "
                         f"displacements (first: node {int(nnum[have][bad][0])}); {_HELP}")
    return nnum[have], points[have], vec[have]


# --------------------------------------------------------------------------------------------------------
# Outer faces of the solid elements
# --------------------------------------------------------------------------------------------------------
#: VTK solid cell types: (linear type, its node count, faces as corner cycles in VTK order,
#: quadratic type or None, the quadratic cell's midside node of each corner edge).
_TET = ((0, 1, 3), (1, 2, 3), (2, 0, 3), (0, 2, 1))
_HEX = ((0, 4, 7, 3), (1, 2, 6, 5), (0, 1, 5, 4), (3, 7, 6, 2), (0, 3, 2, 1), (4, 5, 6, 7))
_WEDGE = ((0, 1, 2), (3, 5, 4), (0, 3, 4, 1), (1, 4, 5, 2), (2, 5, 3, 0))
_PYRAMID = ((0, 3, 2, 1), (0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4))
_SOLIDS = {
    10: (4, _TET, None), 24: (4, _TET, {(0, 1): 4, (1, 2): 5, (0, 2): 6, (0, 3): 7, (1, 3): 8, (2, 3): 9}),
    12: (8, _HEX, None),
    25: (8, _HEX, {(0, 1): 8, (1, 2): 9, (2, 3): 10, (0, 3): 11, (4, 5): 12, (5, 6): 13, (6, 7): 14, (4, 7): 15,
                   (0, 4): 16, (1, 5): 17, (2, 6): 18, (3, 7): 19}),
    13: (6, _WEDGE, None),
    26: (6, _WEDGE, {(0, 1): 6, (1, 2): 7, (0, 2): 8, (3, 4): 9, (4, 5): 10, (3, 5): 11, (0, 3): 12, (1, 4): 13,
                     (2, 5): 14}),
    14: (5, _PYRAMID, None),
    27: (5, _PYRAMID, {(0, 1): 5, (1, 2): 6, (2, 3): 7, (0, 3): 8, (0, 4): 9, (1, 4): 10, (2, 4): 11, (3, 4): 12}),
}


def _triangles(rst, node_ids: np.ndarray, path: str) -> np.ndarray | None:
    """The outer faces of the solid elements as triangles ``(T, 3)`` or ``(T, 6)``, rows of ``node_ids``
    ``(N,)`` (the kept nodes); None without solid elements (see the module docs)."""
    grid = getattr(rst, "quadgrid", None)
    if grid is None or not grid.n_cells:
        return None
    grid_ids = np.asarray(grid.point_data["ansys_node_num"], dtype=np.int64)
    points = np.asarray(grid.points, dtype=np.float64)
    celltypes = np.asarray(grid.celltypes)
    offsets = np.asarray(getattr(grid, "cell_offsets", None) if hasattr(grid, "cell_offsets") else grid.offset,
                         dtype=np.int64)
    conn = np.asarray(grid.cell_connectivity, dtype=np.int64)
    # Cells whose element lost midside nodes (MAPDL writes node 0 there; the reader points them at node 0).
    elems = getattr(rst.mesh, "elem", None)
    lost = np.zeros(len(celltypes), bool)
    if elems is not None and len(elems) == len(celltypes):
        lost = np.array([np.any(np.asarray(e[10:]) == 0) for e in elems], bool)
    others = sorted(set(distinct(celltypes).tolist()) - set(_SOLIDS))
    if others:
        log.info("%s: %d non-solid element(s) (VTK cell types %s: shells, beams, contact, ...) give no boundary "
                 "triangles", path, int(np.isin(celltypes, others).sum()), ", ".join(map(str, others)))
    faces3, faces4 = [], []                     # (corners, mids or -1, element centroid)
    for vtk_type, (ncorner, faces, mids) in _SOLIDS.items():
        cells = np.flatnonzero(celltypes == vtk_type)
        if not len(cells):
            continue
        nodes = conn[offsets[cells][:, None] + np.arange(ncorner + (len(mids) if mids else 0))]
        centroid = points[nodes[:, :ncorner]].mean(axis=1)
        for face in faces:
            corners = nodes[:, face]
            if mids:
                mid = nodes[:, [mids[tuple(sorted((face[i], face[(i + 1) % len(face)])))]
                                for i in range(len(face))]]
                mid[lost[cells]] = -1
            else:
                mid = np.full_like(corners, -1)
            (faces3 if len(face) == 3 else faces4).append((corners, mid, centroid))
    if not faces3 and not faces4:
        return None
    width = 4
    corners = np.concatenate([np.pad(c, ((0, 0), (0, width - c.shape[1])), constant_values=-1)
                              for c, _, _ in faces3 + faces4])
    mids = np.concatenate([np.pad(m, ((0, 0), (0, width - m.shape[1])), constant_values=-1)
                           for _, m, _ in faces3 + faces4])
    centroid = np.concatenate([c for _, _, c in faces3 + faces4])
    # A face is outer when no other face has its corner set (degenerate faces compared by their distinct corners).
    key = np.sort(corners, axis=1)
    key[:, 1:][key[:, 1:] == key[:, :-1]] = -1
    key = np.sort(key, axis=1)
    _, inverse, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    outer = count[inverse.ravel()] == 1
    corners, mids, centroid = corners[outer], mids[outer], centroid[outer]
    n_corner = (corners >= 0).sum(axis=1)
    # Turn each face to face out of its element: its normal (by the diagonals, for a quad) along centre - centroid.
    c = np.where(corners >= 0, corners, corners[:, :1])
    p = points[c]
    quad = n_corner == 4
    normal = np.where(quad[:, None], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1]),
                      np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]))
    centre = np.where(quad[:, None], p.mean(axis=1), p[:, :3].mean(axis=1))
    flip = np.einsum("ij,ij->i", normal, centre - centroid) < 0
    # reversing a cycle a b c (d) -> a (d) c b; its edge mids ab bc c(d)a -> a(d) ... : mids follow their edges
    for n, rev_c, rev_m in ((3, [0, 2, 1, 3], [2, 1, 0, 3]), (4, [0, 3, 2, 1], [3, 2, 1, 0])):
        sel = flip & (n_corner == n)
        corners[sel] = corners[sel][:, rev_c]
        mids[sel] = mids[sel][:, rev_m]
    tri = n_corner == 3
    full_mids = (mids >= 0).sum(axis=1) == n_corner
    if len(corners) and tri.all() and full_mids.all():
        out = np.column_stack([corners[:, :3], mids[:, :3]])                      # (T, 6) tri6
    else:
        pieces = []
        plain_tri, tri6 = tri & ~full_mids, tri & full_mids
        plain_quad, quad8 = quad & ~full_mids, quad & full_mids
        a, b, cc, d = corners.T
        ab, bc, cd, da = mids.T
        pieces.append(np.column_stack([a, b, cc])[plain_tri])
        for t in ((a, ab, cd), (ab, b, bc), (cd, bc, cc), (ab, bc, cd)):         # tri6: mids ab, bc, ca(=cd slot)
            pieces.append(np.column_stack(t)[tri6])
        for t in ((a, b, cc), (a, cc, d)):
            pieces.append(np.column_stack(t)[plain_quad])
        for t in ((a, ab, da), (ab, b, bc), (bc, cc, cd), (cd, d, da), (ab, bc, cd), (ab, cd, da)):
            pieces.append(np.column_stack(t)[quad8])
        out = np.concatenate(pieces) if pieces else np.zeros((0, 3), np.int64)
        out = out[(out[:, 0] != out[:, 1]) & (out[:, 1] != out[:, 2]) & (out[:, 0] != out[:, 2])]
    if not len(out):
        return None
    # grid point -> row of the kept nodes (by node number)
    pos = np.minimum(np.searchsorted(node_ids, grid_ids), max(len(node_ids) - 1, 0))
    row = np.where(node_ids[pos] == grid_ids, pos, -1)
    out = row[out]
    dropped = (out < 0).any(axis=1)
    if dropped.any():
        log.info("%s: %d boundary triangle(s) with a node that has no displacement left out", path,
                 int(dropped.sum()))
        out = out[~dropped]
    return out.astype(np.int64) if len(out) else None


def _one_line(exc: BaseException) -> str:
    """:func:`~hot2cold.errors.one_line`, cut to 200 characters (the reader's own messages can be long)."""
    text = one_line(exc)
    return text if len(text) <= 200 else text[:197] + "..."
