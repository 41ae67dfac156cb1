"""Truncated-SVD least squares (hot2cold.core.lstsq, paper eq. 19-20)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse

from hot2cold.core.bspline import BSplineCurve, BSplineSurface, curve_basis, surface_basis
from hot2cold.core.lstsq import TsvdSolution, reduce_rows, solve_tsvd
from hot2cold.settings import FLT_EPSILON


@pytest.mark.parametrize("shape", [(50, 8), (200, 40), (8, 8), (5, 12)])
@pytest.mark.parametrize("k", [1, 3])
def test_matches_numpy_on_well_conditioned_problems(shape, k):
    rng = np.random.default_rng(shape[0] * 7 + shape[1] + k)
    a = rng.normal(size=shape)
    b = rng.normal(size=(shape[0], k))
    sol = solve_tsvd(a, b)
    assert isinstance(sol, TsvdSolution)
    ref = np.linalg.lstsq(a, b, rcond=None)[0]  # minimum norm also for the wide case
    assert sol.x.shape == (shape[1], k)
    np.testing.assert_allclose(sol.x, ref, rtol=0, atol=1e-10 * max(1.0, np.abs(ref).max()))
    assert sol.rank == min(shape) and sol.n_unknowns == shape[1]
    sv = np.linalg.svd(a, compute_uv=False)
    np.testing.assert_allclose(sol.singular_values, sv, rtol=1e-12)
    assert sol.sigma_max == pytest.approx(sv[0], rel=1e-12)
    assert sol.sigma_min == pytest.approx(sv[-1], rel=1e-12)
    assert sol.condition == pytest.approx(sv[0] / sv[-1], rel=1e-10)
    assert sol.cutoff == pytest.approx(sv[0] * shape[1] * FLT_EPSILON, rel=1e-12)
    assert not sol.rank_deficient or shape[0] < shape[1]


def test_exact_solution_is_reproduced():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(300, 25))
    x = rng.normal(size=(25, 3))
    sol = solve_tsvd(a, a @ x)
    np.testing.assert_allclose(sol.x, x, rtol=0, atol=1e-12)


def test_one_dimensional_right_hand_side():
    rng = np.random.default_rng(2)
    a = rng.normal(size=(40, 6))
    b = rng.normal(size=40)
    sol = solve_tsvd(a, b)
    assert sol.x.shape == (6,)
    np.testing.assert_allclose(sol.x, np.linalg.lstsq(a, b, rcond=None)[0], atol=1e-12)


def test_rank_deficient_gives_minimum_norm_solution_and_rank():
    rng = np.random.default_rng(3)
    base = rng.normal(size=(60, 5))
    # columns 5 and 6 repeat columns 0 and 1, column 7 is zero (an empty knot span): rank 5 of 8
    a = np.c_[base, base[:, 0], base[:, 1], np.zeros(60)]
    b = rng.normal(size=(60, 3))
    sol = solve_tsvd(a, b)
    assert sol.rank == 5
    assert sol.n_unknowns == 8
    assert sol.rank_deficient
    ref = np.linalg.pinv(a, rcond=1e-10) @ b
    np.testing.assert_allclose(sol.x, ref, rtol=0, atol=1e-10)
    # minimum norm: the duplicated columns share the weight equally, the zero column gets nothing
    np.testing.assert_allclose(sol.x[0], sol.x[5], atol=1e-12)
    np.testing.assert_allclose(sol.x[1], sol.x[6], atol=1e-12)
    np.testing.assert_array_equal(sol.x[7], 0.0)
    # and it is a least-squares solution: the residual is orthogonal to the columns
    np.testing.assert_allclose(a.T @ (a @ sol.x - b), 0.0, atol=1e-10)
    assert sol.condition == pytest.approx(sol.singular_values[0] / sol.singular_values[4])
    assert sol.sigma_min < sol.cutoff


def test_a_prior_fills_the_dropped_directions_and_changes_nothing_else():
    rng = np.random.default_rng(4)
    base = rng.normal(size=(60, 5))
    a = np.c_[base, base[:, 0], np.zeros(60)]          # rank 5 of 7: a repeated and an empty column
    truth = rng.normal(size=(7, 3))
    b = a @ truth
    plain = solve_tsvd(a, b)
    assert plain.rank == 5
    assert np.abs(plain.x - truth).max() > 0.1          # minimum norm: not the truth where it is undetermined
    with_truth = solve_tsvd(a, b, prior=truth)           # data and prior agree: exactly the prior
    np.testing.assert_allclose(with_truth.x, truth, rtol=0, atol=1e-12)
    assert with_truth.rank == plain.rank
    prior = rng.normal(size=(7, 3))
    guided = solve_tsvd(a, b, prior=prior)
    np.testing.assert_allclose(a @ guided.x, b, rtol=0, atol=1e-10)       # still a least-squares solution
    np.testing.assert_allclose(guided.x[6], prior[6], rtol=0, atol=1e-12)  # the empty column keeps the prior
    # the repeated pair keeps the prior's difference, its sum is the data's
    np.testing.assert_allclose(guided.x[0] - guided.x[5], prior[0] - prior[5], rtol=0, atol=1e-10)
    full = rng.normal(size=(60, 4))                        # full rank: the prior does not matter
    np.testing.assert_allclose(solve_tsvd(full, b, prior=rng.normal(size=(4, 3))).x, solve_tsvd(full, b).x,
                               rtol=0, atol=1e-10)
    with pytest.raises(ValueError, match=r"prior must be \(7, 3\)"):
        solve_tsvd(a, b, prior=np.zeros((7,)))


def test_a_callable_prior_is_called_only_where_directions_are_dropped():
    rng = np.random.default_rng(5)
    base = rng.normal(size=(60, 5))
    a = np.c_[base, base[:, 0], np.zeros(60)]          # rank 5 of 7
    b = rng.normal(size=(60, 3))
    prior = rng.normal(size=(7, 3))
    calls = []

    def lazy():
        calls.append(1)
        return prior

    np.testing.assert_array_equal(solve_tsvd(a, b, prior=lazy).x, solve_tsvd(a, b, prior=prior).x)
    assert len(calls) == 1
    full = solve_tsvd(base, b, prior=lambda: calls.append(1))    # full rank: never called
    assert full.rank == 5 and len(calls) == 1
    assert solve_tsvd(np.zeros((0, 7)), np.zeros((0, 3)), prior=lazy).x.tolist() == prior.tolist()  # no rows
    with pytest.raises(ValueError, match=r"prior must be \(7, 3\)"):
        solve_tsvd(a, b, prior=lambda: np.zeros(7))


def test_ill_conditioned_columns_are_truncated():
    rng = np.random.default_rng(4)
    s = 80
    base = rng.normal(size=(s, 4))
    # column 4 equals column 3 up to 1e-11: far below the cut-off sigma_1 * s * FLT_EPSILON (~1e-5 relative)
    a = np.c_[base, base[:, 3] + 1e-11 * rng.normal(size=s)]
    b = rng.normal(size=(s, 2))
    sol = solve_tsvd(a, b)
    assert sol.rank == 4
    assert sol.condition < 1e3
    assert np.abs(sol.x).max() < 10.0  # no blow-up
    np.testing.assert_allclose(sol.x[3], sol.x[4], atol=1e-8)
    # numpy's double-precision lstsq keeps the tiny singular value and blows up
    plain = np.linalg.lstsq(a, b, rcond=None)[0]
    assert np.abs(plain).max() > 1e3
    # a tighter epsilon keeps it
    tight = solve_tsvd(a, b, epsilon=1e-20)
    assert tight.rank == 5
    assert tight.condition > 1e8


def test_cutoff_scales_with_unknowns_and_epsilon_not_rows():
    sv = np.array([1.0, 1e-3, 2e-7, 1e-9])
    for s in (10, 10_000):                 # the cut-off does not grow with the rows
        a = np.zeros((s, 4))
        a[:4, :4] = np.diag(sv)
        b = np.ones(s)
        sol = solve_tsvd(a, b)  # cut-off 1 * 4 * 1.19e-7 = 4.8e-7: keeps 1, 1e-3, not 2e-7
        assert sol.cutoff == pytest.approx(4 * FLT_EPSILON)
        assert sol.rank == 2
        np.testing.assert_allclose(sol.x, [1.0, 1e3, 0.0, 0.0], rtol=1e-12)
        assert sol.condition == pytest.approx(1e3)
    assert sol.sigma_min == pytest.approx(1e-9) and sol.sigma_max == pytest.approx(1.0)
    assert solve_tsvd(a, b, epsilon=1e-8).rank == 3
    assert solve_tsvd(a, b, epsilon=1e-6).rank == 2


def test_the_rank_of_a_spline_fit_does_not_change_with_the_node_count():
    """A degree-9 curve's basis (20 poles) sampled evenly at 200 and at 200 000 parameters: sigma_20 / sigma_1
    is 8.3e-3 either way, and every pole is kept either way.  The paper's cut-off, sigma_1 (s - 1)
    FLT_EPSILON, grows with s: 2.4e-2 sigma_1 at 200 000, which would drop combinations the data determine."""
    curve = _curve(20, degree=9)
    for s in (200, 200_000):
        sol = solve_tsvd(curve_basis(curve, np.linspace(0.0, 1.0, s)), np.ones(s))
        ratio = sol.singular_values[-1] / sol.singular_values[0]
        assert 5e-3 < ratio < s * FLT_EPSILON or s == 200
        assert sol.rank == 20


@pytest.mark.parametrize("fmt", ["csr", "csc", "coo"])
def test_sparse_input(fmt):
    rng = np.random.default_rng(5)
    dense = scipy.sparse.random_array((150, 20), density=0.3, format="csr", rng=rng).toarray()
    dense += np.eye(150, 20)  # full column rank
    b = rng.normal(size=(150, 3))
    a = scipy.sparse.csr_array(dense).asformat(fmt)
    sol = solve_tsvd(a, b)
    np.testing.assert_allclose(sol.x, np.linalg.lstsq(dense, b, rcond=None)[0], atol=1e-10)
    # also the older sparse matrix classes
    sol2 = solve_tsvd(scipy.sparse.csr_matrix(dense), b)
    np.testing.assert_allclose(sol2.x, sol.x, atol=1e-13)


def test_input_is_not_modified():
    rng = np.random.default_rng(6)
    a = rng.normal(size=(30, 4))
    b = rng.normal(size=(30, 2))
    a0, b0 = a.copy(), b.copy()
    solve_tsvd(a, b)
    np.testing.assert_array_equal(a, a0)
    np.testing.assert_array_equal(b, b0)


def test_empty_problems():
    no_rows = solve_tsvd(np.zeros((0, 4)), np.zeros((0, 3)))
    assert no_rows.x.shape == (4, 3)
    np.testing.assert_array_equal(no_rows.x, 0.0)
    assert no_rows.rank == 0 and no_rows.n_unknowns == 4 and no_rows.rank_deficient
    no_cols = solve_tsvd(np.zeros((5, 0)), np.ones((5, 3)))
    assert no_cols.x.shape == (0, 3)
    assert no_cols.rank == 0 and no_cols.n_unknowns == 0
    assert solve_tsvd(np.zeros((0, 2)), np.zeros(0)).x.shape == (2,)
    zero = solve_tsvd(np.zeros((6, 3)), np.ones((6, 3)))
    assert zero.rank == 0
    np.testing.assert_array_equal(zero.x, 0.0)
    assert np.isnan(zero.condition)


def test_shape_errors():
    with pytest.raises(ValueError, match=r"\(10, 3\).*\(9, 2\)"):
        solve_tsvd(np.ones((10, 3)), np.ones((9, 2)))
    with pytest.raises(ValueError, match="2-D"):
        solve_tsvd(np.ones(10), np.ones(10))
    with pytest.raises(ValueError, match="B must be"):
        solve_tsvd(np.ones((10, 3)), np.ones((10, 2, 1)))
    with pytest.raises(ValueError, match="NaN"):
        solve_tsvd(np.full((4, 2), np.nan), np.ones(4))
    with pytest.raises(ValueError, match="NaN"):
        solve_tsvd(np.eye(4, 2), np.array([1.0, np.inf, 0.0, 0.0]))
    with pytest.raises(ValueError, match="epsilon"):
        solve_tsvd(np.eye(3), np.ones(3), epsilon=0.0)
    with pytest.raises(ValueError):
        solve_tsvd(scipy.sparse.csr_array(np.ones((4, 2))), np.ones((3, 1)))


# ----------------------------------------------------------------------------------------------------------
# The blockwise QR: every block size, sparse or dense, gives what one SVD of the dense A gives.
# ----------------------------------------------------------------------------------------------------------

def _dense_reference(a: np.ndarray, b: np.ndarray, epsilon: float = FLT_EPSILON):
    """Truncated-SVD solution, rank, singular values and condition from ``numpy.linalg.svd`` of dense ``a``."""
    u, sv, vt = np.linalg.svd(a, full_matrices=False)
    rank = int(np.count_nonzero(sv > sv[0] * a.shape[1] * epsilon))
    b2 = b.reshape(len(b), -1)
    x = vt[:rank].T @ ((u[:, :rank].T @ b2) / sv[:rank, None])
    return x.reshape((a.shape[1],) + b.shape[1:]), rank, sv, sv[0] / sv[rank - 1]


def _assert_matches_reference(sol: TsvdSolution, a: np.ndarray, b: np.ndarray, rounding: float = 1e-12):
    """``sol`` is the dense reference's (its solution to ``rounding`` of its largest entry)."""
    x, rank, sv, condition = _dense_reference(a, b)
    assert sol.x.shape == x.shape
    assert sol.rank == rank and sol.n_unknowns == a.shape[1]
    np.testing.assert_allclose(sol.x, x, rtol=0, atol=rounding * np.abs(x).max())
    np.testing.assert_allclose(sol.singular_values, sv, rtol=1e-12, atol=1e-12 * sv[0])
    assert sol.condition == pytest.approx(condition, rel=1e-10)
    assert sol.cutoff == pytest.approx(sv[0] * a.shape[1] * FLT_EPSILON, rel=1e-12)


