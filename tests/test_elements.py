"""The FE elements' own interpolation (hot2cold.core.elements) and the field sampled inside them
(hot2cold.pipeline.load.element_points): kernel-free."""
from __future__ import annotations

import numpy as np
import pytest

from hot2cold.core.elements import (GMSH_TO_TET10, TRIANGLE_SAMPLES, SurfaceInterpolator, boundary_triangles,
                                    project_to_triangles, sample_triangles, shape_derivatives, shape_functions)
from hot2cold.io.field import DisplacementField
from hot2cold.pipeline.load import element_points
from hot2cold.settings import Settings

#: Parameters of the 6 nodes of the quadratic triangle: corners, then midside nodes of edges 0-1, 1-2, 2-0.
NODE_ST = np.array([[0, 0], [1, 0], [0, 1], [0.5, 0], [0.5, 0.5], [0, 0.5]])


@pytest.mark.parametrize("nodes", [3, 6])
def test_shape_functions_interpolate_at_their_nodes_and_sum_to_one(nodes):
    at_nodes = shape_functions(NODE_ST[:nodes], nodes)
    np.testing.assert_allclose(at_nodes, np.eye(nodes), atol=1e-15)
    st = np.random.default_rng(1).dirichlet(np.ones(3), 50)[:, 1:]
    np.testing.assert_allclose(shape_functions(st, nodes).sum(axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(shape_derivatives(st, nodes).sum(axis=1), 0.0, atol=1e-13)


def test_shape_derivatives_match_finite_differences():
    st = np.array([[0.2, 0.3], [0.6, 0.1]])
    h = 1e-6
    for k in range(2):
        step = np.zeros(2)
        step[k] = h
        fd = (shape_functions(st + step) - shape_functions(st - step)) / (2 * h)
        np.testing.assert_allclose(shape_derivatives(st)[:, :, k], fd, atol=1e-8)


def _curved_triangle():
    """A 6-node triangle on the paraboloid z = 0.1 (x² + y²) (nodes on it, edges bent), and its nodes."""
    xy = 4.0 * NODE_ST + np.array([1.0, -2.0])
    return np.column_stack([xy, 0.1 * (xy ** 2).sum(axis=1)])


def test_a_quadratic_field_is_reproduced_inside_the_quadratic_triangle():
    """Values of a quadratic in (s, t) at the 6 nodes give that quadratic everywhere inside."""
    xyz = _curved_triangle()

    def quadratic(st):
        s, t = st[:, 0], st[:, 1]
        return np.column_stack([1 + 2 * s - t + 3 * s * t, s * s - 2 * t * t, 0.5 + t])

    pos, val = sample_triangles(xyz, np.arange(6)[None], quadratic(NODE_ST), TRIANGLE_SAMPLES)
    np.testing.assert_allclose(val, quadratic(TRIANGLE_SAMPLES), atol=1e-14)
    np.testing.assert_allclose(pos, shape_functions(TRIANGLE_SAMPLES) @ xyz, atol=1e-14)
    # linear triangle: the plane through its corners
    pos3, val3 = sample_triangles(xyz, np.arange(3)[None], quadratic(NODE_ST), np.array([[1 / 3, 1 / 3]]))
    np.testing.assert_allclose(pos3, xyz[:3].mean(axis=0)[None], atol=1e-14)
    np.testing.assert_allclose(val3, quadratic(NODE_ST)[:3].mean(axis=0)[None], atol=1e-14)


def test_points_on_a_curved_triangle_project_onto_themselves():
    xyz = _curved_triangle()
    st = np.random.default_rng(2).dirichlet(np.ones(3), 40)[:, 1:]
    points = shape_functions(st) @ xyz
    found, dist = project_to_triangles(points, np.repeat(xyz[None], len(points), axis=0))
    assert dist.max() < 1e-10
    np.testing.assert_allclose(found, st, atol=1e-8)
    # a point off the triangle by 0.3 mm along the normal at its foot point
    s0 = np.array([[0.25, 0.25]])
    d = shape_derivatives(s0)[0].T @ xyz                                   # (2, 3) tangents
    normal = np.cross(d[0], d[1])
    normal /= np.linalg.norm(normal)
    off = shape_functions(s0) @ xyz + 0.3 * normal
    found, dist = project_to_triangles(off, xyz[None])
    assert dist[0] == pytest.approx(0.3, abs=1e-9)
    np.testing.assert_allclose(found, s0, atol=1e-7)


def _cube_tets(order: int):
    """A unit cube split into 6 tetrahedra about its diagonal 0-6: nodes and tetrahedra (VTK order), with
    midside nodes when ``order`` is 2."""
    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
                       dtype=float)
    tets = np.array([[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]])
    if order == 1:
        return corners, tets
    nodes, index, full = list(corners), {}, []
    for tet in tets:
        mids = []
        for a, b in ((0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)):
            key = tuple(sorted((tet[a], tet[b])))
            if key not in index:
                index[key] = len(nodes)
                nodes.append(0.5 * (corners[key[0]] + corners[key[1]]))
            mids.append(index[key])
        full.append(list(tet) + mids)
    return np.array(nodes), np.array(full)


@pytest.mark.parametrize("order", [1, 2])
def test_the_boundary_of_a_tet_mesh_is_a_closed_surface_on_the_cube(order):
    nodes, tets = _cube_tets(order)
    tri = boundary_triangles(tets)
    assert tri.shape == (12, 3 if order == 1 else 6)
    corners = nodes[tri[:, :3]]
    on_side = np.isclose(corners, 0).all(axis=1) | np.isclose(corners, 1).all(axis=1)
    assert on_side.any(axis=1).all()                                     # every triangle on a side of the cube
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    _, count = np.unique(edges, axis=0, return_counts=True)
    assert (count == 2).all()                                            # closed: every edge in two triangles
    if order == 2:                                                       # midside nodes halfway along their edge
        for k, (a, b) in enumerate(((0, 1), (1, 2), (2, 0))):
            np.testing.assert_allclose(nodes[tri[:, 3 + k]], 0.5 * (nodes[tri[:, a]] + nodes[tri[:, b]]))


def test_gmsh_order_converts_to_vtk_order():
    """gmsh's 10-node tetrahedron lists the midside nodes of edges 2-3 then 1-3; VTK's 1-3 then 2-3."""
    _, tets = _cube_tets(2)
    gmsh = tets[:, [0, 1, 2, 3, 4, 5, 6, 7, 9, 8]]
    np.testing.assert_array_equal(gmsh[:, GMSH_TO_TET10], tets)


def test_the_interpolator_gives_the_elements_field_at_points_near_the_boundary():
    nodes, tets = _cube_tets(2)
    tri = boundary_triangles(tets)
    values = np.column_stack([nodes[:, 0] ** 2, nodes[:, 1] * nodes[:, 2], nodes.sum(axis=1)])   # quadratic
    interp = SurfaceInterpolator(nodes, tri, values)
    rng = np.random.default_rng(3)
    points = rng.uniform(0.05, 0.95, (30, 3))
    points[:, 2] = 1.0                                                   # on the top side
    exact = np.column_stack([points[:, 0] ** 2, points[:, 1] * points[:, 2], points.sum(axis=1)])
    np.testing.assert_allclose(interp(points + [0, 0, 1e-3]), exact, atol=1e-12)


def test_element_points_add_the_field_inside_the_triangles_after_the_nodes():
    nodes, tets = _cube_tets(2)
    tri = boundary_triangles(tets)
    values = 0.01 * nodes ** 2
    field = DisplacementField(nodes, values, np.arange(100, 100 + len(nodes)), "cube", tri)
    dense, added = element_points(field, Settings())
    assert added == 4 * len(tri) == len(dense) - len(field)
    np.testing.assert_array_equal(dense.points[:len(field)], field.points)
    np.testing.assert_array_equal(dense.node_ids[len(field):], -1)
    np.testing.assert_allclose(dense.displacements[len(field):], 0.01 * dense.points[len(field):] ** 2, atol=1e-15)
    same, none = element_points(field, Settings(element_points=False))
    assert same is field and none == 0
    bare, none = element_points(DisplacementField(nodes, values), Settings())
    assert none == 0 and len(bare) == len(nodes)


def test_a_field_refuses_triangles_outside_its_nodes():
    from hot2cold.errors import FieldError

    nodes, _ = _cube_tets(1)
    with pytest.raises(FieldError, match="outside 0..7"):
        DisplacementField(nodes, nodes, triangles=np.array([[0, 1, 8]]))
    with pytest.raises(FieldError, match=r"shape \(T, 3\) or \(T, 6\)"):
        DisplacementField(nodes, nodes, triangles=np.array([[0, 1, 2, 3]]))
    with pytest.raises(FieldError, match="integer"):
        DisplacementField(nodes, nodes, triangles=np.array([[0.0, 1.0, 2.0]]))


def test_triangles_follow_the_nodes_through_take_and_merge():
    from hot2cold.io.field import merge_duplicates

    nodes, tets = _cube_tets(1)
    tri = boundary_triangles(tets)
    field = DisplacementField(nodes, 0.01 * nodes, triangles=tri)
    kept = field.take(np.array([7, 6, 5, 4, 0, 1, 2, 3, 0]))             # reordered, node 0 twice
    np.testing.assert_array_equal(kept.points[kept.triangles], nodes[tri])   # the same triangles, renumbered
    part = field.take(np.arange(7))                                      # without node 7: its triangles go
    assert len(part.triangles) == sum(7 not in t for t in tri)
    assert field.scaled(2.0).triangles is not None
    doubled = DisplacementField(np.vstack([nodes, nodes[:1]]), 0.01 * np.vstack([nodes, nodes[:1]]),
                                triangles=np.vstack([tri, [[8, 1, 2]]]))
    merged = merge_duplicates(doubled)
    assert len(merged) == 8
    np.testing.assert_array_equal(merged.points[merged.triangles], np.vstack([nodes[tri], nodes[[[0, 1, 2]]]]))
