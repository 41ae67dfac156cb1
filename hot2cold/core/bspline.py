"""B-spline curves and surfaces as plain numpy records, and their evaluation.

This is the numeric core's geometry: no kernel objects here.  Conversion to and from OpenCascade lives in
:mod:`hot2cold.kernel.convert`, and the kernel is the oracle the tests check these evaluators against.

Conventions
-----------
* Knot vectors are *full* (every multiplicity written out, clamped: ``degree + 1`` equal knots at each end),
  so a curve with ``n`` poles of degree ``p`` has ``n + p + 1`` knots.
* Indices number from 0.  Surface poles are ``(nu, nv, 3)``; flattened, pole ``(i, j)`` is column
  ``i * nv + j`` of a surface design matrix.
* Rational geometry (cylinders, tori, fillets converted from analytic form) carries weights; the morph moves
  only poles and keeps weights, knots and degrees, so with rational basis functions
  ``R_i = w_i N_i / sum_k w_k N_k`` the displacement is still linear in the pole displacements.
"""
from __future__ import annotations

import functools
import hashlib
import threading
from collections.abc import Callable
from dataclasses import dataclass, replace
from math import comb as _comb

import numpy as np
import scipy.sparse as _sparse

from .arrays import run_places


def _as_float_array(a, name: str, ndim: int) -> np.ndarray:
    arr = np.ascontiguousarray(a, dtype=float)
    if arr.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} dimensions, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} holds NaN or inf")
    return arr


@dataclass(frozen=True, eq=False)
class BSplineCurve:
    """A (possibly rational) clamped B-spline curve.

    Attributes
    ----------
    poles : (n, 3) float array, control points in mm.
    knots : (n + degree + 1,) float array, full non-decreasing knot vector.
    degree : int, polynomial degree p >= 1.
    weights : (n,) float array of positive weights, or None for a non-rational curve.
    """

    poles: np.ndarray
    knots: np.ndarray
    degree: int
    weights: np.ndarray | None = None

    def __post_init__(self):
        poles = _as_float_array(self.poles, "poles", 2)
        knots = _as_float_array(self.knots, "knots", 1)
        if poles.shape[1] != 3:
            raise ValueError(f"poles must be (n, 3), got {poles.shape}")
        if len(knots) != len(poles) + self.degree + 1:
            raise ValueError(
                f"{len(poles)} poles of degree {self.degree} need {len(poles) + self.degree + 1} knots, "
                f"got {len(knots)}")
        object.__setattr__(self, "poles", poles)
        object.__setattr__(self, "knots", knots)
        if self.weights is not None:
            w = _as_float_array(self.weights, "weights", 1)
            if w.shape != (len(poles),):
                raise ValueError(f"weights must be ({len(poles)},), got {w.shape}")
            object.__setattr__(self, "weights", w)

    @property
    def n_poles(self) -> int:
        return len(self.poles)

    @property
    def domain(self) -> tuple[float, float]:
        """Parameter range ``(knots[p], knots[n])``."""
        return float(self.knots[self.degree]), float(self.knots[self.n_poles])

    @property
    def layout(self) -> KnotLayout:
        """The :class:`KnotLayout` of the knots, worked out on first use and kept (shared by :meth:`with_poles`)."""
        found = self.__dict__.get("_layout")
        if found is None:
            found = KnotLayout(self.knots, self.degree)
            object.__setattr__(self, "_layout", found)
        return found

    def with_poles(self, poles: np.ndarray) -> "BSplineCurve":
        """The same curve (degree, knots, weights) with other poles ``(n, 3)``."""
        return _same_layout(self, replace(self, poles=poles))

    def digest(self) -> bytes:
        """16 bytes of the curve's content (degree, knots, poles, weights), as :meth:`BSplineSurface.digest`."""
        return _digest((self.degree,), (self.knots, self.poles, self.weights))


def _digest(degrees: tuple[int, ...], arrays: tuple[np.ndarray | None, ...]) -> bytes:
    """16 bytes of a record's content: its ``degrees``, whether it is rational (the last of ``arrays``, its
    weights, not None) and the shapes and bytes of ``arrays``; equal for records equal to the bit."""
    found = hashlib.blake2b(digest_size=16)
    found.update(np.array([*degrees, arrays[-1] is not None]).tobytes())
    for array in arrays:
        if array is not None:
            found.update(str(array.shape).encode())
            found.update(np.ascontiguousarray(array).tobytes())
    return found.digest()


@dataclass(frozen=True, eq=False)
class BSplineSurface:
    """A (possibly rational) clamped tensor-product B-spline surface.

    Attributes
    ----------
    poles : (nu, nv, 3) float array, control net in mm.
    u_knots : (nu + u_degree + 1,) float array, full knot vector in u.
    v_knots : (nv + v_degree + 1,) float array, full knot vector in v.
    u_degree, v_degree : int, degrees p and q.
    weights : (nu, nv) float array of positive weights, or None for a non-rational surface.
    """

    poles: np.ndarray
    u_knots: np.ndarray
    v_knots: np.ndarray
    u_degree: int
    v_degree: int
    weights: np.ndarray | None = None

    def __post_init__(self):
        poles = _as_float_array(self.poles, "poles", 3)
        uk = _as_float_array(self.u_knots, "u_knots", 1)
        vk = _as_float_array(self.v_knots, "v_knots", 1)
        nu, nv, dim = poles.shape
        if dim != 3:
            raise ValueError(f"poles must be (nu, nv, 3), got {poles.shape}")
        if len(uk) != nu + self.u_degree + 1 or len(vk) != nv + self.v_degree + 1:
            raise ValueError(
                f"a {nu}x{nv} net of degrees ({self.u_degree}, {self.v_degree}) needs "
                f"{nu + self.u_degree + 1} u-knots and {nv + self.v_degree + 1} v-knots, "
                f"got {len(uk)} and {len(vk)}")
        object.__setattr__(self, "poles", poles)
        object.__setattr__(self, "u_knots", uk)
        object.__setattr__(self, "v_knots", vk)
        if self.weights is not None:
            w = _as_float_array(self.weights, "weights", 2)
            if w.shape != (nu, nv):
                raise ValueError(f"weights must be ({nu}, {nv}), got {w.shape}")
            object.__setattr__(self, "weights", w)

    @property
    def shape(self) -> tuple[int, int]:
        """Control net size ``(nu, nv)``."""
        return self.poles.shape[0], self.poles.shape[1]

    @property
    def domain(self) -> tuple[float, float, float, float]:
        """Parameter box ``(u0, u1, v0, v1)``."""
        nu, nv = self.shape
        return (float(self.u_knots[self.u_degree]), float(self.u_knots[nu]),
                float(self.v_knots[self.v_degree]), float(self.v_knots[nv]))

    @property
    def layouts(self) -> tuple[KnotLayout, KnotLayout]:
        """The :class:`KnotLayout` of the u- and the v-knots, worked out on first use and kept (shared by
        :meth:`with_poles`)."""
        found = self.__dict__.get("_layout")
        if found is None:
            found = (KnotLayout(self.u_knots, self.u_degree), KnotLayout(self.v_knots, self.v_degree))
            object.__setattr__(self, "_layout", found)
        return found

    def digest(self) -> bytes:
        """16 bytes of the surface's content (degrees, knots, poles, weights), worked out on each call: equal for
        records equal to the bit.  The key of caches that should find a surface made again as another object
        (a correction run again on the same fits)."""
        return _digest((self.u_degree, self.v_degree), (self.u_knots, self.v_knots, self.poles, self.weights))

    def with_poles(self, poles: np.ndarray) -> "BSplineSurface":
        """The same surface (degrees, knots, weights) with another control net ``(nu, nv, 3)``."""
        return _same_layout(self, replace(self, poles=poles))

    def remember(self, memo: BasisMemo | None) -> None:
        """Keep the basis rows asked of this surface in ``memo`` (None: keep none), and so those of the surfaces
        made from it (:meth:`with_poles`, :func:`refine_surface`)."""
        object.__setattr__(self, "_memo", memo)

    def __getstate__(self) -> dict:
        """Pickled without its :class:`BasisMemo` (the process that unpickles it keeps its own, or none)."""
        return {k: v for k, v in self.__dict__.items() if k != "_memo"}


def _same_layout(old, new):
    """``new`` (made from ``old`` with other poles) given ``old``'s knot layouts where they are worked out, and
    its :class:`BasisMemo`."""
    found = old.__dict__.get("_layout")
    if found is not None and new.poles.shape[:-1] == old.poles.shape[:-1]:
        object.__setattr__(new, "_layout", found)
    if old.__dict__.get("_memo") is not None:
        object.__setattr__(new, "_memo", old.__dict__["_memo"])
    return new


