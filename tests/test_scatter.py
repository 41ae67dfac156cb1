"""The field's scatter about a smooth field (:func:`hot2cold.core.localfit.scatter`) and what it allows at
the nodes (:func:`hot2cold.pipeline.refine.noise_allowance`): numpy only, no kernel."""
import numpy as np
import pytest

from hot2cold.core.localfit import scatter
from hot2cold.pipeline.refine import noise_allowance


def _cylinder(n: int, seed: int = 1) -> np.ndarray:
    """``n`` random points ``(n, 3)`` on a cylinder of radius 20 mm and length 100 mm."""
    rng = np.random.default_rng(seed)
    angle, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 100, n)
    return np.column_stack([20 * np.cos(angle), 20 * np.sin(angle), z])


def _smooth(p: np.ndarray) -> np.ndarray:
    """A smooth field of about 1 mm on the cylinder: bending, stretch and a wave."""
    return np.column_stack([1e-4 * p[:, 0] * p[:, 2], 1e-4 * p[:, 2] ** 2, 1e-2 * np.sin(p[:, 1] / 5)])


def test_a_smooth_field_does_not_scatter():
    points = _cylinder(20000)
    assert scatter(points, _smooth(points)) < 1e-6           # measured 1.4e-7 mm on a 1 mm field


@pytest.mark.parametrize("sigma", [1e-4, 1e-3, 3e-3])
def test_noise_is_measured_by_its_standard_deviation(sigma):
    points = _cylinder(20000)
    noisy = _smooth(points) + np.random.default_rng(2).normal(0.0, sigma, points.shape)
    assert scatter(points, noisy) == pytest.approx(sigma, rel=0.1)


def test_a_thin_wall_is_no_scatter_even_where_one_group_holds_both_sides():
    """Two sides of a wall 0.5 mm thick, nodes 1 mm apart, bent through the wall (the sides move 0.05 mm
    apart): the nearest nodes of a node are on both sides, as where one face wraps round a blade's thin edge.
    The field is smooth through the wall, so neither the sides together nor each on its own scatter; noise on
    it is still measured as it is."""
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 60, (4000, 2))
    lower = np.column_stack([xy, np.zeros(len(xy))])
    upper = np.column_stack([xy, np.full(len(xy), 0.5)])
    points = np.concatenate([lower, upper])
    disp = np.column_stack([0.1 * points[:, 2] * (1 + points[:, 0] / 60), np.zeros(len(points)),
                            1e-4 * points[:, 0] ** 2])
    sides = [np.arange(4000), np.arange(4000, 8000)]
    assert scatter(points, disp) < 1e-9
    assert scatter(points, disp, sides) < 1e-9
    sigma = 2e-4
    noisy = disp + rng.normal(0.0, sigma, disp.shape)
    assert scatter(points, noisy) == pytest.approx(sigma, rel=0.1)


def test_too_few_points_have_no_scatter():
    points = _cylinder(15)
    assert scatter(points, np.random.default_rng(0).normal(size=points.shape)) == 0.0
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        scatter(points, np.zeros((15, 2)))


def test_the_allowance_is_the_largest_normal_distance_the_noise_gives():
    """The largest of n normal distances with standard deviation sigma: about 4 sigma for 10 000 nodes,
    nothing without scatter."""
    assert noise_allowance(0.0, 10000) == 0.0
    assert noise_allowance(1e-3, 10000) == pytest.approx(4.06e-3, rel=0.01)
    rng = np.random.default_rng(4)
    largest = [np.abs(rng.normal(0.0, 1e-3, 10000)).max() for _ in range(50)]
    assert np.median(largest) == pytest.approx(noise_allowance(1e-3, 10000), rel=0.1)
