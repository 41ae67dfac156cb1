"""Inverting a cold-to-hot field into the hot-to-cold field the morph needs.

Some FE workflows compute the displacement the other way: a field ``u`` that takes the cold state to the
hot one, given at the nodes of a mesh of the *hot* CAD part (the only geometry there is).  The hot-to-cold
displacement ``d`` at a hot point ``X`` is the one whose cold point ``X + d`` is carried back to ``X`` by
``u``::

    X + d + u(X + d) = X   <=>   d = -u(X + d)

solved node by node by the fixed-point iteration ``d_(k+1) = -u(X + d_k)`` from ``d_0 = -u(X)``.  Near
each node ``u`` is a quadratic (or, where the nodes do not determine one, linear) least-squares fit over
its nearest nodes (:func:`hot2cold.core.localfit.node_fits`), fixed once per node: an
interpolant whose neighbour set changed as ``X + d`` moves would jump by the fit error and stall the
iteration at that level.  The iteration contracts as long as the displacement gradient is small
(``|grad u| < 1``, always so for elastic and thermal strain); the residual ``max |d + u(X + d)|`` is
reported.

The cold point ``X + d`` lies off the hot surface, so the inversion needs the derivative of ``u`` across
the surface: an FE field's volume nodes give it.  A field of surface nodes alone leaves it undetermined
(the minimum-norm local fit takes it as zero), an error of about ``|du/dn| |d_n|``.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

from ..core.localfit import evaluate_node_fits, node_fits
from ..errors import FieldError
from ..io.field import DisplacementField

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Inversion:
    """How the fixed-point iteration went: ``iterations`` done, final ``residual`` (mm, max over nodes),
    ``history`` of the residual per iteration, and whether it ``converged`` below the tolerance."""

    iterations: int
    residual: float
    history: list[float]
    converged: bool


def invert_field(field: DisplacementField, tolerance: float = 1e-9, max_iterations: int = 50,
                 neighbours: int = 30) -> tuple[DisplacementField, Inversion]:
    """The hot-to-cold field at the nodes of a cold-to-hot ``field`` (see the module docstring).

    Raises :class:`FieldError` when the iteration does not converge (change above ``tolerance`` mm after
    ``max_iterations``, or growing): the field is then too large or too rough to invert.
    """
    coef, scale = node_fits(field.points, field.displacements, neighbours)

    def u(offset: np.ndarray) -> np.ndarray:        # u(X + offset) for every node, (N, 3)
        return evaluate_node_fits(coef, scale, offset)

    d = -field.displacements.copy()
    history = []
    for k in range(1, max_iterations + 1):
        new = -u(d)
        step = float(np.abs(new - d).max())
        d = new
        history.append(step)
        log.debug("inversion iteration %d: change %.3g mm", k, step)
        if step <= tolerance:
            break
        if k > 3 and step > history[-2]:
            raise FieldError(f"inverting the cold-to-hot field {field.source} diverges (change {step:.3g} mm "
                             f"at iteration {k}): the displacements are too large or rough to invert")
    residual = float(np.abs(d + u(d)).max())
    converged = history[-1] <= tolerance
    if not converged:
        raise FieldError(f"inverting the cold-to-hot field {field.source} did not converge in {max_iterations} "
                         f"iterations (residual {residual:.3g} mm)")
    log.info("inverted the field in %d iterations, residual %.3g mm", len(history), residual)
    return (replace(field, displacements=d),
            Inversion(len(history), residual, history, converged))
