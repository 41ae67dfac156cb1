"""The part as the numeric core sees it: faces, edges and vertices as plain records.

Built by :mod:`hot2cold.kernel.topology` from a solid; read by every step of the morph.  Numbering is
0-based throughout and follows the kernel's ``TopExp.MapShapes`` order of the whole input shape, so face
``k`` of the hot part is face ``k`` of the cold part.

Beside the part: the sides of a surface's parameter domain (:class:`Side`, :func:`side_along`), and the
FE nodes' roles (:class:`Role`) with the record of where each node takes part (:class:`Classification`,
filled by :mod:`hot2cold.pipeline.classify`).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from enum import Enum, IntEnum
from typing import Any

import numpy as np

from .arrays import runs
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
    face_labels : tuple of str, a name for each face from its surface kind and place as read ("plane z = 10",
        "cylinder r 5 about z", "B-spline surface near (1, 2, 3)"), for reports; empty when not known.
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
    face_labels: tuple[str, ...] = ()
    styles: Any = None

    @cached_property
    def vertex_edges(self) -> tuple[tuple[int, ...], ...]:
        """The edges ending at each vertex (edge indices in index order, one tuple per vertex), found once: the
        corners ask for them vertex by vertex."""
        at: list[list[int]] = [[] for _ in range(len(self.vertices))]
        for edge in self.edges:
            for v in dict.fromkeys(edge.vertices):
                at[v].append(edge.index)
        return tuple(tuple(edges) for edges in at)

    def face_title(self, k: int) -> str:
        """What face ``k`` is called in reports: its name in the STEP file, else its label ("" if neither)."""
        named = self.face_names[k] if k < len(self.face_names) else ""
        return named or (self.face_labels[k] if k < len(self.face_labels) else "")


class Side(str, Enum):
    """A side of a surface's parameter domain ``[u0, u1] x [v0, v1]``: the parameter ``axis`` (0: u, 1: v)
    held at the domain's low (``end`` 0) or high (``end`` 1) end (eq. 32-36 name the sides u=0, u=1, v=0,
    v=1 of an untrimmed face).

    A ``str`` enum: a side equals, hashes, prints and serialises as its value ("u0", "u1", "v0", "v1"),
    which the JSON report (``tied_sides``) and the G1 messages show.
    """

    U0 = "u0"
    U1 = "u1"
    V0 = "v0"
    V1 = "v1"

    def __str__(self) -> str:
        return self.value

    def __format__(self, spec: str) -> str:
        return format(self.value, spec)

    @property
    def axis(self) -> int:
        """The parameter held on the side: 0 (u) or 1 (v)."""
        return 0 if self.value[0] == "u" else 1

    @property
    def end(self) -> int:
        """0 at the domain's low end of ``axis``, 1 at its high end."""
        return int(self.value[1])


def side_along(surface: BSplineSurface, use: EdgeUse, rel_tol: float = 1e-9,
               whole: bool = True) -> tuple[Side, bool] | None:
    """The side of ``surface``'s domain that the edge use runs along from end to end (with ``whole=False``:
    lies on, whatever part of the side it covers), and whether it runs against the side's direction; None
    when it lies on no side.

    ``use.uv`` (m, 2) is taken to lie on a side when its fixed parameter stays within ``rel_tol`` times the
    domain's span of the side's value.  The answer depends on the domain alone (a face's fits and refinements
    keep it), and is kept on the use for each domain asked about: the fits, the refinement and G1 ask for the
    same uses round after round.
    """
    key = (surface.domain, rel_tol, whole)
    known = use.__dict__.setdefault("_sides", {})           # (a frozen dataclass: its __dict__ takes a cache)
    if key not in known:
        known[key] = _side_along(key[0], use.uv, rel_tol, whole)
    return known[key]


def _side_along(domain: tuple[float, float, float, float], uv: np.ndarray, rel_tol: float, whole: bool
                ) -> tuple[Side, bool] | None:
    """:func:`side_along` of the pcurve ``uv (m, 2)`` on the parameter box ``domain``."""
    u0, u1, v0, v1 = domain
    span = np.array([u1 - u0, v1 - v0])
    for side in Side:
        axis = side.axis
        fixed_value = (u0, u1, v0, v1)[2 * axis + side.end]
        along = 1 - axis
        lo, hi = (u0, v0)[along], (u1, v1)[along]
        if np.all(np.abs(uv[:, axis] - fixed_value) <= rel_tol * span[axis]):
            a, b = uv[0, along], uv[-1, along]
            if not whole or (min(a, b) <= lo + rel_tol * span[along] and max(a, b) >= hi - rel_tol * span[along]):
                return side, bool(a > b)
    return None


class Role(IntEnum):
    """What an FE node feeds (eq. 4, 27, 33-37): a face's interior, an edge, a vertex, or nothing.

    An ``int`` enum: role arrays stay int arrays (the VTU ``role`` point data holds these values) and
    compare with the members directly.
    """

    IGNORED = -1
    FACE = 0
    EDGE = 1
    VERTEX = 2