def _curve(n_poles: int, degree: int = 3) -> BSplineCurve:
    knots = np.r_[np.zeros(degree), np.linspace(0.0, 1.0, n_poles - degree + 1), np.ones(degree)]
    return BSplineCurve(np.zeros((n_poles, 3)), knots, degree)


def _surface(nu: int, nv: int, degree: int = 3) -> BSplineSurface:
    def knots(n):
        return np.r_[np.zeros(degree), np.linspace(0.0, 1.0, n - degree + 1), np.ones(degree)]
    return BSplineSurface(np.zeros((nu, nv, 3)), knots(nu), knots(nv), degree, degree)


# 211 rows (a prime: every block size below leaves a partial last block), 17 columns
_BLOCKS = [None, 1, 5, 16, 17, 64, 211, 500]
_FORMATS = ["dense", "csr", "csc", "coo"]


def _as_format(a: np.ndarray, fmt: str):
    return a if fmt == "dense" else scipy.sparse.csr_array(a).asformat(fmt)


@pytest.mark.parametrize("block_rows", _BLOCKS)
@pytest.mark.parametrize("fmt", _FORMATS)
@pytest.mark.parametrize("k", [None, 1, 3])
def test_blocks_match_dense_svd_on_a_random_tall_problem(block_rows, fmt, k):
    rng = np.random.default_rng(11)
    a = rng.normal(size=(211, 17))
    a[rng.random(a.shape) < 0.5] = 0.0                    # sparse rows of all widths, in no order
    a += np.eye(211, 17)
    b = rng.normal(size=211 if k is None else (211, k))
    sol = solve_tsvd(_as_format(a, fmt), b, block_rows=block_rows)
    assert sol.rank == 17 and not sol.rank_deficient
    _assert_matches_reference(sol, a, b)


