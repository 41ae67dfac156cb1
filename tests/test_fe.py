"""Tests of the FE pipeline (hot2cold.fe): gmsh meshes, CalculiX decks and runs, physics of the results.

Everything runs the real tools on small parts: gmsh (the ``fe`` extra, part of ``.[test]``) and CalculiX's
``ccx`` (Debian/Ubuntu package ``calculix-ccx``).  Tests that need ccx are skipped only when it is not on
the PATH.
"""
from __future__ import annotations

import os
from pathlib import Path

import cadquery as cq
import gmsh
import numpy as np
import pytest

import hot2cold.fe.calculix as calculix
from hot2cold.errors import StepReadError
from hot2cold.fe import SolverError, TetMesh, mesh_step
from hot2cold.fe.calculix import (TI6AL4V, LoadCase, Material, MeshOptions, SolverOptions, blade_temperature,
                                  hot_to_cold_field, hub_faces, read_hot_to_cold, run_ccx, write_deck)
from hot2cold.io.frd import read_frd
from hot2cold.io.field import read_field
from hot2cold.kernel.project import Projector
from hot2cold.kernel.sampling import face_list
from hot2cold.kernel.step import read_step

#: Every test here meshes with gmsh; those that solve need CalculiX's ``ccx`` on the PATH (Debian/Ubuntu:
#: ``apt-get install calculix-ccx``): without it they fail; ``-m "not calculix"`` leaves them out.
pytestmark = pytest.mark.gmsh
needs_ccx = pytest.mark.calculix

SAMPLES = Path(__file__).resolve().parent.parent / "sample_parts"
ALPHA, E, RHO = TI6AL4V.expansion, TI6AL4V.young, TI6AL4V.density


def export(shape, path: Path) -> Path:
    cq.exporters.export(shape, str(path))
    return path


@pytest.fixture(scope="module")
def parts(tmp_path_factory):
    """Small STEP parts: a bar from the origin, a radial rod at radius 100..140, a cylinder."""
    d = tmp_path_factory.mktemp("parts")
    return {
        "bar": export(cq.Workplane().box(40, 8, 8, centered=False), d / "bar.step"),
        "rod": export(cq.Workplane().box(40, 2, 2, centered=False).translate((100, 0, 0)), d / "rod.step"),
        "blade": export(cq.Workplane().box(40, 4, 4, centered=False).translate((100, -2, 0)), d / "blade.step"),
        "cylinder": export(cq.Workplane("XY").circle(10).extrude(30), d / "cylinder.step"),
    }


@pytest.fixture(scope="module")
def bar_mesh(parts):
    return mesh_step(parts["bar"], 2.0)


@pytest.fixture(scope="module")
def rod_mesh(parts):
    return mesh_step(parts["rod"], 1.0)


def sliding(mesh: TetMesh, origin=(0.0, 0.0, 0.0)) -> dict[int, np.ndarray]:
    """Symmetry-plane supports: axis a fixed on the plane x_a = origin_a (free thermal contraction)."""
    return {a: np.flatnonzero(np.abs(mesh.nodes[:, a] - origin[a]) < 1e-9) for a in range(3)}


# ---------------------------------------------------------------------------------------------------------
# Meshing
# ---------------------------------------------------------------------------------------------------------
def test_mesh_second_order_on_cylinder(parts):
    mesh = mesh_step(parts["cylinder"], 3.0)
    assert isinstance(mesh, TetMesh) and mesh.order == 2
    n = len(mesh.nodes)
    assert mesh.nodes.shape == (n, 3) and mesh.tets.shape[1] == 10 and mesh.tets.dtype == np.int64
    assert mesh.tets.min() == 0 and mesh.tets.max() == n - 1
    np.testing.assert_array_equal(mesh.node_tags, np.arange(1, n + 1))
    assert sorted(mesh.surface_nodes) == [1, 2, 3]
    # Every node of the cylindrical face, midside nodes included, lies on the curved CAD surface.
    side = max(mesh.surface_nodes, key=lambda s: len(mesh.surface_nodes[s]))
    r = np.hypot(*mesh.nodes[mesh.surface_nodes[side], :2].T)
    mid = np.intersect1d(mesh.surface_nodes[side], mesh.tets[:, 4:])
    assert len(mid) > 100
    np.testing.assert_allclose(r, 10.0, atol=1e-9)
    np.testing.assert_array_equal(mesh.face_nodes(side - 1), mesh.surface_nodes[side])
    # Volume of the straight-sided corner tetrahedra is positive: gmsh's orientation.
    p = mesh.nodes[mesh.tets[:, :4]]
    vol = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6
    assert vol.min() > 0
    assert vol.sum() == pytest.approx(np.pi * 100 * 30, rel=2e-2)
    with pytest.raises(IndexError, match="no face 3"):
        mesh.face_nodes(3)


