"""One verdict, first and the same everywhere (issue 35): the command's first line, the HTML page's header and
the JSON's ``verdict`` say met / partly measured / NOT met / no tolerance with the largest error at the nodes
and between them and the share of the part's area measured; nothing but a met, fully measured part is shown in
green.  Reports are built directly (no kernel) except in the last test, a small box run end to end (exit 5)."""
from __future__ import annotations

import json
import re
from dataclasses import replace
from html.parser import HTMLParser

import numpy as np
import pytest

from hot2cold.cli import batch
from hot2cold.pipeline.report import (UNSUPPORTED_SHARE, EdgeReport, FaceReport, Feature, Place, Report,
                                      SolidReport, Tone, VerdictState, _percent)
from hot2cold.views import page

#: The greens of the page's style sheet (text and background): none may colour anything but a met part.
GREENS = ("#1a7f37", "#14532d", "#e7f5ec")


def _face(index, *, delta_max=2e-4, between=3e-4, unsupported=0.0, area=30.0, nodes=100):
    return FaceReport(index=index, solid=0, nodes=nodes, control_points="4x4", delta_max=delta_max,
                      delta_mean=delta_max / 3, unknowns=16, rank=16, condition=10.0, tied_sides=[], edge_rows=0,
                      artificial_nodes=0, delta_between=between, unsupported=unsupported, farthest_node=1.0,
                      name=f"plane {index}", area=area)


def _report(faces=None, edges=None, **changes) -> Report:
    """A report of a small part: face 0 of 30 mm², face 1 of 10 mm², one edge, a valid closed solid, the
    default tolerance 1e-3 mm, met everywhere (2e-4 mm at the nodes, 3e-4 mm between them)."""
    faces = faces if faces is not None else [_face(0), _face(1, area=10.0, delta_max=1e-4, between=1e-4)]
    edges = edges if edges is not None else [EdgeReport(0, [0, 1], 20, 6, 1.5e-4, 5e-5, 1e-8, 0)]
    delta_max = max([f.delta_max for f in faces] + [e.delta_max for e in edges])
    base = dict(hot="part.step", field="field.csv", nodes_total=700, nodes_on_faces=200, nodes_on_edges=20,
                nodes_on_vertices=4, nodes_ignored=476, node_distance=0.05, edge_distance=0.005,
                max_displacement=0.3, delta_max=delta_max, delta_mean=5e-5, vertex_delta_max=0.0,
                delta_between=max(f.delta_between for f in faces), valid=True, free_edges=0, faces=faces,
                edges=edges, solids=[SolidReport(0, len(faces), True, 0, 1000.0, 999.0, "part")],
                tolerance=1e-3)
    base.update(changes)
    return Report(**base)


def _met():
    return _report()


def _partly():
    return _report(faces=[_face(0), _face(1, area=10.0, unsupported=0.6, delta_max=1e-4, between=1e-4)])


def _not_met():
    return _report(faces=[_face(0, delta_max=2.2e-3), _face(1, area=10.0)])


def _none():
    return _report(tolerance=None)


STATES = {"met": (_met, VerdictState.MET, Tone.GOOD), "partly": (_partly, VerdictState.PARTLY_MEASURED, Tone.WARNING),
          "not met": (_not_met, VerdictState.NOT_MET, Tone.BAD),
          "no tolerance": (_none, VerdictState.NO_TOLERANCE, Tone.NEUTRAL)}


class _Verdict(HTMLParser):
    """The page's verdict paragraph: its classes and its text."""

    def __init__(self):
        super().__init__()
        self.classes, self.text, self._inside = None, [], False

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "p" and attrs.get("id") == "verdict":
            self.classes, self._inside = (attrs.get("class") or "").split(), True

    def handle_endtag(self, tag):
        if tag == "p":
            self._inside = False

    def handle_data(self, data):
        if self._inside:
            self.text.append(data)


def _header(report) -> str:
    """The top of the page as :func:`page.render_html` puts it (verdict, then the summary), without the
    pictures and the kernel."""
    return page._verdict(report) + page._summary(report)


def _css_rules() -> dict[str, str]:
    return {sel.strip(): body for sel, body in re.findall(r"([^{}]+)\{([^}]*)\}", page.STYLE)}


