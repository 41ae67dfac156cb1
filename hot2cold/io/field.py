"""The FE displacement field: hot node positions and their displacements to the cold state.

A field is one row per FE node: the hot position ``x, y, z`` and the displacement ``dx, dy, dz`` that
takes it to the cold (unloaded, room temperature) state.  Inside hot2cold everything is in millimetres.

File formats read by :func:`read_field`
---------------------------------------
*Text* (``.csv``, ``.txt``, ``.dat``, any other name): a header line naming the positions and the
displacements in any order and any letter case, ``x, y, z, dx, dy, dz`` or as other tools name them
(``ux``, ``U1``, ``COORD1``, ``Points:0``, ``X Location (mm)``: :mod:`hot2cold.io.columns`, which also takes
a unit written after a name and a user's ``columns`` mapping), then one line per node.  Fields are separated
by commas, by semicolons or tabs (then a decimal comma is accepted: ``1,5;2,25``) or by whitespace; the
separator is taken from the header line.  A column named ``id``, ``node``, ``node_id``, ``nodeid``,
``nid``, ``node_number`` (``Node Number``) or ``node_label`` becomes :attr:`DisplacementField.node_ids`; any
other extra column is ignored.  Every line must have as many fields as the header.  ``#`` starts a comment;
blank lines, surrounding spaces, quotes around names, a UTF-8 byte-order mark and UTF-16 text (with its
byte-order mark) are tolerated.  A header written as a comment (``# x,y,z,dx,dy,dz`` as ``numpy.savetxt(...,
header=...)`` writes it) is used when no plain header line precedes the numbers.

*NumPy* ``.npz`` (recognised by its content, whatever the file name): arrays ``points`` (N, 3) and
``displacements`` (N, 3) (or the array named by ``field_name``), optionally ``node_ids`` (N,).  This is what
:func:`hot2cold.fe.calculix.hot_to_cold_field` writes.  An optional array ``triangles`` (T, 3) or (T, 6) of
integer rows of ``points`` gives the FE model's boundary triangles (:attr:`DisplacementField.triangles`).

*CalculiX results* ``.frd`` (ASCII; recognised by the extension or by its first record ``    1C``): the
node block and the last ``DISP`` result block (or the block chosen by ``step``, counting ``DISP`` blocks
from 0; or the dataset named by ``field_name``, or the block of a step as CGX lists it, ``field_name="step
3"``), read by fixed columns (:mod:`hot2cold.io.frd`).  The
``.frd`` of a hot2cold hot-to-cold deck (:mod:`hot2cold.fe.calculix`, recognised by its heading) gives its
hot -> cold field: for a rotating part the last ``DISP`` block minus the first.
``node_ids`` are the CalculiX node numbers; the element block's tetrahedra (C3D4, C3D10) give the boundary
``triangles`` (its shell triangles, tr3 and tr6, when it has no tetrahedra).  The ``.frd`` holds coordinates
to 6 significant digits only: pass ``points_from=`` (the :class:`~hot2cold.fe.mesh.TetMesh` the run was made
on, or a field or ``.npz`` / text file with node ids, in the same length unit as the ``.frd``) to take the
node positions from there, matched by node number; positions that disagree with the ``.frd`` beyond its
rounding raise an error.

*Solver results*: ANSYS Mechanical APDL ``.rst`` (:mod:`hot2cold.io.ansys`, through ansys-mapdl-reader: node
positions, displacements in global axes, the unit system and the solid elements' boundary triangles), Nastran
``.op2`` (NX and MSC, :mod:`hot2cold.io.nastran`, native: the static displacement tables and the GRID
geometry, in the basic frame) and punch ``.pch`` (displacements only: positions from ``points_from``, a
``.bdf``'s GRID cards or a field with node ids).  The last result set, or the one named by ``field_name``
or numbered by ``step``.

*Mesh files read by meshio* (``.vtu``, ``.vtk``, ``.xdmf``/``.xmf``, ``.msh``, ``.med``, ``.h5m`` and
meshio's other formats; VTK, VTU and gmsh files are also recognised by content): the mesh points and a
point field named ``U``, ``displacement``, ``displacements`` or ``DISP`` (any letter case, first match in
that order), or the one named by ``field_name``; its shape must be (N, 3).  Cells of type ``tetra`` or
``tetra10`` give the boundary ``triangles`` (:func:`element_triangles`); a surface mesh's ``triangle`` or
``triangle6`` cells are taken as they are; other cell types are not used (an info log line names them).
Needs meshio (the ``fe`` extra).  ``.dat`` files stay text tables.

Every problem raises :class:`hot2cold.errors.FieldError` with a one-line message that says what is wrong
and what to do.

Duplicate nodes (:func:`merge_duplicates`, applied by :func:`read_field` and :func:`as_field`): nodes at the
same position (within ``DUPLICATE_RTOL`` of the field's extent) with the same displacement (within
``DUPLICATE_DISPLACEMENT_RTOL`` of the largest one) are merged into one, with a log line; with different
displacements they are an error, since a position takes one displacement (the coincident nodes of two
meshes that were not merged, a contact that opened).
"""
from __future__ import annotations

import contextlib
import io
import itertools
import logging
import os
import re
from dataclasses import dataclass, replace

import numpy as np

from ..errors import FieldError, one_line
from .cells import ELEMENT_NAMES as _ELEMENT_NAMES
from .cells import element_triangles

from .columns import ALIASES, HINT, ID_COLUMNS, REQUIRED_COLUMNS, STATED_UNITS, assign, normalise, parse_mapping
from .inputs import read_input_bytes
from ..settings import option

__all__ = ["DisplacementField", "UNITS", "REQUIRED_COLUMNS", "ID_COLUMNS", "DISPLACEMENT_NAMES", "FIELD_FORMATS",
           "read_field",
           "as_field", "match_points", "merge_duplicates", "DUPLICATE_RTOL",
           "DUPLICATE_DISPLACEMENT_RTOL"]

log = logging.getLogger(__name__)

#: Length units a field may be given in, and the factor that takes them to millimetres.
UNITS = {"mm": 1.0, "m": 1000.0}

#: Nodes closer than this times the diagonal of the field's bounding box are at the same position.
DUPLICATE_RTOL = 1e-9

#: Nodes at the same position whose displacements differ by at most this times the largest displacement of the
#: field (or by ``DUPLICATE_RTOL`` times its extent, if more) have the same displacement.
DUPLICATE_DISPLACEMENT_RTOL = 1e-6

_NPZ_MAGIC = b"PK\x03\x04"
_QUOTES = "\"'"