def test_mesh_is_reproducible_and_gmsh_is_finalised(parts):
    a = mesh_step(parts["bar"], 2.5)
    b = mesh_step(parts["bar"], 2.5)
    np.testing.assert_array_equal(a.nodes, b.nodes)
    np.testing.assert_array_equal(a.tets, b.tets)
    assert not gmsh.isInitialized()
    first = mesh_step(parts["bar"], 2.5, order=1)
    assert first.tets.shape[1] == 4 and first.order == 1


def test_mesh_in_a_running_gmsh_session_leaves_it_alone(parts):
    gmsh.initialize([], readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("mine")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 123.0)
        mesh = mesh_step(parts["bar"], 2.5)
        assert gmsh.isInitialized()
        assert gmsh.model.getCurrent() == "mine"
        assert gmsh.option.getNumber("Mesh.MeshSizeMax") == 123.0
        assert len(mesh.nodes) > 100
    finally:
        gmsh.finalize()


def test_mesh_errors(parts, tmp_path):
    with pytest.raises(StepReadError, match="STEP file not found"):
        mesh_step(tmp_path / "missing.step", 1.0)
    junk = tmp_path / "junk.step"
    junk.write_text("this is not STEP\n")
    with pytest.raises(StepReadError, match="junk.step"):
        mesh_step(junk, 1.0)
    assert not gmsh.isInitialized()
    with pytest.raises(ValueError, match="size must be a positive"):
        mesh_step(parts["bar"], 0)
    with pytest.raises(ValueError, match="min_size must lie in"):
        mesh_step(parts["bar"], 1.0, min_size=2.0)
    with pytest.raises(ValueError, match="order must be 1 or 2"):
        mesh_step(parts["bar"], 1.0, order=3)


@pytest.mark.heavy
@pytest.mark.parametrize("name, size", [("filleted_block.step", 10.0), ("rotor37_blade.step", 8.0),
                                        ("twisted_blade.step", 8.0)])
def test_gmsh_surface_k_plus_1_is_hot2cold_face_k(name, size, caplog):
    """gmsh numbers the STEP's faces in hot2cold's order (TopExp.MapShapes), shifted by one."""
    path = SAMPLES / name
    mesh = mesh_step(path, size, min_size=size / 8)
    faces = face_list(read_step(path))
    assert sorted(mesh.surface_nodes) == list(range(1, len(faces) + 1))
    projector = Projector(faces, [])
    corners = np.unique(mesh.tets[:, :4])  # mesh vertices: exactly on the CAD surface
    for k in range(len(faces)):
        nodes = np.intersect1d(mesh.face_nodes(k), corners)
        pick = nodes[np.linspace(0, len(nodes) - 1, min(len(nodes), 25)).astype(int)]
        _, dist = projector.to_face(k, mesh.nodes[pick])
        assert dist.max() < 1e-3, f"{name}: gmsh surface {k + 1} is not face {k}"  # edge tolerances


