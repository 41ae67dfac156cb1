"""Least squares by truncated singular value decomposition (GT2014-26683, eq. 19-20).

The morph's fits (edge control points, face interiors, G1 rows) are linear least-squares problems
``A x = B`` with a B-spline design matrix ``A`` (s, n) whose rank depends on how the FE nodes fall into the
knot spans: a span without nodes leaves control points undetermined.  The paper therefore solves them by
truncated SVD rather than by the normal equations (which square the condition number) or a plain QR (which
needs full rank):

    A = U Sigma V^T,   keep sigma_i > eps = sigma_1 * s * epsilon,   x = V_r Sigma_r^-1 U_r^T B.

The paper writes ``(s - 1)`` for its ``s - 1`` rows; here ``s`` is simply the number of rows of ``A``.  The
result is the minimum-norm least-squares solution of the problem with the small singular values removed:
undetermined combinations of unknowns are set to zero instead of blowing up.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse

from .settings import FLT_EPSILON


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
    cutoff : float, the threshold ``sigma_1 * s * epsilon``.
    singular_values : (min(s, n),) float array, all singular values of ``A`` sorted from largest to smallest.
    """

    x: np.ndarray
    rank: int
    n_unknowns: int
    condition: float
    sigma_max: float
    sigma_min: float
    cutoff: float
    singular_values: np.ndarray

    @property
    def rank_deficient(self) -> bool:
        """True if singular values were dropped (``rank < n_unknowns``)."""
        return self.rank < self.n_unknowns


def _svd(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin SVD; falls back from the divide-and-conquer driver to ``gesvd`` if the former fails."""
    try:
        return scipy.linalg.svd(a, full_matrices=False, check_finite=False, lapack_driver="gesdd")
    except np.linalg.LinAlgError:
        return scipy.linalg.svd(a, full_matrices=False, check_finite=False, lapack_driver="gesvd")


def solve_tsvd(A, B, epsilon: float = FLT_EPSILON) -> TsvdSolution:
    """Solve ``min ||A x - B||`` by truncated SVD (eq. 19-20).

    Parameters
    ----------
    A : (s, n) dense array or ``scipy.sparse`` matrix/array, the design matrix (s observations, n unknowns).
        It is densified: the problems of the morph are a few thousand rows by at most a few thousand
        columns.
    B : (s, k) or (s,) array, right-hand side(s); the k columns (e.g. x, y, z) share one factorisation.
    epsilon : float > 0, the machine-precision factor of the cut-off ``sigma_1 * s * epsilon``; default the
        paper's FLT_EPSILON (single precision, about 1.2e-7).

    Returns
    -------
    TsvdSolution with ``x`` of shape (n, k), or (n,) if ``B`` was (s,).

    Method
    ------
    ``A^T A`` and its inverse are never formed.  For a tall ``A`` (s > n) an economic QR ``A = Q R`` (Q (s, n)
    with orthonormal columns, R (n, n)) is computed first, and then the SVD of the small ``R = U_R Sigma V^T``:
    since Q is orthonormal, ``A = (Q U_R) Sigma V^T`` is an SVD of A with the same singular values, at the
    cost of an SVD of an n x n instead of an s x n matrix; ``U^T B = U_R^T (Q^T B)``.  For a square or wide
    ``A`` the SVD is taken directly.  Singular values ``sigma_i <= cutoff`` are dropped.

    Edge cases: ``n == 0`` gives an empty ``x`` (0, k); ``s == 0`` (no observations) gives ``x = 0`` with
    ``rank == 0``.  An all-zero ``A`` gives ``x = 0``, ``rank == 0``.
    """
    if scipy.sparse.issparse(A):
        if A.ndim != 2:
            raise ValueError(f"A must be a 2-D (s, n) matrix, got shape {A.shape}")
        a = A.toarray().astype(float, copy=False)
    else:
        a = np.array(A, dtype=float)  # a private copy: QR may overwrite it
        if a.ndim != 2:
            raise ValueError(f"A must be a 2-D (s, n) matrix, got shape {a.shape}")
    b = np.asarray(B, dtype=float)
    if b.ndim not in (1, 2):
        raise ValueError(f"B must be (s,) or (s, k), got shape {b.shape}")
    s, n = a.shape
    if b.shape[0] != s:
        raise ValueError(f"A is {a.shape} but B is {b.shape}: B needs {s} rows, one per row of A")
    if not (np.isfinite(epsilon) and epsilon > 0):
        raise ValueError(f"epsilon must be positive and finite, got {epsilon!r}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"A {a.shape} holds NaN or inf")
    if not np.all(np.isfinite(b)):
        raise ValueError(f"B {b.shape} holds NaN or inf")

    vector = b.ndim == 1
    b2 = b.reshape(s, 1) if vector else b
    k = b2.shape[1]

    if s == 0 or n == 0:
        x = np.zeros((n, k))
        return TsvdSolution(x=x[:, 0] if vector else x, rank=0, n_unknowns=n, condition=float("nan"),
                            sigma_max=0.0, sigma_min=0.0, cutoff=0.0, singular_values=np.zeros(0))

    if s > n:
        q, r = scipy.linalg.qr(a, mode="economic", overwrite_a=True, check_finite=False)
        ur, sigma, vt = _svd(r)
        utb = ur.T @ (q.T @ b2)
    else:
        u, sigma, vt = _svd(a)
        utb = u.T @ b2

    cutoff = float(sigma[0]) * s * float(epsilon)
    keep = sigma > cutoff
    rank = int(np.count_nonzero(keep))  # sigma is descending, so the kept ones are the first `rank`
    x = vt[:rank].T @ (utb[:rank] / sigma[:rank, None])
    condition = float(sigma[0] / sigma[rank - 1]) if rank else float("nan")
    return TsvdSolution(x=x[:, 0] if vector else x, rank=rank, n_unknowns=n, condition=condition,
                        sigma_max=float(sigma[0]), sigma_min=float(sigma[-1]), cutoff=cutoff,
                        singular_values=sigma)