# ----------------------------------------------------------------------------------------------------------
# The states
# ----------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", STATES)
def test_each_state_its_tone_and_one_sentence_everywhere(name):
    build, state, tone = STATES[name]
    report = build()
    verdict = report.verdict
    assert verdict.state is state and verdict.tone is tone
    # the command's first line, the JSON's verdict (its first key) and the page's headline are one sentence
    assert report.table().splitlines()[0] == verdict.text
    data = report.to_dict()
    assert next(iter(data)) == "verdict" and data["verdict"]["text"] == verdict.text
    assert data["verdict"]["state"] == state.value
    parsed = _Verdict()
    parsed.feed(page._verdict(report))
    assert "".join(parsed.text) == verdict.text
    assert parsed.classes == ["verdict", f"v-{tone.value}"]
    # the JSON's fields are the record's
    assert data["verdict"]["at_nodes"] == pytest.approx(verdict.at_nodes)
    assert data["verdict"]["at_nodes_where"] == str(verdict.at_nodes_where)
    assert data["verdict"]["between"] == pytest.approx(verdict.between)
    assert data["verdict"]["measured"] == pytest.approx(verdict.measured)
    assert data["tolerance_met"] == report.tolerance_met              # the old key says what it said


def test_met_names_both_errors_and_the_whole_area():
    verdict = _met().verdict
    assert verdict.text == ("tolerance 0.001 mm: met — 0.0003 mm between the nodes (face 0), 0.0002 mm at the "
                            "nodes (face 0); 100 % of the area measured")
    assert verdict.limit == pytest.approx(1e-3) and verdict.measured == 1.0 and verdict.unmeasured_faces == ()


def test_partly_measured_is_met_where_measured_with_a_face_out_of_reach():
    report = _partly()
    assert report.tolerance_met is True and [f.index for f in report.unsupported_faces()] == [1]
    verdict = report.verdict
    # area-weighted: face 1 (10 of 40 mm²) 60 % out of reach
    assert verdict.measured == pytest.approx(1.0 - 0.6 * 10.0 / 40.0)
    assert verdict.unmeasured_faces == (1,)
    assert verdict.text.startswith("tolerance 0.001 mm: met where measured, PARTLY measured — ")
    assert verdict.text.endswith("; only 85 % of the area measured (unmeasured: 60 % of face 1)")


def test_any_unmeasured_area_is_partly_measured_and_not_rounded_to_100():
    """No face beyond UNSUPPORTED_SHARE, but some area the check does not vouch for: not green (a sharp thermal
    front the nodes do not resolve is a few per cent of a face, and the cold part was 2e-3 mm off there)."""
    faces = [_face(0, unsupported=0.004), _face(1, area=10.0, unsupported=UNSUPPORTED_SHARE)]
    verdict = _report(faces=faces).verdict
    assert verdict.state is VerdictState.PARTLY_MEASURED
    assert verdict.measured == pytest.approx(1.0 - (0.004 * 30.0 + 0.1 * 10.0) / 40.0)
    assert verdict.text.endswith("; only 97 % of the area measured (unmeasured: 10 % of face 1, 0.4 % of face 0)")
    assert _report(faces=[_face(0, unsupported=0.0), _face(1, unsupported=0.0)]).verdict.state is VerdictState.MET
    assert _percent(0.9996) == "99.9 %" and _percent(1.0) == "100 %" and _percent(0.0) == "0 %"
    assert _percent(0.004) == "0.4 %" and _percent(0.505) == "50 %" and _percent(0.0004) == "under 0.1 %"
    # a share unmeasured is rounded up: a face named for more than 10 % never reads "10 %"
    assert _percent(0.109, up=True) == "11 %" and _percent(0.0004, up=True) == "0.1 %"
    assert _percent(0.99999, up=True) == "99.9 %"


