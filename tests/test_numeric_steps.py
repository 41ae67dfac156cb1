"""The numeric steps on their own, without the kernel: edges (eq. 10-20), face ties, artificial nodes."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from hot2cold.pipeline.artificial import FieldEstimator, carry_to_feet
from hot2cold.core.bspline import BSplineCurve, BSplineSurface, curve_basis, evaluate_curve
from hot2cold.pipeline.edge_fit import EdgeFitOptions, morph_edge
from hot2cold.pipeline.face_fit import _artificial_parameters
from hot2cold.core.model import EdgeUse, side_along

RNG = np.random.default_rng(11)


@pytest.fixture(autouse=True)
def _draws_of_its_own():
    """Every test draws from a generator of its own, seeded alike, whichever tests ran before it in the process."""
    global RNG
    RNG = np.random.default_rng(11)
A = np.array([[0.996, 0.01, 0.0], [-0.01, 0.996, 0.002], [0.0, -0.002, 0.996]])
B = np.array([0.1, -0.2, 0.05])


def _curve(n=8, degree=3, rational=False):
    inner = np.sort(RNG.uniform(0, 1, n - degree - 1))
    knots = np.concatenate([np.zeros(degree + 1), inner, np.ones(degree + 1)]) * 30.0
    poles = np.column_stack([np.linspace(0, 30, n), RNG.normal(0, 3, n), RNG.normal(0, 3, n)])
    return BSplineCurve(poles, knots, degree, RNG.uniform(0.5, 2.0, n) if rational else None)


@pytest.mark.parametrize("rational", [False, True])
def test_edge_morph_reproduces_an_affine_field(rational):
    curve = _curve(rational=rational)
    t = np.linspace(*curve.domain, 200)
    hot = evaluate_curve(curve, t)
    disp = hot @ A.T + B - hot
    ends = curve.poles[[0, -1]] @ A.T + B - curve.poles[[0, -1]]
    result = morph_edge(curve, t, disp, ends, EdgeFitOptions(None, 1.2e-7))
    assert np.abs(result.curve.poles - (curve.poles @ A.T + B)).max() <= 1e-10
    assert result.rank == result.unknowns == curve.n_poles - 2
    # the end poles are exactly the vertex displacements (eq. 10)
    assert np.array_equal(result.curve.poles[[0, -1]], curve.poles[[0, -1]] + ends)


def test_edge_morph_fills_empty_knot_spans_from_the_estimator():
    curve = _curve(n=10)
    breaks = np.unique(curve.knots)
    t = np.linspace(breaks[0], breaks[2], 50, endpoint=False)   # nodes in the first two spans only
    hot = evaluate_curve(curve, t)
    disp = hot @ A.T + B - hot
    ends = curve.poles[[0, -1]] @ A.T + B - curve.poles[[0, -1]]
    samples = evaluate_curve(curve, np.linspace(*curve.domain, 400))
    estimator = FieldEstimator(samples, samples @ A.T + B - samples)
    result = morph_edge(curve, t, disp, ends, EdgeFitOptions(estimator, 1.2e-7))
    assert result.artificial == (len(breaks) - 3) * (curve.degree + 1)   # degree + 1 in each empty span
    assert np.abs(result.curve.poles - (curve.poles @ A.T + B)).max() <= 1e-8


def test_edge_morph_of_a_high_degree_span_with_its_nodes_bunched_at_one_end():
    """Rotor 67's hub and casing edges: degree 14, the last knot span half the curve, its nodes in its first
    fifth.  The nodes fill the span (more than degree + 1), but not its cells: the empty cells get artificial
    nodes, and the directions the cut-off drops keep the estimate fitted along the curve, not the estimate at
    the poles.  Under a quadratic field (which the estimator reproduces, but a degree-14 curve cannot: the
    field along it is of degree 28) the morphed curve is within 2 x the best the curve can do everywhere (the
    least-squares fit over 2001 points along it), not only at the nodes; it was 100 times that off before."""
    degree = 14
    knots = np.concatenate([np.zeros(degree + 1), [10.0, 20.0], np.full(degree + 1, 100.0)])
    n = len(knots) - degree - 1
    poles = np.column_stack([np.linspace(0, 100, n), 30 * np.sin(np.arange(n)), 20 * np.cos(1.7 * np.arange(n))])
    curve = BSplineCurve(poles, knots, degree)
    t = np.concatenate([np.linspace(0.0, 20.0, 60), np.linspace(20.0, 36.0, 200)])     # none beyond 36
    hot = evaluate_curve(curve, t)
    ends = _quadratic_field(curve.poles[[0, -1]])
    samples = evaluate_curve(curve, np.linspace(*curve.domain, 400))
    estimator = FieldEstimator(samples, _quadratic_field(samples))
    dense = np.linspace(*curve.domain, 2001)
    on = evaluate_curve(curve, dense)
    basis = curve_basis(curve, dense).toarray()
    best = np.linalg.lstsq(basis, _quadratic_field(on), rcond=None)[0]
    best_off = np.linalg.norm(basis @ best - _quadratic_field(on), axis=1)
    # the default cut-off keeps every pole (condition 9e4); a coarse one (1e-3) drops 8 of 15 directions, which
    # then keep the estimate fitted along the curve (0.7 x the best; with the estimate at the poles, 6.6 x)
    for epsilon, full in ((1.2e-7, True), (1e-3, False)):
        result = morph_edge(curve, t, _quadratic_field(hot), ends,
                            EdgeFitOptions(estimator, epsilon, artificial_weight=0.1))
        assert result.artificial > 0 and (result.rank == result.unknowns) == full
        off = np.linalg.norm(evaluate_curve(result.curve, dense) - on - _quadratic_field(on), axis=1)
        assert off.max() <= 2.0 * best_off.max(), (epsilon, off.max(), best_off.max())


def test_field_estimator_is_exact_for_affine_fields_and_extrapolates():
    pts = RNG.uniform(0, 10, (300, 3))
    est = FieldEstimator(pts, pts @ A.T + B - pts, neighbours=12)
    far = np.array([[15.0, -3.0, 12.0], [5.0, 5.0, 5.0]])
    assert np.abs(est(far) - (far @ A.T + B - far)).max() <= 1e-10


def test_displacements_carried_to_the_feet_are_exact_for_an_affine_field():
    feet = RNG.uniform(0, 10, (400, 3))
    offset = RNG.normal(0, 0.05, (400, 3))
    nodes = feet + offset                                   # nodes beside their faces and edges
    disp = nodes @ A.T + B - nodes
    used = np.ones(400, bool)
    used[:5] = False                                        # nodes that take no part keep their value
    carried = carry_to_feet(nodes, feet, disp, used, 20, 1e-12)
    exact = feet @ A.T + B - feet
    assert np.abs(disp[used] - exact[used]).max() > 1e-3    # what the fits would have put at the feet
    assert np.abs(carried[used] - exact[used]).max() <= 1e-10
    np.testing.assert_array_equal(carried[~used], disp[~used])
    on = carry_to_feet(feet, feet, feet @ A.T + B - feet, used, 20, 1e-12)   # nodes on their feet: untouched
    np.testing.assert_array_equal(on, feet @ A.T + B - feet)


def test_remembered_estimates_are_the_estimates_and_asked_once(monkeypatch):
    """The estimator's memo gives the numbers a call gives (to the bit), and asks the fits only for points it has
    not seen (a face fitted again asks for the same artificial nodes)."""
    pts = RNG.random((400, 3)) * 10
    est = FieldEstimator(pts, 1e-3 * np.column_stack([pts[:, 0] ** 2, pts[:, 1] * pts[:, 2], np.sin(pts[:, 0])]), 20)
    first, more = RNG.random((50, 3)) * 12, RNG.random((20, 3)) * 12
    assert np.array_equal(est.remembered(first), est(first))
    asked = []
    real = FieldEstimator.__call__
    monkeypatch.setattr(FieldEstimator, "__call__", lambda self, x, *a: asked.append(len(x)) or real(self, x, *a))
    again = np.concatenate([more, first[::-1], more[:3]])
    assert np.array_equal(est.remembered(again), real(est, again))
    assert asked == [len(more) + 3]          # one call, for the points not seen before (three of them twice)


def test_a_point_far_out_is_fitted_over_the_wide_balls_only(monkeypatch):
    """A point far from the foot points (an artificial node over a trimmed-away part) takes its linear and its
    quadratic fit from the wide balls, so it is not fitted over its ``k`` nearest as well: asked together with
    points among the foot points, the fit over the ``k`` nearest sees only those; the estimates are a call's
    for each point alone (to the bit)."""
    import hot2cold.pipeline.artificial as artificial

    pts = RNG.random((400, 3)) * 10
    est = FieldEstimator(pts, 1e-3 * np.column_stack([pts[:, 0] ** 2, pts[:, 1] * pts[:, 2], np.sin(pts[:, 0])]), 20)
    among, far = RNG.random((30, 3)) * 10, RNG.random((12, 3)) * 10 + [40.0, 0.0, 0.0]
    x = np.concatenate([among, far])
    alone = np.array([est(p[None])[0] for p in x])
    widths = []
    real = artificial.fits_at
    monkeypatch.setattr(artificial, "fits_at", lambda points, *a, **k: widths.append(points.shape[:2]) or
                        real(points, *a, **k))
    assert np.array_equal(est(x), alone)
    assert (len(among), 20) in widths                                  # the k nearest: only the points among them
    assert not any(width == 20 and count > len(among) for count, width in widths)


def test_displacements_carried_together_are_those_carried_one_by_one():
    """Several sets of displacements carried in one call of the estimator, with its estimate at more points, give
    the numbers each gets on its own: an estimate at a point does not depend on the points asked with it."""
    from hot2cold.pipeline.artificial import carried_together

    pts = RNG.random((500, 3)) * 10
    est = FieldEstimator(pts, 1e-3 * np.column_stack([pts[:, 0] ** 2, pts[:, 1] * pts[:, 2], np.sin(pts[:, 0])]), 20)
    carries = []
    for n in (5, 0, 17, 3):
        at = RNG.random((n, 3)) * 10
        to = at + RNG.normal(size=(n, 3)) * 0.01
        to[:2] = at[:2]                                     # not apart: kept as given
        carries.append((RNG.normal(size=(n, 3)), at, to))
    also = RNG.random((30, 3)) * 10
    together, at_also = carried_together(carries, est, 1e-6, also)
    for (disp, at, to), got in zip(carries, together):
        alone = disp.copy()
        apart = np.linalg.norm(to - at, axis=1) > 1e-6
        if apart.any():
            alone[apart] += est(to[apart]) - est(at[apart])
        assert np.array_equal(got, alone)
    assert np.array_equal(at_also, est(also))
    assert carried_together([(carries[0][0], carries[0][1], carries[0][1])], est, 1e-6)[0][0] is carries[0][0]


def test_field_estimator_reaches_past_a_flat_neighbourhood():
    """A point beside a plane of foot points (its 20 nearest all on it) and far from the others: the field's
    change across the plane comes from the foot points that span it, and an affine field is exact there."""
    plane = np.column_stack([RNG.uniform(0, 10, (400, 2)), np.zeros(400)])
    far = np.column_stack([RNG.uniform(0, 10, (30, 2)), np.full(30, 40.0)])      # another face, 40 mm up
    pts = np.concatenate([plane, far])
    est = FieldEstimator(pts, pts @ A.T + B - pts, neighbours=20)
    beside = np.array([[5.0, 5.0, 3.0], [2.0, 8.0, -2.0]])
    assert np.abs(est(beside) - (beside @ A.T + B - beside)).max() <= 1e-10
    from hot2cold.core.localfit import Span
    from hot2cold.pipeline.artificial import OFF_SPAN
    _, idx = cKDTree(pts).query(beside, k=20)
    assert Span.of(pts[idx], np.ones(idx.shape, bool)).off(beside, OFF_SPAN).all()   # what the wider fit is for
    on = np.array([[5.0, 5.0, 0.0]])
    assert not Span.of(pts[idx[:1]], np.ones((1, 20), bool)).off(on, OFF_SPAN).any()


def test_field_estimator_takes_no_gradient_across_a_plane_s_rounding():
    """Foot points of a tilted plane face, off it by nothing but its projection's rounding (2e-8 mm over a
    neighbourhood 80 mm across, as on NIST CTC-02's face 146), and a point 18 mm beside them: that spread
    carries no gradient across the plane (a fit through it took the values' rounding times 1e10 and put an
    affine field 2.5 mm off), so the field's change across comes from the foot points that span it."""
    normal = np.array([1.0, 0.0, 0.03]) / np.hypot(1.0, 0.03)
    along = np.cross(normal, [0.0, 1.0, 0.0])
    uv = RNG.uniform(-40, 40, (400, 2))
    plane = (250.0 * normal + uv[:, :1] * along + uv[:, 1:] * [0.0, 1.0, 0.0]
             + RNG.uniform(-1e-8, 1e-8, (400, 1)) * normal)
    far = 250.0 * normal + RNG.uniform(-40, 40, (60, 3)) - 60.0 * normal        # another face, 60 mm in
    pts = np.concatenate([plane, far])
    est = FieldEstimator(pts, pts @ A.T + B - pts, neighbours=20)
    beside = 250.0 * normal + 18.0 * normal + RNG.uniform(-30, 30, (20, 1)) * along
    assert np.abs(est(beside) - (beside @ A.T + B - beside)).max() <= 1e-8


