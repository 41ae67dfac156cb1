"""A reader of CalculiX ``.frd`` result files (ASCII), for the displacement field.

The ``.frd`` format is fixed-column Fortran output (CalculiX/cgx manual, "Result Format"):

* ``    2C`` opens the node block; records ``(1X,'-1',I5,3E12.5)`` (short format, indicator 0) or
  ``(1X,'-1',I10,3E12.5)`` (long format, indicator 1; what ccx writes), then `` -3``.
* ``    3C`` opens the element block: a header record with the element count in columns 25-36 and the
  format indicator in 74-75, then per element a record ``(1X,'-1',I5,3I5)`` (short) or
  ``(1X,'-1',I10,3I5)`` (long: element number, type, group, material) followed by its node numbers in
  `` -2`` records ``(1X,'-2',15I5)`` or ``(1X,'-2',10I10)`` (as many records as the nodes need), then
  `` -3``.  Kept: the tetrahedra (type 3, te4 = C3D4; type 6, te10 = C3D10, nodes in the VTK order) and the
  shell triangles (type 7, tr3; type 8, tr6) as :attr:`FrdFile.elements`; the boundary triangles of the
  tetrahedra (of the triangles when there are none) become :attr:`FrdResult.triangles`.
* ``  100C`` opens a nodal result block: a header record with the step number in columns 59-63 and the
  format indicator in 74-75, `` -4  DISP`` (dataset name, number of components), one `` -5`` record per
  component (those flagged "to be calculated", such as DISP's ``ALL``, hold no data), then the values:
  `` -1`` + node number + up to 6 ``E12.5`` fields (`` -2`` continuation records for more), `` -3``.
* `` 9999`` ends the file.

Numbers are read by column, never split on blanks: a negative value fills its 12 columns and touches the
one before it (``-1.23456E-01-2.34567E-01``).  Coordinates and values carry 6 significant digits; take
node coordinates from the mesh when it is at hand (``read_field(..., points_from=mesh)``).

A file whose heading (first ``1U`` record) starts with :data:`HOT_TO_COLD_HEADING` comes from a hot2cold
hot-to-cold deck; for a rotating part its displacement is the difference of its two ``DISP`` blocks
(:meth:`FrdFile.hot_to_cold`, see :mod:`hot2cold.fe.calculix`), and ``read_field`` takes it that way.

Binary ``.frd`` files (format indicators 2 and 3) are not read; ccx writes ASCII unless told otherwise.
Every problem raises :class:`hot2cold.errors.FieldError` with a one-line message.
"""
from __future__ import annotations

import logging
import operator
import os
import re
from dataclasses import dataclass, replace

import numpy as np

from ..core.arrays import distinct
from ..errors import FieldError
from .cells import element_triangles
from .inputs import read_input_bytes

__all__ = ["FrdFile", "FrdResult", "parse_frd", "read_frd", "HOT_TO_COLD_HEADING", "ELEMENT_NODES",
           "ELEMENT_TYPES"]

log = logging.getLogger(__name__)

#: How the *HEADING of a hot2cold hot-to-cold deck starts (ccx copies it into the first ``1U`` record).
HOT_TO_COLD_HEADING = "hot2cold hot-to-cold"

_WIDTH = {0: 5, 1: 10}        # node-number field width by format indicator
_FIELD = 12                   # E12.5
_PER_LINE = 6                 # values per record

#: Node count of the ``.frd`` element types (cgx manual, "Element Types"), by type number.
ELEMENT_NODES = {1: 8, 2: 6, 3: 4, 4: 20, 5: 15, 6: 10, 7: 3, 8: 6, 9: 4, 10: 8, 11: 2, 12: 3}

#: The element types :attr:`FrdFile.elements` keeps, by type number, with their meshio names.
ELEMENT_TYPES = {3: "tetra", 6: "tetra10", 7: "triangle", 8: "triangle6"}

_TYPE_NAMES = {1: "he8", 2: "pe6", 3: "te4", 4: "he20", 5: "pe15", 6: "te10", 7: "tr3", 8: "tr6", 9: "qu4",
               10: "qu8", 11: "be2", 12: "be3"}
