"""What a morph gives back (:class:`MorphResult`) and the check that every cold part passes before it is returned
or written (:func:`check_result`)."""
from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..core.model import Classification, Part
from ..errors import MorphError
from ..io.field import DisplacementField
from ..kernel.rebuild import ColdKernel
from ..kernel.shapes import ShapeType, to_user_shape
from ..kernel.step import write_step
from ..kernel.topology import solid_fault
from .edge_fit import EdgeMorph
from .face_fit import FaceMorph
from .report import Report

log = logging.getLogger(__name__)


@dataclass(eq=False)
class MorphResult:
    """What a morph gives back.

    Attributes
    ----------
    report : Report, accuracy and checks.
    part, classification, faces, edges : the intermediate records, for inspection (``part`` is the hot part,
        refined where a tolerance asked for it; its kernel side is the hot part's as loaded).
    field : DisplacementField, the field used (hot positions and hot-to-cold displacements, inverted if
        asked), one row per entry of ``classification``: a node on coincident faces of two solids is in it
        once per solid it feeds (``classification.node`` gives the row of the field as given).
    node_errors : (N,) float array, each entry's distance (mm) to the cold part (eq. 21); NaN where ignored.
    cold_kernel : ColdKernel, the cold part's kernel shape with its faces, edges and vertices in the part's
        numbering (``cold`` wraps its shape).
    problems : tuple of str, what the checks after the sew found wrong with the cold part (a face folded
        over, a solid turned inside out or crossing itself; such solids are reported invalid), one line each;
        :func:`check_result` raises on them.
    shape_type : ShapeType, the library (and class) ``cold`` and ``hot`` come back in: the hot part's when
        it was a build123d object, else CadQuery's.

    ``cold`` and ``hot`` are the parts as CadQuery (or build123d) shapes, made when first asked for (CadQuery
    and VTK are slow to import, and a morph on the command line does not need them).
    """

    report: Report
    part: Part
    classification: Classification
    faces: list[FaceMorph]
    edges: list[EdgeMorph]
    field: DisplacementField
    node_errors: np.ndarray
    cold_kernel: ColdKernel
    problems: tuple[str, ...] = ()
    shape_type: ShapeType = ShapeType()

    @cached_property
    def cold(self):
        """cadquery.Shape, the cold part (a Solid, or a Compound of solids), same topology as the hot one; a
        build123d ``Solid``, ``Part`` or ``Compound`` (the hot part's class) when the hot part was one."""
        return to_user_shape(self.cold_kernel.shape, self.shape_type)

    @cached_property
    def hot(self):
        """The hot part in B-spline form, parameterised as the cold one, in the library of ``cold``."""
        return to_user_shape(self.part.kernel.hot, self.shape_type)

    def _repr_html_(self) -> str:
        """How a notebook shows the result: the verdict, the figures, the 3D view of the cold part coloured by
        its displacement (switchable to the deviation from the field) and the tables
        (:func:`hot2cold.views.notebook.result_html`; the one import of the views from below them)."""
        from ..views.notebook import result_html

        return result_html(self)

    def write_step(self, path: str | os.PathLike) -> None:
        """Write the cold part to a STEP file (atomically).

        When the hot STEP carried names or colours, the cold file is written through XCAF with the hot
        file's assembly tree and the names and colours of its solids and faces (hot solid i is cold
        solid i, hot face k cold face k); otherwise as a plain shape.

        Raises
        ------
        MorphError : the cold part fails :func:`check_result` (a result of ``morph(..., check=False)``), or
            the file, read back, does not hold its solids valid, closed and with their faces
            (:func:`hot2cold.kernel.step.read_back`); nothing is written.
        """
        from ..kernel.xcaf import write_step_styles

        check_result(self)
        styles = self.part.styles
        if styles is not None and styles.placed:
            write_step_styles(self.cold_kernel.shape, styles, path, verify=True)
            return
        if styles is not None:
            log.warning("the hot STEP's names and colours could not be placed on the cold part; "
                        "writing %s without them", path)
        write_step(self.cold_kernel.shape, path, verify=True)


def check_result(result: MorphResult) -> None:
    """Raise :class:`MorphError` unless every cold solid is valid, closed, has its faces and came through the
    checks after the sew (no face folded over, not inside out, not crossing itself)."""
    if result.problems:
        more = len(result.problems) - 1
        also = f" (and {more} more problem{'s' if more > 1 else ''}, see the log)" if more else ""
        raise MorphError(f"{result.problems[0]}{also}: the displacements are too large for this part (check the "
                         f"field's units and scale, and that it belongs to this part); not written")
    for s, hot_faces in zip(result.report.solids, result.part.solids):
        if not s.valid:
            fault = solid_fault(result.cold_kernel.shape, s.index) or "BRepCheck"
            raise MorphError(f"cold solid {s.index} is not valid: {fault}; not written")
        if not s.closed:
            raise MorphError(f"cold solid {s.index} has {s.free_edges} free edges; not written")
        if s.faces != len(hot_faces):
            raise MorphError(f"cold solid {s.index} has {s.faces} faces, the hot one {len(hot_faces)}")