def test_field_estimator_beside_a_flat_neighbourhood_keeps_a_quadratic_field():
    """Three layers of foot points 6 mm apart (three parallel faces) and points 1.5 to 2 mm outside the first:
    their nearest foot points all lie on it, so the field's change across comes from the wider neighbourhood
    that spans the layers, and over it a quadratic field is fitted as quadratic (a linear fit there missed it
    by 5e-3 mm; NIST CTC-02 under a smooth field missed its tolerance by that)."""
    grid = np.stack(np.meshgrid(np.arange(0, 10.5, 1.0), np.arange(0, 10.5, 1.0), indexing="ij"), -1).reshape(-1, 2)
    pts = np.concatenate([np.column_stack([grid, np.full(len(grid), z)]) for z in (0.0, 6.0, 12.0)])

    def field(p):
        x, y, z = p.T
        return 1e-4 * np.column_stack([x * z, y * y - z * z, x * y + z * z])

    est = FieldEstimator(pts, field(pts), neighbours=20)
    beside = np.array([[5.0, 5.0, -2.0], [2.0, 8.0, -1.5]])
    assert np.abs(est(beside) - field(beside)).max() <= 1e-10


@pytest.mark.parametrize("shape", ["spread", "plane", "line", "one point"])
def test_linear_pinv_from_the_span_is_numpy_s(shape):
    """The linear fit's pseudo-inverse built from the SVD of the centred offsets alone (the column of ones
    is orthogonal to them) is the pseudo-inverse of the whole linear design, cut-off included, on full,
    planar, collinear and single-point neighbourhoods with rows left out."""
    from hot2cold.core.localfit import LINEAR_RCOND, Span, monomials

    c, m = 50, 20
    pts = RNG.normal(size=(c, m, 3)) * [3.0, 2.0, 1.0] + RNG.normal(size=(c, 1, 3)) * 100
    if shape == "plane":
        pts[..., 2] = 7.0
    elif shape == "line":
        pts[..., 1:] = pts[..., :1] * [0.5, -2.0]
    elif shape == "one point":
        pts[:] = pts[:, :1]
    valid = RNG.random((c, m)) > 0.3
    valid[:, :3] = True
    span = Span.of(pts, valid)
    design = monomials(span.offsets, 1) * valid[..., None]
    expected = np.linalg.pinv(design, rcond=LINEAR_RCOND)
    got = span.linear_pinv(valid.astype(float))
    assert np.abs(got - expected).max() <= 1e-10 * np.abs(expected).max()


