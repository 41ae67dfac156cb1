"""Checks of a solid: kernel validity, free edges, volume."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from OCP.BRep import BRep_Tool
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.BRepGProp import BRepGProp
from OCP.GProp import GProp_GProps
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_SOLID
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopTools import TopTools_IndexedMapOfShape
from OCP.TopoDS import TopoDS

from .topology import shape_map


@dataclass(frozen=True)
class SolidCheck:
    """Checks of one solid: ``valid`` (BRepCheck_Analyzer), ``free_edges`` (edges used by one face only),
    ``faces`` count and ``volume`` in mm^3."""

    valid: bool
    free_edges: int
    faces: int
    volume: float

    @property
    def closed(self) -> bool:
        return self.free_edges == 0


def free_edges(shape) -> int:
    """Number of non-degenerate edges of ``shape`` that bound exactly one face occurrence (a seam edge
    bounds its face twice)."""
    edges = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, TopAbs_EDGE, edges)
    count = np.zeros(edges.Size() + 1, int)
    faces = TopExp_Explorer(shape, TopAbs_FACE)
    while faces.More():
        explorer = TopExp_Explorer(faces.Current(), TopAbs_EDGE)
        while explorer.More():
            count[edges.FindIndex(explorer.Current())] += 1
            explorer.Next()
        faces.Next()
    return sum(1 for i in range(1, edges.Size() + 1)
               if count[i] == 1 and not BRep_Tool.Degenerated_s(TopoDS.Edge_s(edges.FindKey(i))))


def volume(shape) -> float:
    """Volume of ``shape`` in mm^3."""
    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props)
    return float(props.Mass())


def check_solids(shape) -> list[SolidCheck]:
    """One :class:`SolidCheck` per solid of ``shape``."""
    out = []
    for solid in shape_map(shape, TopAbs_SOLID):
        out.append(SolidCheck(valid=bool(BRepCheck_Analyzer(solid).IsValid()), free_edges=free_edges(solid),
                              faces=len(shape_map(solid, TopAbs_FACE)), volume=volume(solid)))
    return out