_ELEMENT_RECORD = 15          # type, group, material: 3 I5 after the element number


@dataclass(frozen=True, eq=False)
class FrdResult:
    """One nodal result block of an ``.frd`` file, with the coordinates of its nodes.

    Attributes
    ----------
    node_ids : numpy.ndarray, (N,) int64 node numbers, in the block's order.
    points : numpy.ndarray, (N, 3) their coordinates from the node block (6 significant digits).
    values : numpy.ndarray, (N, k) the stored components (k = 3 for DISP: D1, D2, D3).
    name : str, the dataset name (``DISP``).
    components : tuple of str, the names of the stored components.
    step : int, the step number of the block's header (CalculiX counts steps from 1).
    value : float, the header's value (step time, frequency).
    index : int, 0-based position of this block among the file's blocks of the same name.
    count : int, how many blocks of that name the file holds.
    triangles : numpy.ndarray or None, (T, 3) or (T, 6) int64 rows of ``node_ids``: the boundary triangles
        of the file's elements (:attr:`FrdFile.elements`; those naming a node without a result dropped),
        or ``None`` when the file has no tetrahedra or triangles.
    minus : FrdResult or None, the block subtracted from this one (a hot2cold deck of a rotating part:
        :meth:`FrdFile.hot_to_cold`), else None.
    """

    node_ids: np.ndarray
    points: np.ndarray
    values: np.ndarray
    name: str
    components: tuple
    step: int
    value: float
    index: int
    count: int
    triangles: np.ndarray | None = None
    minus: FrdResult | None = None

    @property
    def label(self) -> str:
        """The block as CalculiX's post-processor CGX lists it, for the report: ``"DISP block 2 of 3: step 2,
        time 1"`` (the block's place among those of its name, its header's step and value), or the
        difference of two blocks."""
        own = f"{self.name} block {self.index + 1} of {self.count}: step {self.step}, time {self.value:g}"
        if self.minus is None:
            return own
        return f"{own}, minus block {self.minus.index + 1} (step {self.minus.step}, time {self.minus.value:g})"


@dataclass
class _Block:
    kind: str                 # "nodes", "elements" or "results"
    start: int                # index of the first data line
    end: int                  # index of the closing " -3" line
    fmt: int
    header: int               # index of the header line
    name: str = ""
    ncomp: int = 3            # stored values per node
    components: tuple = ()
    step: int = 0
    value: float = float("nan")
    numnod: int | None = None  # the header's node (element) count


def _int(text: str) -> int | None:
    try:
        return int(text)
    except ValueError:
        return None


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return float("nan")


def _format(line: str, lineno: int, path: str, data_line: str | None, elements: bool = False) -> int:
    """Format indicator of a block header (columns 74-75); inferred from the first data line if blank (its
    length: the number field, then values of 12 columns, or an element record's 3 fields of 5)."""
    fmt = _int(line[73:75].strip()) if len(line) > 73 else None
    if fmt is None and data_line is not None and data_line.startswith(" -1"):
        rest = len(data_line.rstrip()) - 3
        if elements:
            fmt = {_WIDTH[f] + _ELEMENT_RECORD: f for f in _WIDTH}.get(rest)
        else:
            fmt = 1 if rest % _FIELD == 10 else 0 if rest % _FIELD == 5 else None
    if fmt in (2, 3):
        raise FieldError(
            f"results file {path} is a binary .frd (format indicator {fmt} on line {lineno + 1}); hot2cold "
            f"reads ASCII .frd files: run ccx without binary output")
    if fmt not in _WIDTH:
        raise FieldError(
            f"results file {path} line {lineno + 1}: unknown .frd format indicator "
            f"{line[73:75].strip()!r} (expected 0 short or 1 long); is this a CalculiX .frd file?")
    return fmt


