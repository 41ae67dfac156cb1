"""The part as the numeric core sees it: faces, edges and vertices as plain records.

Built by :mod:`hot2cold.kernel.topology` from a solid; read by every step of the morph.  Numbering is
0-based throughout and follows the kernel's ``TopExp.MapShapes`` order of the whole input shape, so face
``k`` of the hot part is face ``k`` of the cold part.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .bspline import BSplineCurve, BSplineSurface


@dataclass(frozen=True, eq=False)
class EdgeUse:
    """One occurrence of an edge in the boundary of a face.

    Attributes
    ----------
    edge : int, index of the edge.
    t : (m,) float array, parameters on the edge curve, ordered, ends included.
    uv : (m, 2) float array, the edge's curve on the face (its pcurve) at ``t``, in the face's parameters.
    """

    edge: int
    t: np.ndarray
    uv: np.ndarray


@dataclass(frozen=True, eq=False)
class Face:
    """A face: its B-spline surface (global coordinates), trimmed-domain box and boundary.

    Attributes
    ----------
    index : int.
    surface : BSplineSurface, the untrimmed carrier surface.
    uv_box : (4,) float array ``(u0, u1, v0, v1)`` bounding the trimmed domain.
    uses : tuple of EdgeUse, every edge occurrence of the face's wires (a seam edge occurs twice).
    solid : int, index of the solid the face belongs to.
    """

    index: int
    surface: BSplineSurface
    uv_box: np.ndarray
    uses: tuple[EdgeUse, ...]
    solid: int


@dataclass(frozen=True, eq=False)
class Edge:
    """An edge shared by the faces in ``faces``.

    Attributes
    ----------
    index : int.
    curve : BSplineCurve or None, the 3D curve restricted to the edge's range (None when degenerate,
        e.g. the apex of a cone).
    vertices : (int, int), the vertex at the curve's start and at its end.
    faces : tuple of int, faces whose boundary holds the edge (two for a manifold solid; a seam edge's
        face once).
    """

    index: int
    curve: BSplineCurve | None
    vertices: tuple[int, int]
    faces: tuple[int, ...]

    @property
    def degenerate(self) -> bool:
        return self.curve is None


@dataclass(frozen=True, eq=False)
class Part:
    """The decomposed part.

    Attributes
    ----------
    faces, edges : lists of Face and Edge.
    vertices : (nv, 3) float array of vertex points.
    solids : list of (int,...) tuples, the faces of each solid.
    diagonal : float, bounding-box diagonal in mm (scale of relative tolerances).
    kernel : opaque handle of the kernel's working copy, used only by :mod:`hot2cold.kernel`.
    solid_names : tuple of str, the name of each solid as the hot STEP gave it ("" where it gave none);
        empty when the input carried no names.
    face_names : tuple of str, the same per face (a face's own label only).
    styles : opaque record of the hot STEP's names, colours and assembly tree
        (:class:`hot2cold.kernel.xcaf.Styles`), or None; the cold STEP is written with them.
    """

    faces: list[Face]
    edges: list[Edge]
    vertices: np.ndarray
    solids: list[tuple[int, ...]]
    diagonal: float
    kernel: Any
    solid_names: tuple[str, ...] = ()
    face_names: tuple[str, ...] = ()
    styles: Any = None
