"""Wrong inputs named for what they are, before any long work, with the fix in the command line's words.

* hot and cold mixed up (:func:`hot2cold.pipeline.checks.check_positions`, before the nodes are classified):
  the cold part's positions with hot-to-cold displacements (positions minus displacements lie on the hot part),
  the cold part's positions with cold-to-hot displacements (positions plus displacements lie on it), with and
  without ``--invert``; never for a right field, however far it moves the nodes, nor for a right ``--invert``;
* a field whose extent is not a unit factor times the part's is not given a unit guess; a solver's results
  are not told to be "converted";
* another part's field is named as such; nodes outside the part beyond a few are warned about, volume nodes
  are not.

Through ``hot2cold.cli.main`` where the user meets them: exit code 2, one line on stderr, nothing written.
"""
from __future__ import annotations

import logging
import re
import time
from pathlib import Path

import numpy as np
import pytest

from hot2cold.cli import main
from hot2cold.errors import FieldError
from hot2cold.io.field import DisplacementField, read_field
from hot2cold.kernel.project import Projector
from hot2cold.kernel.sampling import fe_surface_nodes, volume_nodes
from hot2cold.pipeline.checks import _unit_hint, check_coverage, check_positions
from hot2cold.pipeline.classify import classify_nodes
from hot2cold.pipeline.invert import invert_field
from hot2cold.pipeline.load import load_part
from hot2cold.settings import Settings
from hot2cold.testing.synthetic import AffineField

SAMPLES = Path(__file__).resolve().parents[1] / "sample_parts"
BLADE, BLOCK = SAMPLES / "twisted_blade.step", SAMPLES / "filleted_block.step"
FIELD = AffineField.thermal(contraction=-0.004, rotation_deg=0.3, translation=(0.1, -0.2, 0.05))
#: The checks run before the long work: a refusal comes within this (the mix-ups took minutes before).
PROMPT = 60.0


def _csv(path: Path, points, displacements) -> Path:
    np.savetxt(path, np.column_stack([points, displacements]), delimiter=",", header="x,y,z,dx,dy,dz",
               comments="", fmt="%.12g")
    return path


def _frd(path: Path, points, displacements) -> Path:
    """A CalculiX ``.frd`` with a node block and one DISP block, in CalculiX's fixed columns."""
    ids = np.arange(1, len(points) + 1)
    e = "{:12.5E}".format
    lines = ["    1C", "    1Utest".ljust(70), f"    2C{'':18s}{len(ids):12d}{'':37s}1"]
    lines += [f" -1{i:10d}" + "".join(map(e, p)) for i, p in zip(ids, points)] + [" -3"]
    lines += [f"    1PSTEP{'':25s}1{'':11s}1{'':11s}1",
              f"  100CL{101:5d}{1.0:12.9f}{len(ids):12d}{'':20s}{0:2d}{1:5d}{'':10s}{1:2d}",
              f" -4  {'DISP':8s}{4:5d}{1:5d}"]
    lines += [f" -5  {c:8s}{1:5d}{2:5d}{k + 1:5d}{0:5d}" for k, c in enumerate(("D1", "D2", "D3"))]
    lines += [f" -5  {'ALL':8s}{1:5d}{2:5d}{0:5d}{0:5d}{1:5d}ALL"]
    lines += [f" -1{i:10d}" + "".join(map(e, d)) for i, d in zip(ids, displacements)] + [" -3", " 9999"]
    path.write_text("\n".join(lines) + "\n")
    return path


def _refused(capsys, tmp_path, hot, field, *more, out: str = "out") -> str:
    """Run ``hot2cold morph`` (quiet) with an output and a report asked for, into the new folder ``out`` of
    ``tmp_path``; check exit code 2, one line on stderr, nothing written, and that it came before the long
    work; return the message."""
    out = tmp_path / out
    out.mkdir()
    start = time.perf_counter()
    code = main(["morph", str(hot), str(field), "-o", str(out / "cold.step"), "--report", str(out / "r.json"),
                 *more, "-q"])
    elapsed = time.perf_counter() - start
    captured = capsys.readouterr()
    assert code == 2, captured.err
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("hot2cold: error: "), captured.err
    assert captured.out == "" and not list(out.iterdir())
    assert elapsed < PROMPT
    return lines[0][len("hot2cold: error: "):]


@pytest.fixture(scope="module")
def blade_field():
    return read_field(SAMPLES / "twisted_blade_field.csv")


