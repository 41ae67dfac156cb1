"""Conversion between kernel B-spline objects and the plain records of :mod:`hot2cold.core.bspline`.

This is the only place that knows the kernel's 1-based arrays and its (distinct knots, multiplicities) form
of a knot vector.  Records are always in global coordinates: a face's or edge's ``TopLoc_Location`` is
applied on the way out (``trsf``) and undone on the way back in.
"""
from __future__ import annotations

import numpy as np
from OCP.Geom import Geom_BSplineCurve, Geom_BSplineSurface
from OCP.Geom2d import Geom2d_BSplineCurve
from OCP.gp import gp_Pnt, gp_Pnt2d, gp_Trsf
from OCP.TColgp import TColgp_Array1OfPnt, TColgp_Array1OfPnt2d, TColgp_Array2OfPnt
from OCP.TColStd import (TColStd_Array1OfInteger, TColStd_Array1OfReal,
                         TColStd_Array2OfReal)

from ..core.bspline import BSplineCurve, BSplineSurface
from ..errors import KernelError


def _trsf_matrix(trsf: gp_Trsf | None) -> tuple[np.ndarray, np.ndarray]:
    """``(A (3, 3), b (3,))`` with ``x_global = A @ x_local + b``."""
    if trsf is None or trsf.Form() == 0:  # gp_Identity
        return np.eye(3), np.zeros(3)
    a = np.array([[trsf.Value(r, c) for c in (1, 2, 3)] for r in (1, 2, 3)])
    b = np.array([trsf.Value(r, 4) for r in (1, 2, 3)])
    return a, b


def apply_trsf(points: np.ndarray, trsf: gp_Trsf | None) -> np.ndarray:
    """Points ``(..., 3)`` from local to global coordinates."""
    a, b = _trsf_matrix(trsf)
    return points @ a.T + b


def unapply_trsf(points: np.ndarray, trsf: gp_Trsf | None) -> np.ndarray:
    """Points ``(..., 3)`` from global back to local coordinates."""
    a, b = _trsf_matrix(trsf)
    return np.linalg.solve(a, (points - b).reshape(-1, 3).T).T.reshape(points.shape)


def _flat_knots(n: int, knot, multiplicity) -> np.ndarray:
    """The full knot vector from the ``n`` distinct knots ``knot(i)`` and their ``multiplicity(i)`` (1-based: the
    kernel's accessors, which every OCP build has, where its arrays' ``Value`` is missing from some)."""
    return np.repeat([knot(i) for i in range(1, n + 1)], [multiplicity(i) for i in range(1, n + 1)])


def _distinct_knots(flat: np.ndarray) -> tuple[TColStd_Array1OfReal, TColStd_Array1OfInteger]:
    values, mults = [], []
    for k in flat:
        if values and k == values[-1]:
            mults[-1] += 1
        else:
            values.append(float(k))
            mults.append(1)
    arr = TColStd_Array1OfReal(1, len(values))
    mul = TColStd_Array1OfInteger(1, len(values))
    for i, (v, m) in enumerate(zip(values, mults), start=1):
        arr.SetValue(i, v)
        mul.SetValue(i, m)
    return arr, mul


def curve_to_record(curve: Geom_BSplineCurve, trsf: gp_Trsf | None = None) -> BSplineCurve:
    """A non-periodic ``Geom_BSplineCurve`` as a :class:`BSplineCurve` in global coordinates."""
    if curve.IsPeriodic():
        raise KernelError("periodic curves must be made non-periodic before conversion")
    n = curve.NbPoles()
    poles = np.array([[curve.Pole(i).X(), curve.Pole(i).Y(), curve.Pole(i).Z()] for i in range(1, n + 1)])
    weights = np.array([curve.Weight(i) for i in range(1, n + 1)]) if curve.IsRational() else None
    knots = _flat_knots(curve.NbKnots(), curve.Knot, curve.Multiplicity)
    return BSplineCurve(apply_trsf(poles, trsf), knots, curve.Degree(), weights)


def curve2d_to_record(curve: Geom2d_BSplineCurve) -> BSplineCurve:
    """A non-periodic ``Geom2d_BSplineCurve`` (a pcurve, in a face's parameters) as a :class:`BSplineCurve` whose
    poles are ``(u, v, 0)``."""
    if curve.IsPeriodic():
        raise KernelError("periodic curves must be made non-periodic before conversion")
    n = curve.NbPoles()
    poles = np.array([[q.X(), q.Y(), 0.0] for q in (curve.Pole(i) for i in range(1, n + 1))])
    weights = np.array([curve.Weight(i) for i in range(1, n + 1)]) if curve.IsRational() else None
    return BSplineCurve(poles, _flat_knots(curve.NbKnots(), curve.Knot, curve.Multiplicity), curve.Degree(), weights)


