"""Rotor 37 and the mixer segment with their real CalculiX fields, and the whole chain STEP -> gmsh ->
ccx -> morph -> cold STEP.

The bounds on Rotor 37 and the mixer are the accuracy measured by default (refined to the tolerance of
1e-3 mm), held as regression limits.  Both fields bring their boundary triangles: the morph takes them inside
the elements too, which brings the mixer's lobed walls within 1e-3 mm next to the clamped inlet, where the FE
field changes within a node spacing (its nodes alone left 1.1e-3 mm there).
"""
from __future__ import annotations


import numpy as np
import pytest

from hot2cold.kernel.validity import check_solids
from hot2cold.kernel.step import read_step
from hot2cold.pipeline.morph import check_result, morph

from conftest import SAMPLES


@pytest.fixture(scope="module")
def rotor37():
    return morph(SAMPLES / "rotor37_blade.step", SAMPLES / "rotor37_blade_field.npz")


@pytest.fixture(scope="module")
def mixer():
    return morph(SAMPLES / "mixer_segment.step", SAMPLES / "mixer_segment_field.npz")


@pytest.mark.heavy
def test_rotor37_morph_is_a_valid_closed_solid_near_the_field(rotor37, tmp_path):
    report = rotor37.report
    assert report.element_points == 4 * 22238                   # 4 points in each quadratic boundary triangle
    assert report.nodes_used == report.nodes_total == 44478 + report.element_points
    check_result(rotor37)
    aerofoil = [report.faces[k] for k in (0, 1, 3, 5)]          # leading edge, pressure, suction, trailing
    assert all(f.nodes > 5000 for f in aerofoil)
    assert max(f.delta_max for f in report.faces) <= 3e-3
    assert max(f.delta_mean for f in report.faces) <= 3e-4
    assert report.delta_mean <= 2e-4
    rotor37.write_step(tmp_path / "cold.step")
    checks = check_solids(read_step(tmp_path / "cold.step"))
    assert checks[0].valid and checks[0].closed and checks[0].faces == 6


def test_rotor37_trimming_curves_stay_tangent(rotor37):
    """Issue 15: its four tangent edges are trimming curves of the aerofoil faces; every one within 0.01 deg
    of its hot angle after G1 (measured 0.00387 deg at the most; 0.0117 when the second rows were let kink a
    curve the fit had turned to 0.0039)."""
    g1 = rotor37.report.g1
    assert len(g1) == 4 and all(g["corrected"] for g in g1)
    for g in g1:
        assert g["kink_before_max"] > 0.03 and g["kink_after_max"] <= g["hot_angle_max"] + 0.01, g


@pytest.mark.heavy
def test_mixer_morph_lobed_faces(mixer):
    """The lobed walls (48 x 20 poles hot) miss 1e-3 mm near the clamped inlet, where the field changes
    steeply (4.9e-3 and 3.9e-3 mm with the hot knots): refined, within 1e-3 at the nodes and at the points
    inside the elements; the planar exit face (nodes on a 2.5 mm band) from 0.17 mm to 5e-4."""
    report = mixer.report
    check_result(mixer)
    assert report.element_points == 4 * 26190 and report.tolerance_met
    lobed = [report.faces[k] for k in (0, 2)]                       # outer and inner walls
    assert all(f.nodes > 20000 for f in lobed)
    refined = {r["face"]: r for r in report.refinements}
    assert {0, 2, 5} <= set(refined) and all(refined[k]["net_before"] == "48x20" for k in (0, 2))
    assert max(f.delta_max for f in lobed) <= 1e-3
    assert max(f.delta_mean for f in lobed) <= 1e-4
    assert refined[5]["delta_max_before"] > 0.1 and report.faces[5].delta_max <= 1e-3
    assert report.max_displacement > 3.0                            # the paper's mixer: about 3 mm


@pytest.mark.heavy
@pytest.mark.calculix
@pytest.mark.gmsh
def test_step_to_gmsh_to_ccx_to_cold_step(tmp_path):
    from hot2cold.fe.calculix import LoadCase, MeshOptions, hot_to_cold_field
    step = SAMPLES / "twisted_blade.step"
    # the blade stands on a disc of radius 150 mm turning about the x axis: its span z is radial
    field = hot_to_cold_field(step, tmp_path / "field.npz", mesh=MeshOptions(size=5.0, min_size=0.8),
                              load=LoadCase(omega=1500.0, axis_point=(0.0, 0.0, -150.0),
                                            axis_direction=(1.0, 0.0, 0.0)))
    assert len(field) > 1000 and np.linalg.norm(field.displacements, axis=1).max() > 0.05
    result = morph(step, tmp_path / "field.npz")
    check_result(result)
    # a coarse mesh straightens some inverted curved tetrahedra, leaving their midside nodes up to ~0.5 mm off
    # the CAD surface: those are left out and counted, as any node off the part
    assert result.report.nodes_ignored < 0.05 * result.report.nodes_total
    result.write_step(tmp_path / "cold.step")
    checks = check_solids(read_step(tmp_path / "cold.step"))
    assert checks[0].valid and checks[0].closed and checks[0].faces == 6
    # 5 mm elements: the fit follows the FE field to a few µm on average (the fine sample fields above do better)
    assert result.report.delta_mean <= 5e-3
    assert result.report.delta_mean < 0.05 * result.report.max_displacement