@dataclass(frozen=True, eq=False)
class Classification:
    """Where each of the N field nodes takes part (filled by :func:`hot2cold.pipeline.classify.classify_nodes`).

    Attributes
    ----------
    role : (N,) int, a :class:`Role` value: IGNORED, FACE, EDGE or VERTEX.
    owner : (N,) int, index of the face, edge or vertex (-1 when ignored).
    uv : (N, 2) float, foot-point parameters on the owning face (NaN unless role is FACE).
    t : (N,) float, foot-point parameter on the owning edge (NaN unless role is EDGE).
    foot : (N, 3) float, the foot point S(u, v), C(t) or the vertex (NaN when ignored).
    distance : (N,) float, distance from node to its foot point (inf when ignored).
    node_distance, edge_distance : the lengths (mm) used.
    node : (N,) int, the field row of each entry: ``arange`` for a field whose every node feeds one solid.
        A node on coincident faces of touching solids (or on a free face beside a solid) feeds each of them:
        it has one entry per solid, the first at its own row, the others after the field's rows, all with
        its field row here; :meth:`hot2cold.io.field.DisplacementField.take` gives the field of the entries.
    """

    role: np.ndarray
    owner: np.ndarray
    uv: np.ndarray
    t: np.ndarray
    foot: np.ndarray
    distance: np.ndarray
    node_distance: float
    edge_distance: float
    node: np.ndarray | None = None

    def __post_init__(self):
        if self.node is None:
            object.__setattr__(self, "node", np.arange(len(self.role)))

    @classmethod
    def unclaimed(cls, n: int, node_distance: float, edge_distance: float) -> Classification:
        """``n`` nodes, every one ignored: no owner, no foot point, at an infinite distance (the arrays a
        classification fills in place as faces, edges and vertices claim the nodes)."""
        return cls(np.full(n, Role.IGNORED), np.full(n, -1), np.full((n, 2), np.nan), np.full(n, np.nan),
                   np.full((n, 3), np.nan), np.full(n, np.inf), node_distance, edge_distance)

    def arrays(self) -> tuple[np.ndarray, ...]:
        """``(role, owner, uv, t, foot, distance)``, the per-node arrays."""
        return self.role, self.owner, self.uv, self.t, self.foot, self.distance

    @property
    def field_nodes(self) -> int:
        """How many nodes the field has (the entries of nodes that feed two solids counted once)."""
        return len(self.node) - int(np.count_nonzero(self.node != np.arange(len(self.node))))

    def nodes_of(self, role: Role, index: int) -> np.ndarray:
        """Indices (ascending) of the nodes of ``role`` owned by face, edge or vertex ``index``: a run of the
        nodes sorted by role and owner (:attr:`_by_owner`), not a scan of every node for each of the part's
        faces and edges."""
        order, keys, span = self._by_owner
        if not -1 <= index < span - 1:
            return np.zeros(0, dtype=order.dtype)
        key = int(role) * span + index + 1
        return order[np.searchsorted(keys, key, side="left"):np.searchsorted(keys, key, side="right")].copy()

    @cached_property
    def _by_owner(self) -> tuple[np.ndarray, np.ndarray, int]:
        """The nodes ``(N,)`` sorted by role and owner (by index within each), their sorted keys ``(N,)``
        ``role * span + owner + 1`` and ``span``, the largest owner plus two (owners from -1 up, one key each):
        made when first asked, once the classification's arrays are final (they are filled in place while it is
        made)."""
        span = int(self.owner.max(initial=-1)) + 2
        keys = self.role.astype(np.int64) * span + (self.owner.astype(np.int64) + 1)
        order = np.argsort(keys, kind="stable")
        return order, keys[order], span

    def counts(self, role: Role, owners: int) -> np.ndarray:
        """How many nodes of ``role`` each of ``owners`` faces, edges or vertices owns ``(owners,)``."""
        return np.bincount(self.owner[self.role == role], minlength=owners)

    def groups(self, role: Role) -> list[tuple[int, np.ndarray]]:
        """``(index, nodes)`` for every face, edge or vertex that owns nodes of ``role``, in index order
        (the role's run of :attr:`_by_owner`, the one sort :meth:`nodes_of` reads)."""
        order, keys, span = self._by_owner
        first = int(role) * span
        lo, hi = np.searchsorted(keys, first, side="left"), np.searchsorted(keys, first + span, side="left")
        return [(owner - 1, order[lo:hi][run].copy()) for owner, run in runs(keys[lo:hi] - first)]

    @property
    def used(self) -> np.ndarray:
        """Mask ``(N,)`` of the nodes that take part."""
        return self.role != Role.IGNORED

    @cached_property
    def spacings(self) -> np.ndarray:
        """Distance (mm) from each used node's foot point to the nearest other foot point ``(N,)`` (NaN for
        unused nodes, and for all where fewer than two foot points are distinct): the field's node spacing
        there.  Nodes that share a foot point count once."""
        from .trees import kd_tree, query

        used = np.flatnonzero(self.used)
        nearest = np.full(len(self.role), np.nan)
        feet = self.foot[used]
        if len(feet) < 2:
            return nearest
        tree = kd_tree(feet)
        found = query(tree, feet, k=2)[0][:, 1]
        # a foot point shared by several nodes (a vertex's, one node's in two solids): farther neighbours, up
        # to the nearest one elsewhere (none where all are one point)
        shared = np.flatnonzero(found == 0.0)
        k = 2
        while len(shared) and k < len(feet):
            k = min(4 * k, len(feet))
            dist = query(tree, feet[shared], k=k)[0].reshape(len(shared), k)
            apart = dist > 0.0
            done = apart.any(axis=1)
            found[shared[done]] = dist[done, apart[done].argmax(axis=1)]
            shared = shared[~done]
        found[shared] = np.nan
        nearest[used] = found
        return nearest

    def spacing(self, nodes: np.ndarray | None = None) -> float:
        """The node spacing (mm) of ``nodes`` (all used nodes if None): the median of their
        :attr:`spacings`, inf where none is known.  Over a face's nodes it is the spacing of the field around
        them however few they are (a large plane of a tessellated part with nodes only at its corners has the
        spacing of the nodes next to those corners, not the corners' distance apart)."""
        values = self.spacings if nodes is None else self.spacings[nodes]
        values = values[np.isfinite(values)]
        return float(np.median(values)) if len(values) else float("inf")
