"""Nastran results: static displacements from an OP2 binary or a punch (``.pch``) file, grid positions from
a bulk data (``.bdf``) file.  Read natively with numpy and :mod:`struct`.

OP2 (:func:`read_op2`)
----------------------
The OP2 is a sequence of Fortran unformatted records, each ``[n bytes] payload [n bytes]`` (little-endian
int32 lengths; 64-bit and big-endian files are refused).  A 4-byte record holding one int is a *marker*.
The layout (pyNastran ``op2_reader.py``; MSC "DMAP Programmer's Guide", OUTPUT2)::

    file   = header table* 0
    header = 3 <date: 3 ints> 7 <"NASTRAN FORT TAPE ID CODE - "> 2 <label, 8 chars> [n <...>] -1 0
    table  = 2 <name, 8 chars> [6 <version: MSC 2016+>] -1 7 <trailer: 7 ints> -2
             (1 0 record -k)* 1 0 0        k = 3, 4, ...
    record = (n <4n bytes>)+          one logical record, split into several physical ones when long

Marker ``n > 0`` announces a physical record of ``n`` words; consecutive ones make one logical record.  A
table ends at ``-k 1 0 0``; the file at a ``0`` where the next table's ``2`` would be (a file without it
is taken as truncated).

*Displacements*: any table (``OUGV1``, ``OUG1``, ``BOUGV1`` ...) whose records come in pairs IDENT (146
words) + data.  IDENT words (1-based, MSC DMAP "OUG" datablock): 1 ``approach_code*10 + device_code``,
2 ``table_code + 1000*sort_code``, 4 subcase id, 5 load set (statics) or load factor (nonlinear statics,
float32), 9 format code (1 real), 10 ``num_wide``, 51-82 title, 83-114 subtitle, 115-146 label (ASCII).
Taken: table code 1 (displacement), sort code 0 (real, SORT1), format 1, ``num_wide`` 8, approach code 1
(statics) or 10 (nonlinear statics).  A data row is 8 words ``10*grid_id + device_code, point type
(1 grid, 2 scalar, ...), T1, T2, T3 (float32), R1, R2, R3``; only the grid points' T1-T3 are kept: the
scalar, extra and other points, which have no position, are left out with a warning naming their count and
kind (a set of such points only is refused).  Heat transfer tables (IDENT word 23, thermal flag, 1) hold
temperatures and are skipped.

*Result sets*: one per IDENT of such a table, named ``"subcase <id>"`` (with ``" load <factor>"`` for
nonlinear statics; with ``" (<table>)"`` when another table already gave that name).  ``field_name``
selects one by its name (any letter case) or by the subcase id alone (``"3"``: the last set of subcase
3); ``step`` counts the sets from 0 in file order (negative from the end); the last is the default.

*Positions*: the ``GRID`` records of ``GEOM1`` / ``GEOM1S`` (MSC "GEOM1" datablock; record key
``4501, 45, 1``: 8 words ``ID, CP, X1, X2, X3 (float32), CD, PS, SEID``; MSC 2020+ key ``4501, 45,
1120001``: 11 words with X1-X3 float64).  Positions are given in the grid's CP system and displacements in
its CD system (except in the ``B...`` tables, which are in the basic frame); both are taken to the basic
frame with the ``CORD2R`` / ``CORD2C`` / ``CORD2S`` records (keys ``2101, 21, 8`` / ``2001, 20, 9`` /
``2201, 22, 10``: 13 words ``CID, type, 2, RID, A1-A3, B1-B3, C1-C3``; A the origin, B on the z axis,
C in the xz plane, given in system RID).  A grid in any other system (``CORD1*``, ``CORD3G``) is refused.
Without ``GRID`` records :attr:`NastranResult.points` is ``None``: take the positions from the model's
``.bdf`` (:func:`read_bdf_grids`), which refuses grids in local systems since the displacements would be
in them too.  OP2 positions are float32 (6-7 significant digits) unless the OP2 holds float64 GRIDs.

Punch (:func:`read_punch`)
--------------------------
80-column text; each result block starts with ``$TITLE``, ``$SUBTITLE``, ``$LABEL`` lines, then the
result kind (``$DISPLACEMENTS``), the format (``$REAL OUTPUT``), ``$SUBCASE ID = n`` and, for other than
static results, a ``$TIME`` / ``$FREQUENCY`` / ``$EIGENVALUE`` line.  Each grid takes two lines:
``id  G  T1  T2  T3`` and ``-CONT-  R1  R2  R3`` (columns 73-80 hold a line number); scalar (``S``) and
extra (``E``) points are left out with a warning, as in the OP2.  Static real
displacement blocks are result sets named ``"subcase <id>"``, selected as for the OP2.  The punch holds no
positions, and its displacements are in the grids' CD systems: use :func:`read_bdf_grids`.

Every problem raises :class:`hot2cold.errors.FieldError` with a one-line message naming the file.
"""
from __future__ import annotations

import logging
import mmap
import os
import re
import struct
from dataclasses import dataclass, field

import numpy as np

from ..core.arrays import distinct
from ..errors import FieldError
from .inputs import check_input_file, read_input_bytes

