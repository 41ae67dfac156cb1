"""Loading (METHOD step 1): the hot part read, converted to B-splines and decomposed; the field's points.

:func:`load` does it once for several morphs (the load cases of one part): its :class:`LoadedPart` is given to
:func:`~hot2cold.pipeline.morph.morph` in place of the STEP file, and each morph starts at the classification.

A field that brings its FE elements (``DisplacementField.triangles``) is also sampled inside its boundary
triangles by their own shape functions (:func:`element_points`): what the solver says between its nodes,
so the fits and the refinement follow the FE solution there rather than an estimate from the nodes.
"""
from __future__ import annotations

import logging
import os
import threading
from dataclasses import dataclass, field as dataclass_field, replace

import numpy as np

from ..core.elements import TRIANGLE_SAMPLES, sample_triangles
from ..errors import InputError, KernelError
from ..kernel.shapes import ShapeType, as_topods, shape_type
from ..kernel.side import KernelSide, Volumes
from ..kernel.step import read_step
from ..kernel.topology import decompose
from ..kernel.validity import SolidCheck, check_solids
from ..kernel.xcaf import read_step_styles
from ..core.model import Part
from ..io.field import DisplacementField
from ..settings import Settings
from .checks import check_hot

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class LoadedPart:
    """A hot part loaded once (METHOD step 1, :func:`load`) for several morphs, the load cases of one part:
    given to :func:`~hot2cold.pipeline.morph.morph` in place of the STEP file or shape, it is neither read nor
    converted again, and its volumes are integrated once.  A morph of it gives what a morph of the file gives.

    Attributes
    ----------
    part : Part, the hot part in B-spline form.
    checks : one :class:`~hot2cold.kernel.validity.SolidCheck` per solid of the converted part (``part.kernel.hot``),
        without volumes; the part passed :func:`~hot2cold.pipeline.checks.check_hot`.
    name : str, the hot part as the report names it: the STEP path, else the class of the shape given.
    shape_type : ShapeType, the library (and class) the cold part comes back in.
    edge_samples_per_span : int, ``Settings.edge_samples_per_span`` it was decomposed with: a morph with
        another refuses it.

    Its morphs run one at a time (a morph of it from another thread waits): each keeps the rows it asks of the
    hot faces while it runs.
    """

    part: Part
    checks: list[SolidCheck]
    name: str
    shape_type: ShapeType
    edge_samples_per_span: int
    #: The hot solids' volumes, once asked for (:meth:`volumes`): the first morph's, kept for the others.
    _volumes: list = dataclass_field(default_factory=list, repr=False)
    #: Held by each morph while it runs (:meth:`morphing`).
    _lock: threading.Lock = dataclass_field(default_factory=threading.Lock, repr=False)

    def __repr__(self) -> str:
        solids = len(self.part.solids)
        return (f"LoadedPart({self.name!r}: {solids} solid{'s' * (solids != 1)}, {len(self.part.faces)} faces, "
                f"{len(self.part.edges)} edges)")

    def volumes(self, side: KernelSide) -> Volumes:
        """The hot solids' volumes (mm^3): asked of ``side`` (integrated by its second process while the morph
        goes on, or in this one) until a morph has had them, then that answer for every morph."""
        if not self._volumes or not self._volumes[0].known:
            self._volumes[:] = [side.volumes(self.part.kernel.hot)]
        return self._volumes[0]

    def check(self, settings: Settings) -> None:
        """Raise :class:`InputError` where ``settings`` ask for another load than this one."""
        if settings.edge_samples_per_span != self.edge_samples_per_span:
            raise InputError(f"the part {self.name} was loaded with edge_samples_per_span "
                             f"{self.edge_samples_per_span}, the morph asks for {settings.edge_samples_per_span}: "
                             "load it again with the morph's settings")

    def morphing(self, settings: Settings) -> threading.Lock:
        """The lock a morph of this part holds while it runs, once ``settings`` are found to match the load's
        (:meth:`check`)."""
        self.check(settings)
        return self._lock


def load(hot, settings: Settings | None = None) -> LoadedPart:
    """The hot part ``hot`` (a STEP path, a CadQuery or build123d shape, a ``TopoDS_Shape``) loaded for morphs
    (:func:`load_part`, then refused as a morph refuses it, :func:`~hot2cold.pipeline.checks.check_hot`), so that
    several fields (load cases) morph it without reading and converting it again::

        part = hot2cold.load("blade.step")
        cold = [hot2cold.morph(part, field) for field in ("case1.csv", "case2.csv")]

    ``settings``: those of the morphs (only ``edge_samples_per_span`` matters here; default ``Settings()``).  A
    :class:`LoadedPart` comes back as it is where it was loaded with them.

    Raises
    ------
    StepReadError, InputError, KernelError : as :func:`~hot2cold.pipeline.morph.morph` for the same part.
    """
    settings = settings or Settings()
    if isinstance(hot, LoadedPart):
        hot.check(settings)
        return hot
    part = load_part(hot, settings)
    checks = check_solids(part.kernel.hot, volumes=False)
    check_hot(part, checks)
    name = str(hot) if isinstance(hot, (str, os.PathLike)) else type(hot).__name__
    return LoadedPart(part, checks, name, shape_type(hot), settings.edge_samples_per_span)


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
