"""One morph run, as ``hot2cold morph`` and every batch job do it: morph with the options, write the
report, check the cold part, write the cold STEP, say when the tolerance was missed.

Library code: nothing here prints; it raises :class:`~hot2cold.errors.Hot2ColdError`.  The morph and the
kernel are imported when first used, so the command line starts (and ``--help`` answers) without them.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Iterator

from ..io.atomic import write_atomically
from .options import MorphOptions


def run_morph(hot, field, options: MorphOptions, progress=None):
    """:func:`~hot2cold.pipeline.morph.morph` of ``hot`` (STEP path) with ``field`` (field file path) under
    ``options``; returns the :class:`~hot2cold.pipeline.morph.MorphResult`, unchecked: :func:`write_cold`
    writes the report first and then refuses an invalid part."""
    from ..pipeline.morph import morph

    return morph(hot, field, options.to_settings(), **options.morph_arguments(), progress=progress, check=False)


def write_json(data: dict, path: str | os.PathLike) -> None:
    """Write ``data`` as indented JSON to ``path``, whole or not at all."""
    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(data, fh, indent=2)
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
