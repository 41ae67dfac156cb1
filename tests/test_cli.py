"""The command line: a real run on a sample part, and every refusal as one line with an exit code."""
from __future__ import annotations

import argparse
import json
import logging
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hot2cold.cli import commands, main
from hot2cold.cli.options import MorphOptions
from hot2cold.kernel.validity import check_solids
from hot2cold.kernel.step import read_step
from hot2cold.testing.synthetic import AffineField

SAMPLES = Path(__file__).resolve().parent.parent / "sample_parts"

FIELD = AffineField.thermal(contraction=-0.004, rotation_deg=0.3, translation=(0.1, -0.2, 0.05))


def _write_field(path, points, disp, header="id,x,y,z,dx,dy,dz"):
    rows = np.column_stack([np.arange(len(points)), points, disp])
    np.savetxt(path, rows, delimiter=",", header=header, comments="", fmt="%.12g")
    return path


@pytest.fixture
def block_field(tmp_path, block_nodes):
    return _write_field(tmp_path / "field.csv", block_nodes, FIELD(block_nodes))


@pytest.mark.heavy
def test_morph_writes_valid_cold_step_and_report(tmp_path, block_step, block_field, capsys):
    out, report = tmp_path / "cold.step", tmp_path / "report.json"
    code = main(["morph", str(block_step), str(block_field), "-o", str(out), "--report", str(report)])
    assert code == 0
    printed = capsys.readouterr().out
    assert "Δmax" in printed and "valid, closed" in printed
    data = json.loads(report.read_text())
    assert data["valid"] and data["closed"] and data["free_edges"] == 0
    assert data["delta_max"] <= 1e-7
    assert len(data["faces"]) == check_solids(read_step(out))[0].faces
    assert all({"nodes", "control_points", "delta_max", "delta_mean"} <= set(f) for f in data["faces"])
    assert data["nodes_used"] + data["nodes_ignored"] == data["nodes_total"]
    checks = check_solids(read_step(out))
    assert checks[0].valid and checks[0].closed


@pytest.mark.heavy
def test_field_in_metres_is_scaled(tmp_path, block_step, block_nodes):
    field = _write_field(tmp_path / "m.csv", block_nodes / 1000.0, FIELD(block_nodes) / 1000.0)
    out = tmp_path / "cold.step"
    assert main(["morph", str(block_step), str(field), "-o", str(out), "--field-units", "m", "-q"]) == 0
    assert out.exists()


def _refused(capsys, argv, code, *words):
    assert main(argv) == code
    lines = capsys.readouterr().err.strip().splitlines()
    # progress lines may come first; the error is one line, the last
    err = lines[-1]
    assert err.startswith("hot2cold: error: ")
    assert sum("error" in line for line in lines) == 1
    assert not any("Traceback" in line for line in lines)
    for word in words:
        assert word in err
    return err


@pytest.mark.heavy
def test_a_reader_that_stops_reading_stops_the_printing_not_the_work(tmp_path, block_step, block_field):
    """``hot2cold morph ... | head -1``: the pipe closes after the verdict; the cold part and the report are
    still written, the exit code is the run's, and no "internal error" is said."""
    out, report = tmp_path / "cold.step", tmp_path / "report.json"
    proc = subprocess.Popen([sys.executable, "-m", "hot2cold", "morph", str(block_step), str(block_field), "-o",
                             str(out), "--report", str(report), "--html", str(tmp_path / "r.html")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path)
    proc.stdout.close()                       # the reader is gone before the first line
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=600) == 0, err
    assert "internal error" not in err and "Broken pipe" not in err, err
    assert out.stat().st_size > 1000 and report.is_file() and (tmp_path / "r.html").is_file()
    assert check_solids(read_step(out))[0].valid


def test_missing_step(tmp_path, block_field, capsys):
    out = tmp_path / "cold.step"
    _refused(capsys, ["morph", str(tmp_path / "nope.step"), str(block_field), "-o", str(out)], 2, "not found")
    assert not out.exists()


