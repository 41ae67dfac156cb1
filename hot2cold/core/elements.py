"""The FE model's own interpolation on its boundary: linear (3-node) and quadratic (6-node) triangles.

A field that brings its elements knows the displacement between its nodes: the solver's shape functions
give it, element by element.  The boundary of a tetrahedral mesh is the triangles that no second
tetrahedron shares (:func:`boundary_triangles`); a point is located on its nearest triangle by Gauss-Newton
on the curved triangle (:func:`project_to_triangles`, :class:`SurfaceInterpolator`), and the field there is
the shape functions' blend of the triangle's nodal values.

Node order, as VTK, CalculiX and Abaqus number them (gmsh's 10-node tetrahedron swaps the last two
midside nodes; :data:`GMSH_TO_TET10` converts):

* 3-node triangle: corners 0, 1, 2 at parameters ``(s, t)`` = (0, 0), (1, 0), (0, 1);
* 6-node triangle: the corners, then the midside nodes of the edges 0-1, 1-2, 2-0;
* 4-node tetrahedron: corners 0..3; 10-node: the corners, then the midside nodes of the edges
  0-1, 1-2, 2-0, 0-3, 1-3, 2-3.
"""
from __future__ import annotations

import numpy as np

__all__ = ["TRIANGLE_SAMPLES", "GMSH_TO_TET10", "shape_functions", "shape_derivatives", "boundary_triangles",
           "project_to_triangles", "SurfaceInterpolator", "sample_triangles"]

#: Parameters ``(4, 2)`` of the points sampled inside each triangle: the centres of the four triangles that
#: halving its edges makes.  With the nodes (corners and midside nodes of a quadratic triangle) they cover
#: it at about a quarter of its edge length.
TRIANGLE_SAMPLES = np.array([[1 / 6, 1 / 6], [2 / 3, 1 / 6], [1 / 6, 2 / 3], [1 / 3, 1 / 3]])

#: gmsh's 10-node tetrahedron -> the VTK/CalculiX order (the midside nodes of edges 2-3 and 1-3 swapped).
GMSH_TO_TET10 = np.array([0, 1, 2, 3, 4, 5, 6, 7, 9, 8])

#: The four faces of a tetrahedron: corners, then the midside nodes of their edges a-b, b-c, c-a (VTK order).
_TET_FACES = np.array([[0, 1, 2, 4, 5, 6],
                       [0, 1, 3, 4, 8, 7],
                       [0, 2, 3, 6, 9, 7],
                       [1, 2, 3, 5, 9, 8]])


def shape_functions(st: np.ndarray, nodes: int = 6) -> np.ndarray:
    """The shape functions ``(m, nodes)`` of the 3- or 6-node triangle at parameters ``st`` ``(m, 2)``.

    With ``L = (1 - s - t, s, t)``: ``L_i`` for the linear triangle; ``L_i (2 L_i - 1)`` at the corners and
    ``4 L_i L_j`` at the midside nodes for the quadratic one.
    """
    st = np.asarray(st, dtype=np.float64).reshape(-1, 2)
    s, t = st[:, 0], st[:, 1]
    r = 1.0 - s - t
    if nodes == 3:
        return np.stack([r, s, t], axis=1)
    return np.stack([r * (2 * r - 1), s * (2 * s - 1), t * (2 * t - 1), 4 * r * s, 4 * s * t, 4 * t * r], axis=1)


def shape_derivatives(st: np.ndarray, nodes: int = 6) -> np.ndarray:
    """Derivatives ``(m, nodes, 2)`` of :func:`shape_functions` by ``s`` and ``t`` at ``st`` ``(m, 2)``."""
    st = np.asarray(st, dtype=np.float64).reshape(-1, 2)
    s, t = st[:, 0], st[:, 1]
    if nodes == 3:
        return np.tile(np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]]), (len(s), 1, 1))
    r = 1.0 - s - t
    zero = np.zeros_like(s)
    ds = np.stack([1 - 4 * r, 4 * s - 1, zero, 4 * (r - s), 4 * t, -4 * t], axis=1)
    dt = np.stack([1 - 4 * r, zero, 4 * t - 1, -4 * s, 4 * s, 4 * (r - t)], axis=1)
    return np.stack([ds, dt], axis=2)


