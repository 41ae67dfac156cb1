"""Vectorised foot points and the domain raster against the kernel (the kernel as oracle).

* ``footpoint.project_to_surface`` (Newton in numpy) against ``GeomAPI_ProjectPointOnSurf``: same parameters to
  1e-9 relative, same distances to 1e-9 mm, on the settled nodes; the rest is left to the kernel.
* ``DomainRaster`` / ``Projector.classify`` against ``BRepTopAdaptor_FClass2d`` point by point.
* ``classify_nodes`` against the direct approach: every node projected by the kernel onto every face, the
  nearest inside foot point kept.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from hot2cold.core.bspline import BSplineSurface, evaluate_curve, evaluate_surface, surface_normals
from hot2cold.pipeline.classify import START_SPACING, classify_nodes, start_grid
from hot2cold.core.domain import DomainRaster, Trim
from hot2cold.io.field import as_field
from hot2cold.core.footpoint import project_to_curve, project_to_surface, surface_distances, surface_distances_above
from hot2cold.core.model import Role
from hot2cold.kernel.project import Projector
from hot2cold.pipeline.load import load_part
from hot2cold.settings import Settings

SAMPLES = Path(__file__).resolve().parents[1] / "sample_parts"


@pytest.fixture(scope="module", params=["rotor37_blade", "filleted_block", "mixer_segment"])
def part(request):
    return load_part(SAMPLES / f"{request.param}.step", Settings())


def _near_surface_nodes(face, n: int, offset: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """``n`` nodes ``(n, 3)`` up to ``offset`` mm off ``face``'s surface, and the parameters ``(n, 2)`` they were
    made at."""
    u0, u1, v0, v1 = face.uv_box
    uv = np.column_stack([rng.uniform(u0, u1, n), rng.uniform(v0, v1, n)])
    normal = surface_normals(face.surface, uv[:, 0], uv[:, 1])
    normal = np.nan_to_num(normal)
    points = evaluate_surface(face.surface, uv[:, 0], uv[:, 1]) + rng.uniform(-offset, offset, (n, 1)) * normal
    return points, uv


@pytest.mark.heavy
def test_newton_matches_kernel(part):
    """Nodes within 0.05 mm of each face, started from the nearest point of the face's start grid (as the
    classification starts them): where Newton settles (most nodes), it finds the kernel's foot point."""
    rng = np.random.default_rng(7)
    projector = Projector(part.kernel.faces, part.kernel.edges)
    settled_total = 0
    for face in part.faces:
        points, uv = _near_surface_nodes(face, 300, 0.05, rng)
        box = projector.face_box(face.index)
        size = box[[1, 3]] - box[[0, 2]]
        grid, grid_uv = start_grid(face, START_SPACING * part.diagonal)
        start = grid_uv[cKDTree(grid).query(points)[1]]
        fp = project_to_surface(face.surface, points, start, box)
        ref_uv, ref_dist = projector.to_face(face.index, points)
        s = fp.settled & np.isfinite(ref_dist)
        assert s.mean() > 0.8, f"face {face.index}: only {s.mean():.0%} settled"
        np.testing.assert_allclose(fp.distance[s], ref_dist[s], rtol=0, atol=1e-9)
        np.testing.assert_array_less(np.abs(fp.uv[s] - ref_uv[s]) / size, 1e-9)
        settled_total += int(s.sum())
    assert settled_total > 0.8 * 300 * len(part.faces)


def test_newton_leaves_border_minima_open(part):
    """Points beyond a face's box (the foot point would be on its border) are not settled: they are for the
    kernel."""
    face = max(part.faces, key=lambda f: f.surface.shape[0] * f.surface.shape[1])
    u0, u1, v0, v1 = face.surface.domain
    box = np.array([u0 + 0.25 * (u1 - u0), u0 + 0.75 * (u1 - u0), v0 + 0.25 * (v1 - v0), v0 + 0.75 * (v1 - v0)])
    v = np.linspace(box[2] + 0.1 * (box[3] - box[2]), box[3] - 0.1 * (box[3] - box[2]), 20)
    outside = np.column_stack([np.full_like(v, u0 + 0.9 * (u1 - u0)), v])     # beyond u1 of the box
    points = evaluate_surface(face.surface, outside[:, 0], outside[:, 1])
    fp = project_to_surface(face.surface, points, np.column_stack([np.full_like(v, box[0]), v]), box)
    assert not fp.settled.any()
    assert np.all((fp.uv[:, 0] >= box[0]) & (fp.uv[:, 0] <= box[1]))


