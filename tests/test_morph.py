"""End-to-end morphs of the sample parts against exactly known cold geometry."""
from __future__ import annotations

import numpy as np
import pytest

from hot2cold.core.bspline import evaluate_surface
from hot2cold.core.model import Role
from hot2cold.kernel.convert import surface_to_record
from hot2cold.kernel.step import read_step
from hot2cold.kernel.explore import bspline_surface
from hot2cold.pipeline.morph import morph
from hot2cold.testing.synthetic import AffineField, UntwistField, ZeroField

from conftest import face_deviation

THERMAL = AffineField.thermal(contraction=-0.004, rotation_deg=0.3, axis=(0.2, 0.3, 1.0),
                              translation=(0.1, -0.2, 0.05), center=(5.0, 3.0, 10.0))
UNTWIST = UntwistField(axis_point=(0.0, 0.0, 0.0), untwist_deg_per_mm=0.02, stretch_per_mm2=1e-4, z0=0.0)


def _cold_poles(result) -> list[np.ndarray]:
    """Control nets read back from the cold kernel shape (not from the numeric records)."""
    return [surface_to_record(*bspline_surface(face)).poles for face in result.cold_kernel.faces]


@pytest.mark.heavy
@pytest.mark.parametrize("part", ["block", "blade"])
def test_zero_field_keeps_every_control_point(part, request):
    shape = request.getfixturevalue(f"{part}_shape")
    nodes = request.getfixturevalue(f"{part}_nodes")
    result = morph(shape, (nodes, ZeroField()(nodes)))
    for face, cold in zip(result.part.faces, _cold_poles(result)):
        assert np.abs(cold - face.surface.poles).max() <= 1e-12
    for edge, em in zip(result.part.edges, result.edges):
        if edge.curve is not None:
            assert np.abs(em.curve.poles - edge.curve.poles).max() <= 1e-12
    assert result.report.valid and result.report.free_edges == 0


@pytest.mark.heavy
@pytest.mark.parametrize("part", ["block", "blade"])
def test_affine_field_is_reproduced_exactly(part, request):
    shape = request.getfixturevalue(f"{part}_shape")
    nodes = request.getfixturevalue(f"{part}_nodes")
    result = morph(shape, (nodes, THERMAL(nodes)))
    deviation = face_deviation(result, THERMAL.exact_map, spacing=1.0)
    assert all(len(d) > 0 for d in deviation)
    assert max(d.max() for d in deviation) <= 1e-8
    # the kernel's cold geometry is the one the records describe
    for face, cold in zip(result.part.faces, _cold_poles(result)):
        assert np.abs(cold - THERMAL.exact_map(face.surface.poles.reshape(-1, 3)).reshape(cold.shape)).max() <= 1e-8
    report = result.report
    assert report.valid and report.free_edges == 0
    assert report.delta_max <= 1e-7
    hot_volume, cold_volume = report.solids[0].volume_hot, report.solids[0].volume_cold
    assert cold_volume / hot_volume == pytest.approx(np.linalg.det(THERMAL.matrix), rel=1e-6)


@pytest.mark.heavy
def test_smooth_nonaffine_field_on_twisted_blade(blade_shape, blade_nodes):
    result = morph(blade_shape, (blade_nodes, UNTWIST(blade_nodes)))
    assert np.linalg.norm(UNTWIST(blade_nodes), axis=1).max() > 1.0        # a real deformation, mm
    deviation = np.concatenate(face_deviation(result, UNTWIST.exact_map, spacing=0.5))
    assert deviation.max() <= 1e-3
    assert deviation.mean() <= 1e-4
    report = result.report
    assert report.valid and report.free_edges == 0
    assert report.delta_max <= 1e-3 and report.delta_mean <= 1e-4
    for face in report.faces:
        assert face.nodes > 0 and face.delta_max <= 1e-3


