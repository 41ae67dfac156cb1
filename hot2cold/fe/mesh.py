"""Tetrahedral meshes of a STEP solid with gmsh.

:func:`mesh_step` reads a STEP file with gmsh's OpenCascade reader and meshes every solid in it with
tetrahedra, second order by default, and the element size follows the surface curvature
(``Mesh.MeshSizeFromCurvature``), so thin leading and trailing edges get small elements.  The midside nodes
of boundary edges lie on the curved CAD surface: each is the orthogonal projection of its straight edge's
midpoint onto the curve or surface the edge lies on.  (gmsh's own curved placement takes the midpoint in
the surface's parameters, which on the strongly non-uniform B-spline parameters of a blade lands up to half
an edge length away and inverts thin elements by the hundred.)  Any element still inverted is
straightened (logged as a warning).

Numbering
---------
gmsh imports the STEP faces in the kernel's ``TopExp.MapShapes`` order, the order hot2cold numbers faces
in (:func:`hot2cold.kernel.topology.shape_map`): **gmsh surface tag k + 1 is hot2cold face k**
(checked by ``tests/test_fe.py`` on several parts).  :meth:`TetMesh.face_nodes` uses that.

Nodes are numbered from 0 in the arrays; :attr:`TetMesh.node_tags` keeps gmsh's own node tags (renumbered
1..N by gmsh, so ``node_tags[i] == i + 1`` for a mesh made here).  Tetrahedra keep gmsh's node order
(corners 0-3, then the midside nodes of edges 0-1, 1-2, 2-0, 0-3, 2-3, 1-3).

gmsh runs with one thread (``General.NumThreads = 1``, ``Mesh.MaxNumThreads{1,2,3}D = 1``), so the same
input and options give the same mesh.  gmsh's messages go to :mod:`logging` (logger ``hot2cold.fe.mesh``);
it never prints.
"""
from __future__ import annotations

import contextlib
import itertools
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.arrays import distinct
from ..errors import Hot2ColdError, StepReadError
from ..io.inputs import check_input_file

__all__ = ["SolverError", "TetMesh", "mesh_step", "step_bounding_box", "GMSH_TET_TYPES"]

log = logging.getLogger(__name__)

#: gmsh element type numbers of the tetrahedra, by order: 4-node (1) and 10-node (2).
GMSH_TET_TYPES = {1: 4, 2: 11}

#: Node count of a tetrahedron, by order.
TET_NODES = {1: 4, 2: 10}

#: Corner nodes of the edges of gmsh's 10-node tetrahedron, whose midside nodes are nodes 4..9.
_EDGE_A = np.array([0, 1, 2, 0, 2, 1])
_EDGE_B = np.array([1, 2, 0, 3, 3, 3])


class SolverError(Hot2ColdError, RuntimeError):
    """An external FE tool (the gmsh mesher, the CalculiX solver) is missing or failed."""

    exit_code = 3