def test_a_node_beyond_the_box_slides_to_the_nearest_point_of_its_side(monkeypatch):
    """A node whose nearest point lies beyond one side of the box ends, unsettled, at the nearest point of that
    side, in a few steps: on a plane parametrised askew, ``S(u, v) = (u + v / 2, v, 0)``, the point
    ``(-0.5, 0.5, 0.3)`` is nearest ``S(-0.75, 0.5)``; of the side ``u = 0`` it is nearest ``S(0, 0.2)``
    (``d/dv |S(0, v) - P|^2 = 0``), at ``sqrt(0.54)``.  The full Newton step clipped to the side stops at
    ``v = 0.5`` instead, farther."""
    from hot2cold.core import footpoint

    plane = BSplineSurface(np.array([[[0.0, 0.0, 0.0], [0.5, 1.0, 0.0]], [[1.0, 0.0, 0.0], [1.5, 1.0, 0.0]]]),
                           [0.0, 0.0, 1.0, 1.0], [0.0, 0.0, 1.0, 1.0], 1, 1)
    points = np.array([[-0.5, 0.5, 0.3], [-0.5, 0.25, 0.3]])
    starts = np.array([[0.3, 0.7], [0.1, 0.1]])
    jets = []
    real_jet = footpoint.surface_jet
    monkeypatch.setattr(footpoint, "surface_jet", lambda *a: jets.append(len(a[1])) or real_jet(*a))
    fp = project_to_surface(plane, points, starts)
    assert not fp.settled.any()
    # the second: d/dv ((v/2 + 1/2)^2 + (v - 1/4)^2) = 0 at v = 0
    assert np.allclose(fp.uv, [[0.0, 0.2], [0.0, 0.0]], rtol=0.0, atol=1e-9)
    assert np.allclose(fp.distance, np.sqrt([0.54, 0.25 + 0.0625 + 0.09]), rtol=1e-9)
    assert len(jets) <= 4            # a step to the side, a step along it, and the steps that find it stuck