@pytest.mark.heavy
def test_offset_and_volume_nodes_change_nothing_beyond_that(blade_shape, blade_nodes, blade_volume_nodes):
    clean = morph(blade_shape, (blade_nodes, UNTWIST(blade_nodes)))
    rng = np.random.default_rng(7)
    direction = rng.normal(size=blade_nodes.shape)
    offset = blade_nodes + 3e-3 * direction / np.linalg.norm(direction, axis=1, keepdims=True)   # 3 µm
    points = np.concatenate([offset, blade_volume_nodes])
    # displacements belong to the FE nodes where they are: evaluate the field at the offset positions
    noisy = morph(blade_shape, (points, UNTWIST(points)))
    assert noisy.report.nodes_ignored == len(blade_volume_nodes)
    assert np.all(noisy.classification.role[len(offset):] == Role.IGNORED)
    deviation = np.concatenate(face_deviation(noisy, UNTWIST.exact_map, spacing=0.5))
    assert deviation.max() <= 1e-3 and deviation.mean() <= 1e-4
    for a, b in zip(clean.faces, noisy.faces):
        uv = np.column_stack([np.linspace(*b.surface.domain[:2], 50), np.linspace(*b.surface.domain[2:], 50)])
        change = np.linalg.norm(evaluate_surface(a.surface, uv[:, 0], uv[:, 1])
                                - evaluate_surface(b.surface, uv[:, 0], uv[:, 1]), axis=1)
        assert change.max() <= 2e-4


@pytest.mark.heavy
@pytest.mark.parametrize("part", ["block", "blade"])
def test_cold_step_reads_back_valid_and_closed(part, request, tmp_path):
    from hot2cold.kernel.validity import check_solids
    shape = request.getfixturevalue(f"{part}_shape")
    nodes = request.getfixturevalue(f"{part}_nodes")
    result = morph(shape, (nodes, THERMAL(nodes)))
    path = tmp_path / "cold.step"
    result.write_step(path)
    again = read_step(path)
    checks = check_solids(again)
    assert len(checks) == 1
    assert checks[0].valid and checks[0].free_edges == 0
    assert checks[0].faces == len(result.part.faces)
    assert checks[0].volume == pytest.approx(result.report.solids[0].volume_cold, rel=1e-9)


def test_sparse_nodes_with_empty_patches_still_give_a_valid_solid(blade_shape, blade_nodes):
    rng = np.random.default_rng(3)
    sparse = blade_nodes[rng.choice(len(blade_nodes), 150, replace=False)]
    result = morph(blade_shape, (sparse, UNTWIST(sparse)))
    report = result.report
    assert report.valid and report.free_edges == 0
    assert sum(f.artificial_nodes for f in report.faces) > 0
    assert np.isfinite(report.delta_max)
    deviation = np.concatenate(face_deviation(result, UNTWIST.exact_map, spacing=2.0))
    assert deviation.max() < 0.1          # no wild surface; accuracy is the later issue's business


def _turned():
    import cadquery as cq
    return (cq.Workplane("XZ").spline([(5, 0), (8, 5), (6, 12), (9, 20)], includeCurrent=False)
            .lineTo(0, 20).lineTo(0, 0).close().revolve(360, (0, 0, 0), (0, 1, 0)))


def _parts():
    import cadquery as cq
    return {
        "sphere (degenerate edges, seam)": (cq.Workplane().sphere(10), 1),
        "surface of revolution": (_turned(), 1),
        "cylinder with chamfer (cone)": (cq.Workplane().cylinder(20, 8).faces(">Z").edges().chamfer(2), 1),
        "two solids": (cq.Workplane().box(10, 10, 10).union(cq.Workplane().box(10, 10, 10).translate((30, 0, 0))),
                       2),
    }


@pytest.mark.heavy
@pytest.mark.parametrize("name", list(_parts()))
def test_analytic_faces_and_several_solids_morph_exactly(name):
    from hot2cold.kernel.sampling import fe_surface_nodes
    workplane, n_solids = _parts()[name]
    nodes = fe_surface_nodes(workplane.val().wrapped, 1.0, seed=1)[0]
    result = morph(workplane, (nodes, THERMAL(nodes)))
    assert len(result.report.solids) == n_solids
    assert all(s.valid and s.closed for s in result.report.solids)
    assert max(d.max() for d in face_deviation(result, THERMAL.exact_map, spacing=1.0)) <= 1e-8