__all__ = ["NastranResult", "read_op2", "read_punch", "read_bdf_grids"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class NastranResult:
    """One static displacement result set of a Nastran OP2 or punch file.

    Attributes
    ----------
    node_ids : numpy.ndarray
        (N,) int64 grid ids, in the file's order.
    displacements : numpy.ndarray
        (N, 3) float64 translations T1, T2, T3 in the basic frame (OP2 with geometry) or as the file holds
        them (in the grids' CD systems: punch, OP2 without geometry), in the model's length unit.
    points : numpy.ndarray or None
        (N, 3) float64 grid positions in the basic frame, or ``None`` when the file holds no geometry.
    name : str
        The result set taken (``"subcase 1"``), for a log line.
    available : tuple of str
        The names of all static displacement result sets in the file, in file order.
    """

    node_ids: np.ndarray
    displacements: np.ndarray
    points: np.ndarray | None
    name: str
    available: tuple[str, ...] = field(default_factory=tuple)


# --------------------------------------------------------------------------------------------------------
# Choosing a result set (OP2 and punch)
# --------------------------------------------------------------------------------------------------------
@dataclass
class _Set:
    name: str
    subcase: int
    ids: np.ndarray        # (N,) int64
    values: np.ndarray     # (N, 3) float64
    basic: bool = False    # displacements already in the basic frame (B... tables)
    left_out: str = ""     # the points of the table left out ("3 scalar points"), for a log line


def _pick(sets: list[_Set], path: str, field_name: str | None, step: int | None) -> _Set:
    names = ", ".join(s.name for s in sets)
    if field_name is not None and step is not None:
        raise FieldError(f"{path}: pass field_name or step, not both (result sets: {names})")
    if field_name is not None:
        key = str(field_name).strip().lower()
        for s in sets:
            if s.name.lower() == key:
                return s
        by_id = [s for s in sets if key.lstrip("-").isdigit() and s.subcase == int(key)]
        if by_id:
            return by_id[-1]
        raise FieldError(f"{path} has no result set {field_name!r}; it has: {names}")
    if step is None:
        return sets[-1]
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)):
        raise FieldError(f"{path}: step must be an integer (0 = the first result set, -1 the last), got {step!r}")
    if not -len(sets) <= step < len(sets):
        raise FieldError(f"{path} has {len(sets)} static displacement result set(s) ({names}), no step {step}")
    return sets[step]


def _result(sets: list[_Set], path: str, field_name, step) -> tuple[_Set, tuple[str, ...]]:
    chosen = _pick(sets, path, field_name, step)
    if chosen.left_out and not len(chosen.ids):
        raise FieldError(f"{path}: {chosen.name} holds the displacements of {chosen.left_out} only, no GRID; "
                         f"those points have no position: request the displacements of the grids")
    log.info("%s: took %s (%d grids) of %d result set(s)", path, chosen.name, len(chosen.ids), len(sets))
    if chosen.left_out:
        log.warning("%s: %s of %s left out (no position)", path, chosen.left_out, chosen.name)
    return chosen, tuple(s.name for s in sets)


def _frozen(a: np.ndarray | None) -> np.ndarray | None:
    if a is None:
        return None
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


# --------------------------------------------------------------------------------------------------------
# OP2: Fortran records and tables
# --------------------------------------------------------------------------------------------------------
_FORT_TAPE = b"NASTRAN FORT TAPE ID CODE - "
_GRID_KEYS = {(4501, 45, 1): np.dtype([("id", "<i4"), ("cp", "<i4"), ("x", "<f4", 3), ("cd", "<i4"),
                                       ("ps", "<i4"), ("seid", "<i4")]),
              (4501, 45, 1120001): np.dtype([("id", "<i4"), ("cp", "<i4"), ("x", "<f8", 3), ("cd", "<i4"),
                                             ("ps", "<i4"), ("seid", "<i4")])}
_GRID = np.dtype([("id", "<i8"), ("cp", "<i4"), ("x", "<f8", 3), ("cd", "<i4")])   # what _geometry keeps
# CORD2R/C/S, 13 words: CID, type (1 R, 2 C, 3 S), 2, RID, A, B, C (float32).
_CORD2_KEYS = {(2101, 21, 8): "R", (2001, 20, 9): "C", (2201, 22, 10): "S"}
_CORD2_DTYPE = np.dtype([("cid", "<i4"), ("type", "<i4"), ("two", "<i4"), ("rid", "<i4"), ("abc", "<f4", (3, 3))])
_OTHER_CORDS = {1701: "CORD1C", 1801: "CORD1R", 1901: "CORD1S", 14301: "CORD3G"}
_OTHER_SIZES = {1701: 24, 1801: 24, 1901: 24, 14301: 16}    # bytes per entry
_END_OF_RECORDS = (65535, 65535, 65535)
# One data row of a real SORT1 displacement table (num_wide 8).
_OUG_ROW = np.dtype([("device", "<i4"), ("kind", "<i4"), ("t", "<f4", 3), ("r", "<f4", 3)])
# OUG point types other than 1 (GRID); none has a position, so their rows are left out (and said).
_POINT_KINDS = {2: "scalar point(s)", 3: "extra point(s)", 4: "modal point(s)", 7: "ring/fluid point(s)"}
_OTHER_RESULTS = {7: "eigenvectors", 10: "velocities", 11: "accelerations"}   # OUG table codes
_APPROACH = {1: "statics", 2: "real eigenvalues", 3: "differential stiffness", 5: "frequency",
             6: "transient", 7: "pre-buckling", 8: "post-buckling", 9: "complex eigenvalues",
             10: "nonlinear statics", 11: "geometric nonlinear statics"}