@pytest.fixture(scope="module")
def block():
    """The bundled filleted block: its part, a projector and its bundled field."""
    settings = Settings()
    part = load_part(BLOCK, settings)
    return part, Projector(part.kernel.faces, part.kernel.edges), read_field(SAMPLES / "filleted_block_field.csv")


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    """A 10 mm box as STEP, its part and FE-like surface nodes 1 mm apart."""
    import cadquery as cq
    shape = cq.Workplane().box(10, 10, 10).val()
    step = tmp_path_factory.mktemp("box") / "box.step"
    shape.exportStep(str(step))
    part = load_part(step, Settings())
    return step, part, fe_surface_nodes(shape.wrapped, 1.0, seed=1)[0], shape


# ---------------------------------------------------------------------------------------------------------
# Hot and cold mixed up
# ---------------------------------------------------------------------------------------------------------
def test_cold_positions_with_hot_to_cold_displacements(tmp_path, capsys, blade_field):
    """The deformed mesh's positions (hot + d) with the hot-to-cold d: positions minus displacements lie on the
    hot part.  (The morph ran to its end and blamed units and folds.)"""
    f = blade_field
    field = _csv(tmp_path / "cold_positions.csv", f.points + f.displacements, f.displacements)
    message = _refused(capsys, tmp_path, BLADE, field)
    assert re.match(r".*cold_positions\.csv mixes up hot and cold: its positions minus its displacements lie on "
                    r"the hot part, its positions do not: of 2000 nodes sampled, 9\d % lie within the node distance "
                    r"\(0\.109 mm\) of it so and 3\d % as given", message), message
    assert "the positions are displaced ones (the cold part's, where the displacements go from hot to cold)" in message
    assert "write x-dx, y-dy, z-dz in its x, y, z columns, the displacements as they are" in message
    assert "give --invert if they go from cold to hot" in message


def test_cold_positions_with_cold_to_hot_displacements(tmp_path, capsys, blade_field):
    """The cold part's mesh with displacements that take it to the hot part: positions plus displacements lie on
    it.  (The morph wrote a wrong cold part.)"""
    f = blade_field
    field = _csv(tmp_path / "cold_mesh.csv", f.points + f.displacements, -f.displacements)
    message = _refused(capsys, tmp_path, BLADE, field)
    assert re.match(r".*cold_mesh\.csv mixes up hot and cold: its positions plus its displacements lie on the hot "
                    r"part, its positions do not: .* 9\d % are 10 times nearer so \(median distance [\d.e-]+ mm "
                    r"against 0\.0\d+ mm\); ", message), message
    assert ("the positions are the cold part's and the displacements go from cold to hot, where hot2cold takes the "
            "hot part's positions and displacements from hot to cold: write x+dx, y+dy, z+dz in its x, y, z columns "
            "and -dx, -dy, -dz in its dx, dy, dz columns") in message
    # --invert is no fix for it: that takes a cold-to-hot field at the hot part's nodes
    assert message.endswith("--invert is not for this: it takes a cold-to-hot field at the "
                            "hot part's nodes")


def test_cold_positions_with_cold_to_hot_displacements_and_invert(tmp_path, capsys, blade_field):
    """The same with --invert: inverted, the nodes still lie on the cold part (the morph folded faces and wrote a
    wrong part): named as the field was given, and --invert to be dropped."""
    f = blade_field
    field = _csv(tmp_path / "cold_mesh.csv", f.points + f.displacements, -f.displacements)
    message = _refused(capsys, tmp_path, BLADE, field, "--invert")
    assert "mixes up hot and cold: its positions plus its displacements lie on the hot part" in message
    assert "write x+dx, y+dy, z+dz in its x, y, z columns and -dx, -dy, -dz in its dx, dy, dz columns" in message
    assert "and drop --invert" in message


def test_displaced_positions_with_invert(tmp_path, capsys, blade_field):
    f = blade_field
    field = _csv(tmp_path / "displaced.csv", f.points + f.displacements, f.displacements)
    message = _refused(capsys, tmp_path, BLADE, field, "--invert")
    assert "its positions minus its displacements lie on the hot part" in message
    assert message.endswith("and keep --invert only if they go from cold to hot")


def test_mix_up_in_npz_and_solver_files_is_fixed_in_their_words(tmp_path, capsys, block):
    """An .npz is fixed in its arrays; a solver's results (.frd) cannot be edited: exported as a CSV."""
    part, projector, f = block
    npz = tmp_path / "cold_mesh.npz"
    np.savez(npz, points=f.points + f.displacements, displacements=-f.displacements)
    message = _refused(capsys, tmp_path, BLOCK, npz)
    assert "mixes up hot and cold: its positions plus its displacements" in message
    assert "save points + displacements as its points and -displacements as its displacements" in message
    frd = _frd(tmp_path / "displaced.frd", f.points + f.displacements, f.displacements)
    with pytest.raises(FieldError) as caught:
        check_positions(part, read_field(frd), projector, Settings())
    assert ("its positions minus its displacements lie on the hot part" in str(caught.value)
            and "export the undeformed node positions, x-dx, y-dy, z-dz, as a CSV with the columns x,y,z,dx,dy,dz"
            in str(caught.value))


