"""A face's trimmed domain as a raster, to tell inside from outside for many parameter pairs at once.

The kernel's ``BRepTopAdaptor_FClass2d`` answers one ``(u, v)`` at a time, a kernel call each.  Classifying a
million foot points, or the artificial-node candidates of a finely trimmed face, one by one is too slow, but
almost every point is far from the boundary.  So the face's parameter box is cut into ``n x n`` cells:

* cells the boundary passes through, and their neighbours, are *near*; every other cell lies wholly inside or
  wholly outside, and its state is that of its centre, found by the even-odd rule along the cell row (a scan
  line crossing the boundary polylines);
* a point in a near cell is decided by the polylines themselves: its centre's state, changed at each boundary
  segment the straight line from the centre to the point crosses.  That is the boundary's answer where the
  point lies farther from every segment than the boundary curve can be from it (each segment's *margin*: a
  multiple of the curve's distance from the segment at its middle, plus the kernel's tolerance); a point
  closer than that, near a polyline's end (a face's vertex, :data:`END_REACH`), or whose line passes a vertex
  or a gap between two polylines, is UNSURE, for the kernel; so is a point in a near cell outside the box;
* a point within half the kernel's tolerance of the boundary curve (of a polyline's vertex, which lies on it,
  or of a segment the curve cannot be farther from than that) is on the boundary, as the kernel would say.

The boundary is given as polylines of the face's pcurves (``(m, 2)`` arrays, one per edge use, any order and
orientation); they must follow the pcurves to well within a cell (the kernel samples them so), and the curves
at the segments' middle parameters give the margins.  A point farther than one cell outside the box is outside.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from .arrays import run_places
from .trees import kd_tree


class Trim(IntEnum):
    """Where a parameter pair lies in a face's trimmed domain: one numbering for the raster here and the
    kernel's classification (:meth:`hot2cold.kernel.project.Projector.classify`), so a value means the
    same state everywhere.

    The raster answers INSIDE, OUTSIDE or UNSURE (a point for the kernel to classify); the kernel answers
    INSIDE, ON_BOUNDARY or OUTSIDE.  An ``int`` enum: state arrays stay int arrays.
    """

    INSIDE = 0
    ON_BOUNDARY = 1
    OUTSIDE = 2
    UNSURE = 3


#: A boundary segment's margin is this many times the boundary curve's distance from the segment at its middle
#: parameter (a smooth arc is farthest from its chord near its middle; the factor covers an arc that turns
#: within its segment), plus the kernel's tolerance ...
MARGIN_FACTOR = 4.0
#: ... plus this share of a cell (the rounding of the cell units, many orders of magnitude below it).  A point
#: this close to a cell's centre line through a polyline's vertex is left to the kernel too.
MARGIN_FLOOR = 1e-6
#: Around the polylines' ends (the face's vertices) the kernel's classification says ON_BOUNDARY farther out
#: than its tolerance along the edges (up to 100 times it, seen on corpus parts): points within this many
#: tolerances of an end, or of the gap there, are the kernel's.
END_REACH = 1000.0
#: A segment whose margin, or an end whose reach, is wider than this many cells (a pcurve far from its polyline, a
#: wire with a wide gap) leaves every cell it comes near to the kernel: listing it in each would cost memory as
#: the square of its width.
WALK_MOST = 2.0


@dataclass(frozen=True, eq=False)
class DomainRaster:
    """The trimmed domain of one face on an ``n x n`` grid of cells over ``box``, with the boundary's segments
    to decide the points in the cells next to it.

    Attributes
    ----------
    box : (4,) float, ``(u0, u1, v0, v1)``.
    state : (n, n) int8, Trim.INSIDE, Trim.OUTSIDE or Trim.UNSURE (next to the boundary) per cell (first index
        u, second v).
    centre : (n, n) bool, the even-odd state of each cell's centre (True inside).
    start, end : (s, 2) float, the boundary's segments in cell units (``(u - u0) n / (u1 - u0)``, likewise v).
    deviation : (s,) float, how far (cell units) the boundary curve may be from each segment.
    margin : (s,) float, how near (cell units) a point may come to a segment before only the kernel decides it.
    ends : (g, 2) float, the polylines' end points in cell units; ``reach`` (g,) how near a point, or a centre's
        line to it, may come to one before only the kernel decides: the boundary's gap there (to the nearest end
        of another polyline) plus :data:`END_REACH` tolerances.
    on : float, a point this near (cell units) the boundary curve (a segment's end, or a segment plus its
        deviation) is on the boundary.
    cells, items : (k,) int, sorted cell numbers (``i n + j``) and what lies there: a segment ``0 <= item < s``,
        within its margin, or an end ``s + e``, within its reach.
    kernel : (n, n) bool, the cells whose points are the kernel's alone (a segment or end wider than
        :data:`WALK_MOST` comes near them).
    """

    box: np.ndarray
    state: np.ndarray
    centre: np.ndarray
    start: np.ndarray
    end: np.ndarray
    deviation: np.ndarray
    margin: np.ndarray
    ends: np.ndarray
    reach: np.ndarray
    on: float
    cells: np.ndarray
    items: np.ndarray
    kernel: np.ndarray

    @classmethod
    def build(cls, polylines: list[np.ndarray], box, n: int = 512, midpoints: list[np.ndarray] | None = None,
              tolerance: float = 0.0) -> "DomainRaster":
        """Raster of the region bounded by ``polylines`` (each (m, 2) in (u, v)) within ``box``.

        ``midpoints`` (each (m - 1, 2), one per polyline) are the boundary curves at the middle parameter of each
        segment: their distances from the segments set the margins; without them the polylines are the boundary
        (a polygon).  ``tolerance`` (parameter units) is the kernel's: a point within it of the boundary is on it.
        """
        box = np.asarray(box, dtype=float)
        u0, u1, v0, v1 = box
        if not (u1 > u0 and v1 > v0):
            raise ValueError(f"empty parameter box {box}")
        if midpoints is not None and len(midpoints) != len(polylines):
            raise ValueError(f"{len(midpoints)} midpoint arrays for {len(polylines)} polylines")
        keep = [k for k, p in enumerate(polylines) if len(p) >= 2]
        if not keep:
            raise ValueError("no boundary polylines")
        # Boundary polylines in cell units.
        scale = np.array([n / (u1 - u0), n / (v1 - v0)])
        lines = [(np.asarray(polylines[k], dtype=float) - box[[0, 2]]) * scale for k in keep]
        a = np.concatenate([p[:-1] for p in lines])
        b = np.concatenate([p[1:] for p in lines])
        if midpoints is None:
            middle = 0.5 * (a + b)
        else:
            middle = [(np.asarray(midpoints[k], dtype=float).reshape(-1, 2) - box[[0, 2]]) * scale for k in keep]
            for k, m, p in zip(keep, middle, lines):
                if len(m) != len(p) - 1:
                    raise ValueError(f"polyline {k}: {len(m)} midpoints for {len(p) - 1} segments")
            middle = np.concatenate(middle)
        tol = float(tolerance * np.max(scale))          # (cells are not square: the wider bound for margins,
        on = float(0.5 * tolerance * np.min(scale))      # the narrower for ON)

        centre = _centre_states(a, b, n)
        state = np.where(centre, Trim.INSIDE, Trim.OUTSIDE).astype(np.int8)
        state[_near_cells(a, b, n)] = Trim.UNSURE

        # What the near cells' points are decided by: the segments within their margins and the polylines'
        # ends within their reach, listed per cell they come near.
        deviation = MARGIN_FACTOR * _to_segments(middle, a, b)
        margin = deviation + tol + MARGIN_FLOOR
        ends = np.concatenate([p[[0, -1]] for p in lines])
        reach = _gaps(ends) + END_REACH * tol + MARGIN_FLOOR
        lo = np.concatenate([np.minimum(a, b) - margin[:, None], ends - reach[:, None]])
        hi = np.concatenate([np.maximum(a, b) + margin[:, None], ends + reach[:, None]])
        wide = np.concatenate([margin, reach]) > WALK_MOST
        cells, items = _cells_under(lo[~wide], hi[~wide], n)
        items = np.flatnonzero(~wide)[items]
        kernel = _cells_covered(lo[wide], hi[wide], n)
        state.reshape(-1)[cells] = Trim.UNSURE          # (a margin may reach past the cells grown above)
        state[kernel] = Trim.UNSURE
        return cls(box, state, centre, a, b, deviation, margin, ends, reach, on, cells, items, kernel)

    def classify(self, uv: np.ndarray) -> np.ndarray:
        """State ``(m,)`` int8 (Trim.INSIDE, Trim.ON_BOUNDARY, Trim.OUTSIDE or Trim.UNSURE) of parameter pairs
        ``uv`` ``(m, 2)``; NaN rows are OUTSIDE."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        n = self.state.shape[0]
        u0, u1, v0, v1 = self.box
        cu = (uv[:, 0] - u0) * (n / (u1 - u0))
        cv = (uv[:, 1] - v0) * (n / (v1 - v0))
        out = np.full(len(uv), Trim.OUTSIDE, np.int8)
        finite = np.isfinite(cu) & np.isfinite(cv)
        # Up to one cell outside the box: the border cell decides (it is UNSURE where the boundary runs on
        # the box's edge, and the point the kernel's: on a periodic surface it takes the point into the period,
        # so a point just across a seam may be inside); farther out: outside.  A point on the box's far sides
        # (u = u1 or v = v1, where grids over the box end) lies in its last cell, which decides it as any other.
        near = np.flatnonzero(finite & (cu >= -1) & (cu < n + 1) & (cv >= -1) & (cv < n + 1))
        i = np.clip(np.floor(cu[near]).astype(int), 0, n - 1)
        j = np.clip(np.floor(cv[near]).astype(int), 0, n - 1)
        state = self.state[i, j]
        beyond = (cu[near] < 0) | (cu[near] > n) | (cv[near] < 0) | (cv[near] > n)
        state = np.where(beyond & (state != Trim.UNSURE), Trim.OUTSIDE, state)
        walk = np.flatnonzero((state == Trim.UNSURE) & ~beyond & ~self.kernel[i, j])
        if len(walk):
            points = np.column_stack([cu[near[walk]], cv[near[walk]]])
            state[walk] = self._walk(points, i[walk], j[walk])
        out[near] = state
        return out

    def _walk(self, p: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """State (m,) of points ``p`` (m, 2) in cell units in the near cells ``(i, j)``: the centre's state,
        changed at each segment crossed on the way to the point; UNSURE within a margin, or where the way
        passes a vertex or a gap; ON_BOUNDARY within half the tolerance of the boundary curve."""
        n = self.state.shape[0]
        cell = i.astype(np.int64) * n + j
        first = np.searchsorted(self.cells, cell, side="left")
        count = np.searchsorted(self.cells, cell, side="right") - first
        point = np.repeat(np.arange(len(p)), count)
        item = self.items[np.repeat(first - np.cumsum(count) + count, count) + np.arange(len(point))]
        c = np.column_stack([i, j]) + 0.5
        unsure = np.zeros(len(p), bool)
        on = np.zeros(len(p), bool)

        is_segment = item < len(self.start)
        sp, s = point[is_segment], item[is_segment]
        a, b, q, o = self.start[s], self.end[s], p[sp], c[sp]
        floor = MARGIN_FLOOR
        to_segment = _to_segments(q, a, b)
        on[sp[(np.minimum(_norm(q - a), _norm(q - b)) <= self.on) | (to_segment + self.deviation[s] <= self.on)]] = True
        unsure[sp[(to_segment <= self.margin[s])                     # near the boundary
                  | (_to_segments(o, a, b) <= floor)                 # the centre on it
                  | (_to_segments(a, o, q) <= floor) | (_to_segments(b, o, q) <= floor)]] = True   # a vertex
        side_o, side_q = _cross(b - a, o - a), _cross(b - a, q - a)
        side_a, side_b = _cross(q - o, a - o), _cross(q - o, b - o)
        hit = (np.sign(side_o) * np.sign(side_q) < 0) & (np.sign(side_a) * np.sign(side_b) < 0)
        crossed = np.bincount(sp[hit], minlength=len(p))

        gp, g = point[~is_segment], item[~is_segment] - len(self.start)
        unsure[gp[_to_segments(self.ends[g], c[gp], p[gp]) <= self.reach[g]]] = True

        inside = self.centre[i, j] ^ (crossed % 2 == 1)
        state = np.where(inside, Trim.INSIDE, Trim.OUTSIDE).astype(np.int8)
        state[unsure] = Trim.UNSURE
        state[on] = Trim.ON_BOUNDARY
        return state


def _centre_states(a: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    """(n, n) bool: the even-odd state (True inside) of each cell centre of the segments ``a -> b`` (each
    (s, 2), cell units).

    Along each column of cells (fixed v) a segment crossing the line v = j + 1/2 at u adds one crossing to
    the left of every centre beyond u; the parity of the running count says inside.  (Half-open in v, so a
    vertex on the line counts once.)"""
    crossings = np.zeros((n, n + 1), np.int32)          # (v row, u column)
    lo_v, hi_v = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    first_row = np.maximum(np.ceil(lo_v - 0.5), 0).astype(int)
    last_row = np.minimum(np.ceil(hi_v - 0.5) - 1, n - 1).astype(int)     # centres c with lo <= c < hi
    count = np.maximum(last_row - first_row + 1, 0)
    seg, place = run_places(count)
    row = first_row[seg] + place
    c = row + 0.5
    pa, pb = a[seg], b[seg]
    u_cross = pa[:, 0] + (c - pa[:, 1]) * (pb[:, 0] - pa[:, 0]) / (pb[:, 1] - pa[:, 1])
    column = np.clip(np.ceil(u_cross - 0.5), 0, n).astype(int)           # first centre right of it
    np.add.at(crossings, (row, column), 1)
    return (np.cumsum(crossings, axis=1)[:, :n] % 2 == 1).T


def _near_cells(a: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    """(n, n) bool: the cells the segments ``a -> b`` (each (s, 2), cell units) touch (walked in steps of at
    most half a cell), grown by one cell."""
    near = np.zeros((n + 2, n + 2), bool)
    length = np.ceil(np.max(np.abs(b - a), axis=1) * 2.0).astype(int) + 1
    seg, place = run_places(length + 1)
    t = place / length[seg]                                     # 0, 1/k, ..., 1 along each segment
    pts = a[seg] + t[:, None] * (b[seg] - a[seg])
    cell = np.clip(np.floor(pts).astype(int), -1, n) + 1
    near[cell[:, 0], cell[:, 1]] = True
    grown = near.copy()
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            grown[1:-1, 1:-1] |= near[1 + di:n + 1 + di, 1 + dj:n + 1 + dj]
    return grown[1:-1, 1:-1]

def _norm(d: np.ndarray) -> np.ndarray:
    """Lengths (m,) of 2D vectors ``d`` (m, 2)."""
    return np.sqrt(d[:, 0] ** 2 + d[:, 1] ** 2)


def _cross(d: np.ndarray, e: np.ndarray) -> np.ndarray:
    """The 2D cross products (m,) of ``d`` and ``e`` (m, 2)."""
    return d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0]


def _to_segments(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances (m,) of points ``q`` (m, 2) from the segments ``a -> b`` (each (m, 2))."""
    d = b - a
    length2 = d[:, 0] ** 2 + d[:, 1] ** 2
    t = np.clip(np.einsum("ij,ij->i", q - a, d) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    return _norm(q - a - t[:, None] * d)


def _gaps(ends: np.ndarray) -> np.ndarray:
    """For each polyline end ``ends`` (2 k, 2; start and end of each polyline in turn) the distance to the
    nearest other end (of another polyline, or its own other end: a closed polyline): the boundary's gap there."""
    distance, _ = kd_tree(ends).query(ends, k=2)
    return distance[:, 1]


def _cells_covered(lo: np.ndarray, hi: np.ndarray, n: int) -> np.ndarray:
    """(n, n) bool: the cells of an ``n x n`` raster that the boxes ``lo``-``hi`` (each (m, 2), cell units) overlap
    (summed corner marks, so a wide box costs no more than a narrow one)."""
    first = np.clip(np.floor(lo).astype(np.int64), 0, n - 1)
    last = np.clip(np.floor(hi).astype(np.int64), 0, n - 1) + 1
    marks = np.zeros((n + 1, n + 1), np.int64)
    np.add.at(marks, (first[:, 0], first[:, 1]), 1)
    np.add.at(marks, (last[:, 0], first[:, 1]), -1)
    np.add.at(marks, (first[:, 0], last[:, 1]), -1)
    np.add.at(marks, (last[:, 0], last[:, 1]), 1)
    return marks.cumsum(axis=0).cumsum(axis=1)[:n, :n] > 0


def _cells_under(lo: np.ndarray, hi: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The cells (numbers ``i n + j``, sorted) of an ``n x n`` raster that the boxes ``lo``-``hi`` (each (m, 2),
    cell units) overlap, and which box (m,) each pair is of."""
    first = np.clip(np.floor(lo).astype(np.int64), 0, n - 1)
    last = np.clip(np.floor(hi).astype(np.int64), 0, n - 1)
    size = last - first + 1
    count = size[:, 0] * size[:, 1]
    item, k = run_places(count)
    i = first[item, 0] + k // size[item, 1]
    j = first[item, 1] + k % size[item, 1]
    cells = i * n + j
    order = np.argsort(cells, kind="stable")
    return cells[order], item[order]