def _block_end(lines: list[str], start: int, keys: tuple[str, ...], path: str, what: str, head: int) -> int:
    """Index of the `` -3`` line closing the block whose data start at ``start``."""
    n = len(lines)
    i = start
    while i < n:
        key = lines[i][:3]
        if key == " -3":
            return i
        if key not in keys:
            raise FieldError(
                f"results file {path} line {i + 1}: {what} starting on line {head + 1} has an unexpected "
                f"record {lines[i][:20].rstrip()!r} (expected {' or '.join(repr(k) for k in keys)} or ' -3'); "
                f"the file is malformed")
        i += 1
    raise FieldError(
        f"results file {path} ends inside the {what} starting on line {head + 1} (no ' -3' end record): "
        f"the file is truncated (did ccx finish?)")


def _scan(lines: list[str], path: str) -> tuple[list[_Block], list[_Block], list[_Block], str]:
    """Node blocks, element blocks, result blocks (in file order) and the heading of the file; checks the
    block structure."""
    nodes, elements, results = [], [], []
    heading = None
    n = len(lines)
    i = 0
    ended = False
    while i < n:
        line = lines[i]
        head = line[:6]
        if head == "    2C":
            fmt = _format(line, i, path, lines[i + 1] if i + 1 < n else None)
            end = _block_end(lines, i + 1, (" -1",), path, "node block", i)
            nodes.append(_Block("nodes", i + 1, end, fmt, i, numnod=_int(line[24:36].strip())))
            i = end + 1
        elif head == "    3C":
            first = lines[i + 1] if i + 1 < n else None
            if first is not None and first.startswith(" -3") and _int(line[73:75].strip()) not in (2, 3):
                fmt = 1  # no element: nothing to read in either format
            else:
                fmt = _format(line, i, path, first, elements=True)
            end = _block_end(lines, i + 1, (" -1", " -2"), path, "element block", i)
            elements.append(_Block("elements", i + 1, end, fmt, i, numnod=_int(line[24:36].strip())))
            i = end + 1
        elif head == "  100C":
            i = _result_block(lines, i, path, results)
        elif line.strip() == "9999":
            ended = True
            break
        else:
            if heading is None and head == "    1U":
                heading = line[6:].strip()  # the first user record: the deck's *HEADING
            i += 1
    if not ended:
        raise FieldError(
            f"results file {path} has no ' 9999' end record after line {n}: the file is truncated "
            f"(did ccx finish?)")
    return nodes, elements, results, heading or ""


def _result_block(lines: list[str], i: int, path: str, results: list[_Block]) -> int:
    """Scan the result block whose ``100C`` header is line ``i``; returns the index after it."""
    n = len(lines)
    header = lines[i]
    j = i + 1
    if j >= n or not lines[j].startswith(" -4"):
        raise FieldError(
            f"results file {path} line {j + 1}: a ' -4' dataset record must follow the result header on "
            f"line {i + 1}" + ("; the file is truncated" if j >= n else ""))
    rec = lines[j]
    name = rec[5:13].strip()
    ncomps = _int(rec[13:18].strip())
    if not name or ncomps is None or ncomps < 1:
        raise FieldError(f"results file {path} line {j + 1}: malformed dataset record {rec.rstrip()!r}")
    components = []
    for k in range(ncomps):
        j += 1
        if j >= n or not lines[j].startswith(" -5"):
            raise FieldError(
                f"results file {path} line {j + 1}: dataset {name} on line {i + 2} announces {ncomps} "
                f"components but has {k} ' -5' records" + ("; the file is truncated" if j >= n else ""))
        comp = lines[j]
        exist = _int(comp[33:38].strip()) if len(comp) > 33 else 0
        if exist != 1:  # 1: "to be calculated" (e.g. DISP's ALL), no data in the file
            components.append(comp[5:13].strip())
    j += 1
    fmt = _format(header, i, path, lines[j] if j < n else None)
    end = _block_end(lines, j, (" -1", " -2"), path, f"result block {name}", i)
    results.append(_Block("results", j, end, fmt, i, name=name, ncomp=len(components),
                          components=tuple(components), step=_int(header[58:63].strip()) or 0,
                          value=_float(header[12:24]), numnod=_int(header[24:36].strip())))
    return end + 1


