"""Write ``thin_blade.step``: a twisted compressor-like blade with thin leading and trailing edges, each
inside one face, as a blade-design tool writes them (a benchmark part of ``benchmarks/scale.py``).

Run from anywhere: ``python sample_parts/make_thin_blade.py``.  The output is deterministic (fixed STEP header
time stamp).

The corpus's thin blade, ``corpus/real_parts/rotor67.step``, is a fluid passage with the blade as a hole, and
its two blade faces end at the leading and trailing edges (smallest radius of curvature 0.058 mm, at their
borders), so no face there wraps round a thin edge.  This blade does: it is lofted
(``BRepOffsetAPI_ThruSections``, smooth, cubic along the span) through 6 sections of
:func:`make_samples.airfoil` from z = 0 to 100 mm, chord 40 -> 36 mm, 5 % thickness, skew 0.2, twisted by 30
degrees.  Each section is one periodic cubic B-spline interpolating 160 points at uniform angles theta (so
clustered in x at both edges, as design tools cluster them), split at mid-chord into two faces: the leading
edge wrapped by the one (theta in [-pi/2, pi/2]), the trailing edge by the other.  Two planar caps close it.
Leading-edge radius about 0.07 mm at the hub, trailing-edge radius about 0.03 mm (the script prints the
smallest radii of curvature it measures).
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepOffsetAPI import BRepOffsetAPI_ThruSections
from OCP.Message import Message, Message_Gravity
from OCP.TopoDS import TopoDS, TopoDS_Solid

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from make_samples import check_solid, read_step, section_curve, split_wire, write_step  # noqa: E402

from hot2cold.kernel.sampling import face_list  # noqa: E402

N_SECTIONS = 6
SPAN = 100.0
N_SECTION_POINTS = 160
THICKNESS = 0.05
SKEW = 0.2


def section(z: float):
    """The section wire at height ``z`` (mm): 2 B-spline edges (leading-edge half, trailing-edge half)."""
    chord = 40.0 - 4.0 * z / SPAN
    twist = math.radians(-15.0 + 30.0 * z / SPAN)
    theta = -math.pi / 2 + 2.0 * math.pi * np.arange(N_SECTION_POINTS) / N_SECTION_POINTS
    curve = section_curve(z, chord, twist, theta, thickness=THICKNESS, skew=SKEW)
    return split_wire(curve, [-math.pi / 2, math.pi / 2, 3 * math.pi / 2])


def make_thin_blade() -> TopoDS_Solid:
    loft = BRepOffsetAPI_ThruSections(True, False, 1e-6)
    loft.CheckCompatibility(False)
    loft.SetMaxDegree(3)
    for k in range(N_SECTIONS):
        loft.AddWire(section(SPAN * k / (N_SECTIONS - 1)))
    loft.Build()
    return TopoDS.Solid_s(loft.Shape())


def smallest_radii(path: Path) -> list[float]:
    """The smallest radius of curvature (mm) of every face of the part at ``path``, on a 401 x 401 grid."""
    from hot2cold.core.bspline import surface_jet, surface_normals
    from hot2cold.pipeline.load import load_part
    from hot2cold.settings import Settings

    radii = []
    for face in load_part(path, Settings()).faces:
        u0, u1, v0, v1 = face.uv_box
        uu, vv = (g.ravel() for g in np.meshgrid(np.linspace(u0, u1, 401), np.linspace(v0, v1, 401)))
        _, su, sv, suu, suv, svv = surface_jet(face.surface, uu, vv)
        n = surface_normals(face.surface, uu, vv)
        e, f, g = (su * su).sum(1), (su * sv).sum(1), (sv * sv).sum(1)
        l_, m_, n_ = (suu * n).sum(1), (suv * n).sum(1), (svv * n).sum(1)
        det = e * g - f * f
        h, k = (l_ * g - 2 * m_ * f + n_ * e) / (2 * det), (l_ * n_ - m_ * m_) / det
        largest = np.abs(h) + np.sqrt(np.maximum(h * h - k, 0.0))
        radii.append(float(1.0 / np.nanmax(largest)) if np.nanmax(largest) > 0 else math.inf)
    return radii


def main() -> int:
    Message.DefaultMessenger_s().Printers().First().SetTraceLevel(Message_Gravity.Message_Fail)
    step = HERE / "thin_blade.step"
    shape = make_thin_blade()
    check_solid(shape, "thin_blade")
    write_step(shape, step, author="hot2cold sample_parts/make_thin_blade.py")
    check_solid(read_step(step), "thin_blade (read back)")
    kinds = [BRep_Tool.Surface_s(f).DynamicType().Name() for f in face_list(read_step(step))]
    print(f"{step.name}: {len(kinds)} faces: {', '.join(kinds)}")
    print("smallest radius of curvature per face (mm): "
          + ", ".join(f"{r:.3g}" for r in smallest_radii(step)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
