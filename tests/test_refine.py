"""A tolerance that holds: refinement keeps the hot shape exactly (the kernel agrees), faces and edges are
refined where they miss the tolerance, shared edges stay shared, and ``--tolerance`` is met or exit code 5
says it is not."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.BRep import BRep_Tool
from OCP.GeomAPI import GeomAPI_ProjectPointOnCurve, GeomAPI_ProjectPointOnSurf
from OCP.gp import gp_Pnt

from hot2cold.core.bspline import (BSplineCurve, BSplineSurface, elevated_knots, evaluate_curve, evaluate_surface,
                                   insert_knots, refine_curve, refine_surface, surface_normals)
from hot2cold.cli import main
from hot2cold.kernel.validity import check_solids, volume
from hot2cold.kernel.convert import curve_to_record, record_to_curve, record_to_surface, surface_to_record
from hot2cold.kernel.sampling import fe_surface_nodes
from hot2cold.kernel.step import read_step, write_step
from hot2cold.pipeline.morph import check_result, morph
from hot2cold.core.model import Role, side_along
from hot2cold.core.footpoint import curve_distances
from hot2cold.core.footpoint import surface_distances
from hot2cold.settings import Settings

from conftest import SAMPLES

RNG = np.random.default_rng(4)


@pytest.fixture(autouse=True)
def _draws_of_its_own():
    """Every test draws from a generator of its own, seeded alike: its random nets and points do not depend on
    which tests ran before it in the same process (under ``-n 2`` that changes from run to run)."""
    global RNG
    RNG = np.random.default_rng(4)


def _surface(rational):
    u = np.concatenate([np.zeros(4), [0.3, 0.6], np.ones(4)])
    v = np.concatenate([np.zeros(3), [0.5], np.ones(3)])
    w = RNG.uniform(0.5, 2.0, (6, 4)) if rational else None
    return BSplineSurface(RNG.normal(size=(6, 4, 3)), u, v, 3, 2, w)


def _curve(rational, degree=2):
    knots = np.concatenate([np.zeros(degree + 1), [0.25, 0.7], np.ones(degree + 1)])
    n = len(knots) - degree - 1
    return BSplineCurve(RNG.normal(size=(n, 3)), knots, degree, RNG.uniform(0.5, 2.0, n) if rational else None)


def _gap(edge, face, n: int = 2000) -> float:
    """Largest distance (mm) between an edge's 3D curve and its curve on ``face``, densely sampled."""
    c3d, on_face = BRepAdaptor_Curve(edge), BRepAdaptor_Curve(edge, face)
    t = np.linspace(c3d.FirstParameter(), c3d.LastParameter(), n)
    return max(c3d.Value(x).Distance(on_face.Value(x)) for x in t)


# ----------------------------------------------------------------------------------------------------------
# Refinement operators and local distances.
# ----------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("rational", [False, True])
@pytest.mark.parametrize("axis", [0, 1])
def test_insert_knots_keeps_the_surface_and_matches_the_kernel(rational, axis):
    surface = _surface(rational)
    new_knots = [0.15, 0.45, 0.6] if axis == 0 else [0.25, 0.75]
    refined = insert_knots(surface, axis, new_knots)
    assert refined.shape[axis] == surface.shape[axis] + len(new_knots)
    u, v = RNG.uniform(0, 1, 500), RNG.uniform(0, 1, 500)
    assert np.abs(evaluate_surface(refined, u, v) - evaluate_surface(surface, u, v)).max() <= 1e-12
    kernel = record_to_surface(surface)
    for x in new_knots:
        (kernel.InsertUKnot if axis == 0 else kernel.InsertVKnot)(x, 1, 1e-12, True)
    oracle = surface_to_record(kernel)
    assert np.abs(oracle.poles - refined.poles).max() <= 1e-12
    assert np.array_equal(oracle.u_knots, refined.u_knots) and np.array_equal(oracle.v_knots, refined.v_knots)


@pytest.mark.parametrize("rational", [False, True])
@pytest.mark.parametrize("axis", [0, 1])
def test_refine_surface_raises_the_degree_and_inserts_knots_like_the_kernel(rational, axis):
    """Degree elevation with knot insertion in one step: the same surface, the same net as the kernel's
    IncreaseDegree then InsertUKnot/InsertVKnot."""
    surface = _surface(rational)
    inserted = [0.1, 0.45, 0.8]
    refined = refine_surface(surface, axis, inserted, 4)
    degree = refined.u_degree if axis == 0 else refined.v_degree
    assert degree == 4 and (refined.v_degree, refined.u_degree)[axis] == (surface.v_degree, surface.u_degree)[axis]
    u, v = RNG.uniform(0, 1, 500), RNG.uniform(0, 1, 500)
    assert np.abs(evaluate_surface(refined, u, v) - evaluate_surface(surface, u, v)).max() <= 1e-12
    kernel = record_to_surface(surface)
    kernel.IncreaseDegree(4 if axis == 0 else surface.u_degree, 4 if axis == 1 else surface.v_degree)
    for x in inserted:
        (kernel.InsertUKnot if axis == 0 else kernel.InsertVKnot)(x, 1, 0.0, True)
    oracle = surface_to_record(kernel)
    assert np.array_equal(oracle.u_knots, refined.u_knots) and np.array_equal(oracle.v_knots, refined.v_knots)
    assert np.abs(oracle.poles - refined.poles).max() <= 1e-11
    if rational:
        assert np.abs(oracle.weights - refined.weights).max() <= 1e-11
    assert refine_surface(surface, axis) is surface                     # nothing asked, nothing changed


