"""Artificial nodes: displacements where the FE field has no node (METHOD step 6, paper section 4).

Vertices without a node on them, edge knot spans and face patches ``[U_r, U_r+1) x [V_s, V_s+1)`` without a
node (eq. 39), and the trimmed-away parts of a surface need a displacement to keep the fit well posed; zero
is wrong (paper Fig. 5a).  The paper interpolates or extrapolates barycentrically in the plane of the three
nearest foot points (eq. 40-53).  Here the displacement at a point ``x`` is estimated by local least-squares
polynomials over foot points around it instead:

* a linear fit ``d(x) = a + B (x - c)``.  It reproduces an affine field exactly, as the barycentric rule
  does, but it does not depend on which three points are nearest (three nearly collinear foot points make
  the paper's triangle degenerate and its extrapolation explode), and it averages the noise of many nodes;
* a quadratic correction, weighted by how well the quadratic terms describe the field over the neighbourhood
  (:func:`hot2cold.core.localfit.fits_at`).  A smooth field (thermal strain, an untwist, a span-wise
  stretch) is nearly quadratic at the scale of a part, and the linear fit alone misses its curvature at
  artificial nodes beyond a face's trims by as much as the tolerance, where the quadratic one stays far below
  it.  A real FE field need not be (one clamped at a face is not), and there the correction is left out;
* neighbourhoods that grow with the distance.  The ``k`` nearest foot points of a point far out on a
  trimmed-away part (a blade's hub surface) are a cluster much smaller than that distance, thin across the
  blade, and a fit over them extrapolates its noise and curvature by the ratio of the two: off by a large
  share of the field itself, and the cold surface folds over its trimmed-away part.  A point whose nearest
  foot point is ``rho`` away takes for its linear fit the foot points within ``LINEAR_REACH * rho``, for its
  quadratic one those within ``REACH * rho`` (both thinned to about ``MAX_NEIGHBOURS``), whenever that ball
  holds more than its ``k`` nearest: their spread is then of the order of the extrapolation distance.  The
  quadratic fit needs the wider ball (across a hole in the node set it must reach the far side); the linear
  one, used where the field is not quadratic, stays closer to the point.
"""
from __future__ import annotations

import itertools

import numpy as np

from ..core.arrays import distinct, run_places
from ..core.localfit import fits_at
from ..core.trees import kd_tree

#: A point whose nearest foot point is ``rho`` away fits its quadratic over the foot points within
#: ``REACH * rho`` and its linear fit over those within ``LINEAR_REACH * rho``, when that ball holds more than
#: its ``k`` nearest ones.
REACH, LINEAR_REACH = 3.0, 1.5
#: Most foot points in one wide fit; a larger ball is thinned to a random subset of about this size.
MAX_NEIGHBOURS = 100
#: Fewest neighbours for a quadratic fit (10 coefficients); with fewer the fit is linear (4 coefficients).
_QUADRATIC_MIN = 10


#: A point lies off the span of its neighbourhood when it is farther than this share of the neighbourhood's
#: size from the affine span of the foot points (the directions in which they spread by more than the linear
#: fit's cut-off, :data:`hot2cold.core.localfit.LINEAR_RCOND`).
OFF_SPAN = 1e-9
#: Points (or foot points) whose fits are made together.  A fit's arrays take a few kB a point (for ``k`` of
#: 20: offsets, monomials and their products), so a chunk's arrays are a few MB each.  Smaller chunks cut the
#: page faults of a short run and cost a long one time (docs: the speed page's twenty-second round).
FIT_CHUNK = 4096