class _Unreadable(FieldError):
    """A record of the OP2 that does not read as the table structure expects: ``what``, in ``table`` (None:
    outside a table), at byte ``at``."""

    def __init__(self, message: str, what: str, table: str | None, at: int):
        super().__init__(message)
        self.what, self.table, self.at = what, table, at


class _Op2:
    """A cursor over the Fortran records of an OP2 held in ``buf``; errors name ``path``, table and byte."""

    def __init__(self, buf, path: str):
        self.buf, self.path, self.pos, self.table = buf, path, 0, None

    def fail(self, what: str, at: int | None = None):
        at = self.pos if at is None else at
        where = f" in table {self.table}" if self.table else ""
        raise _Unreadable(f"{self.path} {what}{where} at byte {at}; write it again or pass the .op2 Nastran "
                          f"wrote (PARAM,POST,-1)", what, self.table, at)

    def record(self) -> bytes:
        """The payload of the next Fortran record."""
        start, size = self.pos, len(self.buf)
        if start + 4 > size:
            self.fail("is truncated")
        (n,) = struct.unpack_from("<i", self.buf, start)
        if n < 0 or start + 8 + n > size:
            self.fail("is truncated" if n >= 0 else "is not a valid OP2 (negative record length)", start)
        (n2,) = struct.unpack_from("<i", self.buf, start + 4 + n)
        if n2 != n:
            self.fail("is corrupt (record lengths disagree)", start)
        self.pos = start + 8 + n
        return self.buf[start + 4:start + 4 + n]

    def marker(self) -> int:
        at = self.pos
        payload = self.record()
        if len(payload) != 4:
            self.fail(f"is not a valid OP2 (a {len(payload)}-byte record where a marker belongs)", at)
        return struct.unpack("<i", payload)[0]

    def expect(self, *values: int):
        for v in values:
            at = self.pos
            if (m := self.marker()) != v:
                self.fail(f"is not a valid OP2 (marker {m} where {v} belongs)", at)

    def block(self, words: int) -> bytes:
        """The physical record announced by marker ``words``."""
        at = self.pos
        data = self.record()
        if len(data) != 4 * words:
            self.fail(f"is not a valid OP2 (a record of {len(data)} bytes announced as {4 * words})", at)
        return data

    def logical(self) -> tuple[bytes, int]:
        """Consecutive ``n <4n bytes>`` records joined, and the marker (<= 0) that ends them."""
        parts = []
        while (m := self.marker()) > 0:
            parts.append(self.block(m))
        return b"".join(parts), m


def _check_kind(buf, path: str):
    head = bytes(buf[:4])
    if head == struct.pack("<i", 8):
        raise FieldError(f"{path} is a 64-bit OP2, which this reader does not read; write it with 32-bit "
                         f"words (MSC: omit mode=i8) or export the displacements to a punch or text file")
    if head == struct.pack(">i", 4):
        raise FieldError(f"{path} is a big-endian OP2, which this reader does not read; write it on a "
                         f"little-endian machine or export the displacements to a punch or text file")
    if head != struct.pack("<i", 4):
        raise FieldError(f"{path} is not a Nastran OP2 file (it does not start with a Fortran record); pass "
                         f"the .op2 Nastran wrote (PARAM,POST,-1)")


def _header(op2: _Op2):
    """Skip the ``3 <date> 7 <FORT TAPE> 2 <label> ... -1 0`` header, if the file has one."""
    start = op2.pos
    if op2.marker() != 3:            # no header: the file starts with its first table (2 <name>)
        op2.pos = start
        return
    op2.block(3)
    op2.expect(7)
    if op2.block(7) != _FORT_TAPE:
        op2.fail("is not a Nastran OP2 file (no 'NASTRAN FORT TAPE ID CODE' header)", start)
    while (m := op2.marker()) > 0:
        op2.block(m)
    if m != -1:
        op2.fail(f"is not a valid OP2 (marker {m} ends the header)")
    op2.expect(0)


def _tables(op2: _Op2):
    """Yield ``(name, records, first)`` for each table: ``first`` is its first record after the table header
    (the IDENT of a result table).  The records (bytes) are kept for the geometry tables and for result tables
    whose first IDENT says displacement (table code 1); other tables yield no records."""
    last = None
    while True:
        op2.table = None
        if op2.pos == len(op2.buf):  # a file cut between two tables
            raise FieldError(f"{op2.path} is truncated after table {last} (no end-of-file marker) at byte "
                             f"{op2.pos}; write it again")
        m = op2.marker()
        if m == 0:
            return
        if m != 2:
            op2.fail(f"is not a valid OP2 (marker {m} where a table name belongs)")
        name = op2.block(2).decode("latin-1").strip()
        op2.table = name
        while (m := op2.marker()) > 0:   # MSC 2016+: 6 <version> after the name
            op2.block(m)
        if m != -1:
            op2.fail(f"is not a valid OP2 (marker {m} after the table name)")
        op2.expect(7)
        op2.block(7)                 # trailer
        op2.expect(-2)
        yield name, *_table_records(op2, keep_all=_is_geometry(name))
        last = name