def test_unreadable_step(tmp_path, block_field, capsys):
    bad = tmp_path / "bad.step"
    bad.write_text("this is not STEP\n")
    out = tmp_path / "cold.step"
    _refused(capsys, ["morph", str(bad), str(block_field), "-o", str(out)], 2, "STEP")
    assert not out.exists()


def test_step_without_solid(tmp_path, block_field, capsys):
    import cadquery as cq
    from hot2cold.kernel.step import write_step
    face_only = tmp_path / "face.step"
    write_step(cq.Face.makePlane(10, 10).wrapped, face_only)
    out = tmp_path / "cold.step"
    _refused(capsys, ["morph", str(face_only), str(block_field), "-o", str(out)], 2, "no solid")
    assert not out.exists()


@pytest.mark.parametrize("content, words", [
    ("x,y,z,dx,dy\n1,2,3,4,5\n", ("dz",)),
    ("x,y,z,dx,dy,dz\n", ("no",)),
    ("x,y,z,dx,dy,dz\n1,2,3,nan,0,0\n", ("NaN",)),
    ("x,y,z,dx,dy,dz\n1,2,3,inf,0,0\n", ("inf",)),
])
def test_bad_field_files(tmp_path, block_step, capsys, content, words):
    field = tmp_path / "field.csv"
    field.write_text(content)
    out = tmp_path / "cold.step"
    _refused(capsys, ["morph", str(block_step), str(field), "-o", str(out)], 2, *words)
    assert not out.exists()


def test_no_node_near_the_part(tmp_path, block_step, block_nodes, capsys):
    # a field of another part: same size, 500 mm away
    field = _write_field(tmp_path / "far.csv", block_nodes + 500.0, FIELD(block_nodes))
    out = tmp_path / "cold.step"
    _refused(capsys, ["morph", str(block_step), str(field), "-o", str(out)], 2, "no FE node", "units")
    assert not out.exists()


def test_output_equal_to_input_is_refused(tmp_path, block_step, block_field, capsys):
    import shutil
    hot = tmp_path / "hot.step"
    shutil.copy(block_step, hot)
    before = hot.read_bytes()
    _refused(capsys, ["morph", str(hot), str(block_field), "-o", str(hot)], 2, "input")
    assert hot.read_bytes() == before


def test_missing_output_folder(tmp_path, block_step, block_field, capsys):
    _refused(capsys, ["morph", str(block_step), str(block_field), "-o", str(tmp_path / "no" / "c.step")], 2,
             "does not exist")


