"""The real-world sample parts, read back from their STEP files.

* ``rotor37_blade.step`` (``sample_parts/make_rotor37.py``): the NASA Rotor 37 blade, 4 B-spline aerofoil
  faces (leading edge, suction side, trailing edge, pressure side) trimmed by a hub and a shroud face, which
  are pieces of surfaces of revolution about the z axis.  Millimetres.
* ``mixer_segment.step`` (``sample_parts/make_mixer.py``): a two-lobe exhaust-mixer segment along the x axis,
  outer and inner lobed B-spline walls, two side cuts (B-spline), planar inlet and exit.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from OCP.BRep import BRep_Tool
from OCP.BRepTools import BRepTools
from OCP.Geom import Geom_BSplineSurface, Geom_Plane, Geom_SurfaceOfRevolution
from OCP.GeomAPI import GeomAPI_IntCS, GeomAPI_ProjectPointOnSurf
from OCP.GeomLProp import GeomLProp_SLProps
from OCP.gp import gp_Dir, gp_Pnt
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_VERTEX

from hot2cold.kernel.validity import check_solids
from hot2cold.kernel.step import read_step
from hot2cold.kernel.explore import shape_map
from hot2cold.kernel.topology import decompose

SAMPLES = Path(__file__).resolve().parent.parent / "sample_parts"


@pytest.fixture(scope="module")
def rotor():
    return read_step(SAMPLES / "rotor37_blade.step")


@pytest.fixture(scope="module")
def mixer():
    return read_step(SAMPLES / "mixer_segment.step")


def surface(face):
    return BRep_Tool.Surface_s(face)


def shared_edges(f0, f1) -> list:
    """The edges that faces ``f0`` and ``f1`` share."""
    others = shape_map(f1, TopAbs_EDGE)
    return [e for e in shape_map(f0, TopAbs_EDGE) if any(e.IsSame(g) for g in others)]


def vertex_radius(vertex) -> float:
    """Distance (mm) of a vertex from the z axis."""
    x, y, _ = BRep_Tool.Pnt_s(vertex).Coord()
    return math.hypot(x, y)


def rotor_faces(shape) -> tuple[list, object, object]:
    """``(aerofoil faces, hub face, shroud face)`` of the Rotor 37 blade."""
    faces = shape_map(shape, TopAbs_FACE)
    aerofoil = [f for f in faces if isinstance(surface(f), Geom_BSplineSurface)]
    ends = sorted((f for f in faces if isinstance(surface(f), Geom_SurfaceOfRevolution)),
                  key=lambda f: vertex_radius(shape_map(f, TopAbs_VERTEX)[0]))
    return aerofoil, ends[0], ends[-1]


def boundary_points(face, edge, n: int = 40) -> np.ndarray:
    """Points ``(n, 3)`` of the face's own surface along the edge's curve on the face (its trim boundary)."""
    pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
    first, last = BRep_Tool.Range_s(edge, face)
    s = surface(face)
    out = []
    for t in np.linspace(first, last, n):
        uv = pcurve.Value(float(t))
        out.append(s.Value(uv.X(), uv.Y()).Coord())
    return np.array(out)


def off_meridian(revolution: Geom_SurfaceOfRevolution, points: np.ndarray) -> np.ndarray:
    """``(m,)``: |r - r_line(z)| (mm) of ``points (m, 3)``: z along the surface's axis, r the distance from
    it, r_line(z) the radius of the surface's meridian (its basis curve) at that z."""
    axis = revolution.Axis()
    origin = np.array(axis.Location().Coord())
    direction = np.array(axis.Direction().Coord())
    out = []
    for p in points:
        z = (p - origin) @ direction
        r = np.linalg.norm(p - origin - z * direction)
        hits = GeomAPI_IntCS(revolution.BasisCurve(), Geom_Plane(gp_Pnt(*(origin + z * direction)),
                                                                 gp_Dir(*direction)))
        assert hits.IsDone() and hits.NbPoints() == 1
        q = np.array(hits.Point(1).Coord()) - origin
        out.append(abs(r - np.linalg.norm(q - (q @ direction) * direction)))
    return np.array(out)