class FieldEstimator:
    """Local least-squares estimate (linear, plus a quadratic correction where the field is quadratic) of the
    displacement field from foot points.

    Parameters
    ----------
    points : (n, 3) float array, foot points of the used nodes.
    displacements : (n, 3) float array, their FE displacements.
    neighbours : int, how many nearest foot points an estimate among the data uses (more where the point
        is far from the data, see the module docstring).  With fewer than 10 the fit is linear, with fewer
        than 4 the nearest foot point's displacement is taken.
    tree : a k-d tree over exactly ``points`` the caller has already (:func:`hot2cold.core.trees.kd_tree`),
        or None: one is built.
    """

    def __init__(self, points: np.ndarray, displacements: np.ndarray, neighbours: int = 20, tree=None):
        points = np.asarray(points, float)
        displacements = np.asarray(displacements, float)
        if points.ndim != 2 or points.shape[1] != 3 or displacements.shape != points.shape:
            raise ValueError(f"points and displacements must both be (n, 3), got {points.shape} and "
                             f"{displacements.shape}")
        if len(points) == 0:
            raise ValueError("no foot points to estimate displacements from")
        self._points = points
        self._disp = displacements
        self._k = min(neighbours, len(points))
        self._quadratic = self._k >= _QUADRATIC_MIN
        if tree is not None and tree.n != len(points):
            raise ValueError(f"the tree holds {tree.n} points, but {len(points)} points were given")
        self._tree = kd_tree(points) if tree is None else tree
        # Thinned copies for wide neighbourhoods: level L holds the first n / 2**L foot points of a fixed random
        # order, so each level is a random half of the one before.
        order = np.random.default_rng(0).permutation(len(points))
        self._rank = np.empty(len(points), int)
        self._rank[order] = np.arange(len(points))
        self._memo: dict[bytes, np.ndarray] = {}        # point (its bytes) -> estimate, for remembered()
        self._levels = [(np.arange(len(points)), self._tree)]
        size = len(points) // 2
        while size >= MAX_NEIGHBOURS:
            keep = np.sort(order[:size])
            self._levels.append((keep, kd_tree(points[keep])))
            size //= 2

    def _wide(self, x: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Neighbourhoods ``(m, MAX_NEIGHBOURS)`` (indices, valid mask) of ``x (m, 3)``: the foot points within
        ``radius (m,)``, taken from the densest level that holds at most ``MAX_NEIGHBOURS`` of them (from the
        sparsest level, the first ``MAX_NEIGHBOURS`` of the random order).

        The levels are nested, so a ball holds no fewer foot points on a denser level: the levels are searched
        from the sparsest one on, and a point stops at the first level whose ball holds too many.  Counting
        costs about the number of points counted, so a wide ball (a point far out, where the densest level's
        ball may hold most foot points) costs ``O(MAX_NEIGHBOURS)`` per level rather than ``O(n)``."""
        idx = np.zeros((len(x), MAX_NEIGHBOURS), int)
        valid = np.zeros((len(x), MAX_NEIGHBOURS), bool)
        chosen = np.full(len(x), len(self._levels) - 1)
        pending = np.arange(len(x))
        for level in range(len(self._levels) - 1, -1, -1):
            if not len(pending):
                break
            counts = self._levels[level][1].query_ball_point(x[pending], radius[pending], return_length=True)
            pending = pending[counts <= MAX_NEIGHBOURS]
            chosen[pending] = level
        for level in distinct(chosen):
            keep, tree = self._levels[level]
            rows = np.flatnonzero(chosen == level)
            balls = tree.query_ball_point(x[rows], radius[rows])
            sizes = np.fromiter(map(len, balls), np.int64, count=len(balls))
            found = keep[np.fromiter(itertools.chain.from_iterable(balls), np.int64, count=int(sizes.sum()))]
            # each ball's foot points in the random order (their rank), the first MAX_NEIGHBOURS of it kept
            owner, place = run_places(sizes)
            found = found[np.argsort(owner * len(self._points) + self._rank[found])]
            take = place < MAX_NEIGHBOURS
            idx[rows[owner[take]], place[take]] = found[take]
            valid[rows[owner[take]], place[take]] = True
        return idx, valid

    def __call__(self, x: np.ndarray, chunk: int = FIT_CHUNK) -> np.ndarray:
        """Estimated displacements ``(m, 3)`` at points ``x`` ``(m, 3)``, ``chunk`` points at a time: the linear
        fit plus the trusted share of the quadratic correction (both over the ``k`` nearest foot points, or
        over the wider balls of the module docstring)."""
        x = np.atleast_2d(np.asarray(x, float))
        out = np.empty_like(x)
        if len(x) == 0:
            return out
        if self._k < 4:
            _, idx = self._tree.query(x, k=1)
            return self._disp[np.atleast_1d(idx)].reshape(x.shape)
        for start in range(0, len(x), chunk):
            xs = x[start:start + chunk]
            out[start:start + chunk] = self._estimate(xs, *self._tree.query(xs, k=self._k))
        return out

    def _estimate(self, xs: np.ndarray, dist: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """:meth:`__call__`'s estimates ``(c, 3)`` at ``xs (c, 3)`` from their ``k`` nearest foot points (``dist``,
        ``idx``, each ``(c, k)``, nearest first)."""
        # the fit over the k nearest, where the wide fits below do not take its place: a point far out
        # (an artificial node over a face's trimmed-away part) has both its fits from the wide balls
        wide_linear = LINEAR_REACH * dist[:, 0] > dist[:, -1]
        far, near = np.flatnonzero(wide_linear), np.flatnonzero(~wide_linear)
        linear, correction = np.zeros((len(xs), 3)), np.zeros((len(xs), 3))
        trust, flat = np.zeros(len(xs)), np.zeros(len(xs), bool)
        if len(near):
            linear[near], correction[near], trust[near], flat[near] = fits_at(
                self._points[idx[near]], self._disp[idx[near]], np.ones((len(near), idx.shape[1]), bool), xs[near],
                self._quadratic, OFF_SPAN)
        quadratic = linear + correction
        if len(far):
            wide, valid = self._wide(xs[far], LINEAR_REACH * dist[far, 0])
            fit = fits_at(self._points[wide], self._disp[wide], valid, xs[far], False, OFF_SPAN)
            linear[far], flat[far] = fit.linear, fit.off_span
        far = np.nonzero(REACH * dist[:, 0] > dist[:, -1])[0]
        if self._quadratic and len(far):
            wide, valid = self._wide(xs[far], REACH * dist[far, 0])
            base, correction, trust[far], _ = fits_at(self._points[wide], self._disp[wide], valid, xs[far], True)
            quadratic[far] = base + correction
        out = linear + trust[:, None] * (quadratic - linear)
        flat = np.flatnonzero(flat)
        if len(flat):
            out[flat] = self._spanning(xs[flat])
        return out

    def remembered(self, x: np.ndarray) -> np.ndarray:
        """:meth:`__call__`'s estimates ``(m, 3)`` at ``x (m, 3)``, those at points asked before through this method
        (equal to the bit) from a memo: a face's fit asks for the same points (its artificial nodes, its cells'
        centres, its hot pcurves) each time the face is fitted again on edges moved elsewhere (G1's corners and
        refinement trials).  The same numbers as a call (an estimate does not depend on the points asked with
        it); the memo keeps every point asked, so it is for a fit's few points, not a grid's."""
        x = np.ascontiguousarray(np.atleast_2d(np.asarray(x, float)))
        keys = [row.tobytes() for row in x]
        missing = np.array([i for i, key in enumerate(keys) if key not in self._memo], dtype=int)
        if len(missing):
            for i, estimate in zip(missing, self(x[missing])):
                self._memo[keys[i]] = estimate
        return np.array([self._memo[key] for key in keys]).reshape(x.shape)

    def left_out(self, rows: np.ndarray, chunk: int = FIT_CHUNK) -> np.ndarray:
        """Estimates ``(m, 3)`` at the foot points ``rows (m,)`` (indices into ``points``) from the others,
        ``chunk`` rows at a time: the linear fit plus the trusted share of the quadratic correction over the
        ``k`` nearest foot points but the point itself (:meth:`__call__`'s fit, its wider neighbourhoods
        aside).  How far they miss the points' own displacements tells how well the estimate knows the field at
        a node's spacing from the nodes: little where the field is smooth at that scale, much where it changes
        faster than the nodes resolve (a sharp thermal front, a kink) or scatters."""
        rows = np.asarray(rows, int)
        k = min(self._k + 1, len(self._points))
        if len(rows) == 0 or k < 5:
            return self._nearest_other(rows)
        out = np.empty((len(rows), 3))
        for start in range(0, len(rows), chunk):
            these = rows[start:start + chunk]
            out[start:start + chunk] = self._left_out_fit(these, self._tree.query(self._points[these], k=k)[1])
        return out

    def at_own(self, rows: np.ndarray, chunk: int = FIT_CHUNK) -> tuple[np.ndarray, np.ndarray]:
        """At the foot points ``rows (m,)`` (indices into ``points``): the estimates ``(m, 3)`` that
        :meth:`__call__` gives there (the point among its ``k`` nearest) and those of :meth:`left_out` ``(m,
        3)``, the same numbers from one query of each point's ``k + 1`` nearest (the refinement asks both of
        the same nodes), ``chunk`` rows at a time."""
        rows = np.asarray(rows, int)
        k = min(self._k + 1, len(self._points))
        if len(rows) == 0 or k < 5:
            return self(self._points[rows]).reshape(-1, 3), self._nearest_other(rows)
        own, out = np.empty((len(rows), 3)), np.empty((len(rows), 3))
        for start in range(0, len(rows), chunk):
            these = rows[start:start + chunk]
            x = self._points[these]
            dist, idx = self._tree.query(x, k=k)
            own[start:start + chunk] = self._estimate(x, dist[:, :self._k], idx[:, :self._k])
            out[start:start + chunk] = self._left_out_fit(these, idx)
        return own, out

    def _nearest_other(self, rows: np.ndarray) -> np.ndarray:
        """:meth:`left_out` where there are too few others for a linear fit: the displacements ``(m, 3)`` of the
        nearest other foot point of each of ``rows (m,)``."""
        if len(rows) == 0:
            return np.empty((0, 3))
        _, idx = self._tree.query(self._points[rows], k=min(2, len(self._points)))
        return self._disp[np.reshape(idx, (len(rows), -1))[:, -1]]

    def _left_out_fit(self, rows: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """:meth:`left_out`'s estimates ``(m, 3)`` at ``rows (m,)`` from their nearest foot points ``idx (m, k)``
        (the point itself among them)."""
        valid = idx != rows[:, None]
        valid[valid.all(axis=1), -1] = False        # a duplicate point took its place: drop the farthest
        fit = fits_at(self._points[idx], self._disp[idx], valid, self._points[rows], self._quadratic)
        return fit.linear + fit.trust[:, None] * fit.correction

    def _spanning(self, x: np.ndarray) -> np.ndarray:
        """Estimates ``(m, 3)`` at points ``x (m, 3)`` that lie off the plane or line of their neighbourhood, the
        linear fit plus the trusted share of the quadratic correction as :meth:`__call__`'s: over ever more
        nearest foot points (4, 16, ... times ``k``, thinned to about ``MAX_NEIGHBOURS``) until they span the
        point's direction, else over the widest.

        A flat neighbourhood (the foot points of one planar face, or of a straight edge) says nothing about the
        field's change across it, and the pseudo-inverse takes none: even an affine field is missed at an
        artificial node beside the plane of its nearest foot points, by its gradient across the plane times the
        distance."""
        out = np.empty_like(x)
        pending = np.arange(len(x))
        k = self._k
        while len(pending):
            k = min(4 * k, len(self._points))
            dist, _ = self._tree.query(x[pending], k=k)
            wide, valid = self._wide(x[pending], dist[:, -1] * (1 + 1e-12))
            fit = fits_at(self._points[wide], self._disp[wide], valid, x[pending], self._quadratic, OFF_SPAN)
            out[pending] = fit.linear + fit.trust[:, None] * fit.correction
            if k == len(self._points):
                break
            pending = pending[fit.off_span]
        return out


#: Two points less than this share of the part's diagonal apart are one point: a displacement is carried
#: between them (:func:`carried`) only when they are farther apart.
GAP_SHARE = 1e-12

#: Cut-off factor (eq. 20) of the fits that carry the field's estimate onto all poles of a curve or surface
#: (the priors of the edge and face fits): their points determine every pole, so only rounding is cut (a
#: degree-14 span sampled at the centres of its 15 cells is conditioned about 1e5).
PRIOR_EPSILON = 1e-12


def carried(disp: np.ndarray, at: np.ndarray, to: np.ndarray, estimator: FieldEstimator, gap: float) -> np.ndarray:
    """Displacements ``disp (m, 3)`` at the points ``at (m, 3)`` carried to the points ``to (m, 3)`` by the
    field's change between them, ``disp + estimator(to) - estimator(at)``, where the two are more than ``gap``
    (mm) apart; elsewhere ``disp`` as it is.

    The fits put a displacement where it is wanted: a node's at its foot point (eq. 5, 28), an edge's on the
    face's pcurve, a vertex's at its edges' curve ends, an edge's poles on a face's side row.  Across the part's
    own small gaps between those the field changes by its gradient times the gap; carried, an exactly affine
    field stays exact, and a node's own value (noise included) is kept but for that change."""
    return carried_together([(disp, at, to)], estimator, gap)[0][0]


