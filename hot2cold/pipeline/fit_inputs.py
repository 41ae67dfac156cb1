"""What every edge and face fit of one morph reads besides the edge or face itself: :class:`FitInputs`."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..core.model import Classification
from ..io.field import DisplacementField
from ..settings import Settings
from .artificial import FieldEstimator


@dataclass(frozen=True, eq=False)
class FitInputs:
    """What every edge and face fit of one morph reads besides the part, the edge or face and the
    morphs of its edges.

    Attributes
    ----------
    cls : Classification of the field's nodes.
    field : DisplacementField, hot positions and hot-to-cold displacements, one row per entry of ``cls``.
    vertex_disp : (nv, 3) float array, each vertex's displacement (eq. 10).
    estimator : FieldEstimator, the displacements of artificial nodes (eq. 39).
    settings : Settings.
    trimmed_away : ``trimmed_away(k, uv (m, 2)) -> (m,) bool``, which parameters lie outside face ``k``'s
        trimmed domain (None: the whole domain counts).
    noise : float, the field's scatter (mm per component, :func:`hot2cold.core.localfit.scatter`): a fit is
        smoothed towards the field's estimate until it leaves that much at the face's nodes
        (:func:`~hot2cold.core.lstsq.solve_tsvd`).
    """

    cls: Classification
    field: DisplacementField
    vertex_disp: np.ndarray
    estimator: FieldEstimator
    settings: Settings
    trimmed_away: Callable[[int, np.ndarray], np.ndarray] | None = None
    noise: float = 0.0