@pytest.mark.parametrize("block_rows", [None, 1, 7, 13, 40, 1000])
@pytest.mark.parametrize("fmt", ["dense", "csr"])
@pytest.mark.parametrize("k", [None, 1, 3])
def test_blocks_match_dense_svd_on_a_curve_with_an_empty_stretch(block_rows, fmt, k):
    # cubic, 10 spans of 0.1: no data in [0.3, 0.7] leaves the basis function on exactly those four spans
    # without a row (a zero column) and its neighbours barely determined
    curve = _curve(13)
    rng = np.random.default_rng(12)
    t = rng.uniform(0.0, 1.0, 400)
    t = t[(t < 0.3) | (t > 0.7)]
    a = curve_basis(curve, t).toarray()
    b = np.column_stack([np.sin(3 * t), t ** 2, np.ones_like(t)])[:, :k or 1]
    b = b[:, 0] if k is None else b
    sol = solve_tsvd(_as_format(a, fmt), b, block_rows=block_rows)
    assert sol.rank_deficient
    _assert_matches_reference(sol, a, b)


@pytest.mark.heavy
@pytest.mark.parametrize("block_rows", [None, 3, 30, 97, 5000])
@pytest.mark.parametrize("fmt", ["dense", "csr", "coo"])
@pytest.mark.parametrize("k", [None, 3])
def test_blocks_match_dense_svd_on_a_surface_with_an_empty_patch(block_rows, fmt, k):
    # bicubic, 10 x 6 spans; no data in the patches [0.3, 0.7] x [1/3, 1]: rank-deficient (the poles whose
    # supports lie there are free), rows in random order
    surface = _surface(13, 9)
    rng = np.random.default_rng(13)
    uv = rng.uniform(0.0, 1.0, (3000, 2))
    uv = uv[~((uv[:, 0] > 0.3) & (uv[:, 0] < 0.7) & (uv[:, 1] > 1 / 3))]
    a = surface_basis(surface, uv[:, 0], uv[:, 1])
    b = np.column_stack([np.sin(2 * uv[:, 0]) * uv[:, 1], uv[:, 0] * uv[:, 1], np.cos(uv[:, 1])])
    b = b[:, 0] if k is None else b
    sol = solve_tsvd(a.toarray() if fmt == "dense" else a.asformat(fmt), b, block_rows=block_rows)
    assert sol.rank < 13 * 9
    _assert_matches_reference(sol, a.toarray(), b)