# ---------------------------------------------------------------------------------------------------------
# Deck
# ---------------------------------------------------------------------------------------------------------
def test_deck_layout(bar_mesh, tmp_path):
    fixed = sliding(bar_mesh)
    deck = write_deck(bar_mesh, tmp_path / "job.inp", fixed_nodes=fixed, hot_temperature=500.0, omega=1800.0,
                      axis_point=(1, 2, 3), axis_direction=(0, 0, 2))
    text = deck.read_text()
    assert "*HEADING\nhot2cold hot-to-cold: U = U(last step) - U(first step)\n" in text
    lines = text.splitlines()
    assert max(map(len, lines)) <= 132
    k = lines.index("*ELEMENT, TYPE=C3D10, ELSET=EALL")
    elements = np.array([[int(v) for v in ln.split(",")] for ln in lines[k + 1:k + 1 + len(bar_mesh.tets)]])
    np.testing.assert_array_equal(elements[:, 0], np.arange(1, len(bar_mesh.tets) + 1))
    # gmsh's last two midside nodes (edges 2-3, 1-3) are CalculiX's 1-3, 2-3: swapped.
    swap = [0, 1, 2, 3, 4, 5, 6, 7, 9, 8]
    np.testing.assert_array_equal(elements[:, 1:], bar_mesh.node_tags[bar_mesh.tets[:, swap]])
    # Step 1 rotates (positive omega^2, temperatures stay hot), step 2 removes it and cools.
    assert text.count("*STEP") == 2
    s1, s2 = text.split("*STEP")[1:]
    assert "EALL, CENTRIF, 3240000, 1, 2, 3, 0, 0, 1" in s1 and "*TEMPERATURE" not in s1
    assert "*DLOAD, OP=NEW" in s2 and "NALL, 293\n" in s2 and "CENTRIF" not in s2
    assert "*INITIAL CONDITIONS, TYPE=TEMPERATURE\n1, 500\n" in text
    assert "*ELASTIC\n110000, 0.34\n*DENSITY\n4.43e-09\n*EXPANSION\n9e-06\n" in text
    assert "FIX0, 1, 1\nFIX1, 2, 2\nFIX2, 3, 3" in text
    # Without rotation: one step.
    text = write_deck(bar_mesh, tmp_path / "still.inp", fixed_nodes=[0, 1], hot_temperature=400.0).read_text()
    assert text.count("*STEP") == 1 and "CENTRIF" not in text and "FIX0, 1, 3" in text


def test_deck_errors(bar_mesh, tmp_path):
    kw = dict(fixed_nodes=[0], hot_temperature=400.0)
    with pytest.raises(ValueError, match=r"must end in \.inp"):
        write_deck(bar_mesh, tmp_path / "job.txt", **kw)
    with pytest.raises(ValueError, match="hot_temperature must be"):
        write_deck(bar_mesh, tmp_path / "job.inp", fixed_nodes=[0], hot_temperature=np.ones(3))
    with pytest.raises(ValueError, match="no fixed node"):
        write_deck(bar_mesh, tmp_path / "job.inp", fixed_nodes=[], hot_temperature=400.0)
    with pytest.raises(ValueError, match="fixed node indices must lie in"):
        write_deck(bar_mesh, tmp_path / "job.inp", fixed_nodes=[10 ** 7], hot_temperature=400.0)
    with pytest.raises(ValueError, match="keys must be axes"):
        write_deck(bar_mesh, tmp_path / "job.inp", fixed_nodes={3: [0]}, hot_temperature=400.0)
    with pytest.raises(ValueError, match="axis_direction must not be zero"):
        write_deck(bar_mesh, tmp_path / "job.inp", omega=1.0, axis_direction=(0, 0, 0), **kw)
    with pytest.raises(ValueError, match="material"):
        Material(name="bad name")


def test_blade_temperature_and_hub_face(parts):
    pts = np.array([[100.0, 0, 0], [0, 140.0, 5.0], [0, 120.0, -3.0]])
    np.testing.assert_allclose(blade_temperature(pts), [420.0, 480.0, 450.0])
    mesh = mesh_step(parts["blade"], 2.0)
    (hub,) = hub_faces(mesh)
    np.testing.assert_allclose(mesh.nodes[mesh.face_nodes(hub), 0], 100.0)


