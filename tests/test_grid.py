"""Tensor-product grids of B-spline surfaces and Newton's start grids dense where the surface bends
(``hot2cold.core.bspline``: ``grid_points``, ``grid_jet``, ``normal_turn``, ``bend_parameters``), kernel-free."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from hot2cold.core.bspline import (BSplineSurface, bend_parameters, evaluate_surface, grid_jet, grid_points,
                                   normal_turn, surface_jet, tangent_noise)


def _knots(rng, n: int, p: int, lo: float, hi: float) -> np.ndarray:
    """A clamped knot vector for ``n`` poles of degree ``p`` on ``[lo, hi]`` with one interior knot doubled."""
    inner = np.sort(rng.uniform(lo, hi, n - p - 2))
    inner = np.sort(np.append(inner, inner[len(inner) // 2]))
    return np.concatenate([[lo] * (p + 1), inner, [hi] * (p + 1)])


def _surface(rng, rational: bool) -> BSplineSurface:
    """A random (rational) surface of degrees 3 x 2 on 9 x 7 poles, domain [-1.3, 2.7] x [0.5, 4]."""
    poles = rng.normal(0.0, 10.0, (9, 7, 3))
    weights = rng.uniform(0.5, 2.0, (9, 7)) if rational else None
    return BSplineSurface(poles, _knots(rng, 9, 3, -1.3, 2.7), _knots(rng, 7, 2, 0.5, 4.0), 3, 2, weights)


@pytest.mark.parametrize("rational", [False, True])
def test_grid_equals_point_by_point(rational):
    """On the tensor grid (knots and domain ends among the parameters) the points and the whole jet equal
    ``evaluate_surface`` and ``surface_jet`` at every pair to 1e-12 of their size."""
    rng = np.random.default_rng(11 + rational)
    surface = _surface(rng, rational)
    u = np.concatenate([[-1.3, 2.7], surface.u_knots[4:-4], rng.uniform(-1.3, 2.7, 30)])
    v = np.concatenate([[0.5, 4.0], surface.v_knots[3:-3], rng.uniform(0.5, 4.0, 20)])
    uu, vv = (g.ravel() for g in np.meshgrid(u, v, indexing="ij"))
    points = grid_points(surface, u, v)
    assert points.shape == (len(u), len(v), 3)
    expected = evaluate_surface(surface, uu, vv).reshape(len(u), len(v), 3)
    np.testing.assert_allclose(points, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    for got, want in zip(grid_jet(surface, u, v), surface_jet(surface, uu, vv)):
        want = want.reshape(len(u), len(v), 3)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())


def _cylinder(radius: float, height: float) -> BSplineSurface:
    """A half cylinder of ``radius`` about the z axis, 0 <= z <= ``height``: two rational quarter arcs in u
    (degree 2), a line in v (degree 1)."""
    s = np.sqrt(0.5)
    arc = radius * np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0]], float)
    poles = np.stack([np.column_stack([arc, np.full(5, z)]) for z in (0.0, height)], axis=1)
    weights = np.tile(np.array([1, s, 1, s, 1])[:, None], (1, 2))
    return BSplineSurface(poles, [0, 0, 0, 1, 1, 2, 2, 2], [0, 0, 1, 1], 2, 1, weights)


def test_normal_turns_as_fast_as_the_curvature():
    """On a cylinder of radius 0.05 mm the normal turns by 1/R = 20 rad/mm around it and not at all along it."""
    surface = _cylinder(0.05, 10.0)
    u, v = np.linspace(0, 2, 13), np.linspace(0, 1, 5)
    _, s_u, s_v, s_uu, s_uv, s_vv = grid_jet(surface, u, v)
    around, along = normal_turn(s_u, s_v, s_uu, s_uv, s_vv)
    np.testing.assert_allclose(around, 20.0, rtol=1e-9)
    np.testing.assert_allclose(along, 0.0, atol=1e-9)


def _sphere_eighth(radius: float) -> BSplineSurface:
    """An eighth of a sphere of ``radius``: a rational quarter arc from the equator to the pole in u (degree 2),
    revolved by 90 degrees about z in v (degree 2); the side u = 1 is collapsed into the pole."""
    s = np.sqrt(0.5)
    profile = radius * np.array([[1, 0, 0], [1, 0, 1], [0, 0, 1]], float)
    poles = np.array([[[x, 0, z], [x, x, z], [0, x, z]] for x, _, z in profile])
    weights = np.outer([1, s, 1], [1, s, 1])
    return BSplineSurface(poles, [0, 0, 0, 1, 1, 1], [0, 0, 0, 1, 1, 1], 2, 2, weights)


def test_normal_turn_is_undefined_at_a_pole_and_a_pole_makes_no_dense_grid():
    """On an eighth of a sphere of radius 5 mm the normal turns by 1/R = 0.2 rad/mm wherever it is defined; at the
    pole the tangent along the collapsed side is rounding (its rate any size), so the turn is NaN there, and the
    start grid at 1 mm spacing has about the sphere's arc length over the spacing in each direction, not the
    most it may have (the rounding's turn rates at the pole asked for all 2000 along the collapsed side)."""
    surface = _sphere_eighth(5.0)
    u, v = np.linspace(0, 1, 9), np.linspace(0, 1, 7)
    _, s_u, s_v, s_uu, s_uv, s_vv = grid_jet(surface, u, v)
    noise = (tangent_noise(surface, 0, u)[:, None], tangent_noise(surface, 1, v)[None, :])
    along_u, along_v = normal_turn(s_u, s_v, s_uu, s_uv, s_vv, noise)
    assert np.all(np.isnan(along_u[-1])) and np.all(np.isnan(along_v[-1]))        # the pole
    np.testing.assert_allclose(along_u[:-1], 0.2, rtol=1e-9)
    np.testing.assert_allclose(along_v[:-1], 0.2, rtol=1e-9)
    gu, gv = bend_parameters(surface, surface.domain, 1.0)
    quarter = 0.5 * np.pi * 5.0                                                  # 7.85 mm
    assert quarter <= len(gu) - 1 <= 3 * quarter and quarter <= len(gv) - 1 <= 3 * quarter


def _hairpin(leg: float, half: float, height: float) -> BSplineSurface:
    """A thin edge: one cubic Bezier span in u from (``leg``, ``half``) round a nose near the origin back to
    (``leg``, -``half``), extruded ``height`` mm along z (degree 1 in v)."""
    curve = np.array([[leg, half], [-0.3 * leg, half], [-0.3 * leg, -half], [leg, -half]])
    poles = np.stack([np.column_stack([curve, np.full(4, z)]) for z in (0.0, height)], axis=1)
    return BSplineSurface(poles, [0, 0, 0, 0, 1, 1, 1, 1], [0, 0, 1, 1], 3, 1)


def test_start_grid_dense_across_a_thin_edge_only():
    """A 0.06 mm nose in a 20 mm hairpin, 4 mm spacing: the grid steps about the nose's radius across it and
    4 mm along it and on the legs; a point near either leg has its nearest grid point on its own side."""
    surface = _hairpin(20.0, 1.0, 10.0)
    _, s_u, s_v, s_uu, s_uv, s_vv = grid_jet(surface, [0.5], [0.5])
    radius = 1.0 / normal_turn(s_u, s_v, s_uu, s_uv, s_vv)[0][0, 0]
    assert radius < 0.1
    spacing = 4.0
    u, v = bend_parameters(surface, surface.domain, spacing)
    assert u[0] == 0 and u[-1] == 1 and v[0] == 0 and v[-1] == 1 and np.all(np.diff(u) > 0)
    assert 4 <= len(v) <= 5                     # 10 mm along the edge: two cells of 5 mm, 2 steps of 2.5 mm each
    grid = grid_points(surface, u, v)
    step = np.linalg.norm(np.diff(grid[:, 0], axis=0), axis=1)
    nose = np.abs(u[1:] + u[:-1] - 1.0) < 0.05                  # the steps round the nose
    assert step[nose].max() <= 1.5 * radius
    assert step.max() <= 1.2 * spacing
    assert len(u) < 0.1 * 40.0 / radius                         # not the nose's density all round
    rng = np.random.default_rng(3)
    t = np.concatenate([rng.uniform(0.3, 0.49, 400), rng.uniform(0.51, 0.7, 400)])
    z = rng.uniform(0.0, 1.0, len(t))
    s, s_u, s_v = (a[:, 0] for a in grid_jet(surface, t, [0.5])[:3])
    normal = np.cross(s_u, s_v)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    nodes = s + rng.uniform(-0.02, 0.02, (len(t), 1)) * normal
    nodes[:, 2] = 10.0 * z
    _, nearest = cKDTree(grid.reshape(-1, 3)).query(nodes)
    start_u = np.repeat(u, len(v))[nearest]
    assert np.all((start_u - 0.5) * (t - 0.5) >= 0)


def test_each_span_has_its_own_density():
    """Two half cylinders one after the other in u, tangent where they meet (radius 0.05 mm, then 5 mm, as one
    surface): steps of at most the radius on the sharp spans, and on the gentle ones the spacing's, not the
    sharp spans' (as a grid sized by the face's smallest radius had); v from the spacing.  (How the density
    follows the turn of the normal within a span: ``test_start_grid_dense_across_a_thin_edge_only``.)"""
    sharp, gentle = _cylinder(0.05, 10.0), _cylinder(5.0, 10.0)
    turned = gentle.poles * [-1.0, -1.0, 1.0]                  # starts at (-5, 0) heading -y, as sharp ends
    poles = np.concatenate([sharp.poles, turned[1:] + sharp.poles[-1] - turned[0]])
    weights = np.concatenate([sharp.weights, gentle.weights[1:]])
    surface = BSplineSurface(poles, [0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 4], [0, 0, 1, 1], 2, 1, weights)
    u, v = bend_parameters(surface, surface.domain, 1.0)
    assert np.sum(u < 2) == 12                # pi rad in 12 pieces, each turning by less than a radian: 1 step
    step = np.linalg.norm(np.diff(grid_points(surface, u, [0.0])[:, 0], axis=0), axis=1)
    assert step[u[:-1] < 2].max() <= 0.05                       # at most the radius
    assert 0.5 <= step[u[:-1] >= 2].min() and step[u[:-1] >= 2].max() <= 1.0     # the spacing, not denser
    assert 11 <= len(v) <= 15                 # 10 mm in 4 pieces of 2.5 mm, 3 steps each


@pytest.mark.parametrize("rational", [False, True])
def test_bend_parameters_blockwise_as_at_once(monkeypatch, rational):
    """The jet evaluated a few v lines at a time gives the parameters of the whole grid at once."""
    import hot2cold.core.bspline as bspline

    surface = _surface(np.random.default_rng(5 + rational), rational)
    box = (-1.0, 2.5, 0.7, 3.9)
    whole = bend_parameters(surface, box, 0.5)
    assert whole[0][0] == -1.0 and whole[0][-1] == 2.5 and whole[1][0] == 0.7 and whole[1][-1] == 3.9
    calls = []
    monkeypatch.setattr(bspline, "grid_jet", lambda *args: calls.append(1) or grid_jet(*args))
    monkeypatch.setattr(bspline, "BEND_BLOCK", 100)                # a v piece or two at a time
    for a, b in zip(bend_parameters(surface, box, 0.5), whole):
        np.testing.assert_array_equal(a, b)
    assert len(calls) > 3


def test_a_grid_point_is_vouched_for_only_where_the_nodes_tell_it_is_within_the_limit():
    """Near the nodes the error is at most ``off`` plus the larger of the slack and the uncertainty: a point
    is vouched for where that is within the limit; out of the nodes' reach it is not at all."""
    from hot2cold.pipeline.grids import FaceGrid

    n = 5
    grid = FaceGrid(np.zeros((n, 2)), np.zeros((n, 3)), np.zeros((n, 3)),
                    slack=np.array([0.0, 0.0, 0.0, 6e-4, 0.0]),
                    near=np.array([True, True, True, True, False]),
                    node_distance=np.array([1.0, 1.0, 1.0, 1.0, 9.0]), support=2.0,
                    uncertainty=np.array([1e-4, 2e-3, 1e-4, 1e-4, 0.0]))
    off = np.array([5e-4, 5e-4, 3e-3, 5e-4, 0.0])
    # within; may be beyond (uncertain estimate); beyond; may be beyond (the estimate misses its nodes); far
    assert grid.unmeasured(off, 1e-3).tolist() == [False, True, True, True, True]
    # and within the limit by less than the grid can resolve between its points
    from hot2cold.pipeline.grids import VOUCH_SHARE

    near_limit = np.array([(VOUCH_SHARE + 0.01) * 1e-3 - 1e-4, 0.0, 0.0, 0.0, 0.0])
    assert grid.unmeasured(near_limit, 1e-3)[0]
    assert not grid.unmeasured(off, np.inf)[:4].any()