def test_blocks_skip_zero_rows():
    rng = np.random.default_rng(14)
    a = rng.normal(size=(60, 5))
    a[::3] = 0.0
    b = rng.normal(size=(60, 2))
    for A in (a, scipy.sparse.csr_array(a)):
        sol = solve_tsvd(A, b, block_rows=4)
        assert sol.cutoff == pytest.approx(sol.singular_values[0] * 5 * FLT_EPSILON)
        _assert_matches_reference(sol, a, b)


def test_repeated_and_unsorted_sparse_entries_are_summed():
    rng = np.random.default_rng(15)
    dense = rng.normal(size=(40, 6))
    rows, cols = np.nonzero(dense)
    # every entry stored as two halves, the halves of a row in reversed column order
    order = np.lexsort((-cols, rows))
    rows, cols, vals = rows[order], cols[order], dense[rows[order], cols[order]]
    indptr = np.r_[0, np.cumsum(2 * np.bincount(rows, minlength=40))]
    a = scipy.sparse.csr_array((np.repeat(vals / 2, 2), np.repeat(cols, 2), indptr), shape=(40, 6))
    assert not a.has_canonical_format
    b = rng.normal(size=(40, 3))
    data, indices = a.data.copy(), a.indices.copy()
    sol = solve_tsvd(a, b, block_rows=7)
    _assert_matches_reference(sol, dense, b)
    np.testing.assert_array_equal(a.data, data)            # the caller's matrix is left as it was
    np.testing.assert_array_equal(a.indices, indices)


