"""Build a lobed exhaust-mixer segment as ``mixer_segment.step``.

Run from anywhere: ``python sample_parts/make_mixer.py``.  The output is deterministic (fixed STEP header).

Coordinates: millimetres; the mixer axis is the x axis, the flow goes towards +x.  A point at axial position
``x``, radius ``r`` and angle ``theta`` is ``(x, y, z) = (x, r cos theta, r sin theta)``.

The wall's mid-surface has the radius ``r(theta, x) = R0 + a(x) cos(N theta)``: ``N = 12`` lobes round the
full circle, ``R0 = 300``, and the lobe amplitude ``a(x) = A s^2 (3 - 2 s)``, ``s = x / L``, grows smoothly
(zero slope at both ends) from 0 at the inlet (x = 0) to ``A = 25`` at the exit (x = L = 250).  The wall is
``T = 2.5`` thick radially: outer surface ``r + T/2``, inner surface ``r - T/2``.  The segment is two lobes
wide, ``theta`` in ``[-pi/N, 3 pi/N]``, cut through the lobe troughs by two planes through the axis.

Construction: ``N_SECTIONS`` planar sections x = const, each a closed wire of 4 edges (outer lobed curve,
side line, inner lobed curve, side line).  Each lobed curve is a least-squares clamped cubic B-spline on
``SPANS`` uniform knot spans in theta (the same knots in every section); the side lines are degree-1
B-splines.  ``BRepOffsetAPI_ThruSections`` (smooth, max degree 3, compatibility check off) lofts them into
one solid: outer and inner lobed B-spline faces, two planar side faces as B-splines, and planar inlet and
exit faces.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from scipy.interpolate import BSpline

from OCP.BRep import BRep_Tool
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeWire
from OCP.BRepOffsetAPI import BRepOffsetAPI_ThruSections
from OCP.Geom import Geom_BSplineCurve, Geom_BSplineSurface
from OCP.gp import gp_Pnt
from OCP.Message import Message, Message_Gravity
from OCP.TColgp import TColgp_Array1OfPnt
from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal
from OCP.TopAbs import TopAbs_FACE, TopAbs_VERTEX
from OCP.TopoDS import TopoDS, TopoDS_Solid

from hot2cold.kernel.validity import check_solids
from hot2cold.kernel.explore import shape_map

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from make_samples import check_solid, read_step, write_step  # noqa: E402

N_LOBES = 12
R0 = 300.0               # mm, mean radius of the wall's mid-surface
AMPLITUDE = 25.0         # mm, lobe amplitude at the exit
LENGTH = 250.0           # mm
THICKNESS = 2.5          # mm, radial wall thickness
THETA = (-math.pi / N_LOBES, 3.0 * math.pi / N_LOBES)   # rad, the segment's angular range (two lobes)
SPANS = 45               # knot spans of a lobed section curve in theta: 48 poles
N_SECTIONS = 26          # sections along x (the loft fits them to 1e-6 mm with 20 poles along x)
N_FIT = 600              # points per lobed section curve in its least-squares fit


def amplitude(x: np.ndarray) -> np.ndarray:
    """Lobe amplitude ``(m,)`` (mm) at axial positions ``x (m,)`` (mm): 0 at the inlet, ``AMPLITUDE`` at the
    exit, zero slope at both."""
    s = np.clip(np.asarray(x, float) / LENGTH, 0.0, 1.0)
    return AMPLITUDE * s * s * (3.0 - 2.0 * s)


def wall_radius(theta: np.ndarray, x: np.ndarray, side: float) -> np.ndarray:
    """Radius ``(m,)`` (mm) of the outer (``side`` = +1) or inner (-1) wall surface at ``theta (m,)`` (rad),
    ``x (m,)`` (mm)."""
    return R0 + side * THICKNESS / 2.0 + amplitude(x) * np.cos(N_LOBES * theta)


def _curve(poles: np.ndarray, knots: np.ndarray, mults: list[int], degree: int) -> Geom_BSplineCurve:
    array = TColgp_Array1OfPnt(1, len(poles))
    for i, p in enumerate(poles, start=1):
        array.SetValue(i, gp_Pnt(*map(float, p)))
    k = TColStd_Array1OfReal(1, len(knots))
    m = TColStd_Array1OfInteger(1, len(knots))
    for i, (a, b) in enumerate(zip(knots, mults), start=1):
        k.SetValue(i, float(a))
        m.SetValue(i, int(b))
    return Geom_BSplineCurve(array, k, m, degree)


def lobed_curve(x: float, side: float) -> tuple[Geom_BSplineCurve, float]:
    """The outer (``side`` = +1) or inner (-1) wall curve of the section at ``x`` (mm), theta increasing: a
    clamped cubic B-spline on ``SPANS`` uniform spans, least squares through ``N_FIT`` points uniform in theta.

    Returns the curve and its largest radial deviation (mm) from the exact wall on a 4x finer theta grid.
    """
    flat = np.concatenate([[0.0] * 3, np.arange(SPANS + 1.0), [float(SPANS)] * 3])   # full knot vector
    t = np.linspace(0.0, SPANS, N_FIT)
    theta = THETA[0] + (THETA[1] - THETA[0]) * t / SPANS
    r = wall_radius(theta, np.full_like(theta, x), side)
    points = np.column_stack([np.full_like(theta, x), r * np.cos(theta), r * np.sin(theta)])
    design = BSpline.design_matrix(t, flat, 3).toarray()
    poles = np.linalg.solve(design.T @ design, design.T @ points)
    t_check = np.linspace(0.0, SPANS, 4 * N_FIT)
    fit = BSpline(flat, poles, 3)(t_check)
    theta_check = THETA[0] + (THETA[1] - THETA[0]) * t_check / SPANS
    error = np.abs(np.hypot(fit[:, 1], fit[:, 2]) - wall_radius(theta_check, np.full_like(t_check, x), side))
    knots = np.arange(SPANS + 1.0)
    mults = [4] + [1] * (SPANS - 1) + [4]
    return _curve(poles, knots, mults, 3), float(error.max())


def line(p0: gp_Pnt, p1: gp_Pnt) -> Geom_BSplineCurve:
    """The straight segment from ``p0`` to ``p1`` as a degree-1 B-spline."""
    return _curve(np.array([p0.Coord(), p1.Coord()]), np.array([0.0, 1.0]), [2, 2], 1)


def section_wire(x: float):
    """The closed section at ``x`` (mm): outer curve, side line, inner curve (reversed), side line."""
    outer, e0 = lobed_curve(x, +1.0)
    inner, e1 = lobed_curve(x, -1.0)
    inner = inner.Reversed()
    wire = BRepBuilderAPI_MakeWire()
    for curve in (outer, line(outer.EndPoint(), inner.StartPoint()), inner,
                  line(inner.EndPoint(), outer.StartPoint())):
        wire.Add(BRepBuilderAPI_MakeEdge(curve).Edge())
    return wire.Wire(), max(e0, e1)


def make_mixer() -> tuple[TopoDS_Solid, float]:
    """The lofted segment and the largest radial fit error (mm) of its section curves."""
    maker = BRepOffsetAPI_ThruSections(True, False, 1e-6)
    maker.CheckCompatibility(False)
    maker.SetMaxDegree(3)
    error = 0.0
    for x in np.linspace(0.0, LENGTH, N_SECTIONS):
        wire, e = section_wire(float(x))
        maker.AddWire(wire)
        error = max(error, e)
    maker.Build()
    if not maker.IsDone():
        raise RuntimeError("the loft failed")
    return TopoDS.Solid_s(maker.Shape()), error


def surface_deviation(surface: Geom_BSplineSurface, side: float, n: int = 120) -> float:
    """Largest radial distance (mm) of a lobed face's surface from the exact wall, on an ``n x n`` grid."""
    u0, u1, v0, v1 = surface.Bounds()
    worst = 0.0
    for u in np.linspace(u0, u1, n):
        for v in np.linspace(v0, v1, n):
            x, y, z = surface.Value(float(u), float(v)).Coord()
            theta = math.atan2(z, y)
            worst = max(worst, abs(math.hypot(y, z) - wall_radius(np.array([theta]), np.array([x]), side)[0]))
    return worst