def carried_together(carries: list[tuple[np.ndarray, np.ndarray, np.ndarray]], estimator: FieldEstimator,
                     gap: float, also: np.ndarray | None = None, remember: bool = False
                     ) -> tuple[list[np.ndarray], np.ndarray | None]:
    """:func:`carried` of each ``(disp (m, 3), at (m, 3), to (m, 3))`` of ``carries``, and the estimate ``(k, 3)``
    at the points ``also (k, 3)`` (None: none), from one call of ``estimator`` for all of them: a call's cost is
    mostly its own where a face asks for a few points along each of its edges.  The same numbers as a call
    each (the estimate at a point does not depend on the others asked with it).  ``remember``: through
    :meth:`FieldEstimator.remembered`."""
    asked, apart = [], []
    for disp, at, to in carries:
        rows = np.linalg.norm(to - at, axis=1) > gap
        apart.append(rows)
        asked += [to[rows], at[rows]]
    if also is not None:
        asked.append(also)
    estimates = estimated(estimator, *asked, remember=remember)
    out = []
    for j, ((disp, _, _), rows) in enumerate(zip(carries, apart)):
        if not rows.any():
            out.append(disp)
            continue
        moved = np.array(disp, float)
        moved[rows] += estimates[2 * j] - estimates[2 * j + 1]
        out.append(moved)
    return out, (estimates[-1] if also is not None else None)