# ---------------------------------------------------------------------------------------------------------
# CalculiX runs: physics
# ---------------------------------------------------------------------------------------------------------
@needs_ccx
def test_free_thermal_contraction_is_exact(bar_mesh, tmp_path):
    """A bar on sliding supports cooled by 200 K contracts by alpha * dT * x everywhere."""
    deck = write_deck(bar_mesh, tmp_path / "thermal.inp", fixed_nodes=sliding(bar_mesh), hot_temperature=493.0,
                      room_temperature=293.0)
    frd = run_ccx(deck, timeout=120)
    field = read_hot_to_cold(frd, points_from=bar_mesh)
    assert read_frd(frd).count == 1
    np.testing.assert_array_equal(field.points, bar_mesh.nodes)
    np.testing.assert_array_equal(field.node_ids, bar_mesh.node_tags)
    exact = ALPHA * (293.0 - 493.0) * bar_mesh.nodes
    tip = np.abs(bar_mesh.nodes[:, 0] - 40.0) < 1e-9
    contraction = -field.displacements[tip, 0].mean()
    assert contraction == pytest.approx(ALPHA * 200.0 * 40.0, rel=1e-2)  # 0.072 mm
    assert contraction == pytest.approx(0.072, rel=1e-5)
    # Every node, midside nodes included (the C3D10 node order is right), to the .frd's 6 digits.
    np.testing.assert_allclose(field.displacements, exact, atol=1e-6)
    # The .frd's own coordinates are the mesh's, rounded.
    own = read_field(frd)
    np.testing.assert_allclose(own.points, bar_mesh.nodes, rtol=1e-5, atol=1e-9)
    np.testing.assert_array_equal(own.displacements, field.displacements)


@needs_ccx
def test_centrifugal_rod_against_analytic(rod_mesh, tmp_path):
    """A thin rod from r0 = 100 to r1 = 140 mm spinning about z: u(r1) = rho w^2 / (2E) (r1^2 L - (r1^3 - r0^3) / 3).

    Hot to cold removes the rotation: the tip moves inwards by that much.
    """
    r0, r1, omega = 100.0, 140.0, 1800.0
    fixed = sliding(rod_mesh, origin=(r0, 0.0, 0.0))
    deck = write_deck(rod_mesh, tmp_path / "spin.inp", fixed_nodes=fixed, hot_temperature=293.0, omega=omega)
    frd = run_ccx(deck, timeout=120)
    field = read_hot_to_cold(frd, points_from=rod_mesh)
    assert read_frd(frd).count == 2
    same = read_field(frd, points_from=rod_mesh)  # recognises hot2cold's deck by its heading
    np.testing.assert_array_equal(same.displacements, field.displacements)
    np.testing.assert_array_equal(same.points, rod_mesh.nodes)
    analytic = RHO * omega ** 2 / (2 * E) * (r1 ** 2 * (r1 - r0) - (r1 ** 3 - r0 ** 3) / 3)   # 0.01322 mm
    tip = np.abs(rod_mesh.nodes[:, 0] - r1) < 1e-9
    u_tip = field.displacements[tip, 0].mean()
    assert u_tip < 0  # inwards: the running part is stretched, the cold one shorter
    assert -u_tip == pytest.approx(analytic, rel=1e-2)
    # Along the rod too (nodes on the axis line y = z = 0).
    line = (np.abs(rod_mesh.nodes[:, 1]) < 1e-9) & (np.abs(rod_mesh.nodes[:, 2]) < 1e-9)
    x = rod_mesh.nodes[line, 0]
    u = RHO * omega ** 2 / (2 * E) * (r1 ** 2 * (x - r0) - (x ** 3 - r0 ** 3) / 3)
    np.testing.assert_allclose(field.displacements[line, 0], -u, atol=2e-2 * analytic)


@needs_ccx
def test_negative_centrif_is_ignored_by_ccx(rod_mesh, tmp_path):
    """Why the deck has two steps: ccx 2.20 drops a CENTRIF load of magnitude -omega^2 without a word."""
    fixed = sliding(rod_mesh, origin=(100.0, 0.0, 0.0))
    deck = write_deck(rod_mesh, tmp_path / "spin.inp", fixed_nodes=fixed, hot_temperature=293.0, omega=1800.0)
    positive = read_frd(run_ccx(deck, timeout=120), step=0).values
    assert np.abs(positive).max() > 1e-3
    negative = tmp_path / "negative.inp"
    negative.write_text(deck.read_text().replace("CENTRIF, 3240000,", "CENTRIF, -3240000,"))
    dropped = read_frd(run_ccx(negative, timeout=120), step=0).values
    if np.abs(dropped).max() > 0:  # a later ccx may honour it: then it must be the exact opposite
        np.testing.assert_allclose(dropped, -positive, atol=1e-9)
    else:
        assert np.abs(dropped).max() == 0.0