def test_not_met_names_the_worst_miss_first():
    report = _not_met()
    assert report.tolerance_met is False
    assert report.verdict.text == ("tolerance 0.001 mm: NOT met — 0.0022 mm at the nodes (face 0), 0.0003 mm "
                                   "between the nodes (face 0); 100 % of the area measured")
    # a miss between the nodes (what the refinement measured there) larger than those at the nodes comes first
    refinement = {"face": 1, "between_after": 0.086, "delta_max_after": 1e-4, "rounds": 8, "refinable": False}
    report = replace(report, refinements=[refinement])
    assert report.misses()[0] == ("face 1 between its nodes", 0.086)
    verdict = report.verdict
    assert verdict.text.startswith("tolerance 0.001 mm: NOT met — 0.086 mm between the nodes (face 1), "
                                   "0.0022 mm at the nodes (face 0); ")
    assert verdict.between_where == Place(Feature.FACE, 1) and verdict.at_nodes_where == Place(Feature.FACE, 0)


def test_an_edge_miss_and_the_scatter_allowance_are_named():
    edges = [EdgeReport(3, [0, 1], 20, 6, 4e-3, 1e-3, 1e-8, 0)]
    verdict = _report(edges=edges, allowance=5e-4, scatter=1e-4).verdict
    assert verdict.state is VerdictState.NOT_MET and verdict.limit == pytest.approx(1.5e-3)
    assert verdict.text.startswith("tolerance 0.001 mm + 0.0005 mm for the field's scatter: NOT met — 0.004 mm "
                                   "at the nodes (edge 3)")


def test_a_figure_the_tolerance_does_not_count_says_so():
    """The cold check's grid against the field's local estimate is not what :meth:`Report.misses` counts: a
    met run whose grid finds more than the tolerance says it is not counted, rather than "met — 0.002 mm"."""
    faces = [_face(0, between=2e-3), _face(1, area=10.0)]
    report = _report(faces=faces)
    assert report.tolerance_met is True and report.verdict.state is VerdictState.MET
    assert ("0.002 mm between the nodes (face 0, against the field's local estimate; not counted against the "
            "tolerance)") in report.verdict.text
    # beside a counted figure it comes after it, and the counted one is the verdict's ``between``
    refinement = {"face": 1, "between_after": 4e-4, "delta_max_after": 1e-4, "rounds": 1, "refinable": True}
    verdict = replace(report, refinements=[refinement]).verdict
    assert verdict.between == pytest.approx(4e-4) and verdict.between_where == Place(Feature.FACE, 1)
    assert verdict.uncounted == pytest.approx(2e-3) and verdict.uncounted_where == Place(Feature.FACE, 0)
    assert verdict.text.index("0.0004 mm between the nodes (face 1)") < verdict.text.index(
        "0.002 mm off the field's local estimate between the nodes (face 0; not counted against the tolerance)")
    # NOT met at the nodes: what made it so comes first, the larger figure not counted after it
    missed = _report(faces=[_face(0, between=2e-3), _face(1, area=10.0, delta_max=1.2e-3)]).verdict
    assert missed.state is VerdictState.NOT_MET
    assert missed.text.startswith("tolerance 0.001 mm: NOT met — 0.0012 mm at the nodes (face 1), 0.002 mm between "
                                  "the nodes (face 0, against the field's local estimate; not counted against the "
                                  "tolerance); ")


def test_no_tolerance_and_nothing_measured():
    report = _report(tolerance=None, faces=[_face(0, between=float("nan"), unsupported=float("nan"))])
    verdict = report.verdict
    assert verdict.state is VerdictState.NO_TOLERANCE and verdict.limit is None and verdict.measured is None
    assert verdict.text == ("no tolerance set — 0.0002 mm at the nodes (face 0), nothing measured between the "
                            "nodes; area measured not checked")
    assert report.to_dict()["verdict"]["between"] is None             # NaN written as null


# ----------------------------------------------------------------------------------------------------------
# Colours: green only for met and fully measured
# ----------------------------------------------------------------------------------------------------------

def test_the_style_sheet_gives_green_to_the_good_tone_only():
    rules = _css_rules()
    for tone in Tone:
        body = rules[f"p.verdict.v-{tone.value}"]
        assert any(g in body for g in GREENS) == (tone is Tone.GOOD), (tone, body)
    assert any(g in rules[".ok"] for g in GREENS)
    assert not any(g in rules[".warn"] + rules[".plain"] + rules[".bad"] for g in GREENS)