@pytest.mark.parametrize("block_rows", [0, -3])
def test_block_rows_must_be_positive(block_rows):
    with pytest.raises(ValueError, match="block_rows"):
        solve_tsvd(np.eye(4, 2), np.ones(4), block_rows=block_rows)


def _weak_problem(seed: int = 0):
    """2000 rows, 40 unknowns, the last 5 columns a thousand times weaker (poles few nodes decide)."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(2000, 40))
    a[:, -5:] *= 1e-3
    return rng, a, rng.normal(size=(40, 3))


@pytest.mark.parametrize("sparse", [False, True])
def test_noise_is_smoothed_towards_the_prior_by_the_discrepancy_principle(sparse):
    """Noise of 0.05 on every entry: the plain fit throws the weak directions 2.6 off; smoothed towards a prior
    0.01 off, they stay within 0.02, and the residual is what the noise alone leaves (2000 x 3 x 0.05^2)."""
    rng, a, x_true = _weak_problem()
    b = a @ x_true + rng.normal(0.0, 0.05, (2000, 3))
    prior = x_true + rng.normal(0.0, 0.01, x_true.shape)
    matrix = scipy.sparse.csr_array(a) if sparse else a
    plain = solve_tsvd(matrix, b)
    smooth = solve_tsvd(matrix, b, prior=prior, noise=0.05)
    assert np.abs(plain.x - x_true).max() > 1.0
    assert np.abs(smooth.x - x_true).max() < 0.02
    assert 0 < smooth.smoothing < np.inf and plain.smoothing == 0.0
    assert np.sum((a @ smooth.x - b) ** 2) == pytest.approx(2000 * 3 * 0.05 ** 2, rel=1e-6)


def test_no_smoothing_where_the_fit_misses_by_more_than_the_noise():
    """A model error far above the stated noise: the plain fit is kept as it is, and the prior not asked for."""
    rng, a, x_true = _weak_problem(1)
    b = a @ x_true + rng.normal(0.0, 0.05, (2000, 3))

    def prior():
        raise AssertionError("the prior is not needed")

    plain = solve_tsvd(a, b)
    same = solve_tsvd(a, b, prior=prior, noise=0.001)
    assert same.smoothing == 0.0 and np.array_equal(same.x, plain.x)


def test_noise_beyond_everything_the_data_say_gives_the_prior():
    rng, a, x_true = _weak_problem(2)
    b = a @ x_true
    prior = np.zeros_like(x_true)
    sol = solve_tsvd(a, b, prior=prior, noise=1e6, noisy_rows=100)
    assert sol.smoothing == np.inf and np.array_equal(sol.x, prior)


# ----------------------------------------------------------------------------------------------------------
# Above full_svd_up_to unknowns a clearly full-rank tall problem is solved without the SVD.
# ----------------------------------------------------------------------------------------------------------

def _assert_matches_without_svd(sol: TsvdSolution, a: np.ndarray, b: np.ndarray, rounding: float = 1e-11):
    """``sol`` came from the triangular solve: the reference's solution (to ``rounding`` of its largest entry)
    and rank, its extreme singular values and condition to the Lanczos tolerance, and no spectrum."""
    x, rank, sv, condition = _dense_reference(a, b)
    assert sol.singular_values is None
    assert sol.rank == rank == a.shape[1]
    np.testing.assert_allclose(sol.x, x, rtol=0, atol=rounding * np.abs(x).max())
    assert sol.sigma_max == pytest.approx(sv[0], rel=1e-7)
    assert sol.sigma_min == pytest.approx(sv[-1], rel=1e-7)
    assert sol.condition == pytest.approx(condition, rel=1e-7)
    assert sol.cutoff == pytest.approx(sv[0] * a.shape[1] * FLT_EPSILON, rel=1e-7)


@pytest.mark.parametrize("fmt", ["dense", "csr"])
@pytest.mark.parametrize("k", [None, 3])
def test_full_rank_tall_problems_skip_the_svd(fmt, k):
    rng = np.random.default_rng(21)
    a = rng.normal(size=(211, 17))
    a[rng.random(a.shape) < 0.5] = 0.0
    a += np.eye(211, 17)
    b = rng.normal(size=211 if k is None else (211, k))
    _assert_matches_without_svd(solve_tsvd(_as_format(a, fmt), b, full_svd_up_to=0), a, b)


@pytest.mark.heavy
def test_a_spline_fit_above_the_threshold_skips_the_svd_by_default():
    # bicubic 30 x 20 poles (600 unknowns > FULL_SVD_UP_TO), 20 000 data points spread over the whole domain
    surface = _surface(30, 20)
    rng = np.random.default_rng(22)
    uv = rng.uniform(0.0, 1.0, (20_000, 2))
    a = surface_basis(surface, uv[:, 0], uv[:, 1])
    b = np.column_stack([np.sin(2 * uv[:, 0]) * uv[:, 1], uv[:, 0] * uv[:, 1], np.cos(uv[:, 1])])
    sol = solve_tsvd(a, b)
    _assert_matches_without_svd(sol, a.toarray(), b)
    with_svd = solve_tsvd(a, b, full_svd_up_to=10 ** 6)
    assert with_svd.singular_values is not None and with_svd.rank == sol.rank


@pytest.mark.parametrize("k", [None, 3])
def test_rank_deficient_tall_problems_still_take_the_svd(k):
    # the surface with an empty patch (zero columns: a zero on R's diagonal) and the curve with an empty
    # stretch (nearly zero columns): the SVD decides, whatever the threshold
    surface = _surface(13, 9)
    rng = np.random.default_rng(23)
    uv = rng.uniform(0.0, 1.0, (3000, 2))
    uv = uv[~((uv[:, 0] > 0.3) & (uv[:, 0] < 0.7) & (uv[:, 1] > 1 / 3))]
    a = surface_basis(surface, uv[:, 0], uv[:, 1]).toarray()
    b = rng.normal(size=len(uv) if k is None else (len(uv), k))
    sol = solve_tsvd(a, b, full_svd_up_to=0)
    assert sol.rank_deficient
    _assert_matches_reference(sol, a, b)


@pytest.mark.parametrize("ratio, svd", [(1.05, False), (1.005, True), (0.999, True)])
@pytest.mark.parametrize("n", [8, 40])                   # extremes computed, and by Lanczos
def test_near_the_cutoff_the_svd_decides(ratio, svd, n):
    # singular values 1 .. sigma_n with sigma_n = ratio * cutoff: clearly above the cut-off the triangular
    # solve, within FULL_RANK_MARGIN of it (or below) the SVD, which keeps or drops it exactly
    rng = np.random.default_rng(24)
    u = np.linalg.qr(rng.normal(size=(100, n)))[0]
    v = np.linalg.qr(rng.normal(size=(n, n)))[0]
    sigma = np.geomspace(1.0, ratio * n * FLT_EPSILON, n)
    a = (u * sigma) @ v.T
    b = rng.normal(size=(100, 2))
    sol = solve_tsvd(a, b, full_svd_up_to=0)
    assert (sol.singular_values is not None) == svd
    assert sol.rank == (n if ratio > 1 else n - 1)
    rounding = 1e-15 * sigma[0] / sigma[-1]            # condition 1e5 to 1e6: the rounding of either solution
    if svd:
        _assert_matches_reference(sol, a, b, rounding)
    else:
        _assert_matches_without_svd(sol, a, b, rounding)


@pytest.mark.parametrize("noise, smoothed", [(0.05, True), (0.001, False)])
def test_noise_smoothing_is_the_same_without_the_svd(noise, smoothed):
    """Where the noise asks for smoothing the SVD is taken; where it does not, the triangular solve gives the
    plain fit, as the SVD does."""
    rng, a, x_true = _weak_problem(3)
    a[:, -5:] *= 10.0                                  # weak (1e-2) but well above the cut-off
    b = a @ x_true + rng.normal(0.0, 0.05, (2000, 3))
    prior = x_true + rng.normal(0.0, 0.01, x_true.shape)
    fast = solve_tsvd(a, b, prior=prior, noise=noise, full_svd_up_to=0)
    svd = solve_tsvd(a, b, prior=prior, noise=noise)
    assert (svd.smoothing > 0.0) == smoothed and (fast.singular_values is None) == (not smoothed)
    assert fast.smoothing == svd.smoothing and fast.rank == svd.rank == 40
    np.testing.assert_allclose(fast.x, svd.x, rtol=0, atol=1e-10 * np.abs(svd.x).max())


@pytest.mark.parametrize("n", [1, 2, 3, 33, 60])
def test_the_fast_path_holds_for_any_number_of_unknowns(n):
    # a few unknowns (singular values computed) and more than _DENSE_EXTREMES (Lanczos)
    rng = np.random.default_rng(26 + n)
    a = rng.normal(size=(4 * n + 10, n))
    b = rng.normal(size=(4 * n + 10, 3))
    _assert_matches_without_svd(solve_tsvd(a, b, full_svd_up_to=0), a, b)


def test_full_svd_up_to_must_not_be_negative():
    with pytest.raises(ValueError, match="full_svd_up_to"):
        solve_tsvd(np.eye(3), np.ones(3), full_svd_up_to=-1)


# ----------------------------------------------------------------------------------------------------------
# Steering rows: in the least squares, not in the cut-off
# ----------------------------------------------------------------------------------------------------------

def _steered_problem(seed: int, rows: int = 300, n: int = 24, weak: float = 1e-5):
    """``rows`` data rows of ``n`` unknowns whose last column is ``weak`` (above the data's cut-off
    ``n FLT_EPSILON``, 2.9e-6 of ``sigma_1``), and 6 steering rows 1000 times heavier on the first columns."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(rows, n))
    a[rng.random(a.shape) < 0.6] = 0.0
    a += np.eye(rows, n)
    a[:, -1] *= weak
    e = np.zeros((6, n))
    e[:, :6] = 1e3 * rng.normal(size=(6, 6))
    return rng, a, rng.normal(size=(rows, 3)), e, rng.normal(size=(6, 3))


