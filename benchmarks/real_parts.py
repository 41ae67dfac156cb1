"""Real parts from other CAD systems: every corpus part morphed as a user would, scored against the exact
cold geometry.

Run from the repository::

    python benchmarks/real_parts.py                              # everything (corpus + sample_parts)
    python benchmarks/real_parts.py --quick --nodes fe           # the quick subset, for every change
    python benchmarks/real_parts.py --parts boat,handle --fields affine --nodes fe --timeout 120
    python benchmarks/real_parts.py --json out/real_parts.json

Parts: the corpus of ``corpus/manifest.json`` that is present here (``python benchmarks/corpus.py fetch`` brings
the files that are not committed; see ``corpus/README.md``) and the bundled ``sample_parts/*.step``.  For each
(part, node set, field), in a fresh process (so a crash, a hang or a memory blow-up of one run stops none of
the others, and its peak memory is its own):

* node set ``fe``: :func:`hot2cold.kernel.sampling.fe_surface_nodes` at a spacing of diagonal / 80, bounded
  so the part gets roughly 5 000 to 40 000 nodes; ``tess``: the vertices of the kernel's triangulation
  (:func:`hot2cold.kernel.tessellate.tessellate`), as an STL or CFD surface mesh gives them (no node inside
  a plane);
* field ``affine``: :meth:`hot2cold.testing.synthetic.AffineField.thermal` about the part's centre (scale
  1 + 2e-4, 0.05 degrees about a skew axis, a translation of 1e-4 x diagonal); ``smooth``:
  :class:`hot2cold.testing.synthetic.UntwistField` about the part's longest side, displacements about
  1e-3 x diagonal; written with the nodes as an ``.npz``;
* the morph: ``hot2cold.cli.main(["morph", hot, field.npz, "-o", cold, "--report", json, "-q"])``, its exit
  code and one-line message; time and the process's peak resident memory (``ru_maxrss``) after it;
* on exit 0 or 5 (written, the tolerance missed): the cold STEP read back
  (:func:`hot2cold.kernel.step.read_step`), BRepCheck, free edges and faces
  of its solids (:func:`hot2cold.kernel.validity.check_solids`) against the hot part's; and the error against
  the exact cold geometry: dense samples inside every hot face (:func:`hot2cold.kernel.sampling.face_samples`,
  half the node spacing), mapped by the analytic field, each one's distance to the cold face with the same
  index (:class:`hot2cold.kernel.project.Projector`); the largest over all faces and the face where it is;
  and the faces the report names as out of their nodes' reach (``unsupported_faces``, "not measured").

A run past ``--timeout`` is killed and recorded as such; a child that dies (signal, memory limit
``--max-memory``) is recorded with what it wrote to stderr.  Everything is seeded: the same options give the
same node sets and fields.

``--doc PAGE`` (after a run, or with ``--show``) writes the tables it prints into the page's blocks of their
names (:data:`DOC_PAGES`, ``benchmarks/doc_blocks.py``): the scoreboard into ``real_parts_scoreboard``, the
stage table into ``real_parts_stages``::

    python benchmarks/real_parts.py --json runs.json
    python benchmarks/real_parts.py --show runs.json --doc docs/benchmarks/real_parts.md
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import re
import resource
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))     # the corpus and doc_blocks modules beside this one
import doc_blocks  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "corpus" / "real_parts"
SAMPLES = ROOT / "sample_parts"
FIELDS = ("affine", "smooth")
NODES = ("fe", "tess")
#: Node spacing is the diagonal over this, bounded by the node counts below.
PER_DIAGONAL = 80
NODE_RANGE = (5_000, 40_000)
#: The affine field must be reproduced to this (mm) on every face.
AFFINE_TOLERANCE = 1e-8
#: The default tolerance (mm) the smooth field is scored against.
SMOOTH_TOLERANCE = 1e-3
#: Exit codes with a cold part written: 0, and 5 (written, the tolerance missed).
WRITTEN = (0, 5)
SEED = 0


#: A tangent edge whose angle after the G1 correction is more than this (degrees) above its hot one is counted
#: (issue 15: every originally tangent edge within 0.01 deg).
KINK_LIMIT = 0.01
#: A curvature jump above this share of the curvature across an edge that was curvature-continuous when hot
#: (``Settings.g2_tolerance``'s default) is counted.
G2_LIMIT = 0.01


@dataclass
class Run:
    """One (part, node set, field) run: what the morph said and what the cold part is."""

    part: str
    path: str
    nodes_kind: str
    field: str
    cad: str = ""
    faces: int | None = None            # faces of the hot part's solids
    nodes: int | None = None
    spacing: float | None = None
    exit_code: int | None = None        # None: the child died before the morph returned
    message: str = ""
    seconds: float | None = None        # the morph (cli.main) alone
    peak_mb: float | None = None        # the child's peak resident memory
    valid: bool | None = None           # every solid of the cold STEP, read back, passes BRepCheck
    free_edges: int | None = None
    faces_cold: int | None = None
    exact_max: float | None = None      # mm, over dense samples inside every face
    exact_face: int | None = None       # the face of exact_max
    samples: int | None = None
    delta_max: float | None = None      # mm, the report's, at the nodes
    unmeasured: list[int] | None = None  # faces the report does not vouch for: its unsupported_faces, and on
    #                                     a run it calls partly measured every face with a share unmeasured
    verdict: str | None = None          # the report's verdict: met, partly measured, not met
    measured: float | None = None       # the share of the part's area the report vouches for
    kinks: int | None = None            # the report's tangent edges the morph kinked (its g1 list)
    kink_before: float | None = None    # deg, the largest angle added to a hot one along them before G1
    kink_max: float | None = None       # deg, the largest angle added to a hot one along them after G1
    kinks_over: int | None = None       # how many of them are more than KINK_LIMIT off their hot angle
    g2_edges: int | None = None         # of them, those curvature-continuous when hot (the report's "g2")
    g2_over: int | None = None          # how many of those end with a curvature jump above G2_LIMIT
    g2_max: float | None = None         # the largest curvature jump after the morph on them (share)
    timings: dict[str, float] = field(default_factory=dict)   # s, the report's time of each stage
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """A cold part written (exit 0, or 5: the tolerance missed), valid on read-back, faces kept, 0 free
        edges."""
        return (self.exit_code in WRITTEN and bool(self.valid) and self.free_edges == 0
                and self.faces_cold == self.faces)

    @property
    def exact(self) -> bool:
        """:attr:`ok` and within :data:`AFFINE_TOLERANCE` of the exact cold geometry on every face."""
        return self.ok and self.exact_max is not None and self.exact_max <= AFFINE_TOLERANCE


# ------------------------------------------------------------------------------------------------- the parts

def parts(quick: bool = False) -> list[Path]:
    """The corpus parts present here (``corpus/manifest.json`` through :func:`corpus.corpus_parts`; the quick
    subset with ``quick``), then, for the whole corpus, the bundled sample parts."""
    from corpus import corpus_parts

    found = corpus_parts(quick=quick)
    return found if quick else found + sorted((ROOT / "sample_parts").glob("*.step"))


def cad_system(path: Path) -> str:
    """The STEP header's FILE_NAME ``originating_system`` (else ``preprocessor_version``), shortened."""
    with open(path, "rb") as fh:
        head = fh.read(8192).decode("latin-1")
    match = re.search(r"FILE_NAME\s*\((.*?)\)\s*;", head, re.S)
    if not match:
        return "?"
    strings = [s.strip() for s in re.findall(r"'((?:[^']|'')*)'", match.group(1))]
    # name, time stamp, author(s), organisation(s), preprocessor_version, originating_system, authorization
    for s in (strings[-2], strings[-3]) if len(strings) >= 3 else ():
        if s and s.lower() not in ("unknown", "none"):
            return re.sub(r"\s+", " ", s)[:28]
    return "blank"


