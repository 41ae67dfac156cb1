"""Loading the hot part (METHOD step 1): read it, convert it to B-splines, decompose it."""
from __future__ import annotations

import logging
import os
from dataclasses import replace

from ..errors import KernelError
from ..kernel.shapes import as_topods
from ..kernel.step import read_step
from ..kernel.topology import decompose
from ..kernel.xcaf import read_step_styles
from ..core.model import Part
from ..settings import Settings

log = logging.getLogger(__name__)


def load_part(hot, settings: Settings) -> Part:
    """Decompose ``hot`` (a STEP path, a CadQuery shape or a ``TopoDS_Shape``) into B-spline faces, shared
    edges and vertices.

    A STEP file is read through XCAF: the names and colours of its solids and faces (and its assembly
    tree) come with the part (``Part.solid_names``, ``face_names``, ``styles``), numbered as the part's
    solids and faces, so that the cold STEP can be written with them.
    """
    if not isinstance(hot, (str, os.PathLike)):
        return decompose(as_topods(hot), settings.edge_samples_per_span)
    try:
        shape, styles = read_step_styles(hot)
    except KernelError as exc:     # the names are a bonus: the part itself reads as before
        log.warning("%s; reading the part without names and colours", exc)
        shape, styles = read_step(hot), None
    part = decompose(shape, settings.edge_samples_per_span)
    if styles is None or not styles.carried:
        return part
    if len(styles.solids) != len(part.solids) or len(styles.faces) != len(part.faces):
        log.warning("the names and colours of %s do not match its %d solids and %d faces; not kept",
                    hot, len(part.solids), len(part.faces))
        return part
    return replace(part, solid_names=tuple(s.name for s in styles.solids),
                   face_names=tuple(f.name for f in styles.faces), styles=styles)
