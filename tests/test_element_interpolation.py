"""The FE interpolation (:mod:`hot2cold.core.elements`, which ``benchmarks/fe_fields.py`` measures against and
the morph samples fields inside their elements with) on two hand-made 10-node tetrahedra in gmsh's order.

* the boundary of two tetrahedra sharing a face is their other 6 faces, as 6-node triangles;
* an affine field is reproduced exactly at arbitrary points of the boundary, curved (a midside node moved off
  its edge) or not: the elements are isoparametric;
* a quadratic field is reproduced exactly on straight-sided tetrahedra, where it is quadratic in the
  triangles' parameters too; the nodal values themselves are reproduced at the nodes.
"""
from __future__ import annotations

import numpy as np
import pytest

from hot2cold.core import elements

#: gmsh's midside nodes 4..9 of a 10-node tetrahedron are on these edges.
EDGES = [(0, 1), (1, 2), (2, 0), (0, 3), (2, 3), (1, 3)]


class _Gmsh:
    """:mod:`hot2cold.core.elements` taking tetrahedra in gmsh's node order."""

    shape_functions = staticmethod(elements.shape_functions)
    SurfaceInterpolator = elements.SurfaceInterpolator

    @staticmethod
    def boundary_triangles(tets):
        return elements.boundary_triangles(tets[:, elements.GMSH_TO_TET10])


@pytest.fixture(scope="module")
def bench():
    return _Gmsh()


def two_tets(bulge: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Nodes ``(N, 3)`` and tetrahedra ``(2, 10)`` (gmsh order) of two tetrahedra sharing the face B, C, D;
    the midside node of the boundary edge A-B moved ``bulge`` mm off its edge (a curved boundary)."""
    corners = np.array([[0.0, 0.0, 0.0], [2.0, 0.1, 0.0], [0.2, 1.8, 0.1], [0.1, 0.3, 1.9], [2.1, 2.0, 1.7]])
    nodes, mids, tets = list(corners), {}, []
    for tet in ([0, 1, 2, 3], [1, 2, 3, 4]):
        row = list(tet)
        for a, b in EDGES:
            key = tuple(sorted((tet[a], tet[b])))
            if key not in mids:
                mids[key] = len(nodes)
                nodes.append(0.5 * (corners[key[0]] + corners[key[1]]))
            row.append(mids[key])
        tets.append(row)
    nodes = np.array(nodes)
    nodes[mids[(0, 1)]] += [0.0, -bulge, -bulge]           # away from the solid: the tetrahedron stays valid
    return nodes, np.array(tets)


def boundary_points(bench, nodes, triangles, n: int = 400, seed: int = 0) -> np.ndarray:
    """``n`` points ``(n, 3)`` at random parameters on random boundary triangles."""
    rng = np.random.default_rng(seed)
    tri = rng.integers(len(triangles), size=n)
    st = rng.random((n, 2))
    st = np.where(st.sum(axis=1, keepdims=True) > 1, 1 - st, st)
    return np.einsum("mi,mij->mj", bench.shape_functions(st), nodes[triangles[tri]])


def test_boundary_of_two_tetrahedra(bench):
    nodes, tets = two_tets()
    tri = bench.boundary_triangles(tets)
    assert tri.shape == (6, 6)
    corners = {tuple(sorted(t[:3])) for t in tri.tolist()}
    assert (1, 2, 3) not in corners                                   # the shared face is inside
    assert corners == {(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 4), (1, 3, 4), (2, 3, 4)}
    for t in tri:                                                     # each midside node halfway along its edge
        for k, (a, b) in enumerate([(0, 1), (1, 2), (2, 0)]):
            assert np.allclose(nodes[t[3 + k]], 0.5 * (nodes[t[a]] + nodes[t[b]]))


@pytest.mark.parametrize("bulge", [0.0, 0.15])
def test_affine_field_is_reproduced_on_the_boundary(bench, bulge):
    nodes, tets = two_tets(bulge)
    tri = bench.boundary_triangles(tets)
    a = np.array([[1e-3, 2e-4, -3e-4], [5e-4, -1e-3, 2e-4], [-2e-4, 3e-4, 7e-4]])
    b = np.array([0.01, -0.02, 0.005])
    interp = bench.SurfaceInterpolator(nodes, tri, nodes @ a.T + b)
    points = boundary_points(bench, nodes, tri)
    _, _, dist = interp.locate(points)
    assert dist.max() < 1e-12
    assert np.abs(interp(points) - (points @ a.T + b)).max() < 1e-14


def test_quadratic_field_is_reproduced_on_straight_tetrahedra(bench):
    nodes, tets = two_tets()
    tri = bench.boundary_triangles(tets)

    def quadratic(p):
        x, y, z = p.T
        return np.stack([1e-3 * x * x - 2e-3 * x * y + 5e-4 * z, 3e-4 * y * z + 1e-3 * z * z - 1e-4,
                         -7e-4 * x * z + 2e-4 * y * y + 1e-3 * x], axis=1)

    interp = bench.SurfaceInterpolator(nodes, tri, quadratic(nodes))
    points = boundary_points(bench, nodes, tri, seed=1)
    assert np.abs(interp(points) - quadratic(points)).max() < 1e-14
    assert np.abs(interp(nodes) - quadratic(nodes)).max() < 1e-15       # every node is on the boundary here


def test_element_field_on_and_off_the_boundary():
    """:class:`hot2cold.pipeline.artificial.ElementField`, the reference of the morph's grids for a field with
    elements: a point on the boundary takes the elements' value with no slack; one ``g`` mm off it (along the
    face's normal), within the reach, takes its foot point's value with ``strain * g`` of slack; one beyond the
    reach is not on the boundary."""
    from hot2cold.pipeline.artificial import ElementField

    nodes, tets = two_tets()
    triangles = elements.boundary_triangles(tets[:, elements.GMSH_TO_TET10])
    values = np.column_stack([nodes[:, 0] ** 2, nodes[:, 1] * nodes[:, 2], nodes[:, 2]])
    field = ElementField(nodes, triangles, values, reach=0.05, strain=0.01)
    # the corners A, B, C span a boundary face (the solid lies on the side of D): points on it and beside it
    a, b, c, d = nodes[:4]
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal)
    normal *= -np.sign(normal @ (d - a))                   # outwards
    on_face = a + np.array([[0.2, 0.3], [0.5, 0.1], [0.1, 0.6]]) @ np.array([b - a, c - a])
    points = np.vstack([on_face, on_face + 0.03 * normal, on_face + 0.2 * normal])
    on, disp, slack = field(points)
    assert on.tolist() == [True] * 6 + [False] * 3
    exact = elements.SurfaceInterpolator(nodes, triangles, values)(on_face)
    assert np.abs(disp[:3] - exact).max() < 1e-12 and np.abs(disp[3:] - exact).max() < 1e-9
    assert np.abs(slack - np.r_[0.0, 0.0, 0.0, 3e-4, 3e-4, 3e-4]).max() < 1e-9