@needs_ccx
def test_unswapped_c3d10_nodes_fail(rod_mesh, tmp_path, monkeypatch):
    """gmsh's own order in a C3D10 deck gives inverted elements: ccx stops with a Jacobian error."""
    monkeypatch.setattr(calculix, "GMSH_TO_C3D10", np.arange(10))
    deck = write_deck(rod_mesh, tmp_path / "wrong.inp", fixed_nodes=[0, 1, 2], hot_temperature=400.0)
    with pytest.raises(SolverError, match="nonpositive jacobian") as info:
        run_ccx(deck, timeout=120)
    assert "\n" not in str(info.value)


@needs_ccx
def test_run_ccx_errors(rod_mesh, tmp_path):
    deck = write_deck(rod_mesh, tmp_path / "ok.inp", fixed_nodes=[0, 1, 2], hot_temperature=400.0)
    with pytest.raises(SolverError, match=r"'no-such-ccx-h2c' not found on the PATH; install CalculiX"):
        run_ccx(deck, ccx="no-such-ccx-h2c")
    with pytest.raises(SolverError, match="deck not found"):
        run_ccx(tmp_path / "missing.inp")
    junk = tmp_path / "junk.inp"
    junk.write_text("*FOO\n")
    with pytest.raises(SolverError, match=r"ccx wrote no results into junk.frd .*its warnings: \*WARNING in calinput"):
        run_ccx(junk, timeout=60)
    with pytest.raises(SolverError, match=r"did not finish ok.inp within 0.001 s"):
        run_ccx(deck, timeout=0.001)


@needs_ccx
def test_hot_to_cold_field_pipeline(parts, tmp_path):
    """The whole pipeline on a blade-like box at radius 100..140 mm, root fixed (found as the hub face)."""
    out = tmp_path / "field.npz"
    field = hot_to_cold_field(parts["blade"], out, mesh=MeshOptions(size=1.5, min_size=0.5),
                              solver=SolverOptions(work_dir=tmp_path / "run"))
    assert (tmp_path / "run" / "hot2cold.frd").exists() and (tmp_path / "run" / "hot2cold.log").exists()
    mesh = mesh_step(parts["blade"], 1.5, 0.5)  # the same mesh again: reproducible
    surface = mesh.boundary_nodes()
    np.testing.assert_array_equal(field.points, mesh.nodes[surface])  # mesh positions, not the .frd's
    np.testing.assert_array_equal(field.node_ids, mesh.node_tags[surface])
    mask = os.umask(0)
    os.umask(mask)
    assert out.stat().st_mode & 0o777 == 0o666 & ~mask  # the umask's permissions, not mkstemp's 0600
    assert not list(tmp_path.glob(".field.npz*"))
    saved = read_field(out)
    np.testing.assert_array_equal(saved.points, field.points)
    np.testing.assert_array_equal(saved.displacements, field.displacements)
    np.testing.assert_array_equal(saved.node_ids, field.node_ids)
    # Root fixed; tip shortened by the thermal contraction plus the removed centrifugal stretch.
    x = field.points[:, 0]
    np.testing.assert_array_equal(field.displacements[x == 100.0], 0.0)
    r0, r1 = 100.0, 140.0
    thermal = ALPHA * (r1 - r0) * (450.0 - 293.0)  # mean of 420..480 K over the span: 0.0565 mm
    spin = RHO * 1800.0 ** 2 / (2 * E) * (r1 ** 2 * (r1 - r0) - (r1 ** 3 - r0 ** 3) / 3)  # 0.0132 mm
    u_tip = field.displacements[np.abs(x - r1) < 1e-9, 0].mean()
    assert -u_tip == pytest.approx(thermal + spin, rel=2e-2)
    # No rotation: thermal only.
    still = hot_to_cold_field(parts["blade"], None, mesh=MeshOptions(size=1.5, min_size=0.5), load=LoadCase(omega=0.0),
                              nodes="all")
    assert len(still) == len(mesh.nodes)
    x = still.points[:, 0]
    assert -still.displacements[np.abs(x - r1) < 1e-9, 0].mean() == pytest.approx(thermal, rel=2e-2)