def estimated(estimator: FieldEstimator, *points: np.ndarray, remember: bool = False) -> list[np.ndarray]:
    """``[estimator(p) for p in points]`` (each ``(m_i, 3)`` at ``(m_i, 3)``) from one call of ``estimator``: the
    same numbers (an estimate at a point does not depend on the others asked with it), at a call's cost.
    ``remember``: through :meth:`FieldEstimator.remembered` (a fit's points, asked again when it is made again)."""
    sizes = [len(p) for p in points]
    if not sum(sizes):
        return [np.zeros((n, 3)) for n in sizes]
    together = np.concatenate(points)
    return np.split(estimator.remembered(together) if remember else estimator(together), np.cumsum(sizes)[:-1])


def carry_to_feet(points: np.ndarray, feet: np.ndarray, displacements: np.ndarray, used: np.ndarray,
                  neighbours: int, gap: float) -> np.ndarray:
    """The node displacements ``(N, 3)`` carried (:func:`carried`) from the nodes ``points (N, 3)`` to their foot
    points ``feet (N, 3)``, by the local estimate of :class:`FieldEstimator` over the ``used (N,)`` nodes at their
    own positions.

    A node beside its face or edge (up to ``Settings.node_distance`` and ``edge_distance`` off: a face's node
    near an edge feeds the edge, a mesh's node a little off a curved face) would otherwise move the surface by
    the field's gradient times that offset too much or too little, and even an exactly affine field would not
    be met exactly.  Nodes less than ``gap`` (mm) from their foot point, and unused ones, keep their
    displacement.
    """
    out = np.array(displacements, float)
    off = used & (np.linalg.norm(points - np.where(used[:, None], feet, points), axis=1) > gap)
    if not off.any() or used.sum() < 4:
        return out                      # no estimator built for a field whose nodes sit on their feet
    estimate = FieldEstimator(points[used], displacements[used], neighbours)
    out[off] = carried(out[off], points[off], feet[off], estimate, gap)
    return out


