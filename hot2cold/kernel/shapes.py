"""Accepting the user's shapes (a path, a CadQuery or build123d object, a raw ``TopoDS_Shape``) and handing the
parts back in the library the user's hot part came from.

CadQuery (slow to import, with VTK) is imported only when a CadQuery shape is asked for, and a shape the user
passes in is a CadQuery or build123d one only if that library is loaded already.  build123d needs an OCP build
without VTK, which CadQuery's cannot stand beside in one environment: its objects are taken where build123d
and CadQuery share one OCP (build123d 0.10 with CadQuery 2.7, both on OCP 7.8).
"""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from enum import Enum

from OCP.TopAbs import TopAbs_SOLID
from OCP.TopoDS import TopoDS_Shape

from ..errors import InputError
from .explore import shape_map
from .step import read_step


class ShapeLibrary(Enum):
    """The library whose objects the parts are handed back as."""

    CADQUERY = "cadquery"
    BUILD123D = "build123d"


class Build123dKind(Enum):
    """The build123d class a cold part is handed back as: the hot part's, or its nearest base class that
    takes a shape (a ``Box`` is a ``Part``)."""

    SOLID = "Solid"
    PART = "Part"
    COMPOUND = "Compound"


@dataclass(frozen=True)
class ShapeType:
    """What the user's hot part was, so that the cold one comes back as the same: the library and, for
    build123d, the class (CadQuery's parts come back as the ``cadquery.Shape`` subclass of their kernel
    shape)."""

    library: ShapeLibrary = ShapeLibrary.CADQUERY
    kind: Build123dKind | None = None


def as_topods(hot) -> TopoDS_Shape:
    """The ``TopoDS_Shape`` of ``hot``: a STEP path, a ``cadquery.Shape``, ``cadquery.Workplane`` or
    ``cadquery.Assembly``, a ``build123d.Shape`` (a ``Solid``, ``Part`` or ``Compound``) or ``BuildPart``, or a
    ``TopoDS_Shape``."""
    if isinstance(hot, (str, os.PathLike)):
        return read_step(hot)
    if isinstance(hot, TopoDS_Shape):
        return hot
    cq = sys.modules.get("cadquery")     # not loaded: ``hot`` cannot be one of its objects
    if cq is not None:
        if isinstance(hot, cq.Shape):
            return hot.wrapped
        if isinstance(hot, cq.Workplane):
            return cq.Compound.makeCompound([o for o in hot.vals() if isinstance(o, cq.Shape)]).wrapped
        if isinstance(hot, cq.Assembly):
            return hot.toCompound().wrapped
    b3d = sys.modules.get("build123d")
    if b3d is not None:
        shape = hot.part if isinstance(hot, b3d.BuildPart) else hot
        if isinstance(shape, b3d.Shape) and shape.wrapped is not None:
            return shape.wrapped
        if shape is not hot or isinstance(shape, b3d.Shape):
            raise InputError(f"the build123d {type(hot).__name__} holds no shape: build the part first")
    raise InputError(f"cannot morph a {type(hot).__name__}: give a STEP path, a CadQuery or build123d shape, "
                     f"or a TopoDS_Shape")


def shape_type(hot) -> ShapeType:
    """The library (and class) the parts morphed from ``hot`` are handed back in: build123d's for its objects,
    CadQuery's for everything else."""
    b3d = sys.modules.get("build123d")
    if b3d is None or not isinstance(hot, (b3d.Shape, b3d.BuildPart)):
        return ShapeType()
    if isinstance(hot, b3d.BuildPart) or isinstance(hot, b3d.Part):
        kind = Build123dKind.PART
    elif isinstance(hot, b3d.Solid):
        kind = Build123dKind.SOLID
    else:
        kind = Build123dKind.COMPOUND
    return ShapeType(ShapeLibrary.BUILD123D, kind)


def to_user_shape(shape: TopoDS_Shape, kind: ShapeType):
    """``shape`` (a solid or a compound of solids) as an object of the library ``kind`` names."""
    if kind.library is ShapeLibrary.CADQUERY:
        import cadquery as cq

        return cq.Shape.cast(shape)
    import build123d as b3d

    solids = [b3d.Solid(solid) for solid in shape_map(shape, TopAbs_SOLID)]
    if kind.kind is Build123dKind.SOLID and len(solids) == 1:
        return solids[0]
    return (b3d.Part if kind.kind is Build123dKind.PART else b3d.Compound)(solids)
