"""Build the NASA Rotor 37 compressor blade, trimmed by its hub and shroud, as ``rotor37_blade.step``.

Run from anywhere: ``python sample_parts/make_rotor37.py [DATA_FOLDER]``.  ``DATA_FOLDER`` (default
``/work/shared/data/nasa_rotor37``) holds the report's tables IV and V as ``rotor37geometry.dat`` (13 stream
surfaces hub -> shroud, rows ``J Z R THETA1 THETA2``, cm and radians) and ``rotor37hub-shroud.dat`` (hub and
shroud flow-path lines, cm).  The output is deterministic (fixed STEP header time stamp).

Coordinates: millimetres (the tables' cm x 10).  The machine axis is the z axis; a point at axial position
``Z``, radius ``R`` and angle ``theta`` is ``(x, y, z) = (R sin theta, R cos theta, Z)``, so theta = 0 is the
+y half plane and theta grows towards +x.

Construction (after Gaun et al., GT2014-26683, Fig. 6):

1. Sections.  Each stream surface's rows give a closed section: THETA1 side from the leading edge (the
   file's J = 1, both angles equal) to the trailing edge (J = 100), then the THETA2 side back.  The data
   already has rounded noses (about 0.25 mm radius at the hub) with points clustered there.  A periodic
   cubic spline through the points (chord-length parameters) is the reference curve.  The leading- and
   trailing-edge tips are the section's extreme points along its chord; the leading-edge (trailing-edge)
   face starts as the band of ``LE_HALF_ARC`` (``TE_HALF_ARC``) mm of arc either side of its tip.  Each
   section is then approximated by least squares with one periodic cubic B-spline on ``sum(SPANS)`` uniform
   knot spans, the band ends falling on knots; the first parameters blend arc length and tangent turning
   within a piece, and parameter correction follows (the band ends drift a little: the faces come out about
   1.9 and 1.6 mm wide).  Cut at the band ends, every section is 4 clamped cubic pieces (leading edge,
   suction side = THETA1 side, trailing edge, pressure side = THETA2 side) with 9, 27, 8 and 28 poles, the
   same knots in every section, and C2 joints.  The THETA1 side is taken as the suction side because the
   camber line bulges towards +theta (checked in every section); the rotor then turns towards -theta (an
   inference: the tables do not say).
2. Extension.  Stream surfaces are numbered here from 0 (the file's SURFACE NUMBER minus 1).  The tip
   section (11) lies only 0.36 mm (the tip clearance) below the blade/shroud intersection (12) and is left
   out.  Below the hub and above the shroud one more section each is
   added: every pole of the hub (shroud) section is moved on, along the line from the neighbouring
   section's pole, onto a plane placed so that the whole extra section clears the hub (shroud) line by
   ``CLEARANCE`` mm; the extra sections are planar, so the lofted solid gets planar caps.
3. Loft.  ``BRepOffsetAPI_ThruSections`` (smooth, max degree 3, compatibility check off: the sections
   already match edge by edge) makes a solid with 4 B-spline aerofoil faces, tangent-continuous across
   the four span-wise edges, and two planar caps.
4. Trim.  The annulus is the hub and shroud lines (cubic B-splines interpolating the table points in the
   meridional plane) closed by the inlet and exit planes, revolved about the z axis (profile in the
   theta = pi half plane, so the seam is far from the blade).  ``BRepAlgoAPI_Common`` of blade and annulus
   leaves one solid: the 4 trimmed aerofoil faces, a hub face and a shroud face (both pieces of surfaces of
   revolution).
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from scipy.interpolate import BSpline, CubicSpline

from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.BRepAlgoAPI import BRepAlgoAPI_Common
from OCP.BRepBuilderAPI import (BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace,
                                BRepBuilderAPI_MakeWire)
from OCP.BRepOffsetAPI import BRepOffsetAPI_ThruSections
from OCP.BRepPrimAPI import BRepPrimAPI_MakeRevol
from OCP.BRepTools import BRepTools
from OCP.Geom import Geom_BSplineCurve, Geom_BSplineSurface, Geom_Plane, Geom_SurfaceOfRevolution
from OCP.GeomAPI import GeomAPI_IntCS, GeomAPI_Interpolate, GeomAPI_ProjectPointOnSurf
from OCP.GeomLProp import GeomLProp_SLProps
from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt
from OCP.Message import Message, Message_Gravity
from OCP.Precision import Precision
from OCP.TColgp import TColgp_Array1OfPnt, TColgp_HArray1OfPnt
from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_SOLID, TopAbs_VERTEX
from OCP.TopoDS import TopoDS, TopoDS_Shape, TopoDS_Solid

from hot2cold.kernel.validity import check_solids
from hot2cold.kernel.explore import shape_map

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from make_samples import check_solid, read_step, write_step  # noqa: E402  (the colleague's sample builder)

DATA = Path("/work/shared/data/nasa_rotor37")
CM = 10.0                # mm per cm
#: Stream surfaces (numbered from 0, hub -> shroud) that the loft goes through; 11, the tip section, lies
#: 0.36 mm inside 12 (the blade/shroud intersection) and would make the span-wise interpolation wiggle.
SURFACES = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 12)
PIECES = ("leading edge", "suction side", "trailing edge", "pressure side")
SPANS = (6, 24, 5, 25)   # knot spans per piece: 9, 27, 8 and 28 poles (the paper's 9, 27, 8, 28)
LE_HALF_ARC = 0.8        # mm of section arc either side of the leading-edge tip in the leading-edge face
TE_HALF_ARC = 0.7        # the same for the trailing edge
TURN_WEIGHT = 0.25       # weight of tangent turning against arc length in a piece's first parameters
N_CORRECT = 20           # parameter-correction rounds of a section fit
CLEARANCE = 2.0          # mm, least distance (radial) of the extra sections outside the hub and shroud lines
N_DENSE = 4000           # points of the dense reference polyline of a section


# ----------------------------------------------------------------------------------------------- reading

def read_sections(path: Path) -> list[np.ndarray]:
    """The 13 stream sections, hub -> shroud, each ``(100, 4)``: Z (mm), R (mm), THETA1, THETA2 (rad)."""
    sections, current = [], None
    for line in path.read_text().splitlines():
        if "SURFACE NUMBER" in line:
            current = []
            sections.append(current)
            continue
        words = line.split()
        if current is not None and len(words) == 5 and words[0].isdigit():
            current.append([float(w) for w in words[1:]])
    out = [np.array(s) * [CM, CM, 1.0, 1.0] for s in sections]
    if len(out) != 13 or any(s.shape != (100, 4) for s in out):
        raise ValueError(f"{path}: expected 13 sections of 100 rows, got {[s.shape for s in out]}")
    return out


def read_flow_path(path: Path) -> dict[str, np.ndarray]:
    """``{"Zhub", "Rhub", "Zshroud", "Rshroud"}``: each ``(n,)`` in mm."""
    out, name, values = {}, None, []
    for line in path.read_text().splitlines() + ["Zend"]:
        words = line.split()
        if len(words) == 1 and words[0] in ("Zhub", "Rhub", "Zshroud", "Rshroud", "Zend"):
            if name is not None:
                out[name] = np.array(values) * CM
            name, values = words[0], []
        elif name is not None and words and words[-1] != "points":
            values.extend(float(w) for w in words)
    return out


def cartesian(z: np.ndarray, r: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Points ``(m, 3)`` in mm at axial positions ``z (m,)``, radii ``r (m,)`` (mm), angles ``theta (m,)`` (rad)."""
    return np.column_stack([r * np.sin(theta), r * np.cos(theta), z])


