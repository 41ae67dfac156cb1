"""Accepting the user's shapes (path, CadQuery object or raw ``TopoDS_Shape``) and handing back CadQuery ones.

CadQuery (slow to import, with VTK) is imported only when a CadQuery shape is asked for: a shape the user
passes in is one only if CadQuery is loaded already.
"""
from __future__ import annotations

import os
import sys

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
    cq = sys.modules.get("cadquery")     # not loaded: ``hot`` cannot be one of its objects
    if cq is not None:
        if isinstance(hot, cq.Shape):
            return hot.wrapped
        if isinstance(hot, cq.Workplane):
            return cq.Compound.makeCompound([o for o in hot.vals() if isinstance(o, cq.Shape)]).wrapped
        if isinstance(hot, cq.Assembly):
            return hot.toCompound().wrapped
    raise InputError(f"cannot morph a {type(hot).__name__}: give a STEP path or a CadQuery shape")


def to_cadquery(shape: TopoDS_Shape):
    """``shape`` as the matching ``cadquery.Shape`` subclass (Solid, Compound, ...)."""
    import cadquery as cq

    return cq.Shape.cast(shape)
