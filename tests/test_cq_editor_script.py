"""sample_parts/view_in_cq_editor.py runs through CQGI, the script runner CQ-editor uses.

CQGI executes the script with ``exec`` (no ``__file__``), overriding its top-level assignments with
``build_parameters``; what the script passes to ``show_object`` comes back as ``BuildResult.results``.
Two morphs of the bundled blade (about 10 s each on one core).
"""
from __future__ import annotations

from pathlib import Path

import cadquery as cq
import numpy as np
import pytest
from cadquery import cqgi

from hot2cold.io.field import read_field

SAMPLES = Path(__file__).resolve().parent.parent / "sample_parts"
SCRIPT = SAMPLES / "view_in_cq_editor.py"


def build(**parameters):
    """Parse afresh (CQGI writes parameter values into the parsed tree) and build."""
    return cqgi.parse(SCRIPT.read_text()).build(build_parameters=parameters)


def shown(result) -> dict:
    assert result.success, f"the script failed under CQGI: {result.exception!r}"
    return {r.options.get("name"): r for r in result.results}


def corners(shape) -> np.ndarray:
    return np.array([v.toTuple() for v in shape.Vertices()])


def field_at(field, points: np.ndarray) -> np.ndarray:
    """The displacement of the FE node nearest to each point."""
    d2 = ((points[:, None, :] - field.points[None, :, :]) ** 2).sum(axis=2)
    return field.displacements[d2.argmin(axis=1)]


@pytest.fixture(scope="module")
def field():
    return read_field(SAMPLES / "twisted_blade_field.csv")


@pytest.fixture(scope="module")
def true_scale(tmp_path_factory):
    """Default parameters, run from a folder without the samples: the script finds them without __file__."""
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(tmp_path_factory.mktemp("elsewhere"))
        mp.delenv("HOT2COLD_SAMPLES", raising=False)
        return shown(build())


@pytest.fixture(scope="module")
def exaggerated():
    return shown(build(exaggerate=10.0, show_nodes=False, sample_dir=str(SAMPLES)))


def test_parameters_are_picked_up():
    parameters = cqgi.parse(SCRIPT.read_text()).metadata.parameters
    assert {"exaggerate", "show_nodes", "sample_dir"} <= set(parameters)
    assert parameters["exaggerate"].default_value == 1.0
    assert parameters["show_nodes"].default_value is True


@pytest.mark.heavy
def test_hot_cold_and_nodes_are_shown(true_scale, field):
    assert set(true_scale) == {"hot", "cold", "nodes"}
    for name, colour in (("hot", "red"), ("cold", "blue")):
        item = true_scale[name]
        assert item.options["color"] == colour
        shape = item.shape
        assert isinstance(shape, cq.Shape) and shape.isValid()
        assert len(shape.Solids()) == 1 and shape.Solids()[0].isValid()
    assert 0 < true_scale["hot"].options["alpha"] < 1       # see-through hot part
    nodes = true_scale["nodes"].shape
    assert isinstance(nodes, cq.Compound) and 500 < len(nodes.Vertices()) <= 1500


def test_cold_is_the_hot_moved_by_the_field(true_scale, field):
    hot, cold = true_scale["hot"].shape, true_scale["cold"].shape
    h, c = corners(hot), corners(cold)
    assert h.shape == c.shape  # same topology, corners in the same order
    moved, expected = c - h, field_at(field, h)   # the field has a node on every corner
    assert np.abs(expected).max() > 0.5
    assert np.abs(moved - expected).max() < 0.01
    assert abs(cold.Volume() - hot.Volume()) < 0.05 * hot.Volume()
    # the nodes are shown where the field takes them: on the cold part
    nodes = true_scale["nodes"].shape.Vertices()[::50]
    assert max(cold.distance(v) for v in nodes) < 0.01


@pytest.mark.heavy
def test_exaggerate_scales_the_shown_displacement(true_scale, exaggerated):
    assert set(exaggerated) == {"hot", "cold"}                # show_nodes=False
    h = corners(true_scale["hot"].shape)
    assert np.allclose(corners(exaggerated["hot"].shape), h)  # the hot part is the same
    moved1 = corners(true_scale["cold"].shape) - h
    moved10 = corners(exaggerated["cold"].shape) - h
    assert exaggerated["cold"].shape.isValid()
    assert np.linalg.norm(moved10, axis=1).max() > 5.0         # the blade moves 1.55 mm at the most
    assert np.abs(moved10 - 10 * moved1).max() < 0.01                # 10 x further, to 0.01 mm


def test_a_wrong_sample_dir_fails_with_a_message(tmp_path):
    result = build(sample_dir=str(tmp_path))
    assert not result.success
    assert isinstance(result.exception, FileNotFoundError) and "sample_dir" in str(result.exception)
