"""The numpy B-spline evaluators of hot2cold.core.bspline, checked against the OpenCascade kernel as oracle."""
from __future__ import annotations

import time

import numpy as np
import pytest
import scipy.sparse
from OCP.gp import gp_Pnt, gp_Vec

from hot2cold.core.bspline import (BasisMemo, BSplineCurve, BSplineSurface, _span_rows, curve_basis, evaluated,
                                   curve_derivative_basis, evaluate_curve, evaluate_surface, fit_curve, refine_surface,
                                   surface_basis, surface_derivative_bases, surface_derivatives, surface_first_jet,
                                   surface_normals)
from hot2cold.kernel.convert import (curve2d_to_record, curve_to_record, record_to_curve, record_to_curve2d,
                                     record_to_surface, surface_to_record)

RTOL = 1e-12


# ----------------------------------------------------------------------------------------------- builders
def random_knots(rng, n: int, p: int, lo: float = -1.3, hi: float = 2.7, repeat: bool = True) -> np.ndarray:
    """A clamped knot vector for ``n`` poles of degree ``p`` on ``[lo, hi]``.

    With ``repeat`` some interior knots are repeated: one with multiplicity ``p`` (C0 there) and one with
    multiplicity 2 when there is room.
    """
    n_inner = n - p - 1
    mults = []
    left = n_inner
    for want in ((p, 2) if repeat else ()):  # interior multiplicity never above the degree
        if 0 < want <= min(left, p):
            mults.append(want)
            left -= want
    mults += [1] * left
    values = np.unique(np.round(rng.uniform(0.05, 0.95, len(mults)), 6))
    while len(values) < len(mults):  # distinct values really distinct
        values = np.unique(np.round(rng.uniform(0.05, 0.95, len(mults)), 6))
    rng.shuffle(mults)
    inner = np.repeat(values, mults)
    assert len(inner) == n_inner
    return np.r_[np.zeros(p + 1), inner, np.ones(p + 1)] * (hi - lo) + lo


def random_curve(rng, p: int, rational: bool, n: int | None = None) -> BSplineCurve:
    n = n if n is not None else p + 5
    w = rng.uniform(0.3, 3.0, n) if rational else None
    return BSplineCurve(rng.normal(scale=20.0, size=(n, 3)), random_knots(rng, n, p), p, w)


def random_surface(rng, p: int, q: int, rational: bool, shape=None) -> BSplineSurface:
    nu, nv = shape if shape is not None else (p + 4, q + 5)
    w = rng.uniform(0.3, 3.0, (nu, nv)) if rational else None
    return BSplineSurface(rng.normal(scale=20.0, size=(nu, nv, 3)),
                          random_knots(rng, nu, p, 0.5, 4.0), random_knots(rng, nv, q, -2.0, -0.25),
                          p, q, w)


def curve_params(rng, c: BSplineCurve, m: int = 60) -> np.ndarray:
    lo, hi = c.domain
    return np.r_[lo, hi, np.unique(c.knots), rng.uniform(lo, hi, m)]


def surface_params(rng, s: BSplineSurface, m: int = 80) -> tuple[np.ndarray, np.ndarray]:
    u0, u1, v0, v1 = s.domain
    uk, vk = np.unique(s.u_knots), np.unique(s.v_knots)
    gu, gv = np.meshgrid(uk, vk, indexing="ij")  # every knot crossing, including the four corners
    u = np.r_[gu.ravel(), rng.uniform(u0, u1, m), np.full(5, u0), np.full(5, u1), rng.uniform(u0, u1, 10)]
    v = np.r_[gv.ravel(), rng.uniform(v0, v1, m), rng.uniform(v0, v1, 10), np.full(5, v0), np.full(5, v1)]
    return u, v


def xyz(p) -> list[float]:
    return [p.X(), p.Y(), p.Z()]


def assert_close_rel(actual, expected, rtol=RTOL):
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape
    scale = max(np.abs(expected).max(), 1e-300)
    err = np.abs(actual - expected).max() / scale
    assert err <= rtol, f"relative error {err:.3e} > {rtol:.1e}"


