"""The hot-to-cold load case with CalculiX: input deck, solver run, and the whole pipeline.

The FE model is built on the **hot** geometry (the part as designed at running conditions).  The cold
shape is what the part looks like once the running loads are gone, so the load case on the hot model is
the removal of those loads, linear static (small strains; no stress stiffening or spin softening,
``NLGEOM`` off; material constants independent of temperature):

* temperature: the initial (stress-free) nodal temperatures are the hot ones
  (``*INITIAL CONDITIONS, TYPE=TEMPERATURE``) and a step brings every node to room temperature
  (``*TEMPERATURE``): thermal strain ``alpha * (T_room - T_hot)``, a contraction;
* rotation: the centrifugal body force ``rho * omega^2 * r`` of the running speed is removed;
* supports: the chosen nodes (e.g. the root / hub face) are fixed in all or in chosen directions.

Removing the centrifugal load means applying ``-rho * omega^2 * r``.  CalculiX 2.20 does **not** do that
with ``*DLOAD ... CENTRIF`` and a magnitude ``-omega^2``: the input is accepted without a message and the
load is silently dropped (zero displacement).  A negative amplitude (``*AMPLITUDE`` value -1) and a
negative density are dropped the same way (checked: ``tests/test_fe.py``).  So the deck has two linear
steps and the field is their difference, which linearity makes exact:

1. ``CENTRIF`` with ``+omega^2``, temperatures left at their hot initial values: ``U_1 = K^-1 f_rot``;
2. the centrifugal load removed (``*DLOAD, OP=NEW``), temperatures brought to room temperature:
   ``U_2 = K^-1 f_thermal`` (CalculiX's linear static steps solve for the step's total load);

hot -> cold ``U = U_2 - U_1``.  :func:`read_hot_to_cold` reads an ``.frd`` of such a deck that way, and so
does :func:`hot2cold.io.field.read_field` (the deck's heading marks its ``.frd``).  Without
rotation (``omega = 0``) the deck has only the thermal step and ``U`` is its displacement.

Units: mm, t (tonne), s, N, MPa; temperatures in K; ``omega`` in rad/s.

Node numbers in the deck are :attr:`TetMesh.node_tags`; gmsh's 10-node tetrahedron becomes CalculiX's
C3D10 with its last two nodes swapped (gmsh: midside nodes of edges 2-3 then 1-3; CalculiX: 1-3 then 2-3),
the 4-node one C3D4 unchanged.
"""
from __future__ import annotations

import logging
import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.arrays import distinct
from ..errors import FieldError
from ..io.atomic import write_atomically
from ..io.field import DisplacementField, match_points
from ..io.frd import HOT_TO_COLD_HEADING, FrdFile
from .mesh import SolverError, TetMesh, mesh_step, step_bounding_box

__all__ = ["Material", "TI6AL4V", "write_deck", "run_ccx", "read_hot_to_cold", "hot_to_cold_field",
           "MeshOptions", "LoadCase", "SolverOptions",
           "blade_temperature",
           "hub_faces", "ROOM_TEMPERATURE", "ROTOR37_OMEGA"]

log = logging.getLogger(__name__)

#: Room temperature, K.
ROOM_TEMPERATURE = 293.0

#: NASA Rotor 37 design speed, rad/s (17 188.7 rpm).
ROTOR37_OMEGA = 1800.0

#: gmsh 10-node tetrahedron -> CalculiX C3D10 node order (the last two nodes swapped).
GMSH_TO_C3D10 = np.array([0, 1, 2, 3, 4, 5, 6, 7, 9, 8])

#: CalculiX data lines hold at most 16 entries.
_PER_LINE = 16