def _table_records(op2: _Op2, keep_all: bool) -> tuple[list[bytes], bytes]:
    """The logical records of a table from its first ``1 0`` to its closing ``1 0 0``, and its second record."""
    records, first, keep, k = [], b"", True, -2
    while True:
        op2.expect(1, 0)
        data, m = op2.logical()
        if keep and data:
            records.append(data)
            if len(records) == 2 and not keep_all:
                first = records[1]
                keep = _is_displacement_ident(first)
                records = records if keep else []
        if m == 0:
            return records, first
        if m != k - 1:
            op2.fail(f"is not a valid OP2 (record marker {m} where {k - 1} belongs)")
        k = m


# --------------------------------------------------------------------------------------------------------
# OP2: displacement tables
# --------------------------------------------------------------------------------------------------------
def _is_geometry(name: str) -> bool:
    return name in ("GEOM1", "GEOM1S")


def _is_displacement_ident(rec: bytes) -> bool:
    return len(rec) == 146 * 4 and struct.unpack_from("<i", rec, 4)[0] % 1000 == 1


def _ident(rec: bytes) -> dict | None:
    """The IDENT words of a result table record, or None if ``rec`` is not an IDENT (146 words)."""
    if len(rec) != 146 * 4:
        return None
    w = np.frombuffer(rec, "<i4")
    return {"approach": int(w[0]) // 10, "table_code": int(w[1]) % 1000, "sort_code": int(w[1]) // 1000,
            "subcase": int(w[3]), "word5": rec[16:20], "format": int(w[8]), "num_wide": int(w[9]),
            "thermal": int(w[22])}


