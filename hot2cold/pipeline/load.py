"""Loading (METHOD step 1): the hot part read, converted to B-splines and decomposed; the field's points.

A field that brings its FE elements (``DisplacementField.triangles``) is also sampled inside its boundary
triangles by their own shape functions (:func:`element_points`): what the solver says between its nodes,
so the fits and the refinement follow the FE solution there rather than an estimate from the nodes.
"""
from __future__ import annotations

import logging
import os
from dataclasses import replace

import numpy as np

from ..core.elements import TRIANGLE_SAMPLES, sample_triangles
from ..errors import KernelError
from ..kernel.shapes import as_topods
from ..kernel.step import read_step
from ..kernel.topology import decompose
from ..kernel.xcaf import read_step_styles
from ..core.model import Part
from ..io.field import DisplacementField
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


def element_points(field: DisplacementField, settings: Settings) -> tuple[DisplacementField, int]:
    """``field`` with points inside its FE boundary triangles added, and how many were added.

    Each triangle (``field.triangles`` ``(T, 3 or 6)``) gets the points of
    :data:`~hot2cold.core.elements.TRIANGLE_SAMPLES` (4 each), placed and valued by its shape functions
    (:func:`~hot2cold.core.elements.sample_triangles`): the FE model's own field between its nodes.  They
    follow the field's nodes (rows ``0..N-1`` unchanged), with node id -1 when the field has ids.  Nothing is
    added when the field has no triangles or ``settings.element_points`` is off.
    """
    if field.triangles is None or not settings.element_points:
        return field, 0
    positions, values = sample_triangles(field.points, field.triangles, field.displacements, TRIANGLE_SAMPLES)
    ids = None if field.node_ids is None else np.concatenate([field.node_ids, np.full(len(positions), -1)])
    log.info("field %s: %d points inside its %d boundary triangles added to its %d nodes (the elements' shape "
             "functions)", field.source, len(positions), len(field.triangles), len(field))
    return replace(field, points=np.vstack([field.points, positions]),
                   displacements=np.vstack([field.displacements, values]), node_ids=ids), len(positions)