#: What a :class:`BasisMemo` holds at the most (bytes), and the most rows of one request it keeps.
MEMO_BYTES, MEMO_ROWS = 32 * 2 ** 20, 512
#: What a :class:`BasisMemo` holds at the most (bytes) of whole evaluations (:func:`evaluated`).
MEMO_EVALUATION_BYTES = 16 * 2 ** 20


class BasisMemo:
    """The basis rows asked of a morph's surfaces, kept for when the same rows are asked again.

    A morph asks the same rows many times: the hot faces' normals at the same edge samples in every round of
    G1, a face's grid in every refinement round and every check, a morphed face (a record of the same knots,
    :meth:`BSplineSurface.with_poles`) at its hot face's parameters.  Requests of up to ``max_rows``
    parameters are kept, keyed by the surface's knot layouts (:class:`KnotLayout`, one object per record and
    the records made from it with other poles: the same knots, degrees and weights) and the parameters; the
    least recently used go first beyond ``budget`` bytes.  Whole evaluations asked again of a surface of the
    same content at the same parameters (G1 measures the kinks along every tangent edge in each of its rounds,
    most faces unchanged) are kept apart, up to ``evaluation_budget`` bytes (:func:`evaluated`).  The arrays
    kept are read-only.  Thread-safe: the stages work on faces in threads."""

    def __init__(self, budget: int = MEMO_BYTES, max_rows: int = MEMO_ROWS,
                 evaluation_budget: int = MEMO_EVALUATION_BYTES):
        self.max_rows = max_rows
        self._rows = _Kept(budget, _size)
        self._evaluations = _Kept(evaluation_budget, _evaluation_size)
        self._lock = threading.Lock()

    @property
    def budget(self) -> int:
        """The bytes of basis rows kept at the most (0 once closed)."""
        return self._rows.budget

    @property
    def evaluation_budget(self) -> int:
        """The bytes of whole evaluations kept at the most (0 once closed)."""
        return self._evaluations.budget

    def get(self, key: tuple, nu: int) -> tuple[np.ndarray, list[np.ndarray]] | None:
        """The rows ``(cols, vals)`` of :func:`_surface_rows` up to derivatives of order ``nu`` kept under
        ``key``, or None."""
        with self._lock:
            found = self._rows.get(key)
        if found is None:
            return None
        have, cols, vals = found
        return (cols, vals[:_ROW_SETS[nu]]) if have >= nu else None

    def put(self, key: tuple, nu: int, cols: np.ndarray, vals: list[np.ndarray]) -> None:
        """Keep the rows ``(cols, vals)`` up to derivatives of order ``nu`` under ``key`` (made read-only)."""
        if self.budget <= 0:
            return
        for a in (cols, *vals):
            a.flags.writeable = False
        with self._lock:
            self._rows.put(key, (nu, cols, list(vals)))     # its own list: the caller's may change

    def evaluation(self, key: tuple) -> np.ndarray | None:
        """The evaluation kept under ``key`` (:func:`evaluated`), or None."""
        with self._lock:
            return self._evaluations.get(key)

    def keep_evaluation(self, key: tuple, found: np.ndarray) -> None:
        """Keep the evaluation ``found`` under ``key`` (made read-only)."""
        if self.evaluation_budget <= 0:
            return
        found.flags.writeable = False
        with self._lock:
            self._evaluations.put(key, found)

    def close(self) -> None:
        """Forget every row and evaluation kept and keep none from now on (the surfaces of a finished morph still
        hold it)."""
        with self._lock:
            self._rows.close()
            self._evaluations.close()


class _Kept:
    """One table of a :class:`BasisMemo`: its entries by key, the least recently used first, dropped beyond
    ``budget`` bytes (``size(key, entry)`` each).  Not locked: the memo holds its lock around every call."""

    def __init__(self, budget: int, size: Callable[[tuple, object], int]):
        self.budget, self._size = budget, size
        self.entries: dict[tuple, object] = {}
        self.bytes = 0

    def get(self, key: tuple):
        """The entry under ``key`` (now the most recently used), or None."""
        found = self.entries.pop(key, None)
        if found is not None:
            self.entries[key] = found                                   # the most recently used last
        return found

    def put(self, key: tuple, entry) -> None:
        """Keep ``entry`` under ``key``, the least recently used dropped while the table holds more than its
        budget."""
        old = self.entries.pop(key, None)
        if old is not None:
            self.bytes -= self._size(key, old)
        self.entries[key] = entry
        self.bytes += self._size(key, entry)
        while self.bytes > self.budget and self.entries:
            oldest = next(iter(self.entries))                           # the least recently used
            self.bytes -= self._size(oldest, self.entries.pop(oldest))

    def close(self) -> None:
        """Forget every entry and keep none from now on."""
        self.entries.clear()
        self.bytes = 0
        self.budget = 0


def _size(key: tuple, entry: tuple[int, np.ndarray, list[np.ndarray]]) -> int:
    """The bytes of one entry of basis rows: its parameters (the key) and its rows."""
    return len(key[-2]) + len(key[-1]) + entry[1].nbytes + sum(v.nbytes for v in entry[2])


def _evaluation_size(key: tuple, found: np.ndarray) -> int:
    """The bytes of one kept evaluation: its parameters (the key) and its rows."""
    return len(key[-2]) + len(key[-1]) + found.nbytes


#: The number of value arrays :func:`_surface_rows` gives for derivatives up to order 0, 1, 2.
_ROW_SETS = (1, 3, 6)


# ----------------------------------------------------------------------------------------------------------
# Evaluation: basis matrices and points.
#
# Every basis matrix here is built by the Cox-de Boor triangle (:func:`_triangle`) and kept internally in a
# fixed-width row form: row ``r`` has ``degree + 1`` consecutive non-zero columns starting at ``start[r]``
# (the knot span of the parameter), with values ``vals[r, :]``.  That makes rational weighting, derivatives
# and the row-wise Kronecker product of a surface plain vectorised numpy on (m, degree + 1) arrays; the
# result is handed out as a ``scipy.sparse.csr_array`` with sorted column indices.  Entries that happen to
# be zero (e.g. at a knot) are kept as explicit zeros, so every row of a curve basis stores exactly
# ``degree + 1`` entries and every row of a surface basis ``(u_degree + 1) * (v_degree + 1)``.
# ----------------------------------------------------------------------------------------------------------

#: Parameters outside the domain by at most this fraction of the domain length (or of the largest end
#: value, whichever is larger) are clipped onto the domain; farther ones raise ``ValueError``.
PARAM_RTOL = 1e-10


def _parameters(t, lo: float, hi: float, name: str) -> np.ndarray:
    """``t`` as a float array ``(m,)`` clipped to ``[lo, hi]``; ValueError if farther outside than tolerated."""
    arr = np.asarray(t, dtype=float)
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a scalar or a 1-D array (m,), got shape {arr.shape}")
    if not arr.size:
        return arr
    least, most = arr.min(), arr.max()
    if lo <= least and most <= hi:              # the common case, in two reductions (NaN fails both tests)
        return arr
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} holds NaN or inf")
    tol = PARAM_RTOL * max(hi - lo, abs(lo), abs(hi))
    bad = (arr < lo - tol) | (arr > hi + tol)
    if np.any(bad):
        worst = arr[bad][np.argmax(np.maximum(lo - arr[bad], arr[bad] - hi))]
        raise ValueError(
            f"{np.count_nonzero(bad)} value(s) of {name} lie outside the domain [{lo!r}, {hi!r}] "
            f"(e.g. {worst!r}; tolerance {tol:.3g})")
    return np.clip(arr, lo, hi)


class KnotLayout:
    """What the basis rows of one knot vector and degree need besides the parameters, worked out once: the last
    non-empty span ``last`` and, per degree ``d = 1 .. degree``, the factors ``factors[d]`` of the differences that
    raise a degree-``d - 1`` row to degree ``d`` in :func:`_span_rows` (``d / (T[j+d+1] - T[j+1])`` on the knots
    ``T`` of degree ``d``, 0 on empty spans).  A record keeps one per knot vector (:meth:`BSplineSurface.layouts`),
    so that a morph's many evaluations of the same face do not work them out again each time."""

    __slots__ = ("knots", "degree", "last", "factors")

    def __init__(self, knots: np.ndarray, degree: int):
        self.knots, self.degree = knots, degree
        last = len(knots) - degree - 2      # the last non-empty span (before an end knot of too high a multiplicity)
        while last > degree and knots[last] >= knots[last + 1]:
            last -= 1
        self.last = last
        n = len(knots) - degree - 1
        self.factors: dict[int, np.ndarray] = {}
        for d in range(1, degree + 1):
            td = knots[degree - d:len(knots) - (degree - d)]
            nd = n - degree + d             # number of basis functions of degree d on td
            den = td[d + 1:nd + d] - td[1:nd]   # (nd - 1,): T[j+d+1] - T[j+1]
            with np.errstate(divide="ignore", invalid="ignore"):
                self.factors[d] = np.where(den > 0, d / np.where(den > 0, den, 1.0), 0.0)


