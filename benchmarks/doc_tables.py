"""The docs' tables of what the tool prints for the bundled parts, made by the tool itself.

    python benchmarks/doc_tables.py            # write the tables into the docs' pages
    python benchmarks/doc_tables.py --check    # exit 1 and say which table differs from what the tool prints
    python benchmarks/doc_tables.py --only rotor37

Each table sits in one of the docs' :data:`PAGES` between ``<!-- doc_tables: NAME -->`` and
``<!-- /doc_tables -->``; this script morphs its part with its bundled field by default (``hot2cold morph`` without
options) and writes the rows from the report: per face its name, FE nodes (and points taken inside the FE elements),
control points hot -> cold, Δmax and Δmean at the nodes, Δ between the nodes; then the part's line (valid, exit
code) and one row per tangent edge of G1 (kink before and after, hot angle).  Nothing measured by the clock goes
into them.  A figure at the level of round-off (below :data:`ROUNDOFF_MM` or :data:`ROUNDOFF_DEG`) is written as "<
1e-09" and so on: its digits change with the processor, the BLAS build and its threads, and no user decides anything
on them.  ``--check`` (``tests/test_doc_tables.py``) compares a table's words, counts and verdicts exactly and each
other figure to the precision it is printed with (:func:`differences`).

Tables (``--only``, default all): ``rotor37`` (about 20 s), ``mixer`` (about 2 minutes), ``twisted_blade``,
``g1`` (the largest kinks before and after G1 and Δmax with and without it on four parts and fields, about
2 minutes).
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

if str(Path(__file__).resolve().parent) not in sys.path:      # doc_blocks, beside this one
    sys.path.insert(0, str(Path(__file__).resolve().parent))
import doc_blocks  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_parts"
#: The pages that hold the tables.
PAGES = (ROOT / "docs" / "benchmarks" / "bundled_parts.md", ROOT / "docs" / "guide" / "cli.md")

#: Each table: the part and its bundled field, and the words for its faces where its STEP names none (as
#: the script that made the part builds them).
TABLES = {
    "rotor37": (SAMPLES / "rotor37_blade.step", SAMPLES / "rotor37_blade_field.npz",
                ("leading edge", "pressure side", "shroud", "suction side", "hub", "trailing edge")),
    "mixer": (SAMPLES / "mixer_segment.step", SAMPLES / "mixer_segment_field.npz",
              ("outer lobed wall", "side cut", "inner lobed wall", "side cut", "inlet (plane)", "exit (plane)")),
    "twisted_blade": (SAMPLES / "twisted_blade.step", SAMPLES / "twisted_blade_field.csv", None),
    "g1": None,                       # g1_table(): four parts and fields, with and without G1
}

#: Distances [mm] and angles [°] below these are round-off, not results: the tables say "< 1e-09" for them.
ROUNDOFF_MM = 1e-9
ROUNDOFF_DEG = 1e-6


def _e(x: float) -> str:
    """A distance [mm] to three digits; round-off as ``< 1e-09``."""
    return "–" if x != x else f"< {ROUNDOFF_MM:.0e}" if x < ROUNDOFF_MM else f"{x:.2e}"


def _deg(x: float, digits: int) -> str:
    """An angle [°] to ``digits`` significant digits; round-off as ``< 1e-06``."""
    return f"< {ROUNDOFF_DEG:.0e}" if x < ROUNDOFF_DEG else f"{x:.{digits}g}"


#: A number as the tables print it: its decimals and its exponent give the precision it is stated to.
_NUMBER = re.compile(r"(?<![\w.])[-+]?\d+(?:\.(\d+))?(?:e([-+]?\d+))?(?![\w.])")


def _unit(match: re.Match) -> float:
    """One unit of the last digit a printed number states (0 for an integer: a count is exact)."""
    decimals, exponent = match.group(1), match.group(2)
    if decimals is None and exponent is None:
        return 0.0
    return 10.0 ** (int(exponent or 0) - len(decimals or ""))


def differences(written: str, made: str) -> list[str]:
    """The lines where table ``made`` (as the tool prints it now) says otherwise than ``written`` (the page's).

    Words, counts (integers) and verdicts must be the same to the letter; a figure printed with decimals
    may differ by one unit of the last digit the page states (a rounding of the same value that round-off
    tipped the other way).  Figures at the round-off level are the same text ("< 1e-09") on both sides.
    Returns one line per difference, ``written -> made``; empty where the two agree.
    """
    a, b = written.splitlines(), made.splitlines()
    if len(a) != len(b):
        return [f"{len(a)} lines written, {len(b)} made"]
    found = []
    for line_a, line_b in zip(a, b):
        numbers_a, numbers_b = list(_NUMBER.finditer(line_a)), list(_NUMBER.finditer(line_b))
        same = (_NUMBER.sub("#", line_a) == _NUMBER.sub("#", line_b) and len(numbers_a) == len(numbers_b)
                and all(abs(float(x.group()) - float(y.group())) <= 1.5 * _unit(x)
                        and (_unit(x) == 0) == (_unit(y) == 0) for x, y in zip(numbers_a, numbers_b)))
        if not same:
            found.append(f"{line_a.strip()}  ->  {line_b.strip()}")
    return found


def table(name: str) -> str:
    """The markdown of table ``name``: morph its part, rows from the report."""
    from hot2cold.pipeline.morph import morph
    from hot2cold.cli.run import tolerance_missed

    hot, field, words = TABLES[name]
    result = morph(hot, field, check=False)
    report = result.report
    refined = {r["face"]: r for r in report.refinements}
    lines = ["| face | name | FE nodes | control points | Δmax [mm] | Δmean [mm] | Δ between the nodes [mm] |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for f in report.faces:
        title = words[f.index] if words else f.name
        net = f.control_points.replace("x", "×")
        if f.index in refined:
            net = f"{refined[f.index]['net_before'].replace('x', '×')} → {net}"
        lines.append(f"| {f.index} | {title} | {f.nodes} | {net} | {_e(f.delta_max)} | {_e(f.delta_mean)} | "
                     f"{_e(f.delta_between)} |")
    solids = ", ".join(f"{'valid' if s.valid else 'invalid'}, {'closed' if s.free_edges == 0 else 'open'}"
                       for s in report.solids)
    inside = f" and {report.element_points} points inside its FE elements" if report.element_points else ""
    code = 5 if tolerance_missed(result) else 0
    lines += ["", f"{report.nodes_total - report.element_points} nodes{inside}; {solids}; Δmax {_e(report.delta_max)} "
              f"mm, Δmean {_e(report.delta_mean)} mm; exit {code}."]
    if report.g1:
        lines += ["", "| tangent edge | faces | hot angle [°] | kink before [°] | kink after [°] | how |",
                  "| --- | --- | --- | --- | --- | --- |"]
        for g in report.g1:
            how = g["method"] if g["corrected"] else f"not corrected: {g['reason']}"
            lines.append(f"| {g['edge']} | {g['faces'][0]}, {g['faces'][1]} | {_deg(g['hot_angle_max'], 2)} | "
                         f"{_deg(g['kink_before_max'], 3)} | {_deg(g['kink_after_max'], 2)} | {how} |")
    return "\n".join(lines) + "\n"


def g1_table() -> str:
    """The G1 table: per part and field, its tangent edges, the largest kink before and after G1 (degrees)
    and Δmax with and without G1 (``Settings(g1_angle=None)``)."""
    from hot2cold.kernel.sampling import fe_surface_nodes
    from hot2cold.kernel.step import read_step
    from hot2cold.pipeline.morph import morph
    from hot2cold.settings import Settings
    from hot2cold.testing.synthetic import UntwistField

    block = read_step(SAMPLES / "filleted_block.step")
    nodes = fe_surface_nodes(block, 1.5, seed=2)[0]            # the node set of tests/test_g1.py

    def untwist(rate):
        return nodes, UntwistField.over(nodes, rate, 1e-4)(nodes)

    cases = [("twisted blade, bundled field", SAMPLES / "twisted_blade.step", SAMPLES / "twisted_blade_field.csv"),
             ("filleted block, untwist 0.03°/mm + z² stretch", block, untwist(0.03)),
             ("filleted block, untwist 0.05°/mm + z² stretch", block, untwist(0.05)),
             ("Rotor 37, bundled CalculiX field (trimming curves)", SAMPLES / "rotor37_blade.step",
              SAMPLES / "rotor37_blade_field.npz")]
    lines = ["| part, field | tangent edges | kink before [°] | kink after [°] | Δmax with / without G1 [mm] |",
             "| --- | --- | --- | --- | --- |"]
    for name, hot, field in cases:
        with_g1 = morph(hot, field, check=False).report
        without = morph(hot, field, Settings(g1_angle=None), check=False).report
        before = max(g["kink_before_max"] for g in with_g1.g1)
        after = max(g["kink_after_max"] for g in with_g1.g1)
        refined = sum("refined" in g["method"] for g in with_g1.g1)
        name += " (faces refined for G1)" if refined else ""
        lines.append(f"| {name} | {len(with_g1.g1)} | {_deg(before, 3)} | {_deg(after, 2)} | "
                     f"{_e(with_g1.delta_max)} / {_e(without.delta_max)} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare, do not write; exit 1 on a difference")
    parser.add_argument("--only", default=",".join(TABLES), help="comma-separated tables (default: all)")
    args = parser.parse_args(argv)
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = sorted(set(names) - set(TABLES))
    if unknown:
        parser.error(f"unknown table(s) {', '.join(unknown)}: choose from {', '.join(TABLES)}")
    texts = {page: page.read_text(encoding="utf-8") for page in PAGES}
    blocks = {b.name: (page, b) for page, text in texts.items() for b in doc_blocks.blocks(text)}
    missing = [n for n in names if n not in blocks]
    if missing:
        print(f"no page of the docs has a block for {', '.join(missing)} ({doc_blocks.OPEN})", file=sys.stderr)
        return 2
    made = {n: g1_table() if n == "g1" else table(n) for n in names}
    found = {n: differences(blocks[n][1].body, doc_blocks.indented(made[n], blocks[n][1].indent)) for n in names}
    differ = [n for n in names if found[n]]
    if args.check:
        for n in differ:
            print(f"{doc_blocks.shown(blocks[n][0])}: table {n} differs from what the tool prints now:\n  "
                  + "\n  ".join(found[n]), file=sys.stderr)
        return 1 if differ else 0
    for page, text in texts.items():
        new = doc_blocks.replace_all(text, {n: made[n] for n in doc_blocks.names(text) if n in made})
        if new != text:
            page.write_text(new, encoding="utf-8")
    print(f"{', '.join(differ) or 'no table'} rewritten")
    return 0


if __name__ == "__main__":
    sys.exit(main())