@pytest.mark.parametrize("name", STATES)
def test_no_green_on_the_page_unless_met(name):
    build, state, _ = STATES[name]
    report = build()
    parts = _header(report) + page._checks(report) + page._tolerance(report)
    green = 'class="ok"' in parts or "v-good" in parts
    assert green == (state is VerdictState.MET)
    if state is not VerdictState.MET:
        assert "valid" in parts and "closed" in parts                   # still said, not in green
    if state is VerdictState.NOT_MET:
        assert 'class="bad">NOT met<' in parts
    if state is VerdictState.PARTLY_MEASURED:
        assert 'class="warn">met where measured, PARTLY measured<' in parts


def test_the_verdict_heads_the_summary():
    text = _header(_not_met())
    assert text.index('id="verdict"') < text.index('<dl class="summary">')
    dl = text[text.index('<dl class="summary">'):]
    assert dl.index("<dt>tolerance</dt>") < dl.index("<dt>cold part</dt>")       # valid, closed no headline


# ----------------------------------------------------------------------------------------------------------
# The batch summary
# ----------------------------------------------------------------------------------------------------------

def test_batch_summary_has_each_jobs_verdict(tmp_path):
    def job(name):
        return batch.Job(name, tmp_path / "hot.step", tmp_path / "f.csv", tmp_path / f"{name}.step")

    rows = [batch._result(job("a"), "ok", 0, delta_max=2e-4, verdict="met", verdict_text="tolerance ...: met"),
            batch._result(job("b"), "ok", 0, delta_max=2e-4, verdict="partly measured"),
            batch._result(job("c"), "tolerance-missed", 5, "tolerance 0.001 mm not met", 2e-3, verdict="NOT met"),
            batch._result(job("d"), "failed", 2, "field file not found")]
    data = batch.summary(tmp_path / "jobs.csv", [job(n) for n in "abcd"], rows)
    lines = batch.summary_table(data).splitlines()
    assert lines[0].split()[:3] == ["job", "status", "verdict"]
    assert lines[1].split()[:3] == ["a", "ok", "met"]
    assert lines[2].split()[:4] == ["b", "ok", "partly", "measured"]
    assert lines[3].split()[:4] == ["c", "tolerance-missed", "NOT", "met"]
    assert lines[4].split()[:3] == ["d", "failed", "-"]
    assert [r["verdict"] for r in data["jobs"]] == ["met", "partly measured", "NOT met", None]
    record = {"status": "tolerance-missed", "delta_max": 2e-3,
              "verdict": {"state": "NOT met", "text": "tolerance 0.001 mm: NOT met — ..."}}
    skipped = batch.skipped(job("c"), record)
    assert skipped["verdict"] == "NOT met" and skipped["verdict_text"].startswith("tolerance 0.001 mm: NOT met")


# ----------------------------------------------------------------------------------------------------------
# End to end: a part written with exit 5 carries the verdict
# ----------------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def bent_cube(tmp_path_factory):
    """A 20 mm cube (STEP) and a field bending it by ``dz = 2e-3 x²`` on FE-like nodes 1.5 mm apart (CSV)."""
    import cadquery as cq
    from hot2cold.kernel.sampling import fe_surface_nodes
    from hot2cold.kernel.step import write_step

    folder = tmp_path_factory.mktemp("cube")
    shape = cq.Workplane("XY").box(20.0, 20.0, 20.0).val().wrapped
    step = folder / "cube.step"
    write_step(shape, step)
    nodes = fe_surface_nodes(shape, 1.5, seed=1)[0]
    disp = np.column_stack([np.zeros(len(nodes)), np.zeros(len(nodes)), 2e-3 * nodes[:, 0] ** 2])
    field = folder / "bend.csv"
    np.savetxt(field, np.column_stack([nodes, disp]), delimiter=",", header="x,y,z,dx,dy,dz", comments="",
               fmt="%.12g")
    return step, field