@pytest.mark.parametrize("fmt", ["dense", "csr"])
@pytest.mark.parametrize("full_svd_up_to", [0, 1000])
@pytest.mark.parametrize("rows", [300, 20, 10])     # tall, tall with the steering rows only, wide
def test_steering_rows_enter_the_fit_but_not_the_cutoff(fmt, full_svd_up_to, rows):
    _, a, b, e, f = _steered_problem(31, rows)
    n = a.shape[1]
    stacked, rhs = np.vstack([a, e]), np.vstack([b, f])
    sol = solve_tsvd(_as_format(a, fmt), b, steer=(_as_format(e, fmt), f), full_svd_up_to=full_svd_up_to)
    sigma_data = np.linalg.svd(a, compute_uv=False)[0]
    assert sol.cutoff == pytest.approx(sigma_data * n * FLT_EPSILON, rel=1e-7)
    # nothing the data determine is dropped: the least-squares solution of the stacked rows
    if rows > n:
        assert sol.rank == n
        np.testing.assert_allclose(sol.x, np.linalg.lstsq(stacked, rhs, rcond=None)[0], rtol=0,
                                   atol=1e-8 * np.abs(sol.x).max())
        assert (sol.singular_values is None) == (full_svd_up_to == 0)
    # the same rows as data raise sigma_1 a thousandfold, and the cut-off drops the weak column
    as_data = solve_tsvd(stacked, rhs, full_svd_up_to=full_svd_up_to)
    assert as_data.cutoff > 100 * sol.cutoff
    if rows > n:
        assert as_data.rank == n - 1