def section_loop(section: np.ndarray) -> np.ndarray:
    """The closed section ``(198, 3)`` (mm): THETA1 side J = 1..100, then the THETA2 side J = 99..2."""
    z, r, t1, t2 = section.T
    side1 = cartesian(z, r, t1)
    side2 = cartesian(z, r, t2)[-2:0:-1]
    return np.concatenate([side1, side2])


def camber_bulge(section: np.ndarray) -> float:
    """Circumferential offset (mm, positive towards +theta) of the camber line at row 49 (mid-chord) of a
    stream section ``(100, 4)`` from the straight line joining its leading and trailing edge points."""
    z, r, t1, t2 = section.T
    camber = 0.5 * (t1 + t2)
    chord = np.interp(z[49], [z[0], z[-1]], [camber[0], camber[-1]])
    return float(r[49] * (camber[49] - chord))


# ------------------------------------------------------------------------------------ section fitting

def periodic_design(t: np.ndarray, n_spans: int) -> np.ndarray:
    """Design matrix ``(m, n_spans)`` of the uniform periodic cubic B-spline with knots 0, 1, ..., n_spans.

    Column ``i`` (from 0) multiplies pole ``i + 1`` of the kernel's periodic curve
    ``Geom_BSplineCurve(poles, knots 0..n_spans, multiplicities all 1, degree 3, periodic=True)``.
    """
    knots = np.arange(-3.0, n_spans + 4.0)
    full = BSpline.design_matrix(np.mod(t, n_spans), knots, 3).toarray()   # (m, n_spans + 3)
    out = full[:, :n_spans].copy()
    out[:, :3] += full[:, n_spans:]
    return out