# --------------------------------------------------------------------------------------------------------
# The field record
# --------------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class DisplacementField:
    """An FE displacement field in millimetres.

    Attributes
    ----------
    points : numpy.ndarray
        (N, 3) hot node positions, mm.  Read-only float64, C-contiguous.
    displacements : numpy.ndarray
        (N, 3) displacements hot -> cold, mm.  Read-only float64, C-contiguous.
    node_ids : numpy.ndarray or None
        (N,) int64 FE node ids if the source had an id column, else ``None``.  Read-only.
    source : str
        Where the field came from (a path, ``"arrays"``), for messages.
    triangles : numpy.ndarray or None
        (T, 3) or (T, 6) int64 rows of ``points``: the FE model's boundary triangles (corners, then the
        midside nodes of the edges 0-1, 1-2, 2-0; :mod:`hot2cold.core.elements`) when the source brings its
        elements, else ``None``.  The morph samples the field inside them by their own shape functions.
        Read-only.
    result_set : str
        Which of a solver file's result sets the field is, as the solver's post-processor names it (a
        CalculiX ``"DISP block 2 of 3: step 2, time 1"``, an ANSYS ``"result set 2 (load step 1, substep 3,
        time 2.5)"``, a Nastran ``"subcase 2"``), for the report; ``""`` for other sources.

    Copies that change some arrays are made with :func:`dataclasses.replace`, which keeps the rest.

    The constructor copies the arrays and checks shapes, N >= 1 and finiteness; a violation raises
    :class:`~hot2cold.errors.FieldError`.
    """

    points: np.ndarray
    displacements: np.ndarray
    node_ids: np.ndarray | None = None
    source: str = ""
    triangles: np.ndarray | None = None
    result_set: str = ""

    def __post_init__(self):
        where = f" ({self.source})" if self.source else ""
        arrays = {}
        for name in ("points", "displacements"):
            try:
                given = getattr(self, name)
                if np.iscomplexobj(given):
                    raise TypeError("complex numbers")
                a = np.array(given, dtype=np.float64, order="C", copy=True)
            except (TypeError, ValueError) as exc:
                raise FieldError(
                    f"field{where}: {name} is not an array of numbers ({one_line(exc)}); "
                    f"pass an (N, 3) array of floats") from None
            if a.ndim != 2 or a.shape[1] != 3:
                raise FieldError(
                    f"field{where}: {name} must have shape (N, 3), got shape {a.shape}; "
                    f"pass one row (x, y, z) per FE node")
            arrays[name] = a
        p, d = arrays["points"], arrays["displacements"]
        if p.shape != d.shape:
            raise FieldError(
                f"field{where}: points has shape {p.shape} but displacements has shape {d.shape}; "
                f"they need one row each per FE node")
        if len(p) == 0:
            raise FieldError(f"field{where} has no nodes (shape {p.shape}); it needs at least one FE node")
        for name, a in arrays.items():
            bad = ~np.isfinite(a)
            if bad.any():
                rows = np.flatnonzero(bad.any(axis=1))
                raise FieldError(
                    f"field{where}: {name} has {int(bad.sum())} NaN or inf value(s) in {len(rows)} row(s), "
                    f"first in row {int(rows[0])} (counting from 0); the field must be finite: "
                    f"fix or drop those nodes")
        ids = self.node_ids
        if ids is not None:
            try:
                ids_f = np.asarray(ids)
                if ids_f.dtype.kind not in "iu":
                    ids_f = ids_f.astype(np.float64)
                    if not np.all(np.isfinite(ids_f)) or np.any(ids_f != np.round(ids_f)):
                        raise ValueError("not all integers")
                ids = np.array(ids_f, dtype=np.int64, order="C", copy=True)
            except (TypeError, ValueError, OverflowError) as exc:
                raise FieldError(
                    f"field{where}: node_ids must be integers ({one_line(exc)}); "
                    f"pass integer ids or node_ids=None") from None
            if ids.shape != (len(p),):
                raise FieldError(
                    f"field{where}: node_ids must have shape ({len(p)},) to match the points, "
                    f"got shape {ids.shape}")
            ids.flags.writeable = False
        p.flags.writeable = False
        d.flags.writeable = False
        object.__setattr__(self, "triangles", self._checked_triangles(len(p), where))
        object.__setattr__(self, "points", p)
        object.__setattr__(self, "displacements", d)
        object.__setattr__(self, "node_ids", ids)
        object.__setattr__(self, "source", str(self.source))
        object.__setattr__(self, "result_set", str(self.result_set))

    def _checked_triangles(self, n: int, where: str) -> np.ndarray | None:
        """``self.triangles`` as a read-only ``(T, 3 or 6)`` int64 array of rows below ``n``, or None."""
        if self.triangles is None:
            return None
        try:
            tri = np.asarray(self.triangles)
            if tri.dtype.kind not in "iu":
                raise ValueError(f"dtype {tri.dtype}")
            tri = np.array(tri, dtype=np.int64, order="C", copy=True)
        except (TypeError, ValueError, OverflowError) as exc:
            raise FieldError(f"field{where}: triangles must be integer node rows ({one_line(exc)})") from None
        if tri.ndim != 2 or tri.shape[1] not in (3, 6):
            raise FieldError(f"field{where}: triangles must have shape (T, 3) or (T, 6), got shape {tri.shape}; "
                             f"pass the corner (and midside) node rows of each boundary triangle")
        if len(tri) == 0:
            return None
        if tri.min() < 0 or tri.max() >= n:
            raise FieldError(f"field{where}: triangles refer to node rows outside 0..{n - 1} "
                             f"(found {int(tri.min())}..{int(tri.max())})")
        tri.flags.writeable = False
        return tri

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def take(self, rows: np.ndarray) -> DisplacementField:
        """The field of the nodes ``rows (M,)`` (int, may repeat a node), ids and source kept; the triangles
        whose nodes are all kept, on the first row of each."""
        rows = np.asarray(rows, dtype=np.int64).reshape(-1)
        ids = None if self.node_ids is None else self.node_ids[rows]
        return replace(self, points=self.points[rows], displacements=self.displacements[rows], node_ids=ids,
                       triangles=_renumbered(self.triangles, rows, len(self)))

    def __repr__(self) -> str:
        dmax = float(np.sqrt((self.displacements ** 2).sum(axis=1)).max())
        ids = "" if self.node_ids is None else ", with node ids"
        tri = "" if self.triangles is None else f", {_n(len(self.triangles), 'boundary triangle')}"
        return (f"DisplacementField({_n(len(self), 'node')}, max |d| = {dmax:.6g} mm{ids}{tri}, "
                f"source={self.source!r})")

    def scaled(self, factor: float) -> DisplacementField:
        """A copy with points and displacements multiplied by ``factor`` (e.g. a unit factor)."""
        try:
            f = float(factor)
        except (TypeError, ValueError):
            raise FieldError(f"scale factor must be a number, got {factor!r}") from None
        if not (np.isfinite(f) and f > 0):
            raise FieldError(f"scale factor must be a positive finite number, got {factor!r}")
        return replace(self, points=self.points * f, displacements=self.displacements * f)