def test_steering_rows_alone_and_without_data():
    rng = np.random.default_rng(32)
    e, f = rng.normal(size=(40, 5)), rng.normal(size=40)
    sol = solve_tsvd(np.zeros((0, 5)), np.zeros(0), steer=(e, f))
    np.testing.assert_allclose(sol.x, np.linalg.lstsq(e, f, rcond=None)[0], rtol=0, atol=1e-12)
    assert sol.x.shape == (5,) and sol.rank == 5
    # an empty steer changes nothing
    a, b = rng.normal(size=(30, 5)), rng.normal(size=(30, 2))
    np.testing.assert_array_equal(solve_tsvd(a, b, steer=(np.zeros((0, 5)), np.zeros((0, 2)))).x, solve_tsvd(a, b).x)


def test_steering_rows_are_checked():
    a, b = np.eye(6, 4), np.ones((6, 2))
    with pytest.raises(ValueError, match=r"steer must be rows \(m, 4\) and right-hand sides \(m, 2\)"):
        solve_tsvd(a, b, steer=(np.ones((3, 5)), np.ones((3, 2))))
    with pytest.raises(ValueError, match=r"steer must be rows"):
        solve_tsvd(a, b, steer=(np.ones((3, 4)), np.ones((2, 2))))
    with pytest.raises(ValueError, match="NaN or inf"):
        solve_tsvd(a, b, steer=(np.ones((3, 4)), np.full((3, 2), np.nan)))
    with pytest.raises(ValueError, match="NaN or inf"):
        solve_tsvd(a, b, steer=(scipy.sparse.csr_array(np.full((3, 4), np.inf)), np.ones((3, 2))))


