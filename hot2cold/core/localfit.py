"""Local least-squares polynomials of a vector field over neighbourhoods of points (numpy and scipy only).

Three uses share the monomials, the scaling of the offsets and the linear least squares here:

* :func:`node_fits` (for :mod:`hot2cold.pipeline.invert`): per node, the coefficients of a quadratic (or,
  where the neighbours do not determine one, linear) fit over its nearest nodes, in offsets from the node,
  evaluated later anywhere near it by :func:`evaluate_node_fits`;
* :func:`fits_at` (for :mod:`hot2cold.pipeline.artificial`, in place of the paper's barycentric rule,
  eq. 40-53): the value at a point of a linear fit over a neighbourhood, in offsets from its centroid, plus a
  quadratic correction and the trust in it;
* :func:`scatter` (for the tolerance of :mod:`hot2cold.pipeline.refine`): how far a field's nodes scatter about
  a smooth field, from leave-one-out predictions of quadratics in the surface's tangent plane (with
  terms across it).

The monomials, numbered from 0, are ``1, x, y, z`` (degree 1) and then ``x x, y y, z z, x y, x z, y z``
(degree 2).  Offsets are scaled by each neighbourhood's largest offset component, so the columns are of order
one.  The least squares are pseudo-inverses (batched SVD), never normal equations; the quadratic part of
:func:`fits_at`, whose cut keeps only singular values within 1e3 of the largest, takes its SVD from the
eigen-decomposition of its 6 x 6 Gram matrices (:func:`_right_singular`), and the neighbourhoods' spans
(:class:`Span`) theirs from Jacobi rotations of 3 x 3 Gram matrices, all neighbourhoods at once
(:func:`thin_svd3`; numpy's batched SVD calls LAPACK once per matrix).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from .trees import kd_tree, query

#: Quadratic monomials: products of the coordinate offsets (x x, y y, z z, x y, x z, y z).
PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
#: Relative cut-off of the singular values of a linear fit (pseudo-inverse): a neighbourhood that spreads by
#: less than this share of its size in a direction does not spread in it.  Foot points projected onto a plane
#: lie off it by the projection's rounding; a gradient fitted across that spread is the values' rounding
#: divided by it twice over (the thin singular vector's own error is rounding over the spread), and an
#: estimate beside the plane took it times the distance.  Cut, the gradient across comes from wider
#: neighbourhoods that span it (:meth:`hot2cold.pipeline.artificial.FieldEstimator._spanning`).
LINEAR_RCOND = 1e-6
#: A neighbourhood whose offsets from its centre are all below this share of the centre's size is one point:
#: its offsets are rounding, and a fit over them would take a gradient from noise.
_SAME_POINT = 1e-13
#: A node's quadratic fit is taken where the smallest singular value of its 10 columns is above this share of
#: the largest (see :func:`node_fits`).
NODE_RCOND = 1e-8
#: Relative cut-off of the singular values of the quadratic part of :func:`fits_at`.
QUADRATIC_RCOND = 1e-3
#: The quadratic correction of :func:`fits_at` counts in full where its terms leave less than ``TRUSTED`` of
#: what the linear fit leaves over the neighbourhood (relative rms), not at all where they leave more than
#: ``UNTRUSTED``; in between its weight falls linearly in the logarithm.
TRUSTED, UNTRUSTED = 0.01, 0.1


def _squares(offsets: np.ndarray) -> np.ndarray:
    """The degree-2 monomials ``(..., 6)`` of offsets ``(..., 3)``, in the order of ``PAIRS``."""
    return np.stack([offsets[..., a] * offsets[..., b] for a, b in PAIRS], axis=-1)


def monomials(offsets: np.ndarray, degree: int = 2) -> np.ndarray:
    """The monomials up to ``degree`` (1 or 2) of offsets ``(..., 3)``: ``(..., 4)`` or ``(..., 10)``."""
    cols = [np.ones(offsets.shape[:-1] + (1,)), offsets]
    if degree == 2:
        cols.append(_squares(offsets))
    return np.concatenate(cols, axis=-1)


def offset_scale(offsets: np.ndarray) -> np.ndarray:
    """Per neighbourhood, the largest offset component ``(c,)`` of offsets ``(c, m, 3)`` (1 where all are 0)."""
    scale = np.abs(offsets).max(axis=(1, 2))
    scale[scale == 0] = 1.0
    return scale


def node_fits(points: np.ndarray, values: np.ndarray, neighbours: int,
              chunk: int = 4096, rcond: float = NODE_RCOND) -> tuple[np.ndarray, np.ndarray]:
    """Per node of ``points (N, 3)``, the coefficients ``(N, 10, 3)`` of a least-squares fit of ``values
    (N, 3)`` over its ``neighbours`` nearest nodes, in offsets from the node scaled by ``scale (N,)``
    (returned as ``(coef, scale)``).

    The fit is quadratic where the neighbours determine a quadratic (three or more layers in every
    direction: the smallest singular value of the 10 columns above ``rcond`` times the largest), else linear
    (quadratic coefficients zero): a minimum-norm quadratic fit over two layers of nodes would share the
    normal derivative between the linear and the quadratic term and get it wrong.
    """
    k = min(neighbours, len(points))
    tree = cKDTree(points)
    coef = np.zeros((len(points), 10, 3))
    scale = np.ones(len(points))
    for start in range(0, len(points), chunk):
        xs = points[start:start + chunk]
        _, idx = tree.query(xs, k=k)
        idx = idx.reshape(len(xs), k)
        offsets = points[idx] - xs[:, None, :]
        s = offset_scale(offsets)
        features = monomials(offsets / s[:, None, None])
        sigma = np.linalg.svd(features, compute_uv=False)
        quadratic = sigma[:, -1] > rcond * sigma[:, 0]
        block = np.zeros((len(xs), 10, 3))
        if quadratic.any():
            block[quadratic] = np.linalg.pinv(features[quadratic]) @ values[idx[quadratic]]
        if (~quadratic).any():
            block[~quadratic, :4] = (np.linalg.pinv(features[~quadratic, :, :4], rcond=LINEAR_RCOND)
                                     @ values[idx[~quadratic]])
        coef[start:start + chunk] = block
        scale[start:start + chunk] = s
    return coef, scale


def evaluate_node_fits(coef: np.ndarray, scale: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """The fits of :func:`node_fits` (``coef (N, 10, 3)``, ``scale (N,)``) at ``offsets (N, 3)`` from their
    nodes: ``(N, 3)``."""
    return np.einsum("nf,nfc->nc", monomials(offsets / scale[:, None]), coef)


def _masked(valid: np.ndarray):
    """``mask(x)``: the rows ``(c, m, ...)`` of ``x`` where ``valid (c, m)`` is False set to 0 (by multiplying them
    by 0, the others by 1); where every row is valid, ``x`` itself (a pass over the arrays spared).  The weights
    are repeated along the last axis of ``x`` (once per width): a product of arrays of one shape runs several
    times faster than one broadcast along an axis of three or four, the same products."""
    if valid.all():
        return lambda x: x
    weights = valid[..., None].astype(float)
    repeated: dict[int, np.ndarray] = {}

    def mask(x: np.ndarray) -> np.ndarray:
        width = x.shape[-1]
        if width not in repeated:
            repeated[width] = np.repeat(weights, width, axis=-1)
        return x * repeated[width]
    return mask


def _row_sums(x: np.ndarray) -> np.ndarray:
    """``x.sum(axis=1)`` of ``x (c, m, k)``: ``(c, k)``, by ``einsum``, which runs several times faster where
    the last axis is this short.  Both add the ``m`` rows one after another: the sums are the same to the bit
    on the neighbourhoods measured (docs: the speed page's eighteenth round)."""
    return np.einsum("cmk->ck", x)


class Span(NamedTuple):
    """The spread of neighbourhoods ``(c, m, 3)`` about their centroids, from one batched SVD: ``centre (c,
    3)``, ``count (c,)`` the rows taken, ``scale (c,)`` (:func:`offset_scale`), the scaled offsets ``(c, m,
    3)`` (zero rows left out) and their thin SVD ``u (c, m, 3)``, ``sigma (c, 3)``, ``vt (c, 3, 3)``."""

    centre: np.ndarray
    count: np.ndarray
    scale: np.ndarray
    offsets: np.ndarray
    u: np.ndarray
    sigma: np.ndarray
    vt: np.ndarray

    @classmethod
    def of(cls, points: np.ndarray, valid: np.ndarray) -> Span:
        """The span of ``points (c, m, 3)``, rows where ``valid (c, m)`` is False left out."""
        mask = _masked(valid)
        count = np.maximum(valid.sum(axis=1), 1)
        centre = _row_sums(mask(points)) / count[:, None]
        offsets = mask(points - centre[:, None, :])
        # centred again, so that they sum to zero to their own rounding (not the positions'): the column of
        # ones stays orthogonal to them however small the neighbourhood (linear_pinv relies on it)
        shift = _row_sums(offsets) / count[:, None]
        centre = centre + shift
        offsets = mask(offsets - shift[:, None, :])
        # a neighbourhood that spreads by no more than the rounding of its positions is one point
        size = np.abs(offsets).max(axis=(1, 2))
        offsets[size <= _SAME_POINT * np.abs(centre).max(axis=1)] = 0.0
        scale = offset_scale(offsets)
        offsets = offsets / scale[:, None, None]
        u, sigma, vt = thin_svd3(offsets)
        return cls(centre, count, scale, offsets, u, sigma, vt)

    def off(self, x: np.ndarray, share: float) -> np.ndarray:
        """``(c,)`` bool: which points ``x (c, 3)`` lie farther than ``share`` of the neighbourhood's size
        (its largest singular value) off its affine span, the directions in which it spreads by more than
        ``LINEAR_RCOND`` of that size."""
        at = (x - self.centre) / self.scale[:, None]
        flat = self.sigma <= LINEAR_RCOND * self.sigma[:, :1]
        along = np.einsum("cj,ckj->ck", at, self.vt) * flat                       # components off the span
        return np.linalg.norm(along, axis=1) > share * np.maximum(self.sigma[:, 0], 1e-300)

    def linear_pinv(self, valid: np.ndarray) -> np.ndarray:
        """The pseudo-inverse ``(c, 4, m)`` of the linear monomials ``[1, offsets]`` of the rows ``valid (c,
        m)`` (zero rows elsewhere), singular values below ``LINEAR_RCOND`` of the largest cut.  The column of
        ones is orthogonal to the centred offsets, so its singular value is ``sqrt(count)`` and its row of the
        pseudo-inverse is the mean; the offsets' part is ``V diag(1 / sigma) U^T`` from the span's SVD."""
        top = np.maximum(np.sqrt(self.count), self.sigma[:, 0])
        keep = self.sigma > LINEAR_RCOND * top[:, None]
        inverse = np.where(keep, 1.0 / np.where(keep, self.sigma, 1.0), 0.0)      # (c, 3)
        mean = valid / self.count[:, None]                                         # (c, m)
        weighted = self.vt.transpose(0, 2, 1) * inverse[:, None, :]                # (c, 3, 3): V diag(1 / sigma)
        return np.concatenate([mean[:, None, :], np.matmul(weighted, self.u.transpose(0, 2, 1))], axis=1)


class LocalFit(NamedTuple):
    """What :func:`fits_at` gives at each point: the linear fit's value ``linear (c, 3)``, the quadratic
    ``correction (c, 3)`` to it, the ``trust (c,)`` in 0..1 of that correction, and (when asked for) whether
    the point lies ``off_span (c,)`` of its neighbourhood (:meth:`Span.off`), else None."""

    linear: np.ndarray
    correction: np.ndarray
    trust: np.ndarray
    off_span: np.ndarray | None = None


def fits_at(points: np.ndarray, values: np.ndarray, valid: np.ndarray, x: np.ndarray,
            quadratic: bool, span_share: float | None = None) -> LocalFit:
    """Least-squares polynomials over the neighbourhoods ``points (c, m, 3)`` with ``values (c, m, 3)``, rows
    where ``valid (c, m)`` is False left out, at ``x (c, 3)``: a :class:`LocalFit` of the linear fit's value
    ``(c, 3)``, the quadratic correction to it ``(c, 3)`` (zero if not ``quadratic``) and the trust ``(c,)`` in
    0..1 of that correction; with ``span_share``, also which points lie off their neighbourhood's span by
    more than that share of its size (from the same SVD).

    Offsets are taken from each neighbourhood's centroid and scaled to at most 1.  The linear part is fitted
    first, by the pseudo-inverse (batched SVD of the centred offsets, :class:`Span`): foot points on a plane
    make it rank-deficient, and the pseudo-inverse then gives no gradient across the plane.  The quadratic
    terms, made orthogonal to the linear ones, then fit what the linear part leaves (together the two steps
    are the least-squares quadratic, Frisch-Waugh-Lovell), with their own cut-off ``QUADRATIC_RCOND``: foot
    points along a curve or on a nearly flat patch leave some quadratic combinations barely determined, and
    those are dropped rather than fitted to rounding.  An affine field leaves nothing to the quadratic terms,
    so it is reproduced exactly.

    The quadratic correction is trusted only as far as the field is quadratic over the neighbourhood: the
    trust is 1 where the quadratic terms leave less than ``TRUSTED`` of the linear fit's residual (rms), 0
    where they leave more than ``UNTRUSTED``.  Smooth analytic fields (an untwist, a stretch, bending) leave
    a small fraction of a per cent over the neighbourhoods of the artificial nodes; an FE field next to a
    clamped face leaves far more, and its quadratic terms, extrapolated over a trimmed-away part of the clamped
    face, would move points that the clamp and every node on it hold still.
    """
    span = Span.of(points, valid)
    mask = _masked(valid)
    offsets = span.offsets
    at = (x - span.centre) / span.scale[:, None]
    values = mask(values)
    linear = mask(monomials(offsets, 1))                                         # (c, m, 4)
    linear_pinv = span.linear_pinv(valid.astype(float))                         # (c, 4, m)
    coef = linear_pinv @ values                                                 # (c, 4, 3)
    at_linear = monomials(at, 1)                                                # (c, 4)
    out = np.einsum("ct,ctj->cj", at_linear, coef)
    off = None if span_share is None else span.off(x, span_share)
    if not quadratic:
        return LocalFit(out, np.zeros_like(out), np.zeros(len(out)), off)
    square = _squares(offsets)                                                  # (c, m, 6)
    carried = linear_pinv @ square                                              # (c, 4, 6)
    square = square - linear @ carried                                          # orthogonal to the linear part
    at_square = _squares(at) - np.einsum("ct,cts->cs", at_linear, carried)
    residual = values - linear @ coef                                           # (c, m, 3)
    sigma, v = _right_singular(square)                                          # (c, 6), (c, 6, 6)
    keep = sigma > QUADRATIC_RCOND * sigma[:, :1]
    inverse = np.where(keep, 1.0 / np.where(keep, sigma, 1.0), 0.0)             # (c, 6)
    gain = np.einsum("cs,csj->cj", at_square, v) * inverse                      # (c, 6)
    # the residual on the left singular vectors square v_j / sigma_j, without forming them
    projected = np.matmul(v.transpose(0, 2, 1), np.matmul(square.transpose(0, 2, 1), residual)) * inverse[..., None]
    before = (residual ** 2).sum(axis=(1, 2))
    left = np.sqrt(np.maximum(before - (projected ** 2).sum(axis=(1, 2)), 0.0) / np.maximum(before, 1e-300))
    trust = np.clip(np.log(UNTRUSTED / np.maximum(left, 1e-300)) / np.log(UNTRUSTED / TRUSTED), 0.0, 1.0)
    return LocalFit(out, np.einsum("cj,cjk->ck", gain, projected), trust, off)


def thin_svd3(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The thin SVD of many ``m x 3`` matrices ``a (c, m, 3)``: ``u (c, m, 3)``, ``sigma (c, 3)`` (descending) and
    ``vt (c, 3, 3)``, as ``np.linalg.svd(a, full_matrices=False)`` gives them up to the signs of the singular
    vectors (and their choice within a repeated singular value); singular values within rounding of each other
    may come in either order.

    The right singular vectors are the eigenvectors of the 3 x 3 Gram matrices ``a^T a`` (:func:`sym_eig3`,
    vectorised over ``c``); the singular values are the norms of the columns of ``a v`` and ``u`` those columns
    normalised (zero for a zero singular value), not the square roots of the eigenvalues, so a small singular
    value is as accurate as the vector: to the rounding of the largest, as LAPACK's.  numpy's batched SVD calls
    LAPACK once per matrix, which for matrices this small is mostly the call itself."""
    lam, v = sym_eig3(np.matmul(a.transpose(0, 2, 1), a))
    v = np.take_along_axis(v, np.argsort(-lam, axis=1, kind="stable")[:, None, :], axis=2)
    b = np.matmul(a, v)                                                         # (c, m, 3): u sigma
    sigma = np.sqrt(np.einsum("cmj,cmj->cj", b, b))
    u = b / np.where(sigma > 0.0, sigma, 1.0)[:, None, :]
    return u, sigma, v.transpose(0, 2, 1)


#: Sweeps of :func:`sym_eig3` at most; three to four reach the rounding of symmetric 3 x 3 matrices.
_JACOBI_SWEEPS = 12


def sym_eig3(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The eigenvalues ``(c, 3)`` (in no order) and eigenvectors ``(c, 3, 3)`` (column ``j`` for value ``j``) of
    many symmetric positive semi-definite 3 x 3 matrices ``g (c, 3, 3)``, by cyclic Jacobi rotations, each
    rotation applied to all matrices at once.

    A pair ``(p, q)`` is rotated in a matrix while ``|g_pq| > eps sqrt(g_pp g_qq)`` (the relative criterion of
    Demmel and Veselic: small eigenvalues of graded matrices come out to their own relative accuracy), the
    sweeps stop when no matrix has such a pair."""
    g = np.asarray(g, float)
    a = {(i, j): g[:, i, j].copy() for i in range(3) for j in range(i, 3)}
    v = np.zeros((3, 3, len(g)))                # v[i, j]: row i of eigenvector j, all matrices at once
    v[[0, 1, 2], [0, 1, 2]] = 1.0
    eps = np.finfo(float).eps
    for _ in range(_JACOBI_SWEEPS):
        rotated = False
        for p, q in ((0, 1), (0, 2), (1, 2)):
            apq = a[p, q]
            turn = np.abs(apq) > eps * np.sqrt(np.abs(a[p, p] * a[q, q]))
            if not turn.any():
                continue
            rotated = True
            # tan of the angle that zeroes g_pq, the smaller root of t^2 + 2 t (g_qq - g_pp) / (2 g_pq) = 1,
            # written without that quotient and without np.hypot (slow); 0 where the pair is not turned
            d = a[q, q] - a[p, p]
            t = np.divide(2.0 * apq * np.copysign(1.0, d), np.abs(d) + np.sqrt(d * d + 4.0 * apq * apq),
                          out=np.zeros_like(apq), where=turn)
            cos = 1.0 / np.sqrt(t * t + 1.0)
            sin = t * cos
            a[p, p] = a[p, p] - t * apq
            a[q, q] = a[q, q] + t * apq
            a[p, q] = apq * ~turn
            r = 3 - p - q                                                       # the third row and column
            rp, rq = (min(r, p), max(r, p)), (min(r, q), max(r, q))
            arp, arq = a[rp], a[rq]
            a[rp], a[rq] = cos * arp - sin * arq, sin * arp + cos * arq
            vp, vq = v[:, p], v[:, q]                                           # (3, c) each: every row at once
            v[:, p], v[:, q] = cos * vp - sin * vq, sin * vp + cos * vq
        if not rotated:
            break
    values = np.stack([a[0, 0], a[1, 1], a[2, 2]], axis=1)
    vectors = v.transpose(2, 0, 1).copy()
    return values, vectors


def _right_singular(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The singular values ``(c, k)`` (descending) and right singular vectors ``(c, k, k)`` (column ``j`` for
    value ``j``) of ``a (c, m, k)``, from the eigen-decomposition of ``a^T a``: for the quadratic part of
    :func:`fits_at`, whose cut (``QUADRATIC_RCOND``) keeps singular values within 1e3 of the largest, so the
    squared condition of what is kept (1e6) loses nothing of double precision; a batched eigen-decomposition of
    6 x 6 matrices costs about a third of a batched SVD of the ``m x 6`` ones."""
    lam, v = np.linalg.eigh(np.matmul(a.transpose(0, 2, 1), a))              # ascending
    return np.sqrt(np.maximum(lam[:, ::-1], 0.0)), v[:, :, ::-1]


#: The median of the chi-square distribution with 3 degrees of freedom: ``|r|^2 / sigma^2`` of a vector ``r``
#: of three independent normal components with standard deviation ``sigma`` is below it half of the time.
_CHI2_3_MEDIAN = 2.365974


def scatter(points: np.ndarray, values: np.ndarray, groups: list[np.ndarray] | None = None,
            neighbours: int = 20, samples: int = 4000, seed: int = 0) -> float:
    """The standard deviation (per component, same unit as ``values``) with which the field ``values (N, 3)``
    at ``points (N, 3)`` on a surface scatters about a smooth field: 0 for a smooth field, sigma for one with
    independent normal noise of standard deviation sigma on each component.

    ``groups`` are index arrays of points on one smooth piece of surface each (the nodes of one face: a
    neighbourhood that reached across a thin wall would see the field's change through the wall as scatter);
    None: all points are one group.  In each group of more than ``neighbours`` points, at a seeded random
    share of ``samples`` of them, the value is predicted from the ``neighbours`` nearest other points of the
    group by least squares, leaving the point itself out: a quadratic in the two directions of their tangent
    plane (the two largest principal directions of their offsets, ``s`` and ``t``), plus the offset ``n`` across
    it and its products ``s n``, ``t n``.  A smooth field is a smooth function of the surface's coordinates, so
    the quadratic misses it only by its third-order terms over the neighbourhood; the terms in ``n`` take the
    field's change through the part where one face's neighbourhood holds nodes of both sides of a thin wall
    (a blade's face wrapped round its leading edge), which the quadratic alone took as scatter.  Noise it
    misses by the point's own noise plus the prediction's, ``r = e_0 - a . e``, whose variance is
    ``sigma^2 (1 + |a|^2)`` per component with ``a`` the prediction's weights.  The estimate is the median of
    ``|r|^2 / (1 + |a|^2)`` over the points, divided by the median of a chi-square with three degrees of
    freedom: robust to the points where the field has a kink (a clamped root) or the surface a crease, as
    long as those are fewer than half.  0 when no group has more than ``neighbours`` points.
    """
    points = np.asarray(points, float)
    values = np.asarray(values, float)
    if points.ndim != 2 or points.shape[1] != 3 or values.shape != points.shape:
        raise ValueError(f"points and values must both be (N, 3), got {points.shape} and {values.shape}")
    if groups is None:
        groups = [np.arange(len(points))]
    groups = [np.asarray(g, int) for g in groups if len(g) > neighbours]
    total = sum(len(g) for g in groups)
    if not total:
        return 0.0
    rng = np.random.default_rng(seed)
    z = [_left_out(points[g], values[g], rng.choice(len(g), size=max(1, min(len(g), samples * len(g) // total)),
                                                    replace=False), neighbours) for g in groups]
    return float(np.sqrt(np.median(np.concatenate(z)) / _CHI2_3_MEDIAN))


def _left_out(points: np.ndarray, values: np.ndarray, at: np.ndarray, neighbours: int) -> np.ndarray:
    """``|r|^2 / (1 + |a|^2)`` ``(c,)`` of :func:`scatter` at the points ``at (c,)`` of ``points (n, 3)``."""
    # the quick build: a face's hundreds of thousands of nodes for a few thousand queries
    _, idx = query(kd_tree(points), points[at], k=neighbours + 1)
    idx = idx[:, 1:]                                                            # the point itself left out
    offsets = points[idx] - points[at][:, None, :]                              # (c, k, 3)
    centred = offsets - offsets.mean(axis=1, keepdims=True)
    _, _, vt = thin_svd3(centred)                                               # (c, 3, 3)
    stn = np.einsum("ckj,caj->cka", offsets, vt)                                # (c, k, 3), the point at 0
    stn = stn / np.maximum(np.abs(stn[..., :2]).max(axis=(1, 2)), 1e-300)[:, None, None]
    s, t, n = stn[..., 0], stn[..., 1], stn[..., 2]
    features = np.stack([np.ones_like(s), s, t, s * s, s * t, t * t, n, s * n, t * n], axis=-1)  # (c, k, 9)
    weights = np.linalg.pinv(features, rcond=NODE_RCOND)[:, 0, :]              # (c, k): the value at the point
    r = values[at] - np.einsum("ck,ckj->cj", weights, values[idx])
    return np.sum(r * r, axis=1) / (1.0 + np.sum(weights * weights, axis=1))