@dataclass(frozen=True)
class Material:
    """A linear elastic, isotropic, thermally expanding material in the mm-t-s-N-MPa system.

    Attributes
    ----------
    name : str, a CalculiX material name (letters, digits, ``_``; at most 80 characters).
    young : float, Young's modulus E, MPa.
    poisson : float, Poisson's ratio nu.
    density : float, rho, t/mm^3 (4.43e-9 t/mm^3 = 4430 kg/m^3).
    expansion : float, mean coefficient of thermal expansion alpha, 1/K.
    """

    name: str = "TI6AL4V"
    young: float = 110e3
    poisson: float = 0.34
    density: float = 4.43e-9
    expansion: float = 9.0e-6

    def __post_init__(self):
        if not self.name or not all(c.isalnum() or c == "_" for c in self.name) or len(self.name) > 80:
            raise ValueError(f"material name must be letters, digits and '_' (<= 80), got {self.name!r}")
        if not (self.young > 0 and -1.0 < self.poisson < 0.5 and self.density >= 0 and self.expansion >= 0):
            raise ValueError(f"material constants out of range: {self}")


#: Ti-6Al-4V, the usual compressor blade alloy.
TI6AL4V = Material()


# --------------------------------------------------------------------------------------------------------
# Deck
# --------------------------------------------------------------------------------------------------------
def _axis(axis_point, axis_direction) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(axis_point, dtype=np.float64).reshape(-1)
    d = np.asarray(axis_direction, dtype=np.float64).reshape(-1)
    if p.shape != (3,) or d.shape != (3,) or not (np.all(np.isfinite(p)) and np.all(np.isfinite(d))):
        raise ValueError("axis_point and axis_direction must be 3 finite numbers each")
    n = np.linalg.norm(d)
    if n == 0:
        raise ValueError("axis_direction must not be zero")
    return p, d / n


def _constraints(fixed_nodes, n_nodes: int) -> dict[tuple[int, ...], np.ndarray]:
    """Fixed directions (0-based axes) -> sorted node indices."""
    if isinstance(fixed_nodes, Mapping):
        groups: dict[int, np.ndarray] = {}
        for axis, nodes in fixed_nodes.items():
            if axis not in (0, 1, 2):
                raise ValueError(f"fixed_nodes keys must be axes 0 (x), 1 (y), 2 (z), got {axis!r}")
            groups[int(axis)] = distinct(np.asarray(nodes, dtype=np.int64))
        out = {}
        for axis, nodes in sorted(groups.items()):
            out[(axis,)] = nodes
    else:
        out = {(0, 1, 2): distinct(np.asarray(fixed_nodes, dtype=np.int64))}
    for nodes in out.values():
        if len(nodes) and (nodes[0] < 0 or nodes[-1] >= n_nodes):
            raise ValueError(f"fixed node indices must lie in 0..{n_nodes - 1}")
    if not any(len(v) for v in out.values()):
        raise ValueError("no fixed node: the model would be free to move as a rigid body")
    return out


def _num(v: float) -> str:
    """A float for a CalculiX data line: 13 significant digits, at most 20 characters (ccx's limit per
    entry: a longer one such as ``2.6645352591003757E-15`` is an input error)."""
    return f"{v:.13g}"


def _lines(values: np.ndarray, per_line: int = _PER_LINE) -> list[str]:
    return [", ".join(map(str, values[i:i + per_line])) for i in range(0, len(values), per_line)]


