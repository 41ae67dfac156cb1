"""Speed and scale on two blades: every phase timed at 10 k, 100 k and 1 M surface nodes, against the direct
approach.

Run from the repository::

    python benchmarks/scale.py                      # both blades, 10 000, 100 000 and 1 000 000 nodes
    python benchmarks/scale.py 100000 --direct-max 100000 --blades thin_blade

The blades (``--blades``, default both):

* ``rotor37``: the bundled Rotor 37 blade (``sample_parts/rotor37_blade.step``, leading- and trailing-edge
  faces about 0.25 mm in radius at the hub).  Its bundled CalculiX field (44 478 surface nodes) is resampled
  onto an FE-like surface node set of each size (:func:`hot2cold.kernel.sampling.fe_surface_nodes`,
  displacements by the FE solution's own interpolation over its quadratic boundary triangles,
  :func:`reference`).
* ``thin_blade``: ``sample_parts/thin_blade.step`` (``sample_parts/make_thin_blade.py``): a twisted blade whose
  two faces each wrap round a thin edge, smallest radius of curvature 0.059 mm at the leading edge and
  0.026 mm at the trailing edge, as a blade-design tool writes them.  Its field is synthetic, not FE: the
  smooth :class:`~hot2cold.testing.synthetic.UntwistField` of the twisted blade sample (``make_samples.py``'s
  ``BLADE_FIELD``) on FE-like surface nodes of each size (:func:`hot2cold.kernel.sampling.fe_surface_nodes`).
  (The corpus's ``rotor67.step`` has a 0.058 mm leading edge too, but it is a fluid passage with the blade as a
  hole, and its blade faces end at the edges: none wraps round one.)

Node sets are saved as ``.npz`` under ``--cache`` (default ``benchmarks/.cache``, made once).  Then, in a fresh
process per blade and size so that its peak memory is its own:

* the morph, read from the ``.npz`` (``hot2cold.pipeline.morph``), with the time of each phase: load (STEP and
  field), classify (classification and foot points), fit (edges and faces on the hot knots), refine (to the
  tolerance), G1 (and G2), rebuild and sew, report, and write (the cold STEP); and the process's peak resident
  memory;
* the cold part against the exact cold geometry (:func:`exact_error`): dense samples over every face moved by
  :func:`reference`, the same at every size, so that the accuracy of sizes compares (Δmax at the nodes is a
  largest over more nodes at each size);
* the direct approach, for sizes up to ``--direct-max`` (default 100 000; 1 M takes about 15 minutes):
  every node projected with ``GeomAPI_ProjectPointOnSurf`` onto every face (initialised once per face, the
  kernel's default algorithm), its foot point classified with ``BRepTopAdaptor_FClass2d``, the nearest one
  inside within the node distance kept.  Its time against the classify phase is the ratio printed, and its
  result is compared node by node with the classification's: the same face for every face node, the same
  distance to 1e-9 mm and the same parameters to 1e-9 of the face's box; nodes that the classification
  gives to an edge or vertex must have their direct foot point on one of that edge's or vertex's faces.

The morph runs its faces' work in ``--threads`` threads (``Settings.threads``; default the process's cores, as
``hot2cold morph`` runs it), the direct approach in one: ``--threads 1`` gives the ratio of one thread to one.

The targets of issue 36 are printed against what was reached: end to end (the morph's imports, the morph and the
write) >= 15x the direct approach at 10 k nodes and >= 60x at 100 k, with the classification identical to it;
at 1 M nodes < 15 s end to end and the classification <= 10 us a node; peak memory <= 1 GB at 100 k; Δmax at
the largest size no larger than at the smallest (and so against the exact geometry); no stage but the fit above
a third of the total.  ``--json FILE`` saves the rows; ``--show FILE`` prints the tables and targets of saved rows
(of the blades of ``--blades``).

``--doc PAGE`` (after a run, or with ``--show``) writes each blade's table into the page's block
``scale_<blade>`` (:data:`DOC_PAGES`, ``benchmarks/doc_blocks.py``); a blade whose block the page lacks is an
error::

    python benchmarks/scale.py 10000 100000 1000000 --blades thin_blade --json rows.json
    python benchmarks/scale.py --show rows.json --doc docs/benchmarks/speed.md
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

if str(Path(__file__).resolve().parent) not in sys.path:      # doc_blocks, beside this one
    sys.path.insert(0, str(Path(__file__).resolve().parent))
import doc_blocks  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: The blades measured: their STEP files.
STEPS = {"rotor37": ROOT / "sample_parts" / "rotor37_blade.step",
         "thin_blade": ROOT / "sample_parts" / "thin_blade.step"}
#: Spacing (mm) of the dense samples the cold part is measured at against the exact cold geometry.
EXACT_SPACING = 0.25
#: FE-like node spacing (mm) that gives about the number of nodes on each blade; nodes grow as 1/spacing^2.
REFERENCE = {"rotor37": (0.5, 36_129), "thin_blade": (0.5, 34_000)}
#: The blocks of the docs that ``--doc`` writes (:func:`doc_tables`: ``scale_<blade>``), each with the page it is
#: meant for; the Rotor 37 blade's table has none (its last figures are history, in ``speed_history.md``).
DOC_PAGES = {"scale_thin_blade": ROOT / "docs" / "benchmarks" / "speed.md"}


def reference(blade: str = "rotor37"):
    """``thin_blade``: the :class:`~hot2cold.testing.synthetic.UntwistField` of the twisted blade sample (a callable
    ``points (m, 3) -> displacements (m, 3)``).

    ``rotor37``: the map every resampled field is made of and every cold part is measured against: the bundled
    field's own CalculiX solution (``benchmarks/fe_fields.py``, case ``rotor37``: the same 44 478 surface nodes and
    displacements), interpolated by the quadratic triangles of its mesh's boundary
    (:class:`fe_fields.SurfaceInterpolator`), a callable ``points (m, 3) -> displacements (m, 3)``.  Continuous, as
    a field must be to be followed between any nodes: the field's local fits
    (:class:`~hot2cold.pipeline.artificial.FieldEstimator`), used before, change by up to 9e-4 mm between points
    5 µm apart where their neighbours change.  The solution is solved once (gmsh and ccx, about a minute) and
    cached by ``fe_fields``."""
    if str(ROOT / "benchmarks") not in sys.path:          # this folder, when loaded as a module
        sys.path.insert(0, str(ROOT / "benchmarks"))
    if blade == "thin_blade":
        if str(ROOT / "sample_parts") not in sys.path:
            sys.path.insert(0, str(ROOT / "sample_parts"))
        import make_samples

        return make_samples.BLADE_FIELD
    import fe_fields

    solution = fe_fields.solution(fe_fields.case("rotor37"))
    return fe_fields.SurfaceInterpolator(solution.nodes, solution.triangles, solution.displacements)


def resampled(n: int, cache: Path, blade: str = "rotor37") -> Path:
    """The field of ``blade`` (:func:`reference`) on about ``n`` FE-like surface nodes, as an ``.npz`` in
    ``cache``."""
    path = cache / f"{blade}_fe_{n}.npz"
    if path.exists():
        return path
    from hot2cold.kernel.sampling import fe_surface_nodes
    from hot2cold.kernel.step import read_step

    cache.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    spacing = REFERENCE[blade][0] * np.sqrt(REFERENCE[blade][1] / n)
    points, _ = fe_surface_nodes(read_step(STEPS[blade]), spacing)
    np.savez(path, points=points, displacements=reference(blade)(points))
    print(f"  resampled {len(points)} nodes (spacing {spacing:.3f} mm) in {time.perf_counter() - start:.0f} s",
          flush=True)
    return path


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def direct(part, points: np.ndarray, node_distance: float):
    """The direct approach: ``(owner (n,), distance (n,), uv (n, 2))`` of the nearest inside foot point."""
    from hot2cold.core.domain import Trim
    from hot2cold.kernel.project import Projector

    projector = Projector(part.kernel.faces, part.kernel.edges)
    best = np.full(len(points), np.inf)
    owner = np.full(len(points), -1)
    uv = np.full((len(points), 2), np.nan)
    for face in part.faces:
        f_uv, f_dist = projector.to_face(face.index, points)
        inside = projector.classify_exactly(face.index, f_uv) != Trim.OUTSIDE
        better = inside & (f_dist <= node_distance) & (f_dist < best)
        best[better], owner[better], uv[better] = f_dist[better], face.index, f_uv[better]
    return owner, best, uv


def compare(result, owner: np.ndarray, best: np.ndarray, uv: np.ndarray) -> dict:
    """Node-by-node comparison of the classification with the direct approach."""
    from hot2cold.core.model import Role

    part, cls = result.part, result.classification
    face = cls.role == Role.FACE
    size = np.array([f.uv_box[[1, 3]] - f.uv_box[[0, 2]] for f in part.faces])
    same_face = cls.owner[face] == owner[face]
    both = np.flatnonzero(face)[same_face]
    faces_of_edge = [set(e.faces) for e in part.edges]
    faces_of_vertex = [set() for _ in range(len(part.vertices))]
    for e in part.edges:
        for v in e.vertices:
            faces_of_vertex[v] |= set(e.faces)
    boundary_ok = all(owner[i] in (faces_of_edge if cls.role[i] == Role.EDGE else faces_of_vertex)[cls.owner[i]]
                      for i in np.flatnonzero((cls.role == Role.EDGE) | (cls.role == Role.VERTEX)))
    return {
        "face_nodes": int(face.sum()),
        "other_face": int((~same_face).sum()),
        "distance_max_diff_mm": float(np.max(np.abs(cls.distance[both] - best[both]), initial=0.0)),
        "uv_max_rel_diff": float(np.max(np.abs(cls.uv[both] - uv[both]) / size[cls.owner[both]], initial=0.0)),
        "boundary_nodes_on_a_direct_face": bool(boundary_ok),
        "ignored_here": int((~cls.used).sum()),
        "ignored_direct": int((owner < 0).sum()),
    }


def exact_error(cold: Path, blade: str = "rotor37") -> tuple[float, float, list[float]]:
    """The cold part ``cold`` (a STEP file) against the exact cold geometry: dense samples
    :data:`EXACT_SPACING` mm apart inside every face of the hot blade, each moved by :func:`reference`, and their
    distance to the cold face of the same index (``real_parts.face_errors``).  The same samples and map at
    every size, so the figures of different sizes compare.  ``(max, mean, per-face max)`` in mm."""
    from hot2cold.kernel.step import read_step

    field = reference(blade)
    import real_parts          # on sys.path since reference()

    dists = real_parts.face_errors(read_step(STEPS[blade]), read_step(cold), lambda p: p + field(p), EXACT_SPACING)
    every = np.concatenate(dists)
    return float(every.max()), float(every.mean()), [float(d.max()) for d in dists]


def one(n: int, field: Path, with_direct: bool, blade: str = "rotor37", threads: int = 1) -> dict:
    """Run one size of ``blade`` in this process, its faces' work in up to ``threads`` threads; returns its
    figures.  ``imports`` is the time to import the morph (the process's start-up before its first stage)."""
    clock = time.perf_counter()
    from hot2cold.pipeline.morph import morph
    from hot2cold.settings import Settings
    imports = time.perf_counter() - clock

    # as the command line runs it, with its cores (and its second process for the volumes where it has two)
    settings = Settings(blas_threads=1, threads=threads, kernel_process=threads > 1)
    start = time.perf_counter()
    result = morph(STEPS[blade], field, settings)
    total = time.perf_counter() - start
    with tempfile.TemporaryDirectory() as tmp:
        clock = time.perf_counter()
        result.write_step(Path(tmp) / "cold.step")
        write = time.perf_counter() - clock
        exact = exact_error(Path(tmp) / "cold.step", blade)
    t = result.report.timings
    out = {
        "blade": blade, "nodes": len(result.field.points), "threads": threads, "imports": imports,
        "load": t["read"] + t["load"], "classify": t["classify"], "fit": t["edges"] + t["faces"],
        "refine": t.get("refine", 0.0), "g1": t.get("g1", 0.0) + t.get("g2", 0.0),
        "rebuild_sew": t["rebuild"] + t["sew"], "check": t.get("check", 0.0), "report": t["report"],
        "write": write, "total": imports + total + write, "peak_mb": peak_mb(),
        "delta_max": result.report.delta_max, "exact_max": exact[0], "exact_mean": exact[1],
        "exact_face_max": exact[2], "valid": result.report.valid,
        "face_rank": [f"{f.rank}/{f.unknowns}" for f in result.faces],
    }
    if with_direct:
        from hot2cold.pipeline.load import load_part

        hot = load_part(STEPS[blade], settings)          # the morph's own part holds the cold geometry by now
        node_distance, _ = settings.lengths(hot.diagonal)
        clock = time.perf_counter()
        owner, best, uv = direct(hot, result.field.points, node_distance)
        out["direct"] = time.perf_counter() - clock
        out["compare"] = compare(result, owner, best, uv)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sizes", nargs="*", type=int, default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--blades", default=",".join(STEPS),
                        help=f"comma-separated, of {', '.join(STEPS)} (default all)")
    parser.add_argument("--direct-max", type=int, default=100_000,
                        help="run the direct approach for sizes up to this (default 100000)")
    parser.add_argument("--cache", type=Path, default=ROOT / "benchmarks" / ".cache")
    cores = len(os.sched_getaffinity(0))
    parser.add_argument("--threads", type=int, default=cores,
                        help=f"Settings.threads of the morph (default: this process's cores, {cores}, as "
                             f"hot2cold morph runs it; the direct approach runs in one)")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)        # child process: one size
    parser.add_argument("--field", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--direct", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--json", type=Path, help="save the rows here")
    parser.add_argument("--show", type=Path,
                        help="print the tables of rows saved with --json (of the blades of --blades), and stop")
    doc_blocks.add_doc_argument(parser, "each blade's table (block scale_<blade>)")
    args = parser.parse_args(argv)
    blades = args.blades.split(",")
    for blade in blades:
        if blade not in STEPS:
            parser.error(f"unknown blade {blade!r}: one of {', '.join(STEPS)}")
    if args.show:
        return show([r for r in json.loads(args.show.read_text()) if r["blade"] in blades], args.doc)
    if args.one is not None:
        print(json.dumps(one(args.one, args.field, args.direct, blades[0], args.threads)))
        return 0
    if args.doc and doc_blocks.doc_main(args.doc, table_names=[f"scale_{b}" for b in blades]):
        return 2                                # a missing block: said before the run, not after it

    rows = []
    for blade in blades:
        for n in args.sizes:
            print(f"{blade}, {n} nodes:", flush=True)
            field = resampled(n, args.cache, blade)
            child = subprocess.run([sys.executable, __file__, "--one", str(n), "--field", str(field),
                                    "--blades", blade, "--threads", str(args.threads)]
                                   + (["--direct"] if n <= args.direct_max else []),
                                   capture_output=True, text=True, check=False)
            if child.returncode != 0:
                print(child.stderr[-3000:])
                return 1
            row = json.loads(child.stdout.strip().splitlines()[-1])
            rows.append(row)
            print("  " + json.dumps(row), flush=True)
            if args.json:
                args.json.write_text(json.dumps(rows, indent=1))
    return show(rows, args.doc)


