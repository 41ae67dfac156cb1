"""The volumes integrated in a second process (kernel.side, ``Settings.kernel_process``): the same numbers as
in this process, and this process's own wherever the second one gives none."""
from __future__ import annotations

import io
import os

import pytest

from hot2cold.kernel import side as side_module
from hot2cold.kernel.side import KernelSide, serve
from hot2cold.kernel.validity import solid_volumes


@pytest.fixture(scope="module")
def two_boxes():
    """A compound of two solids of different volumes (a box and a cylinder beside it)."""
    import cadquery as cq

    box = cq.Workplane().box(10, 20, 30).val()
    cylinder = cq.Workplane().cylinder(15, 4).translate((30, 0, 0)).val()
    return cq.Compound.makeCompound([box, cylinder]).wrapped


def test_volumes_of_the_second_process_are_this_ones_to_the_bit(two_boxes):
    expected = solid_volumes(two_boxes)
    assert len(expected) == 2 and abs(expected[0] - 6000.0) < 1e-6      # the box, then the cylinder
    with KernelSide() as side:
        assert side.ready(wait=60.0)
        asked = [side.volumes(two_boxes), side.volumes(two_boxes)]
        folder = side._folder
        assert [a.result() for a in asked] == [expected, expected]      # BinTools keeps every double
        assert side.answer(5) is None                                   # nothing asked: no answer
    assert not side.running and not os.path.exists(folder)              # ended, its files removed


def test_a_second_process_that_cannot_start_leaves_the_volumes_to_this_one(two_boxes, monkeypatch, caplog):
    monkeypatch.setattr(side_module.sys, "executable", "/nonexistent/python")
    with caplog.at_level("INFO", logger="hot2cold.kernel.side"), KernelSide() as side:
        assert not side.running
        assert side.volumes(two_boxes).result() == solid_volumes(two_boxes)
    assert "could not start" in caplog.text


def test_a_second_process_that_ends_leaves_the_volumes_to_this_one(two_boxes, monkeypatch, caplog):
    monkeypatch.setattr(side_module.sys, "executable", "/bin/true")      # `true -m ...` ends at once
    with caplog.at_level("INFO", logger="hot2cold.kernel.side"), KernelSide() as side:
        assert not side.ready(wait=60.0)
        assert side.volumes(two_boxes).result() == solid_volumes(two_boxes)
    assert "ended" in caplog.text


def test_asked_before_the_second_process_is_ready_the_volumes_are_integrated_here(two_boxes, monkeypatch):
    monkeypatch.setattr(KernelSide, "_take", lambda self, block, timeout=None: None)     # it never says ready
    with KernelSide() as side:
        asked = side.volumes(two_boxes)
        assert asked.result() == solid_volumes(two_boxes)
        assert side.running                                             # not waited for


def test_the_second_process_answers_ready_then_one_named_line_per_request(two_boxes, tmp_path):
    from OCP.BinTools import BinTools

    path = tmp_path / "0.bin"
    assert BinTools.Write_s(two_boxes, str(path))
    answers = io.StringIO()
    serve(io.StringIO(f"{path}\n{tmp_path / '1.bin'}\n"), answers)     # the second file is not there
    ready, good, bad = answers.getvalue().splitlines()
    assert ready == "ready"
    assert side_module._answer(good) == (0, solid_volumes(two_boxes)) and good.startswith("ok 0 ")
    assert bad.startswith("error 1 ") and side_module._answer(bad) == (1, None)
    assert side_module._answer("*** a line the kernel printed") is None
    assert not path.exists()                                            # read, then removed


def test_a_morph_with_a_second_process_reports_the_same_volumes(block_shape, block_nodes, monkeypatch):
    """The hot and cold volumes of a morph whose second process integrates them (its answers read while the
    cold part's grids are checked) are this process's, and so is the rest of the report."""
    from hot2cold.pipeline import morph as morph_module
    from hot2cold.pipeline.morph import morph
    from hot2cold.settings import Settings

    monkeypatch.setattr(morph_module, "KERNEL_PROCESS_FACES", 1)      # the block's 18 faces get the process
    started = []
    monkeypatch.setattr(KernelSide, "start", lambda self, start=KernelSide.start: (started.append(1), start(self)))
    from hot2cold.testing.synthetic import AffineField

    thermal = AffineField.thermal(contraction=-0.004, rotation_deg=0.3, axis=(0.2, 0.3, 1.0),
                                  translation=(0.1, -0.2, 0.05), center=(5.0, 3.0, 10.0))
    field = (block_nodes, thermal(block_nodes))
    here, beside = (morph(block_shape, field, Settings(kernel_process=k)) for k in (False, True))
    assert [(s.volume_hot, s.volume_cold) for s in beside.report.solids] == \
        [(s.volume_hot, s.volume_cold) for s in here.report.solids]
    assert beside.report.solids[0].volume_cold != beside.report.solids[0].volume_hot     # the field moved it
    assert beside.report.delta_max == here.report.delta_max
    assert started == [1]                                               # the second morph's process only


def test_the_second_process_runs_this_package_not_one_in_the_working_directory(two_boxes, tmp_path, monkeypatch):
    """A checkout of another version in the working directory (where ``python -m`` would look first) is not
    the one that answers: this one, which integrates the true volumes, does."""
    fake = tmp_path / "hot2cold" / "kernel"
    fake.mkdir(parents=True)
    for folder in (fake.parent, fake):
        (folder / "__init__.py").write_text("")
    (fake / "side.py").write_text("def serve(requests, answers):\n"
                                  "    answers.write('ready\\n'); answers.flush()\n"
                                  "    for line in iter(requests.readline, ''):\n"
                                  "        answers.write('ok 0 1.0 2.0\\n'); answers.flush()\n")
    monkeypatch.chdir(tmp_path)
    with KernelSide() as side:
        assert side.ready(wait=60.0)
        assert side.volumes(two_boxes).result() == solid_volumes(two_boxes)


def test_an_answer_of_another_count_of_solids_is_not_taken(two_boxes, monkeypatch):
    """An answer that does not hold one volume a solid (the second process read some other file) is not taken."""
    with KernelSide() as side:
        assert side.ready(wait=60.0)
        asked = side.volumes(two_boxes)
        monkeypatch.setattr(side, "answer", lambda request: [1.0])
        assert asked.result() == solid_volumes(two_boxes)