def _displacement_sets(name: str, records: list[bytes], path: str, skipped: list[str]) -> list[_Set]:
    """The static real SORT1 displacement result sets of the result table ``name``; others go to ``skipped``."""
    sets = []
    # records[0] is the table's own header (name + 5 words); then IDENT + data pairs.
    for ident_rec, data in zip(records[1::2], records[2::2]):
        ident = _ident(ident_rec)
        if ident is None or ident["table_code"] != 1:
            continue                 # not displacements (eigenvectors are table code 7, velocities 10 ...)
        approach = ident["approach"]
        what = f"{_APPROACH.get(approach, f'approach code {approach}')} displacements in {name}"
        if ident["thermal"] == 1:    # heat transfer: the table holds temperatures, not displacements
            skipped.append(f"temperatures in {name}")
            continue
        if approach not in (1, 10):
            skipped.append(what)
            continue
        if ident["sort_code"] != 0 or ident["format"] != 1 or ident["num_wide"] != 8:
            skipped.append(f"{what} (not real SORT1)")
            continue
        if len(data) % _OUG_ROW.itemsize:
            raise FieldError(f"{path}: the displacement table {name} of subcase {ident['subcase']} has "
                             f"{len(data)} bytes, not a whole number of rows; write the OP2 again")
        rows = np.frombuffer(data, _OUG_ROW)
        grid = rows["kind"] == 1     # point type 1 = GRID; scalar and extra points have no position
        label = f"subcase {ident['subcase']}"
        if approach == 10:
            label += f" load {struct.unpack('<f', ident['word5'])[0]:g}"
        kinds, counts = np.unique(rows["kind"][~grid], return_counts=True)
        left_out = ", ".join(f"{int(c)} {_POINT_KINDS.get(int(k), f'point(s) of type {int(k)}')}"
                             for k, c in zip(kinds, counts))
        sets.append(_Set(label, ident["subcase"], (rows["device"][grid] // 10).astype(np.int64),
                         rows["t"][grid].astype(np.float64), basic=name.startswith("B"), left_out=left_out))
    return sets


def _unique_names(sets: list[_Set], tables: list[str]) -> None:
    seen = set()
    for s, table in zip(sets, tables):
        if s.name.lower() in seen:
            s.name = f"{s.name} ({table})"
        seen.add(s.name.lower())


# --------------------------------------------------------------------------------------------------------
# OP2: geometry (GRID, CORD2*) and coordinate systems
# --------------------------------------------------------------------------------------------------------
@dataclass
class _Geometry:
    grids: np.ndarray           # structured, fields id, cp, x (3,), cd
    cords: dict                 # cid -> (kind "R"/"C"/"S", rid, abc (3, 3))
    other_cords: dict           # cid -> card name of a system this reader does not transform


def _geometry(records: list[bytes], path: str) -> _Geometry:
    grids, cords, other = [], {}, {}
    for rec in records[1:]:      # records[0] holds the table name
        if len(rec) < 12:
            continue
        key = struct.unpack_from("<3i", rec)
        body = rec[12:]
        if key == _END_OF_RECORDS:
            break
        if key in _GRID_KEYS:
            dtype = _GRID_KEYS[key]
            if len(body) % dtype.itemsize:
                raise FieldError(f"{path}: its GRID record has {len(body)} bytes, not whole GRIDs; write the OP2 again")
            g = np.frombuffer(body, dtype)
            out = np.empty(len(g), _GRID)
            for name in _GRID.names:
                out[name] = g[name]
            grids.append(out)
        elif key in _CORD2_KEYS:
            if len(body) % _CORD2_DTYPE.itemsize:
                raise FieldError(f"{path}: its {key} coordinate record is not whole CORD2 entries; write the OP2 again")
            for c in np.frombuffer(body, _CORD2_DTYPE):
                cords[int(c["cid"])] = (_CORD2_KEYS[key], int(c["rid"]), c["abc"].astype(np.float64))
        elif key[0] in _OTHER_SIZES:  # CORD1*: 6 words CID, type, 1, G1, G2, G3; CORD3G: 4 words CID, ...
            size = _OTHER_SIZES[key[0]]
            for cid in np.frombuffer(body[: len(body) - len(body) % size], "<i4")[:: size // 4]:
                other[int(cid)] = _OTHER_CORDS[key[0]]
    return _Geometry(np.concatenate(grids) if grids else np.empty(0, _GRID), cords, other)


def _axes(cords: dict, cid: int, path: str, grid: int, chain=()) -> tuple[str, np.ndarray, np.ndarray]:
    """System ``cid`` as (kind, origin (3,), rotation (3, 3) whose columns are its axes in the basic frame)."""
    if cid not in cords:
        raise FieldError(f"{path}: coordinate system {cid} (used by grid {grid} through system {chain[-1]}) has no "
                         f"CORD2R/C/S card in the OP2; define the systems with CORD2R/C/S cards")
    kind, rid, abc = cords[cid]
    if rid in chain:
        raise FieldError(f"{path}: coordinate systems {cid} and {rid} are defined in terms of each other")
    a, b, c = (_to_basic(cords, rid, row[None], path, grid, chain + (cid,))[0] for row in abc)
    z = b - a
    y = np.cross(z, c - a)
    if np.linalg.norm(z) == 0 or np.linalg.norm(y) == 0:
        raise FieldError(f"{path}: coordinate system {cid} (CORD2{kind}) has coincident or collinear points A, B, C")
    z, y = z / np.linalg.norm(z), y / np.linalg.norm(y)
    return kind, a, np.column_stack([np.cross(y, z), y, z])


def _check_system(cords: dict, other: dict, cid: int, path: str, grid: int):
    if cid != 0 and cid not in cords:
        card = other.get(cid)
        why = f"a {card} card, which this reader does not transform" if card else "no CORD2R/C/S card in the OP2"
        raise FieldError(f"{path}: grid {grid} uses coordinate system {cid}, defined by {why}; put the grids "
                         f"in CORD2R/C/S systems or request the displacements in the basic frame")


def _to_basic(cords: dict, cid: int, x: np.ndarray, path: str, grid: int, chain=()) -> np.ndarray:
    """Positions ``x (M, 3)`` given in system ``cid`` (r, theta, z or r, theta, phi in degrees) in the basic frame."""
    if cid == 0:
        return x
    kind, origin, rot = _axes(cords, cid, path, grid, chain)
    return origin + _cartesian(kind, x) @ rot.T


def _cartesian(kind: str, x: np.ndarray) -> np.ndarray:
    """Local rectangular coordinates (M, 3) of coordinates ``x (M, 3)`` of a system of ``kind``."""
    if kind == "R":
        return x
    r, t, third = x[:, 0], np.radians(x[:, 1]), x[:, 2]
    if kind == "C":
        return np.column_stack([r * np.cos(t), r * np.sin(t), third])
    p = np.radians(third)     # spherical: theta from the z axis, phi about it
    return np.column_stack([r * np.sin(t) * np.cos(p), r * np.sin(t) * np.sin(p), r * np.cos(t)])


def _local_axes(kind: str, local: np.ndarray) -> np.ndarray:
    """(M, 3, 3) unit vectors (columns) of the displacement components at local rectangular points (M, 3)."""
    m = len(local)
    if kind == "R":
        return np.broadcast_to(np.eye(3), (m, 3, 3))
    x, y, z = local.T
    # A grid on the system's axis (r = 0, to rounding of its position) has no direction of its own: take the
    # axes at theta (phi) = 0, the system's x axis, not an angle of the rounding noise of its local x, y.
    scale = np.maximum(np.abs(local).max(axis=1), 1.0)
    on_axis = np.hypot(x, y) <= 1e-9 * scale
    phi = np.where(on_axis, 0.0, np.arctan2(y, x))
    cp, sp, zero, one = np.cos(phi), np.sin(phi), np.zeros(m), np.ones(m)
    if kind == "C":           # e_r, e_theta, e_z
        return np.stack([np.column_stack([cp, sp, zero]), np.column_stack([-sp, cp, zero]),
                         np.column_stack([zero, zero, one])], axis=2)
    theta = np.arctan2(np.hypot(x, y), z)
    ct, st = np.cos(theta), np.sin(theta)      # e_r, e_theta, e_phi
    return np.stack([np.column_stack([st * cp, st * sp, ct]), np.column_stack([ct * cp, ct * sp, -st]),
                     np.column_stack([-sp, cp, zero])], axis=2)


def _grid_rows(geo: _Geometry, ids: np.ndarray, path: str) -> np.ndarray:
    """Rows of ``geo.grids`` of the grid ids ``ids (N,)``."""
    gids = geo.grids["id"].astype(np.int64)
    order = np.argsort(gids, kind="stable")
    pos = np.minimum(np.searchsorted(gids[order], ids), len(gids) - 1)
    missing = gids[order][pos] != ids
    if missing.any():
        raise FieldError(f"{path}: {int(missing.sum())} grid(s) with displacements (first: {int(ids[missing][0])}) "
                         f"have no GRID record in its geometry; pass the .op2 of the whole model")
    return order[pos]


def _positions_and_vectors(geo: _Geometry, chosen: _Set, path: str) -> tuple[np.ndarray, np.ndarray]:
    """Basic-frame positions (N, 3) and displacements (N, 3) of the chosen set's grids."""
    g = geo.grids[_grid_rows(geo, chosen.ids, path)]
    points = np.array(g["x"], dtype=np.float64)
    for cp in distinct(g["cp"]):
        sel = g["cp"] == cp
        _check_system(geo.cords, geo.other_cords, int(cp), path, int(g["id"][sel][0]))
        points[sel] = _to_basic(geo.cords, int(cp), points[sel], path, int(g["id"][sel][0]))
    vectors = chosen.values.copy()
    if chosen.basic:
        return points, vectors
    for cd in distinct(g["cd"]):
        sel = g["cd"] == cd
        first = int(g["id"][sel][0])
        if cd < 0:
            raise FieldError(f"{path}: grid {first} is a fluid grid (CD {int(cd)}); its displacements are not "
                             f"structural, leave fluid grids out of the displacement output")
        if cd == 0:
            continue
        _check_system(geo.cords, geo.other_cords, int(cd), path, first)
        kind, origin, rot = _axes(geo.cords, int(cd), path, first)
        axes = rot @ _local_axes(kind, (points[sel] - origin) @ rot)   # (M, 3, 3): basic <- component
        vectors[sel] = np.einsum("mij,mj->mi", axes, vectors[sel])
    return points, vectors


def read_op2(path: str, field_name: str | None = None, step: int | None = None) -> NastranResult:
    """Read one static displacement result set and the grid positions from a Nastran OP2 file.

    See the module docstring for the tables and records read.  ``field_name`` names the result set
    (``"subcase 2"`` or ``"2"``); ``step`` counts the sets from 0 (negative from the end); the last one by
    default.  Returns a :class:`NastranResult`: ``node_ids (N,)``, ``displacements (N, 3)`` and, when the
    OP2 holds ``GRID`` records, ``points (N, 3)``, both in the basic frame; ``points`` is ``None`` otherwise
    (then ``displacements`` are in the grids' CD systems, as written).
    """
    path = os.fspath(path)
    check_input_file(path, "Nastran OP2 file", FieldError)
    try:
        with open(path, "rb") as f:
            if os.fstat(f.fileno()).st_size == 0:
                raise FieldError(f"{path} is empty; write the OP2 again")
            with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as buf:
                return _read_op2(buf, path, field_name, step)
    except OSError as e:
        raise FieldError(f"cannot read {path}: {e.strerror or e}") from None


def _read_op2(buf, path: str, field_name, step) -> NastranResult:
    _check_kind(buf, path)
    op2 = _Op2(buf, path)
    _header(op2)
    sets, set_tables, skipped, geometry = [], [], [], []
    try:
        for name, records, first in _tables(op2):
            if _is_geometry(name):
                geometry.extend(records)
            elif not records and (ident := _ident(first)) and ident["table_code"] in _OTHER_RESULTS:
                skipped.append(f"{_OTHER_RESULTS[ident['table_code']]} in {name}")
            elif records:
                found = _displacement_sets(name, records, path, skipped)
                sets += found
                set_tables += [name] * len(found)
    except _Unreadable as exc:
        if exc.table is None or sets or not exc.what.startswith("is not a valid OP2"):    # cut short, corrupt
            raise
        # A table of another structure (a matrix written by OUTPUT2, ...) with nothing to take before it:
        # what the file lacks is the displacements, not a well-formed table
        other = f"; before it, it holds {', '.join(dict.fromkeys(skipped))}" if skipped else ""
        reason = exc.what.removeprefix("is not a valid OP2 (").removesuffix(")")
        raise FieldError(f"{path} holds no static real SORT1 displacements before table {exc.table}, which this "
                         f"reader cannot read past (a matrix or another table of its own structure: {reason} at "
                         f"byte {exc.at}){other}; request DISPLACEMENT(PLOT)=ALL in a static subcase (SOL 101 or "
                         f"106) with PARAM,POST,-1") from None
    if not sets:
        other = f"; it holds {', '.join(dict.fromkeys(skipped))}" if skipped else ""
        raise FieldError(f"{path} holds no static real SORT1 displacements{other}; request "
                         f"DISPLACEMENT(PLOT)=ALL in a static subcase (SOL 101 or 106) with PARAM,POST,-1")
    _unique_names(sets, set_tables)
    chosen, available = _result(sets, path, field_name, step)
    geo = _geometry(geometry, path) if geometry else None
    if geo is not None and len(geo.grids):
        points, vectors = _positions_and_vectors(geo, chosen, path)
    else:
        points, vectors = None, chosen.values
        log.info("%s holds no GRID records: take the positions from the model's .bdf", path)
    _check_finite(path, chosen, vectors, points)
    return NastranResult(_frozen(chosen.ids), _frozen(vectors), _frozen(points), chosen.name, available)


def _check_finite(path: str, chosen: _Set, vectors: np.ndarray, points: np.ndarray | None):
    for what, a in (("displacement", vectors), ("position", points)):
        if a is not None and not np.isfinite(a).all():
            bad = int(chosen.ids[~np.isfinite(a).all(axis=1)][0])
            raise FieldError(f"{path}: grid {bad} has a non-finite {what} in {chosen.name}; the file is corrupt "
                             f"or the solution diverged")


# --------------------------------------------------------------------------------------------------------
# Punch
# --------------------------------------------------------------------------------------------------------
_PUNCH_NOT_STATIC = ("$TIME", "$FREQUENCY", "$EIGENVALUE", "$LOAD FACTOR", "$POINT ID", "$ELEMENT ID")


@dataclass
class _PunchBlock:
    kind: str = ""
    output: str = ""
    subcase: int | None = None
    static: bool = True
    rows: list = field(default_factory=list)   # (line number, text)


def _punch_blocks(lines: list[str], path: str) -> list[_PunchBlock]:
    blocks, block = [], _PunchBlock()
    for number, raw in enumerate(lines, 1):
        line = raw[:72].rstrip()
        if not line.strip():
            continue
        if line.startswith("$"):
            head = line.upper()
            if head.startswith("$TITLE") and (block.rows or block.kind):
                blocks.append(block)
                block = _PunchBlock()
            elif head.startswith("$SUBCASE ID"):
                value = head.partition("=")[2].split()
                if not value or not value[0].lstrip("-").isdigit():
                    raise FieldError(f"{path} line {number}: unreadable subcase id {line.strip()!r}; "
                                     f"write the punch file again")
                block.subcase = int(value[0])
            elif head.startswith("$") and "OUTPUT" in head:
                block.output = head[1:].strip()
            elif head.startswith(_PUNCH_NOT_STATIC):
                block.static = False
            elif not head.startswith(("$TITLE", "$SUBTITLE", "$LABEL")) and not block.kind and not block.rows:
                block.kind = head[1:].strip()
            continue
        block.rows.append((number, line))
    if block.rows or block.kind:
        blocks.append(block)
    return blocks


_PUNCH_POINT_KINDS = {"S": "scalar point(s)", "E": "extra point(s)", "M": "modal point(s)"}


def _punch_displacements(block: _PunchBlock, path: str) -> tuple[np.ndarray, np.ndarray, str]:
    """Grid ids (N,) and T1-T3 (N, 3) of a real displacement block (rows ``id G T1 T2 T3`` + ``-CONT-``), and
    the points left out ("3 scalar point(s)")."""
    ids, values, others = [], [], {}
    for number, line in block.rows:
        fields = line.split()
        if fields[0] == "-CONT-":
            continue
        if len(fields) != 5 or not fields[0].isdigit():
            raise FieldError(f"{path} line {number}: expected 'grid-id type T1 T2 T3', got {line.strip()!r}; "
                             f"pass a punch file of real SORT1 displacements")
        if fields[1] != "G":         # scalar (S) and extra (E) points have no position
            others[fields[1]] = others.get(fields[1], 0) + 1
            continue
        try:
            values.append([float(v) for v in fields[2:]])
        except ValueError:
            raise FieldError(f"{path} line {number}: unreadable number in {line.strip()!r}; "
                             f"write the punch file again") from None
        ids.append(int(fields[0]))
    left_out = ", ".join(f"{n} {_PUNCH_POINT_KINDS.get(k, f'point(s) of type {k}')}" for k, n in others.items())
    return np.array(ids, dtype=np.int64), np.array(values, dtype=np.float64).reshape(-1, 3), left_out


def read_punch(path: str, field_name: str | None = None, step: int | None = None) -> NastranResult:
    """Read one static real displacement result set from a Nastran punch (``.pch``) file.

    ``field_name`` (``"subcase 2"`` or ``"2"``) and ``step`` select as in :func:`read_op2`.  Returns a
    :class:`NastranResult` with ``node_ids (N,)``, ``displacements (N, 3)`` (T1-T3 in the grids' CD
    systems) and ``points`` ``None``: a punch file has no positions (see :func:`read_bdf_grids`).
    """
    path = os.fspath(path)
    raw = read_input_bytes(path, "Nastran punch file", FieldError)
    if not raw.strip():
        raise FieldError(f"{path} is empty; write the punch file again")
    if b"\0" in raw[:4096]:
        raise FieldError(f"{path} is a binary file, not a Nastran punch file; pass the .pch (text) or read the "
                         f".op2 with read_op2")
    blocks = _punch_blocks(raw.decode("latin-1").splitlines(), path)
    sets, skipped = [], []
    for b in blocks:
        if not b.kind.startswith("DISPLACEMENT"):
            continue
        if not (b.static and b.output == "REAL OUTPUT" and b.subcase is not None):
            skipped.append(f"{b.output.lower() or 'unlabelled'} {'static' if b.static else 'non-static'} "
                           f"displacements")
            continue
        ids, values, left_out = _punch_displacements(b, path)
        if len(ids) or left_out:
            sets.append(_Set(f"subcase {b.subcase}", b.subcase, ids, values, left_out=left_out))
    if not sets:
        what = f"; it holds {', '.join(dict.fromkeys(skipped))}" if skipped else ""
        raise FieldError(f"{path} holds no static real displacements ($DISPLACEMENTS, $REAL OUTPUT){what}; "
                         f"request DISPLACEMENT(PUNCH)=ALL in a static subcase")
    _merge_repeated_subcases(sets)
    chosen, available = _result(sets, path, field_name, step)
    _check_finite(path, chosen, chosen.values, None)
    return NastranResult(_frozen(chosen.ids), _frozen(chosen.values), None, chosen.name, available)


def _merge_repeated_subcases(sets: list[_Set]) -> None:
    """Blocks of one subcase that follow each other (a long block cut by new headers) become one set."""
    i = 1
    while i < len(sets):
        if sets[i].name == sets[i - 1].name:
            a, b = sets[i - 1], sets.pop(i)
            a.ids, a.values = np.concatenate([a.ids, b.ids]), np.concatenate([a.values, b.values])
            a.left_out = ", ".join(x for x in (a.left_out, b.left_out) if x)
        else:
            i += 1


# --------------------------------------------------------------------------------------------------------
# Bulk data: GRID positions
# --------------------------------------------------------------------------------------------------------
_NASTRAN_EXPONENT = re.compile(r"^([+-]?(?:\d+\.?\d*|\.\d+))([+-]\d+)$")   # 1.5-3 = 1.5E-3


def _bdf_real(text: str, where: str) -> float:
    s = text.strip().upper().replace("D", "E")
    if not s:
        return 0.0
    s = _NASTRAN_EXPONENT.sub(r"\1E\2", s)
    try:
        return float(s)
    except ValueError:
        raise FieldError(f"{where}: {text.strip()!r} is not a number; fix the GRID card") from None


def _bdf_int(text: str, where: str) -> int:
    s = text.strip()
    if not s:
        return 0
    if not s.lstrip("+-").isdigit():
        raise FieldError(f"{where}: {s!r} is not an integer; fix the GRID card")
    return int(s)


def _fields(line: str, large: bool) -> list[str]:
    """Fields 2-5 (large) or 2-9 (small) of a bulk data line; free field when it holds a comma."""
    if "," in line:
        return [f.strip() for f in line.split(",")[1:]]
    line = line.expandtabs(8)
    width, count = (16, 4) if large else (8, 8)
    return [line[8 + i * width:8 + (i + 1) * width] for i in range(count)]


def _bulk_lines(path: str, seen: tuple = ()) -> list[tuple[str, str]]:
    """(where, text) of the bulk data lines of ``path`` and its INCLUDE files, comments removed."""
    lines = read_input_bytes(path, "Nastran bulk data file", FieldError).decode("latin-1").splitlines()
    bulk = [i for i, v in enumerate(lines) if v.upper().startswith("BEGIN BULK")] if not seen else []
    start = bulk[0] + 1 if bulk else 0
    out = []
    for number, line in enumerate(lines[start:], start + 1):
        text = line.partition("$")[0].rstrip()
        if not text.strip():
            continue
        head = text.upper()
        if head.startswith("ENDDATA"):
            break
        if head.startswith("INCLUDE"):
            name = text[7:].strip().strip("'\"")
            target = os.path.join(os.path.dirname(path), name)
            if target in seen:
                raise FieldError(f"{path} line {number}: INCLUDE {name!r} includes itself")
            out += _bulk_lines(target, seen + (path,))
            continue
        out.append((f"{path} line {number}", text))
    return out


def read_bdf_grids(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Grid ids ``(N,) int64`` and positions ``(N, 3) float64`` from the GRID cards of a Nastran bulk data file.

    Small field (8 columns), large field (``GRID*`` with its ``*`` continuation line) and free field (commas)
    cards are read, in the bulk data section (after ``BEGIN BULK`` if the file has one, to ``ENDDATA``) and
    in files pulled in by ``INCLUDE`` (one line, path relative to the including file).  Grids whose CP or CD
    is not 0 (or a ``GRDSET`` that sets them) are refused: their positions, and the displacements a solver
    writes for them, are in local coordinate systems.
    """
    path = os.fspath(path)
    lines = _bulk_lines(path)
    ids, points = [], []
    i = 0
    while i < len(lines):
        where, text = lines[i]
        head = text.expandtabs(8)[:8].split(",")[0].strip().upper()
        i += 1
        if head == "GRDSET":
            f = _fields(text, False) + [""] * 8
            if _bdf_int(f[1], where) or _bdf_int(f[5], where):
                raise FieldError(f"{where}: GRDSET sets a local coordinate system (CP or CD); this reader takes "
                                 f"grids in the basic frame only")
            continue
        if head not in ("GRID", "GRID*"):
            continue
        f = _fields(text, head == "GRID*")
        if head == "GRID*":
            if i == len(lines):
                raise FieldError(f"{where}: GRID* card without its continuation line; complete the card")
            f = f[:4] + _fields(lines[i][1], True)
            i += 1
        f += [""] * (6 - len(f))
        gid, cp, cd = _bdf_int(f[0], where), _bdf_int(f[1], where), _bdf_int(f[5], where)
        if cp or cd:
            raise FieldError(f"{where}: grid {gid} has CP {cp} and CD {cd}; this reader takes grids in the "
                             f"basic frame only (read the .op2 with its geometry, which transforms them)")
        ids.append(gid)
        points.append([_bdf_real(v, where) for v in f[2:5]])
    if not ids:
        raise FieldError(f"{path} holds no GRID cards; pass the bulk data file of the model")
    ids_a = np.array(ids, dtype=np.int64)
    uniq, counts = np.unique(ids_a, return_counts=True)
    if (counts > 1).any():
        raise FieldError(f"{path}: grid {int(uniq[counts > 1][0])} is defined more than once; fix the bulk data")
    return ids_a, np.array(points, dtype=np.float64)