def describe(face) -> tuple[str, str, str]:
    """``(role, kind, net)`` of a face of the segment: role ``outer wall``, ``inner wall``, ``side cut``,
    ``inlet`` or ``exit``; kind the surface's type name; net its poles, degrees and knot spans."""
    surface = BRep_Tool.Surface_s(face)
    kind = surface.DynamicType().Name()
    if not isinstance(surface, Geom_BSplineSurface):
        x = BRep_Tool.Pnt_s(shape_map(face, TopAbs_VERTEX)[0]).X()
        return ("inlet" if x < LENGTH / 2 else "exit"), kind, ""
    net = (f"{surface.NbUPoles()} x {surface.NbVPoles()} poles, degree {surface.UDegree()} x "
           f"{surface.VDegree()}, {surface.NbUKnots() - 1} x {surface.NbVKnots() - 1} knot spans")
    if surface.NbUKnots() == 2:   # one knot span across: a lofted side line
        return "side cut", kind, net
    u0, u1, v0, v1 = surface.Bounds()
    x, y, z = surface.Value((u0 + u1) / 2, (v0 + v1) / 2).Coord()
    mid = wall_radius(np.array([math.atan2(z, y)]), np.array([x]), 0.0)[0]
    return ("outer wall" if math.hypot(y, z) > mid else "inner wall"), kind, net


def main() -> int:
    Message.DefaultMessenger_s().Printers().First().SetTraceLevel(Message_Gravity.Message_Fail)
    shape, fit_error = make_mixer()
    check_solid(shape, "mixer segment")
    step = HERE / "mixer_segment.step"
    write_step(shape, step, "hot2cold sample_parts/make_mixer.py")
    shape = read_step(step)
    check_solid(shape, "mixer segment (read back)")
    check = check_solids(shape)[0]
    print(f"{step.name}: 1 solid, BRepCheck valid {check.valid}, {check.free_edges} free edges, "
          f"{check.faces} faces, volume {check.volume:.0f} mm^3")
    for k, face in enumerate(shape_map(shape, TopAbs_FACE)):
        role, kind, net = describe(face)
        text = f"  face {k} {role:10s} {kind}" + (f", {net}" if net else "")
        if role in ("outer wall", "inner wall"):
            dev = surface_deviation(BRep_Tool.Surface_s(face), 1.0 if role == "outer wall" else -1.0)
            text += f"; <= {dev * 1e3:.2f} um from the exact wall"
        print(text)
    print(f"  section curves: <= {fit_error * 1e3:.3f} um radial fit error; R0 {R0:g} mm, {N_LOBES} lobes, "
          f"{math.degrees(THETA[1] - THETA[0]):g} deg wide, length {LENGTH:g} mm, wall {THICKNESS:g} mm, "
          f"exit amplitude {AMPLITUDE:g} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
