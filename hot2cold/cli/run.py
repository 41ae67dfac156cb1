"""One morph run, as ``hot2cold morph`` and every batch job do it: morph with the options, write the
report, check the cold part, write the cold STEP, say when the tolerance was missed.

Library code: nothing here prints; it raises :class:`~hot2cold.errors.Hot2ColdError`.  The morph and the
kernel are imported when first used, so the command line starts (and ``--help`` answers) without them.
"""
from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path
from typing import Iterator

from ..io.atomic import write_atomically
from .options import MorphOptions


def run_morph(hot, field, options: MorphOptions, progress=None, threads: int = 1):
    """:func:`~hot2cold.pipeline.morph.morph` of ``hot`` (STEP path, or the part loaded from it,
    :class:`~hot2cold.pipeline.load.LoadedPart`) with ``field`` (field file path) under
    ``options``, in up to ``threads`` threads (``Settings.threads``: ``hot2cold morph`` gives its cores, a
    batch job one), with the volumes in a second process where it has more than one
    (``Settings.kernel_process``); returns the :class:`~hot2cold.pipeline.morph.MorphResult`, unchecked:
    :func:`write_cold` writes the report first and then refuses an invalid part."""
    from ..pipeline.morph import morph

    settings = replace(options.to_settings(), threads=threads, kernel_process=threads > 1)
    return morph(hot, field, settings, **options.morph_arguments(), progress=progress, check=False)


def write_json(data: dict, path: str | os.PathLike) -> None:
    """Write ``data`` as indented JSON to ``path``, whole or not at all."""
    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(data, fh, indent=2, ensure_ascii=False)    # the verdict as the report writes it
            fh.write("\n")

    write_atomically([(Path(path), write)])


def write_cold(result, output: str | os.PathLike, report: str | os.PathLike | None = None) -> Iterator[Path]:
    """Write what a morph gives: the JSON report (if asked; written even for an invalid part), then, once
    :func:`~hot2cold.pipeline.morph.check_result` passes, the cold STEP.  ``result`` is the morph's
    :class:`~hot2cold.pipeline.morph.MorphResult`, already made.  Yields each path as it is written; raises
    :class:`MorphError` (invalid part: ``write_step`` checks it) or :class:`OutputError`."""
    if report is not None:
        write_json(result.report.to_dict(), report)
        yield Path(report)
    result.write_step(output)
    yield Path(output)


#: The viewer files a run may write besides the cold STEP and the report: ``hot2cold morph``'s flags and a
#: batch job's columns of the same names.
VIEWS = ("vtu", "stl", "glb", "html")


def view_outputs(views: dict) -> list[tuple[str, Path]]:
    """The files the ``views`` asked for (``{"vtu": path or None, ...}``) will be, as (what, path): a VTU is
    two files, the nodes and the cold surface beside them."""
    from ..views.export import surface_path

    out = []
    for what in VIEWS:
        path = views.get(what)
        if path is not None:
            out.append((what, Path(path)))
            if what == "vtu":
                out.append(("vtu surface", surface_path(path)))
    return out


def write_views(result, views: dict, scale: float | None = None) -> Iterator[Path]:
    """Write the viewer files of ``views`` (``{"vtu": path or None, "stl": ..., "glb": ..., "html": ...}``)
    of a morph ``result``, yielding each path as soon as it is written; the cold surface is triangulated once
    for all of them.  ``scale``: the displacement magnification of the HTML report's pictures.  Raises
    :class:`OutputError` when one cannot be written (those before it stay written)."""
    from ..views import export

    surface = None
    if any(views.get(what) for what in ("vtu", "stl", "glb")):
        surface = export.cold_surface(result)
    if views.get("vtu"):
        yield from export.write_vtu(result, views["vtu"], surface)
    if views.get("stl"):
        yield export.write_stl(result, views["stl"], surface)
    if views.get("glb"):
        yield export.write_glb(result, views["glb"], surface)
    if views.get("html"):
        from ..views.page import write_html

        write_html(result, views["html"], scale=scale)       # atomic itself; OutputError on failure
        yield Path(views["html"])


def tolerance_missed(result) -> str | None:
    """The one-line message when the morph's tolerance (``--tolerance``, default 1e-3 mm) was not met, else
    None."""
    report = result.report
    if report.tolerance_met is not False:
        return None
    noise = (f" + {report.allowance:.3g} mm for the field's scatter" if report.allowance > 0.1 * report.tolerance
             else "")
    misses = report.misses()
    where, error = misses[0]
    more = f" and {len(misses) - 1} more" if len(misses) > 1 else ""
    return (f"tolerance {report.tolerance:g} mm{noise} not met ({where}: {error:.3g} mm{more}; the report says "
            f"where); the cold part is written")