def boundary_triangles(tets: np.ndarray) -> np.ndarray:
    """The boundary of a tetrahedral mesh: the faces no second tetrahedron shares.

    ``tets`` ``(M, 4)`` or ``(M, 10)`` node indices in VTK order -> triangles ``(T, 3)`` or ``(T, 6)`` (corners,
    then midside nodes), in the order of the tetrahedra.
    """
    tets = np.asarray(tets, dtype=np.int64)
    if tets.ndim != 2 or tets.shape[1] not in (4, 10):
        raise ValueError(f"tetrahedra must have shape (M, 4) or (M, 10), got {tets.shape}")
    corners_only = tets.shape[1] == 4
    faces = tets[:, _TET_FACES[:, :3] if corners_only else _TET_FACES].reshape(-1, 3 if corners_only else 6)
    key = np.sort(faces[:, :3], axis=1)
    _, first, count = np.unique(key, axis=0, return_index=True, return_counts=True)
    return faces[np.sort(first[count == 1])]


def _clamp(st: np.ndarray) -> np.ndarray:
    """Parameters ``(m, 2)`` moved into the triangle ``s, t >= 0, s + t <= 1``."""
    st = np.maximum(st, 0.0)
    over = st.sum(axis=1) - 1.0
    st = st - np.where(over > 0, 0.5 * over, 0.0)[:, None]
    st = np.maximum(st, 0.0)
    return st / np.maximum(st.sum(axis=1), 1.0)[:, None]


