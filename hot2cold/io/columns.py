"""Which columns of a text table hold the node positions, the displacements and the node ids.

Solvers and post-processors name them in their own words: ``x, y, z, dx, dy, dz`` (hot2cold's own), ``ux,
uy, uz``, Abaqus reports' ``COORD1..3`` and ``U1..3`` (or ``U.U1``; Abaqus/CAE's CSV ``COORD-COORD1`` and
``U-U1``), ParaView's ``Points:0..2`` and ``U:0..2``, ANSYS Mechanical's ``X Location (mm)`` and
``Directional Deformation X (mm)``.  :func:`assign` finds the six columns among a header's names by the table
:data:`ALIASES`; a user's mapping (``--columns x=X Location,dx=UX``, :func:`parse_mapping`) names the ones the
table does not know or picks between two it does.

A unit written after a name, ``(mm)`` or ``[m]``, is the length unit the file states for that column
(:data:`STATED_UNITS`); the caller scales by it.

Column names are compared normalised (:func:`normalise`): lower case, the unit taken off, and runs of
spaces, dashes, dots and colons as one ``_`` (``U.U1`` -> ``u_u1``, ``Points:0`` -> ``points_0``).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Mapping

from ..errors import FieldError
from ..settings import option

#: The six columns of a field, in the order of :attr:`DisplacementField.points` and ``displacements``.
REQUIRED_COLUMNS = ("x", "y", "z", "dx", "dy", "dz")

#: Key of the node id column in a mapping (``--columns id=Node Number``).
ID_KEY = "id"

#: Column names taken as FE node ids (normalised).
ID_COLUMNS = ("id", "node", "node_id", "nodeid", "nid", "node_number", "node_label")

#: Length units a file may state in its column names, and the factor that takes them to millimetres.
STATED_UNITS = {"mm": 1.0, "m": 1000.0, "cm": 10.0, "um": 1e-3, "µm": 1e-3, "μm": 1e-3, "in": 25.4,
                "inch": 25.4, "ft": 304.8}


def _aliases() -> dict[str, tuple[str, ...]]:
    """Every normalised name taken for each of :data:`REQUIRED_COLUMNS`."""
    table = {}
    for i, a in enumerate("xyz"):
        n = i + 1
        table[a] = (a, f"{a}_location", f"location_{a}", f"{a}_coordinate", f"coordinate_{a}", f"{a}_coord",
                    f"coord_{a}", f"coord{n}", f"coor{n}", f"coord_coor{n}", f"coord_coord{n}", f"points_{i}",
                    f"point_{i}", f"node_{a}", f"{a}_node", f"hot_{a}", f"{a}0")
        table[f"d{a}"] = (f"d{a}", f"d_{a}", f"u{a}", f"u_{a}", f"u{n}", f"u_u{n}", f"u_{i}", f"disp_{a}",
                          f"disp{a}", f"displacement_{a}", f"{a}_displacement", f"deformation_{a}",
                          f"{a}_deformation", f"directional_deformation_{a}", f"displacement_{i}", f"disp_{i}",
                          f"displacements_{i}", f"t{n}")
    return table


#: Normalised column names taken for each of :data:`REQUIRED_COLUMNS` (first a header's own words, then
#: other solvers' and post-processors').
ALIASES = _aliases()

#: Names of a displacement's magnitude: no use without its components, so a header with one of them and no
#: components is told so.
MAGNITUDE_NAMES = ("total_deformation", "u_magnitude", "magnitude", "usum", "u_sum", "disp_magnitude",
                   "displacement_magnitude", "utotal")

_UNIT = re.compile(r"^(.*?)\s*[\(\[]\s*([^\)\]]*?)\s*[\)\]]\s*$")


def normalise(name: str) -> tuple[str, str | None]:
    """``(key, unit)`` of a column name as written: the name normalised (see the module docstring) and the
    text of a trailing ``(unit)`` or ``[unit]`` lower-cased (None without one)."""
    name = name.strip()
    unit = None
    m = _UNIT.match(name)
    if m and m.group(1):
        name, unit = m.group(1), m.group(2).strip().lower()
    return re.sub(r"[\s\-.:]+", "_", name.lower()).strip("_"), unit


def parse_mapping(mapping) -> dict[str, str]:
    """A user's column mapping as ``{key: normalised name}``, keys among :data:`REQUIRED_COLUMNS` and ``id``.

    ``mapping`` is text, ``"x=X Location,dx=UX"`` (pairs ``key=name`` separated by commas; names as written
    in the header, any case, with or without their unit), or a mapping of keys to names.  Raises
    ``ValueError`` saying what is wrong (the caller adds where it came from)."""
    if isinstance(mapping, str):
        pairs = []
        for part in mapping.split(","):
            if not part.strip():
                continue
            key, eq, name = part.partition("=")
            if not eq:
                raise ValueError(f"{part.strip()!r} is no key=name pair (e.g. x=X Location,dx=UX)")
            pairs.append((key, name))
    elif isinstance(mapping, Mapping):
        pairs = list(mapping.items())
    else:
        raise ValueError(f"must be text like 'x=X Location,dx=UX' or a mapping, got {type(mapping).__name__}")
    out: dict[str, str] = {}
    keys = (*REQUIRED_COLUMNS, ID_KEY)
    for key, name in pairs:
        key = str(key).strip().lower()
        if key not in keys:
            raise ValueError(f"unknown column key {key!r}: use {', '.join(keys)}")
        if not isinstance(name, str) or not name.strip():
            raise ValueError(f"column key {key!r} needs a column name after '='")
        if key in out:
            raise ValueError(f"column key {key!r} is given twice")
        out[key] = normalise(name)[0]
    if not out:
        raise ValueError("is empty: give pairs key=name, e.g. x=X Location,dx=UX")
    return out


@dataclass(frozen=True)
class Columns:
    """Where a table's data are: ``cols`` the column numbers (from 0) of :data:`REQUIRED_COLUMNS` in their
    order, ``id_col`` the node id column (or None), and the factors to mm of the positions and the
    displacements as the header states them (``point_unit``/``displacement_unit``: the unit written, None
    where the header states none)."""

    cols: tuple[int, ...]
    id_col: int | None
    point_unit: str | None
    displacement_unit: str | None


def assign(shown: list[str], path: str, mapping: Mapping[str, str] | None = None, layout: str = "") -> Columns:
    """The :class:`Columns` of a header whose names are ``shown`` (as written), by ``mapping`` (from
    :func:`parse_mapping`) where given, else by :data:`ALIASES` and :data:`ID_COLUMNS`; ``layout`` says how
    the header was split ("comma-separated"), for messages.

    Raises :class:`FieldError` naming ``path`` when a column is missing, found twice, or mapped to a name the
    header does not have, or when positions or displacements state different units among themselves."""
    parsed = [normalise(n) for n in shown]
    names = [k for k, _ in parsed]
    mapping = dict(mapping or {})
    for key, name in mapping.items():
        if name not in names:
            raise FieldError(f"field file {path}: {option('columns')} maps {key} to {name!r}, which the header does "
                             f"not have (header: {', '.join(map(repr, shown))})")
    found: dict[str, int] = {}
    for key in (*REQUIRED_COLUMNS, ID_KEY):
        if key in mapping:
            hits = [i for i, n in enumerate(names) if n == mapping[key]]
        else:
            words = ID_COLUMNS if key == ID_KEY else ALIASES[key]
            hits = [i for i, n in enumerate(names) if n in words and n not in mapping.values()]
        if len(hits) > 1 and names[hits[0]] == names[hits[1]]:
            raise FieldError(f"field file {path}: column {names[hits[0]]!r} appears twice in the header; keep "
                             f"one of them")
        if len(hits) > 1:
            raise FieldError(
                f"field file {path}: columns {' and '.join(repr(shown[i]) for i in hits)} both give {key}; "
                f"keep one, or choose with {option('columns', f'{key}=NAME')}")
        if hits:
            found[key] = hits[0]
    missing = [c for c in REQUIRED_COLUMNS if c not in found]
    if missing:
        found_text = ", ".join(map(repr, shown)) + (f", {layout}" if layout else "")
        raise FieldError(f"field file {path} lacks column(s) {', '.join(missing)} (header found: {found_text})"
                         f"{_magnitude_hint(names, shown, missing)}; {HINT}")
    cols = tuple(found[c] for c in REQUIRED_COLUMNS)
    return Columns(cols, found.get(ID_KEY), _group_unit(parsed, shown, cols[:3], "positions", path),
                   _group_unit(parsed, shown, cols[3:], "displacements", path))


#: What a text table's header must say, for messages.
HINT = ("the header must name the columns " + ",".join(REQUIRED_COLUMNS) + " (any order, any case; ux,uy,uz, "
        "U1,U2,U3, 'X Location (mm)' and the like also do), or map them with "
        + option("columns", "x=NAME,...,dz=NAME"))


def _magnitude_hint(names: list[str], shown: list[str], missing: list[str]) -> str:
    """Where displacement components are ``missing`` and the header has a magnitude column: that it cannot
    stand for them."""
    total = next((shown[i] for i, n in enumerate(names) if n in MAGNITUDE_NAMES), None)
    if total is None or not set(missing) & {"dx", "dy", "dz"}:
        return ""
    return (f"; {total!r} is the displacement's magnitude, which cannot move a point: export its three "
            f"components (Directional Deformation X, Y and Z, or U1, U2, U3)")


def _group_unit(parsed, shown, cols, what: str, path: str) -> str | None:
    """The one length unit stated by the columns ``cols`` (None if none states one); FieldError when they
    state different ones, or one that is no length unit."""
    units = {parsed[c][1] for c in cols if parsed[c][1] is not None}
    for unit in units:
        if unit not in STATED_UNITS:
            c = next(c for c in cols if parsed[c][1] == unit)
            raise FieldError(f"field file {path}: column {shown[c]!r} states the unit {unit!r}, which is no "
                             f"length unit hot2cold knows ({', '.join(STATED_UNITS)})")
    if len(units) > 1:
        raise FieldError(f"field file {path}: the {what} columns state different units "
                         f"({', '.join(sorted(units))}); export them in one unit")
    return units.pop() if units else None