def _spans(x: np.ndarray, knots: np.ndarray, degree: int, last: int) -> np.ndarray:
    """The knot span ``s (m,)`` of each parameter ``x (m,)`` (in the domain): ``knots[s] <= x < knots[s + 1]``,
    the span to the right at an inner knot, the last non-empty span (``last``, :class:`KnotLayout`) at the
    domain's end (as ``scipy.interpolate.BSpline.design_matrix`` picks them)."""
    return np.minimum(np.maximum(np.searchsorted(knots, x, side="right") - 1, degree), last)


@functools.lru_cache(maxsize=None)
def _knot_offsets(degree: int) -> np.ndarray:
    """The offsets ``(2 degree,)`` from a span ``s`` of the knots :func:`_triangle` reads: ``s - j``, then
    ``s + 1 + j``, for ``j = 0 .. degree - 1`` (read-only: one array per degree)."""
    offsets = np.concatenate([-np.arange(degree), 1 + np.arange(degree)])
    offsets.flags.writeable = False
    return offsets


def _triangle(x: np.ndarray, knots: np.ndarray, degree: int, lowest: int, last: int
              ) -> tuple[np.ndarray, list[list[np.ndarray]]]:
    """The non-zero B-splines of every degree ``lowest .. degree`` at ``x (m,)`` by the Cox-de Boor triangle
    (The NURBS Book, A2.2), vectorised over ``x``: the span ``s (m,)`` of each parameter and, per degree ``d``, the
    values of the degree-``d`` B-splines ``s - d .. s`` on ``knots`` as ``d + 1`` arrays ``(m,)`` (``last``:
    :func:`_spans`).  Worked column by column, so that every step runs over ``m`` contiguous values."""
    s = _spans(x, knots, degree, last)
    near = knots[s + _knot_offsets(degree)[:, None]]              # (2 degree, m)
    left = x - near[:degree]                                      # left[j] = x - knots[s - j]
    right = near[degree:] - x                                     # right[j] = knots[s + 1 + j] - x
    values = [np.ones(len(x))]
    out = [values] if lowest == 0 else []
    for j in range(1, degree + 1):
        raised, saved = [], None
        for r in range(j):
            temp = values[r] / (right[r] + left[j - 1 - r])
            term = right[r] * temp
            raised.append(term if saved is None else term + saved)
            saved = left[j - 1 - r] * temp
        raised.append(saved)
        values = raised
        if j >= lowest:
            out.append(values)
    return s, out