def _flat_parameters(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Parameters ``(m, 2)`` of the foot points of ``points`` ``(m, 3)`` on the straight triangles of
    ``corners`` ``(m, 3, 3)``, moved into the triangle."""
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    d = points - corners[:, 0]
    a11, a12, a22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    b1, b2 = (d * e1).sum(1), (d * e2).sum(1)
    det = a11 * a22 - a12 * a12
    det = np.where(det > 0, det, np.inf)
    return _clamp(np.stack([(a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det], axis=1))


def project_to_triangles(points: np.ndarray, xyz: np.ndarray, steps: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Foot points of ``points`` ``(m, 3)`` on triangles with node positions ``xyz`` ``(m, 3 or 6, 3)`` (one
    triangle per point): ``(st (m, 2), distance (m,))``.

    Starts from the straight corner triangle, exact for a linear one; a quadratic one then gets ``steps``
    Gauss-Newton steps on the curved triangle, each kept inside it.
    """
    nodes = xyz.shape[1]
    st = _flat_parameters(points, xyz[:, :3])
    for _ in range(steps if nodes == 6 else 0):
        x = np.einsum("mi,mij->mj", shape_functions(st), xyz)
        jac = np.einsum("mik,mij->mjk", shape_derivatives(st), xyz)            # (m, 3, 2)
        jtj = np.einsum("mjk,mjl->mkl", jac, jac)
        jtr = np.einsum("mjk,mj->mk", jac, points - x)
        det = jtj[:, 0, 0] * jtj[:, 1, 1] - jtj[:, 0, 1] ** 2
        det = np.where(det > 0, det, np.inf)
        step = np.stack([jtj[:, 1, 1] * jtr[:, 0] - jtj[:, 0, 1] * jtr[:, 1],
                         jtj[:, 0, 0] * jtr[:, 1] - jtj[:, 0, 1] * jtr[:, 0]], axis=1) / det[:, None]
        st = _clamp(st + step)
    x = np.einsum("mi,mij->mj", shape_functions(st, nodes), xyz)
    return st, np.linalg.norm(points - x, axis=1)


def sample_triangles(nodes: np.ndarray, triangles: np.ndarray, values: np.ndarray,
                     st: np.ndarray = TRIANGLE_SAMPLES) -> tuple[np.ndarray, np.ndarray]:
    """Points inside every triangle and the field there, by the triangles' own shape functions.

    ``nodes`` ``(N, 3)`` positions, ``triangles`` ``(T, 3 or 6)`` node rows, ``values`` ``(N, k)`` nodal values,
    ``st`` ``(s, 2)`` parameters -> positions ``(T s, 3)`` and values ``(T s, k)``, triangle by triangle.
    """
    shape = shape_functions(st, triangles.shape[1])                            # (s, n)
    positions = np.einsum("si,tij->tsj", shape, nodes[triangles]).reshape(-1, 3)
    blended = np.einsum("si,tij->tsj", shape, values[triangles]).reshape(-1, values.shape[1])
    return positions, blended


class SurfaceInterpolator:
    """A nodal field on boundary triangles, interpolated with their shape functions at any point near them.

    Parameters
    ----------
    nodes : (N, 3) node positions, mm.
    triangles : (T, 3) or (T, 6) boundary triangles (:func:`boundary_triangles`).
    values : (N, k) nodal values (e.g. displacements, k = 3).
    candidates : int, triangles tried per point (nearest centres); :data:`WIDER` for the points left farther
        than :data:`FAR` mm from all of them.
    """

    #: A point farther than this (mm) from its best candidate is searched again among :data:`WIDER`.
    FAR = 1e-2
    WIDER = 64
    #: Points per batch (memory: about 1 kB per point and candidate).
    CHUNK = 20_000

    def __init__(self, nodes: np.ndarray, triangles: np.ndarray, values: np.ndarray, candidates: int = 8):
        from scipy.spatial import cKDTree

        self.nodes = np.asarray(nodes, dtype=np.float64)
        self.triangles = np.asarray(triangles, dtype=np.int64)
        self.values = np.asarray(values, dtype=np.float64)
        self.candidates = min(int(candidates), len(self.triangles))
        self._tree = cKDTree(self.nodes[self.triangles[:, :3]].mean(axis=1))

    def locate(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For ``points`` ``(m, 3)``: the triangle ``(m,)`` each one's foot point is on, its parameters
        ``(m, 2)`` and the distance ``(m,)`` mm."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        tri, st, dist = (np.zeros(len(points), dtype=np.int64), np.zeros((len(points), 2)),
                         np.full(len(points), np.inf))
        for lo in range(0, len(points), self.CHUNK):
            part = slice(lo, lo + self.CHUNK)
            tri[part], st[part], dist[part] = self._best(points[part], self.candidates)
        far = np.flatnonzero(dist > self.FAR)
        if len(far) and self.WIDER > self.candidates:
            t2, s2, d2 = self._best(points[far], min(self.WIDER, len(self.triangles)))
            better = d2 < dist[far]
            tri[far[better]], st[far[better]], dist[far[better]] = t2[better], s2[better], d2[better]
        return tri, st, dist

    def _best(self, points: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The nearest foot point of each of ``points`` ``(m, 3)`` among its ``k`` candidate triangles."""
        _, cand = self._tree.query(points, k=k)
        cand = cand.reshape(len(points), k)
        xyz = self.nodes[self.triangles[cand.ravel()]]                          # (m k, 3 or 6, 3)
        st, dist = project_to_triangles(np.repeat(points, k, axis=0), xyz)
        best = np.argmin(dist.reshape(-1, k), axis=1)
        pick = np.arange(len(points)) * k + best
        return cand.ravel()[pick], st[pick], dist[pick]

    def at(self, tri: np.ndarray, st: np.ndarray) -> np.ndarray:
        """Values ``(m, k)`` on triangles ``tri`` ``(m,)`` at parameters ``st`` ``(m, 2)``."""
        shape = shape_functions(st, self.triangles.shape[1])
        return np.einsum("mi,mij->mj", shape, self.values[self.triangles[tri]])

    def position(self, tri: np.ndarray, st: np.ndarray) -> np.ndarray:
        """Positions ``(m, 3)`` on triangles ``tri`` ``(m,)`` at parameters ``st`` ``(m, 2)``."""
        shape = shape_functions(st, self.triangles.shape[1])
        return np.einsum("mi,mij->mj", shape, self.nodes[self.triangles[tri]])

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Values ``(m, k)`` at the foot points of ``points`` ``(m, 3)`` on the boundary."""
        tri, st, _ = self.locate(points)
        return self.at(tri, st)
