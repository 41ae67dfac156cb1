"""Viewer exports (VTU, STL, GLB, HTML) of a morph, and the command line's flags, progress and refusals."""
from __future__ import annotations

import errno
import io
import os
import re
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from hot2cold.views import export
from hot2cold.errors import OutputError
from hot2cold.core.model import Role
from hot2cold.cli.commands import _Progress, main
from hot2cold.testing.synthetic import AffineField

BLOCK_FIELD = AffineField.thermal(contraction=-0.004, rotation_deg=0.3, translation=(0.1, -0.2, 0.05))


@pytest.fixture(scope="module")
def blade_surface(blade):
    return export.cold_surface(blade)


# --- the library -----------------------------------------------------------------------------------------

@pytest.mark.heavy
def test_vtu_nodes_read_back_with_the_result_arrays(blade, blade_surface, tmp_path):
    nodes_path, surface_path = export.write_vtu(blade, tmp_path / "nodes.vtu", blade_surface)
    assert nodes_path == tmp_path / "nodes.vtu" and surface_path == tmp_path / "nodes_surface.vtu"
    m = meshio.read(nodes_path)
    n = len(blade.field.points)
    np.testing.assert_array_equal(m.points, blade.field.points)
    assert [(c.type, c.data.shape) for c in m.cells] == [("vertex", (n, 1))]
    np.testing.assert_array_equal(m.cells[0].data[:, 0], np.arange(n))
    assert set(m.point_data) == {"displacement", "error", "role", "owner", "node_id"}
    shapes = {name: a.shape for name, a in m.point_data.items()}
    assert shapes == {"displacement": (n, 3), "error": (n,), "role": (n,), "owner": (n,), "node_id": (n,)}
    np.testing.assert_array_equal(m.point_data["displacement"], blade.field.displacements)
    np.testing.assert_array_equal(m.point_data["error"], blade.node_errors)        # NaN where NaN
    np.testing.assert_array_equal(m.point_data["role"], blade.classification.role)
    np.testing.assert_array_equal(m.point_data["owner"], blade.classification.owner)
    np.testing.assert_array_equal(m.point_data["node_id"], blade.field.node_ids)
    ignored = m.point_data["role"] == Role.IGNORED
    assert ignored.sum() == blade.report.nodes_ignored == 500
    assert np.isnan(m.point_data["error"][ignored]).all() and np.isfinite(m.point_data["error"][~ignored]).all()
    assert np.nanmax(m.point_data["error"]) == pytest.approx(blade.report.delta_max, rel=1e-12)


def test_vtu_surface_has_faces_and_the_hot_to_cold_displacement(blade, blade_surface, tmp_path):
    _, surface_path = export.write_vtu(blade, tmp_path / "nodes.vtu", blade_surface)
    m = meshio.read(surface_path)
    assert [c.type for c in m.cells] == ["triangle"]
    np.testing.assert_array_equal(m.points, blade_surface.vertices)
    np.testing.assert_array_equal(m.cells[0].data, blade_surface.triangles)
    assert set(m.cell_data) == {"face"}
    face = m.cell_data["face"][0]
    assert face.shape == (len(blade_surface.triangles),) and set(face) == set(range(len(blade.part.faces)))
    assert set(m.point_data) == {"displacement", "uv"}
    d = m.point_data["displacement"]
    assert d.shape == m.points.shape and np.isfinite(d).all()
    np.testing.assert_array_equal(d, blade_surface.displacement)
    # Independent of the fit: each vertex's hot position (cold vertex - displacement) takes about the FE
    # displacement of the nearest used node, within the field's own variation over that distance.
    used = blade.classification.role != Role.IGNORED
    points, disp = blade.field.points[used], blade.field.displacements[used]
    tree = cKDTree(points)
    step, pair = tree.query(points, k=2)
    gradient = np.max(np.linalg.norm(disp[pair[:, 1]] - disp, axis=1) / step[:, 1])
    distance, nearest = tree.query(m.points - d)
    assert distance.max() < 1.0                                  # hot positions lie on the hot part
    diff = np.linalg.norm(disp[nearest] - d, axis=1)
    assert np.all(diff <= 1.1 * gradient * distance + 1e-3)
    assert np.linalg.norm(d, axis=1).max() == pytest.approx(blade.report.max_displacement, rel=0.02)