def _span_rows(x: np.ndarray, knots: np.ndarray, degree: int, nu: int, layout: KnotLayout | None = None
               ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Basis values and the derivatives ``1..nu`` in fixed-width row form.

    ``x`` (m,) must lie in the domain; ``layout`` is ``KnotLayout(knots, degree)`` where the caller keeps one.
    Returns ``start`` (m,) int, the column of the first non-zero basis function of each row, and ``[vals_0, ...,
    vals_nu]``, each (m, degree + 1): ``vals_k[r, a]`` is the ``k``-th derivative of basis function
    ``start[r] + a`` at ``x[r]``.

    Derivatives use the knot-difference identity: the ``k``-th derivative of a degree-``p`` spline on knots
    ``t`` is a degree-``(p - k)`` spline on ``t[k:-k]``, whose coefficients are repeated scaled differences
    ``d (c_{j+1} - c_j) / (T[j+d+1] - T[j+1])`` of the original ones.  So the degree-``(p - k)`` rows (from the
    same Cox-de Boor triangle, :func:`_triangle`) are multiplied by ``k`` bidiagonal difference matrices, done
    here column by column.
    """
    p = degree
    m = x.shape[0]
    if m == 0:
        return np.zeros(0, dtype=np.int64), [np.zeros((0, p + 1)) for _ in range(nu + 1)]
    if layout is None:
        layout = KnotLayout(knots, degree)
    lowest = max(p - nu, 0)
    span, lower = _triangle(x, knots, p, lowest, layout.last)     # lower[i]: degree lowest + i
    start = span - p
    out = []
    for k in range(nu + 1):
        if k > p:
            out.append(np.zeros((m, p + 1)))
            continue
        vals = lower[p - k - lowest]
        # Raise the degree-(p - k) row back to the degree-p index space: multiply by Diff_d, d = p - k + 1 .. p
        # (the end columns as 0.0 - x and x + 0.0: zeros keep the sign a difference from zero gives them).
        for d in range(p - k + 1, p + 1):
            factors = layout.factors[d]
            scaled = [v * factors[start + a] for a, v in enumerate(vals)]
            vals = ([0.0 - scaled[0]] + [scaled[a - 1] - scaled[a] for a in range(1, len(scaled))]
                    + [scaled[-1] + 0.0])
        rows = np.empty((m, p + 1))
        for a, v in enumerate(vals):
            rows[:, a] = v
        out.append(rows)
    return start, out


def _rationalise(vals: list[np.ndarray], wcols: np.ndarray) -> list[np.ndarray]:
    """Rational basis derivatives from non-rational ones.

    ``vals[k]`` (m, w) are k-th derivatives of ``N_i``; ``wcols`` (m, w) the weights of those columns.  With
    ``A_k = w_i N_i^(k)`` and ``W_k = sum_i A_k``, the general Leibniz quotient rule gives
    ``R^(k) = (A_k - sum_{i=1..k} C(k, i) W_i R^(k-i)) / W_0``.
    """
    a = [v * wcols for v in vals]
    wsum = [ak.sum(axis=1, keepdims=True) for ak in a]
    r = []
    for k in range(len(vals)):
        acc = a[k].copy()
        for i in range(1, k + 1):
            acc -= _comb(k, i) * wsum[i] * r[k - i]
        r.append(acc / wsum[0])
    return r


def _to_csr(start: np.ndarray, vals: np.ndarray, n_cols: int) -> _sparse.csr_array:
    m, w = vals.shape
    indices = (start[:, None] + np.arange(w)).ravel()
    indptr = np.arange(0, m * w + 1, w, dtype=np.int64)
    return _sparse.csr_array((vals.ravel(), indices, indptr), shape=(m, n_cols))


def _curve_rows(curve: BSplineCurve, t, nu: int) -> tuple[np.ndarray, list[np.ndarray]]:
    lo, hi = curve.domain
    x = _parameters(t, lo, hi, "t")
    start, vals = _span_rows(x, curve.knots, curve.degree, nu, curve.layout)
    if curve.weights is not None:
        vals = _rationalise(vals, curve.weights[start[:, None] + np.arange(curve.degree + 1)])
    return start, vals


def curve_basis(curve: BSplineCurve, t) -> _sparse.csr_array:
    """Basis function values of ``curve`` at parameters ``t``.

    Parameters
    ----------
    curve : BSplineCurve with ``n`` poles.
    t : (m,) float array (or a scalar, taken as (1,)) of parameters in ``curve.domain``.  Values outside the
        domain by at most ``PARAM_RTOL`` of its length are clipped onto it; farther ones raise ``ValueError``.

    Returns
    -------
    (m, n) ``scipy.sparse.csr_array``; ``B @ curve.poles`` are the curve points ``(m, 3)``.  Each row holds
    ``degree + 1`` stored entries (explicit zeros included).  For a rational curve the entries are
    ``R_i = w_i N_i / sum_k w_k N_k``; rows sum to 1 either way.

    ``t == knots[n]`` (the domain end) is evaluated on the last non-empty knot span, i.e. as the left
    limit, which gives ``B[:, n - 1] == 1`` for a clamped knot vector.
    """
    start, (vals,) = _curve_rows(curve, t, 0)
    return _to_csr(start, vals, curve.n_poles)


def fit_curve(t: np.ndarray, points: np.ndarray, knots: np.ndarray, degree: int) -> BSplineCurve:
    """The non-rational B-spline curve of ``degree`` on the full clamped ``knots`` that passes through the first
    and last of ``points (m, 3)`` at ``t[0]`` and ``t[-1]`` (the ends of the knots) and fits the others, at
    ``t (m,)`` in between, by least squares (``numpy.linalg.lstsq``; enough parameters in each knot span to
    determine its poles are the caller's part)."""
    t, points, knots = np.asarray(t, float), np.asarray(points, float), np.asarray(knots, float)
    n = len(knots) - degree - 1
    if points.shape != (len(t), 3) or n < 2:
        raise ValueError(f"points must be (m, 3) for t (m,) and knots give at least 2 poles: points "
                         f"{points.shape}, t {t.shape}, {n} poles")
    curve = BSplineCurve(np.zeros((n, 3)), knots, degree)
    basis = curve_basis(curve, t).toarray()                                    # (m, n)
    poles = np.empty((n, 3))
    poles[0], poles[-1] = points[0], points[-1]
    rest = points - basis[:, :1] * poles[0] - basis[:, -1:] * poles[-1]
    poles[1:-1] = np.linalg.lstsq(basis[1:-1, 1:-1], rest[1:-1], rcond=None)[0]
    return BSplineCurve(poles, knots, degree)


def curve_derivative_basis(curve: BSplineCurve, t, nu: int = 1) -> _sparse.csr_array:
    """Basis of the ``nu``-th derivative ``d^nu C / dt^nu`` of ``curve`` at parameters ``t`` (m,).

    Returns a sparse (m, n) ``csr_array`` with the same structure as :func:`curve_basis` (``degree + 1``
    stored entries per row); ``D @ curve.poles`` is the ``nu``-th derivative ``(m, 3)``.  For a rational
    curve the quotient (Leibniz) rule is applied to ``R_i = w_i N_i / W``.  ``nu = 0`` is
    :func:`curve_basis`; ``nu > degree`` gives zeros for a non-rational curve.

    At a knot where the curve is only C^(nu-1) the derivative is the one of the span to the right (at the
    domain end: of the last span), as :func:`_spans` picks them.
    """
    if int(nu) != nu or nu < 0:
        raise ValueError(f"nu must be a non-negative integer, got {nu!r}")
    start, vals = _curve_rows(curve, t, int(nu))
    return _to_csr(start, vals[-1], curve.n_poles)


def _surface_parameters(surface: BSplineSurface, u, v) -> tuple[np.ndarray, np.ndarray]:
    """Parameters ``u``, ``v`` checked against the surface's domain as two (m,) arrays (a scalar is
    broadcast to the other's length)."""
    u0, u1, v0, v1 = surface.domain
    uu = _parameters(u, u0, u1, "u")
    vv = _parameters(v, v0, v1, "v")
    if uu.shape != vv.shape:
        if uu.size == 1:
            uu = np.full(vv.shape, uu[0])
        elif vv.size == 1:
            vv = np.full(uu.shape, vv[0])
        else:
            raise ValueError(f"u and v must have the same shape (m,) (or one be a scalar), got {uu.shape} "
                             f"and {vv.shape}")
    return uu, vv


def _net_columns(su: np.ndarray, sv: np.ndarray, p: int, q: int, nv: int) -> np.ndarray:
    """The flat indices ``(m, (p + 1) (q + 1))`` into a net of ``nv`` columns of the poles each row of a surface
    basis reads: ``(su + a) nv + sv + b`` in column ``a (q + 1) + b``, from the rows' first poles ``su``, ``sv``
    ``(m,)`` (one broadcast against the constant offsets: numpy's broadcast of ``(m, p + 1, 1)`` against ``(m, 1,
    q + 1)`` costs several times as much)."""
    return (su * nv + sv)[:, None] + (np.arange(p + 1)[:, None] * nv + np.arange(q + 1)).ravel()


def _surface_rows(surface: BSplineSurface, u, v, nu: int):
    """Fixed-width tensor-product rows up to derivatives of order ``nu`` (0, 1 or 2).

    Returns the column indices ``cols`` (m, (p+1)(q+1)) and a list of value arrays of that shape: the
    (rational if weighted) basis, if ``nu >= 1`` its u- and v-derivatives, and if ``nu == 2`` its uu-, uv-
    and vv-derivatives.
    """
    uu, vv = _surface_parameters(surface, u, v)
    lu, lv = surface.layouts
    memo = surface.__dict__.get("_memo")
    if memo is not None and len(uu) > memo.max_rows:
        memo = None
    if memo is not None:
        key = (lu, lv, uu.tobytes(), vv.tobytes())
        found = memo.get(key, nu)
        if found is not None:
            return found
    p, q = surface.u_degree, surface.v_degree
    nv = surface.shape[1]
    su, bu = _span_rows(uu, surface.u_knots, p, nu, lu)
    sv, bv = _span_rows(vv, surface.v_knots, q, nu, lv)
    m, width = len(uu), (p + 1) * (q + 1)
    cols = _net_columns(su, sv, p, q, nv)
    # row-wise Kronecker products, column a (q + 1) + b of u's column a and v's column b (einsum forms them
    # several times faster than numpy's broadcast of (m, p + 1, 1) by (m, 1, q + 1), without temporaries)

    def kron(a, b):
        return np.einsum("ma,mb->mab", a, b).reshape(m, width)

    vals = [kron(bu[0], bv[0])]
    if nu:
        vals += [kron(bu[1], bv[0]), kron(bu[0], bv[1])]
    if nu > 1:
        vals += [kron(bu[2], bv[0]), kron(bu[1], bv[1]), kron(bu[0], bv[2])]
    if surface.weights is not None:
        # quotient rule on R = A / W, A = w N (columns), W = sum A, and their derivatives
        wcols = surface.weights.reshape(-1)[cols]
        a = [x * wcols for x in vals]
        w = [x.sum(axis=1, keepdims=True) for x in a]
        r = [a[0] / w[0]]
        if nu:
            r += [(a[k] - w[k] * r[0]) / w[0] for k in (1, 2)]
        if nu > 1:
            r += [(a[3] - 2.0 * w[1] * r[1] - w[3] * r[0]) / w[0],
                  (a[4] - w[1] * r[2] - w[2] * r[1] - w[4] * r[0]) / w[0],
                  (a[5] - 2.0 * w[2] * r[2] - w[5] * r[0]) / w[0]]
        vals = r
    if memo is not None:
        memo.put(key, nu, cols, vals)
    return cols, vals


def _cols_to_csr(cols: np.ndarray, vals: np.ndarray, n_cols: int) -> _sparse.csr_array:
    """The fixed-width rows ``vals (m, w)`` in the columns ``cols (m, w)`` as an ``(m, n_cols)`` csr_array of its
    own (rows kept in a :class:`BasisMemo` are read-only and copied: a caller may scale a basis in place)."""
    m, w = vals.shape
    indptr = np.arange(0, m * w + 1, w, dtype=np.int64)
    data = vals.ravel() if vals.flags.writeable else vals.ravel().copy()
    indices = cols.ravel() if cols.flags.writeable else cols.ravel().copy()
    return _sparse.csr_array((data, indices, indptr), shape=(m, n_cols))


def surface_basis(surface: BSplineSurface, u, v) -> _sparse.csr_array:
    """Tensor-product basis of ``surface`` at parameter pairs ``(u[r], v[r])``.

    Parameters
    ----------
    surface : BSplineSurface with a ``(nu, nv)`` control net.
    u, v : (m,) float arrays of parameters (either may be a scalar, repeated for every row), in the domain
        up to ``PARAM_RTOL`` (clipped; farther raises ``ValueError``).

    Returns
    -------
    (m, nu * nv) ``scipy.sparse.csr_array``: the row-wise Kronecker product of the u and v design matrices,
    column ``i * nv + j`` for pole ``(i, j)``; ``B @ surface.poles.reshape(-1, 3)`` are the points (m, 3).
    Rational when the surface has weights (``R_ij = w_ij N_i N_j / sum w N N``).  Each row stores
    ``(u_degree + 1) * (v_degree + 1)`` entries, explicit zeros included.
    """
    cols, (vals,) = _surface_rows(surface, u, v, 0)
    return _cols_to_csr(cols, vals, surface.shape[0] * surface.shape[1])


def surface_derivative_bases(surface: BSplineSurface, u, v) -> tuple[_sparse.csr_array, _sparse.csr_array]:
    """Bases of the first partial derivatives ``(dS/du, dS/dv)``, each an (m, nu * nv) ``csr_array``.

    Same columns and structure as :func:`surface_basis`; rational surfaces use the quotient rule
    ``R_u = (w N_u - W_u R) / W``.  At a knot where the surface is only C0 the derivative of the span on the
    larger-parameter side is returned (at the domain end: of the last span).
    """
    cols, (_, du, dv) = _surface_rows(surface, u, v, 1)
    n = surface.shape[0] * surface.shape[1]
    return _cols_to_csr(cols, du, n), _cols_to_csr(cols, dv, n)


def surface_second_derivative_bases(surface: BSplineSurface, u, v
                                    ) -> tuple[_sparse.csr_array, _sparse.csr_array, _sparse.csr_array]:
    """Bases of the second partial derivatives ``(d2S/du2, d2S/dudv, d2S/dv2)``, each an (m, nu * nv)
    ``csr_array`` with the columns of :func:`surface_basis`: ``B_uu @ poles.reshape(-1, 3)`` is ``S_uu``
    (m, 3).  Rational surfaces by the quotient rule (weights fixed, so the derivatives are linear in the
    poles); at a knot the span on the larger-parameter side, as :func:`surface_derivative_bases`.
    """
    cols, vals = _surface_rows(surface, u, v, 2)
    n = surface.shape[0] * surface.shape[1]
    return tuple(_cols_to_csr(cols, x, n) for x in vals[3:])


def clip_uv(surface: BSplineSurface, uv: np.ndarray) -> np.ndarray:
    """Parameters ``uv (m, 2)`` clipped to the surface's domain, however far outside (no tolerance check)."""
    u0, u1, v0, v1 = surface.domain
    return np.column_stack([np.clip(uv[:, 0], u0, u1), np.clip(uv[:, 1], v0, v1)])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The cross products ``(..., 3)`` of the rows of ``a`` and ``b`` (``(..., 3)``, broadcast): ``np.cross``
    without its axis handling, which costs several times the products on the short arrays most measures ask."""
    out = np.empty(np.broadcast_shapes(np.shape(a), np.shape(b)))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


#: Fewer rows than this are combined with their poles by a gather and a sum (:func:`_combine`), more by a
#: sparse product: building a sparse matrix costs more than the sum for a few rows, less for many.
_FEW_ROWS = 128


def _combine(cols: np.ndarray, vals: list[np.ndarray], poles: np.ndarray) -> list[np.ndarray]:
    """``B @ poles`` for each fixed-width basis ``B`` of ``vals`` (each ``(m, w)``, the columns ``cols (m, w)``)
    and ``poles (n, d)``: the points or derivatives ``(m, d)``."""
    if len(cols) >= _FEW_ROWS:
        return [_cols_to_csr(cols, x, len(poles)) @ poles for x in vals]
    near = poles[cols]                                                        # (m, w, d)
    return [np.einsum("mw,mwk->mk", x, near) for x in vals]


#: Points a surface evaluation takes at a time (:func:`_by_chunks`): its rows' arrays (the basis, its kron
#: products and their columns, about 0.5 kB a point for bicubic patches) stay in the cache.
EVAL_CHUNK = 16_384


def _by_chunks(evaluate):
    """``evaluate(surface, u, v)`` (rows ``(m, ...)``, or a tuple of them) over chunks of ``EVAL_CHUNK`` to
    ``2 EVAL_CHUNK - 1`` points where ``m`` is larger: the same rows to the bit (each row is worked out on its
    own, and every chunk takes the sparse product of :func:`_combine`), in less time where ``m`` is large."""
    @functools.wraps(evaluate)
    def chunked(surface: BSplineSurface, u, v):
        if max(np.size(u), np.size(v)) < 2 * EVAL_CHUNK:
            return evaluate(surface, u, v)
        uu, vv = _surface_parameters(surface, u, v)
        ends = [EVAL_CHUNK * k for k in range(1, len(uu) // EVAL_CHUNK)] + [len(uu)]
        parts = [evaluate(surface, uu[a:b], vv[a:b]) for a, b in zip([0] + ends[:-1], ends)]
        if isinstance(parts[0], tuple):
            return tuple(np.concatenate(rows) for rows in zip(*parts))
        return np.concatenate(parts)
    return chunked


def evaluate_curve(curve: BSplineCurve, t) -> np.ndarray:
    """Points ``C(t)`` (m, 3) of ``curve`` at parameters ``t`` (m,)."""
    start, (vals,) = _curve_rows(curve, t, 0)
    return _combine(start[:, None] + np.arange(curve.degree + 1), [vals], curve.poles)[0]


def curve_jet(curve: BSplineCurve, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(C, C', C'')``, each (m, 3), of ``curve`` at parameters ``t`` (m,), from one evaluation of the basis
    rows (the derivatives as :func:`curve_derivative_basis` takes them)."""
    start, vals = _curve_rows(curve, t, 2)
    return tuple(_combine(start[:, None] + np.arange(curve.degree + 1), vals, curve.poles))


def polyline_length(points: np.ndarray) -> float:
    """Length of the polyline through ``points (m, 3)`` (the length of a curve sampled densely enough)."""
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


@_by_chunks
def evaluate_surface(surface: BSplineSurface, u, v) -> np.ndarray:
    """Points ``S(u, v)`` (m, 3) of ``surface`` at parameters ``u``, ``v`` (m,)."""
    cols, vals = _surface_rows(surface, u, v, 0)
    return _combine(cols, vals, surface.poles.reshape(-1, 3))[0]


@_by_chunks
def surface_derivatives(surface: BSplineSurface, u, v) -> tuple[np.ndarray, np.ndarray]:
    """First partial derivatives ``(S_u (m, 3), S_v (m, 3))`` at parameters ``u``, ``v`` (m,)."""
    cols, (_, du, dv) = _surface_rows(surface, u, v, 1)
    su, sv = _combine(cols, [du, dv], surface.poles.reshape(-1, 3))
    return su, sv


@_by_chunks
def surface_first_jet(surface: BSplineSurface, u, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points and first partial derivatives ``(S, S_u, S_v)``, each (m, 3), at parameters ``u``, ``v`` (m,):
    :func:`evaluate_surface` and :func:`surface_derivatives` from one evaluation of the basis rows
    (:func:`_combine`; Gauss-Newton's inner loop)."""
    cols, vals = _surface_rows(surface, u, v, 1)
    return tuple(_combine(cols, vals, surface.poles.reshape(-1, 3)))


#: Relative tolerance of :func:`surface_normals`: a first derivative is taken as zero where it is below
#: ``NORMAL_RTOL * sum_i |dB_i| * max |pole|`` (rounding noise of the sum), and the normal as undefined where
#: ``|S_u x S_v| <= NORMAL_RTOL * |S_u| * |S_v|`` (parallel tangents).
NORMAL_RTOL = 1e-12


def _normal_parts(surface: BSplineSurface, u, v):
    """``S_u x S_v`` (m, 3), ``|S_u|``, ``|S_v|`` (m,) and the rounding noise (mm, (m,)) of each derivative's
    sum, ``NORMAL_RTOL * sum_i |dB_i| * max |pole|``."""
    cols, (_, du, dv) = _surface_rows(surface, u, v, 1)
    flat = surface.poles.reshape(-1, 3)
    su, sv = _combine(cols, [du, dv], flat)
    size = float(np.abs(flat).max()) if flat.size else 0.0
    noise_u = NORMAL_RTOL * size * np.abs(du).sum(axis=1)
    noise_v = NORMAL_RTOL * size * np.abs(dv).sum(axis=1)
    return cross(su, sv), np.linalg.norm(su, axis=1), np.linalg.norm(sv, axis=1), noise_u, noise_v


@_by_chunks
def surface_normals(surface: BSplineSurface, u, v) -> np.ndarray:
    """Unit normals ``S_u x S_v / |S_u x S_v|`` (m, 3) at parameters ``u``, ``v`` (m,).

    Rows where the normal is undefined are NaN: where ``S_u`` or ``S_v`` vanishes (a collapsed boundary,
    e.g. the pole of a revolved surface) up to rounding, or where the two are parallel (see
    ``NORMAL_RTOL``).  The caller decides what to do there; :func:`normal_rounding` tells how far rounding
    may turn a normal that is defined.
    """
    return _unit_normals(*_normal_parts(surface, u, v))


def evaluated(evaluate: Callable[[BSplineSurface, np.ndarray, np.ndarray], np.ndarray], surface: BSplineSurface,
              u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``evaluate(surface, u, v)`` (an evaluation of ``surface`` at the parameters ``u``, ``v`` (m,), one array of
    rows ``(m, ...)``, as :func:`surface_normals`), kept in the surface's :class:`BasisMemo` where it has one, by
    ``evaluate``, the surface's content (:meth:`BSplineSurface.digest`) and the parameters: asked again of a
    surface of the same content (the same object, or one made again equal to the bit) at the same parameters, the
    same array comes back, read-only.  ``evaluate`` should be a function of the module level: a closure made
    anew for each call is another key each time."""
    memo = surface.__dict__.get("_memo")
    if memo is None or memo.evaluation_budget <= 0:
        return evaluate(surface, u, v)
    key = (evaluate, surface.digest(), np.asarray(u, float).tobytes(), np.asarray(v, float).tobytes())
    found = memo.evaluation(key)
    if found is None:
        found = evaluate(surface, u, v)
        memo.keep_evaluation(key, found)
    return found


def _unit_normals(nrm: np.ndarray, lu: np.ndarray, lv: np.ndarray, noise_u: np.ndarray, noise_v: np.ndarray
                  ) -> np.ndarray:
    """:func:`surface_normals` of :func:`_normal_parts`."""
    length = np.linalg.norm(nrm, axis=1)
    ok = (lu > noise_u) & (lv > noise_v) & (length > NORMAL_RTOL * lu * lv)
    out = np.full_like(nrm, np.nan)
    out[ok] = nrm[ok] / length[ok, None]
    return out


def _rounding(lu: np.ndarray, lv: np.ndarray, noise_u: np.ndarray, noise_v: np.ndarray) -> np.ndarray:
    """:func:`normal_rounding` of :func:`_normal_parts`."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((lu > 0) & (lv > 0), noise_u / lu + noise_v / lv, np.inf)


@_by_chunks
def normals_and_rounding(surface: BSplineSurface, u, v) -> tuple[np.ndarray, np.ndarray]:
    """:func:`surface_normals` ``(m, 3)`` and :func:`normal_rounding` ``(m,)`` at parameters ``u``, ``v`` (m,) from one
    evaluation of the first derivatives."""
    nrm, lu, lv, noise_u, noise_v = _normal_parts(surface, u, v)
    return _unit_normals(nrm, lu, lv, noise_u, noise_v), _rounding(lu, lv, noise_u, noise_v)


def normal_rounding(surface: BSplineSurface, u, v) -> np.ndarray:
    """How far (radians, (m,)) the rounding of the poles may turn the normal at parameters ``u``, ``v`` (m,):
    each first derivative's rounding noise (:data:`NORMAL_RTOL`, as :func:`surface_normals` takes it) over
    its length, ``noise_u / |S_u| + noise_v / |S_v|``; inf where a derivative vanishes.

    Next to a side that is collapsed all but to rounding the normal is defined but rests on pole differences
    of a few rounding units (a STEP writer's sliver face, one first derivative vanishingly short against the
    other at its corner): there the noise of a fit turns the normal by a large angle close to the corner, and
    this estimate bounds that turn rather than taking the normal for exact.
    """
    _, lu, lv, noise_u, noise_v = _normal_parts(surface, u, v)
    return _rounding(lu, lv, noise_u, noise_v)


def knot_breaks(knots: np.ndarray, degree: int) -> np.ndarray:
    """The distinct knots ``(spans + 1,)`` of the domain of a degree-``degree`` spline on the full knot vector
    ``knots``: the ends of its knot spans."""
    knots = np.asarray(knots, float)
    return np.unique(knots[degree:len(knots) - degree])


def span_cells(breaks: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The cells of a parameter direction and a candidate point in each (for artificial nodes, eq. 39).

    Every knot span ``[breaks[r], breaks[r + 1])`` (``breaks (spans + 1,)``, the distinct knots of the
    domain) is cut into ``degree + 1`` equal cells.  Returns the candidates ``t (m,)``, the centres of the
    cells and the two ends of the domain (``m = spans * (degree + 1) + 2``: at least one per basis function's
    support, more than there are basis functions), the knot span ``(m,)`` and the cell ``(m,)`` of each (an
    end is in the first or the last cell), and the cells' edges ``(spans * (degree + 1) + 1,)``.
    """
    breaks = np.asarray(breaks, float)
    spans, m = len(breaks) - 1, degree + 1
    step = np.diff(breaks)[:, None] / m
    edges = np.append((breaks[:-1, None] + np.arange(m) * step).ravel(), breaks[-1])
    centres = (breaks[:-1, None] + (np.arange(m) + 0.5) * step).ravel()
    t = np.concatenate([breaks[:1], centres, breaks[-1:]])
    span = np.concatenate([[0], np.repeat(np.arange(spans), m), [spans - 1]])
    cell = np.concatenate([[0], np.arange(spans * m), [spans * m - 1]])
    return t, span, cell, edges


# ----------------------------------------------------------------------------------------------------------
# Refinement: knot insertion and degree elevation, exact to rounding (the one copy: hot2cold.pipeline.refine
# refines the morph's records with it, and hot2cold.kernel.rebuild gives the kernel objects the refined
# records' knots and degrees).
# ----------------------------------------------------------------------------------------------------------

def _basis(knots: np.ndarray, degree: int, t: np.ndarray) -> np.ndarray:
    """The dense basis matrix ``(len(t), n)`` of the degree-``degree`` B-splines on ``knots`` at ``t``."""
    n = len(knots) - degree - 1
    return curve_basis(BSplineCurve(np.zeros((n, 3)), knots, degree), t).toarray()


def refinement_matrix(old_knots, old_degree: int, new_knots, new_degree: int) -> np.ndarray:
    """The matrix ``T (n_new, n_old)`` taking B-spline coefficients on ``(old_knots, old_degree)`` to the
    same function on ``(new_knots, new_degree)``, which must hold the old spline space (inserted knots,
    raised degree with every knot's multiplicity raised as much).  Found by collocation at the Greville
    points of the new knots, where the new basis matrix is non-singular (Schoenberg-Whitney)."""
    new_knots = np.asarray(new_knots, float)
    n_new = len(new_knots) - new_degree - 1
    tau = np.array([new_knots[j + 1:j + new_degree + 1].mean() for j in range(n_new)])
    old = _basis(np.asarray(old_knots, float), old_degree, tau)
    return np.linalg.solve(_basis(new_knots, new_degree, tau), old)


def elevated_knots(knots, degree: int, new_degree: int) -> np.ndarray:
    """The knot vector of the degree-``new_degree`` space holding the degree-``degree`` splines on ``knots``:
    every distinct knot's multiplicity raised by ``new_degree - degree``."""
    values, counts = np.unique(np.asarray(knots, float), return_counts=True)
    return np.repeat(values, counts + max(new_degree - degree, 0))


def _homogeneous(poles: np.ndarray, weights: np.ndarray | None) -> np.ndarray:
    """Homogeneous poles ``(..., 4)``: ``(w P, w)`` of poles ``(..., 3)`` and weights ``(...)`` (None: 1)."""
    w = np.ones(poles.shape[:-1]) if weights is None else weights
    return np.concatenate([poles * w[..., None], w[..., None]], axis=-1)


def _with_knots(knots: np.ndarray, degree: int, new_degree: int, inserted) -> np.ndarray:
    return np.sort(np.concatenate([elevated_knots(knots, degree, new_degree), np.asarray(inserted, float)]))


def refine_surface(surface: BSplineSurface, axis: int, inserted=(), degree: int | None = None) -> BSplineSurface:
    """The same surface with its u (``axis`` 0) or v (1) direction raised to ``degree`` (if higher) and the
    knots ``inserted`` added: the one knot refinement and degree elevation of the package.  The poles are
    ``T`` (:func:`refinement_matrix`) times the homogeneous poles ``(w P, w)``, so rational surfaces keep their
    shape; refinement changes the control net, never the geometry (to rounding).  Returns ``surface`` itself
    when nothing is asked."""
    old_knots = surface.u_knots if axis == 0 else surface.v_knots
    old_degree = surface.u_degree if axis == 0 else surface.v_degree
    new_degree = max(old_degree, degree or old_degree)
    knots = _with_knots(old_knots, old_degree, new_degree, inserted)
    if new_degree == old_degree and len(knots) == len(old_knots):
        return surface
    t = refinement_matrix(old_knots, old_degree, knots, new_degree)
    homo = _homogeneous(surface.poles, surface.weights)
    homo = np.einsum("ij,jkl->ikl", t, homo) if axis == 0 else np.einsum("kj,ijl->ikl", t, homo)
    w = homo[..., 3]
    poles, weights = homo[..., :3] / w[..., None], (None if surface.weights is None else w)
    if axis == 0:
        out = BSplineSurface(poles, knots, surface.v_knots, new_degree, surface.v_degree, weights)
    else:
        out = BSplineSurface(poles, surface.u_knots, knots, surface.u_degree, new_degree, weights)
    out.remember(surface.__dict__.get("_memo"))
    return out


def refine_curve(curve: BSplineCurve, inserted=(), degree: int | None = None) -> BSplineCurve:
    """The same curve raised to ``degree`` (if higher) with the knots ``inserted`` added (as
    :func:`refine_surface`)."""
    new_degree = max(curve.degree, degree or curve.degree)
    knots = _with_knots(curve.knots, curve.degree, new_degree, inserted)
    if new_degree == curve.degree and len(knots) == len(curve.knots):
        return curve
    homo = refinement_matrix(curve.knots, curve.degree, knots, new_degree) @ _homogeneous(curve.poles, curve.weights)
    return BSplineCurve(homo[:, :3] / homo[:, 3:], knots, new_degree, None if curve.weights is None else homo[:, 3])


def insert_knots(surface: BSplineSurface, axis: int, knots) -> BSplineSurface:
    """The same surface with ``knots`` (each once) inserted in the u (``axis=0``) or v (``axis=1``) knot
    vector: :func:`refine_surface` without a change of degree, after checking that ``axis`` is 0 or 1 and
    every knot lies inside the domain (ValueError otherwise).
    """
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 (u) or 1 (v), got {axis!r}")
    flat = surface.u_knots if axis == 0 else surface.v_knots
    p = surface.u_degree if axis == 0 else surface.v_degree
    lo, hi = flat[p], flat[len(flat) - p - 1]
    for x in np.sort(np.asarray(knots, float)):
        if not lo < x < hi:
            raise ValueError(f"knot {x} is not inside the domain ({lo}, {hi})")
    return refine_surface(surface, axis, np.asarray(knots, float))


# ----------------------------------------------------------------------------------------------------------
# Second derivatives and curvature (for the curvature pictures of the report, paper Fig. 9 and 11).
# ----------------------------------------------------------------------------------------------------------

def _homogeneous_derivatives(surface: BSplineSurface, u, v) -> list[np.ndarray]:
    """Derivatives of the homogeneous surface ``A = sum w_ij N_i N_j (P_ij, 1)``.

    Returns ``[A, A_u, A_v, A_uu, A_uv, A_vv]``, each (m, 4): columns 0-2 the weighted point part, column 3
    the weight function ``W`` and its derivatives; for a non-rational surface (no weights) each (m, 3), the
    surface's own derivatives (``W = 1``).
    """
    uu, vv = _surface_parameters(surface, u, v)
    p, q = surface.u_degree, surface.v_degree
    nu_, nv_ = surface.shape
    lu, lv = surface.layouts
    su, bu = _span_rows(uu, surface.u_knots, p, 2, lu)
    sv, bv = _span_rows(vv, surface.v_knots, q, 2, lv)
    w = surface.weights
    homo = surface.poles if w is None else np.concatenate([surface.poles * w[..., None], w[..., None]], axis=2)
    width = homo.shape[2]
    # The (p+1) x (q+1) block of homogeneous poles of each row: (m, (p+1) (q+1), width).  (np.take on the flat
    # array gathers many times faster than fancy indexing of the 3-D one.)
    m = len(su)
    flat_index = _net_columns(su, sv, p, q, nv_)
    block = np.take(homo.reshape(-1, width), flat_index, axis=0).reshape(m, p + 1, q + 1, width)
    # summed over v first for the three v-derivatives at once, then over u for each pair
    along_v = np.matmul(np.stack(bv, axis=1)[:, None, :, :], block)                 # (m, p + 1, 3, width)
    return [np.einsum("ma,mak->mk", bu[a], along_v[:, :, b, :])
            for a, b in ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))]


def _quotient_jet(a, a_u, a_v, a_uu, a_uv, a_vv) -> tuple[np.ndarray, ...]:
    """``(S, S_u, S_v, S_uu, S_uv, S_vv)``, each (..., 3), of the homogeneous ``A = (w S, w)`` and its
    derivatives, each (..., 4), by the quotient rule."""
    w, w_u, w_v, w_uu, w_uv, w_vv = (x[..., 3:4] for x in (a, a_u, a_v, a_uu, a_uv, a_vv))
    s = a[..., :3] / w
    s_u = (a_u[..., :3] - w_u * s) / w
    s_v = (a_v[..., :3] - w_v * s) / w
    s_uu = (a_uu[..., :3] - 2.0 * w_u * s_u - w_uu * s) / w
    s_uv = (a_uv[..., :3] - w_u * s_v - w_v * s_u - w_uv * s) / w
    s_vv = (a_vv[..., :3] - 2.0 * w_v * s_v - w_vv * s) / w
    return s, s_u, s_v, s_uu, s_uv, s_vv


@_by_chunks
def surface_jet(surface: BSplineSurface, u, v) -> tuple[np.ndarray, ...]:
    """``(S, S_u, S_v, S_uu, S_uv, S_vv)``, each (m, 3): by the quotient rule on the homogeneous form of a
    rational surface, directly for a non-rational one."""
    derivatives = _homogeneous_derivatives(surface, u, v)
    return tuple(derivatives) if surface.weights is None else _quotient_jet(*derivatives)


def surface_second_derivatives(surface: BSplineSurface, u, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Second partial derivatives ``(S_uu, S_uv, S_vv)``, each (m, 3), at parameters ``u``, ``v`` (m,).

    Rational surfaces are differentiated in homogeneous coordinates ``A = w S``:
    ``S_uu = (A_uu - 2 W_u S_u - W_uu S) / W``, ``S_uv = (A_uv - W_u S_v - W_v S_u - W_uv S) / W``, and
    likewise in v.  At a knot where the surface is only C1 (or C0) the derivative of the span on the
    larger-parameter side is returned, as for :func:`surface_derivatives`.
    """
    return surface_jet(surface, u, v)[3:]


def mean_curvature(surface: BSplineSurface, u, v) -> np.ndarray:
    """Mean curvature ``H`` (m,) in 1/mm at parameters ``u``, ``v`` (m,).

    ``H = (L G - 2 M F + N E) / (2 (E G - F^2))`` with the first (``E, F, G``) and second (``L, M, N``,
    against the unit normal ``S_u x S_v / |S_u x S_v|``) fundamental forms; with that normal a sphere whose
    normal points outward has ``H = -1/R`` (the kernel's ``GeomLProp_SLProps`` sign).  NaN where the normal
    is undefined (see :func:`surface_normals`).
    """
    _, s_u, s_v, s_uu, s_uv, s_vv = surface_jet(surface, u, v)
    normal = surface_normals(surface, u, v)
    e = np.einsum("ij,ij->i", s_u, s_u)
    f = np.einsum("ij,ij->i", s_u, s_v)
    g = np.einsum("ij,ij->i", s_v, s_v)
    l_ = np.einsum("ij,ij->i", s_uu, normal)
    m_ = np.einsum("ij,ij->i", s_uv, normal)
    n_ = np.einsum("ij,ij->i", s_vv, normal)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (l_ * g - 2.0 * m_ * f + n_ * e) / (2.0 * (e * g - f * f))


# ----------------------------------------------------------------------------------------------------------
# Tensor-product grids: every point of u (m_u,) x v (m_v,) as B_u . P . B_v^T (homogeneous, per coordinate),
# m_u + m_v basis rows instead of m_u m_v; and grids dense where the surface bends (Newton's start points).
# ----------------------------------------------------------------------------------------------------------

def _grid_homogeneous(surface: BSplineSurface, u, v, nu: int) -> dict[tuple[int, int], np.ndarray]:
    """The homogeneous surface ``A = sum w_ij N_i(u) N_j(v) (P_ij, 1)`` and its derivatives ``d^(a+b) A /
    du^a dv^b`` for ``a + b <= nu`` on the grid ``u (m_u,) x v (m_v,)`` (parameters in the domain up to
    ``PARAM_RTOL``): ``{(a, b): (m_u, m_v, 4)}``, each ``B_u^(a) . H . B_v^(b)T`` per coordinate with the
    basis matrices ``B_u^(a) (m_u, n_u)``, ``B_v^(b) (m_v, n_v)`` and the homogeneous poles ``H (n_u, n_v, 4)``.
    """
    u0, u1, v0, v1 = surface.domain
    uu, vv = _parameters(u, u0, u1, "u"), _parameters(v, v0, v1, "v")
    n_u, n_v = surface.shape
    lu, lv = surface.layouts
    su, bu = _span_rows(uu, surface.u_knots, surface.u_degree, nu, lu)
    sv, bv = _span_rows(vv, surface.v_knots, surface.v_degree, nu, lv)
    homo = _homogeneous(surface.poles, surface.weights).reshape(n_u, n_v * 4)
    out = {}
    for a in range(nu + 1):
        left = (_to_csr(su, bu[a], n_u) @ homo).reshape(len(uu), n_v, 4)        # (m_u, n_v, 4)
        right = left.transpose(1, 0, 2).reshape(n_v, len(uu) * 4)               # (n_v, m_u * 4)
        for b in range(nu + 1 - a):
            grid = (_to_csr(sv, bv[b], n_v) @ right).reshape(len(vv), len(uu), 4)
            out[a, b] = grid.transpose(1, 0, 2)
    return out


def grid_points(surface: BSplineSurface, u, v) -> np.ndarray:
    """Points ``S(u_i, v_j)`` (m_u, m_v, 3) of ``surface`` on the tensor grid of ``u (m_u,)`` and ``v (m_v,)``:
    :func:`evaluate_surface` at every pair, from ``m_u + m_v`` basis rows (rational surfaces by their
    homogeneous poles)."""
    a = _grid_homogeneous(surface, u, v, 0)[0, 0]
    return a[..., :3] / a[..., 3:]


def grid_jet(surface: BSplineSurface, u, v) -> tuple[np.ndarray, ...]:
    """``(S, S_u, S_v, S_uu, S_uv, S_vv)``, each (m_u, m_v, 3), on the tensor grid of ``u (m_u,)`` and
    ``v (m_v,)``: :func:`surface_jet` at every pair (at a knot, the span on the larger-parameter side)."""
    a = _grid_homogeneous(surface, u, v, 2)
    return _quotient_jet(*(a[k] for k in ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))))


def normal_turn(s_u: np.ndarray, s_v: np.ndarray, s_uu: np.ndarray, s_uv: np.ndarray,
                s_vv: np.ndarray, noise: tuple = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """How fast the unit normal turns along u and along v, in radians per mm of the parameter line (1/mm):
    ``|n_u| / |S_u|`` and ``|n_v| / |S_v|``, each (...), from the first and second derivatives, each
    (..., 3).  On a sphere of radius R both are 1/R; along a straight line of a cylinder, 0.  NaN where the
    normal or a tangent is undefined: a tangent no longer than its rounding ``noise`` (``(noise_u, noise_v)``,
    mm per parameter unit, each broadcast against (...); :func:`tangent_noise`), as at a collapsed side or a
    pole, whose derivatives are rounding and whose rates would be any size, or tangents parallel to
    :data:`NORMAL_RTOL`.

    With ``N = S_u x S_v`` and ``n = N / |N|``: ``n_u = (N_u - (n . N_u) n) / |N|``, ``N_u = S_uu x S_v + S_u x
    S_uv`` (and ``N_v = S_uv x S_v + S_u x S_vv``).
    """
    big_n = cross(s_u, s_v)
    size = np.linalg.norm(big_n, axis=-1, keepdims=True)
    length_u, length_v = np.linalg.norm(s_u, axis=-1), np.linalg.norm(s_v, axis=-1)
    defined = (length_u > noise[0]) & (length_v > noise[1]) & (size[..., 0] > NORMAL_RTOL * length_u * length_v)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = big_n / size
        rates = []
        for d, length in ((cross(s_uu, s_v) + cross(s_u, s_uv), length_u),
                          (cross(s_uv, s_v) + cross(s_u, s_vv), length_v)):
            turn = d - np.sum(n * d, axis=-1, keepdims=True) * n
            rate = np.linalg.norm(turn, axis=-1) / (size[..., 0] * length)
            rates.append(np.where(np.isfinite(rate) & defined, rate, np.nan))
    return rates[0], rates[1]


def tangent_noise(surface: BSplineSurface, axis: int, t: np.ndarray) -> np.ndarray:
    """The rounding ``(m,)`` (mm per parameter unit) of the first derivative along ``axis`` (0: u, 1: v) at the
    parameters ``t (m,)`` of that direction, as :func:`surface_normals` takes it: ``NORMAL_RTOL * sum_i |dB_i| *
    max |pole|`` with the (non-rational) basis of that direction; a tangent no longer is a collapsed one."""
    knots, degree = (surface.u_knots, surface.u_degree) if axis == 0 else (surface.v_knots, surface.v_degree)
    lo, hi = surface.domain[2 * axis:2 * axis + 2]
    rows = _span_rows(_parameters(t, lo, hi, "uv"[axis]), knots, degree, 1, surface.layouts[axis])[1][1]
    return NORMAL_RTOL * float(np.abs(surface.poles).max()) * np.abs(rows).sum(axis=1)


#: Most points of the jet :func:`bend_parameters` evaluates at once (a block of v lines at a time): 2^18 points
#: of 6 derivatives, about 40 MB, however many knot spans the surface has.
BEND_BLOCK = 1 << 18


def _piece_steps(s: np.ndarray, rate: np.ndarray, normal: np.ndarray, spacing: float) -> np.ndarray:
    """Steps each piece wants along the first axis of ``s (k + 1, l, 3)`` (points at the pieces' ends, on l
    lines across), with the turn ``rate (k + 1, l)`` of the normal along that axis and the unit normals
    ``normal (k + 1, l, 3)``: ``L max(1 / spacing, bend)`` (not rounded), the largest over the l lines, (k,)."""
    chord = np.linalg.norm(np.diff(s, axis=0), axis=2)                                   # (k, l)
    with np.errstate(invalid="ignore", divide="ignore"):
        angle = 2.0 * np.arcsin(np.minimum(np.linalg.norm(np.diff(normal, axis=0), axis=2) / 2.0, 1.0))
        bend = np.fmax(np.fmax(rate[:-1], rate[1:]), angle / chord)
        need = chord * np.maximum(1.0 / spacing, np.nan_to_num(bend, nan=0.0, posinf=0.0))
    return np.nan_to_num(np.nanmax(need, axis=1, initial=0.0), nan=0.0)


def bend_parameters(surface: BSplineSurface, box, spacing: float, most: int = 2000
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Parameters ``u (m_u,)`` and ``v (m_v,)`` of a tensor grid over ``box = (u0, u1, v0, v1)`` (within the
    domain) whose neighbouring points lie at most about ``spacing`` mm apart, and closer where the surface
    bends: about its radius of curvature apart across a bend (the normal turning by about a radian from
    point to point), piece by piece of every knot span.

    Each direction is cut at its knots inside the box, every knot span into ``degree + 1`` equal cells
    (:func:`span_cells`) and every cell in two halves, the pieces.  On the grid of the pieces' ends in both
    directions (:func:`grid_jet`, :data:`BEND_BLOCK` points at a time), piece j of u gets ``ceil(L_j max(1 /
    spacing, k_j))`` equal parameter steps, with ``L_j`` its longest chord (mm) and ``k_j`` the fastest turn
    of the normal along u at its ends (:func:`normal_turn`) or between them (the angle between the end
    normals over ``L_j``), over all of v; v likewise.  So a 0.05 mm leading edge makes the few pieces round
    it dense in the direction across it, and nothing else.  Each direction has at most about ``most`` steps
    (more are spread thinner in proportion).  Both ends of the box are among the parameters.
    """
    lo = np.asarray(box, float)[[0, 2]]
    hi = np.asarray(box, float)[[1, 3]]
    ends = []
    for axis, (knots, degree) in enumerate(((surface.u_knots, surface.u_degree),
                                            (surface.v_knots, surface.v_degree))):
        inner = knot_breaks(knots, degree)
        breaks = np.unique(np.concatenate([[lo[axis], hi[axis]],
                                           inner[(inner > lo[axis]) & (inner < hi[axis])]]))
        edges = span_cells(breaks, degree)[3]                  # (cells + 1,)
        ends.append(np.append(np.column_stack([edges[:-1], 0.5 * (edges[:-1] + edges[1:])]).ravel(), edges[-1]))
    need = [np.zeros(len(e) - 1) for e in ends]
    noise_u, noise_v = tangent_noise(surface, 0, ends[0])[:, None], tangent_noise(surface, 1, ends[1])[None, :]
    block = max(1, BEND_BLOCK // len(ends[0]) - 1)            # v pieces per block
    for k0 in range(0, len(ends[1]) - 1, block):
        k1 = min(k0 + block, len(ends[1]) - 1)
        s, s_u, s_v, s_uu, s_uv, s_vv = grid_jet(surface, ends[0], ends[1][k0:k1 + 1])    # (pieces_u + 1, ., 3)
        rate_u, rate_v = normal_turn(s_u, s_v, s_uu, s_uv, s_vv, (noise_u, noise_v[:, k0:k1 + 1]))
        with np.errstate(invalid="ignore", divide="ignore"):
            normal = cross(s_u, s_v)
            normal /= np.linalg.norm(normal, axis=2, keepdims=True)
        normal[np.isnan(rate_u)] = np.nan            # no normal where the turn is undefined (a pole): no angle
        need[0] = np.maximum(need[0], _piece_steps(s, rate_u, normal, spacing))
        need[1][k0:k1] = _piece_steps(*(np.swapaxes(a, 0, 1) for a in (s, rate_v, normal)), spacing)
    out = []
    for e, wanted in zip(ends, need):
        count = np.clip(np.ceil(wanted * (1.0 - 1e-9)), 1, most)                        # (pieces,)
        if count.sum() > most:
            count = np.maximum(1, np.ceil(count * most / count.sum()))
        out.append(cut_intervals(e, count.astype(np.int64)))
    return out[0], out[1]


def cut_intervals(points: np.ndarray, pieces: np.ndarray) -> np.ndarray:
    """``points (n,)`` or ``(n, d)`` with the interval between each pair of neighbours cut into ``pieces (n - 1,)``
    (ints, at least 1) equal parts: ``(sum(pieces) + 1,)`` or ``(sum(pieces) + 1, d)``, the given points among them
    in their order."""
    piece, place = run_places(pieces)
    share = place / pieces[piece]
    if points.ndim > 1:
        share = share[:, None]
    return np.concatenate([points[piece] + share * (points[piece + 1] - points[piece]), points[-1:]])
