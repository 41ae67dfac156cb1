"""The docs' generated blocks (``benchmarks/doc_blocks.py``): a table is written between its markers and
nowhere else, a missing block is an error that names it, and every block that ``real_parts.py --doc`` and
``scale.py --doc`` write is in the page it is meant for (a renamed marker fails here, not at the next long run).
"""
from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import pytest

from conftest import benchmark_module

ROOT = Path(__file__).resolve().parents[1]

PAGE = """# A page

Some text.

<!-- doc_tables: first -->
| a | b |
|---|---|
| 1 | 2 |
<!-- /doc_tables -->

* In a list:

  <!-- doc_tables: second -->
  | old |
  |---|
  <!-- /doc_tables -->

The end.
"""


@pytest.fixture(scope="module")
def doc_blocks():
    with benchmark_module("doc_blocks") as module:
        yield module


@pytest.fixture(scope="module")
def scale():
    with benchmark_module("scale") as module:
        yield module


@pytest.fixture(scope="module")
def frd_files():
    with benchmark_module("frd_files") as module:
        yield module


def test_blocks_are_found_with_names_and_indentation(doc_blocks):
    found = doc_blocks.blocks(PAGE)
    assert [(b.name, b.indent) for b in found] == [("first", ""), ("second", "  ")]
    assert found[0].body == "| a | b |\n|---|---|\n| 1 | 2 |\n"
    assert PAGE[found[1].start:found[1].end] == found[1].body
    assert doc_blocks.names(PAGE) == ["first", "second"]
    assert doc_blocks.missing(PAGE, ["second", "third", "first", "fourth"]) == ["third", "fourth"]


def test_replace_writes_the_body_and_keeps_the_rest(doc_blocks):
    new = doc_blocks.replace(PAGE, "first", "| x |\n|---|\n| 9 |")
    assert "<!-- doc_tables: first -->\n| x |\n|---|\n| 9 |\n<!-- /doc_tables -->" in new
    assert "| 1 | 2 |" not in new
    before, after = PAGE.split("<!-- doc_tables: first -->")[0], PAGE.split("<!-- /doc_tables -->", 1)[1]
    assert new.startswith(before + "<!-- doc_tables: first -->\n") and new.endswith(after)


def test_replace_keeps_the_markers_indentation(doc_blocks):
    new = doc_blocks.replace(PAGE, "second", "| new |\n|---|\n\nsummary line\n")
    assert ("  <!-- doc_tables: second -->\n  | new |\n  |---|\n\n  summary line\n  <!-- /doc_tables -->\n"
            in new)
    assert doc_blocks.blocks(new)[1].body == "  | new |\n  |---|\n\n  summary line\n"
    assert doc_blocks.blocks(new)[0] == doc_blocks.blocks(PAGE)[0]          # the other block untouched


def test_two_blocks_on_one_page(doc_blocks):
    new = doc_blocks.replace_all(PAGE, {"first": "one\n", "second": "two\n"})
    assert [b.body for b in doc_blocks.blocks(new)] == ["one\n", "  two\n"]
    assert new.count("<!-- /doc_tables -->") == 2


def test_replace_is_idempotent(doc_blocks):
    once = doc_blocks.replace_all(PAGE, {"first": "one\n", "second": "two"})
    assert doc_blocks.replace_all(once, {"first": "one\n", "second": "two"}) == once
    back = doc_blocks.replace_all(once, {b.name: textwrap.dedent(b.body) for b in doc_blocks.blocks(PAGE)})
    assert back == PAGE                                      # the page's own tables written back: the same page


def test_a_missing_block_is_named(doc_blocks):
    with pytest.raises(doc_blocks.MissingBlocks, match="third") as raised:
        doc_blocks.replace_all(PAGE, {"first": "one\n", "third": "three\n"})
    assert raised.value.names == ["third"]


def test_a_marker_without_its_closing_one_is_no_block(doc_blocks):
    broken = PAGE.replace("  <!-- /doc_tables -->\n", "")
    assert doc_blocks.names(broken) == ["first"]
    unindented = PAGE.replace("  <!-- /doc_tables -->", "<!-- /doc_tables -->")     # closed at another indent
    assert doc_blocks.names(unindented) == ["first"]


def test_write_fills_the_pages_and_says_where(tmp_path, doc_blocks):
    a, b = tmp_path / "a.md", tmp_path / "b.md"
    a.write_text(PAGE, encoding="utf-8")
    b.write_text("<!-- doc_tables: third -->\n<!-- /doc_tables -->\n", encoding="utf-8")
    written = doc_blocks.write([a, b], {"first": "one\n", "third": "three\n"})
    assert [(Path(p).name, n, changed) for p, n, changed in written] == [("a.md", ["first"], True),
                                                                        ("b.md", ["third"], True)]
    assert b.read_text(encoding="utf-8") == "<!-- doc_tables: third -->\nthree\n<!-- /doc_tables -->\n"
    text_a = a.read_text(encoding="utf-8")
    again = doc_blocks.write([a, b], {"first": "one\n", "third": "three\n"})
    assert [changed for _, _, changed in again] == [False, False]
    assert a.read_text(encoding="utf-8") == text_a
    assert "(unchanged)" in doc_blocks.report(again)