def test_stl_and_glb_are_watertight_with_the_cold_volume(blade, blade_surface, tmp_path):
    volume = blade.report.solids[0].volume_cold
    stl = export.write_stl(blade, tmp_path / "cold.stl", blade_surface)
    glb = export.write_glb(blade, tmp_path / "cold.glb", blade_surface)
    mesh = trimesh.load(stl)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert abs(mesh.volume / volume - 1) < 0.01                  # positive: triangles face outward
    scene = trimesh.load(glb)
    assert len(scene.geometry) == 1
    gmesh = scene.to_geometry()
    assert gmesh.is_watertight
    assert abs(gmesh.volume * 1e9 / volume - 1) < 0.01           # metres
    # glTF is Y up: (x, y, z) mm -> (x, z, -y) m
    lo, hi = mesh.bounds
    np.testing.assert_allclose(gmesh.bounds, 1e-3 * np.array([[lo[0], lo[2], -hi[1]], [hi[0], hi[2], -lo[1]]]),
                               atol=1e-9)
    print(f"blade: {len(blade.field.points)} nodes, STL {stl.stat().st_size} B, GLB {glb.stat().st_size} B, "
          f"{len(mesh.faces)} triangles, volume {mesh.volume:.6g} mm³ (solid {volume:.6g} mm³)")


def test_failed_write_leaves_the_old_files_and_no_temporaries(blade, blade_surface, tmp_path, monkeypatch):
    nodes = tmp_path / "nodes.vtu"
    nodes.write_text("old nodes\n")
    real = meshio.write

    def full_disk(path, mesh, file_format=None):
        if "triangle" in mesh.cells_dict:                        # the second file: half written, then ENOSPC
            Path(path).write_bytes(b"<VTKFile")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), path)
        real(path, mesh, file_format=file_format)

    monkeypatch.setattr(meshio, "write", full_disk)
    with pytest.raises(OutputError, match="nodes_surface.vtu: No space left on device") as info:
        export.write_vtu(blade, nodes, blade_surface)
    assert info.value.exit_code == 6
    assert nodes.read_text() == "old nodes\n"                    # whole or not at all, for the pair
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nodes.vtu"]


def test_outputs_get_the_umask_permissions(blade, blade_surface, tmp_path):
    mask = os.umask(0o022)
    os.umask(mask)
    path = export.write_stl(blade, tmp_path / "cold.stl", blade_surface)
    assert path.stat().st_mode & 0o777 == 0o666 & ~mask


def test_surface_path():
    assert export.surface_path("a/b/nodes.vtu") == Path("a/b/nodes_surface.vtu")
    assert export.surface_path("nodes") == Path("nodes_surface.vtu")


# --- the command line --------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def block_field(tmp_path_factory, block_nodes):
    nodes = block_nodes
    path = tmp_path_factory.mktemp("field") / "field.csv"
    np.savetxt(path, np.column_stack([nodes, BLOCK_FIELD(nodes)]), delimiter=",", header="x,y,z,dx,dy,dz",
               comments="", fmt="%.12g")
    return path


def _args(block_step, block_field, folder, *more):
    return ["morph", str(block_step), str(block_field), "-o", str(folder / "cold.step"), *map(str, more)]


