"""A face's trimmed domain as a raster, to tell inside from outside for many parameter pairs at once.

The kernel's ``BRepTopAdaptor_FClass2d`` answers one ``(u, v)`` at a time, a kernel call each.  Classifying a
million foot points, or the artificial-node candidates of a finely trimmed face, one by one is too slow, but
almost every point is far from the boundary.  So the face's parameter box is cut into ``n x n`` cells:

* cells the boundary passes through, and their neighbours, are *unsure*: points in them go to the kernel;
* every other cell lies wholly inside or wholly outside, and its state is that of its centre, found by the
  even-odd rule along the cell row (a scan line crossing the boundary polylines).

The boundary is given as polylines of the face's pcurves (``(m, 2)`` arrays, one per edge use, any order and
orientation); they must follow the pcurves to well within a cell (the kernel samples them so).  A point
farther than one cell outside the box is outside.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np


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


@dataclass(frozen=True, eq=False)
class DomainRaster:
    """The trimmed domain of one face on an ``n x n`` grid of cells over ``box``.

    Attributes
    ----------
    box : (4,) float, ``(u0, u1, v0, v1)``.
    state : (n, n) int8, Trim.INSIDE, Trim.OUTSIDE or Trim.UNSURE per cell (first index u, second v).
    """

    box: np.ndarray
    state: np.ndarray

    @classmethod
    def build(cls, polylines: list[np.ndarray], box, n: int = 512) -> "DomainRaster":
        """Raster of the region bounded by ``polylines`` (each (m, 2) in (u, v)) within ``box``."""
        box = np.asarray(box, dtype=float)
        u0, u1, v0, v1 = box
        if not (u1 > u0 and v1 > v0):
            raise ValueError(f"empty parameter box {box}")
        lines = [np.asarray(p, dtype=float) for p in polylines if len(p) >= 2]
        if not lines:
            raise ValueError("no boundary polylines")
        # Boundary polylines in cell units.
        scale = np.array([n / (u1 - u0), n / (v1 - v0)])
        lines = [(p - box[[0, 2]]) * scale for p in lines]
        a = np.concatenate([p[:-1] for p in lines])
        b = np.concatenate([p[1:] for p in lines])

        # Even-odd rule at the cell centres along each column of cells (fixed v): a segment crossing the
        # line v = j + 1/2 at u adds one crossing to the left of every centre beyond u; the parity of the
        # running count says inside.  (Half-open in v, so a vertex on the line counts once.)
        crossings = np.zeros((n, n + 1), np.int32)          # (v row, u column)
        lo_v, hi_v = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
        first_row = np.maximum(np.ceil(lo_v - 0.5), 0).astype(int)
        last_row = np.minimum(np.ceil(hi_v - 0.5) - 1, n - 1).astype(int)     # centres c with lo <= c < hi
        count = np.maximum(last_row - first_row + 1, 0)
        seg = np.repeat(np.arange(len(a)), count)
        row = first_row[seg] + np.arange(len(seg)) - np.repeat(np.cumsum(count) - count, count)
        c = row + 0.5
        pa, pb = a[seg], b[seg]
        u_cross = pa[:, 0] + (c - pa[:, 1]) * (pb[:, 0] - pa[:, 0]) / (pb[:, 1] - pa[:, 1])
        column = np.clip(np.ceil(u_cross - 0.5), 0, n).astype(int)           # first centre right of it
        np.add.at(crossings, (row, column), 1)
        inside = (np.cumsum(crossings, axis=1)[:, :n] % 2 == 1).T
        state = np.where(inside, Trim.INSIDE, Trim.OUTSIDE).astype(np.int8)

        # Cells the boundary touches (segments walked in steps of at most half a cell), grown by one cell.
        near = np.zeros((n + 2, n + 2), bool)
        length = np.ceil(np.max(np.abs(b - a), axis=1) * 2.0).astype(int) + 1
        seg = np.repeat(np.arange(len(a)), length + 1)
        first = np.repeat(np.cumsum(length + 1) - (length + 1), length + 1)
        t = (np.arange(len(seg)) - first) / length[seg]            # 0, 1/k, ..., 1 along each segment
        pts = a[seg] + t[:, None] * (b[seg] - a[seg])
        cell = np.clip(np.floor(pts).astype(int), -1, n) + 1
        near[cell[:, 0], cell[:, 1]] = True
        grown = near.copy()
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                grown[1:-1, 1:-1] |= near[1 + di:n + 1 + di, 1 + dj:n + 1 + dj]
        state[grown[1:-1, 1:-1]] = Trim.UNSURE
        return cls(box, state)

    def classify(self, uv: np.ndarray) -> np.ndarray:
        """State ``(m,)`` int8 (Trim.INSIDE, Trim.OUTSIDE or Trim.UNSURE) of parameter pairs ``uv`` ``(m, 2)``;
        NaN rows are OUTSIDE."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        n = self.state.shape[0]
        u0, u1, v0, v1 = self.box
        cu = (uv[:, 0] - u0) * (n / (u1 - u0))
        cv = (uv[:, 1] - v0) * (n / (v1 - v0))
        out = np.full(len(uv), Trim.OUTSIDE, np.int8)
        finite = np.isfinite(cu) & np.isfinite(cv)
        # Up to one cell outside the box: the border cell decides (it is UNSURE where the boundary runs on
        # the box's edge); farther out: outside.
        near = finite & (cu >= -1) & (cu < n + 1) & (cv >= -1) & (cv < n + 1)
        i = np.clip(np.floor(cu[near]).astype(int), 0, n - 1)
        j = np.clip(np.floor(cv[near]).astype(int), 0, n - 1)
        state = self.state[i, j]
        beyond = (cu[near] < 0) | (cu[near] >= n) | (cv[near] < 0) | (cv[near] >= n)
        state = np.where(beyond & (state != Trim.UNSURE), Trim.OUTSIDE, state)
        out[near] = state
        return out