def write_deck(mesh: TetMesh, path, *, material: Material = TI6AL4V, fixed_nodes,
               hot_temperature, room_temperature: float = ROOM_TEMPERATURE, omega: float = 0.0,
               axis_point=(0.0, 0.0, 0.0), axis_direction=(0.0, 0.0, 1.0)) -> Path:
    """Write the CalculiX input deck of the hot-to-cold load case (see the module documentation).

    Parameters
    ----------
    mesh : TetMesh
        The hot geometry's mesh, mm.
    path : str or os.PathLike
        The deck to write; must end in ``.inp`` (CalculiX's job name is the file name without it).
    material : Material
        Default Ti-6Al-4V.
    fixed_nodes : array-like or mapping
        Node indices (0-based rows of ``mesh.nodes``) fixed in x, y and z; or a mapping
        ``{axis: indices}`` (axis 0 = x, 1 = y, 2 = z) fixing only those directions (sliding supports,
        symmetry planes).
    hot_temperature : float or array-like
        Running temperature, K: one value, or (N,) per node.
    room_temperature : float
        The cold state's temperature, K (default 293 K).
    omega : float
        Running speed, rad/s; its centrifugal load is removed (two steps, see the module documentation).
        0: no rotation, one step.
    axis_point, axis_direction : 3 floats
        The rotation axis: a point on it, mm, and its direction (normalised here).

    Returns
    -------
    pathlib.Path
        The deck written.
    """
    path = Path(os.fspath(path)).expanduser()
    if path.suffix.lower() != ".inp":
        raise ValueError(f"a CalculiX deck must end in .inp, got {path.name!r}")
    n = len(mesh.nodes)
    temps = np.asarray(hot_temperature, dtype=np.float64)
    if temps.ndim == 0:
        temps = np.full(n, float(temps))
    if temps.shape != (n,) or not np.all(np.isfinite(temps)):
        raise ValueError(f"hot_temperature must be a finite number or shape ({n},), got shape {temps.shape}")
    room = float(room_temperature)
    omega = float(omega)
    if not (np.isfinite(room) and np.isfinite(omega)):
        raise ValueError("room_temperature and omega must be finite")
    point, direction = _axis(axis_point, axis_direction)
    groups = _constraints(fixed_nodes, n)
    ids = np.asarray(mesh.node_tags, dtype=np.int64)
    if len(distinct(ids)) != n or ids.min() < 1:
        raise ValueError("mesh.node_tags must be distinct positive numbers (CalculiX node numbers)")

    if mesh.tets.shape[1] == 10:
        etype, conn = "C3D10", ids[mesh.tets[:, GMSH_TO_C3D10]]
    else:
        etype, conn = "C3D4", ids[mesh.tets]
    elem_ids = np.arange(1, len(conn) + 1)

    out: list[str] = [
        "** hot-to-cold load case written by hot2cold.fe.calculix (units mm, t, s, N, MPa, K)",
        "*HEADING",
        f"{HOT_TO_COLD_HEADING}: U = U(last step) - U(first step)",
        "*NODE, NSET=NALL",
    ]
    out += [f"{i}, {_num(x)}, {_num(y)}, {_num(z)}" for i, (x, y, z) in zip(ids.tolist(), mesh.nodes.tolist())]
    out.append(f"*ELEMENT, TYPE={etype}, ELSET=EALL")
    out += [", ".join(map(str, row)) for row in np.column_stack([elem_ids, conn]).tolist()]
    boundary = []
    for k, (axes, nodes) in enumerate(groups.items()):
        if not len(nodes):
            continue
        name = f"FIX{k}"
        out.append(f"*NSET, NSET={name}")
        out += _lines(ids[nodes])
        boundary.append(f"{name}, {axes[0] + 1}, {axes[-1] + 1}")
    out += ["*BOUNDARY"] + boundary
    m = material
    out += [
        f"*MATERIAL, NAME={m.name}",
        "*ELASTIC",
        f"{_num(m.young)}, {_num(m.poisson)}",
        "*DENSITY",
        _num(m.density),
        "*EXPANSION",
        _num(m.expansion),
        f"*SOLID SECTION, ELSET=EALL, MATERIAL={m.name}",
        "*INITIAL CONDITIONS, TYPE=TEMPERATURE",
    ]
    out += [f"{i}, {_num(t)}" for i, t in zip(ids.tolist(), temps.tolist())]
    if omega != 0.0:
        px, py, pz = point.tolist()
        dx, dy, dz = direction.tolist()
        out += [
            "** step 1: the running speed's centrifugal load on the hot part (temperatures stay hot)",
            "*STEP",
            "*STATIC",
            "*DLOAD",
            "EALL, CENTRIF, " + ", ".join(map(_num, (omega * omega, px, py, pz, dx, dy, dz))),
            "*NODE FILE",
            "U",
            "*END STEP",
            "** step 2: no rotation, room temperature.  Hot to cold = U(step 2) - U(step 1)",
        ]
    out += ["*STEP", "*STATIC", "*TEMPERATURE", f"NALL, {_num(room)}"]
    if omega != 0.0:
        out.append("*DLOAD, OP=NEW")
    out += ["*NODE FILE", "U", "*END STEP", ""]
    too_long = next((ln for ln in out if len(ln) > 132), None)
    if too_long is not None:  # cannot happen with _num; CalculiX would cut the line silently
        raise ValueError(f"deck line longer than 132 characters: {too_long[:60]}...")
    path.write_text("\n".join(out))
    log.info("wrote %s: %d nodes, %d %s, %d fixed node(s), T %g..%g K -> %g K, omega %g rad/s", path, n,
             len(conn), etype, sum(len(v) for v in groups.values()), temps.min(), temps.max(), room, omega)
    return path


