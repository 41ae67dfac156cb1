"""Loading the hot part (METHOD step 1): read it, convert it to B-splines, decompose it."""
from __future__ import annotations

import logging

from .kernel.shapes import as_topods
from .kernel.topology import decompose
from .model import Part
from .settings import Settings

log = logging.getLogger(__name__)


def load_part(hot, settings: Settings) -> Part:
    """Decompose ``hot`` (a STEP path, a CadQuery shape or a ``TopoDS_Shape``) into B-spline faces, shared
    edges and vertices."""
    return decompose(as_topods(hot), settings.edge_samples_per_span)