def solid_faces(shape) -> list:
    """The faces of the solids of ``shape`` (loose shells beside them left out), solid after solid, each in
    the project's numbering (:func:`hot2cold.kernel.sampling.face_list`)."""
    from OCP.TopAbs import TopAbs_SOLID

    from hot2cold.kernel.sampling import face_list
    from hot2cold.kernel.explore import shape_map

    return [f for solid in shape_map(shape, TopAbs_SOLID) for f in face_list(solid)]


def box(shape) -> tuple[np.ndarray, np.ndarray]:
    """Corners ``(3,)``, ``(3,)`` of the bounding box of ``shape`` in mm."""
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    b = Bnd_Box()
    BRepBndLib.Add_s(shape, b, False)
    x0, y0, z0, x1, y1, z1 = b.Get()
    return np.array([x0, y0, z0]), np.array([x1, y1, z1])


def node_spacing(diagonal: float, area: float) -> float:
    """diagonal / :data:`PER_DIAGONAL`, bounded so that ``area`` (mm^2) gets about :data:`NODE_RANGE` nodes."""
    lo, hi = np.sqrt(area / NODE_RANGE[1]), np.sqrt(area / NODE_RANGE[0])
    return float(np.clip(diagonal / PER_DIAGONAL, lo, hi))


def node_set(shape, kind: str, spacing: float) -> np.ndarray:
    """Node positions ``(N, 3)`` of kind ``fe`` (FE-like surface nodes) or ``tess`` (triangulation vertices,
    merged where faces share them; the deflection is raised until at most :data:`NODE_RANGE` [1] remain)."""
    if kind == "fe":
        from hot2cold.kernel.sampling import fe_surface_nodes

        return fe_surface_nodes(shape, spacing, seed=SEED)[0]
    if kind == "tess":
        from hot2cold.kernel.tessellate import tessellate
        from hot2cold.kernel.explore import diagonal

        def vertices(deflection):
            return np.unique(np.round(tessellate(shape, deflection).vertices, 9), axis=0)

        deflection = 1e-3 * diagonal(shape)
        v = vertices(deflection)
        for _ in range(6):                  # coarser while too many
            if len(v) <= NODE_RANGE[1]:
                break
            deflection *= 3.0
            v = vertices(deflection)
        for _ in range(2):                  # finer while too few, as long as not too many
            if len(v) >= NODE_RANGE[0]:
                break
            finer = vertices(deflection / 3.0)
            if len(finer) > NODE_RANGE[1]:
                break
            deflection, v = deflection / 3.0, finer
        return v
    raise ValueError(f"unknown node set {kind!r}: one of {NODES}")


