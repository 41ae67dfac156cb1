"""Checks of a solid: kernel validity, free edges, volume, self-intersection; what a STEP file holds."""
from __future__ import annotations

import logging
import os
from dataclasses import dataclass, replace

import numpy as np

from OCP.BOPAlgo import BOPAlgo_ArgumentAnalyzer, BOPAlgo_CheckStatus
from OCP.BRep import BRep_Tool
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.BRepExtrema import BRepExtrema_DistShapeShape
from OCP.BRepGProp import BRepGProp
from OCP.GProp import GProp_GProps
from OCP.IFSelect import IFSelect_RetDone
from OCP.STEPControl import STEPControl_Reader
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_SHELL, TopAbs_SOLID, TopAbs_VERTEX
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopTools import TopTools_IndexedMapOfShape
from OCP.TopoDS import TopoDS

from ..errors import KernelError
from .explore import index_map, shape_map

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SolidCheck:
    """Checks of one solid: ``valid`` (BRepCheck_Analyzer), ``free_edges`` (edges used by one face only),
    ``faces`` count and ``volume`` in mm^3 (None where not asked for: :func:`check_solids`)."""

    valid: bool
    free_edges: int
    faces: int
    volume: float | None

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


#: Relative accuracy asked of the kernel's adaptive integration of volumes and areas (``BRepGProp`` with an
#: ``Eps``).  Its default fixed Gauss rule is far off on spline solids (a lofted blade's volume by a large
#: share), far more than any strain changes a volume, so the volume checks would judge the rule's error.
GPROP_EPS = 1e-6
#: Relative accuracy asked of the same integration for the faces' areas (:func:`face_areas`): they weigh
#: shares of the part (the area measured, the nodes a face should hold), for which a per mille is plenty, and
#: on refined spline faces the integration to :data:`GPROP_EPS` takes several times as long.
AREA_EPS = 1e-3


def volume(shape) -> float:
    """Volume of ``shape`` in mm^3, to :data:`GPROP_EPS` (relative)."""
    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props, GPROP_EPS)
    return float(props.Mass())


def solid_volumes(shape) -> list[float]:
    """The volume (mm^3) of each solid of ``shape``, in :func:`~hot2cold.kernel.explore.shape_map`'s order
    (:func:`volume`)."""
    return [volume(solid) for solid in shape_map(shape, TopAbs_SOLID)]


def with_volumes(checks: list[SolidCheck], volumes: list[float]) -> list[SolidCheck]:
    """``checks`` (one per solid) with their ``volumes`` (mm^3, one per solid) filled in."""
    if len(volumes) != len(checks):
        raise KernelError(f"{len(volumes)} volumes for {len(checks)} solids")
    return [replace(c, volume=v) for c, v in zip(checks, volumes)]


def face_areas(faces) -> np.ndarray:
    """Areas ``(n,)`` in mm^2 of the faces ``faces`` (trimmed), to :data:`AREA_EPS` (relative)."""
    areas = np.empty(len(faces))
    for k, face in enumerate(faces):
        props = GProp_GProps()
        BRepGProp.SurfaceProperties_s(face, props, AREA_EPS)
        areas[k] = props.Mass()
    return areas


def check_solids(shape, volumes: bool = True) -> list[SolidCheck]:
    """One :class:`SolidCheck` per solid of ``shape``; without ``volumes``, their volumes are not integrated
    (None): on a part of many spline faces the integration to :data:`GPROP_EPS` takes seconds, and a check of
    validity alone does not need it."""
    checks = [SolidCheck(valid=bool(BRepCheck_Analyzer(solid).IsValid()), free_edges=free_edges(solid),
                         faces=len(shape_map(solid, TopAbs_FACE)), volume=None)
              for solid in shape_map(shape, TopAbs_SOLID)]
    return with_volumes(checks, solid_volumes(shape)) if volumes else checks


@dataclass(frozen=True)
class Intersection:
    """Two sub-shapes of a shape that intersect: ``kinds`` ("face", "edge" or "vertex") and ``indices`` in the
    project's numbering of the shape (:func:`.topology.shape_map`, 0-based); ``at``, a point where they meet
    (None for two that share a vertex)."""

    kinds: tuple[str, str]
    indices: tuple[int, int]
    at: tuple[float, float, float] | None = None

    def __str__(self) -> str:
        """E.g. "faces 2 and 5 intersect near (1, 2, 3) mm"."""
        (a, b), (i, j) = self.kinds, self.indices
        where = "" if self.at is None else f" near ({', '.join(f'{x:.4g}' for x in self.at)}) mm"
        return (f"{a} {i} and {b} {j}" if a != b else f"{a}s {i} and {j}") + " intersect" + where


