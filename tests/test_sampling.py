"""Face samples, FE-like surface nodes, volume nodes, the synthetic fields and the sample parts."""
from __future__ import annotations

import importlib.util
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.BRepClass3d import BRepClass3d_SolidClassifier
from OCP.BRepExtrema import BRepExtrema_DistShapeShape
from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
from OCP.gp import gp_Pnt, gp_Trsf, gp_Vec
from OCP.IFSelect import IFSelect_RetDone
from OCP.STEPControl import STEPControl_Reader
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_IN, TopAbs_SHELL, TopAbs_SOLID, TopAbs_VERTEX
from OCP.TopExp import TopExp
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Compound
from OCP.TopTools import TopTools_IndexedMapOfShape
from scipy.spatial import cKDTree

from hot2cold.kernel.sampling import edge_list, face_list, face_samples, fe_surface_nodes, volume_nodes
from hot2cold.testing.synthetic import AffineField, UntwistField, ZeroField, rotation_matrix

PARTS = Path(__file__).resolve().parents[1] / "sample_parts"
SPACING = 2.0


def _read_step(path: Path):
    reader = STEPControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_RetDone
    reader.TransferRoots()
    m = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(reader.OneShape(), TopAbs_SOLID, m)
    assert m.Extent() == 1
    return TopoDS.Solid_s(m.FindKey(1))


@pytest.fixture(scope="module")
def blade():
    return _read_step(PARTS / "twisted_blade.step")


@pytest.fixture(scope="module")
def block():
    return _read_step(PARTS / "filleted_block.step")


@pytest.fixture(scope="module", params=["blade", "block"])
def part(request, blade, block):
    return {"blade": blade, "block": block}[request.param]