CURVE_CASES = [(p, rat) for p in (1, 2, 3, 4, 5) for rat in (False, True)]
SURFACE_CASES = [(p, q, rat) for (p, q) in ((1, 1), (1, 3), (2, 2), (3, 2), (3, 3), (5, 4)) for rat in (False, True)]


# ------------------------------------------------------------------------------------------ kernel oracle
@pytest.mark.parametrize("p,rational", CURVE_CASES)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_curve_matches_kernel(p, rational, seed):
    rng = np.random.default_rng(100 * p + 10 * rational + seed)
    c = random_curve(rng, p, rational)
    g = record_to_curve(c)
    t = curve_params(rng, c)
    pts, d1, d2 = [], [], []
    for x in t:
        pt, v1, v2 = gp_Pnt(), gp_Vec(), gp_Vec()
        g.D2(float(x), pt, v1, v2)
        pts.append(xyz(g.Value(float(x))))
        d1.append(xyz(v1))
        d2.append(xyz(v2))
    assert_close_rel(evaluate_curve(c, t), np.array(pts))
    assert_close_rel(curve_derivative_basis(c, t) @ c.poles, np.array(d1))
    assert_close_rel(curve_derivative_basis(c, t, nu=2) @ c.poles, np.array(d2), rtol=1e-11)


@pytest.mark.parametrize("p,q,rational", SURFACE_CASES)
@pytest.mark.parametrize("seed", [0, 1])
def test_surface_matches_kernel(p, q, rational, seed):
    rng = np.random.default_rng(1000 * p + 100 * q + 10 * rational + seed)
    s = random_surface(rng, p, q, rational)
    g = record_to_surface(s)
    u, v = surface_params(rng, s)
    pts, dus, dvs = [], [], []
    for a, b in zip(u, v):
        pt, du, dv = gp_Pnt(), gp_Vec(), gp_Vec()
        g.D1(float(a), float(b), pt, du, dv)
        pts.append(xyz(g.Value(float(a), float(b))))
        dus.append(xyz(du))
        dvs.append(xyz(dv))
    pts, dus, dvs = np.array(pts), np.array(dus), np.array(dvs)
    assert_close_rel(evaluate_surface(s, u, v), pts)
    su, sv = surface_derivatives(s, u, v)
    assert_close_rel(su, dus)
    assert_close_rel(sv, dvs)
    n_occ = np.cross(dus, dvs)
    n_occ /= np.linalg.norm(n_occ, axis=1, keepdims=True)
    normals = surface_normals(s, u, v)
    assert np.all(np.isfinite(normals))
    np.testing.assert_allclose(normals, n_occ, atol=1e-9)


@pytest.mark.parametrize("rational", [False, True])
def test_surface_round_trip_through_kernel(rational):
    rng = np.random.default_rng(7 + rational)
    for p, q in ((1, 2), (3, 3), (4, 2)):
        rec = random_surface(rng, p, q, rational)
        back = surface_to_record(record_to_surface(rec))
        assert (back.u_degree, back.v_degree) == (rec.u_degree, rec.v_degree)
        np.testing.assert_array_equal(back.u_knots, rec.u_knots)
        np.testing.assert_array_equal(back.v_knots, rec.v_knots)
        np.testing.assert_array_equal(back.poles, rec.poles)
        if rational:
            np.testing.assert_array_equal(back.weights, rec.weights)
        else:
            assert back.weights is None


@pytest.mark.parametrize("rational", [False, True])
@pytest.mark.parametrize("plane", [False, True], ids=["curve", "pcurve"])
def test_curve_round_trip_through_kernel(rational, plane):
    rng = np.random.default_rng(17 + rational)
    rec = random_curve(rng, 3, rational)
    if plane:            # a pcurve: poles (u, v, 0)
        rec = BSplineCurve(np.c_[rec.poles[:, :2], np.zeros(len(rec.poles))], rec.knots, rec.degree, rec.weights)
        back = curve2d_to_record(record_to_curve2d(rec))
    else:
        back = curve_to_record(record_to_curve(rec))
    assert back.degree == rec.degree
    np.testing.assert_array_equal(back.knots, rec.knots)
    np.testing.assert_array_equal(back.poles, rec.poles)
    if rational:
        np.testing.assert_array_equal(back.weights, rec.weights)
    else:
        assert back.weights is None


