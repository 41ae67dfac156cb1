"""Least squares by truncated singular value decomposition (GT2014-26683, eq. 19-20).

The morph's fits (edge control points, face interiors, G1 rows) are linear least-squares problems
``A x = B`` with a B-spline design matrix ``A`` (s, n) whose rank depends on how the FE nodes fall into the
knot spans: a span without nodes leaves control points undetermined.  The paper therefore solves them by
truncated SVD rather than by the normal equations (which square the condition number) or a plain QR (which
needs full rank):

    A = U Sigma V^T,   keep sigma_i > eps = sigma_1 * n * epsilon,   x = V_r Sigma_r^-1 U_r^T B.

The paper writes ``(s - 1)``, its number of rows, where this has ``n``, the number of unknowns: with the rows
the cut-off grows with the node count and drops combinations of poles the nodes determine (the bundled Rotor
37 CalculiX field resampled onto 1 M nodes: ranks 316 of 392 and 303 of 378 on the aerofoil faces, all kept
at 10 k; ``benchmarks/scale.py``).  With the unknowns the rank decision depends on the spline space, not on
how densely the field samples it: for a design sampled evenly, ``sigma_i / sigma_1`` does not change with
``s``.  The result is the minimum-norm least-squares solution of the problem with the small singular values removed:
undetermined combinations of unknowns are set to zero instead of blowing up.  Given a ``prior`` (a guess of
``x``), they keep the prior's value instead: the morph passes the field's local estimate at the poles, so that
a pole the nodes do not determine moves with the field around it rather than staying put.

A face may receive several hundred thousand FE nodes, so a tall ``A`` is never held densely: its rows are
reduced block by block to the triangular factor of a QR decomposition (:func:`solve_tsvd`), and only that
``(n, n)`` factor is decomposed by SVD.  Above :data:`FULL_SVD_UP_TO` unknowns even that SVD (``O(n^3)``,
the largest cost of a refined face's fit) is taken only where it is needed: the largest and smallest singular
values of the factor are found first by Lanczos iteration (:func:`_extremes`, ``O(n w)`` a step for a band of
``w`` diagonals), and where the smallest is clearly above the cut-off nothing is dropped and the solution is the
triangular solve ``R x = Q^T B``, the same least-squares solution.
"""
from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg
import scipy.linalg.lapack
import scipy.sparse
import scipy.sparse.linalg

from ..settings import FLT_EPSILON

log = logging.getLogger(__name__)

#: Default size (bytes) of the dense row block reduced at a time by :func:`solve_tsvd`.
BLOCK_BYTES = 16 * 2 ** 20
#: Rows per block are about this many times the block's column count (when the byte budget allows):
#: the triangular factor stacked on top of every block costs ``1 / ROWS_PER_COLUMN`` extra work.
ROWS_PER_COLUMN = 4
#: Fewest rows per block by default (a block of very short rows would make the loop over blocks dominate).
MIN_BLOCK_ROWS = 1024
#: Unknowns up to which the triangular factor is always decomposed by a full SVD; above, only where the
#: extreme singular values (:func:`_extremes`) show that the cut-off drops some or that the noise smoothing
#: needs the spectrum.
FULL_SVD_UP_TO = 400
#: Relative accuracy of the Lanczos estimates of the extreme singular values.
LANCZOS_TOL = 1e-8
#: A tall problem is taken as full rank without its SVD where the smallest singular value exceeds the cut-off by
#: this factor (a margin far above the estimates' error): nearer the cut-off the SVD decides.
FULL_RANK_MARGIN = 1.01
#: Up to this many unknowns :func:`_extremes` takes all singular values (ARPACK needs more than k + 1 unknowns).
_DENSE_EXTREMES = 32


@dataclass(frozen=True, eq=False)
class TsvdSolution:
    """The result of :func:`solve_tsvd`.

    Attributes
    ----------
    x : (n, k) float array (``(n,)`` when the right-hand side was ``(s,)``), the solution.
    rank : int, number of singular values kept (``> cutoff``).
    n_unknowns : int, ``n``, the number of columns of ``A``; ``rank < n_unknowns`` means some combinations
        of unknowns were undetermined and set to zero (minimum norm).
    condition : float, ``sigma_1 / sigma_rank`` over the kept singular values, i.e. the condition number of
        the truncated problem; NaN when nothing was kept (``rank == 0``).
    sigma_max, sigma_min : float, largest and smallest of all ``min(s, n)`` singular values, kept or not
        (``sigma_max / sigma_min`` is the condition number of ``A`` itself); 0.0 for an empty ``A``.
    cutoff : float, the threshold ``sigma_1 * n * epsilon``.
    singular_values : (min(s, n),) float array, all singular values of ``A`` sorted from largest to smallest;
        None where the full SVD was not taken (a tall, full-rank problem of more than ``full_svd_up_to``
        unknowns, :func:`solve_tsvd`), whose extremes are ``sigma_max`` and ``sigma_min``.
    smoothing : float, the Tikhonov parameter ``lambda`` the data's noise chose (0: none; inf: the prior in
        every direction), see :func:`solve_tsvd`'s ``noise``.
    """

    x: np.ndarray
    rank: int
    n_unknowns: int
    condition: float
    sigma_max: float
    sigma_min: float
    cutoff: float
    singular_values: np.ndarray | None
    smoothing: float = 0.0

    @property
    def rank_deficient(self) -> bool:
        """True if singular values were dropped (``rank < n_unknowns``)."""
        return self.rank < self.n_unknowns