class ElementField:
    """The FE model's own field between its nodes, where a point lies on the FE model's boundary: the shape
    functions of its boundary triangles (:class:`hot2cold.core.elements.SurfaceInterpolator`).

    Where a field brings its elements, this is the reference between the nodes: a local quadratic over the
    nodes smooths over what the elements bend (next to a clamped face, a kink, where a quadratic over the
    neighbours misses the nodes themselves by several times the tolerance).

    Parameters
    ----------
    points : (N, 3) the field's node positions (mm).
    triangles : (T, 3) or (T, 6) its boundary triangles, rows of ``points``.
    displacements : (N, 3) its displacements (mm).
    reach : float, mm: a point farther than this from the boundary is not on it (the node distance).
    strain : float, the field's largest strain (:attr:`hot2cold.pipeline.checks.FieldScale.strain`): a point
        ``g`` mm off the boundary takes its foot point's displacement, up to ``strain * g`` off its own.
    """

    def __init__(self, points: np.ndarray, triangles: np.ndarray, displacements: np.ndarray, reach: float,
                 strain: float):
        from ..core.elements import SurfaceInterpolator

        self._interpolator = SurfaceInterpolator(points, triangles, displacements)
        self.reach, self.strain = float(reach), float(strain)

    def __call__(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For points ``x (m, 3)``: which lie on the boundary ``(m,)`` bool, within ``reach``; their
        displacements ``(k, 3)`` and how far those may be off ``(k,)`` (mm, ``strain`` x distance), ``k`` the
        number on it."""
        tri, st, gap = self._interpolator.locate(x)
        on = gap <= self.reach
        return on, self._interpolator.at(tri[on], st[on]), self.strain * gap[on]