def doc_tables(rows: list[dict]) -> dict[str, str]:
    """The tables this script prints for ``rows``, by the name of their block in the docs: per blade (in the
    order of the rows) ``scale_<blade>``, its :func:`table`."""
    return {f"scale_{blade}": table(blade, [r for r in rows if r["blade"] == blade])
            for blade in dict.fromkeys(r["blade"] for r in rows)}


def show(rows: list[dict], pages=None) -> int:
    """Print the table and targets of each blade of ``rows``; with ``pages`` (``--doc``), write the tables into
    those pages' blocks too (:func:`doc_blocks.doc_main`).  Returns the exit code."""
    for blade in dict.fromkeys(r["blade"] for r in rows):
        _summary(blade, [r for r in rows if r["blade"] == blade])
    if not pages:
        return 0
    print()
    return doc_blocks.doc_main(pages, doc_tables(rows))


def _identical(c: dict) -> bool:
    """Whether the comparison ``c`` (:func:`compare`) finds the classification identical to the direct approach."""
    return (c["other_face"] == 0 and c["distance_max_diff_mm"] <= 1e-9 and c["uv_max_rel_diff"] <= 1e-9
            and c["boundary_nodes_on_a_direct_face"])


#: The columns of the table: (heading, key of a row, format).
COLUMNS = (("nodes", "nodes", "d"), ("imports", "imports", ".2f"), ("load", "load", ".2f"),
           ("classify", "classify", ".2f"), ("fit", "fit", ".2f"), ("refine", "refine", ".2f"), ("G1", "g1", ".2f"),
           ("rebuild + sew", "rebuild_sew", ".2f"), ("check", "check", ".2f"), ("report", "report", ".2f"),
           ("write", "write", ".2f"), ("total", "total", ".2f"), ("peak MB", "peak_mb", ".0f"),
           ("classify us/node", "classify_us", ".1f"), ("direct", "direct", ".1f"), ("ratio", "ratio", ".1f"),
           ("Δmax mm", "delta_max", ".2e"), ("exact max mm", "exact_max", ".2e"))


