"""Truncated-SVD least squares (hot2cold.lstsq, paper eq. 19-20)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse

from hot2cold.lstsq import TsvdSolution, solve_tsvd
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
    assert sol.cutoff == pytest.approx(sv[0] * shape[0] * FLT_EPSILON, rel=1e-12)
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


def test_cutoff_scales_with_rows_and_epsilon():
    sv = np.array([1.0, 1e-3, 2e-6, 1e-9])
    s = 10
    a = np.zeros((s, 4))
    a[:4, :4] = np.diag(sv)
    b = np.ones(s)
    sol = solve_tsvd(a, b)  # cut-off 1 * 10 * 1.19e-7 = 1.19e-6: keeps 1, 1e-3, 2e-6
    assert sol.cutoff == pytest.approx(10 * FLT_EPSILON)
    assert sol.rank == 3
    np.testing.assert_allclose(sol.x, [1.0, 1e3, 5e5, 0.0], rtol=1e-12)
    assert sol.condition == pytest.approx(5e5)
    assert sol.sigma_min == pytest.approx(1e-9) and sol.sigma_max == pytest.approx(1.0)
    assert solve_tsvd(a, b, epsilon=1e-6).rank == 2


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