@pytest.mark.parametrize("rational", [False, True])
def test_refine_curve_raises_the_degree_and_inserts_knots_like_the_kernel(rational):
    curve = _curve(rational)
    refined = refine_curve(curve, [0.1, 0.5], 3)
    t = RNG.uniform(0, 1, 300)
    assert np.abs(evaluate_curve(refined, t) - evaluate_curve(curve, t)).max() <= 1e-12
    kernel = record_to_curve(curve)
    kernel.IncreaseDegree(3)
    for x in (0.1, 0.5):
        kernel.InsertKnot(x, 1, 0.0, True)
    oracle = curve_to_record(kernel)
    assert np.array_equal(oracle.knots, refined.knots) and refined.degree == 3
    assert np.abs(oracle.poles - refined.poles).max() <= 1e-11
    assert np.array_equal(elevated_knots([0, 0, 0.5, 1, 1], 1, 3), [0, 0, 0, 0, 0.5, 0.5, 0.5, 1, 1, 1, 1])


def test_local_distances_match_the_kernel_projection():
    surface = _surface(False)
    u, v = RNG.uniform(0.05, 0.95, 200), RNG.uniform(0.05, 0.95, 200)
    offset = RNG.uniform(-1e-3, 1e-3, 200)
    points = evaluate_surface(surface, u, v) + offset[:, None] * surface_normals(surface, u, v)
    start = np.column_stack([u, v]) + RNG.uniform(-0.01, 0.01, (200, 2))    # a foot point a little off
    d = surface_distances(surface, points, start)
    kernel = GeomAPI_ProjectPointOnSurf()
    kernel.Init(record_to_surface(surface), 0.0, 1.0, 0.0, 1.0)
    oracle = []
    for p in points:
        kernel.Perform(gp_Pnt(*p))
        oracle.append(kernel.LowerDistance())
    assert np.abs(d - np.abs(offset)).max() <= 1e-9
    assert np.all(d >= np.array(oracle) - 1e-12)     # a local distance: never below the global one (this
                                                      # random net folds: another part may come closer)
    curve = _curve(True, 3)
    t = RNG.uniform(0, 1, 100)
    points = evaluate_curve(curve, t) + RNG.normal(scale=1e-4, size=(100, 3))
    d = curve_distances(curve, points, t + RNG.uniform(-0.01, 0.01, 100))
    oracle = [GeomAPI_ProjectPointOnCurve(gp_Pnt(*p), record_to_curve(curve)).LowerDistance() for p in points]
    assert np.abs(d - np.array(oracle)).max() <= 1e-9


# ----------------------------------------------------------------------------------------------------------
# Parts: the blade's planar caps, a tube sector and a wavy band, under bending fields.
# ----------------------------------------------------------------------------------------------------------

def _bend(c):
    """A bending field ``dz = c x^2``: divergence-free, so the cold volume equals the hot one."""
    return lambda p: np.column_stack([np.zeros(len(p)), np.zeros(len(p)), c * p[:, 0] ** 2])


def _write_field(path, points, disp):
    np.savetxt(path, np.column_stack([points, disp]), delimiter=",", header="x,y,z,dx,dy,dz", comments="",
               fmt="%.12g")
    return path


@pytest.fixture(scope="module")
def blade_1mm():
    shape = read_step(SAMPLES / "twisted_blade.step")
    return shape, fe_surface_nodes(shape, 1.0, seed=1)[0]


def _sector():
    """A 120 degree sector of a tube (radii 40 and 42.5 mm, 20 mm high): planar top and bottom faces trimmed
    to thin arcs, cylinders whose arcs are rational quadratics."""
    import cadquery as cq
    tube = cq.Workplane("XY").circle(42.5).circle(40.0).extrude(20.0)
    cut = cq.Workplane("XY").polyline([(0, 0), (100, -30), (100, -100), (-100, -100), (-100, 100),
                                       (-60, 100)]).close().extrude(20.0)
    return tube.cut(cut).val().wrapped


def _wave_band():
    """A band 2.5 mm wide along a sine of amplitude 10 mm over 100 mm, 20 mm high (5000 mm^3): its top and
    bottom are planes trimmed by two wavy 40-span B-spline edges, as the mixer's exit face."""
    import cadquery as cq
    x = np.linspace(0.0, 100.0, 41)
    y = 10.0 * np.sin(2 * np.pi * x / 50.0)
    lower = [(float(a), float(b)) for a, b in zip(x, y)]
    upper = [(float(a), float(b) + 2.5) for a, b in zip(x[::-1], y[::-1])]
    wire = (cq.Workplane("XY").spline(lower, includeCurrent=False).lineTo(*upper[0])
            .spline(upper[1:], includeCurrent=True).close())
    return wire.extrude(20.0).val().wrapped


@pytest.mark.heavy
def test_tolerance_refines_a_face_that_cannot_follow_the_field(blade_1mm):
    """The blade's planar caps (2x2 bilinear nets) cannot bend: with a tolerance they are raised to cubic
    and refined, and then they follow the field (before: 4 rounds of knots alone left 1.1e-3 mm)."""
    shape, nodes = blade_1mm
    field = (nodes, _bend(2e-3)(nodes))
    plain = morph(shape, field, Settings(keep_knots=True))
    refined = morph(shape, field)
    caps = [f.index for f in plain.report.faces if f.control_points == "2x2"]
    assert len(caps) == 2 and min(plain.report.faces[k].delta_max for k in caps) > 0.2      # measured 0.38, 0.29
    assert refined.report.tolerance_met
    assert max(f.delta_max for f in (*refined.report.faces, *refined.report.edges)) <= 1e-3
    entries = {r["face"]: r for r in refined.report.refinements}
    for k in caps:
        assert entries[k]["missed"] and entries[k]["rounds"] >= 1 and entries[k]["degree_after"] == "3x3"
        assert entries[k]["delta_max_before"] > 0.2 and entries[k]["delta_max_after"] <= 1e-3
    check_result(refined)
    hot = refined.report.solids[0].volume_hot
    assert abs(plain.report.solids[0].volume_cold - hot) > 1.0          # the flat caps: 3.7 mm^3 measured
    assert abs(refined.report.solids[0].volume_cold - hot) <= 0.05      # a divergence-free field keeps it