def least_squares(design: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Poles ``(n, 3)`` minimising ``|design @ poles - points|`` for ``design (m, n)``, ``points (m, 3)``, by
    the normal equations (a B-spline fit with points in every span is well conditioned)."""
    return np.linalg.solve(design.T @ design, design.T @ points)


def periodic_curve(poles: np.ndarray) -> BSpline:
    """The uniform periodic cubic B-spline of ``poles (n, 3)`` (mm) on knots ``0..n`` as a scipy
    ``BSpline``, valid for parameters in ``[0, n]`` (wrap them with ``numpy.mod``)."""
    n = len(poles)
    return BSpline(np.arange(-3.0, n + 4.0), poles[np.arange(n + 3) % n], 3)


def foot_parameters(poles: np.ndarray, points: np.ndarray, t: np.ndarray, steps: int = 4) -> np.ndarray:
    """Parameters ``(m,)`` of the foot points of ``points (m, 3)`` on the periodic curve of ``poles``, by
    ``steps`` Gauss-Newton steps (each at most half a knot span) from ``t (m,)``."""
    n = len(poles)
    curve = periodic_curve(poles)
    d1 = curve.derivative()
    for _ in range(steps):
        tm = np.mod(t, n)
        r, a = curve(tm) - points, d1(tm)
        t = t - np.clip(np.einsum("ij,ij->i", r, a) / np.einsum("ij,ij->i", a, a), -0.5, 0.5)
    return t


def fit_section(loop: np.ndarray) -> tuple[np.ndarray, dict]:
    """Periodic cubic least-squares fit of a closed section ``loop (n, 3)`` (mm).

    Returns the poles ``(sum(SPANS), 3)`` (mm) of the periodic curve on knots ``0..sum(SPANS)`` whose pieces
    ``[0, 6], [6, 30], [30, 35], [35, 60]`` are leading edge, suction side, trailing edge and pressure side,
    and a dict of section data: ``chord`` (mm, leading-edge tip to trailing-edge tip) and ``fit_error`` (mm,
    largest distance of a data point from the fitted curve).

    The fit is to ``N_DENSE`` points of the reference spline.  Their first parameters blend arc length and
    tangent turning within each piece; ``N_CORRECT`` rounds of parameter correction (each point's parameter
    moved to its foot point on the last fit, then refit) then remove most of the tangential part of the
    residual, which a parameterisation with jumps in speed leaves at the noses.
    """
    closed = np.concatenate([loop, loop[:1]])
    s_data = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    spline = CubicSpline(s_data, closed, bc_type="periodic")
    # Dense polyline with its true arc length, tangents and turning.
    u = np.linspace(0.0, s_data[-1], N_DENSE, endpoint=False)
    dense = spline(u)
    tangent = spline(u, 1)
    tangent /= np.linalg.norm(tangent, axis=1)[:, None]
    seg = np.linalg.norm(np.diff(np.concatenate([dense, dense[:1]]), axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])             # (N_DENSE + 1,)
    length = arc[-1]
    turn = np.arccos(np.clip(np.einsum("ij,ij->i", tangent, np.roll(tangent, -1, axis=0)), -1.0, 1.0))

    # Chord: the extreme points along the chord direction, found by fixed-point iteration.
    direction = loop[99] - loop[0]
    for _ in range(5):
        direction /= np.linalg.norm(direction)
        proj = dense @ direction
        i_le, i_te = int(np.argmin(proj)), int(np.argmax(proj))
        direction = dense[i_te] - dense[i_le]
    chord = float(np.linalg.norm(direction))

    # Piece ends in arc length from the start of the leading-edge band (periodic).
    s_le, s_te = arc[i_le], arc[i_te]
    start = s_le - LE_HALF_ARC
    ends = np.array([0.0, 2 * LE_HALF_ARC, (s_te - TE_HALF_ARC - start) % length,
                     (s_te + TE_HALF_ARC - start) % length, length])
    if not np.all(np.diff(ends) > 0):
        raise RuntimeError(f"section pieces out of order: {ends}")
    knots_at = np.concatenate([[0], np.cumsum(SPANS)]).astype(float)

    # First parameters: within a piece, a blend of arc length and turning mapped onto its knot spans.
    s_rel = (arc[:-1] - start) % length                       # (N_DENSE,)
    order = np.argsort(s_rel)
    s_sorted = s_rel[order]
    ds = np.diff(np.concatenate([s_sorted, [length]]))
    dturn = turn[order]
    t_sorted = np.empty(N_DENSE)
    for k in range(4):
        mask = (s_sorted >= ends[k]) & (s_sorted < ends[k + 1])
        weight = ds[mask] / ds[mask].sum() + TURN_WEIGHT * dturn[mask] / dturn[mask].sum()
        lead = (s_sorted[mask][0] - ends[k]) / ds[mask].sum()   # first point's offset from the piece start
        cum = np.concatenate([[0.0], np.cumsum(weight)[:-1]]) + lead
        t_sorted[mask] = knots_at[k] + cum / (weight.sum() + lead) * SPANS[k]
    t_dense = np.empty(N_DENSE)
    t_dense[order] = t_sorted

    n = sum(SPANS)
    poles = least_squares(periodic_design(t_dense, n), dense)
    for _ in range(N_CORRECT):
        t_dense = foot_parameters(poles, dense, t_dense)
        poles = least_squares(periodic_design(t_dense, n), dense)

    # Fit error at the data points: distance to their foot points.
    u_points = np.interp(s_data[:-1], u, np.arange(N_DENSE))
    t_points = foot_parameters(poles, loop, t_dense[np.round(u_points).astype(int) % N_DENSE], steps=8)
    error = np.linalg.norm(periodic_curve(poles)(np.mod(t_points, n)) - loop, axis=1).max()
    return poles, {"chord": chord, "fit_error": float(error)}


def extend(poles: np.ndarray, inner: np.ndarray, offset: float) -> np.ndarray:
    """Poles ``(n, 3)`` of a planar section beyond ``poles (n, 3)``: each pole moved on along the line from
    the matching pole of ``inner (n, 3)`` onto the plane that fits ``poles``, shifted ``offset`` mm outwards."""
    centre = poles.mean(axis=0)
    normal = np.linalg.svd(poles - centre)[2][2]
    step = poles - inner
    if (step @ normal).mean() < 0:
        normal = -normal
    level = (poles - centre) @ normal
    alpha = (level.max() + offset - level) / (step @ normal)
    if np.any(alpha <= 0):
        raise RuntimeError("a section pole moves backwards onto the extension plane")
    return poles + alpha[:, None] * step


# ----------------------------------------------------------------------------------------- kernel parts

def _pnt(p: np.ndarray) -> gp_Pnt:
    return gp_Pnt(float(p[0]), float(p[1]), float(p[2]))


def section_wire(poles: np.ndarray):
    """The 4-edge wire (leading edge, suction side, trailing edge, pressure side) of a periodic section."""
    n = len(poles)
    array = TColgp_Array1OfPnt(1, n)
    knots = TColStd_Array1OfReal(1, n + 1)
    mults = TColStd_Array1OfInteger(1, n + 1)
    for i, p in enumerate(poles, start=1):
        array.SetValue(i, _pnt(p))
    for i in range(n + 1):
        knots.SetValue(i + 1, float(i))
        mults.SetValue(i + 1, 1)
    curve = Geom_BSplineCurve(array, knots, mults, 3, True)
    curve.SetNotPeriodic()
    cuts = np.concatenate([[0], np.cumsum(SPANS)]).astype(float)
    wire = BRepBuilderAPI_MakeWire()
    for t0, t1 in zip(cuts[:-1], cuts[1:]):
        piece = curve.Copy()
        piece.Segment(float(t0), float(t1))
        wire.Add(BRepBuilderAPI_MakeEdge(piece).Edge())
    return wire.Wire()


def meridional_curve(z: np.ndarray, r: np.ndarray) -> Geom_BSplineCurve:
    """Cubic B-spline interpolating the flow-path line ``z (n,)``, ``r (n,)`` (mm) in the theta = pi half plane
    (``x = 0``, ``y = -r``)."""
    points = TColgp_HArray1OfPnt(1, len(z))
    for i, (a, b) in enumerate(zip(z, r), start=1):
        points.SetValue(i, gp_Pnt(0.0, -float(b), float(a)))
    interp = GeomAPI_Interpolate(points, False, 1e-9)
    interp.Perform()
    return interp.Curve()


def line_table(curve: Geom_BSplineCurve, samples: int = 20001) -> np.ndarray:
    """``(samples, 2)``: axial position z and radius (mm) along a meridional curve, z increasing."""
    t = np.linspace(curve.FirstParameter(), curve.LastParameter(), samples)
    pts = np.array([[p.Z(), -p.Y()] for p in (curve.Value(float(x)) for x in t)])
    if not np.all(np.diff(pts[:, 0]) > 0):
        raise RuntimeError("a flow-path line is not monotonic in z")
    return pts


def annulus(hub: Geom_BSplineCurve, shroud: Geom_BSplineCurve) -> TopoDS_Solid:
    """The flow-path solid between the hub and shroud curves, revolved a full turn about the z axis."""
    h0, h1 = hub.StartPoint(), hub.EndPoint()
    s0, s1 = shroud.StartPoint(), shroud.EndPoint()
    if abs(h0.Z() - s0.Z()) > 1e-9 or abs(h1.Z() - s1.Z()) > 1e-9:
        raise RuntimeError("hub and shroud lines must start and end at the same z")
    wire = BRepBuilderAPI_MakeWire()
    wire.Add(BRepBuilderAPI_MakeEdge(hub).Edge())
    wire.Add(BRepBuilderAPI_MakeEdge(h1, s1).Edge())
    wire.Add(BRepBuilderAPI_MakeEdge(shroud.Reversed()).Edge())
    wire.Add(BRepBuilderAPI_MakeEdge(s0, h0).Edge())
    face = BRepBuilderAPI_MakeFace(wire.Wire(), True).Face()
    revol = BRepPrimAPI_MakeRevol(face, gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), 2.0 * math.pi)
    revol.Build()
    return TopoDS.Solid_s(revol.Shape())


def loft(sections: list[np.ndarray]) -> TopoDS_Solid:
    """The solid lofted through the periodic sections ``sections[k] (n, 3)`` (poles, mm), hub to shroud."""
    maker = BRepOffsetAPI_ThruSections(True, False, 1e-6)
    maker.CheckCompatibility(False)
    maker.SetMaxDegree(3)
    for poles in sections:
        maker.AddWire(section_wire(poles))
    maker.Build()
    if not maker.IsDone():
        raise RuntimeError("the loft failed")
    return TopoDS.Solid_s(maker.Shape())


# -------------------------------------------------------------------------------------------- reporting

def face_kind(face) -> str:
    return BRep_Tool.Surface_s(face).DynamicType().Name()


def net(face) -> str:
    """Pole net, degrees and knot spans of a B-spline face."""
    s = BRep_Tool.Surface_s(face)
    return (f"{s.NbUPoles()} x {s.NbVPoles()} poles, degree {s.UDegree()} x {s.VDegree()}, "
            f"{s.NbUKnots() - 1} x {s.NbVKnots() - 1} knot spans")


def name_faces(part: TopoDS_Shape) -> dict[str, object]:
    """The part's faces by name: the aerofoil faces by their pole count along the section (9, 27, 8, 28),
    ``hub`` and ``shroud`` (the surfaces of revolution) by their radius."""
    names = {9: "leading edge", 27: "suction side", 8: "trailing edge", 28: "pressure side"}
    out, ends = {}, []
    for face in shape_map(part, TopAbs_FACE):
        surface = BRep_Tool.Surface_s(face)
        if isinstance(surface, Geom_BSplineSurface):
            out[names[surface.NbUPoles()]] = face
        else:
            p = BRep_Tool.Pnt_s(shape_map(face, TopAbs_VERTEX)[0])
            ends.append((math.hypot(p.X(), p.Y()), face))
    ends.sort(key=lambda e: e[0])
    out["hub"], out["shroud"] = ends[0][1], ends[-1][1]
    if len(out) != 6:
        raise RuntimeError(f"expected 4 aerofoil faces, a hub and a shroud face; got {sorted(out)}")
    return out


def boundary_points(face, edge, n: int = 60) -> np.ndarray:
    """Points ``(n, 3)`` (mm) of the face's surface along the edge's curve on that face (its trimming
    boundary), not the edge's 3D curve."""
    pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
    first, last = BRep_Tool.Range_s(edge, face)
    surface = BRep_Tool.Surface_s(face)
    out = []
    for t in np.linspace(first, last, n):
        uv = pcurve.Value(float(t))
        p = surface.Value(uv.X(), uv.Y())
        out.append([p.X(), p.Y(), p.Z()])
    return np.array(out)


def off_revolution(surface: Geom_SurfaceOfRevolution, points: np.ndarray) -> np.ndarray:
    """``(m,)``: |r - r_line(z)| (mm) of ``points (m, 3)``, with z along the surface's axis, r the distance
    from it, and r_line(z) the radius of its meridian (basis curve) at that z."""
    axis = surface.Axis()
    origin = np.array(axis.Location().Coord())
    direction = np.array(axis.Direction().Coord())
    basis = surface.BasisCurve()
    out = []
    for p in points:
        z = (p - origin) @ direction
        r = np.linalg.norm((p - origin) - z * direction)
        plane = Geom_Plane(gp_Pnt(*(origin + z * direction)), gp_Dir(*direction))
        hits = GeomAPI_IntCS(basis, plane)
        if not hits.IsDone() or hits.NbPoints() != 1:
            raise RuntimeError(f"the meridian crosses the plane z = {z:.3f} {hits.NbPoints()} times")
        q = np.array(hits.Point(1).Coord()) - origin
        out.append(abs(r - np.linalg.norm(q - (q @ direction) * direction)))
    return np.array(out)


def shared_edges(f0, f1) -> list:
    """The edges that faces ``f0`` and ``f1`` share."""
    others = shape_map(f1, TopAbs_EDGE)
    return [e for e in shape_map(f0, TopAbs_EDGE) if any(e.IsSame(g) for g in others)]


def g1_kink(faces: list, samples: int = 21) -> float:
    """Largest angle (degrees) between the normals of two of ``faces`` along the edges they share, sampled
    at ``samples`` points per edge."""
    worst = 0.0
    for i, f0 in enumerate(faces):
        for f1 in faces[i + 1:]:
            for edge in shared_edges(f0, f1):
                curve = BRepAdaptor_Curve(edge)
                for t in np.linspace(curve.FirstParameter(), curve.LastParameter(), samples):
                    p = curve.Value(float(t))
                    normals = []
                    for face in (f0, f1):
                        s = BRep_Tool.Surface_s(face)
                        u, v = GeomAPI_ProjectPointOnSurf(p, s).LowerDistanceParameters()
                        normals.append(np.array(GeomLProp_SLProps(s, u, v, 1, 1e-9).Normal().Coord()))
                    cos = min(1.0, abs(float(normals[0] @ normals[1])))
                    worst = max(worst, math.degrees(math.acos(cos)))
    return worst


def width_across(face, samples: int = 400) -> float:
    """Arc length (mm) of a B-spline face's u iso-line across it at the middle of its trimmed v range."""
    s = BRep_Tool.Surface_s(face)
    u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
    pts = np.array([s.Value(float(u), 0.5 * (v0 + v1)).Coord() for u in np.linspace(u0, u1, samples)])
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())