def test_newton_checks_its_input():
    part = load_part(SAMPLES / "twisted_blade.step", Settings())
    surface = part.faces[0].surface
    with pytest.raises(ValueError, match=r"points must be \(n, 3\)"):
        project_to_surface(surface, np.zeros((4, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"start must be \(n, 2\)"):
        project_to_surface(surface, np.zeros((4, 3)), np.zeros((3, 2)))


def test_nodes_started_at_one_point_share_its_jet(monkeypatch):
    """Nodes started at the same point of a start grid (a dense field: many nodes to a start) take that point's
    jet from one evaluation: the foot points are those found with each node's jet evaluated on its own."""
    import hot2cold.core.footpoint as footpoint

    part = load_part(SAMPLES / "twisted_blade.step", Settings())
    face = part.faces[0]
    rng = np.random.default_rng(3)
    points, _ = _near_surface_nodes(face, 2000, 0.02, rng)
    u0, u1, v0, v1 = face.uv_box
    uu, vv = np.meshgrid(np.linspace(u0, u1, 40), np.linspace(v0, v1, 40), indexing="ij")
    grid_uv = np.column_stack([uu.ravel(), vv.ravel()])                     # 1 600 starts for 2 000 nodes
    start = grid_uv[cKDTree(evaluate_surface(face.surface, *grid_uv.T)).query(points)[1]]
    assert len(np.unique(start, axis=0)) < 0.8 * len(start)
    shared = project_to_surface(face.surface, points, start)
    calls = []
    jet = footpoint.surface_jet
    monkeypatch.setattr(footpoint, "surface_jet", lambda s, u, v: calls.append(len(u)) or jet(s, u, v))
    monkeypatch.setattr(footpoint, "_SHARED_LEAST", len(points) + 1)        # every node evaluated on its own
    alone = project_to_surface(face.surface, points, start)
    assert calls[0] == len(points)
    assert np.array_equal(shared.settled, alone.settled) and shared.settled.mean() > 0.95
    assert np.abs(shared.uv - alone.uv).max() <= 1e-12 * np.ptp(grid_uv, axis=0).max()
    assert np.abs(shared.distance - alone.distance).max() <= 1e-12 * part.diagonal


@pytest.mark.parametrize("name", ["twisted_blade", "thin_blade", "rotor37_blade"])
def test_foot_points_of_nodes_on_the_surface_are_theirs_to_rounding(name):
    """Nodes on a face's surface, started from the nearest point of its start grid: Newton settles each on the
    parameters it was made at, to the rounding of the box (1e-12 of it: Rotor 37's parametrisation rounds
    coarser than its box's digits, with any settling step), at a distance of rounding.  Newton settles on a step
    of up to ``SETTLE_RTOL`` of the box and takes that step's own error (its square) out from the second-order
    expansion; for a node on the surface the distance is that error's tangential length, which the step alone
    left far above rounding (the speed page's tenth round)."""
    part = load_part(SAMPLES / f"{name}.step", Settings())
    rng = np.random.default_rng(5)
    for face in part.faces:
        points, uv = _near_surface_nodes(face, 2000, 0.0, rng)
        grid, grid_uv = start_grid(face, START_SPACING * part.diagonal)
        start = grid_uv[cKDTree(grid).query(points)[1]]
        fp = project_to_surface(face.surface, points, start)
        size = np.array(face.surface.domain[1::2]) - np.array(face.surface.domain[::2])
        s = fp.settled
        assert s.mean() > 0.9
        assert np.abs(fp.uv[s] - uv[s]).max() / size.max() <= 1e-12, face.index
        assert fp.distance[s].max() <= 1e-12 * part.diagonal, face.index


def test_nodes_whose_last_correction_is_not_trusted_step_on(monkeypatch):
    """A settling step whose correction is not well below it (``_FIX_SHARE``: a Hessian near singular) is not
    taken as the last: the node steps on.  With the share made tiny, most nodes take that path, one step later,
    and settle on the same foot points, to rounding, as with the share as it is."""
    import hot2cold.core.footpoint as footpoint

    part = load_part(SAMPLES / "twisted_blade.step", Settings())
    face = part.faces[0]
    points, _ = _near_surface_nodes(face, 2000, 0.02, np.random.default_rng(8))
    grid, grid_uv = start_grid(face, START_SPACING * part.diagonal)
    start = grid_uv[cKDTree(grid).query(points)[1]]
    calls = []
    jet = footpoint.surface_jet
    monkeypatch.setattr(footpoint, "surface_jet", lambda s, u, v: calls.append(len(u)) or jet(s, u, v))
    usual = project_to_surface(face.surface, points, start)
    jets = sum(calls)
    monkeypatch.setattr(footpoint, "_FIX_SHARE", 1e-12)
    later = project_to_surface(face.surface, points, start)
    assert sum(calls) - jets > 1.5 * jets / 3                 # most nodes took one more step
    assert np.array_equal(usual.settled, later.settled) and usual.settled.mean() > 0.95
    size = max(np.ptp(grid_uv, axis=0))
    assert np.abs(usual.uv - later.uv)[usual.settled].max() <= 1e-12 * size
    assert np.abs(usual.distance - later.distance)[usual.settled].max() <= 1e-12 * part.diagonal


def test_curve_foot_points_of_points_on_the_curve_are_theirs_to_rounding():
    """Points on an edge's curve, started from the nearest of 200 samples: Newton settles each on the parameter
    it was made at, to the rounding of the domain (the last step's own error taken out, as for surfaces)."""
    part = load_part(SAMPLES / "rotor37_blade.step", Settings())
    rng = np.random.default_rng(6)
    for edge in part.edges:
        curve = edge.curve
        lo, hi = curve.domain
        t = rng.uniform(lo + 0.02 * (hi - lo), hi - 0.02 * (hi - lo), 500)
        points = evaluate_curve(curve, t)
        samples = np.linspace(lo, hi, 200)
        start = samples[cKDTree(evaluate_curve(curve, samples)).query(points)[1]]
        feet = project_to_curve(curve, points, start)
        assert feet.settled.mean() > 0.9
        assert np.abs(feet.t - t)[feet.settled].max() <= 1e-12 * (hi - lo), edge.index
        assert feet.distance[feet.settled].max() <= 1e-12 * part.diagonal, edge.index


def _near_edge_points(curve, n: int, offset: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points ``(n, 3)`` up to ``offset`` mm off ``curve`` (inside its range, away from its ends), and the
    parameters ``(n,)`` of the nearest of 200 samples of the curve, Newton's starts."""
    lo, hi = curve.domain
    t = rng.uniform(lo + 0.02 * (hi - lo), hi - 0.02 * (hi - lo), n)
    points = evaluate_curve(curve, t) + rng.uniform(-offset, offset, (n, 3))
    s = np.linspace(lo, hi, 200)
    return points, s[cKDTree(evaluate_curve(curve, s)).query(points)[1]]


@pytest.mark.heavy
def test_curve_newton_matches_kernel(part):
    """Points within 0.05 mm of every edge, started from the nearest of 200 samples of its curve: where Newton
    settles (most points), it finds the foot point of the kernel's ``GeomAPI_ProjectPointOnCurve``: the same
    distance to 1e-9 mm (or nearer: the kernel's own iteration stops sooner) and parameter to 1e-9 of the
    range."""
    rng = np.random.default_rng(5)
    projector = Projector(part.kernel.faces, part.kernel.edges)
    settled_total = asked = 0
    for edge in part.edges:
        if edge.degenerate:
            continue
        points, start = _near_edge_points(edge.curve, 100, 0.05, rng)
        feet = project_to_curve(edge.curve, points, start)
        ref_t, ref_dist = projector.to_edge(edge.index, points)
        lo, hi = edge.curve.domain
        s = feet.settled
        np.testing.assert_array_less(feet.distance[s], ref_dist[s] + 1e-9)
        np.testing.assert_array_less(np.abs(feet.t[s] - ref_t[s]) / (hi - lo), 1e-9)
        settled_total += int(s.sum())
        asked += len(points)
    assert settled_total > 0.9 * asked


def test_curve_newton_leaves_end_minima_open_and_checks_its_input():
    """Points beyond a curve's end (their nearest point is the end) are not settled: they are for the kernel;
    points on the curve settle on their own parameters; shapes are checked on entry."""
    part = load_part(SAMPLES / "twisted_blade.step", Settings())
    curve = next(e.curve for e in part.edges if not e.degenerate)
    lo, hi = curve.domain
    t = np.linspace(lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo), 25)
    feet = project_to_curve(curve, evaluate_curve(curve, t), t + 0.01 * (hi - lo))
    assert feet.settled.all()
    np.testing.assert_allclose(feet.t, t, rtol=0, atol=1e-9 * (hi - lo))
    assert feet.distance.max() < 1e-9
    end = evaluate_curve(curve, [hi])[0]
    tangent = end - evaluate_curve(curve, [hi - 1e-3 * (hi - lo)])[0]
    beyond = end + np.outer(np.linspace(1, 5, 10), tangent / np.linalg.norm(tangent))
    feet = project_to_curve(curve, beyond, np.full(10, hi - 0.05 * (hi - lo)))
    assert not feet.settled.any()
    assert np.all((feet.t >= lo) & (feet.t <= hi))
    with pytest.raises(ValueError, match=r"points must be \(n, 3\)"):
        project_to_curve(curve, np.zeros((4, 2)), np.zeros(4))
    with pytest.raises(ValueError, match=r"start must be \(n,\)"):
        project_to_curve(curve, np.zeros((4, 3)), np.zeros((4, 2)))


def test_nodes_on_a_thin_blade_need_no_far_side_start():
    """``_foot_points`` starts a node again from the far side of a thin edge unless it settled on the face
    (within ``ON_SURFACE`` of the diagonal): on the thin blade's largest face, nodes on the face and up to 0.2 mm
    off it (its edges are 0.026 and 0.059 mm in radius) get the same foot points either way (to rounding), and only the
    nodes that did not settle on the face are looked at for a far side (their ``_FAR_SIDE_STARTS`` nearest
    starts asked of the tree)."""
    from hot2cold.pipeline import classify as cl

    class Counted:
        """The start tree, counting the points asked for more than their nearest start."""

        def __init__(self, tree):
            self.tree, self.asked = tree, 0

        def query(self, x, k=1, **kwargs):
            self.asked += len(x) if k > 1 else 0
            return self.tree.query(x, k=k, **kwargs)

    part = load_part(SAMPLES / "thin_blade.step", Settings())
    face = max(part.faces, key=lambda f: f.surface.shape[0] * f.surface.shape[1])
    projector = Projector(part.kernel.faces, part.kernel.edges)
    box = projector.face_box(face.index)
    rng = np.random.default_rng(2)
    on, _ = _near_surface_nodes(face, 2000, 0.0, rng)
    off, _ = _near_surface_nodes(face, 2000, 0.2, rng)
    points = np.concatenate([on, off])
    grid, grid_uv, tree = cl.Starts(part).of(face.index)
    every_tree, skip_tree = Counted(tree), Counted(tree)
    every = cl._foot_points(face, points, (grid, grid_uv, every_tree), box, -1.0)
    skip = cl._foot_points(face, points, (grid, grid_uv, skip_tree), box, cl.ON_SURFACE * part.diagonal)
    size = box[[1, 3]] - box[[0, 2]]
    np.testing.assert_array_equal(skip.settled, every.settled)
    np.testing.assert_allclose(skip.distance, every.distance, rtol=0, atol=1e-12)
    assert np.max(np.abs(skip.uv - every.uv) / size) < 1e-12
    on_face = skip.settled & (skip.distance <= cl.ON_SURFACE * part.diagonal)
    assert on_face[:2000].mean() > 0.95 and on_face[2000:].mean() < 0.01
    assert every_tree.asked == len(points)
    assert skip_tree.asked == len(points) - on_face.sum()


def _square_with_hole(n_hole: int = 2001):
    """The unit square and a hole of radius 0.2 at its middle: the polylines, and the hole's circle at each
    segment's middle parameter."""
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], float)
    angle = np.linspace(0, 2 * np.pi, n_hole)[::-1]
    circle = lambda t: 0.5 + 0.2 * np.column_stack([np.cos(t), np.sin(t)])      # noqa: E731
    middles = [0.5 * (square[:-1] + square[1:]), circle(0.5 * (angle[:-1] + angle[1:]))]
    return [square, circle(angle)], middles