@pytest.mark.parametrize("p", [1, 3, 5])
def test_a_fit_on_a_curve_s_own_knots_gives_the_curve_back(p):
    """``fit_curve`` through points of a non-rational curve, on its knots (C0 and C1 knots among them), with
    p + 2 parameters in each span: the curve itself, to rounding; its ends exactly the points' ends."""
    rng = np.random.default_rng(5 + p)
    curve = random_curve(rng, p, False, n=p + 8)
    breaks = np.unique(curve.knots)
    t = np.concatenate([np.linspace(a, b, p + 2) for a, b in zip(breaks[:-1], breaks[1:])])
    points = evaluate_curve(curve, t)
    fitted = fit_curve(t, points, curve.knots, p)
    scale = np.abs(curve.poles).max()
    assert np.abs(fitted.poles - curve.poles).max() <= 1e-9 * scale
    assert np.array_equal(fitted.poles[[0, -1]], points[[0, -1]])


def test_a_fit_passes_through_the_ends_of_noisy_points_and_refuses_bad_shapes():
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 1.0, 40)
    points = np.c_[t, np.sin(3 * t), np.zeros_like(t)] + rng.normal(scale=1e-3, size=(40, 3))
    knots = np.r_[np.zeros(4), 0.25, 0.5, 0.75, np.ones(4)]
    fitted = fit_curve(t, points, knots, 3)
    assert np.array_equal(evaluate_curve(fitted, [0.0, 1.0]), points[[0, -1]])
    assert np.abs(evaluate_curve(fitted, t) - points).max() < 5e-3       # the noise, not the sine, is left
    with pytest.raises(ValueError, match=r"points must be \(m, 3\)"):
        fit_curve(t, points[:, :2], knots, 3)


# ------------------------------------------------------------------------------------- basis properties
@pytest.mark.parametrize("p,rational", CURVE_CASES)
def test_curve_partition_of_unity(p, rational):
    rng = np.random.default_rng(p + 50 * rational)
    c = random_curve(rng, p, rational, n=p + 9)
    t = curve_params(rng, c, 500)
    b = curve_basis(c, t)
    assert isinstance(b, scipy.sparse.csr_array)
    assert b.shape == (len(t), c.n_poles)
    np.testing.assert_allclose(b.sum(axis=1), 1.0, rtol=0, atol=1e-14)
    assert b.min() >= -1e-15  # B-spline and rational bases are non-negative
    d = curve_derivative_basis(c, t)
    np.testing.assert_allclose(d.sum(axis=1), 0.0, atol=1e-11 * abs(d).max())


@pytest.mark.parametrize("p,q,rational", SURFACE_CASES)
def test_surface_partition_of_unity(p, q, rational):
    rng = np.random.default_rng(p + 10 * q + 50 * rational)
    s = random_surface(rng, p, q, rational)
    u, v = surface_params(rng, s, 400)
    b = surface_basis(s, u, v)
    assert isinstance(b, scipy.sparse.csr_array)
    assert b.shape == (len(u), s.shape[0] * s.shape[1])
    np.testing.assert_allclose(b.sum(axis=1), 1.0, rtol=0, atol=1e-14)
    assert b.min() >= -1e-15
    du, dv = surface_derivative_bases(s, u, v)
    for d in (du, dv):
        assert d.shape == b.shape
        np.testing.assert_allclose(d.sum(axis=1), 0.0, atol=1e-11 * abs(d).max())


def random_affine(rng):
    m = rng.normal(size=(3, 3)) + 3 * np.eye(3)
    return m, rng.normal(scale=50.0, size=3)