def _renumbered(triangles: np.ndarray | None, rows: np.ndarray, n: int) -> np.ndarray | None:
    """``triangles`` (node rows below ``n``) in the numbering of a field made of the nodes ``rows``: those
    whose nodes are all among ``rows``, each node on the first row that holds it; None when none is left."""
    if triangles is None:
        return None
    new = np.full(n, -1, dtype=np.int64)
    first = np.unique(rows, return_index=True)
    new[first[0]] = first[1]
    mapped = new[triangles]
    mapped = mapped[(mapped >= 0).all(axis=1)]
    return mapped if len(mapped) else None


# --------------------------------------------------------------------------------------------------------
# Public entry points
# --------------------------------------------------------------------------------------------------------
def read_field(path, units: str | None = None, field_name: str | None = None, *, points_from=None,
               step: int | None = None, columns=None) -> DisplacementField:
    """Read a displacement field from a text table, ``.npz``, solver result or mesh file, in millimetres.

    Parameters
    ----------
    path : str or os.PathLike
        The field file (see the module documentation for the formats; dispatched by extension, then content).
    units : str or None
        ``"mm"`` or ``"m"``: the length unit of the file; the result is in mm.  None (default): the unit the
        file states (an ANSYS ``.rst``'s unit system, a text table's ``X Location (m)``), else mm.  A unit
        given that contradicts the file's is refused.
    field_name : str or None
        Which displacement data to take: the point field of a mesh file, the dataset of an ``.frd``
        (default ``DISP``), the array of an ``.npz`` (default ``displacements``), the result set of an ANSYS
        ``.rst`` or the subcase of a Nastran ``.op2``/``.pch``.  Not for text tables.
    points_from : TetMesh, DisplacementField, path or None
        ``.frd``, ``.op2`` and ``.pch`` only: where to take the node positions from, matched by node number
        (see the module documentation).  ``None``: the file's own (an ``.frd``'s are rounded; a ``.pch`` has
        none).
    step : int or None
        Solver results only: which result set, counting from 0 in file order (negative from the end);
        ``None``: the last.
    columns : str, mapping or None
        Text tables only: which columns hold what, ``"x=X Location,dx=UX"`` or ``{"x": "X Location", ...}``
        (:func:`hot2cold.io.columns.parse_mapping`); the others are found by their usual names.

    Raises
    ------
    FieldError
        The file is missing or unreadable, or its content is malformed, truncated, empty or not finite, or
        lacks the displacement data.
    """
    if units is not None:
        _unit_factor(units)
    if field_name is not None and (not isinstance(field_name, str) or not field_name.strip()):
        raise FieldError(f"field_name must be a non-empty string or None, got {field_name!r}")
    mapping = None
    if columns is not None:
        try:
            mapping = parse_mapping(columns)
        except ValueError as exc:
            raise FieldError(f"columns {exc}") from None
    try:
        fspath = os.fspath(path)
    except TypeError:
        raise FieldError(f"field path must be a file name, got {type(path).__name__}") from None
    if isinstance(fspath, bytes):
        fspath = os.fsdecode(fspath)
    fspath = os.path.expanduser(fspath)
    raw = read_input_bytes(fspath, "field file", FieldError)
    kind = _kind(fspath, raw)
    for given, name, kinds in ((points_from, "points_from", _POSITIONLESS), (step, "step", _SOLVER_KINDS),
                               (mapping, "columns", ("text",))):
        if given is not None and kind.partition(":")[0] not in kinds:
            raise FieldError(f"{name} applies to {_KIND_NAMES[kinds]} only; {fspath} is read as {kind}")
    stated = {}
    if kind == "npz":
        field = _parse_npz(fspath, field_name)
    elif kind == "frd":
        field = _parse_frd(raw, fspath, field_name, step, points_from)
    elif kind in ("rst", "op2", "pch"):
        field, unit = _parse_solver(kind, fspath, field_name, step, points_from)
        stated = {"points": unit, "displacements": unit}
    elif kind.startswith("meshio"):
        field = _parse_meshio(fspath, kind.partition(":")[2] or None, field_name)
    else:
        if field_name is not None:
            raise FieldError(
                f"field_name applies to .frd, .npz, solver result and mesh files; the text table {fspath} needs "
                f"the columns {','.join(REQUIRED_COLUMNS)} (or {option('columns')})")
        field, stated = _parse_text(raw, fspath, mapping)
    field = _in_mm(field, units, stated, fspath)
    log.info("read %d nodes from %s (%s, units %s)", len(field), fspath, kind.partition(":")[0],
             units or next((u for u in stated.values() if u), "mm"))
    return merge_duplicates(field)


def _in_mm(field: DisplacementField, units: str | None, stated: dict[str, str | None], path: str
           ) -> DisplacementField:
    """``field`` scaled to mm: by the units the file ``stated`` (``{"points": unit, "displacements": unit}``,
    a group that states none takes the other's), else by ``units`` (None: mm).  ``units`` given and different
    from a stated one raises."""
    said = {k: u for k, u in stated.items() if u}
    if units is not None:
        for what, unit in said.items():
            if STATED_UNITS[unit] != _unit_factor(units):
                raise FieldError(f"field file {path} states its {what} in {unit}, but the field units were "
                                 f"given as {units.strip().lower()}: drop {option('field_units')} to take the "
                                 f"file's, or fix the file")
        factor = _unit_factor(units)
        return field if factor == 1.0 else field.scaled(factor)
    if not said:
        return field
    fp = STATED_UNITS[said.get("points", said.get("displacements"))]
    fd = STATED_UNITS[said.get("displacements", said.get("points"))]
    if fp == fd == 1.0:
        return field
    log.info("field file %s states its lengths in %s; scaled to mm", path, ", ".join(sorted(set(said.values()))))
    return replace(field, points=field.points * fp, displacements=field.displacements * fd)


