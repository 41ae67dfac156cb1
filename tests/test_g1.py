"""G1 correction along tangent edges (paper section 5, eq. 56-75)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hot2cold.core.bspline import BSplineCurve, BSplineSurface, evaluate_surface, normal_rounding
from hot2cold.pipeline.g1 import (MEASURABLE_DEG, NOT_ISO_SIDE, REFINED, TangentEdge, correct_g1, edge_kinks,
                                 kink_added, kink_angles, kink_maxima, kink_misses, tangent_edges)
from hot2cold.core.model import Edge, EdgeUse, Face, Part

CUBIC5 = np.array([0, 0, 0, 0, 0.5, 1, 1, 1, 1.0])              # 5 poles, degree 3
CUBIC6 = np.array([0, 0, 0, 0, 1 / 3, 2 / 3, 1, 1, 1, 1.0])      # 6 poles, degree 3


def _height(x, y):
    return 0.3 * np.sin(1.3 * x) + 0.2 * np.cos(0.9 * y) + 0.05 * x * y


def _patches(weights: bool = False) -> tuple[BSplineSurface, BSplineSurface]:
    """Two bicubic patches (5 x 6 poles) on [0, 1]^2 sharing the row A[4, :] == B[0, :], G1 (indeed C1)
    across it.

    Non-rational: B[1] - B[0] == A[4] - A[3] with equal knot steps at the seam.  Rational: product weights
    ``w_ij = a_i b_j`` (same ``b`` on both patches, so the common row has the same weights), for which the
    derivative across the seam is ``(p / dU) (a_3 / a_4) (Q_4 - Q_3)`` with ``Q_i(v)`` the rational v-curves,
    so ``B[1] - B[0] = (a_3 / a_4) (a'_0 / a'_1) (A[4] - A[3])`` keeps it C1."""
    y = np.linspace(0.0, 3.0, 6)
    xa = np.array([0.0, 0.4, 1.0, 1.6, 2.0])
    a = np.stack(np.meshgrid(xa, y, indexing="ij"), axis=-1)
    a = np.concatenate([a, _height(a[..., 0], a[..., 1])[..., None]], axis=-1)
    ra = np.array([1.0, 1.2, 0.8, 1.3, 1.0])
    rb = np.array([1.0, 0.7, 1.1, 0.9, 1.2])
    cb = np.array([1.0, 0.8, 1.3, 0.9, 1.1, 1.0])
    factor = (ra[3] / ra[4]) * (rb[0] / rb[1]) if weights else 1.0
    b = np.empty_like(a)
    b[0] = a[4]
    b[1] = a[4] + factor * (a[4] - a[3])
    xb = np.array([2.8, 3.4, 4.0])
    for k, x in enumerate(xb, start=2):
        b[k, :, 0] = x
        b[k, :, 1] = y
        b[k, :, 2] = _height(x, y)
    wa = np.outer(ra, cb) if weights else None
    wb = np.outer(rb, cb) if weights else None
    return (BSplineSurface(a, CUBIC5, CUBIC6, 3, 3, wa), BSplineSurface(b, CUBIC5, CUBIC6, 3, 3, wb))


def _part(sa: BSplineSurface, sb: BSplineSurface) -> Part:
    """A two-face part whose only edge is side u1 of face 0 and side u0 of face 1."""
    t = np.linspace(0.0, 1.0, 25)
    edge = Edge(0, BSplineCurve(sa.poles[-1], CUBIC6, 3, None if sa.weights is None else sa.weights[-1]),
                (0, 1), (0, 1))
    faces = [Face(0, sa, np.array([0, 1, 0, 1.0]), (EdgeUse(0, t, np.column_stack([np.ones_like(t), t])),), 0),
             Face(1, sb, np.array([0, 1, 0, 1.0]), (EdgeUse(0, t, np.column_stack([np.zeros_like(t), t])),), 0)]
    return Part(faces, [edge], np.array([sa.poles[-1, 0], sa.poles[-1, -1]]), [(0, 1)], 6.0, None)


ALL_SIDES = ("u0", "u1", "v0", "v1")


def _kink(surfaces, part, edge=0):
    fa, fb = part.edges[edge].faces
    ua = next(u for u in part.faces[fa].uses if u.edge == edge)
    ub = next(u for u in part.faces[fb].uses if u.edge == edge)
    return float(np.nanmax(kink_angles(surfaces[fa], ua.uv, surfaces[fb], ub.uv)))


def _kinked(sb: BSplineSurface, degrees: float) -> BSplineSurface:
    """``sb`` with the interior poles of its second row lifted non-uniformly (ends kept: they lie on the tied
    sides v0, v1) so that the kink across side u0 is about ``degrees``."""
    poles = sb.poles.copy()
    lift = np.array([0.0, 0.6, 1.0, 0.8, 0.4, 0.0])
    step = np.linalg.norm(poles[1] - poles[0], axis=1).mean()
    poles[1, :, 2] += np.radians(degrees) * step * lift
    return sb.with_poles(poles)


@pytest.mark.parametrize("weights", [False, True])
def test_synthetic_kink_removed(weights):
    sa, sb = _patches(weights)
    part = _part(sa, sb)
    # built G1: tangent_edges finds the seam with a hot angle at rounding level
    edges = tangent_edges(part)
    assert [e.edge for e in edges] == [0]
    assert edges[0].sides == (("u1", False), ("u0", False))
    assert edges[0].hot_angle_max < 1e-9
    kinked = _kinked(sb, 0.5)
    before = _kink([sa, kinked], part)
    assert 0.2 < before < 1.5
    surfaces, reports = correct_g1(part, [sa, kinked], [ALL_SIDES, ALL_SIDES], edges)
    (rep,) = reports
    assert rep.corrected and rep.reason == ""
    assert rep.kink_before_max == pytest.approx(before)
    # the kinks before given by a caller that knows them (rounds on the same surfaces): the same correction
    again, (rep_again,) = correct_g1(part, [sa, kinked], [ALL_SIDES, ALL_SIDES], edges,
                                     before=kink_maxima(part, [sa, kinked], edges))
    assert (rep_again.kink_before_max, rep_again.kink_after_max, rep_again.method) == \
        (rep.kink_before_max, rep.kink_after_max, rep.method)
    assert all(np.array_equal(a.poles, b.poles) for a, b in zip(again, surfaces))
    assert rep.kink_after_max <= 0.01
    assert _kink(surfaces, part) <= 0.01
    # the common row (and everything but the interior of the second rows) is bit for bit unchanged
    assert np.array_equal(surfaces[0].poles[-1], sa.poles[-1])
    assert np.array_equal(surfaces[1].poles[0], sb.poles[0])
    assert np.array_equal(surfaces[0].poles[[0, 1, 2, 4]], sa.poles[[0, 1, 2, 4]])
    assert np.array_equal(surfaces[1].poles[[0, 2, 3, 4]], kinked.poles[[0, 2, 3, 4]])
    assert np.array_equal(surfaces[1].poles[1, [0, -1]], kinked.poles[1, [0, -1]])
    # both faces move, each by less than the perturbation
    moved_a = np.abs(surfaces[0].poles - sa.poles).max()
    moved_b = np.abs(surfaces[1].poles - kinked.poles).max()
    perturbation = np.abs(kinked.poles - sb.poles).max()
    assert 0 < moved_a < perturbation and 0 < moved_b < perturbation


def test_neither_face_can_turn_so_the_edge_is_only_measured():
    sa, sb = _patches()
    part = _part(sa, sb)
    # the edge as a pcurve that is not a side of face 1 (a diagonal), and face 0 held all round two poles
    # deep: reported, not corrected
    use = part.faces[1].uses[0]
    diagonal = EdgeUse(0, use.t, np.column_stack([0.5 * use.t, use.t]))
    thin_a = BSplineSurface(sa.poles[-2:], np.array([0, 0, 1, 1.0]), CUBIC6, 1, 3)
    faces = [Face(0, thin_a, part.faces[0].uv_box, part.faces[0].uses, 0),
             Face(1, sb, part.faces[1].uv_box, (diagonal,), 0)]
    part2 = Part(faces, part.edges, part.vertices, part.solids, part.diagonal, None)
    edges = [TangentEdge(0, (0, 1), (("u1", False), None), 0.0)]
    surfaces, (rep,) = correct_g1(part2, [thin_a, sb], [ALL_SIDES, ALL_SIDES], edges)
    assert not rep.corrected
    assert "opposite boundary row" in rep.reason and NOT_ISO_SIDE in rep.reason
    assert rep.kink_after_max == rep.kink_before_max
    assert surfaces[0] is thin_a and surfaces[1] is sb


def test_a_face_that_cannot_turn_stays_and_the_other_turns_into_its_plane():
    sa, sb = _patches()
    # face 1 two poles deep across the seam: its second row is its far boundary, so only face 0 can turn
    thin = BSplineSurface(sb.poles[:2], np.array([0, 0, 1, 1.0]), CUBIC6, 1, 3)
    part = _part(sa, thin)
    kinked_a = _kinked(sa.with_poles(sa.poles[::-1]), 0.5)          # lift face 0's second row from its u1 side
    kinked_a = kinked_a.with_poles(kinked_a.poles[::-1])
    before = _kink([kinked_a, thin], part)
    assert 0.2 < before < 1.5
    edges = [TangentEdge(0, (0, 1), (("u1", False), ("u0", False)), 0.0)]
    surfaces, (rep,) = correct_g1(part, [kinked_a, thin], [ALL_SIDES, ALL_SIDES], edges)
    assert rep.corrected and rep.reason == ""
    assert rep.kink_before_max == pytest.approx(before)
    assert rep.kink_after_max <= 0.01
    assert surfaces[1] is thin
    moved = np.abs(surfaces[0].poles - kinked_a.poles).max(axis=-1)
    assert moved[3, 1:-1].all() and not np.delete(moved, 3, axis=0).any() and not moved[3, [0, -1]].any()


def test_second_row_of_two_edges_serves_both():
    """A middle face three poles deep between two others: the second rows at its sides u0 and u1 are the
    same row; it is solved for both edges at once and both kinks close."""
    sa, sb = _patches()
    middle = BSplineSurface(np.stack([sa.poles[-1], sb.poles[1], sb.poles[2]]), np.array([0, 0, 0, 1, 1, 1.0]),
                            CUBIC6, 2, 3)
    kinked = _kinked(middle, 0.5)
    # the far face continues the middle one C1 across its side u1 (degree 2: P3 - P2 = P2 - P1)
    far_poles = np.stack([middle.poles[2] + k * (middle.poles[2] - middle.poles[1]) for k in range(5)])
    far = BSplineSurface(far_poles, CUBIC5, CUBIC6, 3, 3)
    far = far.with_poles(far.poles.copy())
    t = np.linspace(0.0, 1.0, 25)

    def use(edge, u):
        return EdgeUse(edge, t, np.column_stack([np.full_like(t, u), t]))

    box = np.array([0, 1, 0, 1.0])
    faces = [Face(0, sa, box, (use(0, 1.0),), 0), Face(1, middle, box, (use(0, 0.0), use(1, 1.0)), 0),
             Face(2, far, box, (use(1, 0.0),), 0)]
    edges = [Edge(0, BSplineCurve(sa.poles[-1], CUBIC6, 3), (0, 1), (0, 1)),
             Edge(1, BSplineCurve(middle.poles[-1], CUBIC6, 3), (2, 3), (1, 2))]
    part = Part(faces, edges, np.zeros((4, 3)), [(0, 1, 2)], 8.0, None)
    tangent = tangent_edges(part)
    assert [te.edge for te in tangent] == [0, 1]
    surfaces, reports = correct_g1(part, [sa, kinked, far], [ALL_SIDES] * 3, tangent)
    assert all(r.corrected for r in reports)
    assert min(r.kink_before_max for r in reports) > 0.1
    assert max(r.kink_after_max for r in reports) <= 0.01


# ------------------------------------------------------------------------------------------------------
# The twisted blade: four side faces meet G1 along four span-wise edges (tied whole sides); the caps meet
# them at about 85-90 degrees.
# ------------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def blade_part(blade_shape):
    from hot2cold.kernel.topology import decompose
    return decompose(blade_shape)


def test_tangent_edges_of_blade(blade_part):
    found = tangent_edges(blade_part)
    assert len(found) == 4
    for te in found:
        assert None not in te.sides                       # whole sides of both faces
        assert te.hot_angle_max < 1e-3
        for k in te.faces:
            assert blade_part.faces[k].surface.shape[0] > 2  # side faces, not the planar caps
    # every other two-face edge meets at a sharp angle (the caps, at ~85-90 deg)
    others = {e.index for e in blade_part.edges} - {te.edge for te in found}
    for e in others:
        edge = blade_part.edges[e]
        fa, fb = (blade_part.faces[k] for k in edge.faces)
        ua = next(u for u in fa.uses if u.edge == e)
        ub = next(u for u in fb.uses if u.edge == e)
        assert np.nanmax(kink_angles(fa.surface, ua.uv, fb.surface, ub.uv)) > 60
    side_faces = {f.index for f in blade_part.faces if f.surface.shape[0] > 2}
    assert {te.edge for te in found} == {e.index for e in blade_part.edges if set(e.faces) <= side_faces}


def test_blade_kinks_removed(blade_part):
    part = blade_part
    found = tangent_edges(part)
    hot = [f.surface for f in part.faces]
    surfaces = list(hot)
    rng = np.random.default_rng(7)
    perturbed_rows = {}
    for te in found:
        for k, (side, _) in zip(te.faces, te.sides):
            axis, end = side.axis, side.end
            s = surfaces[k]
            i = 1 if end == 0 else s.shape[axis] - 2
            poles = s.poles.copy()
            row = poles[i] if axis == 0 else poles[:, i]
            n = len(row)
            # smooth, non-affine, different per row; the row's ends lie on the tied cap edges and stay
            shape = np.sin(np.pi * np.linspace(0, 1, n)) ** 2 * (1 + 0.5 * np.cos(3 * np.linspace(0, 1, n)))
            # about 0.5 deg: the lift relative to the distance between the side row and the second row
            side_row = poles[0 if end == 0 else -1] if axis == 0 else poles[:, 0 if end == 0 else -1]
            step = np.linalg.norm(row - side_row, axis=1).mean()
            direction = rng.normal(size=3)
            row += np.radians(0.5) * step * shape[:, None] * direction / np.linalg.norm(direction)
            surfaces[k] = s.with_poles(poles)
            perturbed_rows.setdefault(k, []).append((axis, i))
    perturbed = list(surfaces)
    perturbation = max(np.abs(a.poles - b.poles).max() for a, b in zip(perturbed, hot))
    tied = [("u0", "u1", "v0", "v1") if f.surface.shape[0] > 2 else () for f in part.faces]
    corrected, reports = correct_g1(part, perturbed, tied, found)
    assert len(reports) == 4
    for rep, te in zip(reports, found):
        assert rep.corrected, rep.reason
        assert 0.1 < rep.kink_before_max < 2
        assert rep.kink_after_max <= 0.01
        # common edge rows unchanged bit for bit
        for k, (side, _) in zip(te.faces, te.sides):
            axis, end = side.axis, side.end
            i = 0 if end == 0 else hot[k].shape[axis] - 1
            index = (i, slice(None)) if axis == 0 else (slice(None), i)
            assert np.array_equal(corrected[k].poles[index], perturbed[k].poles[index])
    for k, (new, old) in enumerate(zip(corrected, perturbed)):
        moved = np.abs(new.poles - old.poles).max(axis=-1)
        assert moved.max() < perturbation
        # nothing but the perturbed second rows moved
        mask = np.zeros(moved.shape, bool)
        for axis, i in perturbed_rows.get(k, []):
            if axis == 0:
                mask[i] = True
            else:
                mask[:, i] = True
        assert not moved[~mask].any()
        # and the surface moves less than the perturbation moved it
        u0, u1, v0, v1 = new.domain
        uu, vv = np.meshgrid(np.linspace(u0, u1, 30), np.linspace(v0, v1, 30), indexing="ij")
        d_fix = np.linalg.norm(evaluate_surface(new, uu.ravel(), vv.ravel())
                               - evaluate_surface(old, uu.ravel(), vv.ravel()), axis=1)
        d_pert = np.linalg.norm(evaluate_surface(old, uu.ravel(), vv.ravel())
                                - evaluate_surface(hot[k], uu.ravel(), vv.ravel()), axis=1)
        assert d_fix.max() <= d_pert.max() + 1e-12


def test_corners_of_tangent_edges_get_one_tangent_plane(blade_part):
    """Turning the cap edges at the blade's corners (as edges fitted one by one do) opens a kink at the
    ends of the span-wise tangent edges; correct_corners closes it by moving only the cap edges' poles next
    to those vertices."""
    from hot2cold.pipeline.g1 import correct_corners
    part = blade_part
    found = tangent_edges(part)
    corner_vertices = {v for te in found for v in part.edges[te.edge].vertices}
    curves = [e.curve for e in part.edges]
    rng = np.random.default_rng(3)
    for e in part.edges:
        if not set(e.vertices) & corner_vertices or e.index in {te.edge for te in found}:
            continue
        poles = e.curve.poles.copy()
        for end, v in enumerate(e.vertices):
            if v in corner_vertices:
                i = 1 if end == 0 else -2
                poles[i] += 0.02 * np.linalg.norm(poles[i] - poles[0 if end == 0 else -1]) * rng.normal(size=3)
        curves[e.index] = e.curve.with_poles(poles)
    corrected, reports = correct_corners(part, curves, found)
    assert {r.vertex for r in reports} == corner_vertices
    assert all(r.reason == "" and r.angle_before > 0.1 and r.angle_after < 1e-6 for r in reports), reports
    for e, before, after in zip(part.edges, curves, corrected):
        moved = np.abs(after.poles - before.poles).max(axis=-1)
        assert not moved[[0, -1]].any()                           # vertices stay
        if e.index in {te.edge for te in found}:
            assert moved.max() < 1e-9                             # span-wise edges: already in the plane
        # a pole next to a vertex moves by less than the perturbation put it off (at most 0.1 of its spacing)
        spacing = np.linalg.norm(np.diff(before.poles, axis=0), axis=1)
        assert moved[1] <= 0.1 * spacing[0] + 1e-12 and moved[-2] <= 0.1 * spacing[-1] + 1e-12
        assert not moved[2:-2].any()


def test_zero_kink_added_moves_no_corner(blade_part):
    from hot2cold.pipeline.g1 import correct_corners
    curves = [e.curve for e in blade_part.edges]
    corrected, reports = correct_corners(blade_part, curves, tangent_edges(blade_part))
    assert all(a is b for a, b in zip(corrected, curves))
    assert all(r.reason == "no kink added" for r in reports)


def test_corners_touched_are_the_ends_and_what_a_short_edge_turns_at_its_far_end(blade_part):
    """An edge's refit touches the corners at its ends; an edge there of three poles or fewer (whose pole next to
    one end is next to the other too) carries the change to its far end."""
    from hot2cold.pipeline.g1 import corners_touched
    part = blade_part
    curves = [e.curve for e in part.edges]
    e = next(e for e in part.edges if not e.degenerate and e.vertices[0] != e.vertices[1])
    ends = set(e.vertices)
    assert all(c is None or c.n_poles > 3 for c in curves)          # the blade's edges: no short ones
    assert corners_touched(part, curves, {e.index}) == ends
    # make the other edges at one end quadratics of three poles: their far ends are touched too
    v = e.vertices[0]
    short = [f for f in part.vertex_edges[v] if f != e.index and curves[f] is not None]
    for f in short:
        c = curves[f]
        curves[f] = BSplineCurve(c.poles[[0, len(c.poles) // 2, -1]], np.r_[[c.knots[0]] * 3, [c.knots[-1]] * 3], 2)
    far = {w for f in short for w in part.edges[f].vertices}
    assert far - ends and corners_touched(part, curves, {e.index}) >= ends | far


def test_corners_corrected_at_given_vertices_only(blade_part):
    """The corner correction is no projection (run on its own output it may move an edge again), so it corrects
    only the corners asked for: those one edge touches move only edges there, and none asked moves none."""
    from hot2cold.pipeline.g1 import corners_touched, correct_corners
    part = blade_part
    found = tangent_edges(part)
    curves = [e.curve for e in part.edges]
    rng = np.random.default_rng(5)
    bent = []
    for e in part.edges:
        if e.index in {te.edge for te in found} or e.degenerate:
            continue
        poles = e.curve.poles.copy()
        poles[1] += 0.02 * np.linalg.norm(poles[1] - poles[0]) * rng.normal(size=3)
        poles[-2] += 0.02 * np.linalg.norm(poles[-2] - poles[-1]) * rng.normal(size=3)
        curves[e.index] = e.curve.with_poles(poles)
        bent.append(e.index)
    one = bent[0]
    touched = corners_touched(part, curves, {one})
    corrected, reports = correct_corners(part, curves, found, vertices=touched)
    assert reports and {r.vertex for r in reports} <= touched
    moved = {k for k, (a, b) in enumerate(zip(curves, corrected)) if a is not b}
    assert one in moved
    assert all(set(part.edges[k].vertices) & touched for k in moved)
    assert set(bent) - moved                                      # bent edges elsewhere stay bent
    unmoved, none = correct_corners(part, curves, found, vertices=set())
    assert all(a is b for a, b in zip(unmoved, curves)) and none == []


def _untwist(nodes, rate, stretch):
    from hot2cold.testing.synthetic import UntwistField
    return UntwistField.over(nodes, rate, stretch)


def _morph_with_and_without_g1(shape, field):
    from hot2cold.pipeline.morph import morph
    from hot2cold.settings import Settings
    return morph(shape, field, Settings(g1_angle=None)), morph(shape, field)


@pytest.mark.heavy
def test_blade_bundled_field_every_tangent_edge_within_0_01_deg(blade_step):
    """The bundled blade and field (the CLI sample): every tangent edge within 0.01 deg after G1, never
    worse than before (the fit alone left 0.0129 deg at the corners before the artificial nodes improved;
    the block test below keeps a field whose plain fit misses 0.01 deg)."""
    from conftest import SAMPLES
    plain, result = _morph_with_and_without_g1(blade_step, SAMPLES / "twisted_blade_field.csv")
    g1 = result.report.g1
    assert len(g1) == 4 and all(g["corrected"] for g in g1)
    assert all(g["kink_after_max"] <= g["kink_before_max"] + 1e-9 for g in g1)
    assert max(g["kink_after_max"] for g in g1) <= 0.01
    # positions: the paper's accuracy is kept, face by face
    for a, b in zip(plain.report.faces, result.report.faces):
        assert b.delta_max <= max(1.05 * a.delta_max, 1e-4)
    assert result.report.delta_max <= 1e-3
    assert all(s.valid and s.closed for s in result.report.solids)


@pytest.mark.heavy
def test_filleted_block_every_tangent_edge_within_0_01_deg(block_shape, block_nodes):
    """Planes, cylinders and tori of the block under an untwist-and-stretch field (|d| up to 0.1 mm): every
    originally tangent edge, whether a whole side of both faces, of one, or none, ends within 0.01 deg."""
    field = _untwist(block_nodes, 0.03, 1e-4)
    plain, result = _morph_with_and_without_g1(block_shape, (block_nodes, field(block_nodes)))
    g1 = result.report.g1
    assert len(g1) == len(tangent_edges(result.part)) >= 24
    assert max(g["kink_before_max"] for g in g1) > 0.01
    assert max(g["kink_after_max"] for g in g1) <= 0.01
    for a, b in zip(plain.report.faces, result.report.faces):
        assert b.delta_max <= 1e-3
    assert result.report.delta_max <= 1.01 * plain.report.delta_max
    assert all(s.valid and s.closed for s in result.report.solids)


@pytest.mark.heavy
def test_filleted_block_under_a_stronger_field_is_refined_along_the_edges_its_nets_cannot_close(
        block_shape, block_nodes, monkeypatch):
    """Under a stronger untwist the second rows and turns leave two of the block's edges above 0.01 deg
    (0.0113 deg; a torus's 3x3 net has one free pole for its four sides): the faces along them are refined
    and corrected again, and every edge ends within 0.01 deg, no farther from the field than G1 without the
    refinement (measured: Δmax 2.26e-4 mm without, 1.20e-4 with; 7.5e-5 without G1 at all, see the note)."""
    import hot2cold.pipeline.continuity as continuity
    from hot2cold.pipeline.morph import morph
    field = _untwist(block_nodes, 0.05, 1e-4)
    data = (block_nodes, field(block_nodes))
    result = morph(block_shape, data)
    monkeypatch.setattr(continuity, "_G1_REFINEMENTS", 0)
    unrefined = morph(block_shape, data)
    before = unrefined.report.g1
    assert sum(g["kink_after_max"] - g["hot_angle_max"] > 0.01 for g in before) == 2
    g1 = result.report.g1
    assert max(g["kink_before_max"] for g in g1) > 0.01
    assert max(g["kink_after_max"] - g["hot_angle_max"] for g in g1) <= 0.01
    assert any(g["method"].endswith(REFINED) for g in g1)
    assert not any(g["method"].endswith(REFINED) for g in before)
    assert result.report.delta_max <= 1.1 * unrefined.report.delta_max
    assert result.report.delta_max <= 1e-3
    assert all(s.valid and s.closed for s in result.report.solids)


def test_trimmed_faces_on_a_side_share_their_row_and_close_the_kink():
    """Trimmed faces whose common edge covers part of a side of both surfaces (Rotor 37's leading and
    trailing edges): each was fitted on its own, so their side rows drifted apart; the rows are made one
    again and the second rows turn, closing the kink along the edge."""
    sa, sb = _patches()
    t = np.linspace(0.1, 0.9, 25)
    edge = Edge(0, BSplineCurve(sa.poles[-1], CUBIC6, 3), (0, 1), (0, 1))
    faces = [Face(0, sa, np.array([0, 1, 0.1, 0.9]), (EdgeUse(0, t, np.column_stack([np.ones_like(t), t])),), 0),
             Face(1, sb, np.array([0, 1, 0.1, 0.9]), (EdgeUse(0, t, np.column_stack([np.zeros_like(t), t])),), 0)]
    part = Part(faces, [edge], np.array([sa.poles[-1, 0], sa.poles[-1, -1]]), [(0, 1)], 6.0, None)
    drift = sb.poles.copy()
    drift[0, :, 2] += 2e-3 * np.sin(np.linspace(0, 3, 6))      # b's side row off a's, as two fits leave it
    kinked = _kinked(sb.with_poles(drift), 0.3)
    edges = tangent_edges(part)
    assert [e.edge for e in edges] == [0] and edges[0].sides == (None, None)    # not whole sides
    surfaces, (rep,) = correct_g1(part, [sa, kinked], [(), ()], edges)
    assert rep.corrected and rep.kink_before_max > 0.1
    assert rep.kink_after_max <= 0.01
    assert np.array_equal(surfaces[0].poles[-1], surfaces[1].poles[0])             # one row again
    assert np.allclose(surfaces[0].poles[-1], 0.5 * (sa.poles[-1] + drift[0]), rtol=0, atol=1e-15)


def test_two_nearly_parallel_corner_planes_on_one_pole_are_one_condition():
    """An edge of three poles constrained at both ends: its middle pole is the pole next to both vertices.
    Planes 1e-5 deg apart that disagree by 1e-6 mm ask for a move of about 1e-6 / 1e-7 = 10 mm if both are
    met; as one condition the pole moves by about the disagreement."""
    from hot2cold.pipeline.g1 import _least_change

    tilt = np.radians(1e-5)
    n0, n1 = np.array([0.0, 0.0, 1.0]), np.array([np.sin(tilt), 0.0, np.cos(tilt)])
    poles_at, delta = _least_change([(1, n0, 1e-6), (1, n1, -1e-6)])
    assert poles_at == [1]
    assert np.linalg.norm(delta) <= 2e-6
    # planes far apart are two conditions, both met exactly
    n2 = np.array([1.0, 0.0, 0.0])
    poles_at, delta = _least_change([(1, n0, 1e-3), (1, n2, -2e-3)])
    np.testing.assert_allclose([delta[0] @ n0, delta[0] @ n2], [1e-3, -2e-3], rtol=0, atol=1e-15)
    # two poles (a longer edge): each meets its own plane
    poles_at, delta = _least_change([(1, n0, 1e-3), (3, n1, 2e-3)])
    assert poles_at == [1, 3]
    np.testing.assert_allclose([delta[0] @ n0, delta[1] @ n1], [1e-3, 2e-3], rtol=0, atol=1e-15)


def _greville(knots: np.ndarray, degree: int) -> np.ndarray:
    return np.array([knots[i + 1:i + degree + 1].mean() for i in range(len(knots) - degree - 1)])


def _split_along_diagonal(eps: float) -> tuple[Part, BSplineSurface, BSplineSurface]:
    """One bicubic surface split along the curve ``u = v`` of its domain into two faces that meet tangentially
    there (the same surface on both sides: a trimming curve inside both domains, as a blade's sides split
    along a line of their surface), and the second face's copy lifted by ``eps * (v - u)`` mm along z (the
    net's Greville abscissae reproduce a linear function exactly): on the curve still, kinked there."""
    surface = _patches()[0]
    gu, gv = _greville(surface.u_knots, 3), _greville(surface.v_knots, 3)
    poles = surface.poles.copy()
    poles[..., 2] += eps * (gv[None, :] - gu[:, None])
    kinked = surface.with_poles(poles)
    t = np.linspace(0.0, 1.0, 41)
    uv = np.column_stack([0.05 + 0.9 * t, 0.05 + 0.9 * t])
    ends = evaluate_surface(surface, uv[[0, -1], 0], uv[[0, -1], 1])
    edge = Edge(0, BSplineCurve(ends, np.array([0, 0, 1, 1.0]), 1, None), (0, 1), (0, 1))
    faces = [Face(k, surface, np.array([0, 1, 0, 1.0]), (EdgeUse(0, t, uv),), 0) for k in (0, 1)]
    return Part(faces, [edge], ends, [(0, 1)], 6.0, None), surface, kinked


def test_turn_rows_ask_nothing_of_faces_that_meet_tangentially():
    """:func:`~hot2cold.pipeline.g1.turn_rows` of two faces that are tangent along their trimming curve ask
    for the pole displacements they have (rows times displacements equal the targets); an edge on a side of
    the face gets no rows (the second rows turn it)."""
    from hot2cold.pipeline.g1 import Neighbours, turn_rows

    part, surface, _ = _split_along_diagonal(0.0)
    moved = surface.with_poles(surface.poles + np.array([0.01, -0.02, 0.03]))      # both moved alike
    edges = [TangentEdge(0, (0, 1), (None, None), 0.0)]
    rows, targets = turn_rows(Neighbours(part, [moved, moved]), edges, 0, 10.0)
    assert rows.shape == (2 * 2 * (5 + 6), 30) and targets.shape == (rows.shape[0], 3)
    assert np.abs(rows @ (moved.poles - surface.poles).reshape(-1, 3) - targets).max() < 1e-12
    on_side = [TangentEdge(0, (0, 1), (("u1", False), None), 0.0)]
    assert turn_rows(Neighbours(part, [moved, moved]), on_side, 0, 10.0)[0].shape == (0, 30)


def test_turn_rows_turn_a_kinked_trimming_curve_into_one_plane():
    """Two faces kinked 0.3 to 2 deg along a trimming curve inside both domains: a least-squares fit of each
    face's displacements to its rows of :func:`~hot2cold.pipeline.g1.turn_rows`, with rows that hold it on
    the curve, leaves them within 0.01 deg of each other at 400 points along it (not only where the rows
    are) and on the curve to 1e-7 mm (eq. 65 keeps both tangents' parts in the plane, which holding the
    curve does not quite allow as they turn: 2.3e-8 mm here, with the curve held 1000 times as hard)."""
    from hot2cold.core.bspline import surface_basis
    from hot2cold.pipeline.g1 import Neighbours, turn_rows

    part, surface, kinked = _split_along_diagonal(0.02)
    dense = np.linspace(0.05, 0.95, 400)
    dense = np.column_stack([dense, dense])
    assert 0.3 < np.nanmax(kink_angles(surface, dense, kinked, dense)) < 2.0
    edges = [TangentEdge(0, (0, 1), (None, None), 0.0)]
    cold = [surface, kinked]
    turned = []
    for k in (0, 1):
        rows, targets = turn_rows(Neighbours(part, cold), edges, k, 10.0)
        rows = rows.toarray()
        hold = surface_basis(surface, dense[:, 0], dense[:, 1]).toarray()
        current = (cold[k].poles - surface.poles).reshape(-1, 3)
        delta = np.linalg.lstsq(np.vstack([1e3 * hold, rows]), np.vstack([1e3 * hold @ current, targets]),
                                rcond=None)[0]
        turned.append(surface.with_poles(surface.poles + delta.reshape(surface.poles.shape)))
        on_curve = evaluate_surface(turned[-1], dense[:, 0], dense[:, 1]) - evaluate_surface(cold[k], dense[:, 0],
                                                                                              dense[:, 1])
        assert np.abs(on_curve).max() < 1e-7
    assert np.nanmax(kink_angles(turned[0], dense, turned[1], dense)) <= 0.01


def test_a_collapsed_side_is_left_out_of_the_kinks():
    """At a collapsed side the hot normals are undefined; the morph leaves it collapsed only to rounding, where
    a cold normal is noise (76 deg on a SolidWorks part of the corpus).  The measures leave such points out."""
    sa, sb = _patches()
    pa, pb = sa.poles.copy(), sb.poles.copy()
    pa[:, 0] = pa[-1, 0]                            # side v0 of both faces collapses onto the edge's end
    pb[:, 0] = pa[-1, 0]
    sa, sb = sa.with_poles(pa), sb.with_poles(pb)
    part = _part(sa, sb)
    (te,) = tangent_edges(part)
    assert te.hot_angle_max < 1e-9
    rng = np.random.default_rng(0)
    noisy_a, noisy_b = pa.copy(), pb.copy()          # the edge's end pole stays where it is
    noisy_a[:-1, 0] += 1e-9 * rng.normal(size=(pa.shape[0] - 1, 3))
    noisy_b[1:, 0] += 1e-9 * rng.normal(size=(pb.shape[0] - 1, 3))
    cold = [sa.with_poles(noisy_a), sb.with_poles(noisy_b)]
    ua, ub = part.faces[0].uses[0], part.faces[1].uses[0]
    raw = kink_angles(cold[0], ua.uv, cold[1], ub.uv)
    assert raw[0] > 1.0 and np.nanmax(raw[1:]) < 1e-6          # the noise at v = 0, nothing elsewhere
    kinks = edge_kinks(part, cold, te)
    assert np.isnan(kinks[0]) and np.allclose(kinks[1:], raw[1:])
    assert kink_added(part, cold, te) < 1e-6


def test_a_side_collapsed_all_but_to_rounding_is_left_out_of_the_kinks():
    """A STEP writer's sliver face: its side v0 shrunk to 1e-9 of its length, not to a point.  The hot normal
    there is defined, but rests on pole differences that a fit's noise (1e-11 mm here) turns by degrees; the vise of the
    real corpus read 0.61 deg at such a corner.  ``normal_rounding`` says so, and the measures leave the points
    out where rounding may turn a hot normal by more than MEASURABLE_DEG, and only those."""
    sa, sb = _patches()
    pa, pb = sa.poles.copy(), sb.poles.copy()
    end = pa[-1, 0].copy()
    pa[:, 0] = end + 1e-9 * (pa[:, 0] - end)           # side v0 of both faces shrinks to 1e-9 of its length
    pb[:, 0] = end + 1e-9 * (pb[:, 0] - end)
    sa, sb = sa.with_poles(pa), sb.with_poles(pb)
    part = _part(sa, sb)
    (te,) = tangent_edges(part)
    ua, ub = part.faces[0].uses[0], part.faces[1].uses[0]
    assert np.isfinite(kink_angles(sa, ua.uv, sb, ub.uv)).all()          # defined: not collapsed to rounding
    rounding = np.degrees(normal_rounding(sa, ua.uv[:, 0], ua.uv[:, 1]))
    assert rounding[0] > 100 * MEASURABLE_DEG and rounding[1:].max() < 1e-3 * MEASURABLE_DEG
    rng = np.random.default_rng(0)
    noisy_a, noisy_b = pa.copy(), pb.copy()
    noisy_a[:-1, 0] += 1e-11 * rng.normal(size=(pa.shape[0] - 1, 3))
    noisy_b[1:, 0] += 1e-11 * rng.normal(size=(pb.shape[0] - 1, 3))
    cold = [sa.with_poles(noisy_a), sb.with_poles(noisy_b)]
    raw = kink_angles(cold[0], ua.uv, cold[1], ub.uv)
    assert raw[0] > 0.1 and np.nanmax(raw[1:]) < 1e-6          # the noise at v = 0, nothing elsewhere
    kinks = edge_kinks(part, cold, te)
    assert np.isnan(kinks[0]) and np.allclose(kinks[1:], raw[1:])
    assert kink_added(part, cold, te) < 1e-6
    # the untouched patches: every point measured
    plain = _part(*_patches())
    (te_plain,) = tangent_edges(plain)
    assert np.isfinite(edge_kinks(plain, [f.surface for f in plain.faces], te_plain)).all()


def test_kink_misses_are_the_edge_points_kinked_beyond_the_limit_on_both_faces():
    """The points a G1 refinement halves patches at: along the edge, on both faces (their own parameters),
    where the kink the morph added exceeds the limit; none on an edge within it."""
    sa, sb = _patches()
    part = _part(sa, sb)
    edges = tangent_edges(part)
    assert kink_misses(part, [sa, sb], edges, 0.01) == {}
    kinked = _kinked(sb, 0.5)
    misses = kink_misses(part, [sa, kinked], edges, 0.01)
    assert sorted(misses) == [0, 1]
    uv_a, uv_b = misses[0], misses[1]
    assert uv_a.shape == uv_b.shape and uv_a.shape[1] == 2
    assert np.allclose(uv_a[:, 0], 1.0) and np.allclose(uv_b[:, 0], 0.0)      # on side u1 of a, u0 of b
    assert np.allclose(uv_a[:, 1], uv_b[:, 1])
    # the lift is zero at the ends (v = 0, 1): the points kinked beyond 0.01 deg lie inside, and a limit
    # above the largest kink leaves none
    assert 0.0 < uv_a[:, 1].min() and uv_a[:, 1].max() < 1.0
    kinks = kink_angles(sa, uv_a, kinked, uv_b)
    assert kinks.min() > 0.01
    assert kink_misses(part, [sa, kinked], edges, 1.01 * _kink([sa, kinked], part)) == {}


@pytest.mark.heavy
def test_a_face_turned_again_and_again_reads_its_rows_once(block_shape, block_nodes, monkeypatch):
    """G1 and G2 fit a face on a tangent edge again with other turning or bending rows only: its rows are
    reduced once (a face with 470 000 nodes took 0.3 s of QR and 0.1 s of rows for each turn) and each new set
    of steering rows gives the fit morph_face gives with them, in this context and in it on another part
    (:meth:`MorphContext.with_part`); the same curves as new objects are the same problem, a moved edge a new one
    (the first kept beside it, up to the bytes a face may keep)."""
    from dataclasses import replace

    from hot2cold.core.lstsq import ReducedRows
    from hot2cold.kernel.project import Projector
    from hot2cold.pipeline.face_fit import morph_face
    from hot2cold.pipeline.fit_inputs import FitInputs
    from hot2cold.pipeline.g1 import TURN_WEIGHT, Neighbours, turn_rows
    from hot2cold.pipeline.context import MorphContext
    from hot2cold.pipeline.morph import morph
    from hot2cold.settings import Settings

    result = morph(block_shape, (block_nodes, _untwist(block_nodes, 0.05, 1e-4)(block_nodes)))
    part, cls, field = result.part, result.classification, result.field
    settings = Settings()
    context = MorphContext.of(part, cls, field, settings, Projector(part.kernel.faces, part.kernel.edges))
    te = context.tangent[0]
    k = te.faces[0]
    surfaces = [f.surface for f in result.faces]
    rows, targets = turn_rows(Neighbours(part, surfaces), [te], k, TURN_WEIGHT, sides=True)
    assert rows.shape[0] > 0
    face, edges = part.faces[k], list(result.edges)
    for scale in (1.0, 2.0, 0.5):
        turn = (rows, scale * targets)
        fit = context.fit_face(part, face, edges, turn)
        inputs = FitInputs(cls, field, context.vertex_displacements, context.estimator, settings,
                           context.trimmed_away, context.noise)
        direct = morph_face(face, part, edges, inputs, turn)
        np.testing.assert_allclose(fit.surface.poles, direct.surface.poles, rtol=0, atol=1e-9)
        assert (fit.rank, fit.unknowns, fit.nodes) == (direct.rank, direct.unknowns, direct.nodes)
        if scale == 1.0:
            (kept,) = _kept_problems(context, k)
            assert isinstance(kept.rows, ReducedRows)
        assert _kept_problems(context, k) == [kept]                       # read once
    # the context on a refined part (G1 after the refinement, G1's own trial) finds the same face's rows
    moved = context.with_part(replace(part))
    moved.fit_face(moved.part, face, edges, (rows, targets))
    assert _kept_problems(moved, k) == [kept]
    use = face.uses[0].edge
    edges[use] = replace(edges[use], curve=replace(edges[use].curve))     # the same curve, new objects
    context.fit_face(part, face, edges, (rows, targets))
    assert _kept_problems(context, k) == [kept]
    curve = edges[use].curve
    edges[use] = replace(edges[use], curve=curve.with_poles(curve.poles + 1e-3))    # the edge moved: new rows
    fit = context.fit_face(part, face, edges, (rows, targets))
    assert len(_kept_problems(context, k)) == 2 and _kept_problems(context, k)[0] is kept
    direct = morph_face(face, part, edges, inputs, (rows, targets))
    np.testing.assert_allclose(fit.surface.poles, direct.surface.poles, rtol=0, atol=1e-9)
    assert not np.allclose(fit.surface.poles, context.fit_face(part, face, list(result.edges), (rows, targets))
                           .surface.poles, rtol=0, atol=1e-6)            # and the first edge's fit is found again
    assert len(_kept_problems(context, k)) == 2
    # where a face's kept factors would hold more than the bound, only the newest fit stays
    from hot2cold.pipeline import context as context_module
    monkeypatch.setattr(context_module, "_PROBLEM_BYTES", kept.rows.factor.nbytes)
    edges[use] = replace(edges[use], curve=curve.with_poles(curve.poles - 1e-3))
    context.fit_face(part, face, edges, (rows, targets))
    (newest,) = _kept_problems(context, k)
    assert newest is not kept


def _kept_problems(context, k: int) -> list:
    """The reduced problems ``context`` keeps for face ``k`` (:meth:`MorphContext.fit_face`), oldest first."""
    return [problem for _, problem in context._problems.get(k, {}).values()]


def test_kink_maxima_are_each_edges_own_largest_kink(blade_part):
    """``kink_maxima`` measures many tangent edges at once (each face's normals at all its edges' samples in
    one evaluation) and finds each edge's largest kink as ``edge_kinks`` does edge by edge, with the points a
    hot normal leaves unmeasured left out alike; so with the mask found at each measure (``measurable`` None)."""
    edges = tangent_edges(blade_part)
    assert len(edges) >= 2
    rng = np.random.default_rng(3)
    cold = [f.surface.with_poles(f.surface.poles + 1e-3 * rng.normal(size=f.surface.poles.shape))
            for f in blade_part.faces]
    one_by_one = np.array([np.nanmax(edge_kinks(blade_part, cold, te)) for te in edges])
    assert np.all(one_by_one > 1e-4)                   # the noise kinks every edge: there is something to find
    assert np.allclose(kink_maxima(blade_part, cold, edges), one_by_one, rtol=0, atol=1e-12)
    unmasked = [replace(te, measurable=None) for te in edges]
    assert np.allclose(kink_maxima(blade_part, cold, unmasked), one_by_one, rtol=0, atol=1e-12)
    assert np.allclose([kink_added(blade_part, cold, te) for te in edges],
                       one_by_one - [te.hot_angle_max for te in edges], rtol=0, atol=1e-12)


def _bent(surface: BSplineSurface, amount: float) -> BSplineSurface:
    """``surface`` with its poles bent about the x axis by ``amount`` (1/mm): other curvatures across its edges."""
    poles = surface.poles.copy()
    poles[..., 2] += amount * poles[..., 1] ** 2
    return surface.with_poles(poles)


def test_curvature_jumps_of_many_edges_are_those_of_each_edge(blade_part):
    """:func:`edge_jumps` evaluates each face once for all its edges; it gives each edge's jump as measured on
    its own (:func:`curvature_jump` at the edge's samples, where the hot normals are measurable)."""
    from hot2cold.pipeline.g1 import _matched_uv, _use_of
    from hot2cold.pipeline.g2 import curvature_jump, edge_jumps

    part = blade_part
    found = tangent_edges(part)
    surfaces = [_bent(f.surface, 0.002 * (k + 1)) for k, f in enumerate(part.faces)]
    together = edge_jumps(part, surfaces, found)
    for te, jump in zip(found, together):
        uv_a, uv_b = _matched_uv(_use_of(part.faces[te.faces[0]], te.edge), _use_of(part.faces[te.faces[1]], te.edge))
        alone = curvature_jump(surfaces[te.faces[0]], uv_a, surfaces[te.faces[1]], uv_b)
        keep = te.measurable
        expected = replace(alone, kappa_a=np.where(keep, alone.kappa_a, np.nan),
                           kappa_b=np.where(keep, alone.kappa_b, np.nan)).relative(1.0 / part.diagonal)
        assert jump > 1e-3                                 # the bends made jumps to measure
        assert jump == pytest.approx(expected, rel=1e-12)
    assert np.array_equal(edge_jumps(part, surfaces, found[::-1]), together[::-1])


def test_hot_edge_points_are_kept_per_face_count_and_hot_faces(blade_part):
    """The hot side of the rows that steer a fit is found once per tangent edge, face, point count and hot faces
    (a refined part's faces are other objects, and are asked again), read-only."""
    from hot2cold.pipeline.g1 import edge_points, hot_defined, hot_edge_points

    part = blade_part
    te = tangent_edges(part)[0]
    k, other = te.faces
    uv, uv_o, measurable = hot_edge_points(part, te, k, 12)
    expected = edge_points(part, te, k, 12)
    assert np.array_equal(uv, expected[0]) and np.array_equal(uv_o, expected[1])
    assert np.array_equal(measurable, hot_defined(part, (k, other), *expected))
    assert hot_edge_points(part, te, k, 12)[0] is uv                    # kept
    assert hot_edge_points(part, te, k, 13)[0].shape == (13, 2)         # another count: found anew
    assert not uv.flags.writeable
    faces = list(part.faces)
    faces[k] = replace(faces[k])                                        # a refined part's face: another object
    assert hot_edge_points(replace(part, faces=faces), te, k, 12)[0] is not uv


def test_corner_edges_are_kept_per_part(blade_part):
    """The hot part's corners (two edges of a face meeting at a vertex, not tangent to each other) are found once
    per part, face and vertex; another part (a refined one) finds its own."""
    from hot2cold.pipeline.g1 import _corner_edges, _edges_at

    part = blade_part
    corners = {(f.index, v): _corner_edges(part, f.index, v) for f in part.faces
               for v in {v for u in f.uses for v in part.edges[u.edge].vertices}}
    found = [c for c in corners.values() if c is not None]
    assert len(found) >= 4                                               # the caps' corners at least
    for (k, v), c in corners.items():
        assert _corner_edges(part, k, v) is c                            # kept
        if c is not None:
            assert {c[0].index, c[1].index} == {e.index for e in _edges_at(part, k, v)}
            assert c[2] == tuple(e.vertices[0] == v for e in c[:2])
    other = replace(part)
    k, v = next(key for key, c in corners.items() if c is not None)
    again = _corner_edges(other, k, v)
    assert again is not corners[(k, v)] and again[:2] == corners[(k, v)][:2]


def test_tangent_edges_found_all_at_once_are_those_found_edge_by_edge(blade_part):
    """:func:`tangent_edges` evaluates each hot face once for all its edges: each edge's largest angle and
    measurable points are those of its own :func:`kink_angles` and :func:`hot_defined`."""
    from hot2cold.pipeline.g1 import _matched_uv, _use_of, hot_defined

    part = blade_part
    found = tangent_edges(part)
    assert found
    for te in found:
        fa, fb = (part.faces[k] for k in te.faces)
        uv_a, uv_b = _matched_uv(_use_of(fa, te.edge), _use_of(fb, te.edge))
        assert te.hot_angle_max == np.nanmax(kink_angles(fa.surface, uv_a, fb.surface, uv_b))
        assert np.array_equal(te.measurable, hot_defined(part, te.faces, uv_a, uv_b))
    loose = tangent_edges(part, angle_tol_deg=90.0)                      # the caps' edges too
    assert len(loose) > len(found) and {te.edge for te in found} <= {te.edge for te in loose}