@pytest.mark.parametrize("rational", [False, True])
def test_surface_digest_tells_content_not_objects(rational):
    """Records equal to the bit give one digest, made apart or copied; a pole or a knot moved to the next float,
    a weight changed, or unit weights given to a non-rational record, another."""
    rng = np.random.default_rng(7 + rational)
    s = random_surface(rng, 3, 2, rational)
    copy = BSplineSurface(s.poles.copy(), s.u_knots.copy(), s.v_knots.copy(), s.u_degree, s.v_degree,
                          None if s.weights is None else s.weights.copy())
    assert copy is not s and copy.digest() == s.digest() == s.with_poles(s.poles.copy()).digest()
    poles = s.poles.copy()
    poles[1, 1, 2] = np.nextafter(poles[1, 1, 2], np.inf)
    knots = s.u_knots.copy()
    knots[s.u_degree + 1] = np.nextafter(knots[s.u_degree + 1], np.inf)
    others = [s.with_poles(poles), BSplineSurface(s.poles, knots, s.v_knots, s.u_degree, s.v_degree, s.weights)]
    if rational:
        weights = s.weights.copy()
        weights[0, 0] *= 1.5
        others.append(BSplineSurface(s.poles, s.u_knots, s.v_knots, s.u_degree, s.v_degree, weights))
    else:
        others.append(BSplineSurface(s.poles, s.u_knots, s.v_knots, s.u_degree, s.v_degree, np.ones(s.shape)))
    assert len({s.digest(), *(o.digest() for o in others)}) == len(others) + 1


@pytest.mark.parametrize("rational", [False, True])
def test_curve_affine_invariance(rational):
    rng = np.random.default_rng(31 + rational)
    for p in (1, 2, 3, 5):
        c = random_curve(rng, p, rational)
        m, b = random_affine(rng)
        t = curve_params(rng, c, 200)
        moved = c.with_poles(c.poles @ m.T + b)
        np.testing.assert_allclose(evaluate_curve(moved, t), evaluate_curve(c, t) @ m.T + b,
                                   rtol=0, atol=1e-11 * np.abs(moved.poles).max())
        d, dm = curve_derivative_basis(c, t) @ c.poles, curve_derivative_basis(moved, t) @ moved.poles
        np.testing.assert_allclose(dm, d @ m.T, rtol=0, atol=1e-11 * np.abs(dm).max())


@pytest.mark.parametrize("rational", [False, True])
def test_surface_affine_invariance(rational):
    rng = np.random.default_rng(41 + rational)
    for p, q in ((1, 1), (2, 3), (3, 3)):
        s = random_surface(rng, p, q, rational)
        m, b = random_affine(rng)
        u, v = surface_params(rng, s, 300)
        moved = s.with_poles(s.poles @ m.T + b)
        np.testing.assert_allclose(evaluate_surface(moved, u, v), evaluate_surface(s, u, v) @ m.T + b,
                                   rtol=0, atol=1e-11 * np.abs(moved.poles).max())
        su, sv = surface_derivatives(s, u, v)
        msu, msv = surface_derivatives(moved, u, v)
        np.testing.assert_allclose(msu, su @ m.T, rtol=0, atol=1e-11 * np.abs(msu).max())
        np.testing.assert_allclose(msv, sv @ m.T, rtol=0, atol=1e-11 * np.abs(msv).max())


def test_surface_basis_is_rowwise_kronecker_of_curve_bases():
    """Column ``i * nv + j`` belongs to pole (i, j): the non-rational surface basis is the row-wise
    Kronecker product of the u and v curve bases."""
    rng = np.random.default_rng(5)
    s = random_surface(rng, 3, 2, False)
    nu, nv = s.shape
    cu = BSplineCurve(np.zeros((nu, 3)), s.u_knots, s.u_degree)
    cv = BSplineCurve(np.zeros((nv, 3)), s.v_knots, s.v_degree)
    u, v = surface_params(rng, s, 100)
    bu, bv = curve_basis(cu, u).toarray(), curve_basis(cv, v).toarray()
    expected = (bu[:, :, None] * bv[:, None, :]).reshape(len(u), nu * nv)
    np.testing.assert_allclose(surface_basis(s, u, v).toarray(), expected, rtol=0, atol=1e-15)
    # and poles (i, j) -> column i * nv + j: a single unit pole reproduces that basis function
    i, j = 2, 1
    poles = np.zeros((nu, nv, 3))
    poles[i, j, 0] = 1.0
    np.testing.assert_allclose(evaluate_surface(s.with_poles(poles), u, v)[:, 0], expected[:, i * nv + j],
                               atol=1e-15)


