"""Artificial nodes: displacements where the FE field has no node (METHOD step 6, paper section 4).

Vertices without a node on them, edge knot spans and face patches ``[U_r, U_r+1) x [V_s, V_s+1)`` without a
node (eq. 39), and the trimmed-away parts of a surface need a displacement to keep the fit well posed; zero
is wrong (paper Fig. 5a).  The paper interpolates or extrapolates barycentrically in the plane of the three
nearest foot points (eq. 40-53).  Here the displacement at a point is the value of a linear least-squares
fit ``d(x) = a + B (x - x0)`` over the ``k`` nearest foot points instead: it reproduces an affine field
exactly as the barycentric rule does, but it does not depend on which three points are nearest (three
nearly collinear foot points make the paper's triangle degenerate and its extrapolation explode), and it
averages the noise of many nodes.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


class FieldEstimator:
    """Local linear estimate of the displacement field from foot points.

    Parameters
    ----------
    points : (n, 3) float array, foot points of the used nodes.
    displacements : (n, 3) float array, their FE displacements.
    neighbours : int, how many nearest foot points each estimate uses.
    """

    def __init__(self, points: np.ndarray, displacements: np.ndarray, neighbours: int = 20):
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
        self._tree = cKDTree(points)

    def __call__(self, x: np.ndarray, chunk: int = 4096) -> np.ndarray:
        """Estimated displacements ``(m, 3)`` at points ``x`` ``(m, 3)``.

        The local fits are solved all at once, ``chunk`` points at a time, by the pseudo-inverse of each
        ``(k, 4)`` design matrix (batched SVD): foot points on a plane make that matrix rank-deficient, and the
        pseudo-inverse then gives the minimum-norm gradient, i.e. none across the plane.
        """
        x = np.atleast_2d(np.asarray(x, float))
        out = np.empty_like(x)
        if len(x) == 0:
            return out
        if self._k < 4:
            _, idx = self._tree.query(x, k=1)
            return self._disp[np.atleast_1d(idx)].reshape(x.shape)
        for start in range(0, len(x), chunk):
            xs = x[start:start + chunk]
            _, idx = self._tree.query(xs, k=self._k)
            offsets = self._points[idx] - xs[:, None, :]                      # (c, k, 3)
            scale = np.abs(offsets).max(axis=(1, 2))
            scale[scale == 0] = 1.0
            design = np.concatenate([np.ones(idx.shape + (1,)), offsets / scale[:, None, None]], axis=2)
            coef = np.linalg.pinv(design, rcond=1e-10) @ self._disp[idx]          # (c, 4, 3)
            out[start:start + chunk] = coef[:, 0, :]
        return out
