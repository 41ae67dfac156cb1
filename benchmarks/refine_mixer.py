"""The mixer segment's planar exit face under --tolerance: refined into a valid closed solid with its volume.

Run from the repository: ``python benchmarks/refine_mixer.py [TOLERANCE ...]`` (default 1e-2; each run takes
about 40 s on 2 cores).  For the plain fit and each tolerance it prints the per-face table and refinement
lines of the report, the time of each stage, the kernel's check of the cold solid (every BRepCheck status
that is not NoError, on the solid's faces and on its edges in the context of each face), the largest
distance between each edge of the exit face and the face, sampled at 2000 points (the sew samples 51), and
the cold volume two ways: the report's (BRepGProp's adaptive integration,
:func:`hot2cold.kernel.validity.volume`; the default Gauss rule before issue 14) and a triangulation of the
cold solid (meaningful only where the faces meet their edges: the plain fit's 0.7 mm gaps spoil it); against
the reference, the triangulated hot solid moved by the field (the local
estimate of :class:`hot2cold.pipeline.artificial.FieldEstimator` from the foot points of every node).

Measured (2 cores, other jobs running; the stage times vary by a factor 3 with the load):

    plain:  face 5 2x2, Δmax 0.173 mm, gaps 0.70 mm; valid; volume 193 656 (adaptive 193 656) mm^3
    1e-2:   face 5 2x2 -> 5x5, degree 1x1 -> 3x3, one round, Δmax 2.08e-3 mm; gaps 8.2e-3 mm sewn, 8.2e-3 at
            2000 points (tolerance 1.2e-2); valid; volume 193 871 (adaptive 193 871, triangulated 193 853);
            reference 193 857 mm^3; refine stage 2.2 s
    1e-3:   also the lobed walls 48x20 -> 59x22 and 49x22, the side faces 4x20 -> 4x22 and their edges, one
            round each (then too few nodes to halve a span further): Δmax 2.6e-3 mm, not met (exit 5);
            valid; volume 193 869 mm^3; refine stage 86 s

The exit face is face 5: a plane (a 2x2 bilinear net over a box of 276 x 79 mm) trimmed to a band 2.5 mm
wide along the two lobed 48-pole edges 2 and 9.  Without refinement it cannot bend (Δmax 0.17 mm, gaps of
0.7 mm to its cold edges).  Refined by knot insertion alone (before this benchmark's commit) it became a
17x17 bilinear net whose kinks could not follow the lobed edges: the true gap (0.015 mm) was twice the sewn
tolerance, BRepCheck reported the edge's curve off the face (InvalidCurveOnSurface, hence the face
UnorientableShape), and the default BRepGProp integration over the many-kinked, wildly extrapolated
trimmed-away part gave 201 592 mm^3 for about 193 860.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.BRepMesh import BRepMesh_IncrementalMesh
from OCP.BRepTools import BRepTools
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_REVERSED
from OCP.TopExp import TopExp_Explorer
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS

from hot2cold.pipeline.morph import morph
from hot2cold.settings import Settings

SAMPLES = Path(__file__).resolve().parent.parent / "sample_parts"
EXIT_FACE = 5


def mesh_volume(shape, deflection: float = 0.003, move=None) -> float:
    """Volume (mm^3) of the triangulated ``shape``, its vertices moved by ``move(points)`` if given."""
    BRepTools.Clean_s(shape)
    BRepMesh_IncrementalMesh(shape, deflection, False, 0.1, True)
    total = 0.0
    explorer = TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        face = TopoDS.Face_s(explorer.Current())
        explorer.Next()
        loc = TopLoc_Location()
        tri = BRep_Tool.Triangulation_s(face, loc)
        trsf = loc.Transformation()
        pts = np.array([tri.Node(i).Transformed(trsf).Coord() for i in range(1, tri.NbNodes() + 1)])
        if move is not None:
            pts = pts + move(pts)
        t = np.array([tri.Triangle(i).Get() for i in range(1, tri.NbTriangles() + 1)]) - 1
        if face.Orientation() == TopAbs_REVERSED:
            t = t[:, [0, 2, 1]]
        total += np.einsum("ij,ij->i", pts[t[:, 0]], np.cross(pts[t[:, 1]], pts[t[:, 2]])).sum() / 6.0
    return float(total)


def statuses(shape, faces) -> list[str]:
    """Every BRepCheck status that is not NoError: on the faces, and on each face's edges in its context."""
    analyzer = BRepCheck_Analyzer(shape)
    out = []
    for k, face in enumerate(faces):
        for s in analyzer.Result(face).Status():
            if s.name != "BRepCheck_NoError":
                out.append(f"face {k}: {s.name}")
        explorer = TopExp_Explorer(face, TopAbs_EDGE)
        while explorer.More():
            for s in analyzer.Result(explorer.Current()).StatusOnShape(face):
                if s.name != "BRepCheck_NoError":
                    out.append(f"face {k}, an edge: {s.name}")
            explorer.Next()
    return out


def dense_gap(edge, face, n: int = 2000) -> float:
    c3d, on_face = BRepAdaptor_Curve(edge), BRepAdaptor_Curve(edge, face)
    t = np.linspace(c3d.FirstParameter(), c3d.LastParameter(), n)
    return max(c3d.Value(x).Distance(on_face.Value(x)) for x in t)


def run(tolerance: float | None, reference: dict) -> None:
    start = time.perf_counter()
    result = morph(SAMPLES / "mixer_segment.step", SAMPLES / "mixer_segment_field.npz",
                   Settings(tolerance=tolerance, blas_threads=1), check=False)    # an invalid part is reported
    seconds = time.perf_counter() - start
    report, part = result.report, result.part
    print(f"\n=== tolerance {tolerance}: {seconds:.1f} s", {k: round(v, 2) for k, v in report.timings.items()})
    print(report.table())
    kernel, cold = part.kernel, result.cold_kernel
    bad = statuses(cold.shape, cold.faces)
    print("BRepCheck:", "valid" if report.valid else "INVALID", "; ".join(bad))
    for use in part.faces[EXIT_FACE].uses:
        edge = cold.edges[use.edge]
        print(f"  exit-face edge {use.edge}: gap sewn {report.edges[use.edge].gap:.2e} mm, at 2000 points "
              f"{dense_gap(edge, cold.faces[EXIT_FACE]):.2e} mm, edge tolerance {BRep_Tool.Tolerance_s(edge):.2e}")
    if "estimator" not in reference:
        from hot2cold.pipeline.artificial import FieldEstimator
        used = result.classification.used
        estimator = FieldEstimator(result.classification.foot[used], result.field.displacements[used])
        reference["estimator"] = estimator
        reference["cold"] = mesh_volume(kernel.hot, move=estimator)
        reference["hot"] = mesh_volume(kernel.hot)
    print(f"  volume hot: report {report.solids[0].volume_hot:.1f}, triangulated {reference['hot']:.1f} mm^3")
    print(f"  volume cold: report {report.solids[0].volume_cold:.1f}, "
          f"triangulated {mesh_volume(cold.shape):.1f}; reference (hot mesh moved by the field) "
          f"{reference['cold']:.1f} mm^3")


def main(argv: list[str]) -> None:
    tolerances = [float(x) for x in argv] or [1e-2]
    reference: dict = {}
    for tolerance in [None, *tolerances]:
        run(tolerance, reference)


if __name__ == "__main__":
    main(sys.argv[1:])