def test_derivative_bases_match_finite_differences():
    rng = np.random.default_rng(9)
    s = random_surface(rng, 3, 3, True, shape=(6, 6))
    s = BSplineSurface(s.poles, random_knots(rng, 6, 3, 0.5, 4.0, repeat=False),
                       random_knots(rng, 6, 3, -2.0, -0.25, repeat=False), 3, 3, s.weights)
    u0, u1, v0, v1 = s.domain
    u, v = rng.uniform(u0 + 0.01, u1 - 0.01, 50), rng.uniform(v0 + 0.01, v1 - 0.01, 50)
    h = 1e-6
    su, sv = surface_derivatives(s, u, v)
    fu = (evaluate_surface(s, u + h, v) - evaluate_surface(s, u - h, v)) / (2 * h)
    fv = (evaluate_surface(s, u, v + h) - evaluate_surface(s, u, v - h)) / (2 * h)
    np.testing.assert_allclose(su, fu, rtol=0, atol=1e-6 * np.abs(su).max())
    np.testing.assert_allclose(sv, fv, rtol=0, atol=1e-6 * np.abs(sv).max())


@pytest.mark.parametrize("rational", [False, True])
def test_first_jet_is_the_points_and_derivatives(rational):
    """surface_first_jet sums each row's poles itself: the same points and first derivatives as the sparse
    bases, on random (rational) nets."""
    rng = np.random.default_rng(7)
    for p, q in ((1, 2), (3, 3), (2, 5)):
        s = random_surface(rng, p, q, rational)
        u, v = surface_params(rng, s)                 # every knot crossing and the domain's ends among them
        points, s_u, s_v = surface_first_jet(s, u, v)
        du, dv = surface_derivatives(s, u, v)
        assert points.shape == s_u.shape == s_v.shape == (len(u), 3)
        assert_close_rel(points, evaluate_surface(s, u, v), 1e-13)
        assert_close_rel(s_u, du, 1e-13)
        assert_close_rel(s_v, dv, 1e-13)


# ----------------------------------------------------------------------------------- domain and shapes
@pytest.mark.parametrize("rational", [False, True])
def test_domain_ends_give_end_poles(rational):
    rng = np.random.default_rng(3)
    for p in (1, 2, 3, 5):
        c = random_curve(rng, p, rational)
        lo, hi = c.domain
        assert hi == c.knots[c.n_poles]
        b = curve_basis(c, [lo, hi]).toarray()
        np.testing.assert_array_equal(b[0], np.eye(c.n_poles)[0])
        np.testing.assert_array_equal(b[1], np.eye(c.n_poles)[-1])
        np.testing.assert_allclose(evaluate_curve(c, [lo, hi]), c.poles[[0, -1]], rtol=0, atol=1e-13)


def test_parameters_slightly_outside_are_clipped_far_outside_raise():
    rng = np.random.default_rng(4)
    c = random_curve(rng, 3, True)
    lo, hi = c.domain
    length = hi - lo
    inside = evaluate_curve(c, [lo, hi])
    np.testing.assert_array_equal(evaluate_curve(c, [lo - 1e-12 * length, hi + 1e-12 * length]), inside)
    with pytest.raises(ValueError, match="outside the domain"):
        curve_basis(c, [lo, hi + 1e-6 * length])
    with pytest.raises(ValueError, match="outside the domain"):
        curve_derivative_basis(c, [lo - 1e-3])
    with pytest.raises(ValueError, match="NaN"):
        curve_basis(c, [np.nan])
    s = random_surface(rng, 2, 2, False)
    u0, u1, v0, v1 = s.domain
    with pytest.raises(ValueError, match="v"):
        surface_basis(s, [u0], [v1 + 1.0])
    with pytest.raises(ValueError, match="same shape"):
        surface_basis(s, [u0, u1], [v0, v1, v0])
    with pytest.raises(ValueError, match="1-D"):
        curve_basis(c, np.zeros((2, 2)))


