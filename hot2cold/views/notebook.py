"""How a morph shows itself in a notebook (Jupyter, VS Code): IPython's ``_repr_html_`` of
:class:`~hot2cold.pipeline.result.MorphResult` and :class:`~hot2cold.pipeline.report.Report` calls these.

A result shows the report page without its pictures (the verdict, the figures, the 3D view coloured by the
displacement, switchable to the deviation from the field, and the tables) in an ``<iframe>`` whose ``srcdoc``
is the page: the page's styles and import map stay its own, and it needs no network and no running kernel once
drawn.  A report alone shows its verdict, its figures and the face table, without scripts.
"""
from __future__ import annotations

import html

from .page import STYLE, head_sections, render_html

#: The height of a result's frame in a notebook (CSS pixels): the verdict, the figures and the 3D view.
FRAME_HEIGHT = 980


def result_html(result, colour: str = "displacement") -> str:
    """The notebook display of ``result`` (a MorphResult): its report page without pictures in an ``<iframe>``,
    the 3D view coloured by ``colour`` first ("displacement" or "deviation")."""
    page = render_html(result, figures=False, colour=colour)
    return (f'<iframe srcdoc="{html.escape(page, quote=True)}" title="hot2cold: the cold part and its report" '
            f'style="width: 100%; height: {FRAME_HEIGHT}px; border: 1px solid #ddd"></iframe>')


def report_html(report) -> str:
    """The notebook display of ``report`` (a Report): its verdict, its figures and the face table."""
    return f'<div class="hot2cold-report"><style>{_scoped(STYLE)}</style>{head_sections(report)}</div>'


def _scoped(style: str) -> str:
    """``style`` (the report page's CSS) with each rule limited to the report's ``<div>`` in the notebook."""
    rules = []
    for rule in style.split("}"):
        selectors, brace, body = rule.partition("{")
        if not brace:
            continue
        scoped = ", ".join(f".hot2cold-report {s.strip()}" if s.strip() not in ("body", "html")
                           else ".hot2cold-report" for s in selectors.split(","))
        rules.append(f"{scoped} {{{body}}}")
    return "\n".join(rules)