def test_mix_up_with_displacements_within_the_node_distance(block):
    """Displacements below the node distance leave the same nodes "on" the part either way (the surface nodes;
    the block's field has volume nodes too); the distances still tell (the morph would have moved the part the
    wrong way)."""
    part, projector, f = block
    d = f.displacements * (0.3 * 0.0762 / np.linalg.norm(f.displacements, axis=1).max())
    with pytest.raises(FieldError, match=r"mixes up hot and cold: its positions plus its displacements .* (\d+) % "
                                        r"lie within the node distance \(0\.0762 mm\) of it so and \1 % as given, "
                                        r"[1-9]\d % are 10 times nearer so"):
        check_positions(part, DisplacementField(f.points + d, -d, source="small.csv"), projector, Settings())


@pytest.mark.heavy
@pytest.mark.parametrize("step, name", [
    ("twisted_blade.step", "twisted_blade_field.csv"), ("filleted_block.step", "filleted_block_field.csv"),
    ("mixer_segment.step", "mixer_segment_field.npz"), ("rotor37_blade.step", "rotor37_blade_field.npz")])
def test_right_fields_are_not_taken_for_mix_ups(step, name):
    """The bundled fields, as given, and as a right --invert field (cold to hot at the hot part's nodes)."""
    settings = Settings()
    part = load_part(SAMPLES / step, settings)
    projector = Projector(part.kernel.faces, part.kernel.edges)
    field = read_field(SAMPLES / name)
    start = time.perf_counter()
    check_positions(part, field, projector, settings)
    assert time.perf_counter() - start < 10.0
    cold_to_hot = DisplacementField(field.points, -field.displacements, source=field.source)
    try:
        inverted, _ = invert_field(cold_to_hot)
    except FieldError:          # Rotor 37's resampled field is too rough to invert
        return
    check_positions(part, inverted, projector, settings, inverted=True)


def test_the_moved_nodes_are_looked_at_only_where_nodes_lie_off_the_part(block, monkeypatch):
    """A right field's nodes lie on the part as given: no node can lie nearer it moved, and the nodes moved are
    not projected; cold positions given lie off it, and the nodes moved are looked at (and the mix-up found)."""
    import hot2cold.pipeline.checks as checks

    part, projector, f = block
    asked = []
    projected = checks.part_distances
    monkeypatch.setattr(checks, "part_distances",
                        lambda part, points, *a, **k: asked.append(len(points)) or projected(part, points, *a, **k))
    settings = Settings()
    on = projected(part, f.points, projector, 0.0762) <= checks._ROUNDING * part.diagonal   # (the field's volume
    f = DisplacementField(f.points[on], f.displacements[on])                                 # nodes left out)
    m = min(len(f), checks._SAMPLE)
    check_positions(part, f, projector, settings)
    assert asked == [m]
    asked.clear()
    d = f.displacements * (0.5 / np.abs(f.displacements).max())
    with pytest.raises(FieldError, match="mixes up hot and cold"):
        check_positions(part, DisplacementField(f.points + d, -d, source="cold.csv"), projector, settings)
    assert asked == [m, 2 * m]


def test_large_and_tiny_displacements_are_no_mix_up(block):
    """A right field that moves the block far beyond the node distance (a 3 degree turn and a 2 mm shift), one
    that hardly moves it, and a right --invert field of the same turn (cold to hot at the hot nodes)."""
    part, projector, f = block
    settings = Settings()
    turn = AffineField.thermal(contraction=-0.005, rotation_deg=3.0, axis=(0.3, 0.2, 1.0), translation=(2.0, 0, 0))
    assert np.linalg.norm(turn(f.points), axis=1).max() > 20 * 0.0762
    check_positions(part, DisplacementField(f.points, turn(f.points)), projector, settings)
    check_positions(part, DisplacementField(f.points, 1e-6 * turn(f.points)), projector, settings)
    back = AffineField(np.linalg.inv(turn.matrix), -np.linalg.inv(turn.matrix) @ turn.translation)
    inverted, _ = invert_field(DisplacementField(f.points, back(f.points)))
    check_positions(part, inverted, projector, settings, inverted=True)