def test_scalar_and_empty_parameters():
    rng = np.random.default_rng(6)
    c = random_curve(rng, 2, False)
    s = random_surface(rng, 2, 3, True)
    nu, nv = s.shape
    assert curve_basis(c, []).shape == (0, c.n_poles)
    assert curve_derivative_basis(c, np.zeros(0)).shape == (0, c.n_poles)
    assert evaluate_curve(c, []).shape == (0, 3)
    assert surface_basis(s, [], []).shape == (0, nu * nv)
    assert evaluate_surface(s, [], []).shape == (0, 3)
    assert surface_normals(s, [], []).shape == (0, 3)
    assert evaluate_curve(c, c.domain[0]).shape == (1, 3)
    # a scalar u with an array v: an iso-curve
    u0, u1, v0, v1 = s.domain
    v = np.linspace(v0, v1, 7)
    np.testing.assert_array_equal(evaluate_surface(s, 0.5 * (u0 + u1), v),
                                  evaluate_surface(s, np.full(7, 0.5 * (u0 + u1)), v))


def test_derivative_beyond_degree_is_zero_and_negative_nu_raises():
    rng = np.random.default_rng(8)
    c = random_curve(rng, 2, False)
    t = curve_params(rng, c)
    assert abs(curve_derivative_basis(c, t, nu=3)).max() == 0.0
    np.testing.assert_array_equal(curve_derivative_basis(c, t, nu=0).toarray(), curve_basis(c, t).toarray())
    with pytest.raises(ValueError):
        curve_derivative_basis(c, t, nu=-1)


def test_normals_unit_and_nan_on_collapsed_edge():
    rng = np.random.default_rng(10)
    s = random_surface(rng, 3, 3, False)
    poles = s.poles.copy()
    poles[0, :, :] = poles[0, 0, :]  # the edge u = u0 collapses to a point
    s = s.with_poles(poles)
    u0, u1, v0, v1 = s.domain
    v = np.linspace(v0, v1, 9)
    assert np.all(np.isnan(surface_normals(s, u0, v)))
    u, v = rng.uniform(u0 + 0.1, u1, 200), rng.uniform(v0, v1, 200)
    n = surface_normals(s, u, v)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-14)
    su, sv = surface_derivatives(s, u, v)
    assert np.all(np.einsum("ij,ij->i", n, su) <= 1e-10 * np.linalg.norm(su, axis=1))
    assert np.all(np.einsum("ij,ij->i", n, np.cross(su, sv)) > 0)


def test_hundred_thousand_points_are_fast():
    """Vectorised: 1e5 points on a rational bicubic 40 x 30 net well within a few seconds (a Python loop
    per point would take far longer)."""
    rng = np.random.default_rng(11)
    s = random_surface(rng, 3, 3, True, shape=(40, 30))
    u0, u1, v0, v1 = s.domain
    u, v = rng.uniform(u0, u1, 100_000), rng.uniform(v0, v1, 100_000)
    start = time.perf_counter()
    b = surface_basis(s, u, v)
    pts = evaluate_surface(s, u, v)
    n = surface_normals(s, u, v)
    elapsed = time.perf_counter() - start
    assert b.shape == (100_000, 1200) and b.nnz == 100_000 * 16
    assert pts.shape == n.shape == (100_000, 3)
    assert elapsed < 5.0, f"{elapsed:.2f} s for 1e5 points"


@pytest.mark.parametrize("degree", range(0, 7))
def test_basis_rows_match_scipy_derivatives(degree):
    """The Cox-de Boor rows and their derivatives equal scipy's B-spline derivatives (an independent
    implementation) on knot vectors with repeated inner knots, at inner knots (the span to the right) and at
    both ends of the domain (the last non-empty span)."""
    from scipy.interpolate import BSpline

    rng = np.random.default_rng(degree)
    for trial in range(4):
        inner = np.sort(rng.uniform(0.0, 3.0, rng.integers(0, 7)))
        if trial == 1 and len(inner):
            inner = np.repeat(inner[:2], min(degree, 2) or 1)                # knots of multiplicity up to 2
        knots = np.concatenate([np.zeros(degree + 1), inner, np.full(degree + 1, 3.0)])
        n = len(knots) - degree - 1
        x = np.concatenate([rng.uniform(0.0, 3.0, 40), [0.0, 3.0], inner])
        for nu in range(degree + 2):
            start, rows = _span_rows(x, knots, degree, nu)
            for k, vals in enumerate(rows):
                dense = np.zeros((len(x), n))
                np.put_along_axis(dense, start[:, None] + np.arange(degree + 1), vals, axis=1)
                for i in range(n):
                    spline = BSpline(knots, np.eye(n)[i], degree, extrapolate=False)
                    expected = spline(x, nu=k) if k <= degree else np.zeros(len(x))
                    # scipy's derivative at a knot may take either side: compare off the knots only there
                    where = ~np.isin(x, knots) | (k == 0) | (k > degree)
                    at_end = x == 3.0                         # scipy gives the left limit there too (extrapolate off)
                    where |= at_end & (k == 0)
                    scale = max(1.0, float(np.abs(expected[where]).max(initial=0.0)))
                    assert np.allclose(dense[where, i], np.nan_to_num(expected[where]), atol=1e-9 * scale), \
                        (degree, nu, k, i)