@pytest.mark.heavy
def test_a_missed_tolerance_run_says_not_met_first_in_every_output(tmp_path, bent_cube, capsys):
    """The cube's 2x2 planes left unrefined (--max-refinements 0) at --tolerance 1e-4: exit 5, the cold STEP
    written, and the printed first line, the JSON report and the HTML page's headline say the same NOT met
    sentence; the output names every file written and what the node counts mean."""
    from hot2cold.cli import main

    step, field = bent_cube
    out, report, html = tmp_path / "cold.step", tmp_path / "report.json", tmp_path / "report.html"
    code = main(["morph", str(step), str(field), "-o", str(out), "--report", str(report), "--html", str(html),
                 "--tolerance", "1e-4", "--max-refinements", "0"])
    printed = capsys.readouterr().out.splitlines()
    assert code == 5 and out.is_file()
    first = printed[0]
    assert first.startswith("tolerance 0.0001 mm: NOT met — ") and "at the nodes (face " in first
    text = report.read_text(encoding="utf-8")
    assert text.splitlines()[1:3] == ['  "verdict": {', f'    "text": {json.dumps(first, ensure_ascii=False)},']
    assert json.loads(text)["verdict"]["state"] == "NOT met"
    parsed = _Verdict()
    page_text = html.read_text(encoding="utf-8")
    parsed.feed(page_text)
    assert "".join(parsed.text) == first and parsed.classes == ["verdict", "v-bad"]
    assert 'class="ok"' not in page_text
    # every file written, named with what it is; the ignored count explained
    wrote = [line for line in printed if line.startswith("wrote ")]
    assert [line.split(": ")[0] for line in wrote] == [f"wrote {report}", f"wrote {out}", f"wrote {html}"]
    assert all(": the " in line for line in wrote)
    nodes_line = next(line for line in printed if line.startswith("nodes: "))
    assert re.search(r"\d+ ignored: farther than [\d.e-]+ mm \(--node-distance\) from every face", nodes_line)


@pytest.mark.heavy
def test_a_missed_tolerance_run_without_a_report_leaves_one_beside_its_part(tmp_path, bent_cube, capsys):
    """Exit 5 with no --report: the report is written beside the cold STEP all the same, the one-line message
    names it, and it says NOT met first; a run that meets its tolerance writes no file it was not asked for."""
    from hot2cold.cli import main

    step, field = bent_cube
    out = tmp_path / "cold.step"
    code = main(["morph", str(step), str(field), "-o", str(out), "--tolerance", "1e-4", "--max-refinements", "0"])
    beside = tmp_path / "cold.report.json"
    captured = capsys.readouterr()
    assert code == 5 and out.is_file() and beside.is_file()
    assert json.loads(beside.read_text(encoding="utf-8"))["verdict"]["state"] == "NOT met"
    assert f"wrote {beside}: the report" in captured.out and str(beside) in captured.err.splitlines()[-1]

    met = tmp_path / "met"
    met.mkdir()
    assert main(["morph", str(step), str(field), "-o", str(met / "cold.step"), "-q"]) == 0
    assert sorted(p.name for p in met.iterdir()) == ["cold.step"]


def test_a_batch_job_that_misses_carries_the_verdict_beside_its_part(tmp_path, bent_cube):
    """A batch job without a report: its record beside the cold STEP starts with the verdict, its result and
    the summary's row say NOT met, and a rerun skipped keeps it."""
    step, field = bent_cube
    jobs = tmp_path / "jobs.csv"
    jobs.write_text(f"name,hot,field,output,tolerance,max_refinements\nt,{step},{field},cold.step,1e-4,0\n")
    (job,) = batch.read_jobs(jobs)
    result = batch.run_job(job)
    assert result["status"] == "tolerance-missed" and result["exit_code"] == 5 and job.output.is_file()
    assert result["verdict"] == "NOT met" and result["verdict_text"].startswith("tolerance 0.0001 mm: NOT met — ")
    text = job.record.read_text(encoding="utf-8")
    assert text.splitlines()[1:3] == ['  "verdict": {',
                                      f'    "text": {json.dumps(result["verdict_text"], ensure_ascii=False)},']
    row = batch.summary_table(batch.summary(jobs, [job], [result])).splitlines()[1]
    assert row.split()[:4] == ["t", "tolerance-missed", "NOT", "met"]
    again = batch.skipped(job, batch.done_before(job))
    assert again["verdict"] == "NOT met" and again["verdict_text"] == result["verdict_text"]