# --------------------------------------------------------------------------------------------------------
# Solver
# --------------------------------------------------------------------------------------------------------
def _tail(text: str, lines: int = 12) -> str:
    kept = [ln.strip() for ln in text.strip().splitlines() if ln.strip()][-lines:]
    return " | ".join(kept)


def run_ccx(deck_path, timeout: float = 3600.0, *, threads: int = 2, ccx: str = "ccx") -> Path:
    """Run CalculiX on a deck and return the path of its ``.frd`` results.

    ccx runs in the deck's folder (it writes ``<job>.frd``, ``.dat``, ``.sta``, ``.cvg`` there) with
    ``OMP_NUM_THREADS`` (and ``CCX_NPROC_*``) set to ``threads``, at most 2; its output is kept in
    ``<job>.log`` next to the deck.

    Parameters
    ----------
    deck_path : str or os.PathLike, the ``.inp`` deck.
    timeout : float, seconds before ccx is stopped.
    threads : int, solver threads (1 or 2).
    ccx : str, the executable's name or path.

    Raises
    ------
    SolverError
        ccx is missing, times out, exits with an error or writes an error message, or leaves no results;
        the message ends with the tail of ccx's output.
    """
    deck = Path(os.fspath(deck_path)).expanduser().resolve()
    if deck.suffix.lower() != ".inp" or not deck.is_file():
        raise SolverError(f"CalculiX deck not found (it must be an .inp file): {deck}")
    exe = shutil.which(ccx)
    if exe is None:
        raise SolverError(
            f"CalculiX executable {ccx!r} not found on the PATH; install CalculiX (Debian/Ubuntu: "
            f"apt-get install calculix-ccx) or pass ccx='/path/to/ccx'")
    nthreads = str(max(1, min(2, int(threads))))
    env = dict(os.environ, OMP_NUM_THREADS=nthreads, CCX_NPROC_EQUATION_SOLVER=nthreads,
               CCX_NPROC_RESULTS=nthreads, CCX_NPROC_STIFFNESS=nthreads)
    job = deck.with_suffix("")
    frd = job.with_suffix(".frd")
    logfile = job.with_suffix(".log")
    if frd.exists():
        frd.unlink()  # never mistake an old result for this run's
    start = time.perf_counter()
    try:
        proc = subprocess.run([exe, "-i", job.name], cwd=deck.parent, env=env, stdin=subprocess.DEVNULL,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=timeout)
    except subprocess.TimeoutExpired as exc:
        output = (exc.output or b"").decode("utf-8", "replace")
        logfile.write_text(output)
        raise SolverError(f"ccx did not finish {deck.name} within {timeout:g} s; tail of its output: "
                          f"{_tail(output)}") from None
    except OSError as exc:
        raise SolverError(f"cannot run CalculiX {exe}: {' '.join(str(exc).split())}") from None
    output = proc.stdout.decode("utf-8", "replace")
    logfile.write_text(output)
    elapsed = time.perf_counter() - start
    lines = [ln.strip() for ln in output.splitlines() if ln.strip()]
    errors = [k for k, ln in enumerate(lines) if "*ERROR" in ln.upper()]
    if proc.returncode != 0 or errors:
        what = (f"killed by signal {-proc.returncode}" if proc.returncode < 0
                else f"exit code {proc.returncode}" if proc.returncode != 0 else "an error message")
        first = ""
        if errors:
            k = errors[0]
            first = (f"{len(errors)} error message(s), the first: "
                     f"{' '.join(lines[k:k + 2]) if k + 1 < len(lines) and '*' not in lines[k + 1] else lines[k]!r}; ")
        raise SolverError(f"ccx failed on {deck.name} ({what}): {first}tail of its output (full log {logfile}): "
                          f"{_tail(output, 6)}")
    if not frd.is_file() or b"  100C" not in frd.read_bytes():
        warnings = [ln for ln in lines if "*WARNING" in ln.upper()][:3]
        said = f"its warnings: {' | '.join(warnings)}; " if warnings else ""
        raise SolverError(f"ccx wrote no results into {frd.name} for {deck.name} (does the deck have a *STEP "
                          f"with *NODE FILE?); {said}tail of its output: {_tail(output, 6)}")
    log.info("ccx solved %s in %.1f s (%s thread(s))", deck.name, elapsed, nthreads)
    return frd


