"""The ``morph-options`` directive: the table of ``hot2cold morph``'s options and the jobs-file columns, made
from :class:`hot2cold.cli.options.MorphOptions` (the one table the command line and batch runs take their
options from), so that the reference cannot drift from the code."""
from __future__ import annotations

from dataclasses import MISSING, fields

from docutils import nodes
from docutils.parsers.rst import Directive


def _row(cells: list[str], code: int = 0) -> nodes.row:
    """A table row of ``cells``, the first ``code`` of them as literal text (a flag's two dashes stay two)."""
    row = nodes.row()
    for k, text in enumerate(cells):
        entry = nodes.entry()
        paragraph = nodes.paragraph()
        paragraph += nodes.literal(text=text) if k < code and text else nodes.Text(text)
        entry += paragraph
        row += entry
    return row


class MorphOptionsTable(Directive):
    """A table: flag (with its argument), jobs-file column, default and help text, one row per option."""

    has_content = False

    def run(self):
        from hot2cold.cli.options import MorphOptions

        header = ["flag", "jobs-file column", "default", "what it does"]
        table = nodes.table()
        group = nodes.tgroup(cols=len(header))
        table += group
        for width in (22, 18, 10, 50):
            group += nodes.colspec(colwidth=width)
        head = nodes.thead()
        head += _row(header)
        group += head
        body = nodes.tbody()
        for f in fields(MorphOptions):
            option = f.metadata["option"]
            argument = option.metavar or (f"{{{','.join(option.choices)}}}" if option.choices else "")
            flag = f"{option.flag} {argument}".strip() if option.type is not None else option.flag
            default = "" if f.default is MISSING or f.default is None else str(f.default)
            body += _row([flag, f.name, default or "(Settings)", option.help.replace("%%", "%")], code=2)
        group += body
        return [table]


def setup(app):
    app.add_directive("morph-options", MorphOptionsTable)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