@dataclass(frozen=True, eq=False)
class TetMesh:
    """A tetrahedral mesh, in millimetres.

    Attributes
    ----------
    nodes : numpy.ndarray
        (N, 3) float64 node coordinates, mm.
    tets : numpy.ndarray
        (M, 10) int64 node indices (0-based rows of ``nodes``) per 10-node tetrahedron, in gmsh's node
        order; (M, 4) for first-order meshes.
    surface_nodes : dict[int, numpy.ndarray]
        gmsh surface tag -> sorted (k,) int64 indices of the nodes on that surface, its boundary curves
        and corners included.  Surface tag ``k + 1`` is hot2cold face ``k`` (see :meth:`face_nodes`).
    node_tags : numpy.ndarray
        (N,) int64 gmsh node tags of the rows of ``nodes``; the node numbers written to a CalculiX deck.
    source : str
        Where the mesh came from (the STEP path), for messages.
    """

    nodes: np.ndarray
    tets: np.ndarray
    surface_nodes: dict = field(default_factory=dict)
    node_tags: np.ndarray | None = None
    source: str = ""

    def __post_init__(self):
        nodes = np.array(self.nodes, dtype=np.float64, order="C", copy=True)
        tets = np.array(self.tets, dtype=np.int64, order="C", copy=True)
        if nodes.ndim != 2 or nodes.shape[1] != 3 or len(nodes) == 0:
            raise ValueError(f"nodes must have shape (N, 3) with N >= 1, got {nodes.shape}")
        if tets.ndim != 2 or tets.shape[1] not in (4, 10) or len(tets) == 0:
            raise ValueError(f"tets must have shape (M, 10) or (M, 4) with M >= 1, got {tets.shape}")
        if tets.min() < 0 or tets.max() >= len(nodes):
            raise ValueError(f"tets refer to node indices outside 0..{len(nodes) - 1}")
        tags = (np.arange(1, len(nodes) + 1, dtype=np.int64) if self.node_tags is None
                else np.array(self.node_tags, dtype=np.int64, copy=True))
        if tags.shape != (len(nodes),):
            raise ValueError(f"node_tags must have shape ({len(nodes)},), got {tags.shape}")
        surfaces = {int(k): distinct(np.asarray(v, dtype=np.int64)) for k, v in self.surface_nodes.items()}
        for arr in itertools.chain((nodes, tets, tags), surfaces.values()):
            arr.flags.writeable = False
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "tets", tets)
        object.__setattr__(self, "node_tags", tags)
        object.__setattr__(self, "surface_nodes", surfaces)

    @property
    def order(self) -> int:
        """1 for 4-node, 2 for 10-node tetrahedra."""
        return 2 if self.tets.shape[1] == 10 else 1

    def face_nodes(self, face: int) -> np.ndarray:
        """Indices ``(k,)`` of the nodes on hot2cold face ``face`` (0-based; gmsh surface ``face + 1``)."""
        try:
            return self.surface_nodes[int(face) + 1]
        except KeyError:
            raise IndexError(f"no face {face}: the mesh has faces 0..{len(self.surface_nodes) - 1}") from None

    def boundary_nodes(self) -> np.ndarray:
        """Sorted indices ``(k,)`` of all nodes on the boundary surfaces."""
        if not self.surface_nodes:
            return np.zeros(0, dtype=np.int64)
        return distinct(np.concatenate(list(self.surface_nodes.values())))

    def __repr__(self) -> str:
        return (f"TetMesh({len(self.nodes)} nodes, {len(self.tets)} tetrahedra of order {self.order}, "
                f"{len(self.surface_nodes)} surfaces, source={self.source!r})")


# --------------------------------------------------------------------------------------------------------
# gmsh session
# --------------------------------------------------------------------------------------------------------
def _import_gmsh():
    try:
        import gmsh
    except (ImportError, OSError) as exc:  # OSError: the wheel's libgmsh misses a system library
        raise SolverError(
            f"gmsh is not available ({' '.join(str(exc).split())}); install the FE extra: "
            f"pip install 'hot2cold[fe]' (the gmsh wheel also needs libGLU, libGL, libXrender, libXcursor, "
            f"libXft, libXinerama)") from None
    return gmsh


_THREAD_OPTIONS = ("General.NumThreads", "Mesh.MaxNumThreads1D", "Mesh.MaxNumThreads2D",
                   "Mesh.MaxNumThreads3D")


@contextlib.contextmanager
def _session(numbers: dict[str, float], strings: dict[str, str]):
    """A gmsh model with the given options, cleaned up on exit even after errors.

    If gmsh is not initialised it is initialised here (without reading the user's config files, without
    installing a signal handler) and finalised on exit.  If the caller already runs gmsh, a new model is
    added and removed on exit, and the options changed here are restored.
    """
    gmsh = _import_gmsh()
    numbers = {"General.Terminal": 0, **numbers}  # gmsh prints nothing: its messages go to logging
    own = not gmsh.isInitialized()
    if own:
        gmsh.initialize([], readConfigFiles=False, run=False, interruptible=False)
        saved_n, saved_s, previous = {}, {}, None
    else:
        saved_n = {k: gmsh.option.getNumber(k) for k in numbers}
        saved_s = {k: gmsh.option.getString(k) for k in strings}
        previous = gmsh.model.getCurrent()
    logging_started = False
    try:
        gmsh.option.setNumber("General.Terminal", 0)  # before the logger starts: nothing printed
        gmsh.logger.start()
        logging_started = True
        for k, v in numbers.items():
            gmsh.option.setNumber(k, v)
        for k, v in strings.items():
            gmsh.option.setString(k, v)
        name = f"hot2cold-{os.getpid()}-{id(numbers)}"
        gmsh.model.add(name)
        yield gmsh
    finally:
        try:
            if logging_started:
                for msg in gmsh.logger.get():
                    log.debug("gmsh: %s", msg)
                gmsh.logger.stop()
        finally:
            if own:
                gmsh.finalize()
            else:
                with contextlib.suppress(Exception):
                    gmsh.model.remove()
                if previous:
                    with contextlib.suppress(Exception):
                        gmsh.model.setCurrent(previous)
                for k, v in saved_n.items():
                    gmsh.option.setNumber(k, v)
                for k, v in saved_s.items():
                    gmsh.option.setString(k, v)


