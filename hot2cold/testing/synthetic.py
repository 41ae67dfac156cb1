"""Analytic displacement fields for the sample parts, the tests and the benchmarks.

Each field is a small frozen dataclass: calling it on node positions ``points (N, 3)`` gives their
displacements ``(N, 3)`` in mm, and :meth:`exact_map` gives the displaced positions ``points + field(points)``.
Pure numpy; no kernel objects.

* :class:`AffineField` -- ``x -> A x + b``: uniform thermal strain and rigid motion.  A correct morph
  reproduces it to rounding error (an affine map takes a B-spline to a B-spline with the same knots).
* :class:`UntwistField` -- a rotation about a span axis by an angle growing linearly along the span, plus an
  axial stretch quadratic in the span coordinate: smooth and not affine.
* :class:`ZeroField` -- no displacement.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _frozen_array(a, shape: tuple[int, ...], name: str) -> np.ndarray:
    arr = np.array(a, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} holds NaN or inf")
    arr.setflags(write=False)
    return arr


def _points(points) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must be (N, 3), got shape {p.shape}")
    return p


def rotation_matrix(axis, angle_deg: float) -> np.ndarray:
    """Rotation ``(3, 3)`` by ``angle_deg`` degrees about the direction ``axis (3,)`` (right-hand rule)."""
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    a = np.radians(angle_deg)
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(a) * cross + (1.0 - np.cos(a)) * (cross @ cross)


@dataclass(frozen=True, eq=False)
class AffineField:
    """The affine map ``x -> matrix @ x + translation``; the displacement is ``map(x) - x``.

    Attributes
    ----------
    matrix : (3, 3) float array, the linear part of the map (the identity for a pure translation).
    translation : (3,) float array in mm.
    """

    matrix: np.ndarray
    translation: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "matrix", _frozen_array(self.matrix, (3, 3), "matrix"))
        object.__setattr__(self, "translation", _frozen_array(self.translation, (3,), "translation"))

    @classmethod
    def thermal(cls, contraction: float = -0.005, rotation_deg: float = 0.0, axis=(0.0, 0.0, 1.0),
                translation=(0.0, 0.0, 0.0), center=(0.0, 0.0, 0.0)) -> "AffineField":
        """Uniform thermal strain ``contraction`` (e.g. -0.005 for -0.5 %) about ``center (3,)``, then a
        rotation by ``rotation_deg`` degrees about the line through ``center`` along ``axis (3,)``, then a
        ``translation (3,)`` in mm::

            x -> center + (1 + contraction) R (x - center) + translation
        """
        c = np.asarray(center, dtype=float)
        a = (1.0 + contraction) * rotation_matrix(axis, rotation_deg)
        return cls(a, c - a @ c + np.asarray(translation, dtype=float))

    def exact_map(self, points) -> np.ndarray:
        """Displaced positions ``(N, 3)`` of ``points (N, 3)``."""
        return _points(points) @ self.matrix.T + self.translation

    def __call__(self, points) -> np.ndarray:
        """Displacements ``(N, 3)`` at ``points (N, 3)``."""
        p = _points(points)
        return self.exact_map(p) - p


@dataclass(frozen=True, eq=False)
class UntwistField:
    """Untwist and stretch of a blade along its span: smooth, not affine.

    With the span coordinate ``z = x . span_axis`` (``span_axis`` normalised), a point ``x`` is rotated about
    the line through ``axis_point`` along ``span_axis`` by ``untwist_deg_per_mm * (z - z0)`` degrees and
    moved along ``span_axis`` by ``stretch_per_mm2 * (z - z0)**2`` mm.  Nothing moves at ``z = z0`` (the
    hub).  On a 100 mm blade of 40 mm chord, ``untwist_deg_per_mm = 0.03`` and ``stretch_per_mm2 = 1e-4``
    give displacements of about 1-2 mm at the tip.

    Attributes
    ----------
    axis_point : (3,) float array, a point of the rotation axis, mm.
    span_axis : (3,) float array, unit direction of the span (normalised on construction).
    untwist_deg_per_mm : float, rotation angle per mm of span, degrees/mm.
    stretch_per_mm2 : float, axial stretch coefficient, 1/mm.
    z0 : float, span coordinate (mm) where the displacement vanishes.
    """

    axis_point: np.ndarray
    span_axis: np.ndarray = (0.0, 0.0, 1.0)
    untwist_deg_per_mm: float = 0.03
    stretch_per_mm2: float = 1e-4
    z0: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "axis_point", _frozen_array(self.axis_point, (3,), "axis_point"))
        axis = np.array(self.span_axis, dtype=float)
        norm = np.linalg.norm(axis) if axis.shape == (3,) else 0.0
        if not norm > 0:
            raise ValueError(f"span_axis must be a non-zero (3,) vector, got {self.span_axis!r}")
        object.__setattr__(self, "span_axis", _frozen_array(axis / norm, (3,), "span_axis"))
        for name in ("untwist_deg_per_mm", "stretch_per_mm2", "z0"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite")

    @classmethod
    def over(cls, points, untwist_deg_per_mm: float, stretch_per_mm2: float) -> UntwistField:
        """The untwist along z of the part ``points (N, 3)`` spread over: about the vertical line through the
        centre of their bounding box, nothing moving at their lowest z (the hub)."""
        p = _points(points)
        lo, hi = p.min(axis=0), p.max(axis=0)
        return cls(axis_point=(lo + hi) / 2, untwist_deg_per_mm=untwist_deg_per_mm,
                   stretch_per_mm2=stretch_per_mm2, z0=float(lo[2]))

    def exact_map(self, points) -> np.ndarray:
        """Displaced positions ``(N, 3)`` of ``points (N, 3)``."""
        p = _points(points)
        e = self.span_axis
        dz = p @ e - self.z0                                   # (N,)
        angle = np.radians(self.untwist_deg_per_mm) * dz       # (N,)
        r = p - self.axis_point                                # (N, 3)
        along = (r @ e)[:, None] * e                           # (N, 3) part of r along the axis
        perp = r - along
        cos, sin = np.cos(angle)[:, None], np.sin(angle)[:, None]
        rotated = perp * cos + np.cross(e, perp) * sin         # Rodrigues, perp is normal to e
        return self.axis_point + along + rotated + (self.stretch_per_mm2 * dz ** 2)[:, None] * e

    def __call__(self, points) -> np.ndarray:
        """Displacements ``(N, 3)`` at ``points (N, 3)``."""
        p = _points(points)
        return self.exact_map(p) - p


@dataclass(frozen=True)
class ZeroField:
    """No displacement: ``exact_map`` is the identity."""

    def exact_map(self, points) -> np.ndarray:
        """A copy ``(N, 3)`` of ``points (N, 3)``."""
        return _points(points).copy()

    def __call__(self, points) -> np.ndarray:
        """Zeros ``(N, 3)``."""
        return np.zeros_like(_points(points))