# --------------------------------------------------------------------------------- remembered basis rows
@pytest.mark.parametrize("rational", [False, True])
def test_remembered_rows_are_the_rows(rational):
    """A surface that remembers its basis rows (BasisMemo) gives the same points, derivatives, normals and
    bases as one that does not, on the first request and on the same request again (served from the memo),
    and so do the records made from it with other poles and refined knots."""
    rng = np.random.default_rng(5)
    plain = random_surface(rng, 3, 2, rational)
    kept = BSplineSurface(plain.poles, plain.u_knots, plain.v_knots, 3, 2, plain.weights)
    memo = BasisMemo()
    kept.remember(memo)
    u, v = surface_params(rng, plain)
    moved = rng.normal(size=plain.poles.shape)
    for a, b in ((plain, kept), (plain.with_poles(moved), kept.with_poles(moved)),
                 (refine_surface(plain, 0, [1.234]), refine_surface(kept, 0, [1.234]))):
        for _ in range(2):
            assert np.array_equal(evaluate_surface(a, u, v), evaluate_surface(b, u, v))
            for x, y in zip(surface_first_jet(a, u, v), surface_first_jet(b, u, v)):
                assert np.array_equal(x, y)
            assert np.array_equal(surface_normals(a, u, v), surface_normals(b, u, v), equal_nan=True)
            for x, y in zip(surface_derivative_bases(a, u, v), surface_derivative_bases(b, u, v)):
                assert np.array_equal(x.toarray(), y.toarray())
    assert memo._rows.entries, "nothing was remembered"


def test_remembered_rows_are_bounded_private_and_not_pickled():
    """The memo keeps at most its budget (least recently used out first) and no request larger than
    max_rows; a basis handed out from it may be scaled in place without changing what it keeps; a pickled
    surface comes back without it."""
    import pickle

    rng = np.random.default_rng(6)
    s = random_surface(rng, 3, 3, True)
    memo = BasisMemo(budget=40_000, max_rows=100)
    s.remember(memo)
    u0, u1, v0, v1 = s.domain
    for m in (30, 30, 30, 30, 150):
        surface_first_jet(s, rng.uniform(u0, u1, m), rng.uniform(v0, v1, m))
        assert memo._rows.bytes <= memo.budget
    assert all(len(entry[1]) <= 100 for entry in memo._rows.entries.values())
    u, v = rng.uniform(u0, u1, 20), rng.uniform(v0, v1, 20)
    before = surface_basis(s, u, v).toarray()
    basis = surface_basis(s, u, v)                  # served from the memo
    basis.data *= 2.0
    assert np.array_equal(surface_basis(s, u, v).toarray(), before)
    back = pickle.loads(pickle.dumps(s))
    assert back.__dict__.get("_memo") is None
    assert np.array_equal(evaluate_surface(back, u, v), evaluate_surface(s, u, v))
    memo.close()
    assert not memo._rows.entries and memo._rows.bytes == 0
    surface_first_jet(s, u, v)                      # a closed memo keeps nothing more
    assert not memo._rows.entries and memo._rows.bytes == 0


