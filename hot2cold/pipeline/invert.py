"""Inverting a cold-to-hot field into the hot-to-cold field the morph needs.

Some FE workflows compute the displacement the other way: a field ``u`` that takes the cold state to the
hot one, given at the nodes of a mesh of the *hot* CAD part (the only geometry there is).  The hot-to-cold
displacement ``d`` at a hot point ``X`` is the one whose cold point ``X + d`` is carried back to ``X`` by
``u``::

    X + d + u(X + d) = X   <=>   d = -u(X + d)

solved node by node by the fixed-point iteration ``d_(k+1) = -u(X + d_k)`` from ``d_0 = -u(X)``.  Near
each node ``u`` is a quadratic (or, where the nodes do not determine one, linear) least-squares fit over
its nearest nodes, fixed once per node: an
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
from dataclasses import dataclass

import numpy as np

from scipy.spatial import cKDTree

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


def _features(offsets: np.ndarray) -> np.ndarray:
    """Quadratic monomials ``(..., 10)`` of offsets ``(..., 3)``: 1, x, y, z, x², y², z², xy, xz, yz."""
    x, y, z = offsets[..., 0], offsets[..., 1], offsets[..., 2]
    return np.stack([np.ones_like(x), x, y, z, x * x, y * y, z * z, x * y, x * z, y * z], axis=-1)


def _local_quadratics(points: np.ndarray, values: np.ndarray, neighbours: int,
                      chunk: int = 4096, rcond: float = 1e-8) -> tuple[np.ndarray, np.ndarray]:
    """Per node, the coefficients ``(N, 10, 3)`` of a least-squares fit of ``values`` over its nearest
    nodes, in offsets scaled by ``scale (N,)``.

    The fit is quadratic where the neighbours determine a quadratic (three or more layers in every
    direction), else linear (quadratic coefficients zero): a minimum-norm quadratic fit over two layers of
    nodes would share the normal derivative between the linear and the quadratic term and get it wrong.
    """
    k = min(neighbours, len(points))
    tree = cKDTree(points)
    coef = np.zeros((len(points), 10, 3))
    scale = np.ones(len(points))
    for start in range(0, len(points), chunk):
        xs = points[start:start + chunk]
        _, idx = tree.query(xs, k=k)
        idx = idx.reshape(len(xs), k)
        offsets = points[idx] - xs[:, None, :]
        s = np.abs(offsets).max(axis=(1, 2))
        s[s == 0] = 1.0
        features = _features(offsets / s[:, None, None])
        sigma = np.linalg.svd(features, compute_uv=False)
        quadratic = sigma[:, -1] > rcond * sigma[:, 0]
        block = np.zeros((len(xs), 10, 3))
        if quadratic.any():
            block[quadratic] = np.linalg.pinv(features[quadratic]) @ values[idx[quadratic]]
        if (~quadratic).any():
            block[~quadratic, :4] = np.linalg.pinv(features[~quadratic, :, :4], rcond=1e-10) @ values[idx[~quadratic]]
        coef[start:start + chunk] = block
        scale[start:start + chunk] = s
    return coef, scale


def invert_field(field: DisplacementField, tolerance: float = 1e-9, max_iterations: int = 50,
                 neighbours: int = 30) -> tuple[DisplacementField, Inversion]:
    """The hot-to-cold field at the nodes of a cold-to-hot ``field`` (see the module docstring).

    Raises :class:`FieldError` when the iteration does not converge (change above ``tolerance`` mm after
    ``max_iterations``, or growing): the field is then too large or too rough to invert.
    """
    coef, scale = _local_quadratics(field.points, field.displacements, neighbours)

    def u(offset: np.ndarray) -> np.ndarray:        # u(X + offset) for every node, (N, 3)
        return np.einsum("nf,nfc->nc", _features(offset / scale[:, None]), coef)

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
    return (DisplacementField(field.points, d, field.node_ids, field.source),
            Inversion(len(history), residual, history, converged))
