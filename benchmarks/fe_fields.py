"""Real FE fields: the default morph scored against the geometry of the CalculiX solution itself, on dense
samples over every face.

Run from the repository::

    python benchmarks/fe_fields.py --timeout 900 --json /tmp/febench/baseline.json      # everything
    python benchmarks/fe_fields.py --cases rotor37 --variants surface,noisy
    python benchmarks/fe_fields.py --morph-args='--tolerance 1e-3' --json out/fe_tol.json
    python benchmarks/fe_fields.py --show /tmp/febench/baseline.json                      # print a saved run

Cases: the hot part is meshed with gmsh (second-degree 10-node tetrahedra, :func:`hot2cold.fe.mesh_step`)
and the hot-to-cold load case solved by CalculiX, with the pieces :func:`hot2cold.fe.hot_to_cold_field` is
made of (:func:`~hot2cold.fe.write_deck`, :func:`~hot2cold.fe.run_ccx`, :func:`~hot2cold.fe.read_hot_to_cold`),
keeping the mesh:

* ``rotor37``: ``sample_parts/rotor37_blade.step``, the options of ``sample_parts/make_fe_fields.py``:
  size 1.5 mm, min 0.15 mm; Ti-6Al-4V at 1800 rad/s about z and 420 K (hub) to 480 K (tip), back to rest at
  293 K; the hub face fixed;
* ``mixer``: ``sample_parts/mixer_segment.step``, as in ``make_fe_fields.py``: size 4 mm, min 0.6 mm; static,
  700 K at the inlet to 850 K at the exit (``mixer_temperature``), the inlet face fixed;
* ``twisted_blade``: ``sample_parts/twisted_blade.step`` with the defaults of :mod:`hot2cold.fe`
  (``MeshOptions()``: size 1/40 of the diagonal; ``LoadCase()``: as Rotor 37, the face nearest the z axis
  fixed).

The solution (mesh nodes, tetrahedra, boundary triangles, displacements of every node, solve times) is cached
in ``benchmarks/.cache/`` under the case and a hash of its STEP file and options, so a second run skips gmsh
and ccx.  ccx runs with one thread.

Variants (``--variants``, default all), the field given to the morph as an ``.npz`` (``points``,
``displacements`` and the mesh's boundary ``triangles``, as a solver's ``.frd`` brings its elements; the morph
then also takes the field inside them, :func:`hot2cold.pipeline.load.element_points`, unless
``--morph-args=--nodes-only``):

* ``surface``: the nodes on the part's faces, as ``hot_to_cold_field(nodes="surface")`` writes them;
* ``volume``: every node of the mesh, the volume nodes mixed in;
* ``noisy``: every node, each displacement component plus Gaussian noise of 0.003 mm (3 µm) standard
  deviation, seed :data:`SEED` (``numpy.random.default_rng(0)``); the reference stays the noise-free field.

For each (case, variant), in a fresh process (``real_parts.spawn``: a timeout, a crash or a memory limit is
recorded, not raised):

* the morph as a user runs it: ``hot2cold.cli.main(["morph", hot, field.npz, "-o", cold, "--report", json,
  "-q", *morph_args])``, its exit code and last ``hot2cold:`` line, time, the process's peak resident memory
  (``ru_maxrss``) after it, and the report's Δmax / Δmean at the nodes (overall and per face);
* on exit 0: the cold STEP read back, BRepCheck and free edges (:func:`hot2cold.kernel.validity.check_solids`),
  and the error against the FE geometry: dense samples inside every hot face
  (:func:`hot2cold.kernel.sampling.face_samples`, 1/:data:`SAMPLES_PER_ELEMENT` of the element size apart),
  each moved by the FE solution's own interpolation, and the distance of (sample + displacement) to the cold
  face with the same index (``real_parts.face_errors``): max and mean per face and overall, and the worst face.

The FE interpolation (:class:`hot2cold.core.elements.SurfaceInterpolator`): the boundary of the mesh is the
6-node triangles of the tetrahedra's faces that no other tetrahedron shares (:func:`boundary_triangles`).  A
sample is located on the nearest of them (candidates by a KD-tree of triangle centres, each projected by
Gauss-Newton on the curved quadratic triangle), and its displacement is the quadratic shape functions' blend
of the 6 nodal ones.  The samples lie on the CAD face, within the mesh's chord error of the FE surface; that
distance is reported too (``fe_gap``).  Samples farther from the FE surface than the morph's ``node_distance``
lie where the FE model is not the CAD part (the twisted blade's leading edge, where gmsh's straightened
elements leave its surface 0.2 to 0.6 mm off): the FE value there is the field that far away, no reference;
they are counted (``fe_off``, with their largest error) and not scored.  Once per case a self-check prints
the interpolation's error at the surface nodes (~0), and at points halfway between neighbouring nodes of the
boundary triangles, both how far a search from the point's position lands from the element's own value (~0)
and how far the quadratic field bends away from the mean of the two nodes (a figure of its smoothness between
the nodes).

Measured (2 cores, another benchmark beside it; ``/tmp/febench/baseline.json`` of the commit that added this
file): every morph exit 0, valid, closed.  Against the FE geometry (max / mean mm): Rotor 37 1.0e-3 / 1.4e-4
(surface and volume), 4.9e-3 / 4.9e-4 noisy; mixer 0.17 / 4e-4, all of it on the planar exit face 5
(``benchmarks/refine_mixer.py``: the plain fit cannot bend it; the other faces within 4.9e-3); twisted blade
7.7e-3 / 3.7e-4 on the leading-edge face 0, 2.6e-2 noisy (larger than the noise's largest component).
Volume nodes within the morph's ``node_distance`` (1e-3 x diagonal, 0.1 mm on the blades) of a face are
taken as its nodes: on Rotor 37 about 5 900 of the 27 000.  FE solves (one ccx thread): Rotor 37 gmsh 33 s +
ccx 45 s, mixer 24 + 22 s, twisted blade 10 + 7 s; morphs 3 to 44 s.

The twisted blade's case is the defaults as they are, not a realistic load: the blade is stacked along z, the
default rotation axis, so the "hub" face nearest the axis is a flank (face 1) and the whole flank is fixed;
the default size (2.7 mm) leaves 492 inverted curved tetrahedra that gmsh straightens, and the samples lie up
to 0.59 mm from that FE surface (``fe_gap``).  ``tests/test_real_fields.py`` loads the same blade about an x
axis 150 mm below it instead.
"""
from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import resource
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import real_parts  # noqa: E402  (the folder above is on sys.path now)

