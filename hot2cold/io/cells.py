"""The FE elements a field brings, by meshio's type names: their boundary triangles (:func:`element_triangles`),
for the field readers (:mod:`hot2cold.io.field`, :mod:`hot2cold.io.frd`)."""
from __future__ import annotations

import logging

import numpy as np

from ..errors import FieldError, one_line

log = logging.getLogger(__name__)


#: Element types :func:`element_triangles` takes (meshio's names) -> their node count.
ELEMENT_NAMES = {"tetra": 4, "tetra10": 10, "triangle": 3, "triangle6": 6}


def element_triangles(elements, source: str = "") -> np.ndarray | None:
    """The boundary triangles of a mesh's elements: ``(T, 3)`` or ``(T, 6)`` int64, in the elements' node
    labels (rows of the points, or node numbers).

    ``elements`` maps meshio's type names to node arrays (or lists of them) in the VTK node order:
    ``tetra`` ``(M, 4)``, ``tetra10`` ``(M, 10)``, ``triangle`` ``(T, 3)``, ``triangle6`` ``(T, 6)``; other
    keys are ignored.  Tetrahedra give their boundary (:func:`hot2cold.core.elements.boundary_triangles`: the
    faces no second tetrahedron shares), and any triangles beside them are not used; without tetrahedra the
    triangles (a surface mesh) are taken as they are.  4- and 10-node elements mixed give the linear
    triangles of all (their corners), logged.  None when there is no tetrahedron or triangle.
    """
    from ..core.elements import boundary_triangles

    where = f" {source}" if source else ""
    arrays: dict[str, np.ndarray] = {}
    for name, nodes in ELEMENT_NAMES.items():
        given = elements.get(name)
        if given is None:
            continue
        blocks = isinstance(given, (list, tuple)) and all(isinstance(a, np.ndarray) and a.ndim == 2 for a in given)
        parts = list(given) if blocks else [given]
        try:
            parts = [np.asarray(a) for a in parts if np.size(a)]
            for a in parts:
                if a.dtype.kind not in "iu":
                    raise ValueError(f"dtype {a.dtype}")
                if a.ndim != 2 or a.shape[1] != nodes:
                    raise ValueError(f"shape {a.shape}")
            conn = np.concatenate([a.astype(np.int64) for a in parts]) if parts else np.zeros((0, nodes), np.int64)
        except (TypeError, ValueError) as exc:
            raise FieldError(f"mesh{where}: the {name} elements are not ({nodes}-node) integer node rows "
                             f"({one_line(exc)})") from None
        if len(conn):
            arrays[name] = conn
    for solid, linear, quadratic in ((True, "tetra", "tetra10"), (False, "triangle", "triangle6")):
        if linear in arrays and quadratic in arrays:
            log.info("mesh%s: %s and %s elements mixed: the boundary is taken with straight (3-node) triangles",
                     where, linear, quadratic)
            conn = np.concatenate([arrays[linear], arrays[quadratic][:, :(4 if solid else 3)]])
        elif linear in arrays or quadratic in arrays:
            conn = arrays.get(linear, arrays.get(quadratic))
        else:
            continue
        return boundary_triangles(conn) if solid else conn
    return None