def make_field(name: str, lo: np.ndarray, hi: np.ndarray):
    """The analytic field ``name`` (``affine`` or ``smooth``) for a part of bounding box ``lo``, ``hi`` (3,)."""
    from hot2cold.testing.synthetic import AffineField, UntwistField

    centre = 0.5 * (lo + hi)
    diag = float(np.linalg.norm(hi - lo))
    if name == "affine":
        t = np.array([1.0, -0.6, 0.3])
        return AffineField.thermal(contraction=2e-4, rotation_deg=0.05, axis=(1.0, 2.0, 3.0),
                                   translation=1e-4 * diag * t / np.linalg.norm(t), center=centre)
    if name == "smooth":
        span = int(np.argmax(hi - lo))
        axis = np.eye(3)[span]
        half = 0.5 * float(hi[span] - lo[span])
        return UntwistField(axis_point=centre, span_axis=axis, untwist_deg_per_mm=np.degrees(1e-3) / half,
                            stretch_per_mm2=5e-4 * diag / half ** 2, z0=float(centre[span]))
    raise ValueError(f"unknown field {name!r}: one of {FIELDS}")


# ----------------------------------------------------------------------------------------------- the measure

def exact_error(hot, cold, exact_map, spacing: float) -> tuple[float, int, int]:
    """Largest distance (mm) of the exact cold positions of dense samples inside every hot face to the cold
    face with the same index; ``(max, face, samples)`` (the reduction of :func:`face_errors`)."""
    worst, where, count = 0.0, -1, 0
    for k, dist in enumerate(face_errors(hot, cold, exact_map, spacing)):
        count += len(dist)
        if len(dist) and dist.max() > worst:
            worst, where = float(dist.max()), k
    return worst, where, count