# ---------------------------------------------------------------------------------------------- rotor 37

def test_rotor37_is_one_valid_closed_solid(rotor):
    checks = check_solids(rotor)
    assert len(checks) == 1
    check = checks[0]
    assert check.valid
    assert check.free_edges == 0
    assert check.faces == 6
    assert 7000.0 < check.volume < 9000.0          # mm^3; the script reports 7906


def test_rotor37_faces_and_nets(rotor):
    faces = shape_map(rotor, TopAbs_FACE)
    kinds = sorted(surface(f).DynamicType().Name() for f in faces)
    assert kinds == ["Geom_BSplineSurface"] * 4 + ["Geom_SurfaceOfRevolution"] * 2
    aerofoil, hub, shroud = rotor_faces(rotor)
    # leading edge 9, suction side 27, trailing edge 8, pressure side 28 poles along the section
    assert sorted(surface(f).NbUPoles() for f in aerofoil) == [8, 9, 27, 28]
    for f in aerofoil:
        s = surface(f)
        assert (s.UDegree(), s.VDegree(), s.NbVPoles()) == (3, 3, 14)
    for end in (hub, shroud):
        assert surface(end).BasisCurve().DynamicType().Name() == "Geom_BSplineCurve"
    # the four aerofoil faces form a ring: each meets two others along one span-wise edge each
    for f in aerofoil:
        neighbours = [g for g in aerofoil if g is not f and shared_edges(f, g)]
        assert len(neighbours) == 2
        assert all(len(shared_edges(f, g)) == 1 for g in neighbours)


def test_rotor37_aerofoil_faces_are_trimmed_by_hub_and_shroud(rotor):
    aerofoil, hub, shroud = rotor_faces(rotor)
    for f in aerofoil:
        u0, u1, v0, v1 = BRepTools.UVBounds_s(f)
        su0, su1, sv0, sv1 = surface(f).Bounds()
        assert u0 == pytest.approx(su0, abs=1e-9) and u1 == pytest.approx(su1, abs=1e-9)   # whole chord piece
        assert sv0 + 0.01 < v0 < v1 < sv1 - 0.01                                             # trimmed span-wise
        for end in (hub, shroud):
            edges = shared_edges(f, end)
            assert len(edges) == 1
            dev = off_meridian(surface(end), boundary_points(f, edges[0]))
            assert dev.max() < 1e-3


def test_rotor37_dimensions(rotor):
    aerofoil, hub, shroud = rotor_faces(rotor)
    points = np.concatenate([boundary_points(f, e) for f in aerofoil for e in shape_map(f, TopAbs_EDGE)])
    r = np.hypot(points[:, 0], points[:, 1])
    assert 170.0 < r.min() < 180.0 and 245.0 < r.max() < 260.0
    assert 35.0 < np.ptp(points[:, 2]) < 50.0                   # axial extent, mm (43 at the hub)
    spans = []
    for i, f in enumerate(aerofoil):
        for g in aerofoil[i + 1:]:
            for e in shared_edges(f, g):
                a, b = (vertex_radius(v) for v in shape_map(e, TopAbs_VERTEX))
                spans.append(abs(b - a))
    assert len(spans) == 4
    assert all(25.0 < s < 75.0 for s in spans)


def test_rotor37_aerofoil_faces_meet_tangentially(rotor):
    aerofoil, _, _ = rotor_faces(rotor)
    worst = 0.0
    for i, f in enumerate(aerofoil):
        for g in aerofoil[i + 1:]:
            for e in shared_edges(f, g):
                for p in boundary_points(f, e, 11):
                    normals = []
                    for face in (f, g):
                        u, v = GeomAPI_ProjectPointOnSurf(gp_Pnt(*p), surface(face)).LowerDistanceParameters()
                        normals.append(np.array(GeomLProp_SLProps(surface(face), u, v, 1, 1e-9).Normal().Coord()))
                    worst = max(worst, math.degrees(math.acos(min(1.0, abs(normals[0] @ normals[1])))))
    assert worst < 1e-3


def test_rotor37_decomposes(rotor):
    part = decompose(rotor)
    assert len(part.faces) == 6
    assert len(part.edges) == 12        # 4 span-wise, 4 on the hub, 4 on the shroud
    assert all(len(edge.faces) == 2 for edge in part.edges)


