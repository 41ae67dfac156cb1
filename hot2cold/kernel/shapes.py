"""Accepting the user's shapes (path, CadQuery object or raw ``TopoDS_Shape``) and handing back CadQuery ones."""
from __future__ import annotations

import os

import cadquery as cq
from OCP.TopoDS import TopoDS_Shape

from ..errors import InputError
from .step import read_step


def as_topods(hot) -> TopoDS_Shape:
    """The ``TopoDS_Shape`` of ``hot``: a STEP path, a ``cadquery.Shape``, a ``cadquery.Workplane`` or
    ``cadquery.Assembly``, or a ``TopoDS_Shape``."""
    if isinstance(hot, (str, os.PathLike)):
        return read_step(hot)
    if isinstance(hot, TopoDS_Shape):
        return hot
    if isinstance(hot, cq.Shape):
        return hot.wrapped
    if isinstance(hot, cq.Workplane):
        return cq.Compound.makeCompound([o for o in hot.vals() if isinstance(o, cq.Shape)]).wrapped
    if isinstance(hot, cq.Assembly):
        return hot.toCompound().wrapped
    raise InputError(f"cannot morph a {type(hot).__name__}: give a STEP path or a CadQuery shape")


def to_cadquery(shape: TopoDS_Shape) -> cq.Shape:
    """``shape`` as the matching ``cadquery.Shape`` subclass (Solid, Compound, ...)."""
    return cq.Shape.cast(shape)