# ---------------------------------------------------------------------------------------------------------
# Units, and another part's field
# ---------------------------------------------------------------------------------------------------------
def test_no_unit_guess_off_a_unit_factor(tmp_path, capsys, box):
    """A field a twentieth of the box (within 0.5x..2x of inches, not within a few per cent): no unit guess, but
    what is wrong, whether a few of its nodes fall on the part (on its face z = 5) or none does."""
    step, _, nodes, _ = box
    on_top = nodes / 20 + [0.0, 0.0, 5.0 - 0.25]
    message = _refused(capsys, tmp_path, step, _csv(tmp_path / "top.csv", on_top, FIELD(nodes) / 20))
    assert re.match(r".*top\.csv covers only part of the solid: .*; the nodes do not lie on this part: \d+ % of them "
                    r"are farther than 0\.0173 mm from it \(the field spans 0\.866 mm, the part "
                    r"17\.32 mm\): give this part's field \(the FIELD argument\)$",
                    message), message
    inside = nodes / 20 + 2.0
    message = _refused(capsys, tmp_path, step, _csv(tmp_path / "inside.csv", inside, FIELD(nodes) / 20), out="out2")
    assert re.match(r"no FE node of .*inside\.csv lies within 0\.0173 mm of the part: the nodes do not lie on this "
                    r"part \(they are [\d.]+ to [\d.]+ mm from its centre; the field spans 0\.866 mm, the part "
                    r"17\.32 mm\): give this part's field \(the FIELD argument\)$",
                    message), message
    assert "looks like" not in message and "inches" not in message


@pytest.mark.heavy
def test_inches_in_a_solver_file_are_not_converted(tmp_path, capsys, box):
    step, _, nodes, _ = box
    message = _refused(capsys, tmp_path, step, _frd(tmp_path / "inches.frd", nodes / 25.4, FIELD(nodes) / 25.4))
    assert message.endswith("100 % of its nodes are off the part: the field looks like inches, which --field-units "
                            "(mm or m) does not take: export its nodes and displacements as a CSV whose column "
                            "headers state the unit, e.g. 'x (in)'")
    assert "convert" not in message
    message = _refused(capsys, tmp_path, step, _frd(tmp_path / "metres.frd", nodes / 1000, FIELD(nodes) / 1000),
                       out="out_m")
    assert message.endswith("the field looks like metres: use --field-units m")
    rst = _unit_hint(1 / 25.4, "rst")
    assert "convert" not in rst and "/UNITS,BIN" in rst
    assert "where the .rst states no length unit" in _unit_hint(1e-3, "rst")


def test_another_parts_field_is_named_as_such(tmp_path, capsys):
    """The bundled blade's field on the bundled block: a few nodes on it, faces bare."""
    message = _refused(capsys, tmp_path, BLOCK, SAMPLES / "twisted_blade_field.csv")
    assert re.match(r".*twisted_blade_field\.csv covers only part of the solid: 5 of its 18 faces get no FE node "
                    r".*; the nodes do not lie on this part: 99 % of them are farther than 0\.0762 mm from it \(\d+ % "
                    r"outside it; the field spans 108\.8 mm, the part 76\.16 mm\): give this part's field \(the FIELD "
                    r"argument\)$", message), message
    assert "units" not in message and "looks like" not in message


# ---------------------------------------------------------------------------------------------------------
# Nodes off the part: outside it, or volume nodes inside it
# ---------------------------------------------------------------------------------------------------------
def _coverage(part, points, caplog) -> list[str]:
    """The warnings of :func:`check_coverage` on the box's field at ``points``."""
    settings = Settings()
    projector = Projector(part.kernel.faces, part.kernel.edges)
    field = DisplacementField(points, FIELD(points), source="nodes.csv")
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="hot2cold"):
        check_positions(part, field, projector, settings)
        check_coverage(part, classify_nodes(part, field, settings, projector), field, settings, projector)
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


def test_nodes_outside_the_part_are_warned_about(box, caplog):
    _, part, nodes, _ = box
    far = _coverage(part, np.concatenate([nodes, 1.5 * nodes[::2]]), caplog)
    assert len(far) == 1 and re.match(r"nodes\.csv: 3\d % of its nodes lie outside the part, farther than 0\.0173 mm "
                                      r"from every face, more than volume nodes explain \(they lie inside it\): nodes "
                                      r"of other parts, or another part's field: check that the field is this "
                                      r"part's; they are ignored$", far[0]), far
    near = _coverage(part, np.concatenate([nodes, 1.006 * nodes[::2]]), caplog)
    assert len(near) == 1 and "most of them within 0.173 mm of it" in near[0] and (
        "raise Settings(node_distance=...)" in near[0]), near


def test_volume_nodes_and_a_few_strays_are_not_warned_about(box, caplog):
    _, part, nodes, shape = box
    inside = volume_nodes(shape.wrapped, 2 * len(nodes), seed=3, margin=0.5)
    assert _coverage(part, np.concatenate([nodes, inside]), caplog) == []
    assert _coverage(part, np.concatenate([nodes, nodes[:20] + 30.0]), caplog) == []