@pytest.mark.parametrize("shape", ["spread", "graded", "plane", "line", "one point", "round"])
def test_thin_svd_of_many_3_column_matrices_is_lapack_s(shape):
    """The SVD of many m x 3 matrices from Jacobi rotations of their Gram matrices is LAPACK's: the same
    singular values (the small ones to the rounding of the largest), the same right singular subspaces
    (a thin direction's vector up to its sign), orthonormal vectors, and the matrices back from the factors."""
    from hot2cold.core.localfit import thin_svd3

    c, m = 200, 9
    a = RNG.normal(size=(c, m, 3))
    if shape == "graded":                       # nearly flat: a thin direction far below rounding of the others
        a = a * [1.0, 0.3, 1e-9]
    elif shape == "plane":
        a[..., 2] = 0.0
    elif shape == "line":
        a = a[..., :1] * [1.0, -2.0, 0.5]
    elif shape == "one point":
        a[:] = 0.0
    elif shape == "round":                      # two equal singular values: any basis of their plane
        q = np.linalg.qr(RNG.normal(size=(m, 2)))[0]
        a = np.stack([q[:, 0], q[:, 1], 1e-3 * RNG.normal(size=m)], axis=1)[None].repeat(c, axis=0)
    a = a @ np.linalg.qr(RNG.normal(size=(3, 3)))[0]          # not along the axes
    u, sigma, vt = thin_svd3(a)
    u0, sigma0, vt0 = np.linalg.svd(a, full_matrices=False)
    top = np.abs(a).max() * 10
    eps = np.finfo(float).eps
    assert np.abs(sigma - sigma0).max() <= 50 * eps * top
    assert np.all(np.diff(sigma, axis=1) <= 50 * eps * top)                         # descending
    assert np.abs(vt @ vt.transpose(0, 2, 1) - np.eye(3)).max() <= 50 * eps
    assert np.abs(np.einsum("cmj,cj,cjk->cmk", u, sigma, vt) - a).max() <= 50 * eps * top
    used = sigma > 1e-6 * np.maximum(sigma[:, :1], 1e-300)
    both = used[:, :, None] & used[:, None, :]
    assert np.abs(np.einsum("cmj,cmk->cjk", u, u) - np.eye(3))[both].max(initial=0.0) <= 1e-8
    # the span of the leading right vectors is LAPACK's wherever a gap separates them from the rest
    for j in range(1, 3):
        gap = sigma0[:, j - 1] > 1e-3 * sigma0[:, 0] + sigma0[:, j] * 1.001
        p = np.einsum("cji,cjk->cik", vt[:, :j], vt[:, :j])
        p0 = np.einsum("cji,cjk->cik", vt0[:, :j], vt0[:, :j])
        assert np.abs(p - p0)[gap].max(initial=0.0) <= 1e-9