def test_write_refuses_a_table_without_its_block_and_writes_nothing(tmp_path, doc_blocks, capsys):
    page = tmp_path / "page.md"
    page.write_text(PAGE, encoding="utf-8")
    with pytest.raises(doc_blocks.MissingBlocks, match="no block scale_rotor37 in .*page.md"):
        doc_blocks.write([page], {"first": "one\n", "scale_rotor37": "table\n"})
    assert page.read_text(encoding="utf-8") == PAGE
    assert doc_blocks.doc_main([page], {"scale_rotor37": "table\n"}) == 2
    assert "scale_rotor37" in capsys.readouterr().err
    assert doc_blocks.doc_main([page], table_names=["first", "second"]) == 0
    assert doc_blocks.doc_main([tmp_path / "absent.md"], table_names=["first"]) == 2


# ---------------------------------------------------------------- the scripts' blocks are in their pages


def test_real_parts_blocks_are_in_their_pages(doc_blocks, real_parts):
    assert set(real_parts.doc_tables([])) == set(real_parts.DOC_PAGES)
    for name, page in real_parts.DOC_PAGES.items():
        assert name in doc_blocks.names(page.read_text(encoding="utf-8")), f"no block {name} in {page}"


def _scale_row(blade: str, nodes: int) -> dict:
    """A saved row of ``scale.py --json`` (figures made up)."""
    stages = dict.fromkeys(("imports", "load", "classify", "fit", "refine", "g1", "rebuild_sew", "check", "report",
                            "write"), 0.5)
    compare = {"face_nodes": nodes, "other_face": 0, "distance_max_diff_mm": 0.0, "uv_max_rel_diff": 0.0,
               "boundary_nodes_on_a_direct_face": True, "ignored_here": 0, "ignored_direct": 0}
    return {**stages, "blade": blade, "nodes": nodes, "threads": 2, "total": 5.0, "peak_mb": 700.0,
            "direct": 10.0, "compare": compare, "delta_max": 1.5e-5, "exact_max": 3e-5, "exact_mean": 2e-6,
            "exact_face_max": [3e-5, 1e-5], "valid": True, "face_rank": ["4/4", "4/4"]}


def test_scale_blocks_are_in_their_pages(doc_blocks, scale):
    for name, page in scale.DOC_PAGES.items():
        assert name in doc_blocks.names(page.read_text(encoding="utf-8")), f"no block {name} in {page}"
    made = scale.doc_tables([_scale_row("thin_blade", 3000), _scale_row("thin_blade", 30000)])
    assert set(made) <= set(scale.DOC_PAGES)
    assert made["scale_thin_blade"].count("| thin_blade |") == 2


def test_scale_show_doc_writes_the_page_and_refuses_a_missing_block(tmp_path, monkeypatch, capsys, scale):
    """``scale.py --show F --doc PAGE`` end to end on made-up rows and a copy of the speed page."""
    monkeypatch.setattr(sys, "argv", ["scale.py"])
    rows = tmp_path / "rows.json"
    rows.write_text(json.dumps([_scale_row("thin_blade", 3000)]))
    page = tmp_path / "speed.md"
    page.write_text(scale.DOC_PAGES["scale_thin_blade"].read_text(encoding="utf-8"), encoding="utf-8")
    assert scale.main(["--show", str(rows), "--doc", str(page)]) == 0
    assert "wrote scale_thin_blade" in capsys.readouterr().out
    written = page.read_text(encoding="utf-8")
    assert "| thin_blade | 3000 |" in written and "| thin_blade | 974151 |" not in written
    assert scale.main(["--show", str(rows), "--doc", str(page)]) == 0
    assert page.read_text(encoding="utf-8") == written                          # idempotent
    rows.write_text(json.dumps([_scale_row("thin_blade", 3000), _scale_row("rotor37", 3000)]))
    assert scale.main(["--show", str(rows), "--doc", str(page)]) == 2           # rotor37 has no block there
    assert "no block scale_rotor37" in capsys.readouterr().err
    assert page.read_text(encoding="utf-8") == written
    assert scale.main(["--show", str(rows), "--blades", "thin_blade", "--doc", str(page)]) == 0


def test_frd_files_blocks_are_in_their_pages(doc_blocks, frd_files):
    for name, page in frd_files.DOC_PAGES.items():
        assert name in doc_blocks.names(page.read_text(encoding="utf-8")), f"no block {name} in {page}"
    rows = [{"file": "a.frd", "kinds": "he20,te10", "outcome": "same", "why": "", "notes": [],
             "blocks": ["DISP block 1 of 2: step 1, time 1", "DISP block 2 of 2: step 2, time 2"]},
            {"file": "b.frd", "kinds": "he8", "outcome": "refused", "why": "no DISP | here", "notes": [], "blocks": []}]
    made = frd_files.doc_tables(rows)
    assert set(made) == set(frd_files.DOC_PAGES)
    assert "| same | 1 | 2 | 1 | 0 | 1 |" in made["frd_files_outcomes"]      # the kinds he20, he8, te10 sorted
    assert "| total | 2 | 2 | 1 | 1 | 1 |" in made["frd_files_outcomes"]
    assert "| `b.frd` | he8 | 0 |  | refused | no DISP / here |" in made["frd_files_rows"]