def face_errors(hot, cold, exact_map, spacing: float) -> list[np.ndarray]:
    """Per hot face, the distances ``(m,)`` (mm) of the exact cold positions of its dense samples to the cold
    face with the same index.

    The samples are :func:`hot2cold.kernel.sampling.face_samples` at ``spacing`` mm inside every face of the
    solids (:func:`solid_faces`); the cold part must have as many faces.  ``exact_map`` maps one face's hot
    samples ``(m, 3)`` to their exact cold points ``(m, 3)``.  A sample the kernel cannot project counts as
    ``inf``.  The kernel's foot points are polished by Newton's method on the cold face's own B-spline
    surface (:func:`hot2cold.core.footpoint.project_to_surface`, the nearer of the two kept): the kernel's
    projection stops about 2e-8 mm short on Rotor 67's degree-14 faces, above the affine target of 1e-8 mm.
    """
    from OCP.TopoDS import TopoDS_Compound
    from OCP.BRep import BRep_Builder

    from hot2cold.core.footpoint import project_to_surface
    from hot2cold.errors import KernelError
    from hot2cold.kernel.convert import surface_to_record
    from hot2cold.kernel.project import Projector
    from hot2cold.kernel.sampling import face_samples
    from hot2cold.kernel.explore import bspline_surface

    hot_faces, cold_faces = solid_faces(hot), solid_faces(cold)
    if len(hot_faces) != len(cold_faces):
        raise ValueError(f"the cold part has {len(cold_faces)} faces, the hot one {len(hot_faces)}")
    compound, builder = TopoDS_Compound(), BRep_Builder()
    builder.MakeCompound(compound)
    for f in hot_faces:
        builder.Add(compound, f)
    projector = Projector(cold_faces, [])
    out = []
    for k, (_, points) in enumerate(face_samples(compound, spacing)):
        cold_points = exact_map(points)
        uv, dist = projector.to_face(k, cold_points)
        found = np.isfinite(dist)
        try:
            surface = surface_to_record(*bspline_surface(cold_faces[k]))
        except KernelError:                       # an analytic face (not a morph's): as the kernel found it
            surface = None
        if found.any() and surface is not None:
            fp = project_to_surface(surface, cold_points[found], uv[found], projector.face_box(k))
            dist[found] = np.where(fp.settled, np.minimum(dist[found], fp.distance), dist[found])
        out.append(dist)
    return out


def one_line(text: str) -> str:
    """The last 'hot2cold: ...' line of ``text``, else its last non-empty line."""
    lines = [s.strip() for s in text.splitlines() if s.strip()]
    for s in reversed(lines):
        if s.startswith("hot2cold:"):
            return s
    return lines[-1] if lines else ""


def run_here(path: Path, nodes_kind: str, field_name: str, workdir: Path, morph_args: tuple = ()) -> Run:
    """One run in this process (the child's work): nodes, field, morph by the command line (with the extra
    options ``morph_args``), checks."""
    from hot2cold.cli import main as cli_main
    from hot2cold.kernel.step import read_step
    from hot2cold.kernel.explore import diagonal
    from hot2cold.kernel.validity import check_solids, face_areas

    from hot2cold.errors import Hot2ColdError

    run = Run(part=path.stem, path=str(path), nodes_kind=nodes_kind, field=field_name, cad=cad_system(path))
    try:
        hot = read_step(path)
    except Hot2ColdError as exc:       # refused as the command line refuses it, with its exit code and words
        run.exit_code, run.message = exc.exit_code, f"hot2cold: error: {exc}".replace(f"{ROOT}{os.sep}", "")
        return run
    faces = solid_faces(hot)
    run.faces = len(faces)
    lo, hi = box(hot)
    run.spacing = node_spacing(diagonal(hot), float(face_areas(faces).sum()))
    points = node_set(hot, nodes_kind, run.spacing)
    run.nodes = len(points)
    analytic = make_field(field_name, lo, hi)
    stem = f"{path.stem}_{nodes_kind}_{field_name}"
    field_path, cold_path, report_path = (workdir / f"{stem}.npz", workdir / f"{stem}_cold.step",
                                          workdir / f"{stem}_report.json")
    np.savez(field_path, points=points, displacements=analytic(points))

    stderr = io.StringIO()
    start = time.perf_counter()
    with contextlib.redirect_stderr(stderr):
        run.exit_code = cli_main(["morph", str(path), str(field_path), "-o", str(cold_path), "--report",
                                  str(report_path), "-q", *morph_args])
    run.seconds = time.perf_counter() - start
    run.peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    run.message = one_line(stderr.getvalue()).replace(f"{workdir}{os.sep}", "")
    if report_path.exists():
        data = json.loads(report_path.read_text())
        run.delta_max, run.unmeasured = data.get("delta_max"), data.get("unsupported_faces")
        run.timings = data.get("timings") or {}
        run.verdict = (data.get("verdict") or {}).get("state")
        run.measured = (data.get("verdict") or {}).get("measured")
        if run.verdict not in (None, "met"):     # it vouches for none of a face with any share unmeasured
            run.unmeasured = sorted(set(run.unmeasured or []) | {
                f["index"] for f in data.get("faces", []) if (f.get("unsupported") or 0.0) > 0.0})
        added = [g["kink_after_max"] - g["hot_angle_max"] for g in data.get("g1", [])]
        run.kinks, run.kink_max = len(added), max(added, default=0.0)
        run.kink_before = max((g["kink_before_max"] - g["hot_angle_max"] for g in data.get("g1", [])), default=0.0)
        run.kinks_over = sum(a > KINK_LIMIT for a in added)
        jumps = [g["jump_after"] for g in data.get("g1", []) if g.get("g2")]
        run.g2_edges, run.g2_over = len(jumps), sum(j > G2_LIMIT for j in jumps)
        run.g2_max = max((j for j in jumps if math.isfinite(j)), default=0.0)
    if run.exit_code not in WRITTEN or not cold_path.exists():
        return run

    cold = read_step(cold_path)
    checks = check_solids(cold)
    run.valid = bool(checks) and all(c.valid for c in checks)
    run.free_edges = sum(c.free_edges for c in checks)
    run.faces_cold = sum(c.faces for c in checks)
    if run.faces_cold == run.faces:
        run.exact_max, run.exact_face, run.samples = exact_error(hot, cold, analytic.exact_map, run.spacing / 2)
    else:
        run.notes.append("faces not kept: no exact error")
    return run


