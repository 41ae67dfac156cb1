"""The options of a morph, in one table: :class:`MorphOptions`.

``hot2cold morph`` takes them as flags (``--field-units m``), a batch jobs file as columns or keys
(``field_units``, also written ``field-units``); both come from the fields of :class:`MorphOptions`, whose
metadata (an :class:`Option`) holds the flag, metavar, help text and the converter of a jobs-file value.
The command-line guide's usage block and the batch guide's list of options (``docs/guide/``) name the same
options (a test compares them); the docs' options reference is made from this table.

A new option is one field here (with its :class:`Option`), its use in :meth:`MorphOptions.to_settings` or
:meth:`MorphOptions.morph_arguments`, and a word in ``docs/guide/cli.md``.

Library code: nothing here prints; a bad value raises :class:`~hot2cold.errors.InputError` (options) or
``ValueError`` (a converter: the words that follow the option's name in the message).
"""
from __future__ import annotations

import argparse
import os
import re
from dataclasses import dataclass, field, fields
from enum import Enum
from pathlib import Path
from typing import Callable

from ..errors import InputError
from ..io.field import UNITS
from ..settings import MORPH_KEYWORDS, OPTION_WORDS, Continuity, Settings


# --------------------------------------------------------------------------------------------------------
# Converters of jobs-file values: a CSV cell (text, stripped) or a TOML value -> the option's value.
# Each takes the jobs file's folder (for paths) and raises ValueError("must be ..., got ...").
# --------------------------------------------------------------------------------------------------------
def to_path(value, folder: Path) -> Path:
    """An absolute path; a relative one is taken relative to ``folder`` (the jobs file's)."""
    if not isinstance(value, str):
        raise ValueError(f"must be a path (text), got {value!r}")
    return Path(os.path.abspath(folder / Path(value).expanduser()))


def to_text(value, folder: Path) -> str:
    if not isinstance(value, str):
        raise ValueError(f"must be text, got {value!r}")
    return value


def to_units(value, folder: Path) -> str:
    key = str(value).strip().lower()
    if key not in UNITS:
        raise ValueError(f"must be one of {', '.join(UNITS)}, got {value!r}")
    return key


def to_flag(value, folder: Path) -> bool:
    if isinstance(value, bool):
        return value
    word = str(value).strip().lower()
    if word in ("1", "true", "yes", "y", "on"):
        return True
    if word in ("0", "false", "no", "n", "off"):
        return False
    raise ValueError(f"must be true or false, got {value!r}")


def _float(value, must: str) -> float:
    """``value`` as a float (not a bool); ``ValueError("must be <must>, got ...")`` otherwise."""
    try:
        if isinstance(value, bool):
            raise ValueError
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(f"must be {must}, got {value!r}") from None


def to_number(value, folder: Path) -> float:
    return _float(value, "a number (mm)")


def to_share(value, folder: Path) -> float:
    """A positive number, a share (of the part's diagonal)."""
    must = "a positive number (a share of the part's diagonal)"
    share = _float(value, must)
    if not share > 0:
        raise ValueError(f"must be {must}, got {value!r}")
    return share


#: The values of ``--continuity`` (:class:`~hot2cold.settings.Continuity`).
CONTINUITIES = tuple(c.value for c in Continuity)


def to_continuity(value, folder: Path) -> str:
    key = str(value).strip().lower()
    if key not in CONTINUITIES:
        raise ValueError(f"must be one of {', '.join(CONTINUITIES)}, got {value!r}")
    return key


def to_count(value, folder: Path) -> int:
    try:
        if isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
            raise ValueError
        return int(value)
    except (TypeError, ValueError):
        raise ValueError(f"must be a whole number, got {value!r}") from None


# --------------------------------------------------------------------------------------------------------
# The table
# --------------------------------------------------------------------------------------------------------
class OptionGroup(Enum):
    """The groups of ``hot2cold morph --help`` the options are listed in (the value: the group's title)."""

    FIELD = "the field: which data of the file, in what unit"
    ACCURACY = "accuracy and checks"


@dataclass(frozen=True)
class Option:
    """How one morph option is given.

    flag : the ``hot2cold morph`` flag (``--`` and the field's name with ``-`` for ``_``).
    group : the :class:`OptionGroup` ``--help`` lists it in.
    help : argparse's help text (a ``%`` written ``%%``).
    convert : a jobs-file value -> the option's value (``value, folder``; ValueError when unusable).
    type : argparse's converter of the flag's argument; None for a switch (``store_true``).
    metavar, choices : as argparse's.
    """

    flag: str
    group: OptionGroup
    help: str
    convert: Callable
    type: Callable | None = None
    metavar: str | None = None
    choices: tuple[str, ...] | None = None