@pytest.mark.heavy
def test_cli_writes_every_export_with_progress_and_table(tmp_path, block_step, block_field, capsys):
    out = {name: tmp_path / name for name in ("nodes.vtu", "cold.stl", "cold.glb", "report.json")}
    code = main(_args(block_step, block_field, tmp_path, "--vtu", out["nodes.vtu"], "--stl", out["cold.stl"],
                      "--glb", out["cold.glb"], "--report", out["report.json"]))
    assert code == 0
    captured = capsys.readouterr()
    written = [tmp_path / "cold.step", out["nodes.vtu"], tmp_path / "nodes_surface.vtu", out["cold.stl"],
               out["cold.glb"]]
    assert all(f"wrote {p}" in captured.out for p in written)
    assert "Δmax" in captured.out and "valid, closed" in captured.out          # the table
    err = captured.err.splitlines()
    assert err[1] == "load ..." and re.fullmatch(r"read: done in \d+\.\d s", err[0])
    assert "classify ..." in err and any(re.fullmatch(r"classify: 4161/4161 done in \d+\.\d s", e) for e in err)
    faces = [e for e in err if e.startswith("faces")]     # issue 17: counts as they go, then the time
    assert faces[0] == "faces ..." and "faces: 2/18" in faces and len(faces) >= 8
    assert re.fullmatch(r"faces: 18/18 done in \d+\.\d s", faces[-1])
    assert err[-2] == "report ..." and re.fullmatch(r"report: \d+/\d+ done in \d+\.\d s", err[-1])
    assert not any("INFO" in line for line in err)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["cold.step", "nodes_surface.vtu", *out])
    nodes = meshio.read(out["nodes.vtu"])
    assert len(nodes.points) == 4161 and np.nanmax(nodes.point_data["error"]) < 1e-9
    np.testing.assert_allclose(nodes.point_data["displacement"], BLOCK_FIELD(nodes.points), atol=1e-9)
    surface = meshio.read(tmp_path / "nodes_surface.vtu")
    hot = surface.points - surface.point_data["displacement"]
    np.testing.assert_allclose(BLOCK_FIELD(hot), surface.point_data["displacement"], atol=1e-6)
    assert set(surface.cell_data["face"][0]) == set(range(18))
    import json
    volume = json.loads(out["report.json"].read_text())["solids"][0]["volume_cold"]
    stl = trimesh.load(out["cold.stl"])
    glb = trimesh.load(out["cold.glb"]).to_geometry()
    assert stl.is_watertight and glb.is_watertight
    assert abs(stl.volume / volume - 1) < 0.01 and abs(glb.volume * 1e9 / volume - 1) < 0.01


@pytest.mark.heavy
def test_cli_quiet_prints_nothing(tmp_path, block_step, block_field, capsys):
    assert main(_args(block_step, block_field, tmp_path, "--stl", tmp_path / "c.stl", "-q")) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert (tmp_path / "cold.step").exists() and (tmp_path / "c.stl").exists()


@pytest.mark.heavy
def test_cli_verbose_logs_each_step(tmp_path, block_step, block_field, capsys):
    assert main(_args(block_step, block_field, tmp_path, "--vtu", tmp_path / "n.vtu", "-v")) == 0
    err = capsys.readouterr().err
    for stage in ("load", "classify", "edges", "faces", "rebuild", "sew", "report"):
        assert f"INFO hot2cold.pipeline.morph: {stage} done in" in err
    assert "INFO hot2cold.kernel.step: wrote" in err
    assert "INFO hot2cold.kernel.tessellate: tessellated 18 faces" in err
    assert f"INFO hot2cold.views.export: wrote {tmp_path / 'n.vtu'} (4161 nodes) and" in err
    assert "faces: 18/18" in err                                           # and the progress


@pytest.mark.heavy
def test_cli_write_failure_is_one_line_with_exit_code_6(tmp_path, block_step, block_field, capsys, monkeypatch):
    def full_disk(self, file_obj=None, file_type=None, **kwargs):
        Path(file_obj).write_bytes(b"solid")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(trimesh.Trimesh, "export", full_disk)
    code = main(_args(block_step, block_field, tmp_path, "--stl", tmp_path / "c.stl", "--vtu", tmp_path / "n.vtu",
                      "--report", tmp_path / "r.json", "-q"))
    assert code == 6
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("hot2cold: error: cannot write ")
    written = ", ".join(str(tmp_path / name) for name in ("r.json", "cold.step", "n.vtu", "n_surface.vtu"))
    assert err[0].endswith(f"c.stl: No space left on device ({written} written)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cold.step", "n.vtu", "n_surface.vtu", "r.json"]


def test_cli_report_failure_writes_nothing(tmp_path, block_step, block_field, capsys, monkeypatch):
    import json

    def full_disk(data, fh, **kwargs):
        fh.write("{")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(json, "dump", full_disk)
    code = main(_args(block_step, block_field, tmp_path, "--report", tmp_path / "r.json", "--stl", tmp_path / "c.stl",
                      "-q"))
    assert code == 6
    err = capsys.readouterr().err.splitlines()
    assert err == [f"hot2cold: error: cannot write {tmp_path / 'r.json'}: No space left on device (nothing written)"]
    assert list(tmp_path.iterdir()) == []


