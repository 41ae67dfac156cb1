"""Triangle meshes of a shape's faces, for pictures and viewers (ParaView, STL, glTF).

Faces are numbered as everywhere in the project (:func:`.topology.shape_map`).  The mesh is OCCT's
``BRepMesh_IncrementalMesh`` of a *copy* of the shape, so the caller's shape keeps no triangulation; each
face's triangles are oriented with the face (outward on a solid) and carry their face's index and the
``(u, v)`` parameters of their vertices on the face's surface.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepBuilderAPI import BRepBuilderAPI_Copy
from OCP.BRepMesh import BRepMesh_IncrementalMesh
from OCP.TopAbs import TopAbs_FACE, TopAbs_REVERSED
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Shape

from ..errors import KernelError
from .explore import diagonal, shape_map

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class TriangleMesh:
    """A triangulated shape.

    Attributes
    ----------
    vertices : (n, 3) float array, mm.
    triangles : (m, 3) int array, vertex indices, counter-clockwise seen from outside.
    face : (m,) int array, the face each triangle belongs to.
    uv : (n, 2) float array, parameters of each vertex on its face's surface.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    face: np.ndarray
    uv: np.ndarray


def tessellate(shape: TopoDS_Shape, deflection: float | None = None, angle_deg: float = 10.0) -> TriangleMesh:
    """Triangulate every face of ``shape``.

    Parameters
    ----------
    shape : the shape (not modified).
    deflection : largest distance (mm) between a triangle and its surface; default 1e-3 of the shape's
        bounding-box diagonal.
    angle_deg : largest angle between neighbouring triangles' normals.

    Raises
    ------
    KernelError : a face got no triangulation.
    """
    work = BRepBuilderAPI_Copy(shape).Shape()
    if deflection is None:
        deflection = 1e-3 * diagonal(work)
    BRepMesh_IncrementalMesh(work, float(deflection), False, float(np.radians(angle_deg)), True)
    vertices, triangles, faces, uvs = [], [], [], []
    offset = 0
    for k, face_shape in enumerate(shape_map(work, TopAbs_FACE)):
        face = TopoDS.Face_s(face_shape)
        loc = TopLoc_Location()
        tri = BRep_Tool.Triangulation_s(face, loc)
        if tri is None:
            raise KernelError(f"face {k} could not be triangulated")
        trsf = loc.Transformation()
        n = tri.NbNodes()
        pts = np.array([tri.Node(i).Transformed(trsf).Coord() for i in range(1, n + 1)])
        uv = (np.array([tri.UVNode(i).Coord() for i in range(1, n + 1)]) if tri.HasUVNodes()
              else np.full((n, 2), np.nan))
        tris = np.array([tri.Triangle(i).Get() for i in range(1, tri.NbTriangles() + 1)], dtype=np.int64) - 1
        if face.Orientation() == TopAbs_REVERSED:
            tris = tris[:, ::-1]
        vertices.append(pts)
        uvs.append(uv)
        triangles.append(tris + offset)
        faces.append(np.full(len(tris), k))
        offset += n
    if not vertices:
        raise KernelError("the shape has no faces to triangulate")
    mesh = TriangleMesh(np.concatenate(vertices), np.concatenate(triangles), np.concatenate(faces),
                        np.concatenate(uvs))
    log.info("tessellated %d faces: %d vertices, %d triangles", len(vertices), len(mesh.vertices),
             len(mesh.triangles))
    return mesh