# ----------------------------------------------------------------------------------------------- mixer

R0, T, A, L = 300.0, 2.5, 25.0, 250.0        # mm: mean radius, wall, exit lobe amplitude, length
WIDTH = 4.0 * math.pi / 12.0                 # rad: two of 12 lobes


def test_mixer_is_one_valid_closed_solid(mixer):
    checks = check_solids(mixer)
    assert len(checks) == 1
    check = checks[0]
    assert check.valid
    assert check.free_edges == 0
    assert check.faces == 6
    # whole lobes: the cos term integrates to zero, the volume is that of the unlobed wall
    assert check.volume == pytest.approx(T * R0 * WIDTH * L, rel=1e-4)


def test_mixer_faces_and_nets(mixer):
    faces = shape_map(mixer, TopAbs_FACE)
    planes = [f for f in faces if isinstance(surface(f), Geom_Plane)]
    splines = [f for f in faces if isinstance(surface(f), Geom_BSplineSurface)]
    assert len(planes) == 2 and len(splines) == 4
    assert sorted(BRep_Tool.Pnt_s(shape_map(f, TopAbs_VERTEX)[0]).X() for f in planes) == \
        pytest.approx([0.0, L], abs=1e-6)
    lobed = [f for f in splines if surface(f).NbUKnots() > 2]
    sides = [f for f in splines if surface(f).NbUKnots() == 2]
    assert len(lobed) == 2 and len(sides) == 2
    for f in lobed:
        s = surface(f)
        assert 32 <= s.NbUPoles() <= 62 and 20 <= s.NbVPoles() <= 38
        assert (s.UDegree(), s.VDegree()) == (3, 3)


def test_mixer_lobes(mixer):
    faces = [f for f in shape_map(mixer, TopAbs_FACE)
             if isinstance(surface(f), Geom_BSplineSurface) and surface(f).NbUKnots() > 2]
    radii = []
    for f in faces:
        s = surface(f)
        u0, u1, v0, v1 = s.Bounds()
        grid = np.array([s.Value(float(u), float(v)).Coord() for u in np.linspace(u0, u1, 41)
                         for v in np.linspace(v0, v1, 11)]).reshape(41, 11, 3)
        r = np.hypot(grid[..., 1], grid[..., 2])
        theta = np.arctan2(grid[..., 2], grid[..., 1])
        s_x = grid[..., 0] / L
        mid = R0 + A * s_x ** 2 * (3 - 2 * s_x) * np.cos(12 * theta)
        radii.append(r - mid)
        exit_row = int(np.argmax(grid[0, :, 0]))                 # v runs along x
        assert grid[0, exit_row, 0] == pytest.approx(L, abs=1e-6)
        assert np.ptp(r[:, exit_row]) == pytest.approx(2 * A, abs=0.01)   # trough to crest at the exit
        assert np.ptp(r[:, int(np.argmin(grid[0, :, 0]))]) < 1e-3          # round at the inlet
    offsets = sorted(float(np.mean(d)) for d in radii)
    assert offsets == pytest.approx([-T / 2, T / 2], abs=1e-3)
    assert all(np.ptp(d) < 1e-3 for d in radii)


def test_mixer_decomposes(mixer):
    part = decompose(mixer)
    assert len(part.faces) == 6 and len(part.edges) == 12


def test_every_face_belongs_to_its_solid():
    """Part.solids and Face.solid number the faces of the kernel's working copy (a two-solid compound)."""
    import cadquery as cq
    from hot2cold.kernel.topology import decompose
    shape = cq.Compound.makeCompound([cq.Solid.makeBox(1, 2, 3), cq.Solid.makeSphere(1, cq.Vector(5, 0, 0))])
    part = decompose(shape.wrapped)
    assert sorted(k for members in part.solids for k in members) == list(range(len(part.faces)))
    assert len(part.solids) == 2 and len(part.solids[0]) == 6 and len(part.solids[1]) >= 1
    assert all(part.faces[k].solid == s for s, members in enumerate(part.solids) for k in members)
