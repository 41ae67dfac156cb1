"""Exports of a morph for viewers: ParaView (VTU), STL and glTF (GLB).

* :func:`write_vtu` writes two files: ``NODES.vtu``, the FE nodes at their hot positions with their
  displacement, error, role and owner as point data (one vertex cell per node), and ``NODES_surface.vtu``
  (:func:`surface_path`), the cold part's surface as triangles with the face index as cell data and the
  hot-to-cold displacement at each surface vertex as point data.  Two files rather than two cell blocks of
  one file, because VTU point data covers every point of a file: in one file the nodes' arrays would have
  to be padded over the surface vertices (and the other way round), so colouring by ``error`` would paint
  the surface NaN.  Each file opens on its own in ParaView; "Warp By Vector" with ``displacement``
  takes the nodes to their cold targets (on the cold surface), and with scale -1 the cold surface back to
  the hot one.
* :func:`write_stl` (mm) and :func:`write_glb` (metres, Y up, as glTF asks) write the cold part's
  triangles with their vertices merged across faces.

Every file is written whole or not at all (a temporary file in the target folder, then renamed); a
failure raises :class:`OutputError` and leaves nothing behind.
"""
from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.arrays import distinct
from ..core.bspline import clip_uv, evaluate_surface
from ..io.atomic import write_atomically

log = logging.getLogger(__name__)

#: glTF's frame: metres, Y up.  CAD's Z-up millimetres map as (x, y, z) -> (x, z, -y) / 1000.
GLTF_FROM_CAD = np.array([[1.0, 0.0, 0.0, 0.0],
                          [0.0, 0.0, 1.0, 0.0],
                          [0.0, -1.0, 0.0, 0.0],
                          [0.0, 0.0, 0.0, 1.0]]) @ np.diag([1e-3, 1e-3, 1e-3, 1.0])