@pytest.mark.heavy
def test_trimmed_faces_do_not_wander_over_their_untrimmed_domain():
    """Rotor 37's faces are trimmed by hub and shroud: artificial nodes over the trimmed-away part keep the
    whole untrimmed surface on the affine field's continuation, and every fit keeps full rank."""
    from conftest import SAMPLES
    from hot2cold.kernel.sampling import fe_surface_nodes
    shape = read_step(SAMPLES / "rotor37_blade.step")
    nodes = fe_surface_nodes(shape, 1.0, seed=1)[0]
    result = morph(shape, (nodes, THERMAL(nodes)))
    for face, fm in zip(result.part.faces, result.faces):
        u0, u1, v0, v1 = face.surface.domain
        uu, vv = np.meshgrid(np.linspace(u0, u1, 60), np.linspace(v0, v1, 60))
        hot = evaluate_surface(face.surface, uu.ravel(), vv.ravel())
        cold = evaluate_surface(fm.surface, uu.ravel(), vv.ravel())
        assert np.linalg.norm(cold - THERMAL.exact_map(hot), axis=1).max() <= 1e-4
        assert fm.rank == fm.unknowns
    assert sum(f.artificial_nodes for f in result.report.faces) > 0


@pytest.mark.heavy
def test_g1_edges_are_reported_and_not_worsened(blade_shape, blade_nodes):
    result = morph(blade_shape, (blade_nodes, UNTWIST(blade_nodes)))
    g1 = result.report.g1
    assert len(g1) == 4                                   # the blade's four span-wise tangent edges
    assert all(g["kink_after_max"] <= g["kink_before_max"] + 1e-9 for g in g1)
    assert max(g["kink_after_max"] for g in g1) < 0.05    # degrees


@pytest.mark.heavy
def test_hot_part_kept_and_blas_left_alone_unless_asked(block_shape, block_nodes):
    """The hot part's kernel shape is left as loaded (the cold geometry goes into a copy the result holds),
    and BLAS keeps its threads during a morph unless ``Settings.blas_threads`` is set."""
    from threadpoolctl import threadpool_info, threadpool_limits

    from hot2cold.settings import Settings

    def blas_threads():
        return {p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}

    seen = {}
    with threadpool_limits(2, "blas"):
        if blas_threads() != {2}:
            pytest.skip("no BLAS that threadpoolctl can set to 2 threads")
        for threads in (None, 1):
            result = morph(block_shape, (block_nodes, THERMAL(block_nodes)), Settings(blas_threads=threads),
                           progress=lambda stage, *_: seen.setdefault(threads, blas_threads()))
        assert blas_threads() == {2}
    assert seen == {None: {2}, 1: {1}}
    hot = [surface_to_record(*bspline_surface(face)).poles for face in result.part.kernel.faces]
    for face, poles, cold in zip(result.part.faces, hot, _cold_poles(result)):
        assert np.array_equal(poles, face.surface.poles)                 # the hot part's kernel, as loaded
        assert np.abs(cold - poles).max() > 1e-3                          # the cold one, moved
    assert result.cold.wrapped.IsSame(result.cold_kernel.shape)


def test_a_step_is_written_only_when_it_reads_back_as_valid_closed_solids(tmp_path):
    """The cold STEP is read back before it is renamed into place: solids that do not come back as they were
    written (a box missing a face, made a solid, comes back as a shell: no solid) are refused (MorphError),
    and nothing is left."""
    import cadquery as cq

    from hot2cold.errors import MorphError
    from hot2cold.kernel.step import read_back, write_step

    box = cq.Solid.makeBox(10, 10, 10)
    good = tmp_path / "box.step"
    write_step(box.wrapped, good, verify=True)
    assert read_step(good) is not None
    open_box = cq.Solid.makeSolid(cq.Shell.makeShell(box.Faces()[:-1]))
    bad = tmp_path / "open.step"
    with pytest.raises(MorphError, match=r"the cold STEP for .*open\.step reads back with 0 solids of \[\] "
                                         r"faces, not the 1 of \[5\] written; not written$"):
        write_step(open_box.wrapped, bad, verify=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["box.step"]
    with pytest.raises(MorphError, match=r"reads back with 1 solids of \[6\] faces, not the 2 of \[6, 6\] written"):
        two = cq.Compound.makeCompound([box, box.translate(cq.Vector(20, 0, 0))])
        read_back(good, two.wrapped, "two.step")