_KINDS = {TopAbs_FACE: "face", TopAbs_EDGE: "edge", TopAbs_VERTEX: "vertex"}


def self_intersections(shape, touch: float) -> list[Intersection]:
    """Pairs of faces, edges or vertices of ``shape`` that intersect where they should not
    (``BOPAlgo_ArgumentAnalyzer``'s self-interference test).

    The analyzer counts sub-shapes whose tolerance zones overlap; a morph widens edge tolerances to the true
    edge-face gaps (:mod:`.tolerances`), and two such edges near each other are no intersection.  So a pair that
    shares no vertex counts only if it is less than ``touch`` (mm) apart (``BRepExtrema_DistShapeShape``);
    a pair that shares a vertex always counts (adjacent faces crossing beyond their common edge).
    """
    analyzer = BOPAlgo_ArgumentAnalyzer()
    analyzer.SetShape1(shape)
    analyzer.SelfInterMode = True
    try:
        analyzer.Perform()
    except Exception as exc:  # Standard_Failure
        raise KernelError(f"the self-intersection check of the cold part failed: {exc}") from exc
    if not analyzer.HasFaulty():
        return []
    maps = {kind: index_map(shape, kind) for kind in _KINDS}
    found: list[Intersection] = []
    for result in analyzer.GetCheckResult():
        if result.GetCheckStatus() != BOPAlgo_CheckStatus.BOPAlgo_SelfIntersect:
            continue
        subs = list(result.GetFaultyShapes1())
        if len(subs) != 2 or any(sub.ShapeType() not in _KINDS for sub in subs):
            continue
        a, b = subs
        at = None
        if not _share_vertex(a, b):
            distance = BRepExtrema_DistShapeShape(a, b)
            if not distance.IsDone() or distance.Value() > touch:
                log.debug("tolerance zones of %s and %s overlap, %.3g mm apart: not an intersection",
                          _KINDS[a.ShapeType()], _KINDS[b.ShapeType()], distance.Value())
                continue
            point = distance.PointOnShape1(1)
            at = (point.X(), point.Y(), point.Z())
        found.append(Intersection((_KINDS[a.ShapeType()], _KINDS[b.ShapeType()]),
                                  (maps[a.ShapeType()].FindIndex(a) - 1, maps[b.ShapeType()].FindIndex(b) - 1), at))
    return found


def _share_vertex(a, b) -> bool:
    va, vb = index_map(a, TopAbs_VERTEX), index_map(b, TopAbs_VERTEX)
    return any(vb.Contains(va.FindKey(i)) for i in range(1, va.Size() + 1))


def step_content(path: str | os.PathLike) -> str | None:
    """What a STEP file that holds no solid holds instead, as words for a message ("1 open shell of 5 faces
    (4 free edges)", "2 faces and no shell"), or None when it cannot be read or does hold a solid."""
    reader = STEPControl_Reader()
    try:
        if reader.ReadFile(str(path)) != IFSelect_RetDone or reader.TransferRoots() == 0:
            return None
        shape = reader.OneShape()
    except Exception:  # Standard_Failure on corrupt files
        return None
    if shape.IsNull() or len(shape_map(shape, TopAbs_SOLID)):
        return None
    shells = index_map(shape, TopAbs_SHELL)
    faces = len(shape_map(shape, TopAbs_FACE))
    if shells.Size():
        open_ = [free_edges(shells.FindKey(i)) for i in range(1, shells.Size() + 1)]
        n_open = sum(1 for f in open_ if f)
        what = (f"{shells.Size()} shell{'s' if shells.Size() > 1 else ''} of {faces} face{'s' if faces != 1 else ''}"
                + (f", {n_open} of them open ({sum(open_)} free edges)" if n_open and shells.Size() > 1
                   else f", open ({sum(open_)} free edges)" if n_open else ", closed"))
        return what
    if faces:
        return f"{faces} loose face{'s' if faces != 1 else ''}"
    edges = len(shape_map(shape, TopAbs_EDGE))
    return f"{edges} edge{'s' if edges != 1 else ''} and no face" if edges else "no face"