@pytest.fixture(scope="module")
def blade_mild_field(tmp_path_factory, blade_1mm):
    """The blade with a mild bend (0.12 mm at most): only the caps miss 1e-4 mm without refinement."""
    shape, nodes = blade_1mm
    return _write_field(tmp_path_factory.mktemp("mild") / "bend.csv", nodes, _bend(2e-4)(nodes))


@pytest.mark.heavy
def test_cli_tolerance_1e4_is_met_by_refinement(tmp_path, blade_mild_field, capsys):
    out, report = tmp_path / "cold.step", tmp_path / "report.json"
    code = main(["morph", str(SAMPLES / "twisted_blade.step"), str(blade_mild_field), "-o", str(out),
                 "--report", str(report), "--tolerance", "1e-4"])
    printed = capsys.readouterr().out
    assert code == 0
    data = json.loads(report.read_text())
    assert data["tolerance"] == 1e-4 and data["tolerance_met"] is True
    assert max(x["delta_max"] for x in (*data["faces"], *data["edges"])) <= 1e-4
    refined = {r["face"]: r for r in data["refinements"]}
    assert set(refined) == {4, 5}                                        # the caps
    for r in refined.values():
        assert r["missed"] and r["delta_max_before"] > 1e-2              # missed without refinement (3.8e-2)
        assert r["delta_max_after"] <= 1e-4 and r["rounds"] >= 1
        assert r["net_before"] == "2x2" and r["degree_before"] == "1x1" and r["degree_after"] == "3x3"
        assert r["knots_added_u"] + r["knots_added_v"] >= 1
        nu, nv = map(int, r["net_after"].split("x"))
        assert nu == 4 + r["knots_added_u"] and nv == 4 + r["knots_added_v"]
        assert data["faces"][r["face"]]["control_points"] == r["net_after"]
    assert "face 4 refined: 2x2 ->" in printed and "tolerance 0.0001 mm: met" in printed
    checks = check_solids(read_step(out))
    assert checks[0].valid and checks[0].closed and checks[0].faces == 6


@pytest.mark.heavy
def test_cli_tolerance_missed_without_refinement_exits_5(tmp_path, blade_mild_field, capsys):
    out, report = tmp_path / "cold.step", tmp_path / "report.json"
    code = main(["morph", str(SAMPLES / "twisted_blade.step"), str(blade_mild_field), "-o", str(out),
                 "--report", str(report), "--tolerance", "1e-4", "--max-refinements", "0"])
    assert code == 5
    assert "tolerance 0.0001 mm not met" in capsys.readouterr().err
    data = json.loads(report.read_text())
    assert data["tolerance_met"] is False
    missed = {r["face"]: r for r in data["refinements"]}
    assert set(missed) == {4, 5} and all(r["rounds"] == 0 and r["net_after"] == "2x2" for r in missed.values())
    assert min(data["faces"][k]["delta_max"] for k in missed) > 1e-2
    assert out.exists()                                                  # written all the same


def test_cli_refuses_negative_max_refinements(tmp_path, blade_mild_field, capsys):
    code = main(["morph", str(SAMPLES / "twisted_blade.step"), str(blade_mild_field), "-o",
                 str(tmp_path / "cold.step"), "--tolerance", "1e-4", "--max-refinements", "-1"])
    assert code == 2
    assert "max_refinements" in capsys.readouterr().err


@pytest.mark.heavy
def test_edges_and_the_faces_sharing_them_are_refined_together():
    """The sector's arcs (rational quadratics) cannot follow the bend: they are raised to cubic and refined,
    and so are the cylinders whose side rows they are, with the same knots, so that each arc stays one edge
    shared pole for pole (no gap) and the cold solid stays closed and valid."""
    shape = _sector()
    nodes = fe_surface_nodes(shape, 1.0, seed=1)[0]
    plain = morph(shape, (nodes, _bend(2e-4)(nodes)), Settings(keep_knots=True))
    result = morph(shape, (nodes, _bend(2e-4)(nodes)))
    report = result.report
    edges = {r["edge"]: r for r in report.edge_refinements}
    arcs = [e for e, r in edges.items() if r["missed"]]
    assert len(arcs) == 4
    for e in arcs:
        r = edges[e]
        assert r["delta_max_before"] > 5e-2 and r["delta_max_after"] <= 1e-3      # measured 9.7e-2, 8.5e-2
        assert (r["degree_before"], r["degree_after"]) == (2, 3) and r["knots_added"] >= 1
    faces = {r["face"]: r for r in report.refinements}
    cylinders = [k for k, r in faces.items() if not r["missed"]]
    assert len(cylinders) == 2                                           # refined only because of their arcs
    assert max(report.faces[k].delta_max for k in cylinders) <= 1e-3
    assert max(e.delta_max for e in report.edges) <= 1e-3               # (the trimmed planes: see the band below)
    part = result.part
    shared = 0
    for k in cylinders:
        face, cold = part.faces[k], result.faces[k].surface
        assert faces[k]["degree_after"] == "3x1" and faces[k]["knots_added_u"] >= 1
        assert set(result.faces[k].tied_sides) == {"u0", "u1", "v0", "v1"}      # still tied to every edge
        for use in face.uses:
            if use.edge not in arcs:
                continue
            side, backwards = side_along(face.surface, use)
            row = cold.poles[:, 0 if side == "v0" else -1]                      # the arcs run along u
            edge = result.edges[use.edge].curve
            poles = edge.poles[::-1] if backwards else edge.poles
            assert np.abs(row - poles).max() <= 1e-9                  # the face's row is the edge, pole for pole
            assert _gap(result.cold_kernel.edges[use.edge], result.cold_kernel.faces[k]) <= 1e-9
            shared += 1
    assert shared == 4
    check_result(result)
    # a divergence-free field keeps the volume: the plain fit is 0.87 mm^3 off, refined 0.03 (0.58 and 0.10
    # with the linear field estimator of the artificial nodes)
    hot = volume(result.hot.wrapped)
    assert abs(volume(result.cold.wrapped) - hot) <= abs(volume(plain.cold.wrapped) - hot) / 5