def test_jacobi_eigen_decomposition_of_3_by_3_matrices():
    """The eigen-decomposition of many symmetric semi-definite 3 x 3 matrices by Jacobi rotations: ``g v = v
    diag(lam)`` to the rounding of ``g``, ``v`` orthonormal, the eigenvalues numpy's; a diagonal matrix (nothing
    to rotate) and a zero one come back as they are, with ``v`` the identity."""
    from hot2cold.core.localfit import sym_eig3

    b = RNG.normal(size=(300, 3, 3))
    g = np.concatenate([b @ b.transpose(0, 2, 1), np.diag([3.0, 1.0, 2.0])[None], np.zeros((1, 3, 3))])
    lam, v = sym_eig3(g)
    eps = np.finfo(float).eps
    scale = np.abs(g).max(axis=(1, 2), keepdims=True)
    assert (np.abs(g @ v - v * lam[:, None, :]) <= 20 * eps * scale).all()
    assert np.abs(v.transpose(0, 2, 1) @ v - np.eye(3)).max() <= 20 * eps
    assert (np.abs(np.sort(lam, axis=1) - np.linalg.eigvalsh(g)) <= 20 * eps * scale[:, :, 0]).all()
    assert np.array_equal(lam[-2], [3.0, 1.0, 2.0]) and np.array_equal(v[-2], np.eye(3))
    assert np.array_equal(lam[-1], np.zeros(3)) and np.array_equal(v[-1], np.eye(3))