def data_distance(faces: list, points: np.ndarray) -> np.ndarray:
    """``(m,)``: distance (mm) of ``points (m, 3)`` from the nearest of the (untrimmed) face surfaces."""
    projectors = [GeomAPI_ProjectPointOnSurf() for _ in faces]
    for proj, face in zip(projectors, faces):
        surface = BRep_Tool.Surface_s(face)
        proj.Init(surface, *surface.Bounds(), Precision.Confusion_s())
    out = np.full(len(points), np.inf)
    for i, p in enumerate(points):
        for proj in projectors:
            proj.Perform(gp_Pnt(*p))
            if proj.NbPoints():
                out[i] = min(out[i], proj.LowerDistance())
    return out


def report(part: TopoDS_Shape, raw: list[np.ndarray], infos: list[dict]) -> None:
    """Print the faces, their nets and trims, sizes and the fit to the NASA data."""
    check = check_solids(part)[0]
    named = name_faces(part)
    aerofoil = [named[n] for n in PIECES]
    order = shape_map(part, TopAbs_FACE)
    print(f"rotor37_blade.step: 1 solid, BRepCheck valid {check.valid}, {check.free_edges} free edges, "
          f"{check.faces} faces, volume {check.volume:.1f} mm^3")
    for name, face in named.items():
        k = next(i for i, f in enumerate(order) if f.IsSame(face))
        line = f"  face {k} {name:13s} {face_kind(face)}"
        surface = BRep_Tool.Surface_s(face)
        if isinstance(surface, Geom_BSplineSurface):
            u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
            sv0, sv1 = surface.Bounds()[2:]
            line += f", {net(face)}; trimmed span-wise to v in [{v0:.4f}, {v1:.4f}] of [{sv0:g}, {sv1:g}]"
        else:
            basis = surface.BasisCurve()
            line += (f" of a {basis.DynamicType().Name()} ({basis.NbPoles()} poles, degree {basis.Degree()}) "
                     f"about the z axis")
        print(line)
    for end in ("hub", "shroud"):
        dev = np.concatenate([off_revolution(BRep_Tool.Surface_s(named[end]), boundary_points(face, edge))
                              for face in aerofoil for edge in shared_edges(face, named[end])])
        print(f"  aerofoil face boundaries on the {end}: {len(dev)} points, |r - r_{end}(z)| <= {dev.max():.2e} mm")
    print(f"  normal kink across the edges between aerofoil faces: <= {g1_kink(aerofoil):.1e} deg")
    print("  width across at mid-span: " + ", ".join(f"{n} {width_across(named[n]):.2f}" for n in PIECES) + " mm")

    # sizes: radial heights of the 4 span-wise edges, radii and chords
    heights = []
    for i, f0 in enumerate(aerofoil):
        edge = shared_edges(f0, aerofoil[(i + 1) % 4])[0]
        r = [math.hypot(*BRep_Tool.Pnt_s(v).Coord()[:2]) for v in shape_map(edge, TopAbs_VERTEX)]
        heights.append(abs(r[1] - r[0]))
    pts = np.concatenate([boundary_points(f, e) for f in aerofoil for e in shape_map(f, TopAbs_EDGE)])
    r = np.hypot(pts[:, 0], pts[:, 1])
    print("  span (radial height of the span-wise edges): " + ", ".join(
        f"{PIECES[i]}/{PIECES[(i + 1) % 4]} {h:.2f}" for i, h in enumerate(heights)) + " mm")
    print(f"  radius {r.min():.2f} .. {r.max():.2f} mm, z {pts[:, 2].min():.2f} .. {pts[:, 2].max():.2f} mm, "
          f"chord (tip to tip) {infos[0]['chord']:.2f} mm at the hub, {infos[-1]['chord']:.2f} mm at the shroud")

    # fit to the data
    used = np.concatenate([section_loop(raw[k]) for k in SURFACES])
    left_out = np.concatenate([section_loop(raw[k]) for k in range(len(raw)) if k not in SURFACES])
    print(f"  NASA points from the aerofoil surfaces: <= {data_distance(aerofoil, used).max() * 1e3:.1f} um on the "
          f"lofted stream surfaces, <= {data_distance(aerofoil, left_out).max() * 1e3:.1f} um on the tip section "
          f"(left out)")