def _refused_before_the_run(capsys, monkeypatch, argv, *words):
    def no_run(*args, **kwargs):
        raise AssertionError("the morph started")

    monkeypatch.setattr(sys.modules["hot2cold.pipeline.morph"], "morph", no_run)
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert captured.out == "" and len(lines) == 1 and lines[0].startswith("hot2cold: error: ")
    for word in words:
        assert word in lines[0]
    return lines[0]


def test_cli_unwritable_folder_is_refused_before_the_run(tmp_path, block_step, block_field, capsys, monkeypatch):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    if os.access(locked, os.W_OK):       # root writes anywhere: let the folder look as it would to a user
        real = os.access
        monkeypatch.setattr(os, "access", lambda p, mode, *a, **k:
                            False if Path(p) == locked and mode & os.W_OK else real(p, mode, *a, **k))
    try:
        for flag, name in (("--vtu", "n.vtu"), ("--stl", "c.stl"), ("--glb", "c.glb"), ("--html", "r.html")):
            _refused_before_the_run(capsys, monkeypatch, _args(block_step, block_field, tmp_path, flag,
                                                               locked / name), flag, "not writable")
        assert list(locked.iterdir()) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["locked"]
    finally:
        locked.chmod(0o755)


@pytest.mark.parametrize("more, words", [
    (("--stl", "{tmp}/cold.step"), ("--stl", "output", "same file")),
    (("--vtu", "{tmp}/n.vtu", "--glb", "{tmp}/n_surface.vtu"), ("--glb", "--vtu surface", "same file")),
    (("--stl", "{field}"), ("--stl", "input")),
    (("--html", "{tmp}"), ("--html", "is a folder")),
    (("--glb", "{tmp}/no/c.glb"), ("--glb", "does not exist")),
    (("--scale", "10"), ("--scale", "--html")),
    (("--html", "{tmp}/r.html", "--scale", "-1"), ("--scale", "positive")),
    (("--html", "{tmp}/r.html", "--scale", "nan"), ("--scale", "positive")),
])
def test_cli_bad_outputs_are_refused_before_the_run(tmp_path, block_step, block_field, capsys, monkeypatch, more,
                                                    words):
    more = [m.format(tmp=tmp_path, field=block_field) for m in more]
    _refused_before_the_run(capsys, monkeypatch, _args(block_step, block_field, tmp_path, *more), *words)
    assert list(tmp_path.iterdir()) == []


def test_cli_html_without_its_module_is_refused_before_the_run(tmp_path, block_step, block_field, capsys,
                                                               monkeypatch):
    monkeypatch.setitem(sys.modules, "hot2cold.views.page", None)      # the import fails
    _refused_before_the_run(capsys, monkeypatch, _args(block_step, block_field, tmp_path, "--html",
                                                       tmp_path / "r.html"), "--html", "not available")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.heavy
def test_cli_html(tmp_path, block_step, block_field, capsys):
    html = tmp_path / "report.html"
    assert main(_args(block_step, block_field, tmp_path, "--html", html, "--scale", "50", "-q")) == 0
    assert capsys.readouterr().err == ""
    text = html.read_text(encoding="utf-8")
    assert text.lstrip().lower().startswith("<!doctype html") and "</html>" in text.lower()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cold.step", "report.html"]


def test_progress_rewrites_one_line_on_a_terminal():
    class Terminal(io.StringIO):
        def isatty(self):
            return True

    tty, pipe = Terminal(), io.StringIO()
    for stream in (tty, pipe):
        clock = iter([0.0, 0.5, 1.0, 1.1, 1.2, 2.0, 3.0, 3.25])
        progress = _Progress(stream, clock=lambda: next(clock))
        for call in (("load", 0, 1), ("load", 1, 1), ("faces", 0, 30), ("faces", 3, 30), ("faces", 4, 30),
                     ("faces", 30, 30), ("report", 0, 1), ("report", 1, 1)):
            progress(*call)
    assert tty.getvalue() == ("\r\033[Kload ...\r\033[Kload: done in 0.5 s\r\033[Kfaces ...\r\033[Kfaces: 3/30"
                              "\r\033[Kfaces: 30/30 done in 1.0 s\r\033[Kreport ...\r\033[Kreport: done in 0.2 s\n")
    assert pipe.getvalue() == ("load ...\nload: done in 0.5 s\nfaces ...\nfaces: 3/30\nfaces: 30/30 done in 1.0 s\n"
                               "report ...\nreport: done in 0.2 s\n")
