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

from dataclasses import dataclass, field, replace

import numpy as np


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

    def with_poles(self, poles: np.ndarray) -> "BSplineCurve":
        """The same curve (degree, knots, weights) with other poles ``(n, 3)``."""
        return replace(self, poles=poles)


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

    def with_poles(self, poles: np.ndarray) -> "BSplineSurface":
        """The same surface (degrees, knots, weights) with another control net ``(nu, nv, 3)``."""
        return replace(self, poles=poles)