def _cells(r: dict) -> dict:
    """A row's figures with the derived ones: classification per node (us) and the direct approach's time over
    the morph's end to end (``ratio``, NaN without it)."""
    return {**r, "classify_us": 1e6 * r["classify"] / r["nodes"], "direct": r.get("direct", float("nan")),
            "ratio": r["direct"] / r["total"] if "direct" in r else float("nan")}


def table(blade: str, rows: list[dict]) -> str:
    """The markdown table of ``rows`` (one blade's sizes; seconds unless said)."""
    lines = ["| blade | " + " | ".join(h for h, _, _ in COLUMNS) + " |", "|---|" + "---:|" * len(COLUMNS)]
    for r in rows:
        c = _cells(r)
        lines.append(f"| {blade} | " + " | ".join("–" if isinstance(c[k], float) and np.isnan(c[k])
                                                  else format(c[k], f) for _, k, f in COLUMNS) + " |")
    return "\n".join(lines)


def _summary(blade: str, rows: list[dict]) -> None:
    """Print the table of ``rows`` (one blade's sizes) and the targets."""
    print()
    print(f"{blade} (the morph in {rows[0]['threads'] if rows else '?'} threads; s unless said; total: imports, "
          f"the morph and the write, end to end; ratio: the direct approach over that total):")
    print(table(blade, rows))
    print()
    for r in rows:
        print(f"{r['nodes']} nodes: Δmax {r['delta_max']:.3g} mm at the nodes, {r['exact_max']:.3g} mm (mean "
              f"{r['exact_mean']:.3g}) against the exact geometry (per face "
              f"{' '.join(f'{x:.2g}' for x in r['exact_face_max'])}), valid {r['valid']}, face fits rank/unknowns "
              f"{' '.join(r['face_rank'])}")
    for r in rows:
        if "compare" in r:
            print(f"{r['nodes']} nodes, against the direct approach: {json.dumps(r['compare'])}")
    print()
    by_size = {r["nodes"]: r for r in rows}

    def nearest(n):
        return by_size[min(by_size, key=lambda k: abs(k - n))] if by_size else None

    def verdict(ok: bool) -> str:
        return "met" if ok else "MISSED"

    r10, r100, r1m = nearest(10_000), nearest(100_000), nearest(1_000_000)
    for r, size, least in ((r10, 10_000, 15), (r100, 100_000, 60)):
        if r is not None and "direct" in r and 0.5 * size < r["nodes"] < 2 * size:
            ratio = r["direct"] / r["total"]
            print(f"target (issue 36): {r['nodes']} nodes end to end >= {least}x the direct approach: {ratio:.1f}x "
                  f"{verdict(ratio >= least)} ({r['total']:.2f} s against {r['direct']:.1f} s); classification "
                  f"identical: {'yes' if _identical(r['compare']) else 'NO'}")
    if r100 is not None and 50_000 < r100["nodes"] < 200_000:
        print(f"target: {r100['nodes']} nodes peak memory <= 1024 MB: {r100['peak_mb']:.0f} MB "
              f"{verdict(r100['peak_mb'] <= 1024)}")
    if r1m is not None and r1m["nodes"] > 500_000:
        per = 1e6 * r1m["classify"] / r1m["nodes"]
        print(f"target: {r1m['nodes']} nodes end to end < 15 s: {r1m['total']:.1f} s {verdict(r1m['total'] < 15)}; "
              f"classification <= 10 us a node: {per:.1f} us {verdict(per <= 10)}; peak {r1m['peak_mb']:.0f} MB")
    if len(rows) > 1:
        first, last = rows[0], rows[-1]
        print(f"target: Δmax at {last['nodes']} nodes no larger than at {first['nodes']}: {last['delta_max']:.3g} "
              f"against {first['delta_max']:.3g} mm {verdict(last['delta_max'] <= first['delta_max'])}; against "
              f"the exact geometry {last['exact_max']:.3g} against {first['exact_max']:.3g} mm "
              f"{verdict(last['exact_max'] <= first['exact_max'])}")
    for r in rows:
        stages = {k: r[k] for k in ("imports", "load", "classify", "refine", "g1", "rebuild_sew", "check", "report",
                                    "write")}
        worst = max(stages, key=stages.get)
        print(f"{r['nodes']} nodes: the largest stage other than the fit is {worst}, {stages[worst]:.2f} s, "
              f"{100 * stages[worst] / r['total']:.0f} % of {r['total']:.2f} s "
              f"({verdict(stages[worst] <= r['total'] / 3)} at most a third)")


if __name__ == "__main__":
    sys.exit(main())