@pytest.mark.parametrize("fmt", ["dense", "csr"])
@pytest.mark.parametrize("k", [None, 3])
@pytest.mark.parametrize("full_svd_up_to", [0, 1000])
def test_reduced_rows_solve_as_the_rows_themselves(fmt, k, full_svd_up_to):
    """Rows reduced once (G1 turns a face again and again with other steering rows) give the solution of the
    rows themselves with each set of steering rows, the smoothing towards a prior included."""
    rng = np.random.default_rng(33)
    a = rng.normal(size=(300, 24))
    a[rng.random(a.shape) < 0.6] = 0.0
    a += np.eye(300, 24)
    a[:, -2:] *= 1e-3
    b = rng.normal(size=300 if k is None else (300, k))
    reduced = reduce_rows(_as_format(a, fmt), b)
    prior = rng.normal(size=(24,) if k is None else (24, k))
    for m in (0, 3, 8):
        e = rng.normal(size=(m, 24)) * 50.0
        f = rng.normal(size=m if k is None else (m, k))
        for noise in (0.0, 0.5):
            steer = (_as_format(e, fmt), f)
            direct = solve_tsvd(_as_format(a, fmt), b, prior=prior, noise=noise, steer=steer,
                                full_svd_up_to=full_svd_up_to)
            again = solve_tsvd(reduced, None, prior=prior, noise=noise, steer=steer, full_svd_up_to=full_svd_up_to)
            assert again.x.shape == direct.x.shape and again.rank == direct.rank
            assert again.cutoff == pytest.approx(direct.cutoff, rel=1e-12)
            assert again.smoothing == pytest.approx(direct.smoothing, rel=1e-9)
            np.testing.assert_allclose(again.x, direct.x, rtol=0, atol=1e-10 * np.abs(direct.x).max())
    assert reduced.factor.shape == (24, 24 + (1 if k is None else k))      # never changed by the solves
    np.testing.assert_array_equal(reduced.factor, reduce_rows(_as_format(a, fmt), b).factor)


@pytest.mark.parametrize("k", [None, 3])
def test_reduced_rows_of_one_unknown_solve_alike_again(k):
    """A face with one free pole: its reduced rows' factor is one row, whose ``R`` is a single column (already
    in Fortran order); solving them must not let the SVD overwrite it, so the second solve, and the third, give
    the first one's solution and the factor stays the rows' own."""
    rng = np.random.default_rng(5)
    a = rng.normal(size=(20, 1))
    b = rng.normal(size=20 if k is None else (20, k))
    reduced = reduce_rows(a, b)
    first = solve_tsvd(reduced, None)
    for _ in range(2):
        again = solve_tsvd(reduced, None)
        np.testing.assert_array_equal(again.x, first.x)
    np.testing.assert_array_equal(reduced.factor, reduce_rows(a, b).factor)
    direct = solve_tsvd(a, b)
    np.testing.assert_allclose(first.x, direct.x, rtol=1e-12, atol=0)


def test_reduced_rows_are_checked():
    with pytest.raises(ValueError, match="tall problems"):
        reduce_rows(np.ones((4, 6)), np.ones(4))
    with pytest.raises(ValueError, match="B needs 8 rows"):
        reduce_rows(np.ones((8, 3)), np.ones(7))
    with pytest.raises(ValueError, match="pass None"):
        solve_tsvd(reduce_rows(np.eye(8, 3), np.ones(8)), np.ones(8))