def _parse_rows(lines: list[str], block: _Block, nvals: int, path: str, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Node numbers ``(n,)`` and the first ``nvals`` values ``(n, nvals)`` of a block's `` -1`` records."""
    if block.kind == "results" and block.ncomp > _PER_LINE:  # continuation records " -2" in between
        index = [k for k in range(block.start, block.end) if lines[k].startswith(" -1")]
    else:
        index = range(block.start, block.end)
    rows = [lines[k] for k in index]
    if block.numnod is not None and block.numnod > 0 and block.numnod != len(rows):
        raise FieldError(
            f"results file {path}: the {what} starting on line {block.header + 1} announces {block.numnod} "
            f"nodes but holds {len(rows)}; the file is malformed or truncated")
    if not rows:
        return np.zeros(0, dtype=np.int64), np.zeros((0, nvals))
    s0 = 3 + _WIDTH[block.fmt]
    cols = [(s0 + _FIELD * c, s0 + _FIELD * (c + 1)) for c in range(nvals)]
    try:
        # A record cut inside its last field would still parse (as a shorter number): check lengths first.
        if min(map(len, rows)) < cols[-1][1]:
            raise ValueError("record cut short")
        ids = np.array([r[3:s0] for r in rows]).astype(np.float64)
        vals = np.array([r[a:b] for r in rows for a, b in cols]).astype(np.float64).reshape(len(rows), nvals)
        if not np.all(ids == np.round(ids)):
            raise ValueError("node number not an integer")
    except ValueError:
        _locate_bad(rows, list(index), s0, cols, path, what)
        raise  # not reached: _locate_bad raises
    return ids.astype(np.int64), vals


def _locate_bad(rows: list[str], index: list[int], s0: int, cols, path: str, what: str) -> None:
    """Raise a FieldError naming the first record that does not parse."""
    for r, k in zip(rows, index):
        try:
            node = float(r[3:s0])
            if node != round(node):
                raise ValueError(r[3:s0])
        except ValueError:
            raise FieldError(
                f"results file {path} line {k + 1}: no node number in columns 4-{s0} of the {what} "
                f"({r[:s0 + _FIELD].rstrip()!r}); the file is malformed") from None
        for a, b in cols:
            text = r[a:b]
            try:
                if len(r) < b:
                    raise ValueError(text)
                float(text)
            except ValueError:
                if len(r) < b:
                    raise FieldError(
                        f"results file {path} line {k + 1}: the record of node {int(node)} in the {what} is "
                        f"cut short ({len(r)} columns, needs {b}); the file is truncated or "
                        f"malformed") from None
                raise FieldError(
                    f"results file {path} line {k + 1}, columns {a + 1}-{b}: {text.strip()!r} is not a "
                    f"number (node {int(node)}, {what})") from None
    raise FieldError(f"results file {path}: the {what} does not parse")  # pragma: no cover


def _parse_elements(lines: list[str], block: _Block, path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The elements of an element block: their types ``(M,)``, the index of each one's first node number
    ``(M,)`` in the node numbers ``(K,)`` of all of them (in file order), all as int64.  Checks every record:
    a malformed or cut one, or an element with another number of nodes than its type has, raises FieldError
    naming its line."""
    w = _WIDTH[block.fmt]
    what = f"the element block starting on line {block.header + 1}"
    body = lines[block.start:block.end]
    keys = np.array([ln[:3] for ln in body], dtype="U3")
    heads = np.flatnonzero(keys == " -1")
    if len(body) and keys[0] != " -1":
        raise FieldError(
            f"results file {path} line {block.start + 1}: a ' -2' node record before any ' -1' element record "
            f"in {what}; the file is malformed")
    # Fewer elements than the header counts: some are lost.  More: CalculiX counts the deck's elements and
    # writes, for beams and shells, the solid elements it expanded them into as well.
    if block.numnod is not None and block.numnod > len(heads):
        raise FieldError(
            f"results file {path}: {what} announces {block.numnod} elements but holds {len(heads)}; the file is "
            f"malformed or truncated")
    if not len(body):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    records = [body[k] for k in heads]
    node_rows = np.flatnonzero(keys == " -2")
    texts = [body[k][3:].rstrip() for k in node_rows]
    lengths = np.fromiter(map(len, texts), dtype=np.int64, count=len(texts))
    try:
        if min(map(len, records)) < 3 + w + _ELEMENT_RECORD or np.any(lengths % w):
            raise ValueError("record cut short")
        types = np.array([r[3 + w:8 + w] for r in records]).astype(np.int64)
        np.array([r[3:3 + w] for r in records]).astype(np.int64)      # the element numbers parse (not kept)
        joined = "".join(texts).encode("latin-1", "replace")
        numbers = np.frombuffer(joined, dtype=f"S{w}").astype(np.int64) if joined else np.zeros(0, np.int64)
    except (ValueError, OverflowError):
        _locate_bad_element(body, block, w, path, what)
        raise  # not reached: _locate_bad_element raises
    owner = np.cumsum(keys == " -1")[node_rows] - 1          # the element of each node record
    counts = np.bincount(owner, weights=lengths // w, minlength=len(heads)).astype(np.int64)
    expected = np.full(len(types), -1, dtype=np.int64)     # unknown types: any number of nodes
    for t, k in ELEMENT_NODES.items():
        expected[types == t] = k
    bad = np.flatnonzero((expected >= 0) & (counts != expected))
    if len(bad):
        k = int(bad[0])
        t = int(types[k])
        more = f" ({len(bad)} elements like it)" if len(bad) > 1 else ""
        raise FieldError(
            f"results file {path} line {block.start + int(heads[k]) + 1}: element {records[k][3:3 + w].strip()} "
            f"of {what} has {int(counts[k])} node numbers in its ' -2' records, but its type {t} ({_TYPE_NAMES[t]}) "
            f"has {int(expected[k])} nodes{more}; the file is truncated or malformed")
    return types, np.cumsum(counts) - counts, numbers


def _locate_bad_element(body: list[str], block: _Block, w: int, path: str, what: str) -> None:
    """Raise a FieldError naming the first record of an element block that does not parse."""
    for k, r in enumerate(body):
        lineno = block.start + k + 1
        if r.startswith(" -1"):
            need = 3 + w + _ELEMENT_RECORD
            if len(r) < need:
                raise FieldError(
                    f"results file {path} line {lineno}: the element record in {what} is cut short "
                    f"({len(r)} columns, needs {need}); the file is truncated or malformed")
            fields = [(3, 3 + w, "element number"), (3 + w, 8 + w, "element type")]
        else:
            text = r[3:].rstrip()
            if len(text) % w:
                raise FieldError(
                    f"results file {path} line {lineno}: the node record in {what} ends inside a field of "
                    f"{w} columns ({len(r.rstrip())} columns); the file is truncated or malformed")
            fields = [(a, a + w, "node number") for a in range(3, 3 + len(text), w)]
        for a, b, name in fields:
            try:
                int(r[a:b])
            except ValueError:
                raise FieldError(
                    f"results file {path} line {lineno}, columns {a + 1}-{b}: {r[a:b].strip()!r} is not "
                    f"{'an' if name.startswith('e') else 'a'} {name} ({what})") from None
    raise FieldError(f"results file {path}: {what} does not parse")  # pragma: no cover


class FrdFile:
    """An ASCII ``.frd`` file, scanned once; :meth:`result` extracts result blocks.

    Parameters
    ----------
    text : str, the file's content.
    path : str, its name, for messages.
    """

    def __init__(self, text: str, path: str = "<frd>"):
        self.path = path
        self._lines = text.splitlines()
        if not self._lines or not text.strip():
            raise FieldError(f"results file {path} is empty")
        self._nodes, self._element_blocks, self._results, self.heading = _scan(self._lines, path)
        self._coords: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._elements: dict[int, np.ndarray] | None = None
        self._boundary: np.ndarray | None = None

    @property
    def elements(self) -> dict[int, np.ndarray]:
        """The tetrahedra and triangles of the file's element blocks: ``.frd`` type number (3 te4, 6 te10,
        7 tr3, 8 tr6; :data:`ELEMENT_TYPES`) -> ``(M, k)`` int64 node numbers, in the file's (CalculiX, VTK)
        node order; only the types the file has (empty without an element block).  Other types are left out,
        with an info log line naming them.  Parsed on first use; a malformed element block raises
        FieldError."""
        if self._elements is None:
            kept: dict[int, list[np.ndarray]] = {}
            skipped: dict[int, int] = {}
            for block in self._element_blocks:
                types, first, numbers = _parse_elements(self._lines, block, self.path)
                for t in distinct(types).tolist():
                    sel = types == t
                    if t not in ELEMENT_TYPES:
                        skipped[t] = skipped.get(t, 0) + int(sel.sum())
                        continue
                    k = ELEMENT_NODES[t]
                    kept.setdefault(t, []).append(numbers[first[sel][:, None] + np.arange(k)])
            if skipped:
                log.info("%s: element type(s) %s not used (hot2cold takes tetrahedra and triangles)", self.path,
                         ", ".join(f"{t} ({_TYPE_NAMES.get(t, 'unknown')}, {_n_elements(c)})"
                                   for t, c in sorted(skipped.items())))
            self._elements = {t: np.concatenate(parts) for t, parts in sorted(kept.items())}
        return self._elements

    def element_kinds(self) -> dict[str, int]:
        """How many elements of each kind (CalculiX's names: he8, te10, tr3, ...) the file's element blocks hold,
        every kind, not only those :attr:`elements` takes."""
        counts: dict[str, int] = {}
        for block in self._element_blocks:
            types = _parse_elements(self._lines, block, self.path)[0]
            for t, c in zip(*np.unique(types, return_counts=True)):
                name = _TYPE_NAMES.get(int(t), f"type {int(t)}")
                counts[name] = counts.get(name, 0) + int(c)
        return counts

    def boundary_triangles(self) -> np.ndarray | None:
        """The boundary triangles of :attr:`elements` (:func:`hot2cold.io.cells.element_triangles`), ``(T, 3)``
        or ``(T, 6)`` int64 node numbers; None when the file has no tetrahedra or triangles."""
        if self._boundary is None:
            cells = {ELEMENT_TYPES[t]: conn for t, conn in self.elements.items()}
            tri = element_triangles(cells, self.path)
            self._boundary = np.zeros((0, 3), np.int64) if tri is None else tri
        return self._boundary if len(self._boundary) else None

    def _triangle_rows(self, ids: np.ndarray) -> np.ndarray | None:
        """:meth:`boundary_triangles` as rows of the node numbers ``ids`` ``(N,)``; those naming a node that is
        not among them are dropped (info log line); None when none is left."""
        tri = self.boundary_triangles()
        if tri is None:
            return None
        order = np.argsort(ids, kind="stable")
        pos = np.minimum(np.searchsorted(ids[order], tri), len(ids) - 1)
        found = (ids[order][pos] == tri).all(axis=1)
        if not found.all():
            log.info("%s: %d of %d boundary triangles name nodes without results; dropped", self.path,
                     int((~found).sum()), len(tri))
        rows = order[pos[found]]
        return rows if len(rows) else None

    @classmethod
    def read(cls, path) -> FrdFile:
        """Read and scan the file at ``path`` (str or os.PathLike)."""
        fspath = os.path.expanduser(os.fspath(path))
        raw = read_input_bytes(fspath, "CalculiX results file", FieldError)
        return cls(raw.decode("latin-1"), fspath)

    def is_hot_to_cold(self) -> bool:
        """Whether the file comes from a hot2cold hot-to-cold deck (by its heading, see :data:`HOT_TO_COLD_HEADING`)."""
        return self.heading.startswith(HOT_TO_COLD_HEADING)

    def hot_to_cold(self) -> FrdResult:
        """The hot -> cold displacements of a hot2cold deck (:func:`hot2cold.fe.calculix.write_deck`).

        Two ``DISP`` blocks (a rotating part: step 1 the centrifugal load, step 2 the cooled part at rest):
        ``U(last) - U(first)``; one block: that block.
        """
        count = self.count("DISP")
        if count not in (1, 2):
            raise FieldError(f"results file {self.path} has {count} DISP blocks; a hot-to-cold deck written by "
                             f"hot2cold gives 1 or 2")
        last = self.result("DISP")
        if count == 1:
            return last
        first = self.result("DISP", 0)
        if not np.array_equal(first.node_ids, last.node_ids):
            raise FieldError(f"results file {self.path}: its two DISP blocks hold different nodes")
        return replace(last, values=last.values - first.values, minus=first)

    def datasets(self) -> list[str]:
        """Names of the result blocks, in file order (repeated per step)."""
        return [b.name for b in self._results]

    def count(self, dataset: str = "DISP") -> int:
        """How many result blocks named ``dataset`` (case-insensitive) the file holds."""
        want = dataset.strip().upper()
        return sum(b.name.upper() == want for b in self._results)

    def result(self, dataset: str = "DISP", step: int | None = None) -> FrdResult:
        """One result block: see :func:`read_frd`."""
        path = self.path
        want, numbered = _dataset_and_step(dataset)
        if numbered is not None and step is not None:
            raise FieldError(f"results file {path}: give the block by its step number ({dataset!r}) or by its "
                             f"index (step {step!r}), not both")
        matching = [b for b in self._results if b.name.upper() == want]
        if not matching:
            found = sorted({b.name for b in self._results})
            raise FieldError(
                f"results file {path} has no {want} result block (found: "
                f"{', '.join(found) or 'no result block'}); request the displacements in the deck with "
                f"'*NODE FILE' and 'U'")
        if numbered is not None:
            steps = [b.step for b in matching]
            if numbered not in steps:
                raise FieldError(f"results file {path} has no {want} block of step {numbered}; its {want} blocks "
                                 f"are of steps {_ranges(steps)}")
            index = len(steps) - 1 - steps[::-1].index(numbered)      # the last block of that step
        elif step is None:
            index = len(matching) - 1
        else:
            try:
                index = operator.index(step)
            except TypeError:
                raise FieldError(f"step must be an integer block index, got {step!r}") from None
            if not -len(matching) <= index < len(matching):
                raise FieldError(
                    f"results file {path} has {len(matching)} {want} block(s); step must lie in "
                    f"{-len(matching)}..{len(matching) - 1} (0 = first, -1 = last), got {step!r}")
            index %= len(matching)
        block = matching[index]
        # a node with more freedoms (the rotations D4-D6 of shells and beams, the potentials of an
        # electromagnetic run) stores them after its displacements D1-D3: the first three
        translations = block.ncomp > 3 and tuple(c.upper() for c in block.components[:3]) == ("D1", "D2", "D3")
        if block.ncomp != 3 and not translations:
            raise FieldError(
                f"results file {path}: dataset {block.name} on line {block.header + 1} stores {block.ncomp} "
                f"component(s) ({', '.join(block.components)}); a displacement is a vector of 3")
        before = [k for k, b in enumerate(self._nodes) if b.end < block.header]
        if not before:
            raise FieldError(f"results file {path} has no node block ('    2C') before its {want} block on "
                             f"line {block.header + 1}")
        nvals = min(block.ncomp, _PER_LINE)
        ids, values = _parse_rows(self._lines, block, nvals, path, f"{block.name} block")
        if translations:
            log.info("%s: the %s block on line %d holds %s besides the displacements D1-D3: not used", path,
                     block.name, block.header + 1, ", ".join(block.components[3:nvals]))
            values, nvals = values[:, :3], 3
        if len(ids) == 0:
            raise FieldError(
                f"results file {path}: the {block.name} block on line {block.header + 1} holds no node")
        if len(distinct(ids)) != len(ids):
            raise FieldError(f"results file {path}: a node appears twice in the {block.name} block on line "
                             f"{block.header + 1}")
        sorted_ids, sorted_xyz, node_block = self._node_coords(before[-1])
        pos = np.minimum(np.searchsorted(sorted_ids, ids), len(sorted_ids) - 1)
        missing = sorted_ids[pos] != ids
        if missing.any():
            raise FieldError(
                f"results file {path}: {int(missing.sum())} node(s) of the {block.name} block (first: node "
                f"{int(ids[missing][0])}) have no coordinates in the node block on line {node_block.header + 1}")
        log.debug("%s: %s block %d of %d (step %d, value %g), %d nodes", path, block.name, index + 1,
                  len(matching), block.step, block.value, len(ids))
        if len(ids) < len(sorted_ids):    # *NODE FILE of a node set, or nodes of no element: said, not dropped
            log.info("%s: %d of the file's %d nodes have no value in the %s block on line %d (not in the field)",
                     path, len(sorted_ids) - len(ids), len(sorted_ids), block.name, block.header + 1)
        return FrdResult(ids, sorted_xyz[pos], values, block.name, block.components[:nvals], block.step,
                         block.value, index, len(matching), self._triangle_rows(ids))

    def _node_coords(self, k: int) -> tuple[np.ndarray, np.ndarray, _Block]:
        """Node block ``k``: ids sorted ``(n,)``, their coordinates ``(n, 3)``, the block."""
        block = self._nodes[k]
        if k not in self._coords:
            ids, xyz = _parse_rows(self._lines, block, 3, self.path, "node block")
            if len(ids) == 0:
                raise FieldError(f"results file {self.path}: the node block on line {block.header + 1} is empty")
            order = np.argsort(ids, kind="stable")
            ids, xyz = ids[order], xyz[order]
            if np.any(ids[1:] == ids[:-1]):
                dup = int(ids[1:][ids[1:] == ids[:-1]][0])
                raise FieldError(f"results file {self.path}: node {dup} appears twice in the node block on "
                                 f"line {block.header + 1}")
            self._coords[k] = (ids, xyz)
        return (*self._coords[k], block)


_NUMBERED = re.compile(r"^(?:(\w+)\s+)?STEP\s*(\d+)$")


def _dataset_and_step(dataset: str) -> tuple[str, int | None]:
    """The dataset name and, when ``dataset`` names one as CGX lists the blocks (``"step 3"``, ``"DISP step
    3"``), the step number of the block's header: ``("DISP", 3)``; else ``(name, None)``."""
    text = " ".join(dataset.strip().upper().split())
    found = _NUMBERED.match(text)
    if found is None:
        return text, None
    return found.group(1) or "DISP", int(found.group(2))


def _ranges(numbers: list[int]) -> str:
    """``1-4, 7, 9-10`` of the distinct ``numbers``."""
    distinct = sorted(set(numbers))
    runs, start = [], None
    for k, n in enumerate(distinct):
        if start is None:
            start = n
        if k + 1 == len(distinct) or distinct[k + 1] != n + 1:
            runs.append(f"{start}-{n}" if n > start else f"{n}")
            start = None
    return ", ".join(runs)


def _n_elements(count: int) -> str:
    return f"{count} element" + ("" if count == 1 else "s")


def parse_frd(text: str, path: str = "<frd>", dataset: str = "DISP", step: int | None = None) -> FrdResult:
    """Parse the text of an ASCII ``.frd`` file; see :func:`read_frd`."""
    return FrdFile(text, path).result(dataset, step)


def read_frd(path, dataset: str = "DISP", step: int | None = None) -> FrdResult:
    """Read one nodal result block (default the displacements) of an ASCII CalculiX ``.frd`` file.

    Parameters
    ----------
    path : str or os.PathLike
    dataset : str
        The dataset name (``-4`` record), case-insensitive; ``DISP`` by default.  ``"step 3"`` or ``"DISP step
        3"`` names a block as CalculiX's post-processor CGX lists it, by the step number of its header (the
        last block of that step if it has several).
    step : int or None
        Which of the file's blocks of that name, counting from 0 in file order (negative from the end);
        ``None``: the last one (the final state of the last step).

    Raises
    ------
    FieldError
        Missing or unreadable file, binary or malformed or truncated content, no such block.
    """
    return FrdFile.read(path).result(dataset, step)