@pytest.mark.heavy
def test_cli_exit_5_where_the_data_cannot_carry_the_tolerance(tmp_path, capsys):
    """A field with a kink (``dz = 0.02 |x - 20|``, a slope that jumps by 0.04 across the plane x = 20 mm) on
    the sector, nodes 1 mm apart: no spline follows a kink, and the spans across it are halved until they
    are one node spacing long, no further (finer spans would follow the artificial nodes, not the nodes).
    Where it still misses the tolerance the report says so, the part is written, the exit code is 5."""
    step, out, report = tmp_path / "sector.step", tmp_path / "cold.step", tmp_path / "report.json"
    shape = _sector()
    write_step(shape, step)
    nodes = fe_surface_nodes(shape, 1.0, seed=1)[0]
    kink = np.column_stack([np.zeros(len(nodes)), np.zeros(len(nodes)), 0.02 * np.abs(nodes[:, 0] - 20.0)])
    field = _write_field(tmp_path / "kink.csv", nodes, kink)
    code = main(["morph", str(step), str(field), "-o", str(out), "--report", str(report), "-q",
                 "--max-refinements", "12"])
    assert code == 5
    assert re.match(r"hot2cold: tolerance 0\.001 mm not met \(face [35] at its nodes: 0\.0\d+ mm",
                    capsys.readouterr().err)
    data = json.loads(report.read_text())
    assert data["tolerance_met"] is False and data["allowance"] < 1e-5        # no scatter: the field is exact
    stuck = [r for r in data["refinements"] if not r["refinable"]]
    assert {r["face"] for r in stuck} == {3, 5}                                 # the planar top and bottom
    assert all(r["delta_max_after"] > 1e-3 for r in stuck)
    assert all(r["rounds"] < 12 for r in data["refinements"])                   # stopped, not out of rounds
    result = morph(shape, (nodes, kink), Settings(max_refinements=12), check=False)
    from scipy.spatial import cKDTree
    spacing = np.median(cKDTree(nodes).query(nodes, k=2)[0][:, 1])             # 0.86 mm (1 mm, jittered)
    for r in stuck:                                  # no span is shorter than a node spacing (a plane: exact)
        surface = result.part.faces[r["face"]].surface
        u, v = np.unique(surface.u_knots), np.unique(surface.v_knots)
        along_u = evaluate_surface(surface, u, np.full(len(u), v.mean()))
        along_v = evaluate_surface(surface, np.full(len(v), u.mean()), v)
        for ends in (along_u, along_v):
            assert np.linalg.norm(np.diff(ends, axis=0), axis=1).min() >= 0.95 * spacing
    checks = check_solids(read_step(out))
    assert checks[0].valid and checks[0].closed


@pytest.mark.heavy
def test_refined_trimmed_band_face_stays_on_its_edges_and_keeps_thevolume():
    """The mixer's exit-face defect on a small part: a plane trimmed to a thin wavy band.  Refined by knots
    alone the bilinear plane could not follow its curved cold edges (the gap, sampled by the sew at 51
    points, was then under-estimated and BRepCheck found the face's edge off it), and the volume came out
    wrong.  Raised to cubic it follows both its nodes and its edges, and the volume of a divergence-free
    bend is kept."""
    shape = _wave_band()
    nodes = fe_surface_nodes(shape, 1.0, seed=1)[0]
    field = (nodes, _bend(1e-4)(nodes - [50.0, 0.0, 0.0]))
    plain = morph(shape, field, Settings(keep_knots=True))
    refined = morph(shape, field)
    bands = [f.index for f in plain.report.faces if f.control_points == "2x2" and f.delta_max > 0.1]
    assert len(bands) == 2                                               # top and bottom: 0.17, 0.18 mm
    assert refined.report.tolerance_met
    assert {r["face"] for r in refined.report.refinements} == set(bands)
    check_result(refined)
    kernel = refined.cold_kernel
    for k in bands:                        # each edge of the refined faces lies on them, densely sampled
        for use in refined.part.faces[k].uses:
            edge = kernel.edges[use.edge]
            gap = _gap(edge, kernel.faces[k])
            assert gap <= 1e-3 and gap <= BRep_Tool.Tolerance_s(edge)
    hot = volume(refined.hot.wrapped)
    assert abs(hot - 5000.0) <= 0.01
    # the volume of a divergence-free bend: 0.087 mm^3 off plain, 1e-5 refined (0.013 with the linear
    # field estimator of the artificial nodes)
    assert abs(volume(refined.cold.wrapped) - hot) <= abs(volume(plain.cold.wrapped) - hot) / 5