# -------------------------------------------------------------------------------------------- the processes

def load(data: dict) -> Run:
    """A :class:`Run` from its saved dict."""
    return Run(**{k: v for k, v in data.items() if k in Run.__dataclass_fields__})


def spawn(cmd: list[str], timeout: float, max_memory_gb: float | None, stderr_path: Path):
    """Run ``cmd`` in a fresh process group (the repository first on its ``PYTHONPATH``, its stderr into
    ``stderr_path``, address space capped at ``max_memory_gb``), killed after ``timeout`` seconds.

    Returns ``(status, usage, seconds)``: the wait status (or ``"timeout"``), the child's
    ``resource.struct_rusage`` and the wall time.
    """
    def limit():
        os.setsid()
        if max_memory_gb:
            cap = int(max_memory_gb * 2 ** 30)
            resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    with open(stderr_path, "wb") as err:
        child = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, preexec_fn=limit, env=env)
        start, status, usage = time.perf_counter(), None, None
        while True:
            pid, status, usage = os.wait4(child.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - start > timeout:
                os.killpg(child.pid, signal.SIGKILL)
                _, status, usage = os.wait4(child.pid, 0)
                status = "timeout"
                break
            time.sleep(0.2)
        child.returncode = 0        # reaped here; keep Popen from waiting again
    return status, usage, time.perf_counter() - start


def died(status, timeout: float, stderr_path: Path) -> str:
    """What became of a child that wrote no result: ``timeout after T s``, ``child exit N: <its last line>``
    or ``child killed by signal N: ...``; ``status`` as :func:`spawn` returns it."""
    if status == "timeout":
        return f"timeout after {timeout:.0f} s"
    code = os.waitstatus_to_exitcode(status)
    tail = one_line(stderr_path.read_text(errors="replace"))
    return (f"child killed by signal {-code}" if code < 0 else f"child exit {code}") + (f": {tail}" if tail else "")


def run_child(path: Path, nodes_kind: str, field_name: str, timeout: float, max_memory_gb: float | None,
              morph_args: tuple = ()) -> Run:
    """:func:`run_here` in a fresh process; a timeout, a crash or a memory limit is recorded, not raised."""
    with tempfile.TemporaryDirectory(prefix="real_parts_") as tmp:
        tmp = Path(tmp)
        out = tmp / "run.json"
        cmd = [sys.executable, __file__, "--one", str(path), "--nodes", nodes_kind, "--fields", field_name,
               "--workdir", str(tmp), "--json", str(out), f"--morph-args={' '.join(morph_args)}"]
        status, usage, seconds = spawn(cmd, timeout, max_memory_gb, tmp / "stderr.txt")
        if out.exists():
            run = load(json.loads(out.read_text()))
        else:
            run = Run(part=path.stem, path=str(path), nodes_kind=nodes_kind, field=field_name, cad=cad_system(path))
            run.message = died(status, timeout, tmp / "stderr.txt")
            run.peak_mb = usage.ru_maxrss / 1024.0
            run.seconds = seconds
        return run


# -------------------------------------------------------------------------------------------- the scoreboard

def _num(x, fmt: str) -> str:
    return "-" if x is None else "inf" if x == float("inf") else format(x, fmt)


def _faces(faces: list[int], most: int = 4) -> str:
    """``"6, 9, 8 +11"``: the first ``most`` faces and how many more; "" for none."""
    more = f" +{len(faces) - most}" if len(faces) > most else ""
    return ", ".join(str(k) for k in faces[:most]) + more


def scoreboard(runs: list[Run], width: int = 90) -> str:
    """The table of ``runs`` and the summary line."""
    head = ("part", "CAD system", "faces", "nodes", "field", "exit", "message", "time s", "peak MB", "valid",
            "free edges", "faces kept", "exact max mm", "worst face", "Δmax nodes mm", "verdict", "not measured",
            "kinked edges", f"> {KINK_LIMIT:g}° after G1", "largest kink added ° before G1", "after",
            "G2 edges", f"jump > {100 * G2_LIMIT:g} %", "largest jump %")
    rows = []
    for r in runs:
        message = r.message.removeprefix("hot2cold: ").removeprefix("error: ")
        if len(message) > width:
            message = message[:width - 1] + "…"
        rows.append((r.part, r.cad, _num(r.faces, "d"), f"{r.nodes_kind} {_num(r.nodes, 'd')}", r.field,
                     _num(r.exit_code, "d"), message, _num(r.seconds, ".1f"), _num(r.peak_mb, ".0f"),
                     _num(r.valid, ""), _num(r.free_edges, "d"),
                     "-" if r.faces_cold is None else "yes" if r.faces_cold == r.faces else f"{r.faces_cold}",
                     _num(r.exact_max, ".2e"), _num(r.exact_face, "d"), _num(r.delta_max, ".2e"),
                     (r.verdict or "-") + ("" if r.measured is None or r.measured >= 0.995
                                           else f" ({100 * r.measured:.0f} %)"),
                     "-" if r.unmeasured is None else _faces(r.unmeasured), _num(r.kinks, "d"),
                     _num(r.kinks_over, "d"), _num(r.kink_before, ".2g"), _num(r.kink_max, ".2g"),
                     _num(r.g2_edges, "d"), _num(r.g2_over, "d"),
                     _num(None if r.g2_max is None else 100 * r.g2_max, ".2g")))
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    lines += ["", by_kind(runs), "", summary(runs)]
    return "\n".join(lines)


#: Failure kinds of a run, in the order the scoreboard lists them: (kind, test on a run).
KINDS = (
    ("morphed", lambda r: r.ok),
    ("refused: broken as given", lambda r: r.exit_code == 2 and any(
        words in r.message for words in ("is not valid", "is not closed", "cannot read STEP file"))),
    ("refused: other input error", lambda r: r.exit_code == 2),
    ("B-spline conversion", lambda r: r.exit_code == 3 and "conversion" in r.message),
    ("other kernel failure", lambda r: r.exit_code == 3),
    ("cold part invalid (exit 4)", lambda r: r.exit_code == 4),
    ("written but invalid, open or faces lost on read-back", lambda r: r.exit_code in WRITTEN),
    ("timeout", lambda r: r.message.startswith("timeout")),
    ("killed (memory, signal)", lambda r: r.exit_code is None),
    ("other", lambda r: True),
)


def failure_kind(run: Run) -> str:
    """The first of :data:`KINDS` that ``run`` is."""
    return next(kind for kind, test in KINDS if test(run))


def by_kind(runs: list[Run]) -> str:
    """The runs counted by failure kind and field, each kind with its parts; then the CAD systems covered."""
    fields = sorted({r.field for r in runs})
    lines = ["| kind | " + " | ".join(fields) + " | parts |", "|---|" + "---|" * len(fields) + "---|"]
    for kind, _ in KINDS:
        these = [r for r in runs if failure_kind(r) == kind]
        if not these:
            continue
        names = "" if kind == "morphed" else ", ".join(sorted({r.part for r in these}))
        counts = " | ".join(str(sum(r.field == f for r in these)) for f in fields)
        lines.append(f"| {kind} | {counts} | {names} |")
    systems: dict = {}
    for r in runs:
        systems.setdefault(r.cad or "?", set()).add(r.part)
    lines += ["", "CAD systems: " + ", ".join(f"{cad} ({len(p)})" for cad, p in sorted(systems.items()))]
    peak = max((r for r in runs if r.peak_mb is not None), key=lambda r: r.peak_mb, default=None)
    if peak is not None:
        lines.append(f"largest peak memory: {peak.peak_mb:.0f} MB ({peak.part}, {peak.field})")
    return "\n".join(lines)


def summary(runs: list[Run]) -> str:
    """"N of M morph (written, valid on read-back, faces kept, 0 free edges); affine within 1e-8 mm on K of
    A; smooth within 1e-3 mm on J of S; exit 0 beyond it on a face not named as unmeasured: F (parts)": F
    counts the silent misses, a success exit for a part off the exact geometry where the report measured it."""
    affine = [r for r in runs if r.field == "affine"]
    smooth = [r for r in runs if r.field == "smooth"]
    met = sum(r.ok and r.exact_max is not None and r.exact_max <= SMOOTH_TOLERANCE for r in smooth)
    silent = [r.part for r in smooth if r.exit_code == 0 and r.exact_max is not None
              and r.exact_max > SMOOTH_TOLERANCE and r.exact_face not in (r.unmeasured or [])]
    return (f"{sum(r.ok for r in runs)} of {len(runs)} morph (a cold part written, exit 0 or 5, valid on "
            f"read-back, faces kept, 0 free edges; {sum(r.exit_code == 0 for r in runs)} exit 0); affine within "
            f"{AFFINE_TOLERANCE:g} mm on {sum(r.exact for r in affine)} of {len(affine)}; smooth within "
            f"{SMOOTH_TOLERANCE:g} mm on {met} of {len(smooth)}; exit 0 beyond it on a face not named as "
            f"unmeasured: {len(silent)}{' (' + ', '.join(silent) + ')' if silent else ''}")


#: The stages of :func:`stage_table`, each the report's timings it sums ("fit": edges and faces, eq. 1-39).
STAGES = (("read+load", ("read", "invert", "load")), ("classify", ("classify",)), ("fit", ("edges", "faces")),
          ("refine", ("refine",)), ("G1+G2", ("g1", "g2")), ("rebuild+sew", ("rebuild", "sew")),
          ("check", ("check",)), ("report", ("report",)))
#: A stage other than the fit may take at most this share of a run's time (issue 36).
STAGE_SHARE = 1 / 3
#: A part of at most these faces and nodes morphs in at most ``STAGE_SECONDS`` (issue 36).
STAGE_FACES, STAGE_NODES, STAGE_SECONDS = 300, 60_000, 20.0


def stage_table(runs: list[Run]) -> str:
    """Per run with timings: the time (s) of each of :data:`STAGES`, the total of the command (``seconds``), the
    largest stage other than the fit and its share of the total; then the runs of parts of at most
    :data:`STAGE_FACES` faces and :data:`STAGE_NODES` nodes over :data:`STAGE_SECONDS` or with a stage other
    than the fit over :data:`STAGE_SHARE` of their time."""
    head = ("part", "faces", "nodes", "field") + tuple(name for name, _ in STAGES) + ("total s", "largest other",
                                                                                      "share")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    slow, lopsided, counted = [], [], 0
    for r in runs:
        if not r.timings or r.seconds is None:
            continue
        times = {name: sum(r.timings.get(k, 0.0) for k in keys) for name, keys in STAGES}
        other = max((name for name in times if name != "fit"), key=times.get)
        share = times[other] / r.seconds if r.seconds > 0 else 0.0
        lines.append("| " + " | ".join([r.part, _num(r.faces, "d"), _num(r.nodes, "d"), r.field]
                                       + [f"{times[name]:.2f}" for name, _ in STAGES]
                                       + [f"{r.seconds:.1f}", other, f"{100 * share:.0f} %"]) + " |")
        if (r.faces or 0) <= STAGE_FACES and (r.nodes or 0) <= STAGE_NODES:
            counted += 1
            if r.seconds > STAGE_SECONDS:
                slow.append(f"{r.part} {r.seconds:.1f} s")
            if share > STAGE_SHARE:
                lopsided.append(f"{r.part} {other} {100 * share:.0f} %")
    lines += ["", f"of {counted} runs of parts with at most {STAGE_FACES} faces and {STAGE_NODES} nodes: "
                  f"{len(slow)} over {STAGE_SECONDS:g} s ({', '.join(slow) or 'none'}); {len(lopsided)} with a "
                  f"stage other than the fit over {100 * STAGE_SHARE:.0f} % of the time "
                  f"({', '.join(lopsided) or 'none'})"]
    return "\n".join(lines)


#: The blocks of the docs that ``--doc`` writes (:func:`doc_tables`), each with the page it is meant for.
DOC_PAGES = {"real_parts_scoreboard": ROOT / "docs" / "benchmarks" / "real_parts.md",
             "real_parts_stages": ROOT / "docs" / "benchmarks" / "real_parts.md"}


def doc_tables(runs: list[Run]) -> dict[str, str]:
    """The tables this script prints for ``runs``, by the name of their block in the docs: the scoreboard
    (:func:`scoreboard`, with the counts by kind and the summary) and :func:`stage_table`."""
    return {"real_parts_scoreboard": scoreboard(runs), "real_parts_stages": stage_table(runs)}


def show(runs: list[Run], pages=None) -> int:
    """Print the tables of ``runs``; with ``pages`` (``--doc``), write them into those pages' blocks too
    (:func:`doc_blocks.doc_main`).  Returns the exit code."""
    tables = doc_tables(runs)
    print("\n\n".join(tables.values()))
    return doc_blocks.doc_main(pages, tables) if pages else 0


def select(paths: list[Path], names: str | None) -> list[Path]:
    """The parts whose file name contains one of the comma-separated ``names`` (case-insensitive)."""
    if not names:
        return paths
    wanted = [n.strip().lower() for n in names.split(",") if n.strip()]
    return [p for p in paths if any(w in p.name.lower() for w in wanted)]


def run_arguments(parser: argparse.ArgumentParser, timeout: float) -> None:
    """The options every benchmark of runs in child processes takes (this one and ``fe_fields.py``): time and
    memory limits per run, ``--json``/``--show``, ``--morph-args``, and the child's own ``--one``/``--workdir``."""
    parser.add_argument("--timeout", type=float, default=timeout, help=f"seconds per run (default {timeout:g})")
    parser.add_argument("--max-memory", type=float, default=8.0, metavar="GB",
                        help="address-space limit of each run (default 8 GB; 0: none)")
    parser.add_argument("--json", type=Path, help="save the runs here")
    parser.add_argument("--show", type=Path, nargs="+", metavar="JSON",
                        help="print the tables of runs saved with --json (several files: joined), run nothing")
    parser.add_argument("--morph-args", default="", metavar="ARGS",
                        help="extra options of every morph, one string (e.g. --morph-args='--keep-knots')")
    parser.add_argument("--one", help=argparse.SUPPRESS)                    # child: one run
    parser.add_argument("--workdir", type=Path, help=argparse.SUPPRESS)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", help="comma-separated parts of file names (default: all)")
    parser.add_argument("--quick", action="store_true",
                        help="the corpus's quick subset (about 15 parts) instead of the whole corpus")
    parser.add_argument("--fields", default=",".join(FIELDS), help=f"comma-separated, of {FIELDS}")
    parser.add_argument("--nodes", default=",".join(NODES), help=f"comma-separated node sets, of {NODES}")
    run_arguments(parser, 600.0)
    doc_blocks.add_doc_argument(parser, "the scoreboard and the stage table (blocks real_parts_scoreboard, "
                                        "real_parts_stages)")
    args = parser.parse_args(argv)
    morph_args = tuple(args.morph_args.split())
    fields = [f for f in args.fields.split(",") if f]
    kinds = [n for n in args.nodes.split(",") if n]
    for f in fields:
        if f not in FIELDS:
            parser.error(f"unknown field {f!r}: one of {FIELDS}")
    for n in kinds:
        if n not in NODES:
            parser.error(f"unknown node set {n!r}: one of {NODES}")

    if args.show:
        return show([load(r) for path in args.show for r in json.loads(path.read_text())], args.doc)
    if args.one is not None:
        run = run_here(Path(args.one), kinds[0], fields[0], args.workdir, morph_args)
        args.json.write_text(json.dumps(asdict(run)))
        return 0

    paths = select(parts(quick=args.quick), args.parts)
    if not paths:
        parser.error(f"no part matches {args.parts!r}")
    if args.doc and doc_blocks.doc_main(args.doc, table_names=DOC_PAGES):      # a missing block: say so now
        return 2
    runs = []
    for path in paths:
        for kind in kinds:
            for name in fields:
                run = run_child(path, kind, name, args.timeout, args.max_memory or None, morph_args)
                runs.append(run)
                print(f"{run.part} {kind} {name}: exit {run.exit_code} {_num(run.seconds, '.1f')} s "
                      f"exact {_num(run.exact_max, '.2e')} {run.message}", flush=True)
                if args.json:
                    args.json.write_text(json.dumps([asdict(r) for r in runs], indent=1))
    print()
    return show(runs, args.doc)


if __name__ == "__main__":
    sys.exit(main())