@pytest.fixture(scope="module")
def make_samples():
    spec = importlib.util.spec_from_file_location("make_samples", PARTS / "make_samples.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _compound(shapes):
    comp = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(comp)
    for s in shapes:
        builder.Add(comp, s)
    return comp


def _distances(shape, points: np.ndarray) -> np.ndarray:
    """Distances ``(m,)`` of ``points (m, 3)`` to ``shape`` (a face, edge or compound of them)."""
    dist = BRepExtrema_DistShapeShape()
    dist.LoadS1(shape)
    out = np.empty(len(points))
    for i, p in enumerate(points):
        dist.LoadS2(BRepBuilderAPI_MakeVertex(gp_Pnt(*p)).Vertex())
        dist.Perform()
        assert dist.IsDone()
        out[i] = dist.Value()
    return out


def _subset(a: np.ndarray, n: int, seed: int = 1) -> np.ndarray:
    if len(a) <= n:
        return a
    return a[np.sort(np.random.default_rng(seed).choice(len(a), n, replace=False))]


# --------------------------------------------------------------------------------------------- sample parts

def test_sample_parts_topology(blade, block):
    for solid in (blade, block):
        assert BRepCheck_Analyzer(solid).IsValid()
        shells = TopTools_IndexedMapOfShape()
        TopExp.MapShapes_s(solid, TopAbs_SHELL, shells)
        assert shells.Extent() == 1 and BRep_Tool.IsClosed_s(shells.FindKey(1))
    kinds = {name: Counter(BRep_Tool.Surface_s(f).DynamicType().Name() for f in face_list(s))
             for name, s in (("blade", blade), ("block", block))}
    assert kinds["blade"] == {"Geom_BSplineSurface": 4, "Geom_Plane": 2}
    assert kinds["block"] == {"Geom_Plane": 6, "Geom_CylindricalSurface": 8, "Geom_ToroidalSurface": 4}
    assert (len(edge_list(blade)), len(edge_list(block))) == (12, 40)


def test_face_list_is_map_order(block):
    m = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(block, TopAbs_FACE, m)
    faces = face_list(block)
    assert len(faces) == m.Extent() == 18
    for k, f in enumerate(faces):
        assert f.IsSame(m.FindKey(k + 1))


# --------------------------------------------------------------------------------------------- face_samples

def test_face_samples_on_and_inside_faces(part):
    spacing = 4.0
    faces = face_list(part)
    samples = face_samples(part, spacing)
    assert len(samples) == len(faces)
    for face, (uv, pts) in zip(faces, samples):
        assert uv.ndim == 2 and uv.shape[1] == 2 and pts.shape == (len(uv), 3) and len(uv) >= 1
        surface = BRep_Tool.Surface_s(face)
        # the points are the surface at uv ...
        for (u, v), p in zip(uv, pts):
            q = surface.Value(u, v)
            assert np.linalg.norm(p - [q.X(), q.Y(), q.Z()]) < 1e-12
        check = _subset(np.arange(len(uv)), 60)
        # ... on the surface by an independent projection ...
        for p in pts[check]:
            proj = GeomAPI_ProjectPointOnSurf(gp_Pnt(*p), surface)
            assert proj.NbPoints() >= 1 and proj.LowerDistance() < 1e-7
        # ... and inside the trimmed face: distance 0 to the face, positive to its boundary
        assert np.max(_distances(face, pts[check])) < 1e-7
        edges = TopTools_IndexedMapOfShape()
        TopExp.MapShapes_s(face, TopAbs_EDGE, edges)
        boundary = _compound([edges.FindKey(i) for i in range(1, edges.Extent() + 1)])
        assert np.min(_distances(boundary, pts[check])) > 1e-6


def test_face_samples_spacing(block):
    for spacing in (2.0, 5.0):
        samples = face_samples(block, spacing)
        top = max(range(len(samples)), key=lambda k: len(samples[k][0]))  # the large bottom/top plane
        pts = samples[top][1]
        d, _ = cKDTree(pts).query(pts, k=2)
        assert 0.7 * spacing < np.median(d[:, 1]) <= spacing + 1e-9
        assert sum(len(uv) for uv, _ in samples) > 2 * 60 * 40 / spacing ** 2


def test_face_samples_small_faces_get_a_sample(blade, block):
    for solid in (blade, block):
        assert all(len(uv) >= 1 for uv, _ in face_samples(solid, 50.0))


def test_face_samples_apply_location():
    box = BRepPrimAPI_MakeBox(10.0, 20.0, 30.0).Shape()
    trsf = gp_Trsf()
    trsf.SetTranslation(gp_Vec(100.0, -50.0, 7.0))
    moved = box.Moved(TopLoc_Location(trsf))
    for (uv0, p0), (uv1, p1) in zip(face_samples(box, 3.0), face_samples(moved, 3.0)):
        np.testing.assert_allclose(uv1, uv0, atol=1e-12)
        np.testing.assert_allclose(p1, p0 + [100.0, -50.0, 7.0], atol=1e-12)


# --------------------------------------------------------------------------------------------- FE-like nodes

def test_fe_surface_nodes_cover_every_face(part):
    points, face_index = fe_surface_nodes(part, SPACING, seed=0)
    faces = face_list(part)
    assert points.shape == (len(face_index), 3) and face_index.dtype.kind == "i"
    assert set(np.unique(face_index)) <= set(range(-1, len(faces)))
    tree = cKDTree(points)
    for k, (_, samples) in enumerate(face_samples(part, SPACING)):
        d, _ = tree.query(samples)
        assert d.min() < SPACING, f"face {k} has no node near it"
        assert np.count_nonzero(face_index == k) >= 1, f"face {k} has no interior node"
    # no two nodes crowd each other, and none is far from all others
    d, _ = tree.query(points, k=2)
    assert d[:, 1].min() > SPACING / 5
    assert d[:, 1].max() < 1.5 * SPACING


def test_fe_surface_nodes_vertices_edges_faces(part):
    points, face_index = fe_surface_nodes(part, SPACING, seed=3)
    tree = cKDTree(points)
    vmap = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(part, TopAbs_VERTEX, vmap)
    vertices = np.array([[*BRep_Tool.Pnt_s(TopoDS.Vertex_s(vmap.FindKey(i))).Coord()]
                         for i in range(1, vmap.Extent() + 1)])
    d, _ = tree.query(vertices)
    assert d.max() < 1e-12                                      # every vertex is a node
    assert np.all(face_index[:len(vertices)] == -1)
    boundary = points[face_index == -1]
    assert len(boundary) > len(vertices)
    edges = edge_list(part)
    # every boundary node lies on an edge, and each edge (seen once) carries its nodes only once
    dist_edges = np.array([_distances(e, boundary) for e in edges])  # (n_edges, n_boundary)
    assert dist_edges.min(axis=0).max() < 1e-7
    d, _ = cKDTree(boundary).query(boundary, k=2)
    assert d[:, 1].min() > SPACING / 4
    # face nodes are on their face and keep about spacing / 3 from its edges
    faces = face_list(part)
    for k, face in enumerate(faces):
        pts = _subset(points[face_index == k], 40)
        assert np.max(_distances(face, pts)) < 1e-7
        emap = TopTools_IndexedMapOfShape()
        TopExp.MapShapes_s(face, TopAbs_EDGE, emap)
        rim = _compound([emap.FindKey(i) for i in range(1, emap.Extent() + 1)])
        assert np.min(_distances(rim, pts)) > SPACING / 3 - 0.05 * SPACING


def test_fe_surface_nodes_deterministic(block):
    a, fa = fe_surface_nodes(block, SPACING, seed=7)
    b, fb = fe_surface_nodes(block, SPACING, seed=7)
    c, _ = fe_surface_nodes(block, SPACING, seed=8)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(fa, fb)
    assert a.shape != c.shape or not np.array_equal(a, c)


@pytest.mark.heavy
def test_volume_nodes_inside_with_margin(part):
    margin = 0.5
    pts = volume_nodes(part, 40, seed=0, margin=margin)
    assert pts.shape == (40, 3)
    classifier = BRepClass3d_SolidClassifier(part)
    for p in pts:
        classifier.Perform(gp_Pnt(*p), 1e-7)
        assert classifier.State() == TopAbs_IN
    skin = _compound(face_list(part))
    assert _distances(skin, pts).min() >= margin
    np.testing.assert_array_equal(pts, volume_nodes(part, 40, seed=0, margin=margin))
    assert len(np.unique(pts, axis=0)) == 40


def test_volume_nodes_impossible_margin(blade):
    with pytest.raises(ValueError):
        volume_nodes(blade, 5, margin=5.0, max_candidates=256)  # the blade is only 3.4 mm thick


# --------------------------------------------------------------------------------------------- fields

def _affine_residual(field, points: np.ndarray) -> float:
    """Largest residual (mm) of the least-squares affine fit of ``field.exact_map`` on ``points (N, 3)``."""
    a = np.column_stack([points, np.ones(len(points))])
    target = field.exact_map(points)
    coef, *_ = np.linalg.lstsq(a, target, rcond=None)
    return float(np.abs(a @ coef - target).max())


def test_affine_field_is_affine():
    rng = np.random.default_rng(0)
    field = AffineField.thermal(contraction=-0.005, rotation_deg=0.3, axis=(0.2, 0.3, 1.0),
                                translation=(0.1, -0.2, 0.05), center=(5.0, 1.0, -2.0))
    x, y = rng.uniform(-50, 50, (2, 200, 3))
    t = rng.uniform(-1, 2, (200, 1))
    np.testing.assert_allclose(field.exact_map(t * x + (1 - t) * y),
                               t * field.exact_map(x) + (1 - t) * field.exact_map(y), atol=1e-11)
    np.testing.assert_allclose(field(x), field.exact_map(x) - x, atol=1e-13)
    assert _affine_residual(field, x) < 1e-11
    # uniform scale by 0.995 times a rotation of 0.3 degrees, centre moved by the translation
    r = field.matrix / 0.995
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(r) == pytest.approx(1.0)
    assert np.degrees(np.arccos((np.trace(r) - 1) / 2)) == pytest.approx(0.3, rel=1e-6)
    np.testing.assert_allclose(field.exact_map(np.array([[5.0, 1.0, -2.0]])), [[5.1, 0.8, -1.95]], atol=1e-12)
    dx = np.linalg.norm(field.exact_map(x) - field.exact_map(y), axis=1)
    np.testing.assert_allclose(dx, 0.995 * np.linalg.norm(x - y, axis=1), rtol=1e-12)
    with pytest.raises(ValueError):
        AffineField(np.eye(2), np.zeros(3))
    with pytest.raises(ValueError):
        field.matrix[0, 0] = 2.0                                 # frozen: read-only arrays


def test_untwist_field_not_affine_and_in_range(blade, make_samples):
    field = make_samples.BLADE_FIELD
    assert isinstance(field, UntwistField)
    points, _ = fe_surface_nodes(blade, SPACING)
    mag = np.linalg.norm(field(points), axis=1)
    assert 1.0 < mag.max() < 3.0
    assert mag[points[:, 2] < 1e-6].max() < 1e-12              # nothing moves at the hub, z = z0 = 0
    assert _affine_residual(field, points) > 0.05                # clearly not affine
    # a rotation about the z axis plus a z shift: distance to the axis kept, z moved by c (z - z0)^2
    cold = field.exact_map(points)
    np.testing.assert_allclose(np.linalg.norm(cold[:, :2], axis=1), np.linalg.norm(points[:, :2], axis=1),
                               atol=1e-12)
    np.testing.assert_allclose(cold[:, 2] - points[:, 2], 1e-4 * points[:, 2] ** 2, atol=1e-12)
    p2, c2 = points[:, :2], cold[:, :2]
    angle = np.degrees(np.arctan2(p2[:, 0] * c2[:, 1] - p2[:, 1] * c2[:, 0], (p2 * c2).sum(axis=1)))
    far = np.linalg.norm(points[:, :2], axis=1) > 1.0
    np.testing.assert_allclose(angle[far], 0.03 * points[far, 2], atol=1e-9)


def test_untwist_field_general_axis():
    rot = rotation_matrix((1.0, -2.0, 0.5), 40.0)
    a = UntwistField(axis_point=(0.0, 0.0, 0.0), span_axis=(0.0, 0.0, 1.0), untwist_deg_per_mm=0.05,
                     stretch_per_mm2=2e-4, z0=10.0)
    b = UntwistField(axis_point=rot @ [0.0, 0.0, 0.0], span_axis=rot @ [0.0, 0.0, 3.0], untwist_deg_per_mm=0.05,
                     stretch_per_mm2=2e-4, z0=10.0)
    x = np.random.default_rng(2).uniform(-30, 30, (100, 3))
    np.testing.assert_allclose(b(x @ rot.T), a(x) @ rot.T, atol=1e-12)  # the field turns with its axis


def test_zero_field():
    x = np.random.default_rng(3).normal(size=(10, 3))
    np.testing.assert_array_equal(ZeroField()(x), np.zeros((10, 3)))
    np.testing.assert_array_equal(ZeroField().exact_map(x), x)


# --------------------------------------------------------------------------------------------- field files

@pytest.mark.parametrize("name, field_name, low, high",
                         [("twisted_blade", "BLADE_FIELD", 1.0, 3.0), ("filleted_block", "BLOCK_FIELD", 0.1, 1.0)])
def test_field_files(name, field_name, low, high, make_samples, blade, block):
    path = PARTS / f"{name}_field.csv"
    assert path.stat().st_size < 3e6
    assert path.read_text().splitlines()[0] == "id,x,y,z,dx,dy,dz"
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(data[:, 0], np.arange(len(data)))
    xyz, disp = data[:, 1:4], data[:, 4:7]
    field = getattr(make_samples, field_name)
    np.testing.assert_allclose(disp, field(xyz), rtol=0, atol=1e-10)
    assert low < np.linalg.norm(disp, axis=1).max() < high
    # the file holds exactly the seed-0 FE surface nodes of the part plus 500 volume nodes, shuffled
    solid = {"twisted_blade": blade, "filleted_block": block}[name]
    surface, face_index = fe_surface_nodes(solid, make_samples.SPACING[name], seed=make_samples.SEED)
    assert len(data) == len(surface) + make_samples.N_VOLUME
    d, _ = cKDTree(xyz).query(surface)
    assert d.max() < 1e-9
    assert not np.array_equal(xyz[:len(surface)], surface)        # shuffled
    d_surf, _ = cKDTree(surface).query(xyz)
    assert np.count_nonzero(d_surf > 1e-9) == make_samples.N_VOLUME