@pytest.mark.heavy
def test_console_script_runs_without_traceback(tmp_path, block_step):
    field = tmp_path / "field.csv"
    field.write_text("x,y,z,dx,dy\n")
    proc = subprocess.run([sys.executable, "-m", "hot2cold", "morph", str(block_step), str(field), "-o",
                           str(tmp_path / "c.step")], capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.startswith("hot2cold: error:") and "Traceback" not in proc.stderr
    assert not (tmp_path / "c.step").exists()


@pytest.mark.heavy
def test_quiet_run_prints_nothing(tmp_path, block_step, block_field):
    """``-q``: nothing on either stream of a successful run.  Run as a process: the kernel's STEP writer prints
    its transfer statistics to the process's own standard output, past Python's ``sys.stdout``."""
    proc = subprocess.run([sys.executable, "-m", "hot2cold", "morph", str(block_step), str(block_field), "-o",
                           str(tmp_path / "c.step"), "-q"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "" and proc.stderr == ""
    assert check_solids(read_step(tmp_path / "c.step"))[0].valid


@pytest.mark.heavy
def test_inverted_field_gives_the_same_cold_part(tmp_path, block_step, block_nodes, capsys):
    # the cold-to-hot field of an affine hot-to-cold map x -> A x + b is y -> A^-1 (y - b), taken at hot nodes
    # FE output has volume nodes too (the inversion needs them for the displacement's normal derivative):
    # a 2 mm grid over the block's box stands in for them
    lo, hi = block_nodes.min(axis=0), block_nodes.max(axis=0)
    grid = np.stack(np.meshgrid(*[np.arange(a, b + 1e-9, 2.0) for a, b in zip(lo, hi)], indexing="ij"), -1)
    nodes = np.concatenate([block_nodes, grid.reshape(-1, 3)])
    a, b = FIELD.matrix, FIELD.translation
    cold_to_hot = np.linalg.solve(a, (nodes - b).T).T - nodes
    field = _write_field(tmp_path / "c2h.csv", nodes, cold_to_hot)
    out, report = tmp_path / "cold.step", tmp_path / "r.json"
    assert main(["morph", str(block_step), str(field), "-o", str(out), "--report", str(report), "--invert"]) == 0
    data = json.loads(report.read_text())
    assert data["inversion"]["residual"] < 1e-9 and data["delta_max"] < 1e-6
    assert "fixed-point iterations" in capsys.readouterr().out


def test_field_in_metres_without_units_is_caught(tmp_path, block_step, block_nodes, capsys):
    field = _write_field(tmp_path / "m.csv", block_nodes / 1000.0, FIELD(block_nodes) / 1000.0)
    _refused(capsys, ["morph", str(block_step), str(field), "-o", str(tmp_path / "c.step")], 2,
             "metres", "--field-units m")


def test_help_lists_extrapolate_and_both_commands(capsys):
    with pytest.raises(SystemExit) as info:
        main(["morph", "--help"])
    assert info.value.code == 0
    assert "--extrapolate" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["batch", "--help"])
    assert "JOBS" in capsys.readouterr().out


def test_help_lists_every_field_format_and_groups_the_options(capsys):
    """``hot2cold morph --help`` names every field format the tool reads and lists the options in groups: the
    outputs, the field's, accuracy and checks, viewer exports, messages (each option in exactly one)."""
    with pytest.raises(SystemExit):
        main(["morph", "--help"])
    out = capsys.readouterr().out
    field_help = " ".join(out.split("positional arguments:")[1].split("options:")[0].split())
    for ext in (".csv", ".txt", ".npz", ".frd", ".rst", ".op2", ".pch", ".vtu", ".msh"):
        assert ext in field_help, ext
    titles = ["outputs:", "the field: which data of the file, in what unit:", "accuracy and checks:",
              "viewer exports (written after the cold STEP):", "messages:"]
    at = [out.index(f"\n{t}\n") for t in titles]
    assert at == sorted(at)
    sections = dict(zip(titles, (out[a:b] for a, b in zip(at, at[1:] + [len(out)]))))
    assert "--report" in sections["outputs:"] and "--field-points" in sections[titles[1]]
    assert "--tolerance" in sections["accuracy and checks:"] and "--html" in sections[titles[3]]
    assert "--quiet" in sections["messages:"]
    for flag in (o.flag for o in MorphOptions.table().values()):
        assert sum(f"  {flag}" in text for text in sections.values()) == 1, flag


GUIDE = Path(__file__).resolve().parents[1] / "docs" / "guide"


def _morph_parser():
    parser = commands._parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices["morph"]


def test_the_guide_names_the_morph_options_of_the_table():
    """The command-line guide's `hot2cold morph` usage block and the batch guide's list of options name exactly
    the options of the table the parser and the jobs files are made from (:class:`MorphOptions`)."""
    usage = re.search(r"```\n(hot2cold morph .*?)```", (GUIDE / "cli.md").read_text(encoding="utf-8"), re.S).group(1)
    flags = set(re.findall(r"(?<![\w-])--?[a-z][a-z-]*", usage))
    table = {opt.flag for opt in MorphOptions.table().values()}
    assert table <= flags, f"the guide's usage block lacks {sorted(table - flags)}"
    assert flags <= set(_morph_parser()._option_string_actions), "the guide's usage block names an unknown option"
    listed = re.search(r"the options of `hot2cold morph` with the\s+same meaning: (.*?) \(`-` or `_`",
                       (GUIDE / "batch.md").read_text(encoding="utf-8"), re.S)
    assert re.findall(r"`(\w+)`", listed.group(1)) == list(MorphOptions.names())


def test_the_parser_takes_the_options_of_the_table():
    parser = _morph_parser()
    for name, opt in MorphOptions.table().items():
        assert opt.flag == "--" + name.replace("_", "-")      # a jobs file's `max-refinements` is the flag's
        assert parser._option_string_actions[opt.flag].dest == name
    args = commands._parser().parse_args(["morph", "h.step", "f.csv", "-o", "c.step", "--field-units", "m",
                                          "--tolerance", "1e-3", "--max-refinements", "2", "--extrapolate"])
    options = MorphOptions.from_args(args)
    assert options == MorphOptions(field_units="m", tolerance=1e-3, max_refinements=2, extrapolate=True)
    assert MorphOptions.from_args(commands._parser().parse_args(["morph", "h", "f", "-o", "c"])) == MorphOptions()
    assert options.morph_arguments() == {"units": "m", "field_name": None, "field_step": None, "columns": None,
                                         "field_points": None, "invert": False}
    settings = options.to_settings()
    assert (settings.tolerance, settings.max_refinements, settings.extrapolate) == (1e-3, 2, True)


def test_the_log_goes_to_stderr_through_the_hot2cold_logger(monkeypatch, capsys):
    """main() gives hot2cold's logger a stderr handler for the call only; the root logger is left alone."""
    root, ours = logging.getLogger(), logging.getLogger("hot2cold")
    before = list(root.handlers), list(ours.handlers), ours.level
    seen = []

    def run(args):
        seen.append(list(root.handlers))
        logging.getLogger("hot2cold.pipeline.test").warning("a warning")
        logging.getLogger("hot2cold.pipeline.test").info("a step")
        logging.getLogger("another.library").warning("not ours")
        return 0

    monkeypatch.setattr(commands, "_run", run)
    assert main(["batch", "jobs.csv"]) == 0
    assert capsys.readouterr().err == "WARNING hot2cold.pipeline.test: a warning\n"
    assert main(["batch", "jobs.csv", "-v"]) == 0
    assert capsys.readouterr().err == "WARNING hot2cold.pipeline.test: a warning\nINFO hot2cold.pipeline.test: a step\n"
    assert main(["batch", "jobs.csv", "-q"]) == 0
    assert capsys.readouterr().err == ""
    assert seen == [before[0]] * 3
    assert (list(root.handlers), list(ours.handlers), ours.level) == before


def test_the_librarys_option_words_are_said_in_the_command_lines_and_the_jobs_files():
    """The library names an option in Python's words (:func:`hot2cold.settings.option`); the command line says
    its flag (a switch without its value, the FIELD argument by name), a batch its jobs-file column; a setting the
    command line does not take keeps Python's words."""
    from hot2cold.cli.options import in_words
    from hot2cold.settings import option

    text = (f"use {option('field_units', 'm')}, or {option('extrapolate', True)}; raise {option('node_distance')}; "
            f"give ({option('field')}); choose with {option('columns', 'dx=UX')}; {option('g2_tolerance', 0.1)}")
    assert text == ("use morph(units='m'), or Settings(extrapolate=True); raise Settings(node_distance=...); give "
                    "(morph(field=...)); choose with morph(columns='dx=UX'); Settings(g2_tolerance=0.1)")
    assert in_words(text) == ("use --field-units m, or --extrapolate; raise --node-distance; give (the FIELD "
                              "argument); choose with --columns dx=UX; Settings(g2_tolerance=0.1)")
    assert in_words(text, jobs=True) == (
        "use field_units = m in the jobs file, or extrapolate = true in the jobs file; raise the jobs file's "
        "node_distance column; give (the jobs file's field column); choose with columns = dx=UX in the jobs file; "
        "Settings(g2_tolerance=0.1)")
    with pytest.raises(ValueError, match="no option 'field_unit'"):
        option("field_unit", "m")


def test_a_python_user_reads_python_words(tmp_path):
    """From Python the same refusal names the keyword of morph(), not a flag."""
    from hot2cold import morph
    from hot2cold.errors import FieldError

    nodes = np.loadtxt(SAMPLES / "twisted_blade_field.csv", delimiter=",", skiprows=1)[::8]
    with pytest.raises(FieldError) as info:
        morph(SAMPLES / "twisted_blade.step", (nodes[:, 1:4] * 1e-3, nodes[:, 4:7] * 1e-3))
    assert str(info.value).endswith("the field looks like metres: use morph(units='m')"), str(info.value)
