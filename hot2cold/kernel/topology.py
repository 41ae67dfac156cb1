"""Decomposing a solid into B-spline faces, shared edges and vertices.

The input is converted to B-spline form (planes, cylinders, cones, tori, fillets and surfaces of revolution
included; :mod:`hot2cold.kernel.conversion`) and copied: ``hot`` is the converted part, ``work`` its copy
whose faces and edges the morph projects onto; neither is changed by the morph, whose rebuild
(:mod:`hot2cold.kernel.rebuild`) writes the cold geometry into a further copy of ``work``.  Every face keeps
its edges by reference, so the two faces of a shared edge see the very same edge before and after the
morph: this is what keeps the cold solid watertight.

The conversion normalises the geometry so that the numeric core can treat it uniformly: periodic surfaces and
curves become non-periodic, and every surface and edge curve is clamped (end poles on the boundary); an edge
curve is cut to the edge's range, so its end poles are its vertices (the premise of eq. 10).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepBuilderAPI import BRepBuilderAPI_Copy
from OCP.BRepTools import BRepTools
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_FORWARD, TopAbs_SOLID, TopAbs_VERTEX
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopoDS import TopoDS, TopoDS_Shape

from ..errors import InputError, KernelError
from ..core.model import Edge, EdgeUse, Face, Part
from .conversion import to_bspline
from .convert import curve_to_record, surface_to_record
from .explore import bspline_curve, bspline_surface, diagonal, index_map, shape_map
from .faults import face_label, solid_faults

log = logging.getLogger(__name__)


@dataclass(eq=False)
class KernelPart:
    """The kernel side of a :class:`~hot2cold.core.model.Part` (opaque to the numeric core), as loaded: the morph
    does not change it (the cold part is a :class:`~hot2cold.kernel.rebuild.ColdKernel`).

    ``faces``, ``edges`` and ``vertices`` are shapes of ``work`` in the part's numbering; ``surfaces`` and
    ``curves`` are their geometry handles with the location that places them (``None`` for degenerate
    edges).  ``hot_faces`` and ``hot_edges`` are the same shapes in ``hot``.
    """

    source: TopoDS_Shape
    hot: TopoDS_Shape
    work: TopoDS_Shape
    faces: list
    edges: list
    vertices: list
    surfaces: list
    curves: list
    hot_faces: list
    hot_edges: list


def _edge_parameters(curve_record, per_span: int) -> np.ndarray:
    """Parameters ``(m,)`` on an edge curve: ``per_span`` intervals in every knot span, ends included."""
    breaks = np.unique(curve_record.knots[curve_record.degree:curve_record.n_poles + 1])
    pieces = [np.linspace(a, b, per_span + 1)[:-1] for a, b in zip(breaks[:-1], breaks[1:])]
    return np.concatenate(pieces + [breaks[-1:]])


def _open(solid) -> bool:
    """Whether ``solid`` has free edges (an open shell, which BRepCheck refuses too)."""
    from .validity import free_edges     # validity builds on this module

    return free_edges(solid) > 0


def _refuse_broken(shape: TopoDS_Shape) -> None:
    """Raise :class:`InputError` naming the first face at fault of the first solid of ``shape`` that the kernel
    finds invalid as given; nothing when every solid is valid."""
    message = broken_solid(shape)
    if message:
        raise InputError(message)


def broken_solid(shape: TopoDS_Shape) -> str | None:
    """"hot solid S is not valid: face F (Plane, near (x, y, z) mm): <BRepCheck statuses>" for the first solid of
    ``shape`` that ``BRepCheck_Analyzer`` refuses, or None when every solid is valid."""
    for s, solid in enumerate(shape_map(shape, TopAbs_SOLID)):
        if _open(solid):     # named as open by check_hot
            continue
        faults = solid_fault(shape, s)
        if faults:
            return f"hot solid {s} is not valid: {faults}"
    return None


def solid_fault(shape: TopoDS_Shape, s: int) -> str | None:
    """What ``BRepCheck_Analyzer`` finds wrong with solid ``s`` of ``shape``: "face F (Plane, near (x, y, z) mm):
    <statuses>" for the first face at fault, "(and N more)" for the others; None when the solid is valid.
    Faces are numbered as in ``shape``."""
    faces = index_map(shape, TopAbs_FACE)
    solid = shape_map(shape, TopAbs_SOLID)[s]
    faults = solid_faults(solid, [(faces.FindIndex(f) - 1, f) for f in shape_map(solid, TopAbs_FACE)])
    if not faults:
        return None
    return f"{faults[0]}" + (f" (and {len(faults) - 1} more)" if len(faults) > 1 else "")


def decompose(shape: TopoDS_Shape, samples_per_span: int = 4) -> Part:
    """Decompose ``shape`` (a solid or a compound of solids) into a :class:`~hot2cold.core.model.Part`.

    ``samples_per_span`` sets how densely each edge's pcurve is sampled in every knot span of its curve.
    """
    solids = shape_map(shape, TopAbs_SOLID)
    if not solids:
        raise KernelError("the shape holds no solid")
    try:
        hot = to_bspline(shape)
    except KernelError:
        _refuse_broken(shape)     # a broken input is named as such, not as a failure of the conversion
        raise
    work = BRepBuilderAPI_Copy(hot, True, False).Shape()     # hot and work share parameterisations exactly

    faces = shape_map(work, TopAbs_FACE)
    edges = shape_map(work, TopAbs_EDGE)
    vertices = shape_map(work, TopAbs_VERTEX)
    face_ids = index_map(work, TopAbs_FACE)
    edge_ids = index_map(work, TopAbs_EDGE)
    vertex_ids = index_map(work, TopAbs_VERTEX)

    vertex_points = np.array([[p.X(), p.Y(), p.Z()] for p in (BRep_Tool.Pnt_s(v) for v in vertices)])

    curves, edge_records = [], []
    for edge in edges:
        if BRep_Tool.Degenerated_s(edge):
            curves.append(None)
            edge_records.append(None)
            continue
        curve, trsf = bspline_curve(edge)
        curves.append((curve, trsf))
        edge_records.append(curve_to_record(curve, trsf))

    edge_faces: list[list[int]] = [[] for _ in edges]
    surfaces, face_records = [], []
    for k, face in enumerate(faces):
        surface, trsf = bspline_surface(face)
        surfaces.append((surface, trsf))
        record = surface_to_record(surface, trsf)
        u_lo, u_hi, v_lo, v_hi = record.domain
        uses = []
        explorer = TopExp_Explorer(face, TopAbs_EDGE)
        while explorer.More():
            edge = TopoDS.Edge_s(explorer.Current())
            e = edge_ids.FindIndex(edge) - 1
            if k not in edge_faces[e]:
                edge_faces[e].append(k)
            first, last = BRep_Tool.Range_s(edge, face)
            if edge_records[e] is not None:
                t = _edge_parameters(edge_records[e], samples_per_span)
            else:
                t = np.linspace(first, last, 2 * samples_per_span + 1)
            pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
            if pcurve is None:
                raise KernelError(f"edge {e} of face {k} has no curve on the face")
            # pcurves of boolean results may overshoot the surface's domain by a hair: clip to it
            uv = np.array([[p.X(), p.Y()] for p in (pcurve.Value(float(x)) for x in t)])
            uv = np.clip(uv, [u_lo, v_lo], [u_hi, v_hi])
            uses.append(EdgeUse(edge=e, t=t, uv=uv))
            explorer.Next()
        box = np.array(BRepTools.UVBounds_s(face))
        box = np.clip(box, [u_lo, u_lo, v_lo, v_lo], [u_hi, u_hi, v_hi, v_hi])
        face_records.append((record, box, tuple(uses)))

    solid_of_face = np.full(len(faces), -1)
    solid_faces = []
    for s, solid in enumerate(shape_map(work, TopAbs_SOLID)):     # work's solids: its faces are numbered
        members = tuple(face_ids.FindIndex(f) - 1 for f in shape_map(solid, TopAbs_FACE))
        solid_faces.append(members)
        solid_of_face[list(members)] = s

    edge_list = []
    for e, edge in enumerate(edges):
        forward = edge.Oriented(TopAbs_FORWARD)
        v0 = vertex_ids.FindIndex(TopExp.FirstVertex_s(TopoDS.Edge_s(forward))) - 1
        v1 = vertex_ids.FindIndex(TopExp.LastVertex_s(TopoDS.Edge_s(forward))) - 1
        edge_list.append(Edge(index=e, curve=edge_records[e], vertices=(v0, v1), faces=tuple(edge_faces[e])))

    face_list = [Face(index=k, surface=rec, uv_box=box, uses=uses, solid=int(solid_of_face[k]))
                 for k, (rec, box, uses) in enumerate(face_records)]
    kernel = KernelPart(source=shape, hot=hot, work=work, faces=faces, edges=edges, vertices=vertices,
                        surfaces=surfaces, curves=curves, hot_faces=shape_map(hot, TopAbs_FACE),
                        hot_edges=shape_map(hot, TopAbs_EDGE))
    log.info("decomposed %d solid(s): %d faces, %d edges, %d vertices",
             len(solids), len(faces), len(edges), len(vertices))
    source_faces = shape_map(shape, TopAbs_FACE)       # as read: its planes are planes yet
    labels = tuple(face_label(f) for f in source_faces) if len(source_faces) == len(faces) else ()
    return Part(faces=face_list, edges=edge_list, vertices=vertex_points, solids=solid_faces,
                diagonal=diagonal(shape), kernel=kernel, face_labels=labels)