def _last_error(gmsh, exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    try:
        errors = [m for m in gmsh.logger.get() if m.startswith("Error")]
    except Exception:
        errors = []
    if errors:
        text = " ".join(errors[-1].split())
    return text or type(exc).__name__


# --------------------------------------------------------------------------------------------------------
# Meshing
# --------------------------------------------------------------------------------------------------------
def mesh_step(step_path, size: float, min_size: float | None = None, curvature: float = 20,
              order: int = 2) -> TetMesh:
    """Mesh every solid of a STEP file with tetrahedra.

    Parameters
    ----------
    step_path : str or os.PathLike
        The STEP file (lengths are read in millimetres, whatever unit the file declares).
    size : float
        Largest element edge, mm (``Mesh.MeshSizeMax``).
    min_size : float or None
        Smallest element edge, mm (``Mesh.MeshSizeMin``); ``None`` for no lower bound, so the curvature
        alone decides how fine small radii get.
    curvature : float
        Target number of elements per 2*pi of surface curvature (``Mesh.MeshSizeFromCurvature``); 0 turns
        curvature sizing off.  20 puts about 10 elements around a leading-edge half circle.
    order : int
        2 (default) for 10-node tetrahedra with midside nodes on the CAD surface, 1 for 4-node ones.

    Returns
    -------
    TetMesh
        Nodes (N, 3) mm, tetrahedra (M, 10) (or (M, 4)), nodes per gmsh surface.

    Raises
    ------
    StepReadError
        The STEP file is missing, or gmsh finds no solid in it.
    SolverError
        gmsh is not installed, or fails, or leaves inverted elements even with straight edges.

    Notes
    -----
    A curved tetrahedron whose Jacobian turns non-positive anywhere (gmsh's ``minDetJac``) is straightened
    (logged as a warning with the largest distance of a straightened boundary node from the CAD surface).
    This happens where the surface curves more sharply than the elements can follow (a blade's leading edge
    whose B-spline has curvature spikes far sharper than the smallest element); the straightened elements'
    boundary nodes then lie off the CAD surface, by as much as the warning states.
    ValueError
        A size, the curvature or the order is out of range.
    """
    path = check_input_file(Path(os.fspath(step_path)).expanduser(), "STEP file", StepReadError)
    size = float(size)
    if not (np.isfinite(size) and size > 0):
        raise ValueError(f"size must be a positive number of mm, got {size!r}")
    if min_size is not None:
        min_size = float(min_size)
        if not (np.isfinite(min_size) and 0 <= min_size <= size):
            raise ValueError(f"min_size must lie in [0, size={size}] mm, got {min_size!r}")
    curvature = float(curvature)
    if not (np.isfinite(curvature) and curvature >= 0):
        raise ValueError(f"curvature must be >= 0 elements per 2*pi, got {curvature!r}")
    if order not in TET_NODES:
        raise ValueError(f"order must be 1 or 2, got {order!r}")

    numbers = {k: 1 for k in _THREAD_OPTIONS}
    numbers.update({
        "Mesh.MeshSizeMax": size,
        "Mesh.MeshSizeMin": 0.0 if min_size is None else min_size,
        "Mesh.MeshSizeFromCurvature": curvature,
        "Mesh.MeshSizeExtendFromBoundary": 1,
        "Mesh.ElementOrder": order,
        "Mesh.SecondOrderLinear": 1,         # straight first; then projected onto the CAD geometry
        "Mesh.HighOrderOptimize": 0,
        "Mesh.Optimize": 1,
    })
    strings = {"Geometry.OCCTargetUnit": "MM"}
    with _session(numbers, strings) as gmsh:
        _import_step(gmsh, path)
        volumes = gmsh.model.getEntities(3)
        if not volumes:
            raise StepReadError(f"STEP file {path} holds no solid gmsh can mesh")
        try:
            gmsh.model.mesh.generate(3)
        except Exception as exc:
            raise SolverError(f"gmsh failed to mesh {path}: {_last_error(gmsh, exc)}") from None
        etype = GMSH_TET_TYPES[order]
        if order == 2:
            moved, largest = _place_midside(gmsh, etype)
            log.debug("%s: %d midside nodes projected onto the CAD geometry, up to %.3g mm off the chord",
                      path, moved, largest)
            _straighten_inverted(gmsh, etype, path)
        gmsh.model.mesh.renumberNodes()
        gmsh.model.mesh.renumberElements()
        mesh = _extract(gmsh, etype, TET_NODES[order], str(path))
    log.info("meshed %s: %d nodes, %d tetrahedra (order %d, size %g mm, min %s, curvature %g)", path,
             len(mesh.nodes), len(mesh.tets), order, size, "none" if min_size is None else f"{min_size:g} mm",
             curvature)
    return mesh


def _import_step(gmsh, path: Path) -> None:
    try:
        gmsh.model.occ.importShapes(str(path), highestDimOnly=True)
        gmsh.model.occ.synchronize()
    except Exception as exc:
        raise StepReadError(f"gmsh cannot read STEP file {path}: {_last_error(gmsh, exc)}") from None


def step_bounding_box(step_path) -> np.ndarray:
    """The bounding box ``(2, 3)`` (min corner, max corner), mm, of a STEP file's shapes, read by gmsh."""
    path = check_input_file(Path(os.fspath(step_path)).expanduser(), "STEP file", StepReadError)
    with _session({}, {"Geometry.OCCTargetUnit": "MM"}) as gmsh:
        _import_step(gmsh, path)
        box = np.array(gmsh.model.getBoundingBox(-1, -1), dtype=np.float64).reshape(2, 3)
    if not np.all(np.isfinite(box)) or np.any(box[1] < box[0]):
        raise StepReadError(f"STEP file {path} holds no geometry")
    return box


def _min_det_jac(gmsh, etype: int) -> tuple[np.ndarray, np.ndarray]:
    """Element tags ``(M,)`` and their smallest Jacobian determinant ``(M,)`` (gmsh's adaptive bound)."""
    tags, _ = gmsh.model.mesh.getElementsByType(etype)
    if len(tags) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    return np.asarray(tags, dtype=np.int64), np.asarray(gmsh.model.mesh.getElementQualities(tags, "minDetJac"))


def _all_nodes(gmsh) -> tuple[np.ndarray, np.ndarray]:
    """All node tags ``(n,)`` sorted, and their coordinates ``(n, 3)``."""
    tags, coords, _ = gmsh.model.mesh.getNodes(returnParametricCoord=False)
    tags = np.asarray(tags, dtype=np.int64)
    order = np.argsort(tags)
    return tags[order], np.asarray(coords, dtype=np.float64).reshape(-1, 3)[order]


def _midside_edges(gmsh, etype: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every midside node tag ``(k,)`` with the tags of its edge's two corner nodes ``(k,)``, ``(k,)``."""
    _, enodes = gmsh.model.mesh.getElementsByType(etype)
    conn = np.asarray(enodes, dtype=np.int64).reshape(-1, 10)
    mids = conn[:, 4:].ravel()
    a = conn[:, _EDGE_A].ravel()
    b = conn[:, _EDGE_B].ravel()
    mids, first = np.unique(mids, return_index=True)
    return mids, a[first], b[first]


def _place_midside(gmsh, etype: int) -> tuple[int, float]:
    """Put the midside nodes of boundary edges on the CAD geometry, by projection of the edge's midpoint.

    gmsh's own curved placement (``Mesh.SecondOrderLinear = 0``) takes the parametric midpoint of the edge,
    which lands far from the edge (up to half its length) where a B-spline surface's parameters are strongly
    non-uniform, and inverts thin elements.  The orthogonal projection of the straight midpoint onto the curve
    or surface is off the chord by the sagitta only.

    Returns the number of nodes moved and the largest move, mm.
    """
    mids, a, b = _midside_edges(gmsh, etype)
    tags, xyz = _all_nodes(gmsh)
    chord = 0.5 * (xyz[np.searchsorted(tags, a)] + xyz[np.searchsorted(tags, b)])
    length = np.linalg.norm(xyz[np.searchsorted(tags, a)] - xyz[np.searchsorted(tags, b)], axis=1)
    moved, largest = 0, 0.0
    for dim in (1, 2):
        for _, ent in gmsh.model.getEntities(dim):
            ntags, _, _ = gmsh.model.mesh.getNodes(dim, ent, includeBoundary=False, returnParametricCoord=False)
            ntags = np.asarray(ntags, dtype=np.int64)
            k = np.searchsorted(mids, ntags)
            on = (k < len(mids)) & (mids[np.minimum(k, len(mids) - 1)] == ntags)
            k = k[on]
            if not len(k):
                continue
            foot, par = gmsh.model.getClosestPoint(dim, ent, chord[k].ravel())
            foot = np.asarray(foot, dtype=np.float64).reshape(-1, 3)
            par = np.asarray(par, dtype=np.float64).reshape(len(k), -1)
            off = np.linalg.norm(foot - chord[k], axis=1)
            good = np.isfinite(off) & (off <= 0.5 * length[k])  # else: keep the straight midpoint
            for tag, x, uv in zip(mids[k][good].tolist(), foot[good].tolist(), par[good].tolist()):
                gmsh.model.mesh.setNode(tag, x, uv)
            moved += int(good.sum())
            if good.any():
                largest = max(largest, float(off[good].max()))
    return moved, largest


def _straighten_inverted(gmsh, etype: int, path: Path) -> None:
    """Straighten (midside nodes at the chord midpoints) the curved tetrahedra that are inverted.

    A straight-sided tetrahedron with positive volume is valid, so this always ends with a valid mesh; the
    straightened boundary nodes lie off the CAD surface by their edge's sagitta.
    """
    for _ in range(5):
        tags, det = _min_det_jac(gmsh, etype)
        bad = tags[det <= 0]
        if not len(bad):
            return
        mids, a, b = _midside_edges(gmsh, etype)
        ntags, xyz = _all_nodes(gmsh)
        todo = set()
        for e in bad.tolist():
            _, enodes, _, _ = gmsh.model.mesh.getElement(e)
            todo.update(int(t) for t in enodes[4:])
        todo = np.array(sorted(todo), dtype=np.int64)
        k = np.searchsorted(mids, todo)
        pa = xyz[np.searchsorted(ntags, a[k])]
        pb = xyz[np.searchsorted(ntags, b[k])]
        now = xyz[np.searchsorted(ntags, todo)]
        mid = 0.5 * (pa + pb)
        off = float(np.linalg.norm(now - mid, axis=1).max())
        for tag, x in zip(todo.tolist(), mid.tolist()):
            _, _, dim, _ = gmsh.model.mesh.getNode(tag)
            gmsh.model.mesh.setNode(tag, x, [] if dim == 3 else _param(gmsh, tag, x, dim))
        log.warning("%s: %d curved tetrahedra inverted; straightened their %d midside nodes (moved up to "
                    "%.3g mm off the CAD surface); a smaller size or min_size avoids this", path, len(bad),
                    len(todo), off)
    tags, det = _min_det_jac(gmsh, etype)
    if np.any(det <= 0):
        raise SolverError(
            f"gmsh left {int((det <= 0).sum())} inverted tetrahedra in the mesh of {path}, even with straight "
            f"edges; use a smaller size or min_size")


def _param(gmsh, tag: int, x, dim: int) -> list:
    """Parametric coordinates of point ``x`` on the entity node ``tag`` is classified on."""
    _, _, _, ent = gmsh.model.mesh.getNode(tag)
    _, par = gmsh.model.getClosestPoint(dim, ent, list(x))
    return list(par)


def _extract(gmsh, etype: int, nper: int, source: str) -> TetMesh:
    """The mesh of the current gmsh model as a :class:`TetMesh` (nodes used by tetrahedra only)."""
    tags, coords, _ = gmsh.model.mesh.getNodes()
    tags = np.asarray(tags, dtype=np.int64)
    coords = np.asarray(coords, dtype=np.float64).reshape(-1, 3)
    _, enodes = gmsh.model.mesh.getElementsByType(etype)
    enodes = np.asarray(enodes, dtype=np.int64).reshape(-1, nper)
    if len(enodes) == 0:
        raise SolverError(f"gmsh produced no tetrahedra for {source}")
    used = distinct(enodes)
    order = np.argsort(tags)
    tags, coords = tags[order], coords[order]
    pos = np.searchsorted(tags, used)
    if np.any(pos >= len(tags)) or np.any(tags[np.minimum(pos, len(tags) - 1)] != used):
        raise SolverError(f"gmsh's tetrahedra of {source} refer to unknown nodes")
    node_tags, nodes = tags[pos], coords[pos]
    tets = np.searchsorted(node_tags, enodes)
    surfaces = {}
    for _, s in gmsh.model.getEntities(2):
        stags, _, _ = gmsh.model.mesh.getNodes(2, s, includeBoundary=True)
        stags = distinct(np.asarray(stags, dtype=np.int64))
        k = np.searchsorted(node_tags, stags)
        ok = (k < len(node_tags)) & (node_tags[np.minimum(k, len(node_tags) - 1)] == stags)
        surfaces[int(s)] = k[ok]
    return TetMesh(nodes, tets, surfaces, node_tags, source)