@pytest.mark.parametrize("shape", [(1, 20, 3), (30, 21, 3), (4096, 21, 3), (7, 5, 4)])
def test_row_sums_are_numpy_s_to_the_bit_whatever_the_chunk(shape):
    """The local fits' sums over a neighbourhood's rows (``einsum``) are numpy's ``sum(axis=1)`` to the bit, and a
    neighbourhood's sums do not depend on the others asked with it (an estimate is the same alone or in a chunk:
    the estimator's memo relies on it)."""
    from hot2cold.core.localfit import _row_sums

    x = RNG.normal(size=shape) * 10.0 ** RNG.integers(-8, 8, size=shape)
    sums = _row_sums(x)
    assert np.array_equal(sums, x.sum(axis=1))
    for i in (0, shape[0] // 2, shape[0] - 1):
        assert np.array_equal(_row_sums(x[i:i + 1])[0], sums[i])


def test_masks_repeat_the_weights_and_give_the_same_products():
    """A mask multiplies the rows left out by 0 and the others by 1 whatever the width of the last axis (its
    weights kept per width), the products of a broadcast to the bit; every row valid: the array itself."""
    from hot2cold.core.localfit import _masked

    valid = RNG.random((40, 9)) > 0.3
    mask = _masked(valid)
    for width in (3, 4, 3, 6):
        x = RNG.normal(size=(40, 9, width))
        assert np.array_equal(mask(x), x * valid[..., None].astype(float))
    x = RNG.normal(size=(40, 9, 3))
    assert _masked(np.ones((40, 9), bool))(x) is x


def test_local_fits_over_whole_neighbourhoods_skip_only_the_mask(monkeypatch):
    """Neighbourhoods whose rows are all valid are fitted without multiplying by the mask (a pass over the arrays
    spared): the same numbers as the masked path gives them, and a row left out still counts for nothing."""
    import hot2cold.core.localfit as localfit

    c, m = 40, 20
    pts = RNG.normal(size=(c, m, 3)) * [3.0, 2.0, 0.01]
    values = RNG.normal(size=(c, m, 3))
    x = RNG.normal(size=(c, 3))
    every = np.ones((c, m), bool)
    spared = localfit.fits_at(pts, values, every, x, True, 1e-9)
    multiply = localfit._masked

    def always(valid):
        w = valid[..., None].astype(float)
        return lambda a: a * w

    monkeypatch.setattr(localfit, "_masked", always)
    masked = localfit.fits_at(pts, values, every, x, True, 1e-9)
    for a, b in zip(spared, masked):
        assert np.array_equal(a, b)          # x * 1.0 is x: the same numbers, not close ones
    monkeypatch.setattr(localfit, "_masked", multiply)
    valid = every.copy()
    valid[:, 0] = False
    moved = values.copy()
    moved[:, 0] += 1e3                       # a row left out moves nothing
    for a, b in zip(localfit.fits_at(pts, values, valid, x, True), localfit.fits_at(pts, moved, valid, x, True)):
        assert np.array_equal(a, b)


def test_field_estimator_handles_coplanar_points():
    xy = RNG.uniform(0, 10, (100, 2))
    pts = np.column_stack([xy, np.full(100, 2.0)])
    est = FieldEstimator(pts, pts @ A.T + B - pts)
    q = np.array([[3.0, 4.0, 2.0]])
    assert np.abs(est(q) - (q @ A.T + B - q)).max() <= 1e-10


def _surface():
    u = np.concatenate([np.zeros(4), [0.5], np.ones(4)])
    v = np.concatenate([np.zeros(3), [0.3, 0.6], np.ones(3)])
    poles = RNG.normal(size=(5, 5, 3))
    return BSplineSurface(poles, u, v, 3, 2)


@pytest.mark.parametrize("uv, expected", [
    (np.column_stack([np.zeros(5), np.linspace(0, 1, 5)]), ("u0", False)),
    (np.column_stack([np.ones(5), np.linspace(1, 0, 5)]), ("u1", True)),
    (np.column_stack([np.linspace(0, 1, 5), np.ones(5)]), ("v1", False)),
    (np.column_stack([np.zeros(5), np.linspace(0, 0.7, 5)]), None),          # part of a side only
    (np.column_stack([np.linspace(0, 1, 5), np.linspace(0, 1, 5)]), None),   # a diagonal trim curve
])
def test_side_detection(uv, expected):
    assert side_along(_surface(), EdgeUse(edge=0, t=np.linspace(0, 1, len(uv)), uv=uv)) == expected


def test_side_detection_is_kept_per_domain():
    """A use's side is kept for the domain it was asked about: asked again (with other poles on the same
    knots), the same answer; asked about another domain, that domain's answer, each as found afresh."""
    surface = _surface()
    use = EdgeUse(edge=0, t=np.linspace(0, 1, 5), uv=np.column_stack([np.ones(5), np.linspace(0, 1, 5)]))
    assert side_along(surface, use) == ("u1", False)
    assert side_along(surface.with_poles(surface.poles + 1.0), use) == ("u1", False)
    wider = BSplineSurface(surface.poles, surface.u_knots * 2.0, surface.v_knots, 3, 2)    # u in [0, 2]
    assert side_along(wider, use) is None
    assert side_along(wider, use, whole=False) is None
    assert side_along(surface, use, whole=False) == ("u1", False)
    assert side_along(surface, use) == ("u1", False)


def test_sparse_patches_get_a_grid_of_artificial_nodes():
    surface = _surface()                                  # 2 x 3 patches of degrees (3, 2)
    full = np.column_stack([np.repeat(np.linspace(0.01, 0.49, 4), 3), np.tile(np.linspace(0.01, 0.29, 3), 4)])
    uv = np.concatenate([full, [[0.75, 0.1], [0.25, 0.45]]])   # patch (0, 0) full, two with one node
    nodes = _artificial_parameters(surface, uv)
    on_side = np.isin(nodes[:, 0], [0.0, 1.0]) | np.isin(nodes[:, 1], [0.0, 1.0])
    inner = nodes[~on_side]
    assert len(inner) == 5 * 4 * 3                       # five patches below 12 data, a 4 x 3 grid each
    counts = np.histogram2d(inner[:, 0], inner[:, 1], bins=[[0, 0.5, 1], [0, 0.3, 0.6, 1]])[0]
    assert counts.tolist() == [[0, 12, 12], [12, 12, 12]]
    # the sparse patches along the sides also take their grid's lines on the sides: a side patch's candidates are
    # (4 or 5) x (3 or 4) instead of 4 x 3; (0, 1) and (1, 1) touch one side (3 more each), the corner patches
    # (0, 2), (1, 0) and (1, 2) two (5 x 4 - 12 = 8 more each)
    side = nodes[on_side]
    assert len(side) == 3 + 8 + 8 + 3 + 8
    assert not np.any((side[:, 0] == 0.0) & (side[:, 1] < 0.3))         # patch (0, 0) is full: none there


def test_trimmed_away_grid_points_become_artificial_nodes():
    surface = _surface()
    uv = np.column_stack([np.repeat(np.linspace(0.01, 0.99, 20), 20), np.tile(np.linspace(0.01, 0.99, 20), 20)])
    assert len(_artificial_parameters(surface, uv)) == 0            # every patch is full
    nodes = _artificial_parameters(surface, uv, trimmed_away=lambda p: p[:, 0] > 0.5)
    assert np.all(nodes[:, 0] > 0.5)
    # the grids of the three patches u > 0.5 (4 x 3 each), with the domain's side u = 1 and its ends v = 0, 1:
    # 5 abscissae in u times 3 + 3 + 3 + 2 in v
    assert len(nodes) == 5 * 11
    assert np.count_nonzero(nodes[:, 0] == 1.0) == 11 and np.count_nonzero(np.isin(nodes[:, 1], [0.0, 1.0])) == 10


def _quadratic_field(p):
    """Affine plus bilinear and quadratic terms (an untwist about z growing along y, a span-wise stretch)."""
    x, y, z = p.T
    return p @ (A - np.eye(3)).T + B + np.column_stack([-1e-4 * y * z, 2e-5 * y ** 2, 1e-4 * y * x])


def test_field_estimator_is_exact_for_quadratic_fields():
    pts = RNG.uniform(0, 10, (300, 3))
    est = FieldEstimator(pts, _quadratic_field(pts))
    q = np.array([[15.0, -3.0, 12.0], [5.0, 5.0, 5.0], [0.5, 9.0, 2.0]])
    assert np.abs(est(q) - _quadratic_field(q)).max() <= 1e-10


def test_field_estimator_far_from_a_thin_plate():
    """Nodes on the two walls (z = -0.5 and 0.5, 0.5 mm apart) of a 30 x 30 mm plate, estimates 10 to 25 mm off
    it: the 20 nearest nodes of such a point lie on one wall, a cluster a few mm across with no spread across
    the plate.  A fit over them alone was 0.1 to 0.26 mm off even for an affine field; the neighbourhood that
    grows with the distance takes both walls and is exact for affine and quadratic fields."""
    g = np.arange(0.0, 30.01, 0.5)
    xx, yy = np.meshgrid(g, g, indexing="ij")
    walls = np.concatenate([np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)]) for z in (-0.5, 0.5)])
    far = np.array([[15.0, 0.0, 20.0], [15.0, 0.0, 10.0], [5.0, 10.0, 15.0], [30.0, 30.0, 25.0]])
    affine = FieldEstimator(walls, walls @ A.T + B - walls)
    assert np.abs(affine(far) - (far @ A.T + B - far)).max() <= 1e-10
    quadratic = FieldEstimator(walls, _quadratic_field(walls))
    assert np.abs(quadratic(far) - _quadratic_field(far)).max() <= 1e-10