@dataclass(frozen=True, eq=False)
class ColdSurface:
    """The cold part's surface as triangles (vertices not merged: each face has its own).

    Attributes
    ----------
    vertices : (n, 3) float array, mm.
    triangles : (m, 3) int array, counter-clockwise seen from outside.
    face : (m,) int array, the face of each triangle (numbered as the hot part's faces).
    uv : (n, 2) float array, each vertex's parameters on its face's surface (hot and cold alike).
    displacement : (n, 3) float array, hot -> cold at each vertex: ``S_cold(u, v) - S_hot(u, v)`` (NaN
        where a vertex has no parameters).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    face: np.ndarray
    uv: np.ndarray
    displacement: np.ndarray


def points_on_faces(surfaces: list, mesh) -> np.ndarray:
    """Each vertex of a triangle ``mesh`` (:class:`hot2cold.kernel.tessellate.TriangleMesh`) at its ``(u, v)``
    on the surface of its face: ``(n, 3)``, with ``surfaces`` one BSplineSurface per face (the hot ones, the
    cold ones: the morph keeps each face's parameterisation, so one mesh's ``(u, v)`` serve both).  The
    parameters are clipped to the surface's domain; rows are NaN where a vertex has no ``(u, v)`` or is in
    no triangle."""
    vertex_face = np.full(len(mesh.vertices), -1)
    vertex_face[mesh.triangles] = mesh.face[:, None]
    points = np.full(mesh.vertices.shape, np.nan)
    for k in distinct(mesh.face):
        idx = np.flatnonzero((vertex_face == k) & np.isfinite(mesh.uv).all(axis=1))
        if len(idx):
            uv = clip_uv(surfaces[k], mesh.uv[idx])
            points[idx] = evaluate_surface(surfaces[k], uv[:, 0], uv[:, 1])
    return points


def cold_surface(result, deflection: float | None = None) -> ColdSurface:
    """Triangulate the cold part of a :class:`~hot2cold.morph.MorphResult` and give each vertex the
    displacement of its ``(u, v)`` from the hot surface to the cold one (:func:`points_on_faces`).

    ``deflection``: largest distance (mm) between a triangle and its face (default 1e-3 of the part's
    bounding-box diagonal).
    """
    from ..kernel.tessellate import tessellate

    mesh = tessellate(result.cold_kernel.shape, deflection)
    displacement = (points_on_faces([fm.surface for fm in result.faces], mesh)
                    - points_on_faces([face.surface for face in result.part.faces], mesh))
    return ColdSurface(mesh.vertices, mesh.triangles, mesh.face, mesh.uv, displacement)


def surface_path(path: str | os.PathLike) -> Path:
    """The surface file that goes with the nodes file ``path``: ``NODES.vtu`` -> ``NODES_surface.vtu``."""
    path = Path(path)
    return path.with_name(f"{path.stem}_surface{path.suffix or '.vtu'}")


def node_mesh(result):
    """The FE nodes as a :class:`meshio.Mesh`: hot positions, one vertex cell each, and point data
    ``displacement`` (hot -> cold, mm), ``error`` (eq. 21, mm; NaN where ignored), ``role`` (-1 ignored,
    0 face, 1 edge, 2 vertex: :class:`hot2cold.core.model.Role`), ``owner`` (the face, edge or vertex; -1 where
    ignored) and ``node_id`` (when the field has ids)."""
    import meshio

    field, cls = result.field, result.classification
    n = len(field.points)
    data = {"displacement": np.asarray(field.displacements, dtype=np.float64),
            "error": np.asarray(result.node_errors, dtype=np.float64),
            "role": np.asarray(cls.role, dtype=np.int32),
            "owner": np.asarray(cls.owner, dtype=np.int32)}
    if field.node_ids is not None:
        data["node_id"] = np.asarray(field.node_ids, dtype=np.int64)
    return meshio.Mesh(np.asarray(field.points, dtype=np.float64),
                       [("vertex", np.arange(n, dtype=np.int64).reshape(-1, 1))], point_data=data)


def surface_mesh(surface: ColdSurface):
    """The cold surface as a :class:`meshio.Mesh`: triangles with cell data ``face``, point data
    ``displacement`` (hot -> cold, mm) and ``uv``."""
    import meshio

    return meshio.Mesh(surface.vertices, [("triangle", np.asarray(surface.triangles, dtype=np.int64))],
                       point_data={"displacement": surface.displacement, "uv": surface.uv},
                       cell_data={"face": [np.asarray(surface.face, dtype=np.int32)]})


def write_vtu(result, path: str | os.PathLike, surface: ColdSurface | None = None) -> tuple[Path, Path]:
    """Write the nodes to ``path`` and the cold surface to :func:`surface_path` ``(path)`` (VTU, binary,
    zlib); returns both paths.  ``surface`` saves a second triangulation when one is at hand."""
    import meshio

    path = Path(path)
    other = surface_path(path)
    surface = surface if surface is not None else cold_surface(result)
    nodes, tris = node_mesh(result), surface_mesh(surface)
    write_atomically([(path, lambda tmp: meshio.write(tmp, nodes, file_format="vtu")),
                       (other, lambda tmp: meshio.write(tmp, tris, file_format="vtu"))])
    log.info("wrote %s (%d nodes) and %s (%d triangles)", path, len(nodes.points), other, len(surface.triangles))
    return path, other


def to_trimesh(surface: ColdSurface):
    """The cold surface as a :class:`trimesh.Trimesh` with vertices merged across faces (mm)."""
    import trimesh

    mesh = trimesh.Trimesh(surface.vertices, surface.triangles, process=True)
    mesh.merge_vertices()
    if not mesh.is_watertight:
        log.warning("the cold part's triangles are not watertight once merged (%d vertices, %d triangles)",
                    len(mesh.vertices), len(mesh.faces))
    return mesh


def write_stl(result, path: str | os.PathLike, surface: ColdSurface | None = None) -> Path:
    """Write the cold part as a binary STL (mm) to ``path``."""
    path = Path(path)
    mesh = to_trimesh(surface if surface is not None else cold_surface(result))
    write_atomically([(path, lambda tmp: mesh.export(tmp, file_type="stl"))])
    log.info("wrote %s (%d triangles, volume %.6g mm³)", path, len(mesh.faces), mesh.volume)
    return path


def write_glb(result, path: str | os.PathLike, surface: ColdSurface | None = None) -> Path:
    """Write the cold part as binary glTF to ``path``: metres and Y up, as glTF asks (:data:`GLTF_FROM_CAD`)."""
    path = Path(path)
    mesh = to_trimesh(surface if surface is not None else cold_surface(result))
    mesh.apply_transform(GLTF_FROM_CAD)
    write_atomically([(path, lambda tmp: mesh.export(tmp, file_type="glb"))])
    log.info("wrote %s (%d triangles, in metres, Y up)", path, len(mesh.faces))
    return path