from hot2cold.core.elements import GMSH_TO_TET10, SurfaceInterpolator, boundary_triangles  # noqa: E402

ROOT = HERE.parent
SAMPLES = ROOT / "sample_parts"
CACHE = HERE / ".cache"
#: Bump when the cached solution's content or the solve changes.
CACHE_VERSION = 1
CASES = ("rotor37", "mixer", "twisted_blade")
VARIANTS = ("surface", "volume", "noisy")
#: Standard deviation of the ``noisy`` variant's noise, mm per component.
NOISE = 0.003
SEED = 0
#: Samples per element length on every face: their spacing is the element size over this.
SAMPLES_PER_ELEMENT = 3
# ------------------------------------------------------------------------------------------- the FE solutions

@dataclass(frozen=True)
class Case:
    """One FE case: the hot part and how it is meshed and loaded (``load`` builds the :class:`LoadCase`)."""

    name: str
    step: Path
    mesh: object          # hot2cold.fe.MeshOptions
    load: object          # () -> hot2cold.fe.LoadCase
    about: str


def _make_fe_fields():
    """``sample_parts/make_fe_fields.py`` as a module (its mixer temperature and inlet face)."""
    if str(SAMPLES) not in sys.path:
        sys.path.insert(0, str(SAMPLES))
    import make_fe_fields

    return make_fe_fields