@pytest.mark.heavy
def test_a_face_with_nodes_only_on_its_edges_is_refined_from_them():
    """The wave band's planar top and bottom from a triangulation's vertices, as an STL or CFD surface mesh
    gives them: a plane's triangulation has vertices only on its boundary, so the band faces get no node of
    their own.  With their knots kept they stay flat between their bent edges (0.17 mm off the exact cold
    geometry); by default they are refined from what their edges and the field's estimate near the edge
    nodes say, and follow the field."""
    from hot2cold.core.model import Role
    from hot2cold.kernel.tessellate import tessellate

    from conftest import face_deviation

    shape = _wave_band()
    nodes = np.unique(np.round(tessellate(shape, 0.05).vertices, 9), axis=0)
    bend = _bend(1e-4)
    field = (nodes, bend(nodes - [50.0, 0.0, 0.0]))

    def exact(points):
        return points + bend(points - [50.0, 0.0, 0.0])

    plain = morph(shape, field, Settings(keep_knots=True))
    result = morph(shape, field)
    before = face_deviation(plain, exact, 0.5)
    after = face_deviation(result, exact, 0.5)
    bands = [f.index for f in plain.report.faces if f.control_points == "2x2" and before[f.index].max() > 0.1]
    assert len(bands) == 2                                             # flat between bent edges
    assert all(not len(result.classification.nodes_of(Role.FACE, k)) for k in bands)     # no node of their own
    assert max(after[k].max() for k in bands) <= 1e-3
    refined = {r["face"]: r for r in result.report.refinements}
    assert all(refined[k]["between_before"] > 0.1 and refined[k]["between_after"] <= 1e-3 for k in bands)
    check_result(result)


@pytest.mark.heavy
def test_a_face_without_nodes_that_still_misses_between_them_is_not_met(tmp_path, capsys):
    """NIST Geom on a triangulation's vertices: a plane with no node of its own was refined for 8 rounds and
    still 0.059 mm off the field's estimate between its edges' nodes (2.9 mm off the exact cold geometry),
    and the run said "tolerance met", exit 0, since only errors at nodes counted.  Here the wave band's planar
    top and bottom (0.17 mm off between their bent edges with their hot knots), with no refinement round
    allowed: the miss between the nodes is the tolerance's too."""
    from hot2cold.kernel.tessellate import tessellate

    shape = _wave_band()
    step, out, report = tmp_path / "band.step", tmp_path / "cold.step", tmp_path / "report.json"
    write_step(shape, step)
    nodes = np.unique(np.round(tessellate(shape, 0.05).vertices, 9), axis=0)
    field = _write_field(tmp_path / "bend.csv", nodes, _bend(1e-4)(nodes - [50.0, 0.0, 0.0]))
    code = main(["morph", str(step), str(field), "-o", str(out), "--report", str(report), "-q",
                 "--max-refinements", "0"])
    err = capsys.readouterr().err
    data = json.loads(report.read_text())
    bands = [r for r in data["refinements"] if r["between_after"] > 1e-3]
    assert bands and all(data["faces"][r["face"]]["nodes"] == 0 for r in bands)
    assert data["delta_max"] <= 1e-3                       # at the nodes it is met
    assert code == 5 and data["tolerance_met"] is False
    assert re.match(r"hot2cold: tolerance 0\.001 mm not met \(face \d+ between its nodes: ", err)
    assert out.exists()                                    # written: inaccurate, not wrong


@pytest.mark.heavy
def test_an_edge_its_few_nodes_just_determine_is_refined_from_the_field_between_them():
    """NIST Geom's defect on a cylinder: its circular edges (19 poles) keep 7 nodes each, the faces hundreds.
    Fitted to its nodes alone, a circle wanders between them under a bending field, and its faces with it
    (9.5e-3 mm off the exact cold geometry, when only the nodes were measured).  Measured also against the
    field's estimate along it, near the nodes around it, it is refined and its faces follow."""
    import cadquery as cq
    from hot2cold.core.model import Role

    from conftest import face_deviation

    shape = cq.Workplane("XY").cylinder(20.0, 50.0).val().wrapped
    nodes = fe_surface_nodes(shape, 4.0, seed=1)[0]
    bend = _bend(2e-4)
    cls = morph(shape, (nodes, bend(nodes))).classification
    keep = np.ones(len(nodes), bool)
    circles = []
    for e in range(3):
        own = cls.nodes_of(Role.EDGE, e)
        if len(own) > 7:
            circles.append(e)
            keep[np.setdiff1d(own, own[np.linspace(0, len(own) - 1, 7).astype(int)])] = False
    assert len(circles) == 2
    nodes = nodes[keep]
    result = morph(shape, (nodes, bend(nodes)))
    assert all(result.report.edges[e].nodes == 7 for e in circles)
    refined = {r["edge"]: r for r in result.report.edge_refinements}
    assert all(refined[e]["between_before"] > 0.05 and refined[e]["between_after"] <= 1e-3 for e in circles)
    assert max(d.max() for d in face_deviation(result, lambda p: p + bend(p), 1.0)) <= 1e-3
    assert result.report.tolerance_met
    check_result(result)


