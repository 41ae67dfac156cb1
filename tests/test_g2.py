"""The curvature (G2) measure across edges, on exact surfaces (kernel-free): hot2cold.pipeline.g2."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hot2cold.cli.options import MorphOptions
from hot2cold.core.bspline import BSplineSurface, evaluate_surface
from hot2cold.errors import InputError
from hot2cold.pipeline.g2 import cross_curvature, curvature_jump
from hot2cold.settings import Continuity, Settings

R = 5.0          # mm
L = 20.0


def quarter_cylinder(radius: float = R) -> BSplineSurface:
    """The exact quarter cylinder ``x^2 + y^2 = radius^2``, ``0 <= z <= L``: u round (rational quadratic arc
    from (radius, 0) to (0, radius)), v along z."""
    arc = np.array([[radius, 0.0], [radius, radius], [0.0, radius]])
    poles = np.zeros((3, 2, 3))
    poles[:, :, :2] = arc[:, None, :]
    poles[:, 1, 2] = L
    weights = np.array([[1.0, 1.0], [math.sqrt(0.5)] * 2, [1.0, 1.0]])
    return BSplineSurface(poles, np.r_[0.0, 0.0, 0.0, 1.0, 1.0, 1.0], np.r_[0.0, 0.0, 1.0, 1.0], 2, 1, weights)


def tangent_plane() -> BSplineSurface:
    """The plane ``x = R`` from y = -10 to 0, ``0 <= z <= L``: tangent to the cylinder along its line u = 0."""
    poles = np.array([[[R, -10.0, 0.0], [R, -10.0, L]], [[R, 0.0, 0.0], [R, 0.0, L]]])
    return BSplineSurface(poles, np.r_[0.0, 0.0, 1.0, 1.0], np.r_[0.0, 0.0, 1.0, 1.0], 1, 1)


def _points(surface, uv):
    return evaluate_surface(surface, uv[:, 0], uv[:, 1])


def test_cross_curvature_of_a_cylinder_is_one_over_its_radius_across_a_line_and_zero_across_a_circle():
    cylinder = quarter_cylinder()
    line = np.column_stack([np.full(9, 0.4), np.linspace(0.0, 1.0, 9)])         # along z
    kappa, normal, ab = cross_curvature(cylinder, line, np.gradient(_points(cylinder, line), axis=0))
    np.testing.assert_allclose(np.abs(kappa), 1.0 / R, rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(normal, axis=1), 1.0, rtol=1e-12)
    circle = np.column_stack([np.linspace(0.0, 1.0, 9), np.full(9, 0.5)])       # round the axis
    kappa, _, _ = cross_curvature(cylinder, circle, np.gradient(_points(cylinder, circle), axis=0))
    np.testing.assert_allclose(kappa, 0.0, atol=1e-12)


def test_a_cylinder_and_its_tangent_plane_jump_by_the_whole_curvature():
    """A fillet meets its plane tangentially (G1) but not curvature-continuously: the jump is 1/R, all of
    the curvature there; the same surface on both sides of a line on it does not jump."""
    cylinder, plane = quarter_cylinder(), tangent_plane()
    uv_cyl = np.column_stack([np.zeros(7), np.linspace(0.0, 1.0, 7)])
    uv_plane = np.column_stack([np.ones(7), np.linspace(0.0, 1.0, 7)])
    np.testing.assert_allclose(_points(cylinder, uv_cyl), _points(plane, uv_plane), atol=1e-12)
    jump = curvature_jump(cylinder, uv_cyl, plane, uv_plane)
    np.testing.assert_allclose(jump.jump, 1.0 / R, rtol=1e-12)
    assert jump.relative(1e-3) == pytest.approx(1.0)
    inside = np.column_stack([np.full(7, 0.3), np.linspace(0.0, 1.0, 7)])
    assert curvature_jump(cylinder, inside, cylinder, inside).relative(1e-3) == 0.0


def test_the_jump_is_judged_against_the_curvature_where_it_happens_and_does_not_mind_the_normals_sides():
    """Two cylinders of radii 5 and 5.1 mm tangent along a line: 2 % of the curvature there, whichever way
    either face's normal points; on nearly flat faces the floor (one over the part's diagonal) is the scale."""
    a, b = quarter_cylinder(R), quarter_cylinder(1.02 * R)
    shift = np.array([R - 1.02 * R, 0.0, 0.0])        # b's line u = 0 moved onto a's
    b = BSplineSurface(b.poles + shift, b.u_knots, b.v_knots, 2, 1, b.weights)
    uv = np.column_stack([np.zeros(5), np.linspace(0.0, 1.0, 5)])
    jump = curvature_jump(a, uv, b, uv)
    assert jump.relative(1e-6) == pytest.approx(1.0 - 1.0 / 1.02, rel=1e-9)
    flipped = BSplineSurface(b.poles[:, ::-1], b.u_knots, b.v_knots, 2, 1, b.weights[:, ::-1])
    uv_flipped = np.column_stack([np.zeros(5), np.linspace(1.0, 0.0, 5)])
    assert curvature_jump(a, uv, flipped, uv_flipped).relative(1e-6) == pytest.approx(jump.relative(1e-6))
    assert jump.relative(10.0) == pytest.approx((1.0 / R - 1.0 / (1.02 * R)) / 10.0, rel=1e-9)


def test_curvature_jump_refuses_mismatched_points():
    cylinder = quarter_cylinder()
    with pytest.raises(ValueError, match=r"\(m, 2\)"):
        curvature_jump(cylinder, np.zeros((4, 2)), cylinder, np.zeros((3, 2)))


def test_continuity_setting_and_option():
    assert Settings().continuity is Continuity.G1
    assert Settings(continuity="g2").continuity is Continuity.G2
    with pytest.raises(ValueError, match="continuity must be one of g1, g2, got 'c2'"):
        Settings(continuity="c2")
    with pytest.raises(ValueError, match="g2_tolerance"):
        Settings(g2_tolerance=0.0)
    assert MorphOptions(continuity="g2").to_settings().continuity is Continuity.G2
    with pytest.raises(InputError, match="continuity"):
        MorphOptions(continuity="g3").to_settings()