def as_field(field, units: str | None = None, field_name: str | None = None, *, step: int | None = None,
             columns=None, points_from=None) -> DisplacementField:
    """Turn what a user passed into a :class:`DisplacementField` in millimetres.

    Accepts a :class:`DisplacementField` (returned as it is unless it has duplicate nodes, see
    :func:`merge_duplicates`; it is already in mm, so ``units`` must be ``"mm"`` or None), a path (``str`` or
    ``os.PathLike``; see :func:`read_field`, which gets ``units``, ``field_name``, ``step``, ``columns`` and
    ``points_from``), a ``meshio.Mesh`` or a pyvista dataset in ``units`` (None: mm) with a point displacement
    array (named as in a mesh file, or ``field_name``; its tetrahedra and triangles give the boundary
    ``triangles``, as a mesh file's do), or a pair ``(points, displacements)`` of (N, 3) array-likes in
    ``units``.
    Duplicate nodes are merged or refused (:func:`merge_duplicates`).
    """
    if isinstance(field, (str, bytes, os.PathLike)):
        return read_field(field, units, field_name, step=step, columns=columns, points_from=points_from)
    if (step, columns, points_from) != (None, None, None):
        raise FieldError("step, columns and points_from apply to a field file, not to a field given as arrays")
    factor = 1.0 if units is None else _unit_factor(units)
    if isinstance(field, DisplacementField):
        if factor != 1.0:
            raise FieldError(
                f"a DisplacementField is already in mm, so units={units!r} cannot apply to it; "
                f"use field.scaled(...) or pass units='mm'")
        return merge_duplicates(field)
    mesh = _in_memory_mesh(field)
    if mesh is not None:
        name = type(field).__name__
        result = _mesh_field(mesh, f"the {name} given", f"{name} in memory", field_name)
        return merge_duplicates(result.scaled(factor) if factor != 1.0 else result)
    if isinstance(field, (tuple, list)) and len(field) == 2:
        points, displacements = field
        result = DisplacementField(points, displacements, source="arrays")
        return merge_duplicates(result.scaled(factor) if factor != 1.0 else result)
    raise FieldError(
        f"cannot make a displacement field from {type(field).__name__}: pass a DisplacementField, "
        f"a file path, a meshio.Mesh or pyvista dataset with a point displacement array, or a (points, "
        f"displacements) pair of (N, 3) arrays")