@pytest.mark.heavy
def test_a_face_whose_nodes_do_not_fill_its_patches_is_measured_between_them():
    """Rotor 37's leading edge under 10 180 nodes: 158 nodes for 126 poles, so more nodes than poles, but 66
    knot-span patches that need 16 each to fix their cubic pieces; its shape between the nodes was the
    artificial nodes', unmeasured, and 1.8e-3 mm off the exact geometry while the run met the tolerance.  Here
    the twisted blade under 2 mm nodes: its leading-edge face has 276 nodes for 72 poles in 27 patches."""
    from hot2cold.core.model import Role
    from hot2cold.pipeline.refine import nodes_determine

    shape = read_step(SAMPLES / "twisted_blade.step")
    nodes = fe_surface_nodes(shape, 2.0, seed=1)[0]

    def field(p):
        return np.column_stack([np.zeros(len(p)), 0.2 * np.sin(p[:, 0] / 12.0) * p[:, 2] / 100.0,
                                0.1 * (p[:, 0] / 20.0) ** 2])

    result = morph(shape, (nodes, field(nodes)), Settings(keep_knots=True))
    part, cls = result.part, result.classification
    face = part.faces[0]
    own = len(cls.nodes_of(Role.FACE, 0))
    assert np.prod(face.surface.shape) < own < 27 * 16              # more nodes than poles, fewer than 16 a patch
    assert not nodes_determine(face, cls)
    assert nodes_determine(part.faces[1], cls)                      # 884 nodes for 42 patches: 672 needed
    refined = {r["face"]: r for r in morph(shape, (nodes, field(nodes))).report.refinements}
    assert refined[0]["between_before"] > 2e-3                      # its grid measured (3.15e-3 mm)


def test_distance_past_a_border_is_across_the_surface():
    """A point slid along a plane past its parameter box is measured from the plane (``past_border``), not
    from the box's edge; within the box both measures agree."""
    surface = BSplineSurface(np.array([[[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0]]]),
                             np.array([0.0, 0.0, 1.0, 1.0]), np.array([0.0, 0.0, 1.0, 1.0]), 1, 1)
    points = np.array([[1.5, 0.5, 0.01], [0.5, 0.5, 0.01]])
    uv = np.array([[1.0, 0.5], [0.5, 0.5]])
    assert surface_distances(surface, points, uv, past_border=True) == pytest.approx([0.01, 0.01])
    assert surface_distances(surface, points, uv) == pytest.approx([np.hypot(0.5, 0.01), 0.01])