def case(name: str) -> Case:
    """The case ``name`` (one of :data:`CASES`)."""
    from hot2cold.fe import LoadCase, MeshOptions

    if name == "rotor37":
        return Case(name, SAMPLES / "rotor37_blade.step", MeshOptions(size=1.5, min_size=0.15),
                    lambda: LoadCase(omega=1800.0, axis_point=(0, 0, 0), axis_direction=(0, 0, 1)),
                    "make_fe_fields.py: size 1.5, min 0.15, 1800 rad/s about z, 420-480 K, hub fixed")
    if name == "mixer":
        step = SAMPLES / "mixer_segment.step"

        def load():
            mf = _make_fe_fields()
            return LoadCase(omega=0.0, axis_point=(0, 0, 0), axis_direction=(1, 0, 0),
                            hot_temperature=mf.mixer_temperature, fixed_faces=[mf._face_nearest(step, 0)])
        return Case(name, step, MeshOptions(size=4.0, min_size=0.6), load,
                    "make_fe_fields.py: size 4, min 0.6, static, 700-850 K along x, inlet fixed")
    if name == "twisted_blade":
        return Case(name, SAMPLES / "twisted_blade.step", MeshOptions(), LoadCase,
                    "hot2cold.fe defaults: MeshOptions(), LoadCase()")
    raise ValueError(f"unknown case {name!r}: one of {CASES}")


@dataclass(frozen=True)
class Solution:
    """A solved case, mm: ``nodes`` (N, 3), ``tets`` (M, 10) gmsh order, ``triangles`` (T, 6) boundary,
    ``surface`` (S,) indices of the nodes on the part's faces, ``displacements`` (N, 3) hot -> cold of every
    node; the element size used, the fixed faces, and the mesh and solve times (s) when it was made."""

    nodes: np.ndarray
    tets: np.ndarray
    triangles: np.ndarray
    surface: np.ndarray
    displacements: np.ndarray
    size: float
    fixed_faces: tuple
    mesh_seconds: float
    ccx_seconds: float
    cached: bool = False


def _options(c: Case, load) -> dict:
    """What the solution depends on, as JSON-ready values (the cache key)."""
    temp = load.hot_temperature
    return {
        "case": c.name, "version": CACHE_VERSION,
        "step": hashlib.sha1(c.step.read_bytes()).hexdigest(),
        "mesh": asdict(c.mesh),
        "material": asdict(load.material),
        "hot_temperature": (None if temp is None else getattr(temp, "__qualname__", None) if callable(temp)
                            else np.asarray(temp).tolist()),
        "room_temperature": load.room_temperature, "omega": load.omega,
        "axis": [list(load.axis_point), list(load.axis_direction)],
        "fixed_faces": load.fixed_faces,
    }


def cache_path(c: Case, load) -> Path:
    """``benchmarks/.cache/fe_fields_<case>_<hash>.npz`` for case ``c`` under ``load``."""
    key = hashlib.sha1(json.dumps(_options(c, load), sort_keys=True).encode()).hexdigest()[:16]
    return CACHE / f"fe_fields_{c.name}_{key}.npz"