@pytest.mark.parametrize("rational", [False, True])
def test_evaluations_kept_by_content(rational):
    """``evaluated`` gives what the evaluation gives, read-only; asked again of the same surface or of one equal to
    the bit made apart (a correction run again on the same fits) at the same parameters, the kept array; at other
    parameters, of a surface with a pole moved or of one without a memo, a new evaluation.  The memo keeps at
    most its budget, and nothing once closed."""
    rng = np.random.default_rng(12 + rational)
    s = random_surface(rng, 3, 2, rational)
    memo = BasisMemo(evaluation_budget=20_000)
    s.remember(memo)
    u, v = surface_params(rng, s)
    first = evaluated(surface_normals, s, u, v)
    assert np.array_equal(first, surface_normals(s, u, v), equal_nan=True) and not first.flags.writeable
    assert evaluated(surface_normals, s, u, v) is first
    twin = s.with_poles(s.poles.copy())
    assert twin is not s and evaluated(surface_normals, twin, u, v) is first
    poles = s.poles.copy()
    poles[1, 1, 0] += 1.0
    for other, (a, b) in ((s.with_poles(poles), (u, v)), (s, (u[::-1], v[::-1])), (s, (u, v[::-1]))):
        again = evaluated(surface_normals, other, a, b)
        assert again is not first
        assert np.array_equal(again, surface_normals(other, a, b), equal_nan=True)
    assert evaluated(evaluate_surface, s, u, v) is not evaluated(surface_normals, s, u, v)
    plain = random_surface(rng, 2, 2, rational)                       # no memo: evaluated each time
    pu, pv = surface_params(rng, plain)
    assert evaluated(surface_normals, plain, pu, pv) is not evaluated(surface_normals, plain, pu, pv)
    for m in (200, 300, 400):
        u0, u1, v0, v1 = s.domain
        evaluated(surface_normals, s, rng.uniform(u0, u1, m), rng.uniform(v0, v1, m))
        assert memo._evaluations.bytes <= memo.evaluation_budget
    memo.close()
    assert not memo._evaluations.entries and memo._evaluations.bytes == 0
    assert evaluated(surface_normals, s, u, v).flags.writeable and not memo._evaluations.entries


@pytest.mark.parametrize("rational", [False, True])
def test_curve_digest_tells_content_not_objects(rational):
    """Curves equal to the bit give one digest, made apart or copied; a pole moved to the next float, a knot
    moved or another degree's record, another."""
    rng = np.random.default_rng(9 + rational)
    c = random_curve(rng, 3, rational)
    copy = BSplineCurve(c.poles.copy(), c.knots.copy(), c.degree, None if c.weights is None else c.weights.copy())
    assert copy is not c and copy.digest() == c.digest() == c.with_poles(c.poles.copy()).digest()
    poles = c.poles.copy()
    poles[1, 0] = np.nextafter(poles[1, 0], np.inf)
    knots = c.knots.copy()
    knots[c.degree + 1] = np.nextafter(knots[c.degree + 1], -np.inf)
    others = [c.with_poles(poles), BSplineCurve(c.poles, knots, c.degree, c.weights)]
    assert len({c.digest(), *(o.digest() for o in others)}) == len(others) + 1


@pytest.mark.parametrize("rational", [False, True])
def test_large_evaluations_in_chunks_are_the_whole_ones_to_the_bit(rational):
    """Points, derivatives, normals and jets of more than two chunks of parameters (``EVAL_CHUNK``, the last one
    longer) are those of one evaluation of them all, to the bit, with a scalar ``v`` broadcast as before."""
    from hot2cold.core import bspline

    rng = np.random.default_rng(11)
    surface = random_surface(rng, 3, 2, rational)
    u0, u1, v0, v1 = surface.domain
    m = 2 * bspline.EVAL_CHUNK + 17
    u, v = rng.uniform(u0, u1, m), rng.uniform(v0, v1, m)
    for evaluate in (bspline.evaluate_surface, bspline.surface_derivatives, bspline.surface_first_jet,
                     bspline.surface_normals, bspline.normals_and_rounding, bspline.surface_jet):
        for vv in (v, v0):
            chunked, whole = evaluate(surface, u, vv), evaluate.__wrapped__(surface, u, vv)
            chunked, whole = ((x,) if isinstance(x, np.ndarray) else x for x in (chunked, whole))
            assert len(chunked) == len(whole)
            for a, b in zip(chunked, whole):
                assert a.shape[0] == m
                np.testing.assert_array_equal(a, b)