@pytest.mark.heavy
def test_the_g1_steps_keep_an_edge_or_face_fit_they_would_take_off_the_field(blade_1mm):
    """NIST CTC-04: edges refined to 9.7e-4 mm were turned at their corners afterwards and left their nodes by
    1.6e-3 mm.  A turn (or a G1-corrected face) that takes an edge or face farther off its nodes than the
    tolerance, and than its fit was, is refused with the reason; one that stays within is taken."""
    from dataclasses import replace

    from hot2cold.core.model import Role
    from hot2cold.kernel.project import Projector
    from hot2cold.pipeline.grids import FaceGrid
    from hot2cold.pipeline.context import MorphContext
    from hot2cold.pipeline.distance import Allowance

    shape, nodes = blade_1mm
    result = morph(shape, (nodes, _bend(2e-4)(nodes)))
    part, cls = result.part, result.classification
    context = MorphContext.of(part, cls, result.field, Settings(), Projector(part.kernel.faces, part.kernel.edges))
    e = max(range(len(part.edges)), key=lambda e: len(cls.nodes_of(Role.EDGE, e)))
    k = max(range(len(part.faces)), key=lambda k: len(cls.nodes_of(Role.FACE, k)))
    fit, surface = result.edges[e], result.faces[k].surface
    grid = FaceGrid(np.zeros((0, 2)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, bool), np.zeros(0))
    chord = fit.curve.poles[-1] - fit.curve.poles[0]
    across = np.cross(chord, [1.0, 0.0, 0.0] if abs(chord[0]) < 0.9 * np.linalg.norm(chord) else [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)                                      # a direction across the edge
    u0, u1, v0, v1 = surface.domain
    normal = surface_normals(surface, np.array([(u0 + u1) / 2]), np.array([(v0 + v1) / 2]))[0]
    for shift, refused in ((2e-6, False), (5e-3, True)):
        why = context.distances.edge_moved_off(e, fit, replace(fit.curve, poles=fit.curve.poles + shift * across))
        assert bool(why) == refused and (not refused or why.startswith(f"turning edge {e} would take it 0.00"))
        why = context.distances.moved_off(k, surface, surface.with_poles(surface.poles + shift * normal), grid)
        assert bool(why) == refused and (not refused or why.startswith(f"turning face {k} would take it 0.00"))
    # the verdicts are kept by the surfaces' content, the grid and the allowance: asked again of surfaces made
    # anew (other objects), the same; under a wider allowance, the other
    moved = surface.with_poles(surface.poles + 5e-3 * normal)
    anew = surface.with_poles(surface.poles.copy()), moved.with_poles(moved.poles.copy())
    again = context.distances.moved_off(k, *anew, grid)
    assert again.startswith(f"turning face {k} would take it 0.00")
    assert context.distances.moved_off(k, surface, moved, grid, Allowance("turning", 10.0)) == ""


@pytest.mark.heavy
def test_a_refit_of_some_edges_puts_right_only_the_corners_they_touch(blade_1mm):
    """A refinement round that refines faces only (no edge) fitted every face of a tangent edge again: the
    refit of the edges re-applied the corner correction everywhere, and that correction, run on its own
    output, moved 128-150 edges of NIST FTC-07 again each round.  With the blade's corners kinked (the cap
    edges' poles next to them moved off the common planes): no refined edge, every edge morph stays the same
    object; one refined edge, only edges at the corners it touches change, the kinks elsewhere stay."""
    from dataclasses import replace

    from hot2cold.kernel.project import Projector
    from hot2cold.pipeline.context import MorphContext
    from hot2cold.pipeline.g1 import corners_touched

    shape, nodes = blade_1mm
    result = morph(shape, (nodes, _bend(2e-4)(nodes)))
    part, cls = result.part, result.classification
    context = MorphContext.of(part, cls, result.field, Settings(), Projector(part.kernel.faces, part.kernel.edges))
    tangent = {te.edge for te in context.tangent}
    assert tangent
    rng = np.random.default_rng(3)
    edges = list(result.edges)
    for k, m in enumerate(edges):
        if k in tangent or part.edges[k].degenerate:
            continue
        poles = m.curve.poles.copy()
        for i, end in ((1, 0), (-2, -1)):
            poles[i] += 0.02 * np.linalg.norm(poles[i] - poles[end]) * rng.normal(size=3)
        edges[k] = replace(m, curve=m.curve.with_poles(poles))
    everywhere = context.refit_edges(part, edges, set(tangent))        # every corner touched: all put right
    assert sum(a is not b for a, b in zip(edges, everywhere)) > len(tangent)
    assert all(a is b for a, b in zip(context.refit_edges(part, edges, set()), edges))
    e = min(tangent)
    touched = corners_touched(part, [m.curve for m in edges], {e})
    after = context.refit_edges(part, edges, {e})
    changed = {k for k, (a, b) in enumerate(zip(edges, after)) if a is not b}
    assert e in changed and len(changed) > 1                        # the refit edge and the cap edges at its ends
    assert all(set(part.edges[k].vertices) & touched for k in changed), (changed, touched)
    bent = [k for k in range(len(edges)) if k not in tangent and not part.edges[k].degenerate]
    assert any(edges[k] is after[k] for k in bent)                  # kinked corners elsewhere stay


@pytest.mark.heavy
def test_the_report_says_when_the_rounds_ran_out(blade_1mm):
    """A face that still misses when the most rounds allowed are done says so (the bundled twisted blade's
    CalculiX field needed 6 rounds; with the 4 of the default before, it missed by 1.46e-3 mm silently)."""
    shape, nodes = blade_1mm
    wave = np.column_stack([0 * nodes[:, 0], 0 * nodes[:, 0], 1e-2 * np.sin(nodes[:, 0] / 3.0)])
    result = morph(shape, (nodes, wave), Settings(max_refinements=1), check=False)
    assert not result.report.tolerance_met
    lines = [line for line in result.report.table().splitlines() if line.startswith(("face", "edge"))
             and "refined:" in line]
    assert lines and any(line.endswith("it still misses after the most rounds allowed (Settings(max_refinements=...))")
                         for line in lines)
    met = morph(shape, (nodes, _bend(2e-4)(nodes)), Settings(max_refinements=1), check=False)
    assert not any("most rounds allowed" in line for line in met.report.table().splitlines())


@pytest.mark.heavy
def test_a_face_out_of_its_nodes_reach_is_named_not_measured(tmp_path, capsys):
    """A triangulation's vertices lie only on a plane's border: the bundled filleted block's 50 mm cap met the
    tolerance where its edges' nodes measured it and was 3e-3 mm off the exact cold geometry in its middle,
    25 mm from any node, with "tolerance met" and nothing else said.  Here a 40 x 40 x 6 mm plate, whose
    triangulation has vertices at its corners only: every face is named as not measured (the report's text,
    JSON and HTML), the big planes first; FE-like nodes over every face leave nothing unmeasured."""
    import cadquery as cq
    from hot2cold.kernel.tessellate import tessellate

    shape = cq.Workplane("XY").box(40.0, 40.0, 6.0).val().wrapped
    step, out, report = tmp_path / "plate.step", tmp_path / "cold.step", tmp_path / "report.json"
    write_step(shape, step)
    bend = _bend(1e-4)
    nodes = np.unique(np.round(tessellate(shape, 0.05).vertices, 9), axis=0)
    field = _write_field(tmp_path / "bend.csv", nodes, bend(nodes))
    code = main(["morph", str(step), str(field), "-o", str(out), "--report", str(report)])
    printed = capsys.readouterr().out
    data = json.loads(report.read_text())
    # a box's triangulation has vertices at its corners only: the 40 x 40 planes' middles are 28.3 mm from a
    # node, the 40 x 6 sides' 20 mm
    assert sorted(data["unsupported_faces"]) == list(range(6))
    big = data["unsupported_faces"][:2]
    assert all(data["faces"][k]["unsupported"] > 0.5 for k in big)
    assert all(abs(data["faces"][k]["farthest_node"] - 20.0 * np.sqrt(2.0)) < 1.0 for k in big)
    assert code in (0, 5) and "\nnot measured: face " in printed           # the report's text, as printed
    from hot2cold.views.page import render_html

    bare = morph(shape, (nodes, bend(nodes)), Settings(tolerance=None))      # and with no tolerance set
    assert "<p>Not measured: face " in render_html(bare)

    fe = fe_surface_nodes(shape, 1.5, seed=1)[0]
    covered = morph(shape, (fe, bend(fe)))
    assert covered.report.unsupported_faces() == []
    assert all(f.unsupported == 0.0 for f in covered.report.faces)


def test_refine_patches_halves_the_patches_at_the_points_in_their_classes():
    """G1's refinement (:func:`refine_patches`): the patches of face 1 that hold the points are halved, and
    face 0's direction along the shared edge with it (one parameter class through the edge), so the edge
    stays shared pole for pole; the hot shape is kept; a face that may not be halved further gives None."""
    from hot2cold.pipeline.face_fit import FaceMorph
    from hot2cold.pipeline.edge_fit import EdgeMorph
    from hot2cold.pipeline.refine import Refitter, refine_patches
    from test_g1 import _part, _patches

    sa, sb = _patches()
    part = _part(sa, sb)
    tied = ("u0", "u1", "v0", "v1")
    faces = [FaceMorph(k, f.surface, 0, 0, 0, tied, 0, 0, 1.0) for k, f in enumerate(part.faces)]
    edges = [EdgeMorph(0, part.edges[0].curve, 0, 0, 0, 0, 1.0)]
    calls = {"faces": [], "edges": [], "grids": []}

    def fit_face(p, face, edge_morphs):
        calls["faces"].append(face.index)
        return FaceMorph(face.index, face.surface, 0, 0, 0, tied, 0, 0, 1.0)

    def fit_edges(p, edge_morphs, refined):
        calls["edges"].append(set(refined))
        return [EdgeMorph(e.index, p.edges[e.index].curve, 0, 0, 0, 0, 1.0) for e in edge_morphs]

    def regrid(p, ks):
        calls["grids"].append(list(ks))
        return [f"grid {k}" for k in ks]

    points = {1: np.array([[0.1, 0.2], [0.1, 0.3]])}      # both in face 1's patch u [0, 0.5] x v [0, 1/3]
    refitter = Refitter(fit_face, fit_edges, regrid)
    out = refine_patches(part, (faces, edges), points, np.zeros(2), refitter)
    b = out.part.faces[1].surface
    assert out.knots_added[1] == (1, 1)
    assert np.allclose(b.u_knots, [0, 0, 0, 0, 0.25, 0.5, 1, 1, 1, 1])
    assert np.allclose(b.v_knots, [0, 0, 0, 0, 1 / 6, 1 / 3, 2 / 3, 1, 1, 1, 1])
    a, edge = out.part.faces[0].surface, out.part.edges[0].curve
    assert out.knots_added[0] == (0, 1) and np.allclose(a.v_knots, b.v_knots) and np.allclose(a.u_knots, sa.u_knots)
    assert np.allclose(edge.knots, b.v_knots)
    assert np.abs(a.poles[-1] - edge.poles).max() <= 1e-12 and np.abs(b.poles[0] - edge.poles).max() <= 1e-12
    uv = RNG.uniform(0, 1, (200, 2))
    for before, after in ((sa, a), (sb, b)):
        assert np.abs(evaluate_surface(after, uv[:, 0], uv[:, 1])
                      - evaluate_surface(before, uv[:, 0], uv[:, 1])).max() <= 1e-12
    assert calls == {"faces": [0, 1], "edges": [{0}], "grids": [[0, 1]]}
    assert out.grids == {0: "grid 0", 1: "grid 1"}
    # halves shorter than the shortest span allowed: nothing to do
    assert refine_patches(part, (faces, edges), points, np.full(2, 1e3), refitter) is None


@pytest.mark.heavy
def test_a_node_the_field_around_it_does_not_follow_is_not_chased(blade_1mm):
    """One node of a blade face 3e-3 mm off a smooth field that its neighbours follow (1 mm apart): no smooth
    face passes it and them, so once a round that refined the face for it leaves it where it was (above
    STALL_SHARE of its error), it is left, and the report says so; the rest of the part is refined as without
    it.  (Rotor 37's
    field resampled onto 1 M nodes: nodes like it took its faces through seven rounds, to 2 664 and 1 512
    poles, and kinked its tangent edges by 1.3 to 3.6 degrees.)"""
    shape, nodes = blade_1mm
    disp = _bend(2e-4)(nodes)
    clean = morph(shape, (nodes, disp), Settings(tolerance=1e-4), check=False)
    cls = clean.classification
    on_face = cls.nodes_of(Role.FACE, 0)
    middle = on_face[np.argmin(np.linalg.norm(cls.foot[on_face] - cls.foot[on_face].mean(axis=0), axis=1))]
    outlier = int(cls.node[middle])
    disp[outlier, 2] += 3e-3
    result = morph(shape, (nodes, disp), Settings(tolerance=1e-4), check=False)
    assert not result.report.tolerance_met
    entry = {r["face"]: r for r in result.report.refinements}[0]
    # measured: one round (12x6 -> 12x7 poles), 2.10e-4 -> 2.05e-4 mm at the node; chased, five rounds to
    # 13x11 poles left it at 1.63e-4 mm, where the spans reached the nodes' spacing
    assert entry["unresolved"] == 1 and not entry["refinable"] and entry["rounds"] <= 2
    assert result.node_errors[middle] > 1e-4 and result.report.delta_max == result.node_errors[middle]
    assert ("where it still misses, at 1 of its nodes a finer net did not bring it closer"
            in result.report.table())
    # the faces the outlier is not on are refined as without it
    others = {r["face"]: r for r in clean.report.refinements}
    for r in result.report.refinements:
        if r["face"] != 0 and r["face"] in others:
            assert r["net_after"] == others[r["face"]]["net_after"]



def test_the_rebuild_inserts_the_knots_the_kernel_lacks_counting_multiplicities():
    from hot2cold.kernel.rebuild import _insert_missing

    inserted = []
    _insert_missing([0.0] * 4 + [0.5] + [1.0] * 4, np.array([0.0] * 4 + [0.25, 0.5, 0.5, 0.75] + [1.0] * 4),
                    lambda *args: inserted.append(args))
    assert inserted == [(0.25, 1, 0.0, True), (0.5, 1, 0.0, True), (0.75, 1, 0.0, True)]