def solve(c: Case, load, threads: int = 1) -> Solution:
    """Mesh and solve case ``c`` under ``load`` as :func:`hot2cold.fe.hot_to_cold_field` does, keeping the
    mesh and every node's displacement."""
    from hot2cold.fe import blade_temperature, hub_faces, mesh_step, read_hot_to_cold, run_ccx, write_deck
    from hot2cold.fe.calculix import _default_size

    size = _default_size(c.step) if c.mesh.size is None else c.mesh.size
    min_size = size / 10.0 if c.mesh.min_size is None else c.mesh.min_size
    t0 = time.perf_counter()
    mesh = mesh_step(c.step, size, min_size, c.mesh.curvature, c.mesh.degree)
    t_mesh = time.perf_counter() - t0
    faces = (hub_faces(mesh, load.axis_point, load.axis_direction) if load.fixed_faces is None
             else [int(f) for f in load.fixed_faces])
    fixed = np.unique(np.concatenate([mesh.face_nodes(f) for f in faces]))
    if load.hot_temperature is None:
        temps = blade_temperature(mesh.nodes, axis_point=load.axis_point, axis_direction=load.axis_direction)
    elif callable(load.hot_temperature):
        temps = load.hot_temperature(mesh.nodes)
    else:
        temps = load.hot_temperature
    with tempfile.TemporaryDirectory(prefix="fe_fields_") as tmp:
        deck = write_deck(mesh, Path(tmp) / "hot2cold.inp", material=load.material, fixed_nodes=fixed,
                          hot_temperature=temps, room_temperature=load.room_temperature, omega=load.omega,
                          axis_point=load.axis_point, axis_direction=load.axis_direction)
        t1 = time.perf_counter()
        full = read_hot_to_cold(run_ccx(deck, threads=threads), points_from=mesh)
        t_ccx = time.perf_counter() - t1
    order = np.argsort(full.node_ids)
    rows = order[np.searchsorted(full.node_ids, mesh.node_tags, sorter=order)]
    if not np.array_equal(full.node_ids[rows], mesh.node_tags):
        raise RuntimeError(f"{c.name}: the .frd misses nodes of the mesh")
    return Solution(mesh.nodes, mesh.tets, boundary_triangles(mesh.tets[:, GMSH_TO_TET10]), mesh.boundary_nodes(),
                    np.asarray(full.displacements)[rows], float(size), tuple(faces), t_mesh, t_ccx)


def solution(c: Case) -> Solution:
    """Case ``c`` solved, from the cache when it holds it (else solved and cached)."""
    load = c.load()
    path = cache_path(c, load)
    if path.exists():
        with np.load(path) as d:
            return Solution(d["nodes"], d["tets"], d["triangles"], d["surface"], d["displacements"],
                            float(d["size"]), tuple(int(f) for f in d["fixed_faces"]), float(d["mesh_seconds"]),
                            float(d["ccx_seconds"]), cached=True)
    sol = solve(c, load)
    CACHE.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".part.npz")
    np.savez_compressed(tmp, nodes=sol.nodes, tets=sol.tets, triangles=sol.triangles, surface=sol.surface,
                        displacements=sol.displacements, size=sol.size, fixed_faces=np.array(sol.fixed_faces),
                        mesh_seconds=sol.mesh_seconds, ccx_seconds=sol.ccx_seconds)
    os.replace(tmp, path)
    return sol