def read_hot_to_cold(frd_path, points_from=None) -> DisplacementField:
    """The hot -> cold field from the ``.frd`` of a :func:`write_deck` deck, mm.

    Two displacement blocks (a rotating part): ``U(last) - U(first)``; one block: that block
    (:meth:`hot2cold.io.frd.FrdFile.hot_to_cold`; ``read_field`` does the same for an ``.frd`` whose
    heading marks it as hot2cold's).  Node positions from ``points_from`` (the :class:`TetMesh` of the run,
    or see :func:`hot2cold.io.field.match_points`), else the ``.frd``'s own 6-digit ones; ``node_ids`` the
    CalculiX node numbers; ``triangles`` the boundary triangles of the ``.frd``'s tetrahedra
    (:attr:`hot2cold.io.frd.FrdResult.triangles`).
    """
    frd = FrdFile.read(frd_path)
    result = frd.hot_to_cold()
    points = result.points if points_from is None else match_points(points_from, result.node_ids,
                                                                    result.points, frd.path)
    return DisplacementField(points, result.values, result.node_ids, source=frd.path,
                             triangles=result.triangles, result_set=result.label)


# --------------------------------------------------------------------------------------------------------
# The pipeline
# --------------------------------------------------------------------------------------------------------
def _radius(points: np.ndarray, point: np.ndarray, direction: np.ndarray) -> np.ndarray:
    rel = points - point
    return np.linalg.norm(rel - np.outer(rel @ direction, direction), axis=1)


def blade_temperature(points, hub: float = 420.0, tip: float = 480.0, axis_point=(0.0, 0.0, 0.0),
                      axis_direction=(0.0, 0.0, 1.0)) -> np.ndarray:
    """A blade's running temperature, K ``(N,)``: linear in the radius of ``points`` ``(N, 3)`` mm about the
    axis, ``hub`` at the smallest radius among them and ``tip`` at the largest."""
    p, d = _axis(axis_point, axis_direction)
    r = _radius(np.asarray(points, dtype=np.float64).reshape(-1, 3), p, d)
    span = r.max() - r.min()
    s = (r - r.min()) / span if span > 0 else np.zeros_like(r)
    return hub + (tip - hub) * s


def hub_faces(mesh: TetMesh, axis_point=(0.0, 0.0, 0.0), axis_direction=(0.0, 0.0, 1.0)) -> list[int]:
    """The hot2cold face (0-based) nearest the axis: the one whose nodes have the smallest mean radius.

    For a blade that is the root (hub) face; for other parts pass the faces to fix explicitly.
    """
    p, d = _axis(axis_point, axis_direction)
    mean = {s - 1: float(_radius(mesh.nodes[idx], p, d).mean())
            for s, idx in mesh.surface_nodes.items() if len(idx)}
    if not mean:
        raise SolverError(f"the mesh of {mesh.source} has no surface nodes")
    return [min(mean, key=mean.get)]


