"""Many faces: a plate with a grid of filleted, chamfered, counterbored holes (about 2000 faces at 20 x 20
holes), its morph timed stage by stage, with its peak memory and the stage it peaked in.

Run from the repository::

    python benchmarks/many_faces.py                              # 10 and 20 holes per side, both fields
    python benchmarks/many_faces.py --holes 10 20 27 --json out/many_faces.json
    python benchmarks/many_faces.py --holes 20 --fields affine --profile out/profiles
    python benchmarks/many_faces.py --holes 27 --build-only       # the part alone: faces, build time, validity

The part (:func:`build`): a plate ``N * PITCH`` mm square (400 mm at the default pitch of 20 mm and 20 holes
per side) and :data:`THICKNESS` mm thick, with ``N x N`` holes, ``--holes N``.  Each hole is a through hole
chamfered at the bottom (a cone) with a counterbore at the top whose rim is filleted (a torus): a torus, two
cylinders, the counterbore's flat floor and a cone, 5 faces per hole, so ``5 N^2 + 6`` faces (10: 506, 20:
2006, 27: 3651); the plate's top and bottom faces are single planes with ``N^2`` inner wires each.  Built
with CadQuery and OCP in one boolean: the hole's void, one solid of revolution (the profile revolved, so its
faces are the analytic cylinders, torus and cone), placed ``N^2`` times and cut from the box at once
(``BRepAlgoAPI_Cut``, every placement a tool: about 2 s for 20 x 20); checked by ``BRepCheck_Analyzer``
(one solid, ``5 N^2 + 6`` faces) and written as STEP under ``--cache`` (default ``benchmarks/.cache``,
``many_faces_<N>.step``, made once).  The pitch stays the same at every size, so the nodes grow with the faces.

Then, for each size and field, in a fresh process (one at a time, so that its peak memory is its own):

* nodes: :func:`hot2cold.kernel.sampling.fe_surface_nodes` at ``--spacing`` mm (default :data:`SPACING`,
  about 30 000 nodes at 20 x 20 holes; seed 0);
* field ``smooth`` or ``affine``: ``real_parts.make_field`` on the part's bounding box (an untwist about the
  longest side with displacements about 1e-3 x diagonal; a thermal contraction with a small rotation and
  translation);
* the morph, ``hot2cold.pipeline.morph.morph`` with ``Settings(blas_threads=1, threads=--threads)`` (as the
  ``hot2cold morph`` command runs it), each stage's time from ``report.timings`` (read, load, classify,
  edges, faces, refine, g1, g2, rebuild, sew, check, report: the time between one stage's end and the next
  one's start counts in the next one), then the cold STEP written (``MorphResult.write_step``, read back and
  checked);
* the verdict as ``hot2cold morph`` gives it: exit 0, 5 (the tolerance missed, written), 4 (cold part
  invalid), 3 (kernel), 2 (input); Δmax at the nodes (the report's);
* the cold part's validity: :func:`hot2cold.kernel.validity.check_solids` (BRepCheck, free edges, faces);
* for the fields in ``--exact`` (default ``affine``): the cold part against the exact cold geometry
  (``real_parts.exact_error``: dense samples at half the node spacing inside every hot face, mapped by the
  analytic field, their distance to the cold face of the same index);
* memory: the process's peak resident memory (``ru_maxrss``), and its resident memory sampled every
  :data:`SAMPLE_SECONDS` s in a thread (``VmRSS`` of ``/proc/self/status``) with the stage running at each
  sample (the morph's ``progress`` callback), so the stage at the peak is named; the resident memory when the
  morph starts (the part read, the nodes made) is its baseline.

A child is killed when its resident memory passes ``--max-rss`` (default 12 GB, sampled by the parent every
:data:`SAMPLE_SECONDS` s) or it runs past ``--timeout`` (default 3600 s), and that is recorded with the stage it
was in.  With ``--profile DIR`` each child runs under ``cProfile`` and leaves ``DIR/many_faces_<N>_<field>.prof``
(``python -m pstats``), for the stages that grow faster than the faces.

The table gives per size and field: faces, nodes, each stage's seconds, the morph's total, the write, peak MB
and the stage at the peak, the verdict, Δmax, validity and the exact error.  Then, between consecutive sizes,
each stage's growth against the faces' as an exponent (time ~ faces^p; 1 is linear), the stages above
:data:`SUPERLINEAR` named.
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import os
import resource
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))     # real_parts beside this one

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "benchmarks" / ".cache"
FIELDS = ("smooth", "affine")

#: The plate: hole pitch (mm; the plate is holes x PITCH square) and thickness (mm).
PITCH = 20.0
THICKNESS = 12.0
#: The hole (mm): through-hole radius, chamfer at the bottom (45 degrees), counterbore radius and depth from the
#: top, fillet radius on the counterbore's rim.
HOLE_RADIUS = 4.0
CHAMFER = 1.0
CBORE_RADIUS = 6.0
CBORE_DEPTH = 4.0
FILLET = 1.5
#: Faces per hole (torus, counterbore cylinder, counterbore floor, hole cylinder, cone) and of the plate.
FACES_PER_HOLE = 5
PLATE_FACES = 6
#: Node spacing (mm) of the FE-like surface nodes: about 30 000 nodes at 20 x 20 holes.
SPACING = 4.5
#: Seconds between two samples of resident memory (the child's own and the parent's watch).
SAMPLE_SECONDS = 0.2
#: A stage whose time or memory grows as faces^p with p above this between two sizes is named super-linear.
SUPERLINEAR = 1.3
#: Stages shorter than this (s) at the larger size are not judged (their growth is noise).
JUDGED_SECONDS = 1.0
#: The morph's stages as ``report.timings`` names them, in order.
STAGES = ("read", "load", "classify", "edges", "faces", "refine", "g1", "g2", "rebuild", "sew", "check", "report")

log = logging.getLogger("many_faces")


# ------------------------------------------------------------------------------------------------- the part

def faces_of(holes: int) -> int:
    """Faces of the part with ``holes`` x ``holes`` holes."""
    return FACES_PER_HOLE * holes * holes + PLATE_FACES


def hole_tool():
    """The void of one hole, centred on the z axis, the plate between z = +-THICKNESS/2: its profile (x radial,
    z up) revolved about z, so that its faces are the analytic surfaces (plane, cone, cylinder, torus)."""
    import cadquery as cq

    half = THICKNESS / 2
    profile = (cq.Workplane("XZ").moveTo(0, -half)
               .lineTo(HOLE_RADIUS + CHAMFER, -half).lineTo(HOLE_RADIUS, -half + CHAMFER)   # the chamfer
               .lineTo(HOLE_RADIUS, half - CBORE_DEPTH).lineTo(CBORE_RADIUS, half - CBORE_DEPTH)
               .lineTo(CBORE_RADIUS, half - FILLET)
               .radiusArc((CBORE_RADIUS + FILLET, half), FILLET)          # the fillet, centre in the plate
               .lineTo(0, half).close())
    return profile.revolve(360, (0, 0, 0), (0, 1, 0)).val().wrapped      # the workplane's y is global z


def build(holes: int):
    """The plate with ``holes`` x ``holes`` holes as a ``TopoDS_Shape`` (one solid): the box with every
    placement of :func:`hole_tool` cut from it in one boolean.  Raises RuntimeError when the boolean fails
    or gives anything but one valid solid of :func:`faces_of` faces."""
    import cadquery as cq
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.gp import gp_Trsf, gp_Vec
    from OCP.TopAbs import TopAbs_FACE, TopAbs_SOLID
    from OCP.TopLoc import TopLoc_Location
    from OCP.TopTools import TopTools_ListOfShape

    from hot2cold.kernel.explore import shape_map

    side = holes * PITCH
    plate = cq.Solid.makeBox(side, side, THICKNESS, pnt=cq.Vector(0, 0, -THICKNESS / 2)).wrapped
    tool = hole_tool()
    arguments, tools = TopTools_ListOfShape(), TopTools_ListOfShape()
    arguments.Append(plate)
    for i in range(holes):
        for j in range(holes):
            move = gp_Trsf()
            move.SetTranslation(gp_Vec((i + 0.5) * PITCH, (j + 0.5) * PITCH, 0.0))
            tools.Append(tool.Moved(TopLoc_Location(move)))
    cut = BRepAlgoAPI_Cut()
    cut.SetArguments(arguments)
    cut.SetTools(tools)
    cut.SetRunParallel(True)
    cut.Build()
    if not cut.IsDone():
        raise RuntimeError(f"the boolean of {holes} x {holes} holes failed")
    shape = cut.Shape()
    solids, faces = shape_map(shape, TopAbs_SOLID), shape_map(shape, TopAbs_FACE)
    if len(solids) != 1 or len(faces) != faces_of(holes) or not BRepCheck_Analyzer(shape).IsValid():
        raise RuntimeError(f"{holes} x {holes} holes: {len(solids)} solids, {len(faces)} faces (expected 1 and "
                           f"{faces_of(holes)}), BRepCheck valid {BRepCheck_Analyzer(shape).IsValid()}")
    return solids[0]


def part_path(holes: int, cache: Path = CACHE) -> Path:
    """The cached STEP of the part with ``holes`` x ``holes`` holes (its dimensions in the name, so a change
    of them makes a new one)."""
    dims = "_".join(f"{x:g}" for x in (PITCH, THICKNESS, HOLE_RADIUS, CHAMFER, CBORE_RADIUS, CBORE_DEPTH, FILLET))
    return cache / f"many_faces_{holes}_{dims}.step"


def cached_part(holes: int, cache: Path = CACHE) -> tuple[Path, float | None]:
    """The part's STEP (:func:`part_path`), built and written when missing: ``(path, build seconds or None
    when it was cached)``."""
    from hot2cold.kernel.step import write_step

    path = part_path(holes, cache)
    if path.exists():
        return path, None
    cache.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    shape = build(holes)
    seconds = time.perf_counter() - start
    write_step(shape, path, verify=True)        # atomic; read back as one valid closed solid with its faces
    return path, seconds


# ---------------------------------------------------------------------------------------------- the memory

def rss_mb(pid: int | str = "self") -> float:
    """Resident memory (MB) of process ``pid`` (``VmRSS`` of ``/proc/<pid>/status``); 0 when it is gone."""
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError):
        pass
    return 0.0


class StageMemory:
    """The stage the morph is in (its ``progress`` callback) and this process's resident memory sampled every
    :data:`SAMPLE_SECONDS` s in a thread, each sample with the stage it fell in.

    A stage is current from its start to its end; between one stage's end and the next one's start the label
    is ``"after <stage>"`` (that time counts in the next stage's timing: :meth:`peak` names it so).  Outside
    the morph the caller names what runs (:meth:`set`).  Each stage's CPU time (``time.process_time``, every
    thread's) is kept as ``report.timings`` keeps its wall time, from the last stage's end (or
    :meth:`start_clock`) to its own: on a machine shared with other jobs it grows with the work alone."""

    def __init__(self):
        self.stage = "start"
        self.samples: list[tuple[float, float, str]] = []       # (seconds, MB, stage)
        self.at_end: dict[str, float] = {}                      # MB when each stage ended
        self.cpu: dict[str, float] = {}                         # CPU seconds of each stage
        self._cpu_last = time.process_time()
        self._start = time.perf_counter()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> StageMemory:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def set(self, stage: str) -> None:
        """``stage`` runs from now on (a sample is taken at once; logged, for the parent of a child that is
        killed)."""
        if stage != self.stage:
            log.info("begin %s", stage)
        self.stage = stage
        self._sample()

    def start_clock(self) -> None:
        """The first stage's CPU time runs from now."""
        self._cpu_last = time.process_time()

    def progress(self, stage: str, done: int, total: int) -> None:
        """The morph's progress callback: ``(stage, 0, total)`` at a stage's start, ``(stage, total, total)``
        at its end."""
        if done >= total:
            now = time.process_time()
            self.cpu[stage], self._cpu_last = now - self._cpu_last, now
            self.at_end[stage] = rss_mb()
            self.set(f"after {stage}")
        elif self.stage != stage:
            self.set(stage)

    def _sample(self) -> None:
        self.samples.append((time.perf_counter() - self._start, rss_mb(), self.stage))

    def _run(self) -> None:
        while not self._stop.wait(SAMPLE_SECONDS):
            self._sample()

    def peak(self, order: list[str]) -> tuple[float, str]:
        """``(MB, stage)`` of the largest sample; ``"after X"`` named as the stage after X in ``order`` (the
        stages in the order they ran), where its time counts."""
        if not self.samples:
            return 0.0, "?"
        _, mb, stage = max(self.samples, key=lambda s: s[1])
        if stage.startswith("after "):
            done = stage.removeprefix("after ")
            if done in order and order.index(done) + 1 < len(order):
                stage = order[order.index(done) + 1]
        return mb, stage


# ------------------------------------------------------------------------------------------------ one run

def run_here(holes: int, field_name: str, spacing: float, threads: int, exact: bool, cache: Path) -> dict:
    """One size and field in this process (the child's work): nodes, field, morph, write, checks; its
    figures as a dict."""
    from hot2cold.cli.run import tolerance_missed
    from hot2cold.errors import Hot2ColdError
    from hot2cold.kernel.sampling import fe_surface_nodes
    from hot2cold.kernel.step import read_step
    from hot2cold.kernel.validity import check_solids
    from hot2cold.pipeline.morph import morph
    from hot2cold.settings import Settings
    import real_parts

    path = part_path(holes, cache)
    out: dict = {"holes": holes, "field": field_name, "threads": threads, "spacing": spacing, "timings": {},
                 "exit": None, "message": ""}
    with StageMemory() as memory:
        memory.set("nodes")
        hot = read_step(path)
        out["faces"] = len(real_parts.solid_faces(hot))
        lo, hi = real_parts.box(hot)
        clock = time.perf_counter()
        points = fe_surface_nodes(hot, spacing, seed=real_parts.SEED)[0]
        out["nodes_seconds"] = time.perf_counter() - clock
        out["nodes"] = len(points)
        analytic = real_parts.make_field(field_name, lo, hi)
        displacements = analytic(points)
        out["baseline_mb"] = rss_mb()

        memory.set("read")
        settings = Settings(blas_threads=1, threads=threads)
        start, cpu = time.perf_counter(), time.process_time()
        memory.start_clock()
        result = None
        try:
            result = morph(path, (points, displacements), settings, progress=memory.progress, check=False)
            out["morph"] = time.perf_counter() - start
            out["morph_cpu"] = time.process_time() - cpu
            out["timings"] = dict(result.report.timings)
            out["delta_max"] = result.report.delta_max
            out["report_valid"] = result.report.valid
            with tempfile.TemporaryDirectory(prefix="many_faces_") as tmp:
                memory.set("write")
                clock = time.perf_counter()
                result.write_step(Path(tmp) / "cold.step")          # check_result first: MorphError, exit 4
                out["write"] = time.perf_counter() - clock
            missed = tolerance_missed(result)
            out["exit"], out["message"] = (5, missed) if missed else (0, "")
        except Hot2ColdError as exc:
            out["morph"] = out.get("morph", time.perf_counter() - start)
            out["exit"], out["message"] = exc.exit_code, str(exc).splitlines()[0]
        out["morph_peak_mb"], out["morph_peak_stage"] = memory.peak(list(out["timings"]) or list(STAGES))
        out["stage_end_mb"] = dict(memory.at_end)
        out["cpu"] = dict(memory.cpu)

        if result is not None:
            memory.set("validity")
            clock = time.perf_counter()
            checks = check_solids(result.cold_kernel.shape)          # the shape result.cold wraps
            out["valid"] = bool(checks) and all(c.valid for c in checks)
            out["free_edges"] = sum(c.free_edges for c in checks)
            out["faces_cold"] = sum(c.faces for c in checks)
            out["validity_seconds"] = time.perf_counter() - clock
            if exact and out["faces_cold"] == out["faces"]:
                memory.set("exact")
                clock = time.perf_counter()
                out["exact_max"], out["exact_face"], out["exact_samples"] = real_parts.exact_error(
                    hot, result.cold_kernel.shape, analytic.exact_map, spacing / 2)
                out["exact_seconds"] = time.perf_counter() - clock
        out["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        out["sampled_peak_mb"], out["peak_stage"] = memory.peak(list(out["timings"]) or list(STAGES))
    return out


def run_child(holes: int, field_name: str, args) -> dict:
    """:func:`run_here` in a fresh process (its own process group), watched: killed past ``args.max_rss`` GB
    of resident memory or ``args.timeout`` seconds, and recorded so with the stage its log was at."""
    with tempfile.TemporaryDirectory(prefix="many_faces_") as tmp:
        tmp = Path(tmp)
        result, stderr_path = tmp / "run.json", tmp / "stderr.txt"
        cmd = [sys.executable, __file__, "--one", str(holes), "--fields", field_name, "--spacing", str(args.spacing),
               "--threads", str(args.threads), "--cache", str(args.cache), "--out", str(result)]
        if field_name in args.exact.split(","):
            cmd.append("--exact-here")
        if args.profile:
            args.profile.mkdir(parents=True, exist_ok=True)
            cmd += ["--profile-to", str(args.profile / f"many_faces_{holes}_{field_name}.prof")]
        env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        limit_mb = args.max_rss * 1024.0
        with open(stderr_path, "wb") as err:
            child = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, start_new_session=True, env=env)
            start, watched, killed, usage = time.perf_counter(), 0.0, "", None
            while True:
                pid, status, usage = os.wait4(child.pid, os.WNOHANG)
                if pid:
                    break
                now = rss_mb(child.pid)
                watched = max(watched, now)
                seconds = time.perf_counter() - start
                if now > limit_mb or seconds > args.timeout:
                    killed = (f"killed: resident memory {now:.0f} MB > {limit_mb:.0f} MB" if now > limit_mb
                              else f"killed: timeout after {seconds:.0f} s")
                    os.killpg(child.pid, signal.SIGKILL)
                    _, status, usage = os.wait4(child.pid, 0)
                    break
                time.sleep(SAMPLE_SECONDS)
            child.returncode = 0        # reaped here; keep Popen from waiting again
        seconds = time.perf_counter() - start
        if result.exists():
            row = json.loads(result.read_text())
        else:
            text = stderr_path.read_text(errors="replace")
            stage = last_stage(text)
            code = os.waitstatus_to_exitcode(status)
            tail = [s for s in text.splitlines() if s.strip()][-1:] or [""]
            row = {"holes": holes, "field": field_name, "faces": faces_of(holes), "exit": None,
                   "message": (killed or f"child exit {code}: {tail[0][:200]}") + f" (in {stage})",
                   "peak_mb": usage.ru_maxrss / 1024.0, "peak_stage": stage, "timings": {}}
        row["wall"] = seconds
        row["watched_peak_mb"] = watched
        return row


def last_stage(stderr: str) -> str:
    """The stage a child's log (its stderr) was last in: the last ``begin <stage>`` line."""
    stage = "start"
    for line in stderr.splitlines():
        if "many_faces: begin " in line:
            stage = line.split("many_faces: begin ", 1)[1].strip()
    return stage


# ------------------------------------------------------------------------------------------------ the table

def _cell(x, fmt: str) -> str:
    return "-" if x is None else format(x, fmt)


def table(rows: list[dict]) -> str:
    """The figures of ``rows`` as a markdown table: seconds per stage (wall, ``report.timings``), the morph's
    wall and CPU seconds, the write, memory (the child's peak ``ru_maxrss``, the sampled peak within the morph
    and its stage, the baseline before it), the verdict, Δmax, validity and the exact error."""
    stages = [s for s in STAGES if any(s in r["timings"] for r in rows)]
    head = ("holes", "faces", "nodes", "field", *stages, "morph s", "morph CPU s", "write s", "peak MB",
            "morph peak MB", "stage at morph peak", "base MB", "exit", "Δmax mm", "valid (free edges, faces)",
            "exact mm")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        valid = r.get("valid")
        verdict = _cell(r.get("exit"), "d") + (f" ({r['message'][:80]})" if r.get("message") else "")
        cells = (str(r["holes"]), str(r["faces"]), _cell(r.get("nodes"), "d"), r["field"],
                 *(_cell(r["timings"].get(s), ".2f") for s in stages), _cell(r.get("morph"), ".1f"),
                 _cell(r.get("morph_cpu"), ".1f"), _cell(r.get("write"), ".1f"), _cell(r.get("peak_mb"), ".0f"),
                 _cell(r.get("morph_peak_mb"), ".0f"), r.get("morph_peak_stage", r.get("peak_stage", "-")),
                 _cell(r.get("baseline_mb"), ".0f"), verdict, _cell(r.get("delta_max"), ".2e"),
                 "-" if valid is None else f"{valid} ({r['free_edges']}, {r['faces_cold']})",
                 _cell(r.get("exact_max"), ".2e"))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def exponent(small: float, large: float, ratio: float) -> float:
    """p in large / small = ratio^p (NaN where either is not positive)."""
    if not (small > 0 and large > 0 and ratio > 1):
        return float("nan")
    return math.log(large / small) / math.log(ratio)


def growth(rows: list[dict]) -> list[str]:
    """Between consecutive sizes of each field: each stage's wall and CPU time, the morph's, and the morph's
    memory above the baseline as faces^p; a stage whose CPU time (wall time where not measured) grows with p
    above :data:`SUPERLINEAR`, and takes at least :data:`JUDGED_SECONDS` s at the larger size, is named."""
    lines = []
    for name in dict.fromkeys(r["field"] for r in rows):
        these = sorted((r for r in rows if r["field"] == name and r["timings"]), key=lambda r: r["faces"])
        for a, b in zip(these, these[1:]):
            ratio = b["faces"] / a["faces"]
            parts, over = [], []
            for s in STAGES:
                p = exponent(a["timings"].get(s, 0.0), b["timings"].get(s, 0.0), ratio)
                ca, cb = a.get("cpu", {}).get(s), b.get("cpu", {}).get(s)
                q = exponent(ca or 0.0, cb or 0.0, ratio)
                if not math.isfinite(p):
                    continue
                parts.append(f"{s} {p:.2f}" + (f"/{q:.2f}" if math.isfinite(q) else ""))
                judged, seconds = (q, (ca, cb)) if math.isfinite(q) else \
                    (p, (a["timings"][s], b["timings"][s]))
                if judged > SUPERLINEAR and seconds[1] >= JUDGED_SECONDS:
                    over.append(f"{s} ({seconds[0]:.2f} -> {seconds[1]:.2f} s)")
            morph_p = exponent(a.get("morph", 0.0), b.get("morph", 0.0), ratio)
            morph_q = exponent(a.get("morph_cpu", 0.0), b.get("morph_cpu", 0.0), ratio)
            grown = [r.get("morph_peak_mb", 0.0) - r.get("baseline_mb", 0.0) for r in (a, b)]
            memory_p = exponent(*grown, ratio)
            if memory_p > SUPERLINEAR:
                over.append(f"the morph's memory above the baseline ({grown[0]:.0f} -> {grown[1]:.0f} MB)")
            lines.append(f"{name}, {a['faces']} -> {b['faces']} faces (x{ratio:.2f}; nodes x"
                         f"{b['nodes'] / a['nodes']:.2f}): time ~ faces^p, p wall/CPU: {', '.join(parts)}; morph "
                         f"{morph_p:.2f}/{morph_q:.2f}; the morph's memory above the baseline {memory_p:.2f}; faster "
                         f"than linear (p > {SUPERLINEAR:g}): {', '.join(over) or 'none'}")
    return lines


def details(rows: list[dict]) -> list[str]:
    """Per run: the exact error and what the benchmark's own steps took; resident memory at each stage's end
    and the peaks."""
    lines = []
    for r in rows:
        if r.get("exact_max") is not None:
            lines.append(f"{r['holes']} holes, {r['field']}: exact error {r['exact_max']:.3g} mm (face "
                         f"{r['exact_face']}, {r['exact_samples']} samples, {r['exact_seconds']:.1f} s)")
    for r in rows:
        if r.get("stage_end_mb"):
            lines.append(f"{r['holes']} holes, {r['field']}: nodes made in {r['nodes_seconds']:.1f} s, validity "
                         f"checked in {r.get('validity_seconds', float('nan')):.1f} s; resident MB at each stage's "
                         f"end: " + ", ".join(f"{s} {mb:.0f}" for s, mb in r["stage_end_mb"].items())
                         + f"; sampled peak in the morph {r['morph_peak_mb']:.0f} MB ({r['morph_peak_stage']}), in "
                         f"the run {r['sampled_peak_mb']:.0f} MB ({r['peak_stage']}), ru_maxrss {r['peak_mb']:.0f} "
                         f"MB; the parent saw {r.get('watched_peak_mb', 0.0):.0f} MB")
    return lines


def summary(rows: list[dict], threads: int | str, spacing: float | str) -> str:
    """The table, the growth between sizes and the details of ``rows``."""
    head = f"the morph in {threads} threads, nodes {spacing} mm apart; wall seconds per stage (report.timings)"
    return "\n".join([head, table(rows), "", *growth(rows), "", *details(rows)])


# ------------------------------------------------------------------------------------------------ main

def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--holes", type=int, nargs="+", default=[10, 20], metavar="N",
                        help="holes per side, one size each (default 10 20; 27 gives about 3650 faces)")
    parser.add_argument("--fields", default=",".join(FIELDS), help=f"comma-separated, of {', '.join(FIELDS)}")
    parser.add_argument("--spacing", type=float, default=SPACING, help=f"node spacing in mm (default {SPACING:g})")
    cores = len(os.sched_getaffinity(0))
    parser.add_argument("--threads", type=int, default=cores,
                        help=f"Settings.threads of the morph (default: this process's cores, {cores})")
    parser.add_argument("--exact", default="affine",
                        help="comma-separated fields whose cold part is measured against the exact geometry "
                             "(default affine; 'none': no field)")
    parser.add_argument("--max-rss", type=float, default=12.0, metavar="GB",
                        help="kill a child past this resident memory (default 12 GB)")
    parser.add_argument("--timeout", type=float, default=3600.0, help="seconds per child (default 3600)")
    parser.add_argument("--cache", type=Path, default=CACHE, help="where the parts' STEP files are kept")
    parser.add_argument("--json", type=Path, help="save the runs here")
    parser.add_argument("--profile", type=Path, metavar="DIR", help="run each child under cProfile, stats to DIR")
    parser.add_argument("--build-only", action="store_true", help="build (or find) the parts and stop")
    parser.add_argument("--show", type=Path, metavar="JSON", help="print the tables of runs saved with --json")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)              # child: one size and field
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--exact-here", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--profile-to", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    fields = [f for f in args.fields.split(",") if f]
    for f in fields:
        if f not in FIELDS:
            parser.error(f"unknown field {f!r}: one of {', '.join(FIELDS)}")

    if args.one is not None:                  # the child
        logging.basicConfig(stream=sys.stderr, level=logging.INFO,
                            format="%(asctime)s %(levelname)s %(name)s: %(message)s")
        run = (args.one, fields[0], args.spacing, args.threads, args.exact_here, args.cache)
        if args.profile_to:
            import cProfile

            profiler = cProfile.Profile()
            row = profiler.runcall(run_here, *run)
            profiler.dump_stats(args.profile_to)
        else:
            row = run_here(*run)
        args.out.write_text(json.dumps(row))
        return 0

    if args.show:
        rows = json.loads(args.show.read_text())
        print(summary(rows, rows[0].get("threads", "?") if rows else "?", rows[0].get("spacing", "?") if rows else "?"))
        return 0
    for holes in args.holes:
        path, seconds = cached_part(holes, args.cache)
        made = f"built in {seconds:.1f} s" if seconds is not None else "cached"
        print(f"{holes} x {holes} holes: {faces_of(holes)} faces, {path.name} ({made}; one valid solid)", flush=True)
    if args.build_only:
        return 0

    rows = []
    for holes in args.holes:
        for name in fields:
            row = run_child(holes, name, args)
            rows.append(row)
            print(f"{holes} x {holes} holes, {name}: exit {row.get('exit')} morph {_cell(row.get('morph'), '.1f')} s "
                  f"peak {row['peak_mb']:.0f} MB in {row.get('peak_stage')}"
                  + (f": {row['message']}" if row.get("message") else ""), flush=True)
            if args.json:
                args.json.parent.mkdir(parents=True, exist_ok=True)
                args.json.write_text(json.dumps(rows, indent=1))
    print()
    print(summary(rows, args.threads, f"{args.spacing:g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