def test_field_strain_is_the_largest_ratio_over_the_nearest_neighbours():
    """``FieldScale.strain``: the largest ``|du| / |dx|`` of a node and its nearest neighbours, as by brute force;
    a node given twice (it feeds two solids) is one point, not an infinite strain."""
    from hot2cold.core.model import Classification, Role
    from hot2cold.io.field import DisplacementField
    from hot2cold.pipeline.checks import _STRAIN_NEIGHBOURS, FieldScale

    rng = np.random.default_rng(5)
    points = rng.uniform(0, 10, (400, 3))
    disp = 1e-3 * rng.normal(size=(400, 3))
    points[1], disp[1] = points[0], disp[0] + 1.0                   # the same point twice
    n = len(points)
    cls = Classification(np.full(n, Role.FACE), np.zeros(n, int), np.zeros((n, 2)), np.full(n, np.nan), points,
                         np.zeros(n), 0.1, 0.05)
    strain = FieldScale.of(cls, DisplacementField(points, disp)).strain
    d, j = cKDTree(points).query(points, k=_STRAIN_NEIGHBOURS + 1)
    expected = max(np.linalg.norm(disp[j[i, m]] - disp[i]) / d[i, m]
                   for i in range(n) for m in range(1, _STRAIN_NEIGHBOURS + 1) if d[i, m] > 0)
    assert strain == pytest.approx(expected, rel=1e-12)
    assert strain > 1e-4