def main(argv: list[str]) -> int:
    Message.DefaultMessenger_s().Printers().First().SetTraceLevel(Message_Gravity.Message_Fail)
    data = Path(argv[1]) if len(argv) > 1 else DATA
    raw = read_sections(data / "rotor37geometry.dat")
    path = read_flow_path(data / "rotor37hub-shroud.dat")
    hub = meridional_curve(path["Zhub"], path["Rhub"])
    shroud = meridional_curve(path["Zshroud"], path["Rshroud"])

    # 1. sections
    poles, infos = [], []
    for k in SURFACES:
        p, info = fit_section(section_loop(raw[k]))
        poles.append(p)
        infos.append(info)
    if min(camber_bulge(raw[k]) for k in SURFACES) <= 0.0:
        raise RuntimeError("the THETA1 side is not the convex (suction) side in every section")
    print(f"sections: {len(SURFACES)} stream surfaces {SURFACES}, {sum(SPANS)} periodic cubic spans each; "
          f"largest fit error at a data point {max(i['fit_error'] for i in infos) * 1e3:.2f} um")
    print(f"chord (tip to tip): hub {infos[0]['chord']:.2f} mm, shroud {infos[-1]['chord']:.2f} mm")

    # 2. extra planar sections beyond hub and shroud, each clearing its line by CLEARANCE
    def clearance(section_poles: np.ndarray, table: np.ndarray, outside: float) -> float:
        """Least radial distance (mm) of the section outside (``outside`` = +1) or inside (-1) a line."""
        pts = periodic_design(np.linspace(0, sum(SPANS), 2000, endpoint=False), sum(SPANS)) @ section_poles
        r = np.hypot(pts[:, 0], pts[:, 1])
        return float((outside * (r - np.interp(pts[:, 2], table[:, 0], table[:, 1]))).min())

    extra = {}
    for name, outer, inner, line, outside in (("hub", poles[0], poles[1], line_table(hub), -1.0),
                                              ("shroud", poles[-1], poles[-2], line_table(shroud), 1.0)):
        offset = CLEARANCE
        for _ in range(20):
            candidate = extend(outer, inner, offset)
            gap = clearance(candidate, line, outside)
            if abs(gap - CLEARANCE) < 1e-3:
                break
            offset += CLEARANCE - gap
        else:
            raise RuntimeError(f"cannot place the extra section beyond the {name}")
        extra[name] = candidate
        print(f"extra section beyond the {name}: plane {offset:.3f} mm out, clears the {name} line by "
              f"{gap:.3f} mm")
    sections = [extra["hub"]] + poles + [extra["shroud"]]

    # 3. loft
    blade = loft(sections)
    check_solid(blade, "untrimmed blade")

    # 4. trim
    ring = annulus(hub, shroud)
    check_solid(ring, "annulus")
    common = BRepAlgoAPI_Common(blade, ring)
    common.Build()
    if not common.IsDone():
        raise RuntimeError("Common of blade and annulus failed")
    solids = shape_map(common.Shape(), TopAbs_SOLID)
    if len(solids) != 1:
        raise RuntimeError(f"Common gives {len(solids)} solids")
    part = solids[0]
    check_solid(part, "rotor 37 blade")

    step = HERE / "rotor37_blade.step"
    write_step(part, step, "hot2cold sample_parts/make_rotor37.py")
    part = read_step(step)
    check_solid(part, "rotor 37 blade (read back)")
    report(part, raw, infos)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