def _distance_to_square_with_hole(uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Truly inside (m,) bool, and the distance (m,) to the boundary of the square with the hole."""
    radius = np.linalg.norm(uv - 0.5, axis=1)
    inside = np.all((uv > 0) & (uv < 1), axis=1) & (radius > 0.2)
    in_square = np.all((uv >= 0) & (uv <= 1), axis=1)
    to_square = np.where(in_square, np.min(np.concatenate([uv, 1 - uv], axis=1), axis=1),
                         np.linalg.norm(np.maximum(np.maximum(-uv, uv - 1), 0), axis=1))
    return inside, np.minimum(np.abs(radius - 0.2), to_square)


def test_raster_of_a_square_with_a_hole():
    """Pure numpy: the unit square with a circular hole (a 2000-gon, the circle at its segments' middles); every
    decided point agrees with the exact geometry, the points within a cell of the boundary included, and in
    the box only points within the margins (four times the polygon's 2.5e-7 from the circle) are left UNSURE
    (outside the box, the border cells' points are left to the kernel)."""
    lines, middles = _square_with_hole()
    raster = DomainRaster.build(lines, (0, 1, 0, 1), n=256, midpoints=middles)
    rng = np.random.default_rng(3)
    uv = np.concatenate([rng.uniform(-0.05, 1.05, (200_000, 2)),
                         0.5 + (0.2 + rng.uniform(-1e-3, 1e-3, (50_000, 1)))       # within a cell of the hole
                         * np.exp(1j * rng.uniform(0, 2 * np.pi, 50_000)).view(float).reshape(-1, 2)])
    state = raster.classify(uv)
    inside, to_boundary = _distance_to_square_with_hole(uv)
    decided = (state == Trim.INSIDE) | (state == Trim.OUTSIDE)
    assert np.all((state[decided] == Trim.INSIDE) == inside[decided])
    unsure = (state == Trim.UNSURE) & np.all((uv >= 0) & (uv <= 1), axis=1)
    sag = 0.2 * (1 - np.cos(np.pi / 2000))
    within = to_boundary[unsure] <= 5 * sag + 2e-6 / 256          # the chord's margin, and the chord's sag
    assert within.sum() >= 1 and (~within).sum() <= 5               # (else: a way past a vertex within 1e-6)
    near = (to_boundary < 1.0 / 256) & np.all((uv >= 0) & (uv <= 1), axis=1)
    assert near.sum() > 40_000 and decided[near].mean() > 0.99
    assert np.all(raster.classify(np.array([[np.nan, 0.5], [2.0, 0.5]])) == Trim.OUTSIDE)


def _even_odd(uv: np.ndarray, lines: list[np.ndarray]) -> np.ndarray:
    """Brute-force even-odd rule: (m,) bool, ``uv`` (m, 2) inside the closed polylines ``lines``."""
    a = np.concatenate([p[:-1] for p in lines])
    b = np.concatenate([p[1:] for p in lines])
    x, y = uv[:, :1], uv[:, 1:]
    straddle = (a[:, 1] <= y) != (b[:, 1] <= y)
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return np.sum(straddle & (cross > x), axis=1) % 2 == 1


def test_raster_decides_the_far_sides_of_its_box():
    """A grid over a face's box ends on its far sides (u = u1, v = v1): those points lie in the last cells and are
    decided there as the near sides' are, on the boundary where it runs along the side and outside where the
    domain does not reach it, not left to the kernel.  Just beyond the box the border cells still leave them to
    it (a periodic surface's kernel takes such a point into its period)."""
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], float)
    raster = DomainRaster.build([square], (0, 1, 0, 1), n=64, tolerance=1e-9)
    g = np.linspace(0, 1, 101)
    sides = np.concatenate([np.column_stack([np.ones_like(g), g]), np.column_stack([g, np.ones_like(g)]),
                            np.column_stack([np.zeros_like(g), g]), np.column_stack([g, np.zeros_like(g)])])
    assert np.all(raster.classify(sides) == Trim.ON_BOUNDARY)
    assert np.all(raster.classify(sides[:202] + 1e-6) == Trim.UNSURE)
    # a triangle in the square's box: its far sides reach the box at one corner, the rest is outside
    triangle = np.array([[0, 0], [1, 0], [0, 1], [0, 0]], float)
    raster = DomainRaster.build([triangle], (0, 1, 0, 1), n=64, tolerance=1e-9)
    state = raster.classify(sides[:202])
    corner = np.all(sides[:202] == [1, 0], axis=1) | np.all(sides[:202] == [0, 1], axis=1)
    apart = np.minimum(np.linalg.norm(sides[:202] - [1, 0], axis=1), np.linalg.norm(sides[:202] - [0, 1], axis=1))
    assert np.all(state[corner] == Trim.ON_BOUNDARY)
    assert np.all(state[apart > 2 / 64] == Trim.OUTSIDE)        # (next to a vertex its way may pass it: UNSURE)


def test_raster_of_a_polygon_decides_next_to_its_edges():
    """A star polygon given in three open pieces (one polyline per "edge", in any orientation): the points
    next to its edges are decided as the even-odd rule decides them, the points on its vertices and edges
    (within half the tolerance) are ON_BOUNDARY, and a point whose way from its cell's centre passes through a
    gap between two pieces is UNSURE."""
    t = np.linspace(0, 2 * np.pi, 41)
    radius = np.where(np.arange(41) % 2 == 0, 0.45, 0.2)
    star = 0.5 + radius[:, None] * np.column_stack([np.cos(t), np.sin(t)])
    pieces = [star[:15], star[14:30][::-1], star[29:]]
    raster = DomainRaster.build(pieces, (0, 1, 0, 1), n=64, tolerance=1e-9)
    rng = np.random.default_rng(4)
    edge = rng.integers(0, 40, 100_000)
    along = rng.uniform(0, 1, (100_000, 1))
    uv = star[edge] + along * (star[edge + 1] - star[edge]) + rng.normal(0, 1e-3, (100_000, 2))
    state = raster.classify(uv)
    decided = (state == Trim.INSIDE) | (state == Trim.OUTSIDE)
    assert decided.mean() > 0.999
    assert np.all((state[decided] == Trim.INSIDE) == _even_odd(uv[decided], [star]))
    on = np.concatenate([star[:40], 0.5 * (star[:40] + star[1:41]) + 1e-10])
    assert np.all(raster.classify(on) == Trim.ON_BOUNDARY)
    # the first piece moved a hair (1e-4), so that gaps open at its ends: a point whose way passes one is the
    # kernel's
    apart = DomainRaster.build([star[:15] + [0.0, 1e-4], star[14:30], star[29:]], (0, 1, 0, 1), n=64)
    cell = np.floor(star[14] * 64)
    centre = (cell + 0.5) / 64
    beyond = centre + 1.05 * (star[14] + [0.0, 0.5e-4] - centre)      # through the middle of the gap
    assert np.all(beyond // (1 / 64) == cell)          # (the same cell)
    assert apart.classify(beyond[None])[0] == Trim.UNSURE


def test_raster_leaves_the_points_within_a_margin_to_the_kernel():
    """A boundary curve that bulges from its polyline (an arc given by its chord and its middle point):
    the points between chord and curve are UNSURE, not decided by the chord."""
    chord = np.array([[0.2, 0.5], [0.8, 0.5]])
    arc_middle = np.array([[0.5, 0.52]])
    outer = np.array([[0.8, 0.5], [0.8, 0.1], [0.2, 0.1], [0.2, 0.5]])
    middles = [arc_middle, 0.5 * (outer[:-1] + outer[1:])]
    raster = DomainRaster.build([chord, outer], (0, 1, 0, 1), n=4, midpoints=middles)
    between = np.column_stack([np.linspace(0.3, 0.7, 50), np.full(50, 0.51)])
    assert np.all(raster.classify(between) == Trim.UNSURE)
    assert np.all(raster.classify(np.array([[0.5, 0.6], [0.5, 0.3]])) == [Trim.OUTSIDE, Trim.INSIDE])
    with pytest.raises(ValueError, match="midpoints"):
        DomainRaster.build([chord, outer], (0, 1, 0, 1), n=4, midpoints=[arc_middle, arc_middle])


def test_raster_leaves_a_wide_margin_to_the_kernel_without_listing_it():
    """A boundary curve far from its one-segment polyline (its middle 0.3 off the chord, 77 cells of margin on a
    raster of 64): the cells it comes near are the kernel's, and the raster does not list that segment in them
    (its lists would grow as the square of the margin); with the curve on its chord the points are decided."""
    chord = np.array([[0.2, 0.5], [0.8, 0.5]])
    outer = np.array([[0.8, 0.5], [0.8, 0.1], [0.2, 0.1], [0.2, 0.5]])
    outer_middles = 0.5 * (outer[:-1] + outer[1:])
    raster = DomainRaster.build([chord, outer], (0, 1, 0, 1), n=64, midpoints=[np.array([[0.5, 0.8]]), outer_middles])
    assert raster.kernel.sum() > 0.8 * 64 * 64 and not np.any(raster.items == 0)     # (segment 0: the chord)
    assert np.all(raster.classify(np.array([[0.5, 0.51], [0.5, 0.3]])) == Trim.UNSURE)
    narrow = DomainRaster.build([chord, outer], (0, 1, 0, 1), n=64, midpoints=[np.array([[0.5, 0.5]]), outer_middles])
    assert not narrow.kernel.any()
    assert np.all(narrow.classify(np.array([[0.5, 0.3], [0.5, 0.51], [0.21, 0.3]])) ==
                  [Trim.INSIDE, Trim.OUTSIDE, Trim.INSIDE])


def test_pcurve_points_are_the_kernels_for_every_kind_of_pcurve():
    """``pcurve_points`` evaluates lines, circles and B-splines in numpy, and other pcurves (an ellipse) by the
    kernel: every kind gives the kernel's points to rounding, on a part as built (lines, circles, an ellipse on
    the slanted cut's plane) and on the same part converted to B-splines (B-spline pcurves, rational ones)."""
    import cadquery as cq
    from OCP.BRepAdaptor import BRepAdaptor_Curve2d
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Common
    from OCP.GeomAbs import GeomAbs_BSplineCurve, GeomAbs_Circle, GeomAbs_Ellipse, GeomAbs_Line
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    from hot2cold.kernel.conversion import to_bspline
    from hot2cold.kernel.project import pcurve_points
    from hot2cold.kernel.sampling import face_list

    made = cq.Workplane().box(20, 20, 10).faces(">Z").workplane().hole(6).val().wrapped
    slant = cq.Workplane().cylinder(30, 4).val().rotate((0, 0, 0), (1, 0, 0), 30).wrapped
    cut = BRepAlgoAPI_Common(slant, cq.Workplane().box(40, 40, 20).val().wrapped).Shape()
    seen = set()
    for shape in (made, cut, to_bspline(made), to_bspline(cut)):
        for face in face_list(shape):
            explorer = TopExp_Explorer(face, TopAbs_EDGE)
            while explorer.More():
                curve = BRepAdaptor_Curve2d(TopoDS.Edge_s(explorer.Current()), face)
                t = np.linspace(curve.FirstParameter(), curve.LastParameter(), 57)
                kernel = np.array([(q.X(), q.Y()) for q in map(curve.Value, t)])
                got = pcurve_points(curve)(t)
                assert got.shape == (57, 2)
                np.testing.assert_allclose(got, kernel, rtol=0, atol=1e-12 * max(1.0, np.abs(kernel).max()))
                seen.add(curve.GetType())
                explorer.Next()
    assert {GeomAbs_Line, GeomAbs_Circle, GeomAbs_Ellipse, GeomAbs_BSplineCurve} <= seen


@pytest.mark.heavy
def test_classify_matches_fclass2d(part):
    """``Projector.classify`` (raster + kernel at the boundary) equals ``BRepTopAdaptor_FClass2d`` point by
    point, on random points of each face's box and points close to its edges."""
    rng = np.random.default_rng(5)
    projector = Projector(part.kernel.faces, part.kernel.edges)
    for face in part.faces:
        u0, u1, v0, v1 = face.uv_box
        size = np.array([u1 - u0, v1 - v0])
        uv = [np.column_stack([rng.uniform(u0 - 0.01 * size[0], u1 + 0.01 * size[0], 3000),
                               rng.uniform(v0 - 0.01 * size[1], v1 + 0.01 * size[1], 3000)])]
        for use in face.uses:
            pick = use.uv[rng.integers(0, len(use.uv), 200)]
            uv += [pick + rng.normal(0, 1e-3, pick.shape) * size, pick + rng.normal(0, 1e-7, pick.shape) * size]
        uv = np.concatenate(uv)
        np.testing.assert_array_equal(projector.classify(face.index, uv), projector.classify_exactly(face.index, uv))


@pytest.mark.heavy
def test_classification_matches_direct_projection():
    """Rotor 37 with 2500 nodes (surface nodes of its CalculiX field): the classification equals the direct
    approach, every node projected by the kernel onto every face and the nearest inside foot point kept."""
    part = load_part(SAMPLES / "rotor37_blade.step", Settings())
    data = np.load(SAMPLES / "rotor37_blade_field.npz")
    pick = np.random.default_rng(11).choice(len(data["points"]), 2500, replace=False)
    field = as_field((data["points"][pick], data["displacements"][pick]), "mm", None)
    projector = Projector(part.kernel.faces, part.kernel.edges)
    settings = Settings()
    cls = classify_nodes(part, field, settings, projector)
    node_distance, _ = settings.lengths(part.diagonal)

    best = np.full(len(pick), np.inf)
    owner = np.full(len(pick), -1)
    uv = np.full((len(pick), 2), np.nan)
    for face in part.faces:
        f_uv, f_dist = projector.to_face(face.index, field.points)
        inside = projector.classify_exactly(face.index, f_uv) != Trim.OUTSIDE
        better = inside & (f_dist <= node_distance) & (f_dist < best)
        best[better], owner[better], uv[better] = f_dist[better], face.index, f_uv[better]
    on_face = cls.role == Role.FACE
    assert on_face.sum() > 2000
    np.testing.assert_array_equal(cls.owner[on_face], owner[on_face])
    np.testing.assert_allclose(cls.distance[on_face], best[on_face], rtol=0, atol=1e-9)
    size = np.array([f.uv_box[[1, 3]] - f.uv_box[[0, 2]] for f in part.faces])[owner[on_face]]
    assert np.max(np.abs(cls.uv[on_face] - uv[on_face]) / size) < 1e-9
    # Nodes the classification gave to edges and vertices had a foot point on a face in the direct approach.
    assert np.all(owner[cls.used] >= 0)


@pytest.mark.parametrize("limit", [0.0, 1e-3, 5e-3, 1.0, np.inf])
def test_distances_above_a_limit_are_exact_there_and_at_the_largest(limit):
    """The refinement's errors at the nodes and G1's largest distance from the field: the Gauss-Newton distance
    wherever it can exceed the limit or be the largest, the distance at the point's own parameters (a bound)
    elsewhere."""
    surface = BSplineSurface(np.random.default_rng(4).normal(size=(6, 4, 3)),
                             np.concatenate([np.zeros(4), [0.3, 0.6], np.ones(4)]),
                             np.concatenate([np.zeros(3), [0.5], np.ones(3)]), 3, 2)
    rng = np.random.default_rng(5)
    uv = rng.uniform(0.0, 1.0, (5000, 2)) * [surface.domain[1], surface.domain[3]]
    normal_ish = rng.normal(size=(len(uv), 3))
    points = evaluate_surface(surface, uv[:, 0], uv[:, 1]) + rng.exponential(2e-3, (len(uv), 1)) * normal_ish
    box = surface.domain
    exact = surface_distances(surface, points, uv, box, past_border=True)
    found, feet = surface_distances_above(surface, points, uv, box, limit, return_uv=True)
    assert feet.shape == uv.shape and np.all(feet >= [box[0], box[2]]) and np.all(feet <= [box[1], box[3]])
    bounded = found != exact                    # not projected: found at the points' own parameters
    np.testing.assert_array_equal(feet[bounded], uv[bounded])
    assert found.max() == exact.max()
    above = exact > limit
    np.testing.assert_array_equal(found[above], exact[above])
    assert np.all(found >= exact) and not np.any(found[~above] > limit)
    if limit == 0.0:
        np.testing.assert_array_equal(found, exact)
    else:                                      # the points within the limit keep their bounds, unprojected
        assert np.count_nonzero(found != exact) > 1000           # measured: 1570 of 5000 at 1e-3 mm


@pytest.mark.parametrize("clearance", [1, 3, 48])
def test_candidate_faces_are_those_of_the_k_nearest_samples(clearance, monkeypatch):
    """``_candidates``: a point's owners are those of its ``k`` nearest samples within ``margin`` of its
    nearest, none beyond ``reach + margin``; the points whose nearest sample is clear of other owners' take
    its owner alone, as from their ``k`` nearest (samples of two owners at one point included), however
    many of a sample's nearest its clearance is looked for among (1: none is clear, every point is asked)."""
    from scipy.spatial import cKDTree

    from hot2cold.pipeline import classify
    from hot2cold.pipeline.classify import _candidates

    monkeypatch.setattr(classify, "CLEARANCE_NEIGHBOURS", clearance)

    rng = np.random.default_rng(3)
    for trial in range(40):
        samples = rng.uniform(0, 5, (int(rng.integers(2, 300)), 3))
        owner = rng.integers(0, 4, len(samples))
        samples = np.concatenate([samples, samples[:5]])             # edge samples: one point, two owners
        owner = np.concatenate([owner, owner[:5] + 1])
        points = rng.uniform(-0.5, 5.5, (200, 3))
        reach, margin, k = rng.uniform(0, 0.5), rng.uniform(0, 0.4), int(rng.integers(1, 30))
        node, face = _candidates(cKDTree(samples), owner, points, reach, margin, k)
        got = set(zip(node.tolist(), face.tolist()))
        d = np.linalg.norm(points[:, None] - samples[None], axis=2)
        kth = np.sort(d, axis=1)[:, min(k, len(samples)) - 1]
        surely, maybe = set(), set()          # a sample tied with the k-th nearest may be taken or not
        for i in range(len(points)):
            d0 = d[i].min()
            if d0 <= reach + margin:
                within = d[i] <= d0 + margin
                surely |= {(i, int(o)) for o in owner[within & (d[i] < kth[i])]}
                maybe |= {(i, int(o)) for o in owner[within & (d[i] <= kth[i])]}
        assert surely <= got <= maybe, trial
        assert np.all(np.diff(face.astype(np.int64) * len(points) + node) > 0)      # by owner, then point


@pytest.mark.heavy
def test_starts_shared_by_the_check_and_the_classification_change_nothing():
    """``classify.Starts`` keeps each face's start grid and the candidate clouds for every classification of
    the part's nodes: the check of a sample of the nodes (``part_distances``) and then the classification of
    them all, sharing one, classify every node as a classification with starts of its own does (Rotor 37, 3 000
    surface nodes of its CalculiX field), and the shared clouds are the same objects where the spacing is."""
    from hot2cold.pipeline.classify import Starts, part_distances

    part = load_part(SAMPLES / "rotor37_blade.step", Settings())
    data = np.load(SAMPLES / "rotor37_blade_field.npz")
    pick = np.random.default_rng(5).choice(len(data["points"]), 3000, replace=False)
    field = as_field((data["points"][pick], data["displacements"][pick]), "mm", None)
    settings = Settings()
    fresh = classify_nodes(part, field, settings, Projector(part.kernel.faces, part.kernel.edges))
    projector = Projector(part.kernel.faces, part.kernel.edges)
    starts = Starts(part)
    near = part_distances(part, field.points[:500], projector, settings.lengths(part.diagonal)[0], 1, starts)
    assert np.isfinite(near).mean() > 0.9
    shared = classify_nodes(part, field, settings, projector, starts)
    np.testing.assert_array_equal(shared.role, fresh.role)
    np.testing.assert_array_equal(shared.owner, fresh.owner)
    np.testing.assert_allclose(shared.distance[fresh.used], fresh.distance[fresh.used], rtol=0, atol=1e-12)
    assert starts.cloud(projector, 3000) is starts.cloud(projector, 3000)