def test_node_spacings_are_the_distances_to_the_nearest_other_foot_point():
    """``Classification.spacings``: each used node's distance to the nearest foot point elsewhere, nodes that
    share a foot point (a vertex's) counted once, NaN for unused nodes and where all feet are one point."""
    from hot2cold.core.model import Classification, Role

    rng = np.random.default_rng(2)
    for trial in range(60):
        n = int(rng.integers(1, 80))
        foot = rng.normal(size=(n, 3)).round(1)                        # some coincide
        foot[rng.integers(0, n, n // 3)] = foot[0]                     # a shared foot point
        if trial % 10 == 0:
            foot[:] = foot[0]
        role = rng.choice([Role.FACE, Role.EDGE, Role.IGNORED], n)
        cls = Classification(role, np.zeros(n, int), np.zeros((n, 2)), np.zeros(n), foot, np.zeros(n), 0.1, 0.01)
        used = role != Role.IGNORED
        d = np.linalg.norm(foot[:, None] - foot[used][None], axis=2)
        d[d == 0] = np.inf
        expected = np.where(used, d.min(axis=1, initial=np.inf), np.nan)
        expected[np.isinf(expected)] = np.nan
        np.testing.assert_array_equal(cls.spacings, expected)


def test_nodes_of_are_those_a_scan_finds():
    """``Classification.nodes_of`` (a run of the nodes sorted by role and owner) equals a scan of every node, in
    ascending order, for every role and owner, an owner beyond the largest and an ignored node's -1 included, and
    a caller's change to the indices it got leaves the next answer alone; ``groups`` from the same sort."""
    from hot2cold.core.model import Classification, Role

    rng = np.random.default_rng(7)
    for trial in range(40):
        n = int(rng.integers(0, 300))
        role = rng.choice(list(Role), n)
        owner = np.where(role == Role.IGNORED, -1, rng.integers(0, 1 + trial, n))
        cls = Classification(role, owner, np.zeros((n, 2)), np.zeros(n), np.zeros((n, 3)), np.zeros(n), 0.1, 0.01)
        for r in Role:
            for k in range(-2, trial + 3):
                found = cls.nodes_of(r, k)
                np.testing.assert_array_equal(found, np.flatnonzero((role == r) & (owner == k)))
                found[:] = 0
                np.testing.assert_array_equal(cls.nodes_of(r, k), np.flatnonzero((role == r) & (owner == k)))
            groups = cls.groups(r)              # every owner of the role with its nodes, in owner order
            expected = [(k, np.flatnonzero((role == r) & (owner == k))) for k in np.unique(owner[role == r])]
            assert [k for k, _ in groups] == [int(k) for k, _ in expected]
            for (_, nodes), (_, scan) in zip(groups, expected):
                np.testing.assert_array_equal(nodes, scan)
                nodes[:] = 0
            for (_, nodes), (_, scan) in zip(cls.groups(r), expected):
                np.testing.assert_array_equal(nodes, scan)


def _brute_closing(hot, cold, spacing):
    i, j = np.triu_indices(len(hot), 1)
    d_hot = np.linalg.norm(hot[i] - hot[j], axis=1)
    d_cold = np.linalg.norm(cold[i] - cold[j], axis=1)
    return int(np.count_nonzero((d_cold < 2 * spacing) & (d_hot > 2 * d_cold + spacing)))


def test_closing_pairs_finds_a_gap_that_closed_and_nothing_else():
    """Two plates 3 mm apart (grid 1 mm, spacing 1 mm), a dense cluster of a small face's grid among them:
    moved rigidly, no pair closes; with the upper plate pressed to 0.5 mm above the lower one over a patch,
    pairs close, as counting every pair finds."""
    from hot2cold.pipeline.checks import closing_pairs

    x, y = np.meshgrid(np.arange(20.0), np.arange(20.0), indexing="ij")
    plate = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    cluster = RNG.uniform(0, 0.05, (300, 3)) + [5.0, 5.0, 1.5]       # a tiny face's 300 grid points
    hot = np.concatenate([plate, plate + [0, 0, 3.0], cluster])
    rigid = hot @ A.T + B
    assert closing_pairs(hot, rigid, 1.0) == 0 == _brute_closing(hot, rigid, 1.0)
    pressed = hot.copy()
    upper = slice(len(plate), 2 * len(plate))
    patch = np.linalg.norm(pressed[upper, :2] - [14.0, 14.0], axis=1) < 3.0
    pressed[np.arange(len(plate), 2 * len(plate))[patch], 2] = 0.5
    assert _brute_closing(hot, pressed, 1.0) > 0
    assert closing_pairs(hot, pressed, 1.0) > 0


def test_closing_pairs_misses_no_pair_of_the_whole_set():
    """Random clouds of clustered points moved by random local squeezes: wherever counting every pair finds
    one closing, the count over the points kept finds one too."""
    from hot2cold.pipeline.checks import closing_pairs

    for _ in range(30):
        centres = RNG.uniform(0, 10, (15, 3))
        hot = (centres[:, None, :] + RNG.normal(0, RNG.uniform(0.01, 1.0), (15, 40, 3))).reshape(-1, 3)
        cold = hot + RNG.normal(0, 1.0, (15, 1, 3)).repeat(40, axis=1).reshape(-1, 3)
        if _brute_closing(hot, cold, 1.0):
            assert closing_pairs(hot, cold, 1.0) > 0


def test_closing_pairs_counts_every_qualifying_pair_of_the_points_kept():
    """The count skips the square roots of the pairs that cannot qualify (``d_hot^2 <= 4 d_cold^2 + margin^2``)
    and drops none that does: it is the count over every pair of the points kept, on clouds squeezed so that
    many pairs close."""
    from hot2cold.pipeline.checks import closing_pairs

    counts = []
    for _ in range(20):
        hot = RNG.uniform(0, 10, (2000, 3))
        cold = hot * [1.0, 1.0, RNG.uniform(0.05, 1.0)]              # squeezed along z: gaps close
        counts.append(_every_kept_pair(hot, cold, 1.0)[0])
        assert closing_pairs(hot, cold, 1.0) == counts[-1]
    assert max(counts) > 100


def _every_kept_pair(hot, cold, spacing):
    """The closing pairs' count over every pair of the points :func:`~hot2cold.pipeline.checks.closing_pairs`
    keeps, those points (hot, cold) and the pairs ``(c, 2)`` that qualify."""
    from scipy.spatial import cKDTree

    from hot2cold.pipeline.checks import _SAME_SHARE

    eps = _SAME_SHARE * spacing
    keys = np.floor(np.column_stack([hot, cold]) / (eps / np.sqrt(3.0))).astype(np.int64)
    keep = np.unique(keys, axis=0, return_index=True)[1]
    hot, cold = hot[keep], cold[keep]
    pairs = cKDTree(cold).query_pairs(2.0 * spacing + 2.0 * eps, output_type="ndarray").reshape(-1, 2)
    d_hot = np.linalg.norm(hot[pairs[:, 0]] - hot[pairs[:, 1]], axis=1)
    d_cold = np.linalg.norm(cold[pairs[:, 0]] - cold[pairs[:, 1]], axis=1)
    closing = pairs[d_hot > 2.0 * d_cold + spacing - 6.0 * eps]
    return len(closing), hot, cold, closing


def test_closing_pairs_lists_only_the_pairs_of_cells_whose_moves_differ():
    """A block rotated by a few degrees and strained (a smooth field) with a pocket squeezed shut in one
    corner: the cell filter keeps every point of each qualifying pair and few others (the smooth field's
    cells none), and the count is the one over every pair of the points kept."""
    from hot2cold.pipeline.checks import _SAME_SHARE, _may_close, closing_pairs

    assert closing_pairs(np.zeros((0, 3)), np.zeros((0, 3)), 1.0) == 0          # no point, one point: no pair
    assert closing_pairs(np.zeros((1, 3)), np.ones((1, 3)), 1.0) == 0
    angle = np.radians(3.0)
    turn = np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    for trial in range(6):
        hot = RNG.uniform(0, 30, (6000, 3))
        cold = hot @ (turn * (1.0 + 1e-3 * trial)).T
        assert closing_pairs(hot, cold, 1.0) == 0 == _every_kept_pair(hot, cold, 1.0)[0]
        pocket = np.all(hot < 6.0, axis=1)
        cold[pocket, 2] *= RNG.uniform(0.05, 0.3)                       # the pocket squeezed along z
        count, kept_hot, kept_cold, closing = _every_kept_pair(hot, cold, 1.0)
        eps = _SAME_SHARE
        may = _may_close(kept_cold, kept_cold - kept_hot, 2.0 + 2.0 * eps, 1.0 - 6.0 * eps)
        assert count > 0 and may[closing].all()
        assert may.sum() < 0.2 * len(may)
        assert closing_pairs(hot, cold, 1.0) == count
        smooth = kept_hot @ turn.T
        assert not _may_close(smooth, smooth - kept_hot, 2.0 + 2.0 * eps, 1.0 - 6.0 * eps).any()
        # pairs that only just qualify: 1 % beyond the margin (0.25) apart hot, 0.001 apart cold
        near = RNG.uniform(10, 30, (20, 3))
        apart = RNG.normal(size=(20, 3))
        apart /= np.linalg.norm(apart, axis=1, keepdims=True)
        pairs_hot = np.concatenate([near, near + 0.2525 * apart])
        pairs_cold = np.concatenate([near, near + 0.001 * apart]) @ turn.T
        hot2, cold2 = np.concatenate([hot, pairs_hot]), np.concatenate([hot @ turn.T, pairs_cold])
        count = _every_kept_pair(hot2, cold2, 1.0)[0]
        assert count >= 20 and closing_pairs(hot2, cold2, 1.0) == count


def test_the_estimate_at_the_nodes_and_left_out_come_from_one_query_as_from_two():
    """``at_own`` gives at the nodes what the estimate and ``left_out`` give there one by one (its one query of
    each node's k + 1 nearest serves both): the same neighbourhoods, so the same numbers to rounding (another
    neighbourhood, the node left in or out or one more, moves an estimate of this field by 1e-2 in the median), on
    nodes with duplicates, over several chunks, and on node sets too small for a fit (the nearest other's
    displacement)."""
    rng = np.random.default_rng(11)
    uv = rng.uniform(0.0, 40.0, (3000, 2))
    points = np.column_stack([uv, 0.01 * uv[:, 0] ** 2])
    points = np.concatenate([points, points[:30]])                     # 30 nodes twice
    field = np.column_stack([1e-3 * points[:, 0] ** 2, np.sin(points[:, 1]), 1e-4 * points[:, 0] * points[:, 1]])
    rows = np.concatenate([np.arange(0, 3030, 3), np.arange(30)])
    for n, neighbours in ((3030, 20), (3030, 9), (6, 20), (4, 20), (3, 20)):
        estimate = FieldEstimator(points[:n], field[:n], neighbours)
        asked = rows[rows < n]
        own, left_out = estimate.at_own(asked, chunk=256)
        assert own.shape == left_out.shape == (len(asked), 3)
        rounding = 1e-12 * np.abs(field).max()
        np.testing.assert_allclose(own, estimate(points[asked]), rtol=0.0, atol=rounding)
        np.testing.assert_allclose(left_out, estimate.left_out(asked), rtol=0.0, atol=rounding)


def test_the_left_out_estimate_tells_how_well_the_nodes_know_the_field():
    """Left out in turn, nodes on a smooth field are predicted by the others to within the estimate's
    truncation; across a thermal front narrower than the nodes' spacing they are not, by more than the
    estimate over all of them misses them (the slack of the checks): the left-out miss is what the nodes do
    not tell between them."""
    rng = np.random.default_rng(5)
    uv = rng.uniform(0.0, 40.0, (3000, 2))
    points = np.column_stack([uv, 0.01 * uv[:, 0] ** 2])              # a curved sheet, nodes ~0.7 mm apart
    rows = np.arange(0, 3000, 7)

    quadratic = np.column_stack([1e-3 * points[:, 0] ** 2, 2e-3 * points[:, 1],
                                 1e-4 * points[:, 0] * points[:, 1]])
    smooth = FieldEstimator(points, quadratic, 20)
    assert np.abs(smooth.left_out(rows) - quadratic[rows]).max() < 1e-5           # 1 % of a 1e-3 mm tolerance

    front = np.column_stack([0.01 * np.tanh((points[:, 1] - 20.0) / 0.3), np.zeros(3000), np.zeros(3000)])
    sharp = FieldEstimator(points, front, 20)
    at_front = rows[np.abs(points[rows, 1] - 20.0) < 0.5]
    left_out = np.linalg.norm(sharp.left_out(at_front) - front[at_front], axis=1)
    fitted = np.linalg.norm(sharp(points[at_front]) - front[at_front], axis=1)
    assert left_out.max() > 1e-3                                       # a tolerance of 1e-3 mm is not told
    assert left_out.max() >= fitted.max()
