"""The B-spline conversion of real parts: around the faces it keeps (the tool's way) against the whole part at
once (``BRepBuilderAPI_NurbsConvert`` on every face), measured in one run.

    python benchmarks/conversion.py [--parts NAME,...] [--repeat N] [--max-faces F] [--json F]

For each corpus and sample part (as ``benchmarks/real_parts.py`` finds them) of at most ``--max-faces`` faces:
its faces, the B-spline faces and those of them the conversion keeps out of the kernel's, the median seconds of
``kernel.conversion.to_bspline`` both ways over ``--repeat`` runs taken alternately in this process (both see
the same load), their ratio, whether each result is a valid shape (``BRepCheck_Analyzer``), and the largest
distance between an edge's curve and its face through a pcurve, as a share of the edge's tolerance, both ways
(above 1: the edge is farther from a face than it says).  Last, the totals over the parts.
"""
from __future__ import annotations

import argparse
import json
import logging
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))     # real_parts beside this one

from OCP.BRep import BRep_Tool                                   # noqa: E402
from OCP.BRepCheck import BRepCheck_Analyzer                     # noqa: E402
from OCP.Geom import Geom_BSplineSurface                         # noqa: E402
from OCP.TopAbs import TopAbs_FACE, TopAbs_FORWARD               # noqa: E402
from OCP.TopLoc import TopLoc_Location                           # noqa: E402
from OCP.TopoDS import TopoDS                                    # noqa: E402

from hot2cold.errors import Hot2ColdError                        # noqa: E402
from hot2cold.kernel import conversion, kept_faces               # noqa: E402
from hot2cold.kernel.explore import edges_of, shape_map          # noqa: E402
from hot2cold.kernel.step import read_step                       # noqa: E402


class _GivenUp(logging.Handler):
    """Counts the faces the conversion would keep yet converts with the others (its debug lines say so)."""

    def __init__(self):
        super().__init__(logging.DEBUG)
        self.faces = 0

    def emit(self, record):
        self.faces += "converted with the others" in record.getMessage()


def whole_part_at_once(shape):
    """``to_bspline`` as it converts a part that keeps no face: ``BRepBuilderAPI_NurbsConvert`` on all of it."""
    around = conversion.convert_around
    conversion.convert_around = lambda copy: None
    try:
        return conversion.to_bspline(shape)
    finally:
        conversion.convert_around = around


def worst_gap(shape) -> float:
    """The largest distance between an edge's curve and a face through its pcurve, at 23 parameters of each
    edge use, as a share of the edge's tolerance: where ``BRepCheck`` looks (its 23 control points).  The
    kernel's own, denser measure (``tolerances._gap``, 8 points a knot) finds edges of parts as read farther
    from their faces between those points (Wrist_Roll_Pitch_08i: 94 times the tolerance as read and around the
    kept faces, 59 times after the whole-part conversion, which grows some tolerances)."""
    worst = 0.0
    for face in shape_map(shape, TopAbs_FACE):
        face = TopoDS.Face_s(face.Oriented(TopAbs_FORWARD))
        face_location = TopLoc_Location()
        surface = BRep_Tool.Surface_s(face, face_location)
        for edge in edges_of(face):
            if BRep_Tool.Degenerated_s(edge):
                continue
            first, last = BRep_Tool.Range_s(edge, face)
            pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
            curve_location = TopLoc_Location()
            curve = BRep_Tool.Curve_s(edge, curve_location, 0.0, 0.0)
            gap = max(surface.Value(uv.X(), uv.Y()).Transformed(face_location.Transformation()).Distance(
                curve.Value(t).Transformed(curve_location.Transformation()))
                for t in np.linspace(first, last, 23) for uv in (pcurve.Value(t),))
            worst = max(worst, gap / BRep_Tool.Tolerance_s(edge))
    return worst


def measure(path: Path, repeat: int, shape=None) -> dict:
    """One part's row (``shape``: the part as read from ``path``, if read already)."""
    shape = read_step(path) if shape is None else shape
    faces = shape_map(shape, TopAbs_FACE)
    row = {"part": path.stem, "faces": len(faces),
           "bspline_faces": sum(isinstance(BRep_Tool.Surface_s(f), Geom_BSplineSurface) for f in faces),
           "kept": sum(kept_faces._kept(f) for f in shape_map(conversion._turned_copy(shape), TopAbs_FACE))}
    times = {"around": [], "whole": []}
    results = {}
    for _ in range(repeat):
        for way, convert in (("around", conversion.to_bspline), ("whole", whole_part_at_once)):
            given_up = _GivenUp()
            logging.getLogger(kept_faces.__name__).addHandler(given_up)
            start = time.perf_counter()
            results[way] = convert(shape)
            times[way].append(time.perf_counter() - start)
            logging.getLogger(kept_faces.__name__).removeHandler(given_up)
            if way == "around":
                given_up_faces = given_up.faces
    row["kept"] -= given_up_faces               # the last run's: every run gives up the same faces
    for way in times:
        row[f"{way}_s"] = statistics.median(times[way])
        row[f"{way}_valid"] = BRepCheck_Analyzer(results[way]).IsValid()
        row[f"{way}_gap"] = worst_gap(results[way])
    row["ratio"] = row["around_s"] / row["whole_s"]
    return row


def main() -> int:
    from real_parts import parts

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", help="comma-separated part names (file stems; default: all)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--max-faces", type=int, default=300)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    logging.getLogger(kept_faces.__name__).setLevel(logging.DEBUG)      # its faces given up, counted
    chosen = set(args.parts.split(",")) if args.parts else None
    rows = []
    print(f"{'part':40} {'faces':>5} {'bspl':>5} {'kept':>5} {'around s':>9} {'whole s':>8} {'ratio':>6} "
          f"{'valid':>6} {'gap/tol':>15}")
    for path in parts():
        if chosen is not None and path.stem not in chosen:
            continue
        try:
            shape = read_step(path)
            if len(shape_map(shape, TopAbs_FACE)) > args.max_faces:
                continue
            row = measure(path, args.repeat, shape)
        except Hot2ColdError as exc:
            print(f"{path.stem:40} refused: {exc}")
            continue
        rows.append(row)
        print(f"{row['part'][:40]:40} {row['faces']:5d} {row['bspline_faces']:5d} {row['kept']:5d} "
              f"{row['around_s']:9.2f} {row['whole_s']:8.2f} {row['ratio']:6.2f} "
              f"{'ok' if row['around_valid'] and row['whole_valid'] else 'NO':>6} "
              f"{row['around_gap']:7.2g}/{row['whole_gap']:<7.2g}", flush=True)
    around, whole = sum(r["around_s"] for r in rows), sum(r["whole_s"] for r in rows)
    print(f"{len(rows)} parts: {around:.1f} s around the kept faces, {whole:.1f} s the whole part at once "
          f"(ratio {around / whole:.2f}); {sum(r['kept'] for r in rows)} of {sum(r['bspline_faces'] for r in rows)} "
          f"B-spline faces kept; {sum(not (r['around_valid'] and r['whole_valid']) for r in rows)} parts invalid "
          f"either way; largest gap / tolerance {max(r['around_gap'] for r in rows):.3g} around, "
          f"{max(r['whole_gap'] for r in rows):.3g} whole")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