def _write_npz(field: DisplacementField, path: Path) -> None:
    """Write ``points``, ``displacements``, ``node_ids`` (and ``triangles`` when the field has them)
    compressed under exactly ``path``, whole or not at all (:func:`hot2cold.io.atomic.write_atomically`: a
    failed write raises OutputError and leaves nothing)."""
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise FieldError(f"output folder does not exist: {folder}")

    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:             # a file object: savez given a name would add ".npz" to it
            extra = {} if field.triangles is None else {"triangles": field.triangles}
            np.savez_compressed(fh, points=field.points, displacements=field.displacements,
                                node_ids=field.node_ids, **extra)

    write_atomically([(path, write)])


@dataclass(frozen=True)
class MeshOptions:
    """How :func:`hot_to_cold_field` meshes the hot part (see :func:`hot2cold.fe.mesh.mesh_step`).

    Attributes
    ----------
    size : float or None, target element size, mm; default 1/40 of the part's bounding-box diagonal.
    min_size : float or None, smallest element size, mm; default ``size / 10``.
    curvature : float, elements per 2 pi of surface curvature.
    degree : int, element degree: 2, second-order tetrahedra (CalculiX C3D10), or 1 (gmsh's ``order``).
    """

    size: float | None = None
    min_size: float | None = None
    curvature: float = 20
    degree: int = 2


@dataclass(frozen=True, eq=False)
class LoadCase:
    """The hot-to-cold load case of :func:`hot_to_cold_field` (cool down, stop rotating, root fixed).

    Attributes
    ----------
    material : Material, default Ti-6Al-4V.
    hot_temperature : float, (N,) array, callable or None
        Running temperature, K: one value, per node, or a function of the node positions (N, 3) mm
        returning (N,) K.  Default: :func:`blade_temperature`, 420 K at the hub to 480 K at the tip.
    room_temperature : float, K, default 293.
    omega : float, running speed, rad/s, default 1800 (Rotor 37); 0 for a part that does not rotate.
    axis_point, axis_direction : the rotation axis (default the z axis), also the axis of the default
        temperature and hub face.
    fixed_faces : list of int or None
        hot2cold faces (numbered from 0) whose nodes are fixed in x, y, z; default :func:`hub_faces` (the face
        nearest the axis, a blade's root).  Ignored when ``fixed_nodes`` is given.
    fixed_nodes : array-like or mapping or None
        Node indices of the mesh to fix, as in :func:`write_deck` (needs the mesh in advance: rarely
        useful here).
    """

    material: Material = TI6AL4V
    hot_temperature: float | np.ndarray | Callable | None = None
    room_temperature: float = ROOM_TEMPERATURE
    omega: float = ROTOR37_OMEGA
    axis_point: tuple = (0.0, 0.0, 0.0)
    axis_direction: tuple = (0.0, 0.0, 1.0)
    fixed_faces: list | None = None
    fixed_nodes: object = None


@dataclass(frozen=True)
class SolverOptions:
    """How :func:`hot_to_cold_field` runs CalculiX.

    Attributes
    ----------
    work_dir : str or os.PathLike or None
        Folder for the deck and ccx's files, kept; default a temporary folder removed afterwards.
    timeout, threads, ccx : see :func:`run_ccx`.
    """

    work_dir: str | os.PathLike | None = None
    timeout: float = 3600.0
    threads: int = 2
    ccx: str = "ccx"


