"""Write the sample parts and their synthetic FE displacement fields into this folder.

Run from anywhere: ``python sample_parts/make_samples.py``.  The output is deterministic: a re-run in a
fresh process rewrites byte-identical files (the STEP header's time stamp is fixed).

* ``twisted_blade.step``: a compressor-like blade lofted (``BRepOffsetAPI_ThruSections``, smooth, cubic in
  the span direction) through 6 cambered airfoil sections from z = 0 to 100 mm, chord 42 -> 38 mm, 8 %
  thickness, twisted by 30 degrees about the z axis (the stacking line through 40 % chord).  Each section is
  one periodic cubic B-spline interpolating an analytic airfoil, split into leading edge, suction side,
  trailing edge and pressure side, so the blade has the four tangent-continuous B-spline side faces of the
  paper's aerofoil plus planar hub and tip caps.
* ``filleted_block.step``: a 60 x 40 x 20 mm block (centred at the origin) with its vertical edges filleted
  (r = 6) and then its top edges (r = 3): planes, cylinders and tori.
* ``twisted_blade_field.csv`` / ``filleted_block_field.csv``: ``id,x,y,z,dx,dy,dz`` of FE-like surface nodes
  (about 2 mm apart) plus 500 volume nodes, shuffled, displaced by an :class:`~hot2cold.testing.synthetic.UntwistField`
  and an :class:`~hot2cold.testing.synthetic.AffineField` respectively.  Nodes are computed on the part as read back
  from its STEP file.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from OCP.APIHeaderSection import APIHeaderSection_MakeHeader
from OCP.BRep import BRep_Tool
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeWire
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.BRepGProp import BRepGProp
from OCP.BRepOffsetAPI import BRepOffsetAPI_ThruSections
from OCP.GeomAPI import GeomAPI_Interpolate
from OCP.GProp import GProp_GProps
from OCP.gp import gp_Pnt
from OCP.IFSelect import IFSelect_RetDone
from OCP.Interface import Interface_Static
from OCP.Message import Message, Message_Gravity
from OCP.STEPControl import STEPControl_AsIs, STEPControl_Reader, STEPControl_Writer
from OCP.TCollection import TCollection_HAsciiString
from OCP.TColgp import TColgp_HArray1OfPnt
from OCP.TColStd import TColStd_HArray1OfReal
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_SHELL, TopAbs_SOLID
from OCP.TopExp import TopExp
from OCP.TopoDS import TopoDS, TopoDS_Shape, TopoDS_Solid
from OCP.TopTools import TopTools_IndexedDataMapOfShapeListOfShape, TopTools_IndexedMapOfShape

from hot2cold.kernel.sampling import face_list, fe_surface_nodes, volume_nodes
from hot2cold.testing.synthetic import AffineField, UntwistField

HERE = Path(__file__).resolve().parent
#: mm between FE-like surface nodes.  The blade's leading- and trailing-edge faces are only ~6 mm wide
#: with 10-12 control points across, so its mesh is fine there as a real FE mesh would be; at 2 mm they
#: get three node columns and their fit is under-determined between nodes.
SPACING = {"twisted_blade": 0.7, "filleted_block": 2.0}
N_VOLUME = 500         # volume nodes mixed into each field
VOLUME_MARGIN = 0.5    # mm, least distance of a volume node from the surface
SEED = 0

# Blade: sections along z, one periodic cubic per section, split into 4 edges at these airfoil angles.
N_SECTIONS = 6
SPAN = 100.0
N_SECTION_POINTS = 40
LE_HALF_ANGLE = 0.7    # the leading-edge face spans theta in [-0.7, 0.7]
TE_HALF_ANGLE = 0.5    # the trailing-edge face spans theta in [pi - 0.5, pi + 0.5]


def airfoil(theta: np.ndarray, chord: float, thickness: float = 0.08, camber: float = 0.05,
            skew: float = 0.3) -> np.ndarray:
    """Closed cambered airfoil ``(m, 2)`` at angles ``theta (m,)`` (period 2 pi), leading edge at the origin.

    ``x = chord (1 - cos theta) / 2``; the half thickness ``a sin(theta) (1 + skew cos(theta))`` gives an
    elliptic, blunter leading edge (theta = 0) and a thinner rounded trailing edge (theta = pi), with the
    largest thickness ``thickness * chord``; the camber line is a parabola of height ``camber * chord``.
    Suction side: 0 < theta < pi.
    """
    c = (-1.0 + math.sqrt(1.0 + 8.0 * skew ** 2)) / (4.0 * skew)   # cos(theta) at the thickest point
    a = thickness * chord / 2.0 / (math.sqrt(1.0 - c * c) * (1.0 + skew * c))
    x = chord * (1.0 - np.cos(theta)) / 2.0
    y = 4.0 * camber * x * (1.0 - x / chord) + a * np.sin(theta) * (1.0 + skew * np.cos(theta))
    return np.column_stack([x, y])


def section_curve(z: float, chord: float, twist: float, theta: np.ndarray, **shape):
    """The periodic cubic B-spline (made non-periodic, ``Geom_BSplineCurve``) at height ``z`` (mm) that
    interpolates the :func:`airfoil` of ``chord`` at the angles ``theta (m,)`` (its parameters, period 2 pi;
    ``shape``: the airfoil's other arguments), stacked on the camber line at 40 % chord and turned by
    ``twist`` radians about the z axis."""
    xy = airfoil(theta, chord, **shape)
    xy -= [0.4 * chord, 4.0 * 0.05 * 0.4 * 0.6 * chord]   # stacking line: the camber line at 40 % chord
    rot = np.array([[math.cos(twist), -math.sin(twist)], [math.sin(twist), math.cos(twist)]])
    xy = xy @ rot.T
    pts = TColgp_HArray1OfPnt(1, len(theta))
    par = TColStd_HArray1OfReal(1, len(theta) + 1)  # periodic: one more parameter closes the curve
    for i, ((x, y), t) in enumerate(zip(xy, theta), start=1):
        pts.SetValue(i, gp_Pnt(float(x), float(y), z))
        par.SetValue(i, float(t))
    par.SetValue(len(theta) + 1, float(theta[0] + 2.0 * math.pi))
    interp = GeomAPI_Interpolate(pts, par, True, 1e-9)
    interp.Perform()
    curve = interp.Curve()
    curve.SetNotPeriodic()
    return curve


def split_wire(curve, cuts) -> object:
    """The wire of the pieces of ``curve`` between consecutive parameters of ``cuts``, one edge each."""
    wire = BRepBuilderAPI_MakeWire()
    for t0, t1 in zip(cuts[:-1], cuts[1:]):
        piece = curve.Copy()
        piece.Segment(t0, t1)
        wire.Add(BRepBuilderAPI_MakeEdge(piece).Edge())
    return wire.Wire()


def blade_section(z: float):
    """The section wire at height ``z`` (mm): 4 B-spline edges (LE, suction side, TE, pressure side)."""
    chord = 42.0 - 4.0 * z / SPAN
    twist = math.radians(-15.0 + 30.0 * z / SPAN)
    theta = -LE_HALF_ANGLE + 2.0 * math.pi * np.arange(N_SECTION_POINTS) / N_SECTION_POINTS
    cuts = [-LE_HALF_ANGLE, LE_HALF_ANGLE, math.pi - TE_HALF_ANGLE, math.pi + TE_HALF_ANGLE,
            2.0 * math.pi - LE_HALF_ANGLE]
    return split_wire(section_curve(z, chord, twist, theta), cuts)


def make_blade() -> TopoDS_Solid:
    loft = BRepOffsetAPI_ThruSections(True, False, 1e-6)
    loft.CheckCompatibility(False)   # the sections already match edge by edge; the check would split edges
    loft.SetMaxDegree(3)
    for k in range(N_SECTIONS):
        loft.AddWire(blade_section(SPAN * k / (N_SECTIONS - 1)))
    loft.Build()
    return TopoDS.Solid_s(loft.Shape())


def make_block() -> TopoDS_Solid:
    import cadquery as cq
    wp = cq.Workplane("XY").box(60.0, 40.0, 20.0).edges("|Z").fillet(6.0).edges(">Z").fillet(3.0)
    return TopoDS.Solid_s(wp.solids().val().wrapped)


def check_solid(shape: TopoDS_Shape, name: str) -> None:
    """Raise if ``shape`` is not one valid, closed solid of positive volume."""
    if shape.ShapeType() != TopAbs_SOLID:
        raise RuntimeError(f"{name}: not a solid")
    if not BRepCheck_Analyzer(shape).IsValid():
        raise RuntimeError(f"{name}: BRepCheck_Analyzer finds it invalid")
    shells = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, TopAbs_SHELL, shells)
    if shells.Extent() != 1 or not BRep_Tool.IsClosed_s(shells.FindKey(1)):
        raise RuntimeError(f"{name}: not one closed shell")
    ancestors = TopTools_IndexedDataMapOfShapeListOfShape()
    TopExp.MapShapesAndAncestors_s(shape, TopAbs_EDGE, TopAbs_FACE, ancestors)
    for i in range(1, ancestors.Extent() + 1):
        if ancestors.FindFromIndex(i).Size() != 2 and not BRep_Tool.Degenerated_s(TopoDS.Edge_s(ancestors.FindKey(i))):
            raise RuntimeError(f"{name}: edge {i - 1} bounds {ancestors.FindFromIndex(i).Size()} faces")
    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props)
    if not props.Mass() > 0:
        raise RuntimeError(f"{name}: volume {props.Mass()}")


def write_step(shape: TopoDS_Shape, path: Path, author: str = "hot2cold sample_parts/make_samples.py") -> None:
    """AP214 STEP with a fixed header (``author`` names the script), so a re-run writes the same bytes."""
    writer = STEPControl_Writer()   # set the statics after creating the writer, which initialises them
    Interface_Static.SetCVal_s("write.step.schema", "AP214IS")
    Interface_Static.SetCVal_s("write.step.product.name", path.stem)
    if writer.Transfer(shape, STEPControl_AsIs) != IFSelect_RetDone:
        raise RuntimeError(f"cannot transfer {path.name}")
    header = APIHeaderSection_MakeHeader(writer.Model())
    header.SetName(TCollection_HAsciiString(path.name))
    header.SetTimeStamp(TCollection_HAsciiString("2024-01-01T00:00:00"))
    header.SetAuthorValue(1, TCollection_HAsciiString(author))
    header.SetOrganizationValue(1, TCollection_HAsciiString("hot2cold"))
    if writer.Write(str(path)) != IFSelect_RetDone:
        raise RuntimeError(f"cannot write {path}")


def read_step(path: Path) -> TopoDS_Solid:
    reader = STEPControl_Reader()
    if reader.ReadFile(str(path)) != IFSelect_RetDone:
        raise RuntimeError(f"cannot read {path}")
    reader.TransferRoots()
    shape = reader.OneShape()
    solids = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(shape, TopAbs_SOLID, solids)
    if solids.Extent() != 1:
        raise RuntimeError(f"{path.name}: {solids.Extent()} solids")
    return TopoDS.Solid_s(solids.FindKey(1))


def write_field(path: Path, shape: TopoDS_Shape, field, seed: int, spacing: float) -> np.ndarray:
    """FE-like surface nodes plus volume nodes of ``shape``, shuffled, with ``field`` displacements.

    Returns the displacements ``(N, 3)``.
    """
    surface, _ = fe_surface_nodes(shape, spacing, seed=seed)
    volume = volume_nodes(shape, N_VOLUME, seed=seed, margin=VOLUME_MARGIN)
    nodes = np.concatenate([surface, volume])
    nodes = nodes[np.random.default_rng(seed).permutation(len(nodes))]
    disp = field(nodes)
    with open(path, "w", newline="\n") as f:
        f.write("id,x,y,z,dx,dy,dz\n")
        for i, (p, d) in enumerate(zip(nodes, disp)):
            f.write(f"{i},{p[0]:.12g},{p[1]:.12g},{p[2]:.12g},{d[0]:.12g},{d[1]:.12g},{d[2]:.12g}\n")
    print(f"{path.name}: {len(surface)} surface + {len(volume)} volume nodes, "
          f"max |d| = {np.linalg.norm(disp, axis=1).max():.4f} mm, {path.stat().st_size / 1e6:.2f} MB")
    return disp


#: The fields of the sample parts (also used by tests and benchmarks).
BLADE_FIELD = UntwistField(axis_point=(0.0, 0.0, 0.0), span_axis=(0.0, 0.0, 1.0), untwist_deg_per_mm=0.03,
                           stretch_per_mm2=1e-4, z0=0.0)
BLOCK_FIELD = AffineField.thermal(contraction=-0.004, rotation_deg=0.3, axis=(0.2, 0.3, 1.0),
                                  translation=(0.1, -0.2, 0.05), center=(0.0, 0.0, 0.0))


def main() -> int:
    Message.DefaultMessenger_s().Printers().First().SetTraceLevel(Message_Gravity.Message_Fail)
    parts = [("twisted_blade", make_blade, BLADE_FIELD), ("filleted_block", make_block, BLOCK_FIELD)]
    for name, build, field in parts:
        step = HERE / f"{name}.step"
        shape = build()
        check_solid(shape, name)
        write_step(shape, step)
        shape = read_step(step)
        check_solid(shape, f"{name} (read back)")
        kinds = [BRep_Tool.Surface_s(f).DynamicType().Name() for f in face_list(shape)]
        print(f"{step.name}: {len(kinds)} faces: {', '.join(kinds)}")
        write_field(HERE / f"{name}_field.csv", shape, field, SEED, SPACING[name])
    return 0


if __name__ == "__main__":
    sys.exit(main())