def variant_field(sol: Solution, variant: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The morph's input for ``variant``: node positions ``(n, 3)`` and displacements ``(n, 3)``, mm, and the
    mesh's boundary triangles ``(T, 6)`` as rows of them (the field's elements, as a solver's file brings them)."""
    from hot2cold.io.field import DisplacementField

    if variant == "surface":
        rows = sol.surface
    elif variant in ("volume", "noisy"):
        rows = np.arange(len(sol.nodes))
    else:
        raise ValueError(f"unknown variant {variant!r}: one of {VARIANTS}")
    displacements = sol.displacements
    if variant == "noisy":
        displacements = displacements + np.random.default_rng(SEED).normal(0.0, NOISE, displacements.shape)
    field = DisplacementField(sol.nodes, displacements, triangles=sol.triangles).take(rows)
    return field.points, field.displacements, field.triangles


# --------------------------------------------------------------------------------------------- the self-check

def self_check(sol: Solution, limit: int = 20_000) -> dict:
    """The interpolation's own figures, mm, on at most ``limit`` boundary triangles.

    ``nodes``: largest error at the surface nodes, located from their positions (should be ~0);
    ``search``: at points halfway between neighbouring nodes of the triangles, located from their positions,
    the largest difference from the element's own value there (~0 up to the choice between triangles that
    share an edge); ``bend_max``, ``bend_mean``: there, the quadratic field's departure from the mean of the
    two nodes (how far it curves between the nodes); ``largest``: the largest displacement.
    """
    interp = SurfaceInterpolator(sol.nodes, sol.triangles, sol.displacements)
    at_nodes = interp(sol.nodes[sol.surface])
    rng = np.random.default_rng(SEED)
    tri = np.sort(rng.choice(len(sol.triangles), min(limit, len(sol.triangles)), replace=False))
    # halfway between corner 0, mid 01, corner 1, mid 12, corner 2, mid 20 (round the triangle)
    ring = np.array([[0, 0], [0.5, 0], [1, 0], [0.5, 0.5], [0, 1], [0, 0.5]])
    local = np.array([0, 3, 1, 4, 2, 5])                   # node of each ring point
    half = 0.5 * (ring + np.roll(ring, -1, axis=0))
    tri_h, st_h = np.repeat(tri, 6), np.tile(half, (len(tri), 1))
    own = interp.at(tri_h, st_h)
    found = interp(interp.position(tri_h, st_h))
    ends = sol.triangles[tri][:, local]
    linear = 0.5 * (sol.displacements[ends] + sol.displacements[np.roll(ends, -1, axis=1)]).reshape(-1, 3)
    bend = np.linalg.norm(own - linear, axis=1)
    return {"nodes": float(np.linalg.norm(at_nodes - sol.displacements[sol.surface], axis=1).max()),
            "search": float(np.linalg.norm(found - own, axis=1).max()),
            "bend_max": float(bend.max()), "bend_mean": float(bend.mean()),
            "largest": float(np.linalg.norm(sol.displacements, axis=1).max()), "points": int(len(bend))}


# ------------------------------------------------------------------------------------------------- the runs

@dataclass
class FERun:
    """One (case, variant) run: what the morph said and how far the cold part is from the FE geometry."""

    case: str
    variant: str
    morph_args: str = ""
    nodes: int | None = None
    elements: int | None = None
    size: float | None = None           # the mesh's element size, mm
    mesh_seconds: float | None = None   # gmsh, when the solution was made (cached or not)
    ccx_seconds: float | None = None
    fe_cached: bool | None = None
    largest: float | None = None        # largest FE displacement, mm
    noise_std: float | None = None      # noisy: the noise added, standard deviation and largest |component|
    noise_max: float | None = None
    faces: int | None = None
    exit_code: int | None = None        # None: the child died before the morph returned
    message: str = ""
    seconds: float | None = None        # the morph (cli.main) alone
    peak_mb: float | None = None
    delta_max: float | None = None      # mm, the report's, at the nodes
    delta_mean: float | None = None
    ignored: int | None = None          # the report's nodes_ignored (off the part, e.g. straightened elements)
    node_distance: float | None = None  # the report's: nodes up to this far (mm) from a face are its nodes
    valid: bool | None = None
    free_edges: int | None = None
    faces_cold: int | None = None
    fe_max: float | None = None         # mm, against the FE geometry on dense samples
    fe_mean: float | None = None
    fe_face: int | None = None
    samples: int | None = None
    spacing: float | None = None
    fe_gap: float | None = None         # largest distance of a sample from the FE surface (chord error)
    fe_off: int | None = None           # samples farther than node_distance from the FE surface: not scored
    fe_off_max: float | None = None     # their largest error (mm), the FE field taken that far off its surface
    per_face: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def load_run(data: dict) -> FERun:
    """An :class:`FERun` from its saved dict."""
    return FERun(**{k: v for k, v in data.items() if k in FERun.__dataclass_fields__})


def morph(hot: Path, points: np.ndarray, displacements: np.ndarray, stem: str, workdir: Path, run: FERun,
          morph_args: tuple, triangles: np.ndarray | None = None) -> tuple[Path, dict | None]:
    """Write the field (with its boundary ``triangles`` when given), morph it by the command line into ``run``
    (exit, message, time, memory, Δ); the cold STEP's path and the report (None when none was written)."""
    from hot2cold.cli import main as cli_main

    field_path, cold, report_path = (workdir / f"{stem}.npz", workdir / f"{stem}_cold.step",
                                     workdir / f"{stem}_report.json")
    extra = {} if triangles is None else {"triangles": triangles}
    np.savez(field_path, points=points, displacements=displacements, **extra)
    stderr = io.StringIO()
    start = time.perf_counter()
    with contextlib.redirect_stderr(stderr):
        run.exit_code = cli_main(["morph", str(hot), str(field_path), "-o", str(cold), "--report",
                                  str(report_path), "-q", *morph_args])
    run.seconds = time.perf_counter() - start
    run.peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    run.message = real_parts.one_line(stderr.getvalue()).replace(f"{workdir}{os.sep}", "")
    report = json.loads(report_path.read_text()) if report_path.exists() else None
    if report is not None:
        run.delta_max, run.delta_mean = report.get("delta_max"), report.get("delta_mean")
        run.ignored, run.node_distance = report.get("nodes_ignored"), report.get("node_distance")
    return cold, report


def score(hot, cold_path: Path, sol: Solution, run: FERun, report: dict | None) -> None:
    """Read the cold STEP back into ``run``: validity, free edges, and the error against the FE geometry,
    overall and per face (with the report's per-face Δ at the nodes beside it)."""
    from hot2cold.kernel.step import read_step
    from hot2cold.kernel.validity import check_solids

    cold = read_step(cold_path)
    checks = check_solids(cold)
    run.valid = bool(checks) and all(c.valid for c in checks)
    run.free_edges = sum(c.free_edges for c in checks)
    run.faces_cold = sum(c.faces for c in checks)
    if run.faces_cold != run.faces:
        run.notes.append("faces not kept: no error against the FE geometry")
        return
    interp = SurfaceInterpolator(sol.nodes, sol.triangles, sol.displacements)
    gaps = []

    def exact_map(points):
        tri, st, gap = interp.locate(points)
        gaps.append(gap)
        return points + interp.at(tri, st)

    run.spacing = sol.size / SAMPLES_PER_ELEMENT
    every = real_parts.face_errors(hot, cold, exact_map, run.spacing)
    # a sample farther from the FE surface than a node may be from its face is where the FE model is not the
    # CAD part (the twisted blade's straightened elements, 0.2 to 0.6 mm off its leading edge): its FE value
    # is the field that far away, no reference for the face; it is counted, not scored
    bound = run.node_distance if run.node_distance is not None else np.inf
    dists = [d[g <= bound] for d, g in zip(every, gaps)]
    off = np.concatenate([d[g > bound] for d, g in zip(every, gaps)])
    faces_report = {f["index"]: f for f in (report or {}).get("faces", [])}
    for k, d in enumerate(dists):
        rep = faces_report.get(k, {})
        run.per_face.append({"face": k, "samples": len(d), "fe_max": float(d.max()) if len(d) else None,
                             "fe_mean": float(d.mean()) if len(d) else None, "nodes": rep.get("nodes"),
                             "delta_max": rep.get("delta_max"), "delta_mean": rep.get("delta_mean"),
                             "off": int(len(every[k]) - len(d))})
    scored = np.concatenate(dists)
    run.samples = len(scored)
    run.fe_max, run.fe_mean = float(scored.max()), float(scored.mean())
    run.fe_face = int(np.argmax([d.max() if len(d) else -1.0 for d in dists]))
    run.fe_gap = float(np.concatenate(gaps).max()) if gaps else None
    run.fe_off, run.fe_off_max = len(off), (float(off.max()) if len(off) else None)


def run_here(name: str, variant: str, workdir: Path, morph_args: tuple = ()) -> FERun:
    """One run in this process (the child's work): the case's solution (cached), the variant's field, the
    morph by the command line (with the extra options ``morph_args``), the scores."""
    from hot2cold.kernel.step import read_step

    c = case(name)
    sol = solution(c)
    run = FERun(case=name, variant=variant, morph_args=" ".join(morph_args), elements=len(sol.tets),
                size=sol.size, mesh_seconds=sol.mesh_seconds, ccx_seconds=sol.ccx_seconds, fe_cached=sol.cached,
                largest=float(np.linalg.norm(sol.displacements, axis=1).max()))
    hot = read_step(c.step)
    run.faces = len(real_parts.solid_faces(hot))
    points, displacements, triangles = variant_field(sol, variant)
    run.nodes = len(points)
    if variant == "noisy":
        noise = displacements - sol.displacements
        run.noise_std, run.noise_max = float(noise.std()), float(np.abs(noise).max())
    cold, report = morph(c.step, points, displacements, f"{name}_{variant}", workdir, run, morph_args, triangles)
    if run.exit_code in real_parts.WRITTEN and cold.exists():       # 5: written, the tolerance missed
        score(hot, cold, sol, run, report)
    return run


def run_child(name: str, variant: str, timeout: float, max_memory_gb: float | None,
              morph_args: tuple = ()) -> FERun:
    """:func:`run_here` in a fresh process; a timeout, a crash or a memory limit is recorded, not raised."""
    with tempfile.TemporaryDirectory(prefix="fe_fields_") as tmp:
        tmp = Path(tmp)
        out = tmp / "run.json"
        cmd = [sys.executable, __file__, "--one", name, "--variants", variant, "--workdir", str(tmp),
               "--json", str(out), f"--morph-args={' '.join(morph_args)}"]
        status, usage, seconds = real_parts.spawn(cmd, timeout, max_memory_gb, tmp / "stderr.txt")
        if out.exists():
            return load_run(json.loads(out.read_text()))
        run = FERun(case=name, variant=variant, morph_args=" ".join(morph_args))
        run.message = real_parts.died(status, timeout, tmp / "stderr.txt")
        run.peak_mb = usage.ru_maxrss / 1024.0
        run.seconds = seconds
        return run


# ------------------------------------------------------------------------------------------------ the tables

_num = real_parts._num


def table(runs: list[FERun], width: int = 70) -> str:
    """The markdown table of ``runs``, one row each."""
    head = ("case", "variant", "nodes", "ignored", "exit", "message", "time s", "peak MB", "valid", "free edges",
            "Δmax nodes mm", "Δmean nodes mm", "FE max mm", "FE mean mm", "worst face")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in runs:
        message = r.message.removeprefix("hot2cold: ").removeprefix("error: ")
        if len(message) > width:
            message = message[:width - 1] + "…"
        row = (r.case, r.variant + (f" `{r.morph_args}`" if r.morph_args else ""), _num(r.nodes, "d"),
               _num(r.ignored, "d"), _num(r.exit_code, "d"), message, _num(r.seconds, ".1f"),
               _num(r.peak_mb, ".0f"), _num(r.valid, ""), _num(r.free_edges, "d"), _num(r.delta_max, ".2e"),
               _num(r.delta_mean, ".2e"), _num(r.fe_max, ".2e"), _num(r.fe_mean, ".2e"), _num(r.fe_face, "d"))
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def face_table(run: FERun) -> str:
    """Per face of ``run``: nodes and Δmax / Δmean at them (the report), samples and the error against the FE
    geometry (max / mean), mm."""
    head = ("face", "nodes", "Δmax mm", "Δmean mm", "samples", "FE max mm", "FE mean mm", "off FE surface")
    lines = [f"{run.case} {run.variant}{' ' + run.morph_args if run.morph_args else ''}: "
             f"{run.samples} samples {_num(run.spacing, '.3g')} mm apart, up to {_num(run.fe_gap, '.1e')} mm "
             f"from the FE surface" + (f"; {run.fe_off} more farther than {run.node_distance:.3g} mm from it, "
                                       f"not scored (their error up to {_num(run.fe_off_max, '.2e')} mm)"
                                       if run.fe_off else "")
             + (f"; noise std {run.noise_std:.2e}, max {run.noise_max:.2e} mm" if run.noise_std is not None
                else ""),
             "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for f in run.per_face:
        lines.append("| " + " | ".join((str(f["face"]), _num(f["nodes"], "d"), _num(f["delta_max"], ".2e"),
                                        _num(f["delta_mean"], ".2e"), _num(f["samples"], "d"),
                                        _num(f["fe_max"], ".2e"), _num(f["fe_mean"], ".2e"),
                                        _num(f.get("off"), "d"))) + " |")
    return "\n".join(lines)


def fe_table(runs: list[FERun]) -> str:
    """One line per case: elements, element size, largest displacement and the gmsh and ccx times."""
    seen, lines = set(), []
    for r in runs:
        if r.case in seen or r.elements is None:
            continue
        seen.add(r.case)
        lines.append(f"{r.case}: {r.elements} tetrahedra, size {r.size:.3g} mm, max |d| {r.largest:.4f} mm; "
                     f"solved in gmsh {r.mesh_seconds:.1f} s + ccx {r.ccx_seconds:.1f} s (one thread)")
    return "\n".join(lines)


def report(runs: list[FERun]) -> str:
    """Everything printed at the end: the FE solutions, the table, the per-face tables."""
    parts = [fe_table(runs), "", table(runs)]
    parts += ["\n" + face_table(r) for r in runs if r.per_face]
    return "\n".join(parts)


# ------------------------------------------------------------------------------------------------------ main

def _names(text: str, allowed: tuple, what: str, parser) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    for n in names:
        if n not in allowed:
            parser.error(f"unknown {what} {n!r}: one of {allowed}")
    return names


def prepare(name: str) -> None:
    """Solve (or load) case ``name`` and print its solve times and self-check."""
    start = time.perf_counter()
    sol = solution(case(name))
    how = "cached" if sol.cached else f"solved in {time.perf_counter() - start:.1f} s"
    print(f"{name}: {len(sol.nodes)} nodes, {len(sol.tets)} tetrahedra, {len(sol.triangles)} boundary "
          f"triangles, size {sol.size:.3g} mm, fixed face(s) {list(sol.fixed_faces)}; {how} "
          f"(gmsh {sol.mesh_seconds:.1f} s, ccx {sol.ccx_seconds:.1f} s)", flush=True)
    t0 = time.perf_counter()
    check = self_check(sol)
    print(f"  self-check ({time.perf_counter() - t0:.1f} s): at the {len(sol.surface)} surface nodes "
          f"{check['nodes']:.1e} mm; at {check['points']} points halfway between nodes: search "
          f"{check['search']:.1e} mm, quadratic vs nodes' mean max {check['bend_max']:.2e} mean "
          f"{check['bend_mean']:.2e} mm (max |d| {check['largest']:.4f} mm)", flush=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, of {CASES}")
    parser.add_argument("--variants", default=",".join(VARIANTS), help=f"comma-separated, of {VARIANTS}")
    real_parts.run_arguments(parser, 900.0)
    args = parser.parse_args(argv)
    morph_args = tuple(args.morph_args.split())
    variants = _names(args.variants, VARIANTS, "variant", parser)

    if args.show:
        print(report([load_run(r) for path in args.show for r in json.loads(path.read_text())]))
        return 0
    if args.one is not None:
        run = run_here(args.one, variants[0], args.workdir, morph_args)
        args.json.write_text(json.dumps(asdict(run)))
        return 0

    cases = _names(args.cases, CASES, "case", parser)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
    runs = []
    for name in cases:
        prepare(name)
        for variant in variants:
            run = run_child(name, variant, args.timeout, args.max_memory or None, morph_args)
            runs.append(run)
            print(f"  {name} {variant}: exit {run.exit_code} {_num(run.seconds, '.1f')} s "
                  f"{_num(run.peak_mb, '.0f')} MB, Δmax nodes {_num(run.delta_max, '.2e')}, FE max "
                  f"{_num(run.fe_max, '.2e')} mean {_num(run.fe_mean, '.2e')} (face {_num(run.fe_face, 'd')}) "
                  f"{run.message}", flush=True)
            if args.json:
                args.json.write_text(json.dumps([asdict(r) for r in runs], indent=1))
    print()
    print(report(runs))
    return 0


if __name__ == "__main__":
    sys.exit(main())
