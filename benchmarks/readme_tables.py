"""The README's tables of what the tool prints for the bundled parts, made by the tool itself.

    python benchmarks/readme_tables.py            # write the tables into README.md
    python benchmarks/readme_tables.py --check    # exit 1 and say which table differs from what the tool prints
    python benchmarks/readme_tables.py --only rotor37

Each table sits in the README between ``<!-- readme_tables: NAME -->`` and ``<!-- /readme_tables -->``; this
script morphs its part with its bundled field by default (``hot2cold morph`` without options) and writes the
rows from the report: per face its name, FE nodes (and points taken inside the FE elements), control points
hot -> cold, Δmax and Δmean at the nodes, Δ between the nodes; then the part's line (valid, exit code) and
one row per tangent edge of G1 (kink before and after, hot angle).  Nothing measured by the clock goes into
them, so ``--check`` (``tests/test_readme_tables.py``) compares them exactly.

Tables (``--only``, default all): ``rotor37`` (about 20 s), ``mixer`` (about 2 minutes), ``twisted_blade``,
``g1`` (the largest kinks before and after G1 and Δmax with and without it on four parts and fields, about
2 minutes).
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_parts"
README = ROOT / "README.md"

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

#: A table's place: its markers, indented as the text around them (a table inside a list item), and between them
#: the table, indented the same.
_BLOCK = re.compile(r"^(( *)<!-- readme_tables: (\w+) -->\n)(.*?)(^\2<!-- /readme_tables -->)", re.S | re.M)


def _e(x: float) -> str:
    return "–" if x != x else f"{x:.2e}"


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
            lines.append(f"| {g['edge']} | {g['faces'][0]}, {g['faces'][1]} | {g['hot_angle_max']:.2g} | "
                         f"{g['kink_before_max']:.3g} | {g['kink_after_max']:.2g} | {how} |")
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
        lines.append(f"| {name} | {len(with_g1.g1)} | {before:.3g} | {after:.2g} | "
                     f"{_e(with_g1.delta_max)} / {_e(without.delta_max)} |")
    return "\n".join(lines) + "\n"


def _indented(text: str, indent: str) -> str:
    return "".join(indent + line if line.strip() else line for line in text.splitlines(keepends=True))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare, do not write; exit 1 on a difference")
    parser.add_argument("--only", default=",".join(TABLES), help="comma-separated tables (default: all)")
    args = parser.parse_args(argv)
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = sorted(set(names) - set(TABLES))
    if unknown:
        parser.error(f"unknown table(s) {', '.join(unknown)}: choose from {', '.join(TABLES)}")
    text = README.read_text(encoding="utf-8")
    blocks = {m.group(3): m for m in _BLOCK.finditer(text)}
    missing = [n for n in names if n not in blocks]
    if missing:
        print(f"README.md has no block for {', '.join(missing)} (<!-- readme_tables: NAME -->)", file=sys.stderr)
        return 2
    made = {n: _indented(g1_table() if n == "g1" else table(n), blocks[n].group(2)) for n in names}
    differ = [n for n in names if blocks[n].group(4) != made[n]]
    if args.check:
        for n in differ:
            print(f"README table {n} differs from what the tool prints now:\n{made[n]}", file=sys.stderr)
        return 1 if differ else 0
    new = _BLOCK.sub(lambda m: m.group(1) + made.get(m.group(3), m.group(4)) + m.group(5), text)
    README.write_text(new, encoding="utf-8")
    print(f"README.md: {', '.join(differ) or 'no table'} rewritten")
    return 0


if __name__ == "__main__":
    sys.exit(main())