def _svd(a: np.ndarray, overwrite: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin SVD; falls back from the divide-and-conquer driver to ``gesvd`` if the former fails.  With
    ``overwrite`` the SVD may destroy ``a`` (no copy of it beside the SVD's workspace), and a failure of the
    first driver raises LinAlgError, as ``a`` is gone."""
    try:
        return scipy.linalg.svd(a, full_matrices=False, check_finite=False, lapack_driver="gesdd",
                                overwrite_a=overwrite)
    except np.linalg.LinAlgError:
        if overwrite:
            raise
        return scipy.linalg.svd(a, full_matrices=False, check_finite=False, lapack_driver="gesvd")


class _Rows:
    """Row access to ``A`` (s, n), dense or CSR: the column extent of every row and dense blocks of rows.

    ``first`` and ``last`` (s,) int are the first and last column holding a stored entry (sparse) or a
    non-zero (dense) of each row; ``empty`` (s,) bool marks rows without any, for which both are 0.
    """

    def __init__(self, A, n: int, chunk_bytes: int):
        if scipy.sparse.issparse(A):
            csr = scipy.sparse.csr_array(A)  # no copy of a CSR input; its indices may be unsorted or repeated
            self.dense = None
            self.indptr = csr.indptr.astype(np.int64, copy=False)
            self.indices = csr.indices
            self.data = np.asarray(csr.data, dtype=float)
            if not np.all(np.isfinite(self.data)):
                raise ValueError(f"A {csr.shape} holds NaN or inf")
            counts = np.diff(self.indptr)
            self.empty = counts == 0
            self.first = np.zeros(len(counts), np.int64)
            self.last = np.zeros(len(counts), np.int64)
            full = ~self.empty
            if full.any():
                starts = self.indptr[:-1][full]
                self.first[full] = np.minimum.reduceat(self.indices, starts)
                self.last[full] = np.maximum.reduceat(self.indices, starts)
        else:
            a = np.asarray(A)
            self.dense = a
            s = a.shape[0]
            self.first = np.zeros(s, np.int64)
            self.last = np.zeros(s, np.int64)
            self.empty = np.zeros(s, bool)
            step = max(1, chunk_bytes // max(8 * n, 1))
            for i in range(0, s, step):  # chunked, so that the temporaries stay within the block budget
                block = np.asarray(a[i:i + step], dtype=float)
                if not np.all(np.isfinite(block)):
                    raise ValueError(f"A {a.shape} holds NaN or inf")
                nz = block != 0
                self.empty[i:i + step] = ~nz.any(axis=1)
                self.first[i:i + step] = np.argmax(nz, axis=1)
                self.last[i:i + step] = n - 1 - np.argmax(nz[:, ::-1], axis=1)

    def block(self, rows: np.ndarray, lo: int, width: int, out: np.ndarray) -> None:
        """Write columns ``lo .. lo + width - 1`` of ``rows`` (m,) into ``out`` (m, width) (repeated sparse
        entries summed); every stored entry of those rows must lie in these columns."""
        if self.dense is not None:
            out[:] = self.dense[rows, lo:lo + width]
            return
        begin, end = self.indptr[rows], self.indptr[rows + 1]
        counts = end - begin
        offsets = np.cumsum(counts) - counts
        where = np.repeat(begin - offsets, counts) + np.arange(int(counts.sum()))
        flat = np.repeat(np.arange(len(rows)) * width, counts) + (self.indices[where] - lo)
        out[:] = np.bincount(flat, weights=self.data[where], minlength=len(rows) * width).reshape(len(rows), width)


def _triangular_factor(rows: _Rows, b: np.ndarray, n: int, block_rows: int | None,
                       block_bytes: int, start: np.ndarray | None = None) -> np.ndarray:
    """``[R | C]`` (n, n + k) with ``R`` upper triangular and ``Q^T [A | B] = [R | C; 0 | D]`` for some
    orthogonal ``Q``: the QR factor of the augmented matrix, computed block by block.  With ``start`` (an
    earlier ``[R0 | C0]`` (n, n + k)), the factor of ``[R0 | C0; A | B]``: the rows of ``A`` added to a problem
    already reduced (``start`` is updated in place and returned).

    Rows of ``A`` are taken in the order of their first column, ``block_rows`` at a time (default: sized from
    ``block_bytes``).  A block whose rows hold entries only in columns ``lo .. hi`` changes only the rows and
    columns ``lo .. hi`` of ``R`` (and the rows ``lo .. hi`` of ``C``) as long as no earlier row reaches beyond
    ``hi`` from there: the QR of the stacked ``[R[lo:hi+1, lo:hi+1], C[lo:hi+1]; A_block, B_block]`` then
    updates them (Householder reflections of the columns before ``lo`` are the identity, since ``R`` is
    triangular and the block is zero there).  For a B-spline design matrix a row's entries span a band
    (``p nv + q + 1`` columns for a surface with its poles numbered ``i nv + j``), so each block costs
    ``O(m w^2)`` with ``w`` about that band rather than ``n``; a dense matrix has ``w = n``.  The rows below
    ``n`` of the QR factor (the residual) are dropped as they come: they do not enter ``R`` or ``C``.
    """
    k = b.shape[1]
    if start is None:
        rc = np.zeros((n, n + k))
        reach = np.full(n, -1, np.int64)   # reach[i]: last column of a stored entry in row i of R (-1: none)
    else:
        rc = start
        nonzero = rc[:, :n] != 0
        reach = np.where(nonzero.any(axis=1), n - 1 - np.argmax(nonzero[:, ::-1], axis=1), -1)
    keep = np.flatnonzero(~rows.empty)      # rows of zeros move only the residual
    order = keep[np.argsort(rows.first[keep], kind="stable")]
    first, last = rows.first[order], rows.last[order]
    if block_rows is None:
        width = int(np.median(last - first)) + 1 if len(order) else 1
        block_rows = max(MIN_BLOCK_ROWS, ROWS_PER_COLUMN * (width + k))
        block_rows = max(1, min(block_rows, block_bytes // (8 * (width + k))))
    blocks, widest = 0, 0
    for i in range(0, len(order), block_rows):
        j = min(i + block_rows, len(order))
        lo = int(first[i])
        hi = max(int(last[i:j].max()), int(reach[lo:].max()))
        w = hi - lo + 1
        window = np.zeros((w + j - i, w + k), order="F")
        window[:w, :w] = rc[lo:hi + 1, lo:hi + 1]
        window[:w, w:] = rc[lo:hi + 1, n:]
        rows.block(order[i:j], lo, w, window[w:, :w])
        window[w:, w:] = b[order[i:j]]
        (_, _), r = scipy.linalg.qr(window, mode="raw", overwrite_a=True, check_finite=False)
        rc[lo:hi + 1, lo:hi + 1] = r[:w, :w]
        rc[lo:hi + 1, n:] = r[:w, w:]
        reach[lo:hi + 1] = hi
        blocks, widest = blocks + 1, max(widest, w)
    log.debug("blockwise QR of %d rows x %d columns: %d blocks of %d rows, widest %d columns",
              len(rows.first), n, blocks, block_rows, widest)
    return rc


@dataclass(frozen=True, eq=False)
class ReducedRows:
    """The rows of a tall problem ``A x = B`` reduced once (:func:`reduce_rows`), to be solved by
    :func:`solve_tsvd` with other steering rows each time (G1's turning rows, G2's bending rows) without
    reading ``A`` again.

    Attributes
    ----------
    factor : (n, n + k) float array, ``[R | C]``, the QR factor of ``[A | B]`` (:func:`_triangular_factor`).
    shape : ``(s, n)``, the shape of ``A``.
    square_sum : float, ``||B||^2``.
    vector : bool, ``B`` was ``(s,)`` (the solution is then ``(n,)``).
    """

    factor: np.ndarray
    shape: tuple[int, int]
    square_sum: float
    vector: bool


def _checked_problem(A, B) -> tuple:
    """``A`` (2-D, dense as an array or sparse) and ``B`` (a float array) of :func:`solve_tsvd`, checked."""
    if scipy.sparse.issparse(A):
        if A.ndim != 2:
            raise ValueError(f"A must be a 2-D (s, n) matrix, got shape {A.shape}")
    else:
        A = np.asarray(A)
        if A.ndim != 2:
            raise ValueError(f"A must be a 2-D (s, n) matrix, got shape {A.shape}")
    b = np.asarray(B, dtype=float)
    if b.ndim not in (1, 2):
        raise ValueError(f"B must be (s,) or (s, k), got shape {b.shape}")
    if b.shape[0] != A.shape[0]:
        raise ValueError(f"A is {A.shape} but B is {b.shape}: B needs {A.shape[0]} rows, one per row of A")
    if not np.all(np.isfinite(b)):
        raise ValueError(f"B {b.shape} holds NaN or inf")
    return A, b


def reduce_rows(A, B, block_rows: int | None = None, block_bytes: int = BLOCK_BYTES) -> ReducedRows:
    """The tall problem ``A x = B`` (``A`` (s, n) with ``s > n``, dense or sparse; ``B`` (s, k) or (s,)) reduced
    to its QR factor, as :func:`solve_tsvd` reduces it (block by block, ``O(n^2)`` memory), for
    :func:`solve_tsvd` to solve as often as asked, each time with other ``steer`` rows: the same solution as
    ``solve_tsvd(A, B, steer=...)`` (to rounding) at the cost of the steering rows alone."""
    A, b = _checked_problem(A, B)
    s, n = A.shape
    if s <= n:
        raise ValueError(f"reduce_rows takes tall problems (more rows than unknowns), got A {A.shape}")
    b2 = b.reshape(s, -1)
    factor = _triangular_factor(_Rows(A, n, block_bytes), b2, n, block_rows, block_bytes)
    return ReducedRows(factor, (s, n), float(np.sum(b2 * b2)), b.ndim == 1)


def solve_tsvd(A, B, epsilon: float = FLT_EPSILON, *, prior=None, noise: float = 0.0,  # noqa: PLR0913
               noisy_rows: int | None = None, steer: tuple | None = None, block_rows: int | None = None,
               block_bytes: int = BLOCK_BYTES, full_svd_up_to: int = FULL_SVD_UP_TO) -> TsvdSolution:
    """Solve ``min ||A x - B||`` by truncated SVD (eq. 19-20).

    The keyword options are the solver's public interface, which the fits across the package set, so it takes
    more than six parameters; the steps are the helpers named under Method.

    Parameters
    ----------
    A : (s, n) dense array or ``scipy.sparse`` matrix/array, the design matrix (s observations, n unknowns);
        or a :class:`ReducedRows` of a tall problem (:func:`reduce_rows`), with ``B`` None.
        A tall ``A`` is read a block of rows at a time (a sparse one densified block by block), so ``s`` may
        be in the millions: memory is ``O(n^2)`` plus one block and a few integers per row (no copy of a CSR
        ``A``; other sparse formats are converted to CSR once).
    B : (s, k) or (s,) array, right-hand side(s); the k columns (e.g. x, y, z) share one factorisation; None
        with :class:`ReducedRows`.
    epsilon : float > 0, the machine-precision factor of the cut-off ``sigma_1 * n * epsilon``; default the
        paper's FLT_EPSILON (single precision, about 1.2e-7).
    prior : (n, k) or (n,) array, or a callable returning one, or None: a guess of ``x`` that the dropped
        directions keep: the solution is the truncated minimum-norm solution plus the prior's component in
        the dropped directions, ``x = V_r Sigma_r^-1 U_r^T B + (I - V_r V_r^T) prior``.  Where nothing is
        dropped the prior changes nothing (and a callable is not called: a prior that costs a solve of its own
        is paid for only where it is used); where directions are dropped they take the prior's value instead
        of zero.  None: zero, the paper's minimum-norm solution.
    noise : float >= 0, the standard deviation of the noise on each entry of ``B`` (rows of weight 1), e.g.
        the scatter of an FE field about a smooth one.  With a prior, the kept directions are then smoothed
        towards it (Tikhonov, filter factors ``sigma_i^2 / (sigma_i^2 + lambda^2)``), ``lambda`` chosen by
        the discrepancy principle: the residual ``||A x - B||^2`` becomes ``noisy_rows * k * noise^2``, what
        the noise alone leaves, where the plain fit's residual is below that (it fits noise); where it is
        above (the fit misses the data by more than their noise), nothing is smoothed.  The fit then follows
        the signal and leaves the noise, above all in directions the data barely determine (poles with few
        nodes), where a plain fit amplifies it.  0: no smoothing.
    noisy_rows : int or None, the rows that carry the noise (default all ``s``).
    steer : ``(E, F)`` or None: rows ``E`` (m, n) (dense or sparse) with right-hand sides ``F`` (m, k) or
        (m,) added to the problem, ``min ||A x - B||^2 + ||E x - F||^2``, that steer the fit (G1's rows that turn
        a face's tangents, G2's that bend it) without moving the cut-off: it stays ``sigma_1(A) n epsilon``,
        the data's own.  Added rows only raise every singular value (``A^T A + E^T E`` is no smaller than
        ``A^T A``), so a direction the data determine stays kept, however heavily the steering rows weigh; as
        part of ``A`` they would raise ``sigma_1`` and drop what the data determine (Rotor 37 at 1 M nodes:
        turning rows raised it from 37 to 2071, and 1022 of 4752 directions fell to the prior).
    block_rows : int > 0 or None, rows of ``A`` reduced at a time; None: ``ROWS_PER_COLUMN`` times the
        columns of a typical row (first to last entry) plus k, at least ``MIN_BLOCK_ROWS``, at most what fits
        ``block_bytes``.  It changes the rounding, not the result.
    block_bytes : int, memory budget of one dense block when ``block_rows`` is None.
    full_svd_up_to : int >= 0, unknowns up to which a tall problem's triangular factor is always decomposed by a
        full SVD; above, the SVD is skipped where the problem is clearly full rank and needs no smoothing (see
        Method).  It changes the rounding, not the result.

    Returns
    -------
    TsvdSolution with ``x`` of shape (n, k), or (n,) if ``B`` was (s,).

    Method
    ------
    ``A^T A`` and its inverse are never formed.  For a tall ``A`` (s > n) the QR factor of the augmented
    matrix ``[A | B] = Q [R | C; 0 | D]`` (R (n, n) upper triangular, ``C = Q^T B`` in its first n rows) is
    built block by block of rows (:func:`_triangular_factor`), without ever holding Q or all of ``A``, and
    then the SVD of the small ``R = U_R Sigma V^T`` is taken: since Q is orthogonal, ``A = (Q U_R) Sigma V^T``
    is an SVD of A with the same singular values, at the cost of an SVD of an n x n instead of an s x n
    matrix; ``U^T B = U_R^T C`` (:func:`_tall_spectrum`).  For a square or wide ``A`` the SVD is taken
    directly (:func:`_wide_spectrum`).  Singular values ``sigma_i <= cutoff`` are dropped
    (:func:`_truncated_solution`; with ``steer``, the rows ``E`` are reduced into the factor after those of
    ``A``, the cut-off taken from ``A``'s, :func:`_sigma_max`).  With more than ``full_svd_up_to`` unknowns,
    ``sigma_1`` and ``sigma_n`` of ``R`` are estimated first (:func:`_extremes`); where
    ``sigma_n > FULL_RANK_MARGIN * cutoff`` nothing is dropped, and unless the noise asks for smoothing (the
    plain fit's residual ``||B||^2 - ||C||^2`` below its target) ``x = R^-1 C``, the solution the SVD would
    give, by back substitution (:func:`_full_rank`).

    Edge cases: ``n == 0`` gives an empty ``x`` (0, k); ``s == 0`` (no observations) gives ``x = 0`` with
    ``rank == 0``.  An all-zero ``A`` gives ``x = 0``, ``rank == 0``.
    """
    options = _checked_options(epsilon, block_rows, block_bytes, full_svd_up_to)
    problem = _checked_inputs(A, B, prior, steer)
    if problem.empty:
        return _empty_solution(problem, prior)
    target = _noise_target(problem, noise, noisy_rows, prior)
    spectrum = _tall_spectrum(problem, options, target) if problem.tall else _wide_spectrum(problem)
    if isinstance(spectrum, TsvdSolution):           # clearly of full rank: solved without the SVD (_full_rank)
        return replace(spectrum, x=problem.shaped(spectrum.x))
    return _truncated_solution(problem, spectrum, options.epsilon, target, prior)


@dataclass(frozen=True, eq=False)
class _Options:
    """The numerical options of :func:`solve_tsvd`, checked (:func:`_checked_options`).

    Attributes
    ----------
    epsilon : float > 0, the machine-precision factor of the cut-off ``sigma_1 * n * epsilon`` (eq. 20), as
        given.
    block_rows : int > 0 or None, rows of ``A`` reduced at a time (:func:`_triangular_factor`).
    block_bytes : int, memory budget of one dense block (of rows, and of ``A``'s check for NaN and inf).
    full_svd_up_to : int >= 0, unknowns up to which a tall problem's triangular factor is always decomposed by
        a full SVD (:func:`_full_rank` above).
    """

    epsilon: float
    block_rows: int | None
    block_bytes: int
    full_svd_up_to: int


def _checked_options(epsilon: float, block_rows: int | None, block_bytes: int, full_svd_up_to: int) -> _Options:
    """:func:`solve_tsvd`'s ``epsilon``, ``block_rows``, ``block_bytes`` and ``full_svd_up_to`` as
    :class:`_Options`, or ValueError."""
    if not (np.isfinite(epsilon) and epsilon > 0):
        raise ValueError(f"epsilon must be positive and finite, got {epsilon!r}")
    if block_rows is not None and block_rows < 1:
        raise ValueError(f"block_rows must be a positive number of rows, got {block_rows!r}")
    if full_svd_up_to < 0:
        raise ValueError(f"full_svd_up_to must be a number of unknowns >= 0, got {full_svd_up_to!r}")
    return _Options(epsilon, block_rows, block_bytes, full_svd_up_to)


@dataclass(frozen=True, eq=False)
class _Problem:
    """The problem ``min ||A x - B||^2 + ||E x - F||^2`` of :func:`solve_tsvd`, checked and with its right-hand
    sides as columns (:func:`_checked_inputs`).

    Attributes
    ----------
    a : ``A`` (s, n), a dense array or ``scipy.sparse`` matrix/array (its entries are checked for NaN and inf
        where they are read), or the :class:`ReducedRows` of a tall problem.
    b : (s, k) float array, ``B``; None with :class:`ReducedRows` (which hold it in their factor).
    shape : ``(s, n)``, the shape of ``A``.
    b_shape : ``(s,)`` or ``(s, k)``, the shape of ``B`` as given (that of the prior and of ``x`` follow it).
    extra : (m, n) float array or CSR array, the steering rows ``E``; no rows without ``steer``.
    f : (m, k) float array, their right-hand sides ``F``.
    """

    a: object
    b: np.ndarray | None
    shape: tuple[int, int]
    b_shape: tuple[int, ...]
    extra: object
    f: np.ndarray

    @property
    def n(self) -> int:
        """The number of unknowns."""
        return self.shape[1]

    @property
    def vector(self) -> bool:
        """``B`` was ``(s,)``: so is ``x``, ``(n,)``."""
        return len(self.b_shape) == 1

    @property
    def k(self) -> int:
        """The number of right-hand sides."""
        return 1 if self.vector else self.b_shape[1]

    @property
    def reduced(self) -> ReducedRows | None:
        """``A`` as :class:`ReducedRows`, or None."""
        return self.a if isinstance(self.a, ReducedRows) else None

    @property
    def empty(self) -> bool:
        """No rows (of data or steering) or no unknowns: nothing to decompose."""
        return self.shape[0] + self.extra.shape[0] == 0 or self.n == 0

    @property
    def tall(self) -> bool:
        """More rows than unknowns (always so for :class:`ReducedRows`): reduced to the triangular factor."""
        return self.reduced is not None or self.shape[0] + self.extra.shape[0] > self.n

    def shaped(self, x: np.ndarray) -> np.ndarray:
        """A solution ``x`` (n, k) in the shape ``B`` had: ``(n,)`` for ``B`` (s,)."""
        return x[:, 0] if self.vector else x

    def prior(self, prior) -> np.ndarray:
        """``prior`` (an array, or a callable called here) checked, of shape ``(n,) + b_shape[1:]``."""
        return _checked_prior(prior, self.shape, self.b_shape)


def _checked_inputs(A, B, prior, steer) -> _Problem:
    """:func:`solve_tsvd`'s ``A``, ``B`` (or :class:`ReducedRows` and None), an array ``prior`` and ``steer``
    checked, as a :class:`_Problem`; or ValueError.  A callable prior is checked where it is called."""
    reduced = A if isinstance(A, ReducedRows) else None
    if reduced is not None:
        if B is not None:
            raise ValueError("B comes with the reduced rows: pass None")
        (s, n), k = reduced.shape, reduced.factor.shape[1] - reduced.shape[1]
        b_shape = (s,) if reduced.vector else (s, k)
    else:
        A, b = _checked_problem(A, B)
        (s, n), b_shape = A.shape, b.shape
    if prior is not None and not callable(prior):
        _checked_prior(prior, (s, n), b_shape)
    k = 1 if len(b_shape) == 1 else b_shape[1]
    b2 = None if reduced is not None else b.reshape(s, k)
    extra, f = _checked_steer(steer, n, k)
    return _Problem(A, b2, (s, n), b_shape, extra, f)


def _empty_solution(problem: _Problem, prior) -> TsvdSolution:
    """The solution of a problem without rows or unknowns (:attr:`_Problem.empty`): ``x`` (n, k) the prior
    where one is given, else 0, with ``rank == 0``."""
    n, k = problem.n, problem.k
    x = np.zeros((n, k))
    if prior is not None and n:
        x = problem.prior(prior).reshape(n, k).copy()
    return TsvdSolution(x=problem.shaped(x), rank=0, n_unknowns=n, condition=float("nan"),
                        sigma_max=0.0, sigma_min=0.0, cutoff=0.0, singular_values=np.zeros(0))


def _noise_target(problem: _Problem, noise: float, noisy_rows: int | None, prior) -> float | None:
    """The residual ``||A x - B||^2`` the noise alone leaves, ``noisy_rows * k * noise^2`` (``noisy_rows``
    default s), which the smoothing towards the prior aims at (:func:`_smoothed`); None where no smoothing is
    asked for (no noise, or no prior)."""
    smoothing = noise > 0 and prior is not None
    target = (problem.shape[0] if noisy_rows is None else noisy_rows) * problem.k * float(noise) ** 2
    return target if smoothing else None


@dataclass(frozen=True, eq=False)
class _Factor:
    """A tall problem reduced to its triangular factor (:func:`_triangular_factor`), as :func:`_full_rank`
    takes it.

    Attributes
    ----------
    r : (n, n) float array, ``R``, upper triangular.
    c : (n, k) float array, ``C``, the first n rows of ``Q^T [B; F]``.
    total : float, ``||B||^2 + ||F||^2``, the right-hand side's square sum.
    scale : float or None, ``sigma_1`` of the data's own ``A`` where steering rows were added (the scale of the
        cut-off), else None (``R``'s own).
    """

    r: np.ndarray
    c: np.ndarray
    total: float
    scale: float | None


@dataclass(frozen=True, eq=False)
class _Spectrum:
    """The SVD ``[A; E] = U Sigma V^T`` of a problem, as far as the truncated solution needs it (eq. 19-20):
    ``p = min(s + m, n)`` singular triplets, ``U`` only as ``U^T [B; F]``.

    Attributes
    ----------
    sigma : (p,) float array, the singular values, from largest to smallest.
    vt : (p, n) float array, ``V^T``, the right singular vectors as rows.
    utb : (p, k) float array, ``U^T [B; F]``.
    total : float, ``||B||^2 + ||F||^2``, the right-hand side's square sum.
    scale : float or None, ``sigma_1`` of the data's own ``A`` where steering rows were added (the scale of the
        cut-off), else None (``sigma[0]``).
    """

    sigma: np.ndarray
    vt: np.ndarray
    utb: np.ndarray
    total: float
    scale: float | None

    def cut(self, n: int, epsilon: float) -> tuple[float, int]:
        """``(cutoff, rank)``: the cut-off ``sigma_1 * n * epsilon`` (eq. 20; ``sigma_1`` the scale where
        steering rows were added) and the number of singular values above it, the first ``rank``."""
        cutoff = float(self.sigma[0] if self.scale is None else self.scale) * n * float(epsilon)
        keep = self.sigma > cutoff
        return cutoff, int(np.count_nonzero(keep))  # sigma is descending, so the kept ones are the first `rank`


def _tall_spectrum(problem: _Problem, options: _Options, target: float | None) -> _Spectrum | TsvdSolution:
    """The SVD of a tall problem (:attr:`_Problem.tall`) by way of its triangular factor ``[R | C]``
    (:func:`_factorization`): ``R = U_R Sigma V^T`` (n, n), ``U^T B = U_R^T C``.  Above
    ``options.full_svd_up_to`` unknowns, the solution itself (``x`` (n, k)) where :func:`_full_rank` finds the
    problem clearly of full rank and ``target`` (:func:`_noise_target`) asks for no smoothing."""
    n = problem.n
    factor, total = _factorization(problem, options)
    rc, scale = factor()
    total += float(np.sum(problem.f * problem.f))
    if n > options.full_svd_up_to:
        fast = _full_rank(_Factor(rc[:, :n], rc[:, n:], total, scale), options.epsilon, target)
        if fast is not None:
            return fast
    # R alone, in the layout LAPACK takes, and overwritten: the SVD's workspace is about 4 n^2 beside its
    # factors, and a copy of R and the augmented factor beside it would add 2 n^2 more.  Always a copy:
    # ``rc`` may be a ReducedRows' own factor, solved again later, and ``np.asfortranarray`` hands back a
    # slice that is Fortran-ordered already (one column, n = 1) as it is, for the SVD to overwrite.
    r, c = np.array(rc[:, :n], order="F"), rc[:, n:].copy()
    del rc
    try:
        ur, sigma, vt = _svd(r, overwrite=True)
    except np.linalg.LinAlgError:                     # R once more for the slower driver
        ur, sigma, vt = _svd(factor()[0][:, :n])
    return _Spectrum(sigma, vt, ur.T @ c, total, scale)    # R, C and U_R not held while the prior is solved


def _factorization(problem: _Problem, options: _Options
                   ) -> tuple[Callable[[], tuple[np.ndarray, float | None]], float]:
    """``(factor, total)`` of a tall problem.  ``factor()`` returns ``([R | C], scale)``: ``[R | C]`` (n, n + k)
    the QR factor of ``[A | B; E | F]`` (:func:`_triangular_factor`; the steering rows reduced after the data's,
    into :class:`ReducedRows`' factor as it is where there are none) and ``scale`` the data's ``sigma_1``
    (:func:`_data_scale`) where steering rows were added, else None.  It may be called a second time (the SVD's
    fallback, :func:`_tall_spectrum`).  ``total`` is ``||B||^2``."""
    n, block_rows, block_bytes = problem.n, options.block_rows, options.block_bytes
    steering = _Rows(problem.extra, n, block_bytes) if problem.extra.shape[0] else None
    reduced = problem.reduced
    if reduced is None:
        rows = _Rows(problem.a, n, block_bytes)     # checks A for NaN and inf

        def data() -> np.ndarray:
            return _triangular_factor(rows, problem.b, n, block_rows, block_bytes)

        total = float(np.sum(problem.b * problem.b))
    else:
        def data() -> np.ndarray:           # copied only where steering rows are reduced into it in place
            return reduced.factor if steering is None else reduced.factor.copy()

        total = reduced.square_sum

    def factor() -> tuple[np.ndarray, float | None]:
        """``[R | C]`` of ``[A | B; E | F]``, and ``sigma_1`` of ``A``'s own ``R`` with steering rows."""
        rc = data()
        if steering is None:
            return rc, None
        top = _data_scale(rc[:, :n])         # before the steering rows are reduced into rc in place
        return _triangular_factor(steering, problem.f, n, block_rows, block_bytes, start=rc), top or None

    return factor, total


def _data_scale(r: np.ndarray) -> float:
    """``sigma_1`` of the data's own triangular factor ``r`` (n, n), the scale of the cut-off where steering
    rows are added: by Lanczos iteration (:func:`_sigma_max`), by the dense singular values where ARPACK
    fails."""
    try:
        return _sigma_max(r)
    except scipy.sparse.linalg.ArpackError:                  # the dense way, at the SVD's cost
        return float(scipy.linalg.svdvals(r, check_finite=False)[0])


def _wide_spectrum(problem: _Problem) -> _Spectrum:
    """The SVD of a square or wide problem (``s + m <= n``), taken directly of a dense copy of ``[A; E]``
    ((s + m, n)); the cut-off's scale is the data's ``sigma_1`` where steering rows are added."""
    A, s, extra = problem.a, problem.shape[0], problem.extra
    a = A.toarray() if scipy.sparse.issparse(A) else A
    a = np.array(a, dtype=float)  # a private copy: the SVD may overwrite it
    if not np.all(np.isfinite(a)):
        raise ValueError(f"A {a.shape} holds NaN or inf")
    b2, scale = problem.b, None
    if extra.shape[0]:
        scale = (float(scipy.linalg.svdvals(a, check_finite=False)[0]) if s else 0.0) or None
        e = extra.toarray() if scipy.sparse.issparse(extra) else np.array(extra, dtype=float)
        a, b2 = np.vstack([a, e]), np.vstack([b2, problem.f])
    total = float(np.sum(b2 * b2))
    u, sigma, vt = _svd(a)
    return _Spectrum(sigma, vt, u.T @ b2, total, scale)


def _truncated_solution(problem: _Problem, spectrum: _Spectrum, epsilon: float, target: float | None,
                        prior) -> TsvdSolution:
    """The truncated-SVD solution (eq. 19-20) of ``problem`` from its ``spectrum``: the singular values above
    the cut-off kept, ``x = V_r Sigma_r^-1 U_r^T B`` (n, k) plus the prior's component in the dropped
    directions, ``(I - V_r V_r^T) prior``; or, where ``target`` (:func:`_noise_target`) asks for it, smoothed
    towards the prior (:func:`_smoothed`)."""
    n, k = problem.n, problem.k
    sigma, vt, utb = spectrum.sigma, spectrum.vt, spectrum.utb
    cutoff, rank = spectrum.cut(n, epsilon)
    lam = 0.0
    if target is not None and rank:
        lam, x = _smoothed(spectrum, rank, target, lambda: problem.prior(prior))
    else:
        x = None
    if x is None:
        x = vt[:rank].T @ (utb[:rank] / sigma[:rank, None])
        if prior is not None and rank < n:
            x0 = problem.prior(prior).reshape(n, k)
            x += x0 - vt[:rank].T @ (vt[:rank] @ x0)
    condition = float(sigma[0] / sigma[rank - 1]) if rank else float("nan")
    return TsvdSolution(x=problem.shaped(x), rank=rank, n_unknowns=n, condition=condition,
                        sigma_max=float(sigma[0]), sigma_min=float(sigma[-1]), cutoff=cutoff,
                        singular_values=sigma, smoothing=lam)


def _extremes(r: np.ndarray) -> tuple[float, float]:
    """``(sigma_1, sigma_n)``, the largest and smallest singular values of an upper triangular ``r`` (n, n)
    with no zero on its diagonal, to a relative :data:`LANCZOS_TOL`: the largest eigenvalues of ``R^T R`` and
    of ``R^-1 R^-T`` by Lanczos iteration (ARPACK, started from a fixed random vector, so that the result does
    not change between runs), each step two products with ``R`` or two back substitutions, taken in band
    storage (a B-spline fit's factor is a band of about ``p nv + q + 1`` diagonals, :func:`_triangular_factor`).
    Ritz values bound the largest eigenvalue from below: ``sigma_1`` comes out at most its true value,
    ``sigma_n`` at least.  Up to ``_DENSE_EXTREMES`` unknowns the singular values are simply computed."""
    n = len(r)
    if n <= _DENSE_EXTREMES:
        sigma = scipy.linalg.svdvals(r, check_finite=False)
        return float(sigma[0]), float(sigma[-1])
    nonzero = r != 0
    width = int(np.max(n - 1 - np.argmax(nonzero[:, ::-1], axis=1) - np.arange(n)))      # last diagonal used
    band = np.zeros((width + 1, n))                      # LAPACK's upper band storage: band[w + i - j, j]
    for d in range(width + 1):
        band[width - d, d:] = np.diagonal(r, d)

    def solve(v: np.ndarray, trans: str) -> np.ndarray:
        x, info = scipy.linalg.lapack.dtbtrs(band, v.reshape(n, 1), uplo="U", trans=trans)
        if info:
            raise np.linalg.LinAlgError(f"dtbtrs info {info}")
        return x[:, 0]

    inverse_gram = scipy.sparse.linalg.LinearOperator((n, n), matvec=lambda v: solve(solve(v, "T"), "N"),
                                                      dtype=float)
    bottom = scipy.sparse.linalg.eigsh(inverse_gram, k=1, which="LA", v0=_lanczos_start(n), tol=LANCZOS_TOL,
                                       return_eigenvectors=False)[0]
    return _sigma_max(r), float(1.0 / np.sqrt(bottom))


def _lanczos_start(n: int) -> np.ndarray:
    """The fixed random start ``(n,)`` of the Lanczos iterations, so that their results do not change between
    runs."""
    return np.random.default_rng(0).standard_normal(n)


def _sigma_max(r: np.ndarray) -> float:
    """``sigma_1`` (the largest singular value) of an upper triangular ``r`` (n, n), zero rows allowed: the
    largest eigenvalue of ``R^T R`` by Lanczos iteration (ARPACK, to a relative :data:`LANCZOS_TOL`, each step
    two sparse products with ``R``; a Ritz value, at most the true one), or all singular values up to
    ``_DENSE_EXTREMES`` unknowns."""
    n = len(r)
    if n <= _DENSE_EXTREMES:
        return float(scipy.linalg.svdvals(r, check_finite=False)[0]) if n else 0.0
    sparse_r = scipy.sparse.csr_array(r)
    if not sparse_r.nnz:
        return 0.0
    sparse_rt = sparse_r.T.tocsr()
    gram = scipy.sparse.linalg.LinearOperator((n, n), matvec=lambda v: sparse_rt @ (sparse_r @ v), dtype=float)
    top = scipy.sparse.linalg.eigsh(gram, k=1, which="LA", v0=_lanczos_start(n), tol=LANCZOS_TOL,
                                    return_eigenvectors=False)[0]
    return float(np.sqrt(max(top, 0.0)))


def _checked_steer(steer, n: int, k: int) -> tuple:
    """:func:`solve_tsvd`'s ``steer`` checked: ``(E, F)`` with ``E`` (m, n) (CSR if sparse) and ``F`` (m, k);
    ``(E, F)`` of no rows for None."""
    if steer is None:
        return np.zeros((0, n)), np.zeros((0, k))
    extra, f = steer
    extra = scipy.sparse.csr_array(extra) if scipy.sparse.issparse(extra) else np.asarray(extra, dtype=float)
    f = np.asarray(f, dtype=float)
    f = f.reshape(len(f), 1) if f.ndim == 1 else f
    if extra.ndim != 2 or extra.shape[1] != n or f.shape != (extra.shape[0], k):
        raise ValueError(f"steer must be rows (m, {n}) and right-hand sides (m, {k}), got {extra.shape} and "
                         f"{f.shape}")
    values = extra.data if scipy.sparse.issparse(extra) else extra
    if not (np.all(np.isfinite(values)) and np.all(np.isfinite(f))):
        raise ValueError(f"the steering rows {extra.shape} or their right-hand sides {f.shape} hold NaN or inf")
    return extra, f


def _full_rank(factor: _Factor, epsilon: float, target: float | None) -> TsvdSolution | None:
    """The solution ``R^-1 C`` (x ``(n, k)``) of a tall problem reduced to ``factor`` (``R`` (n, n), ``C``
    (n, k), the right-hand side's square sum ``total``) where nothing falls below the cut-off, with a margin,
    and no smoothing towards the prior is due (a ``target`` given, :func:`_noise_target`, and the residual
    below it); else None (the SVD decides).  The cut-off is ``scale n epsilon`` (eq. 20), ``scale`` the data's
    ``sigma_1`` where steering rows were added (:func:`solve_tsvd`), else ``R``'s own.  The diagonal bounds the
    singular values of a triangular matrix (``sigma_n <= min |r_ii|``, ``sigma_1 >= max |r_ii|``), so a
    diagonal entry at or below the cut-off (with ``max |r_ii|`` for ``sigma_1``) is a dropped direction without
    any iteration."""
    r, c, scale = factor.r, factor.c, factor.scale
    n = len(r)
    diagonal = np.abs(np.diag(r))
    if diagonal.min() <= FULL_RANK_MARGIN * (diagonal.max() if scale is None else scale) * n * epsilon:
        return None
    if target is not None and _outside(factor.total, c) < target:
        return None
    try:
        sigma_max, sigma_min = _extremes(r)
    except (scipy.sparse.linalg.ArpackError, np.linalg.LinAlgError) as exc:      # the SVD decides
        log.debug("Lanczos estimate of %d singular values failed (%s): full SVD", n, exc)
        return None
    cutoff = (sigma_max if scale is None else scale) * n * float(epsilon)
    if not sigma_min > FULL_RANK_MARGIN * cutoff:
        return None
    x = scipy.linalg.solve_triangular(r, c, check_finite=False)
    log.debug("%d unknowns of full rank (condition %.3g): solved without the SVD", n, sigma_max / sigma_min)
    return TsvdSolution(x=x, rank=n, n_unknowns=n, condition=sigma_max / sigma_min, sigma_max=sigma_max,
                        sigma_min=sigma_min, cutoff=cutoff, singular_values=None)


def _outside(total: float, projected: np.ndarray) -> float:
    """``||B||^2 - ||P||^2`` (at least 0) for the right-hand side's square sum ``total`` (``||B||^2``) and its
    coordinates ``projected`` in orthonormal columns whose span holds the range of ``A`` (``Q^T B``'s first n
    rows, or ``U^T B``): the part of the residual outside them, which no ``x`` removes (all of it for a
    full-rank fit)."""
    return max(total - float(np.sum(projected * projected)), 0.0)


def _smoothed(spectrum: _Spectrum, rank: int, target: float, prior) -> tuple[float, np.ndarray | None]:
    """The Tikhonov solution towards ``prior() (n, k)`` whose residual is ``target``, and its ``lambda``:
    ``(0, None)`` where the plain truncated fit leaves ``target`` or more already.

    ``spectrum`` holds the singular values ``sigma (p,)`` (the first ``rank`` kept), the SVD's right vectors
    ``vt (p, n)`` and ``utb = U^T B (p, k)``, and the right-hand side's square sum ``total = ||B||^2``.  With
    ``c = U^T (B - A x0)`` (``c_i = (U^T B)_i - sigma_i (V^T x0)_i``), ``x = x0 + sum_i f_i c_i / sigma_i v_i``
    over the kept directions (the prior in the dropped ones) leaves ``||B||^2 - ||U^T B||^2`` (outside the
    range of ``A``), the dropped ``c_i``, and ``(1 - f_i)^2 c_i^2`` with
    ``1 - f_i = lambda^2 / (sigma_i^2 + lambda^2)``: increasing in ``lambda``, solved for by bisection on its
    logarithm."""
    sigma, vt, utb = spectrum.sigma, spectrum.vt, spectrum.utb
    outside = _outside(spectrum.total, utb)
    if outside + float(np.sum(utb[rank:] ** 2)) >= target:
        return 0.0, None
    x0 = prior().reshape(vt.shape[1], -1)
    c = utb - sigma[:, None] * (vt @ x0)                                        # (p, k)
    fixed = outside + float(np.sum(c[rank:] ** 2))
    power = np.sum(c[:rank] ** 2, axis=1)                                       # (rank,)
    kept = sigma[:rank]

    def residual(lam: float) -> float:
        return fixed + float(np.sum((lam ** 2 / (kept ** 2 + lam ** 2)) ** 2 * power))

    if fixed + float(power.sum()) <= target:                                    # lambda -> inf: all prior
        return float("inf"), x0.copy()
    lo, hi = np.log(kept[-1]) - 30.0, np.log(kept[0]) + 30.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if residual(np.exp(mid)) < target else (lo, mid)
    lam = float(np.exp(0.5 * (lo + hi)))
    f = kept ** 2 / (kept ** 2 + lam ** 2)
    return lam, x0 + vt[:rank].T @ ((f / kept)[:, None] * c[:rank])


def _checked_prior(prior, a_shape: tuple[int, int], b_shape: tuple[int, ...]) -> np.ndarray:
    """``prior`` (an array, or a callable returning one, called here) as a float array of shape
    ``(n,) + b_shape[1:]`` for ``A`` of ``a_shape``, or ValueError."""
    x0 = np.asarray(prior() if callable(prior) else prior, dtype=float)
    n = a_shape[1]
    if x0.shape != (n,) + tuple(b_shape[1:]):
        raise ValueError(f"A is {a_shape} and B {b_shape}, so prior must be {(n,) + tuple(b_shape[1:])}, "
                         f"got {x0.shape}")
    if not np.all(np.isfinite(x0)):
        raise ValueError(f"prior {x0.shape} holds NaN or inf")
    return x0