def _option(default, *, flag: str, group: OptionGroup, convert: Callable, help: str, **more):
    """A field of :class:`MorphOptions`: its default and its :class:`Option` as metadata."""
    return field(default=default, metadata={"option": Option(flag=flag, group=group, help=help, convert=convert,
                                                             **more)})


@dataclass(frozen=True)
class MorphOptions:
    """The options of one morph, as ``hot2cold morph`` and a batch job take them (None: the default of
    :class:`~hot2cold.settings.Settings`).  Lengths in mm.  The fields' order is the order of ``--help``,
    of the jobs-file messages and of a batch record's ``options``."""

    field_units: str | None = _option(
        None, flag="--field-units", group=OptionGroup.FIELD, convert=to_units, type=str, choices=tuple(sorted(UNITS)),
        help="length unit of the field file (default: the unit the file states, as an ANSYS .rst or a column "
        "'X Location (m)' does, else mm)")
    field_name: str | None = _option(
        None, flag="--field-name", group=OptionGroup.FIELD, convert=to_text, type=str, metavar="NAME",
        help="which displacements to take: the point field of a VTK/VTU file (default: U, displacement or DISP), "
        "the dataset of an .frd (DISP) or its block by step number as CGX lists it ('step 3'), the result set of "
        "an ANSYS .rst (LS,SUB) or the subcase of a Nastran .op2/.pch (its id); default the last; the report "
        "names the set taken")
    field_step: int | None = _option(
        None, flag="--field-step", group=OptionGroup.FIELD, convert=to_count, type=int, metavar="N",
        help="which result set of a solver results file (.frd, .rst, .op2, .pch), counting from 0 in file "
        "order, negative from the end (default: the last)")
    columns: str | None = _option(
        None, flag="--columns", group=OptionGroup.FIELD, convert=to_text, type=str, metavar="MAP",
        help="which columns of a text field hold what, e.g. 'x=X Location,y=Y Location,z=Z Location,dx=UX,"
        "dy=UY,dz=UZ' (keys x y z dx dy dz id; names as in the header, any case); the others are found by their "
        "usual names")
    field_points: Path | None = _option(
        None, flag="--field-points", group=OptionGroup.FIELD, convert=to_path, type=Path, metavar="FILE",
        help="where the node positions of a results file without them come from (.pch; .op2 without geometry; "
        ".frd for full precision): the Nastran model (.bdf, .dat, .nas: its GRID cards) or a field file with "
        "node ids, matched by node number")
    invert: bool = _option(
        False, flag="--invert", group=OptionGroup.FIELD, convert=to_flag,
        help="the field goes cold to hot (at the hot mesh's nodes): invert it by fixed-point iteration")
    tolerance: float | None = _option(
        None, flag="--tolerance", group=OptionGroup.ACCURACY, convert=to_number, type=float, metavar="MM",
        help="largest accepted error, at the nodes and between them (default 0.001, the paper's aerofoil "
        "accuracy; widened by the field's own scatter): where it is missed, faces and edges are refined (knot "
        "insertion, degree raised to cubic; the hot shape is kept) and fitted again; exit code 5 when it "
        "still is not met")
    keep_knots: bool = _option(
        False, flag="--keep-knots", group=OptionGroup.ACCURACY, convert=to_flag,
        help="keep every degree and knot vector of the hot part (the paper's strict mode): nothing is refined; "
        "the tolerance is still checked (exit code 5 when it is not met)")
    max_refinements: int | None = _option(
        None, flag="--max-refinements", group=OptionGroup.ACCURACY, convert=to_count, type=int, metavar="N",
        help=f"rounds of refinement to the tolerance at the most (default {Settings.max_refinements})")
    node_distance: float | None = _option(
        None, flag="--node-distance", group=OptionGroup.ACCURACY, convert=to_number, type=float, metavar="MM",
        help="nodes farther than this from every face are ignored (default 0.1%% of the part size)")
    edge_distance: float | None = _option(
        None, flag="--edge-distance", group=OptionGroup.ACCURACY, convert=to_number, type=float, metavar="MM",
        help="nodes this close to an edge feed the edge (default 0.01%% of the part size)")
    extrapolate: bool = _option(
        False, flag="--extrapolate", group=OptionGroup.ACCURACY, convert=to_flag,
        help="morph faces that get no FE node from the field of the other faces, extrapolated (with a "
        "warning); without it such a field is refused")
    nodes_only: bool = _option(
        False, flag="--nodes-only", group=OptionGroup.ACCURACY, convert=to_flag,
        help="use the field's nodes alone, not the FE elements it brings (.frd, VTU cells, an .npz with "
        "triangles): by default the field is also taken inside the boundary elements by their shape functions")
    continuity: str = _option(
        "g1", flag="--continuity", group=OptionGroup.ACCURACY, convert=to_continuity, type=str, choices=CONTINUITIES,
        help="g1 (default): the tangent planes restored along edges where the hot faces met tangentially; g2: "
        "also their curvature across edges where it was continuous when hot (jump within 1%% of the curvature)")
    max_displacement_rel: float | None = _option(
        None, flag="--max-displacement-rel", group=OptionGroup.ACCURACY, convert=to_share, type=float, metavar="SHARE",
        help="largest node displacement accepted, as a share of the part's diagonal (default 0.1): a field "
        "that moves the part farther is refused as no hot-to-cold field (cold positions given as "
        "displacements, another part's field)")

    @staticmethod
    def names() -> tuple[str, ...]:
        """The options' names, in the table's order (the jobs-file columns and keys)."""
        return tuple(f.name for f in fields(MorphOptions))

    @staticmethod
    def table() -> dict[str, Option]:
        """Every option's :class:`Option` by name, in the table's order."""
        return {f.name: f.metadata["option"] for f in fields(MorphOptions)}

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the options' flags to ``parser`` (the ``hot2cold morph`` parser), in the table's order, each in
        the argument group of its :class:`OptionGroup`."""
        groups = {g: parser.add_argument_group(g.value) for g in OptionGroup}
        for f in fields(MorphOptions):
            opt: Option = f.metadata["option"]
            if opt.type is None:
                groups[opt.group].add_argument(opt.flag, action="store_true", help=opt.help)
            else:
                groups[opt.group].add_argument(opt.flag, type=opt.type, default=f.default, metavar=opt.metavar,
                                               choices=opt.choices, help=opt.help)

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> MorphOptions:
        """The options of a parsed ``hot2cold morph`` command line."""
        return cls(**{name: getattr(args, name) for name in cls.names()})

    def to_settings(self) -> Settings:
        """:class:`~hot2cold.settings.Settings` from these options (None: the default); :class:`InputError`
        on a bad value."""
        try:
            given = {name: value for name, value in (("max_refinements", self.max_refinements),
                                                      ("max_displacement_rel", self.max_displacement_rel))
                     if value is not None}
            if self.tolerance is not None:
                given["tolerance"] = self.tolerance
            return Settings(node_distance=self.node_distance, edge_distance=self.edge_distance,
                            keep_knots=self.keep_knots, extrapolate=self.extrapolate,
                            element_points=not self.nodes_only, continuity=self.continuity, **given)
        except ValueError as exc:
            raise InputError(str(exc)) from exc

    def morph_arguments(self) -> dict:
        """The keyword arguments of :func:`~hot2cold.pipeline.morph.morph` that are not in the settings."""
        return {"units": self.field_units, "field_name": self.field_name, "field_step": self.field_step,
                "columns": self.columns, "field_points": self.field_points, "invert": self.invert}

    def as_dict(self) -> dict:
        """The options as JSON-ready values, in the table's order (a batch record's ``options``, hashed for
        skip-on-rerun: its keys and values must not change for the same options)."""
        return {name: str(value) if isinstance(value, Path) else value
                for name, value in ((name, getattr(self, name)) for name in self.names())}


def _plain(value: str) -> str:
    """A value as Python's ``repr`` wrote it (:func:`hot2cold.settings.option`), as a command line or a jobs file
    writes it: without quotes, ``true`` for ``True``."""
    if len(value) > 1 and value[0] == value[-1] and value[0] in "'\"":
        return value[1:-1]
    return value.lower() if value in ("True", "False") else value


def in_words(text: str, jobs: bool = False) -> str:
    """``text``, a message of the library, with each option it names in Python's words
    (:func:`hot2cold.settings.option`: ``morph(units='m')``, ``Settings(extrapolate=True)``) said as ``hot2cold
    morph`` takes it (``--field-units m``, ``--extrapolate``, the FIELD argument) or, with ``jobs``, as a batch
    jobs file does (``field_units = m`` in the jobs file).  A setting the command line does not take keeps
    Python's words."""
    table = MorphOptions.table()
    by_python = {("morph", keyword): name for name, keyword in MORPH_KEYWORDS.items()}
    by_python.update({("Settings", name): name for name in table if name not in MORPH_KEYWORDS})

    def say(match: re.Match) -> str:
        api, keyword, value = match.groups()
        name = by_python.get((api, keyword))
        if name is None:
            return match.group(0)
        shown = None if value == "..." else _plain(value)
        if jobs:
            return f"the jobs file's {name} column" if shown is None else f"{name} = {shown} in the jobs file"
        if name == "field":
            return "the FIELD argument"
        opt = table[name]
        return opt.flag if shown is None or opt.type is None else f"{opt.flag} {shown}"

    return re.sub(OPTION_WORDS, say, text)