def merge_duplicates(field: DisplacementField) -> DisplacementField:
    """``field`` with its duplicate nodes merged: nodes within ``DUPLICATE_RTOL`` times the field's extent of
    each other are one position; if their displacements agree (see ``DUPLICATE_DISPLACEMENT_RTOL``) they
    become one node (their mean; the first one's id), logged.  ``field`` itself when it has no duplicates.

    Raises :class:`FieldError` when nodes at one position have different displacements, naming how many
    positions and the first one.
    """
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components
    from ..core.trees import kd_tree

    n = len(field)
    if n < 2:
        return field
    p, d = field.points, field.displacements
    extent = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
    tol = DUPLICATE_RTOL * extent
    if tol > 0:
        pairs = kd_tree(p).query_pairs(tol, output_type="ndarray")
    else:  # every node at one point
        pairs = np.column_stack([np.zeros(n - 1, np.int64), np.arange(1, n)])
    if not len(pairs):
        return field
    # Groups of nodes at one position (a chain of close pairs is one group).
    graph = coo_array((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    order = np.argsort(label, kind="stable")
    first = np.ones(n, bool)
    first[1:] = label[order][1:] != label[order][:-1]
    starts = np.flatnonzero(first)
    sizes = np.diff(np.append(starts, n))
    group = np.repeat(np.arange(len(starts)), sizes)           # group of each node in ``order``
    mean = np.zeros((len(starts), 3))
    np.add.at(mean, group, d[order])
    mean /= sizes[:, None]
    spread = np.linalg.norm(d[order] - mean[group], axis=1)
    worst = np.zeros(len(starts))
    np.maximum.at(worst, group, spread)
    dmax = float(np.linalg.norm(d, axis=1).max())
    agree = max(DUPLICATE_DISPLACEMENT_RTOL * dmax, tol, 1e-12)
    where = f" {field.source}" if field.source else ""
    bad = np.flatnonzero((sizes > 1) & (worst > agree))
    if len(bad):
        g = int(bad[0])
        members = np.sort(order[starts[g]:starts[g] + sizes[g]])
        i, j = int(members[0]), int(members[np.argmax(np.linalg.norm(d[members] - d[members[0]], axis=1))])
        ids = "" if field.node_ids is None else f", node ids {int(field.node_ids[i])} and {int(field.node_ids[j])}"
        raise FieldError(
            f"field{where} has {_n(len(bad), 'position')} with duplicate nodes of different displacements, "
            f"e.g. ({_fmt(p[i])}) mm: rows {i} and {j} (from 0{ids}) move by ({_fmt(d[i])}) and ({_fmt(d[j])}) mm; "
            f"a position takes one displacement: merge the coincident nodes in the FE model or drop one of them")
    keep = order[starts]                                         # the first node (in ``order``) of each group
    keep_sorted = np.argsort(keep, kind="stable")
    merged = n - len(starts)
    log.info("field%s: %s at the same position as another with the same displacement merged", where,
             _n(merged, "duplicate node"))
    ids = None if field.node_ids is None else field.node_ids[keep[keep_sorted]]
    triangles = None
    if field.triangles is not None:                              # each node -> its group's row in the result
        row_of_group = np.empty(len(starts), dtype=np.int64)
        row_of_group[keep_sorted] = np.arange(len(starts))
        new = np.empty(n, dtype=np.int64)
        new[order] = row_of_group[group]
        triangles = new[field.triangles]
    return replace(field, points=p[keep[keep_sorted]], displacements=mean[keep_sorted], node_ids=ids,
                   triangles=triangles)


# --------------------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------------------
def _fmt(v) -> str:
    return ", ".join(f"{float(x):.6g}" for x in v)



def _unit_factor(units) -> float:
    key = units.strip().lower() if isinstance(units, str) else None
    if key not in UNITS:
        raise FieldError(f"unknown units {units!r} for the field: use one of {', '.join(map(repr, UNITS))}")
    return UNITS[key]


def _parse_npz(path: str, field_name: str | None = None) -> DisplacementField:
    name = "displacements" if field_name is None else field_name
    try:
        with np.load(path, allow_pickle=False) as npz:
            keys = list(npz.files)
            missing = [k for k in ("points", name) if k not in keys]
            if missing:
                raise FieldError(
                    f"field file {path} lacks array(s) {', '.join(missing)} (found: "
                    f"{', '.join(keys) or 'none'}); "
                    f"save it with np.savez(path, points=..., {name}=...)")
            points = npz["points"]
            displacements = npz[name]
            node_ids = npz["node_ids"] if "node_ids" in keys else None
            triangles = npz["triangles"] if "triangles" in keys else None
    except FieldError:
        raise
    except Exception as exc:  # zipfile.BadZipFile, ValueError (pickled objects), OSError, ...
        raise FieldError(
            f"cannot read field file {path} as .npz: {one_line(exc)}; "
            f"save it with np.savez(path, points=..., displacements=...)") from None
    return DisplacementField(points, displacements, node_ids, source=path, triangles=triangles)


#: Extensions read by meshio (besides those meshio itself knows, minus the ones kept as text tables).
_TEXT_EXTENSIONS = (".csv", ".txt", ".dat", ".tsv")
_MESHIO_EXTENSIONS = (".vtu", ".vtk", ".vtp", ".xdmf", ".xmf", ".msh", ".med", ".h5m", ".cgns", ".e", ".exo",
                      ".ex2", ".inp", ".bdf", ".nas", ".fem", ".mesh", ".meshb", ".su2", ".ugrid", ".avs",
                      ".mdpa", ".ply", ".obj", ".off", ".tec", ".vol", ".xml", ".f3grid", ".hmf", ".post",
                      ".dato")

#: The field file formats read, one entry each (for the command line's help and the docs; the module docstring
#: has the details).
FIELD_FORMATS = (
    "a text table (.csv, .txt, .dat: comma, semicolon, tab or whitespace separated) with columns x,y,z,dx,dy,dz "
    "or the solvers' names for them (U1, COORD1, 'X Location (mm)', Points:0, ...)",
    "NumPy .npz with arrays points and displacements",
    "CalculiX .frd",
    "ANSYS .rst",
    "Nastran .op2 and .pch (a .pch with the positions of its .bdf)",
    "a mesh file meshio reads (.vtu, .vtk, .xdmf, .msh, .med, ...) with a point field U or displacement",
)

#: Point-field names taken as displacements in mesh files (case-insensitive, in this order of preference).
DISPLACEMENT_NAMES = ("u", "displacement", "displacements", "disp")


#: Solver result files by extension: ANSYS Mechanical APDL results, Nastran OP2 and punch.
_SOLVER_EXTENSIONS = {".rst": "rst", ".rth": "rst", ".op2": "op2", ".pch": "pch", ".punch": "pch"}
#: The kinds that take a result set (``step``) and those whose positions may come from elsewhere.
_SOLVER_KINDS = ("frd", "rst", "op2", "pch")
_POSITIONLESS = ("frd", "op2", "pch")
_KIND_NAMES = {_SOLVER_KINDS: "solver results (.frd, .rst, .op2, .pch)", _POSITIONLESS: ".frd, .op2 and .pch files",
               ("text",): "text tables"}


def _kind(path: str, raw: bytes) -> str:
    """How to read the file: ``npz``, ``frd``, ``rst``, ``op2``, ``pch``, ``meshio[:format]`` or ``text``."""
    if raw.startswith(_NPZ_MAGIC):
        return "npz"
    name = path.lower()
    ext = os.path.splitext(name)[1]
    if ext == ".frd":
        return "frd"
    if ext in _SOLVER_EXTENSIONS:
        return _SOLVER_EXTENSIONS[ext]
    if ext in _TEXT_EXTENSIONS:
        return "text"
    head = raw[:512].lstrip(b"\xef\xbb\xbf")
    if head.startswith(b"    1C"):
        return "frd"
    if ext in _MESHIO_EXTENSIONS or name.endswith((".vol.gz", ".post.gz", ".dato.gz")):
        return "meshio"
    if head.startswith(b"# vtk DataFile"):
        return "meshio:vtk"
    if head.lstrip().startswith(b"<?xml") or head.lstrip().startswith(b"<VTKFile"):
        if b"<VTKFile" in head and b"UnstructuredGrid" in head:
            return "meshio:vtu"
        if b"<Xdmf" in head:
            return "meshio:xdmf"
    if head.startswith(b"$MeshFormat"):
        return "meshio:gmsh"
    return "text"


def _parse_frd(raw: bytes, path: str, field_name: str | None, step, points_from) -> DisplacementField:
    from .frd import FrdFile

    frd = FrdFile(raw.decode("latin-1"), path)
    if field_name is None and step is None and frd.is_hot_to_cold():
        result = frd.hot_to_cold()
    else:
        result = frd.result("DISP" if field_name is None else field_name, step)
    log.info("%s: %s", path, result.label)
    points = result.points
    if points_from is not None:
        points = match_points(points_from, result.node_ids, result.points, path)
    return DisplacementField(points, result.values[:, :3], result.node_ids, source=path,
                             triangles=result.triangles, result_set=result.label)


#: Nastran bulk data (input decks), whose GRID cards give node positions (``points_from``).
_BULK_DATA = (".bdf", ".dat", ".nas", ".blk", ".bulk")


def match_points(source, ids: np.ndarray, rounded: np.ndarray | None, path: str = "the results") -> np.ndarray:
    """Full-precision positions ``(N, 3)`` of the nodes ``ids (N,)`` of an ``.frd`` (or a result file without
    positions) from ``source``.

    ``source`` is a :class:`~hot2cold.fe.mesh.TetMesh` (anything with ``nodes`` and ``node_tags``), a
    :class:`DisplacementField` with node ids, a Nastran input deck (``.bdf``, ``.dat``, ``.nas``: its GRID
    cards, :func:`hot2cold.io.nastran.read_bdf_grids`) or a field file with node ids.  The positions must agree
    with the ``.frd``'s 6-digit ``rounded`` ones ``(N, 3)`` to within that rounding, else FieldError;
    ``rounded`` None: nothing to compare with.
    """
    if hasattr(source, "nodes") and hasattr(source, "node_tags"):  # a TetMesh
        src_ids, src_pts, what = np.asarray(source.node_tags), np.asarray(source.nodes), "the mesh"
    elif isinstance(source, (str, os.PathLike)) and os.path.splitext(os.fspath(source))[1].lower() in _BULK_DATA:
        from .nastran import read_bdf_grids

        src_ids, src_pts = read_bdf_grids(os.fspath(source))
        what = os.fspath(source)
    else:
        if isinstance(source, (str, bytes, os.PathLike)):
            source = read_field(source)
        if not isinstance(source, DisplacementField):
            raise FieldError(
                f"points_from must be a TetMesh, a DisplacementField with node ids or a field file, "
                f"got {type(source).__name__}")
        if source.node_ids is None:
            raise FieldError(
                f"points_from ({source.source or 'a field'}) has no node ids to match the nodes of {path} by")
        src_ids, src_pts, what = source.node_ids, source.points, source.source or "points_from"
    src_ids = np.asarray(src_ids, dtype=np.int64)
    src_pts = np.asarray(src_pts, dtype=np.float64)
    if src_pts.ndim != 2 or src_pts.shape[1] != 3 or src_ids.shape != (len(src_pts),):
        raise FieldError(f"points_from ({what}) must hold (N, 3) positions and (N,) node ids")
    order = np.argsort(src_ids, kind="stable")
    sorted_ids = src_ids[order]
    pos = np.searchsorted(sorted_ids, ids)
    pos = np.minimum(pos, max(len(sorted_ids) - 1, 0))
    missing = (sorted_ids[pos] != ids) if len(sorted_ids) else np.ones(len(ids), bool)
    if missing.any():
        raise FieldError(
            f"{int(missing.sum())} node(s) of {path} (first: node {int(ids[missing][0])}) are not in points_from "
            f"({what}); pass the mesh the results were computed on")
    points = src_pts[order[pos]]
    if rounded is None:
        return points
    # The .frd rounds to 6 significant digits (E12.5): half a unit of the 6th digit, and some slack.
    tol = 1e-5 * np.maximum(np.abs(rounded), np.abs(rounded).max() * 1e-6) + 1e-12
    off = np.abs(points - rounded) > tol
    if off.any():
        k = int(np.flatnonzero(off.any(axis=1))[0])
        raise FieldError(
            f"points_from ({what}) does not match {path}: node {int(ids[k])} is at "
            f"{tuple(float(f'{v:.6g}') for v in points[k])} there but at "
            f"{tuple(float(v) for v in rounded[k])} in the results ({int(off.any(axis=1).sum())} node(s) differ); "
            f"pass the mesh the results were computed on, in the same length unit")
    return points


def _parse_solver(kind: str, path: str, field_name: str | None, step: int | None, points_from
                  ) -> tuple[DisplacementField, str | None]:
    """The field of an ANSYS ``.rst`` (:mod:`hot2cold.io.ansys`) or a Nastran ``.op2``/``.pch``
    (:mod:`hot2cold.io.nastran`) in the file's length unit, and that unit where the file states it."""
    if kind == "rst":
        from .ansys import read_rst as read
    else:
        from .nastran import read_op2, read_punch
        read = read_op2 if kind == "op2" else read_punch
    result = read(path, field_name, step)
    log.info("%s: result set %s (of %d: %s)", path, result.name, len(result.available), "; ".join(result.available))
    points = result.points
    if points_from is not None:
        points = match_points(points_from, result.node_ids, None, path)
    elif points is None:
        raise FieldError(f"{path} holds no node positions; pass the model they belong to "
                         f"({option('field_points', 'model.bdf')}) to take them by node number")
    label = f"result set {result.name}" if kind == "rst" else result.name
    return (DisplacementField(points, result.displacements, result.node_ids, source=path,
                              triangles=getattr(result, "triangles", None), result_set=label),
            getattr(result, "unit", None))


def _parse_meshio(path: str, file_format: str | None, field_name: str | None) -> DisplacementField:
    try:
        import meshio
    except ImportError:
        raise FieldError(
            f"reading {path} needs meshio: pip install 'hot2cold[fe]' (or convert the field to CSV or .npz)"
        ) from None
    return _mesh_field(_meshio_read(meshio, path, file_format), f"mesh file {path}", path, field_name)


def _mesh_field(mesh, what: str, source: str, field_name: str | None) -> DisplacementField:
    """The field of a ``meshio.Mesh``: its points and the point field named ``field_name`` (default the first of
    :data:`DISPLACEMENT_NAMES`), its tetrahedra's and triangles' boundary as ``triangles``; ``what`` names the
    mesh in messages ("mesh file PATH"), ``source`` becomes the field's."""
    data = dict(mesh.point_data)
    found = ", ".join(f"{k!r} {np.shape(v)}" for k, v in data.items()) or "none"
    if field_name is not None:
        key = field_name if field_name in data else None
        if key is None:
            folded = [k for k in data if k.lower() == field_name.lower()]
            key = folded[0] if len(folded) == 1 else None
        if key is None:
            raise FieldError(
                f"{what} has no point field {field_name!r} (point fields: {found})"
                + _cell_hint(mesh, field_name))
    else:
        key = next((k for name in DISPLACEMENT_NAMES for k in data if k.lower() == name), None)
        if key is None:
            raise FieldError(
                f"{what} has no displacement point field named U, displacement, displacements or "
                f"DISP (point fields: {found}); name the field with {option('field_name')}")
    points = np.asarray(mesh.points, dtype=np.float64)
    values = np.asarray(data[key])
    if points.ndim == 2 and points.shape[1] == 2:  # a 2D mesh: z = 0
        points = np.column_stack([points, np.zeros(len(points))])
        if values.ndim == 2 and values.shape[1] == 2:
            values = np.column_stack([values, np.zeros(len(values))])
    if values.ndim != 2 or values.shape != (len(points), 3):
        raise FieldError(
            f"{what}: point field {key!r} has shape {values.shape}, but a displacement needs one "
            f"(x, y, z) vector per point: shape ({len(points)}, 3)")
    if values.dtype.kind not in "iuf":
        raise FieldError(f"{what}: point field {key!r} holds {values.dtype} values, not numbers")
    # The field's rows are meshio's points, in its order (none dropped): cells index them as they are.
    return DisplacementField(points, values, None, source=source, triangles=_mesh_triangles(mesh, source))


def _in_memory_mesh(field):
    """A ``meshio.Mesh`` of a field given as one or as a pyvista dataset (``pyvista.to_meshio``: PyMAPDL's and
    DPF's results as pyvista hands them over), None for anything else; recognised by the type's package, so that
    neither is imported for other inputs."""
    package = type(field).__module__.partition(".")[0]
    if package == "meshio" and hasattr(field, "point_data"):
        return field
    if package == "pyvista" and hasattr(field, "point_data"):
        import pyvista

        return pyvista.to_meshio(field)
    return None


def _mesh_triangles(mesh, source: str) -> np.ndarray | None:
    """The boundary triangles of a meshio mesh's cells (rows of its points), see :func:`element_triangles`;
    ``source`` names the mesh (its path)."""
    cells: dict[str, list] = {}
    for block in getattr(mesh, "cells", None) or []:
        cells.setdefault(str(block.type), []).append(block.data)
    unused = sorted(k for k in cells if k not in _ELEMENT_NAMES)
    if unused:
        log.info("mesh %s: cells of type %s not used (hot2cold takes tetrahedra and triangles)", source,
                 ", ".join(f"{k} ({sum(len(a) for a in cells[k])})" for k in unused))
    return element_triangles({k: v for k, v in cells.items() if k in _ELEMENT_NAMES}, source)


def _meshio_read(meshio, path: str, file_format: str | None):
    """``meshio`` reading ``path``, quietly.

    ``meshio.read`` prints its errors and calls ``sys.exit`` when no reader succeeds; here each candidate
    format's reader is called directly (``meshio._helpers.reader_map``, falling back to ``meshio.read``),
    with stdout and stderr captured (logged at debug level), and failures become one FieldError.
    """
    if file_format:
        formats = [file_format]
    else:
        name = os.path.basename(path).lower()
        formats = next((v for k, v in sorted(meshio.extension_to_filetypes.items(), key=lambda kv: -len(kv[0]))
                        if name.endswith(k)), [])
    if not formats:
        raise FieldError(f"cannot tell the mesh format of {path} from its name; use a .vtu, .vtk, .xdmf or .msh "
                         f"file")
    readers = getattr(getattr(meshio, "_helpers", None), "reader_map", {})
    problems = []
    sink = io.StringIO()
    try:
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            for fmt in formats:
                try:
                    reader = readers.get(fmt)
                    return reader(path) if reader is not None else meshio.read(path, file_format=fmt)
                except SystemExit:
                    problems.append(f"{fmt}: unreadable")
                except Exception as exc:  # meshio raises ReadError, KeyError, ValueError, ... on bad files
                    problems.append(f"{fmt}: {one_line(exc)}")
    finally:
        if sink.getvalue().strip():
            log.debug("meshio on %s: %s", path, " ".join(sink.getvalue().split()))
    raise FieldError(f"cannot read mesh file {path} with meshio ({'; '.join(problems)})")


def _cell_hint(mesh, name: str) -> str:
    cells = [k for k in getattr(mesh, "cell_data", {}) if k.lower() == name.lower()]
    return f"; {cells[0]!r} is cell data, hot2cold needs point (nodal) data" if cells else ""


def _decode(raw: bytes, path: str) -> str:
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return raw.decode("utf-16")
        except UnicodeDecodeError:
            pass
    if b"\x00" in raw:
        raise FieldError(
            f"field file {path} is binary, neither a text table nor an .npz file; "
            f"export the field as CSV with columns x,y,z,dx,dy,dz")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        # Numbers and column names are ASCII; other text (ignored columns, comments) may be anything.
        return raw.removeprefix(b"\xef\xbb\xbf").decode("latin-1")


def _split(line: str, delim: str | None) -> list[str]:
    """The fields of ``line`` (already free of comments): stripped, without quotes."""
    if delim is None:
        return [f.strip(_QUOTES) for f in line.split()]
    return [f.strip().strip(_QUOTES).strip() for f in line.split(delim)]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _delimiter(header: str) -> str | None:
    if "," in header:
        return ","
    if ";" in header:
        return ";"
    return None


def _delim_name(delim: str | None) -> str:
    return {",": "comma-separated", ";": "semicolon-separated", "\t": "tab-separated",
            None: "whitespace-separated"}[delim]


def _n(count: int, noun: str) -> str:
    return f"{count} {noun}" + ("" if count == 1 else "s")


def _short(text: str, n: int = 60) -> str:
    text = text.strip()
    return text if len(text) <= n else text[: n - 3] + "..."


#: A whitespace-separated header's names: a quoted name may hold spaces (``"Node Label"``).
_WORDS = re.compile(r"\"[^\"]*\"|'[^']*'|\S+")


def _header_names(content: str, delim: str | None, first_data: str | None) -> list[str]:
    """The column names of the header line ``content`` as written, separated by ``delim``.  Separated by
    whitespace, a name may be quoted (``"Node Label"``); where the names are more than the fields of the first
    data line ``first_data`` (a name with a space in it, ``Node Label``), runs of two or more spaces or a tab
    separate them when that gives as many (solvers' reports align their columns so)."""
    if delim is not None:
        return _split(content, delim)
    plain = [f.strip(_QUOTES) for f in _WORDS.findall(content)]
    fields = None if first_data is None else len(first_data.split())
    if fields is None or len(plain) <= fields:
        return plain
    wide = [f.strip(_QUOTES) for f in re.split(r"\s{2,}|\t", content.strip()) if f]
    if 1 < len(wide) == fields:
        return wide
    return _joined(plain, len(plain) - fields)


def _joined(names: list[str], extra: int) -> list[str]:
    """``names`` with up to ``extra`` pairs of neighbours joined by a space where together they are a column name
    hot2cold knows (``Node`` ``Label`` -> ``Node Label``, :data:`~hot2cold.io.columns.ALIASES`, ``ID_COLUMNS``)."""
    known = {*ID_COLUMNS, *(name for names_ in ALIASES.values() for name in names_)}
    out: list[str] = []
    for name in names:
        if extra and out and normalise(f"{out[-1]} {name}")[0] in known and normalise(name)[0] not in known:
            out[-1] = f"{out[-1]} {name}"
            extra -= 1
        else:
            out.append(name)
    return out


def _first_data(lines: list[str], after: int) -> str | None:
    """The first line after line ``after`` that holds anything but a comment, without its comment."""
    for line in lines[after + 1:]:
        content = line.partition("#")[0].strip()
        if content:
            return content
    return None


def _fits(shown: list[str], path: str, mapping) -> bool:
    """Whether the header names ``shown`` give every column (:func:`hot2cold.io.columns.assign`)."""
    try:
        assign(shown, path, mapping)
    except FieldError:
        return False
    return True


def _find_header(lines: list[str], path: str, mapping) -> tuple[int, list[str], str | None]:
    """(index of the first data line, the column names as written (:func:`_header_names`), delimiter)."""
    for h, line in enumerate(lines):
        content = line.partition("#")[0].strip()
        if content:
            break
    else:
        raise FieldError(
            f"field file {path} has no header and no data; {HINT}, followed by one line per FE node")
    delim = _delimiter(content)
    if delim is None and "\t" in content and not _fits(_split(content, None), path, mapping):
        delim = "\t"          # tab-separated names with spaces in them (ANSYS Mechanical's "X Location (mm)")
    if not all(_is_number(n) for n in _split(content, delim)):
        return h + 1, _header_names(content, delim, _first_data(lines, h)), delim
    # The first line holds numbers: a header may have been written as a comment (numpy.savetxt).
    for c in range(h - 1, -1, -1):
        text = lines[c].strip()
        if not text.startswith("#"):
            continue
        text = text.lstrip("#").strip()
        cdelim = _delimiter(text)
        shown = _header_names(text, cdelim, content)
        if not _fits(shown, path, mapping):
            break
        return h, shown, cdelim
    raise FieldError(
        f"field file {path} has no header line: line {h + 1} ({_short(content)!r}) holds numbers; "
        f"add a first line naming the columns, e.g. {','.join(REQUIRED_COLUMNS)}")


def _parse_text(raw: bytes, path: str, mapping=None) -> tuple[DisplacementField, dict[str, str | None]]:
    """The field of a text table in the length units its header states, and those units (``{"points": unit,
    "displacements": unit}``, None where it states none); ``mapping`` names columns
    (:func:`hot2cold.io.columns.parse_mapping`)."""
    text = _decode(raw, path)
    if not text.strip():
        raise FieldError(
            f"field file {path} is empty; it needs a header line naming {','.join(REQUIRED_COLUMNS)} "
            f"and one line per FE node")
    lines = text.splitlines()
    start, shown, delim = _find_header(lines, path, mapping)   # the names as written, for messages
    names = [normalise(n)[0] for n in shown]
    found = assign(shown, path, mapping, _delim_name(delim))
    cols, id_col = list(found.cols), found.id_col
    ncols = len(names)

    # Data lines: comments cut, blank lines dropped; line numbers kept for messages.
    body = lines[start:]
    if text.count("#") > sum(ln.count("#") for ln in lines[:start]):
        body = [ln.partition("#")[0] for ln in body]
    if "" in body or any(map(str.isspace, body)):
        keep = [i for i, ln in enumerate(body) if ln.strip()]
        data = [body[i] for i in keep]
        lineno = np.asarray(keep, dtype=np.int64) + (start + 1)
    else:
        data = body
        lineno = np.arange(start + 1, start + 1 + len(body), dtype=np.int64)
    if not data:
        raise FieldError(
            f"field file {path} has a header but no data lines; add one line per FE node "
            f"({', '.join(shown)})")
    if delim in (";", "\t"):
        data = [ln.replace(",", ".") for ln in data]  # decimal comma, as Excel and ANSYS write it in many locales

    # Numbers, by numpy's C parser; if it fails, a line-by-line pass names the first bad line.  When every
    # column is needed, loadtxt itself insists on the same number of fields on every line; otherwise the
    # fields are counted per line first (cheaper than parsing columns nobody needs).
    needed = cols + ([] if id_col is None else [id_col])
    if len(needed) != ncols:
        _check_field_counts(data, lineno, delim, ncols, path)
    values = ids = None
    try:
        table = np.loadtxt(data, delimiter=delim, usecols=None if len(needed) == ncols else needed,
                           dtype=np.float64, comments=None, ndmin=2, encoding=None)
        if table.shape == (len(data), ncols if len(needed) == ncols else len(needed)):
            if len(needed) == ncols:
                table = table[:, needed]
            values = table[:, :6]
            ids = table[:, 6] if id_col is not None else None
    except Exception:
        pass
    if values is None:
        if len(needed) == ncols:
            _check_field_counts(data, lineno, delim, ncols, path)
        try:
            values = np.loadtxt(data, delimiter=delim, usecols=cols, dtype=np.float64, comments=None,
                                ndmin=2, encoding=None)
            if values.shape != (len(data), 6):
                raise ValueError(f"parsed shape {values.shape}")
        except Exception as exc:
            # numpy names the (0-based) row it stopped at: check that one first, to spare a slow pass.
            m = re.search(r"at row (\d+)", str(exc))
            if m and int(m.group(1)) < len(data):
                k = int(m.group(1))
                _parse_slow(data[k:k + 1], lineno[k:k + 1], delim, cols, shown, path)
            values = _parse_slow(data, lineno, delim, cols, shown, path)
        if id_col is not None:
            ids = _parse_ids(data, delim, id_col)

    finite = np.isfinite(values)
    if not finite.all():
        nbad = int((~finite).sum())
        r, c = np.argwhere(~finite)[0]
        raise FieldError(
            f"field file {path} has {nbad} NaN or inf value(s), the first on line {int(lineno[r])} "
            f"(column {shown[cols[c]]!r}: {values[r, c]}); the field must be finite: "
            f"fix or remove those lines")

    node_ids = None
    if ids is not None:
        if np.all(np.isfinite(ids)) and np.all(ids == np.round(ids)) and np.all(np.abs(ids) <= 2.0 ** 53):
            node_ids = ids.astype(np.int64)
        else:
            log.warning("field file %s: column %r does not hold integers; node ids ignored",
                        path, shown[id_col])
    elif id_col is not None:
        log.warning("field file %s: column %r is not numeric; node ids ignored", path, shown[id_col])

    field = DisplacementField(values[:, :3], values[:, 3:], node_ids, source=path)
    return field, {"points": found.point_unit, "displacements": found.displacement_unit}


def _check_field_counts(data, lineno, delim, ncols, path) -> None:
    """Raise if a line has more or fewer fields than the header."""
    if delim is None:
        counts = np.fromiter(map(len, map(str.split, data)), dtype=np.int64, count=len(data))
    else:
        counts = np.fromiter(map(str.count, data, itertools.repeat(delim)), dtype=np.int64,
                             count=len(data)) + 1
    bad = np.flatnonzero(counts != ncols)
    if bad.size:
        k = int(bad[0])
        more = f" ({bad.size} lines like it)" if bad.size > 1 else ""
        split = ("; a column name with a space in it (Node Label) counts as two in a whitespace-separated "
                 "header: quote it, or separate the names by tabs, commas or two spaces"
                 if delim is None and bad.size == len(data) and 1 < counts[k] < ncols else "")
        raise FieldError(
            f"field file {path} line {int(lineno[k])} has {_n(int(counts[k]), 'field')} but the header has "
            f"{ncols} ({_delim_name(delim)}){more}{split}; give every line one value per header column")


def _parse_slow(data, lineno, delim, cols, names, path) -> np.ndarray:
    """The required columns, line by line; raise naming the first line and column that is no number."""
    values = np.empty((len(data), 6), dtype=np.float64)
    for k, ln in enumerate(data):
        fields = _split(ln, delim)
        for j, c in enumerate(cols):
            tok = fields[c]
            try:
                values[k, j] = float(tok)
            except ValueError:
                what = "is empty" if not tok else f"has {_short(tok, 30)!r}, which is not a number"
                raise FieldError(
                    f"field file {path} line {int(lineno[k])}, column {names[c]!r} {what}; "
                    f"fix or remove that line") from None
    return values


def _parse_ids(data, delim, id_col) -> np.ndarray | None:
    """The id column as floats, or None if it is not numeric."""
    try:
        return np.loadtxt(data, delimiter=delim, usecols=(id_col,), dtype=np.float64, comments=None,
                          ndmin=1, encoding=None)
    except Exception:
        try:
            return np.array([float(_split(ln, delim)[id_col]) for ln in data], dtype=np.float64)
        except ValueError:
            return None