def surface_to_record(surface: Geom_BSplineSurface, trsf: gp_Trsf | None = None) -> BSplineSurface:
    """A non-periodic ``Geom_BSplineSurface`` as a :class:`BSplineSurface` in global coordinates."""
    if surface.IsUPeriodic() or surface.IsVPeriodic():
        raise KernelError("periodic surfaces must be made non-periodic before conversion")
    nu, nv = surface.NbUPoles(), surface.NbVPoles()
    poles = np.empty((nu, nv, 3))
    weights = np.empty((nu, nv))
    for i in range(nu):
        for j in range(nv):
            p = surface.Pole(i + 1, j + 1)
            poles[i, j] = p.X(), p.Y(), p.Z()
            weights[i, j] = surface.Weight(i + 1, j + 1)
    rational = surface.IsURational() or surface.IsVRational()
    u_knots = _flat_knots(surface.NbUKnots(), surface.UKnot, surface.UMultiplicity)
    v_knots = _flat_knots(surface.NbVKnots(), surface.VKnot, surface.VMultiplicity)
    return BSplineSurface(apply_trsf(poles, trsf), u_knots, v_knots, surface.UDegree(), surface.VDegree(),
                          weights if rational else None)


def record_to_curve(rec: BSplineCurve, trsf: gp_Trsf | None = None) -> Geom_BSplineCurve:
    """A new ``Geom_BSplineCurve`` from a record; ``trsf`` is the location it will be placed under."""
    poles = unapply_trsf(rec.poles, trsf)
    arr = TColgp_Array1OfPnt(1, rec.n_poles)
    for i, p in enumerate(poles, start=1):
        arr.SetValue(i, gp_Pnt(*p))
    return _curve(Geom_BSplineCurve, arr, rec, "curve")


def record_to_curve2d(rec: BSplineCurve) -> Geom2d_BSplineCurve:
    """A new ``Geom2d_BSplineCurve`` (a pcurve) from a record whose poles are ``(u, v, 0)``, as
    :func:`curve2d_to_record` makes them."""
    arr = TColgp_Array1OfPnt2d(1, rec.n_poles)
    for i, (u, v, _) in enumerate(rec.poles, start=1):
        arr.SetValue(i, gp_Pnt2d(float(u), float(v)))
    return _curve(Geom2d_BSplineCurve, arr, rec, "pcurve")


def _curve(kind, poles, rec: BSplineCurve, what: str):
    """A new ``kind`` (``Geom_BSplineCurve`` or ``Geom2d_BSplineCurve``) on the kernel array ``poles`` with the
    knots, degree and weights of ``rec``; a failure is a :class:`KernelError` naming ``what`` it builds."""
    kn, mu = _distinct_knots(rec.knots)
    try:
        if rec.weights is None:
            return kind(poles, kn, mu, rec.degree, False)
        w = TColStd_Array1OfReal(1, rec.n_poles)
        for i, x in enumerate(rec.weights, start=1):
            w.SetValue(i, float(x))
        return kind(poles, w, kn, mu, rec.degree, False)
    except Exception as exc:  # Standard_ConstructionError and friends
        raise KernelError(f"cannot build a B-spline {what}: {exc}") from exc


def record_to_surface(rec: BSplineSurface, trsf: gp_Trsf | None = None) -> Geom_BSplineSurface:
    """A new ``Geom_BSplineSurface`` from a record; ``trsf`` is the location it will be placed under."""
    poles = unapply_trsf(rec.poles, trsf)
    nu, nv = rec.shape
    arr = TColgp_Array2OfPnt(1, nu, 1, nv)
    for i in range(nu):
        for j in range(nv):
            arr.SetValue(i + 1, j + 1, gp_Pnt(*poles[i, j]))
    uk, um = _distinct_knots(rec.u_knots)
    vk, vm = _distinct_knots(rec.v_knots)
    try:
        if rec.weights is None:
            return Geom_BSplineSurface(arr, uk, vk, um, vm, rec.u_degree, rec.v_degree, False, False)
        w = TColStd_Array2OfReal(1, nu, 1, nv)
        for i in range(nu):
            for j in range(nv):
                w.SetValue(i + 1, j + 1, float(rec.weights[i, j]))
        return Geom_BSplineSurface(arr, w, uk, vk, um, vm, rec.u_degree, rec.v_degree, False, False)
    except Exception as exc:
        raise KernelError(f"cannot build a B-spline surface: {exc}") from exc


def set_curve_poles(curve: Geom_BSplineCurve, poles: np.ndarray, trsf: gp_Trsf | None = None) -> None:
    """Move the poles of ``curve`` in place to ``poles`` ``(n, 3)`` given in global coordinates."""
    local = unapply_trsf(np.asarray(poles, float), trsf)
    if local.shape != (curve.NbPoles(), 3):
        raise KernelError(f"curve has {curve.NbPoles()} poles, got {local.shape}")
    for i, p in enumerate(local, start=1):
        curve.SetPole(i, gp_Pnt(*p))


def set_surface_poles(surface: Geom_BSplineSurface, poles: np.ndarray, trsf: gp_Trsf | None = None) -> None:
    """Move the poles of ``surface`` in place to ``poles`` ``(nu, nv, 3)`` given in global coordinates."""
    local = unapply_trsf(np.asarray(poles, float), trsf)
    if local.shape != (surface.NbUPoles(), surface.NbVPoles(), 3):
        raise KernelError(f"surface has {surface.NbUPoles()}x{surface.NbVPoles()} poles, got {local.shape}")
    for i in range(local.shape[0]):
        for j in range(local.shape[1]):
            surface.SetPole(i + 1, j + 1, gp_Pnt(*local[i, j]))