def hot_to_cold_field(step_path, out_path=None, *, mesh: MeshOptions = MeshOptions(),
                      load: LoadCase = LoadCase(), solver: SolverOptions = SolverOptions(),
                      nodes: str = "surface") -> DisplacementField:
    """The whole FE pipeline: mesh the hot STEP, solve the hot-to-cold load case, return the field.

    For example ``hot_to_cold_field("blade.step", "blade_field.npz", mesh=MeshOptions(size=1.5),
    load=LoadCase(omega=1800.0))``.

    Parameters
    ----------
    step_path : str or os.PathLike
        The hot part.
    out_path : str or os.PathLike or None
        Where to write the field as a compressed ``.npz`` (``points`` (N, 3) mm, ``displacements``
        (N, 3) mm, ``node_ids`` (N,) the CalculiX node numbers, ``triangles`` (T, 6) the mesh's boundary
        triangles as rows of them); ``None`` writes nothing.
    mesh : MeshOptions
        Element size, smallest size, curvature and degree of the mesh.
    load : LoadCase
        Material, temperatures, speed and axis, fixed faces or nodes.
    solver : SolverOptions
        Work folder, timeout, threads and executable of CalculiX.
    nodes : str
        ``"surface"`` (default): the field holds the nodes on the part's faces, which are all the morph
        uses; ``"all"``: every node.

    Returns
    -------
    DisplacementField
        Hot node positions from the mesh (full precision, not the ``.frd``'s 6 digits), displacements
        hot -> cold from CalculiX, mm; ``node_ids`` the CalculiX node numbers; ``triangles`` the mesh's
        boundary triangles (the morph takes the field inside them too).
    """
    if nodes not in ("surface", "all"):
        raise ValueError(f"nodes must be 'surface' or 'all', got {nodes!r}")
    step_path = Path(os.fspath(step_path)).expanduser()
    size = _default_size(step_path) if mesh.size is None else mesh.size
    min_size = size / 10.0 if mesh.min_size is None else mesh.min_size
    t0 = time.perf_counter()
    tets = mesh_step(step_path, size, min_size, mesh.curvature, mesh.degree)
    t_mesh = time.perf_counter() - t0
    point, direction = _axis(load.axis_point, load.axis_direction)
    fixed_nodes = load.fixed_nodes
    if fixed_nodes is None:
        faces = (hub_faces(tets, point, direction) if load.fixed_faces is None
                 else [int(f) for f in load.fixed_faces])
        try:
            fixed_nodes = distinct(np.concatenate([tets.face_nodes(f) for f in faces]))
        except IndexError as exc:
            raise ValueError(f"fixed_faces: {exc}") from None
        log.info("fixing face(s) %s: %d nodes", faces, len(fixed_nodes))
    if load.hot_temperature is None:
        temps = blade_temperature(tets.nodes, axis_point=point, axis_direction=direction)
    elif callable(load.hot_temperature):
        temps = np.asarray(load.hot_temperature(tets.nodes), dtype=np.float64)
    else:
        temps = load.hot_temperature

    tmp = None
    if solver.work_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="hot2cold-ccx-")
        folder = Path(tmp.name)
    else:
        folder = Path(os.fspath(solver.work_dir)).expanduser()
        folder.mkdir(parents=True, exist_ok=True)
    try:
        deck = write_deck(tets, folder / "hot2cold.inp", material=load.material, fixed_nodes=fixed_nodes,
                          hot_temperature=temps, room_temperature=load.room_temperature, omega=load.omega,
                          axis_point=point, axis_direction=direction)
        t1 = time.perf_counter()
        frd = run_ccx(deck, solver.timeout, threads=solver.threads, ccx=solver.ccx)
        t_ccx = time.perf_counter() - t1
        full = read_hot_to_cold(frd, points_from=tets)
    finally:
        if tmp is not None:
            tmp.cleanup()
    keep = tets.boundary_nodes() if nodes == "surface" else np.arange(len(tets.nodes))
    order = np.argsort(full.node_ids)
    index = order[np.searchsorted(full.node_ids, tets.node_tags[keep], sorter=order)]
    kept = full.take(index)                       # the boundary triangles come along, renumbered
    field = DisplacementField(kept.points, kept.displacements, kept.node_ids,
                              source=str(out_path) if out_path is not None else f"FE run on {step_path}",
                              triangles=kept.triangles)
    log.info("hot-to-cold field of %s: %d of %d nodes (%s), max |d| %.4g mm; mesh %.1f s, ccx %.1f s",
             step_path, len(field), len(tets.nodes), nodes,
             float(np.linalg.norm(field.displacements, axis=1).max()), t_mesh, t_ccx)
    if out_path is not None:
        _write_npz(field, Path(os.fspath(out_path)).expanduser())
    return field


def _default_size(step_path: Path) -> float:
    """1/40 of the bounding-box diagonal of the part, mm."""
    box = step_bounding_box(step_path)
    return float(np.linalg.norm(box[1] - box[0])) / 40.0
