"""Second derivatives and mean curvature of hot2cold.core.bspline, checked against the OpenCascade kernel."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from OCP.GeomLProp import GeomLProp_SLProps
from OCP.gp import gp_Pnt, gp_Vec

from hot2cold.core.bspline import (BSplineSurface, mean_curvature, surface_derivatives, surface_normals,
                                   surface_second_derivative_bases, surface_second_derivatives)
from hot2cold.kernel.convert import record_to_surface

from test_bspline import random_knots, random_surface, surface_params, xyz

SAMPLES = Path(__file__).resolve().parent.parent / "sample_parts"
CASES = [(p, q, rat) for (p, q) in ((1, 1), (1, 3), (2, 2), (3, 2), (3, 3), (5, 4)) for rat in (False, True)]


def _kernel_second(g, u, v):
    """``(S_uu, S_uv, S_vv)`` from ``Geom_BSplineSurface.D2``."""
    out = [], [], []
    for a, b in zip(u, v):
        pt, du, dv, duu, dvv, duv = gp_Pnt(), gp_Vec(), gp_Vec(), gp_Vec(), gp_Vec(), gp_Vec()
        g.D2(float(a), float(b), pt, du, dv, duu, dvv, duv)
        out[0].append(xyz(duu))
        out[1].append(xyz(duv))
        out[2].append(xyz(dvv))
    return tuple(np.array(x) for x in out)


@pytest.mark.parametrize("p,q,rational", CASES)
def test_second_derivative_bases_match_kernel(p, q, rational):
    """The bases of the fit rows (linear in the poles, weights fixed) give the kernel's D2."""
    rng = np.random.default_rng(3000 * p + 300 * q + 30 * rational)
    s = random_surface(rng, p, q, rational)
    u, v = surface_params(rng, s)
    bases = surface_second_derivative_bases(s, u, v)
    theirs = _kernel_second(record_to_surface(s), u, v)
    floor = float(np.abs(s.poles).max())
    for basis, b in zip(bases, theirs):
        assert basis.shape == (len(u), s.shape[0] * s.shape[1])
        assert _rel_err(basis @ s.poles.reshape(-1, 3), b, floor) < 1e-9


def _kernel_mean(g, u, v):
    props = GeomLProp_SLProps(g, 2, 1e-12)
    out = []
    for a, b in zip(u, v):
        props.SetParameters(float(a), float(b))
        out.append(props.MeanCurvature() if props.IsCurvatureDefined() else math.nan)
    return np.array(out)


def _rel_err(actual, expected, floor: float) -> float:
    """Largest difference relative to the largest expected value (at least ``floor``: a degree-1 direction
    has zero second derivative, where both sides hold only rounding)."""
    return float(np.abs(actual - expected).max() / max(np.abs(expected).max(), floor))


@pytest.mark.parametrize("p,q,rational", CASES)
@pytest.mark.parametrize("seed", [0, 1])
def test_second_derivatives_match_kernel(p, q, rational, seed):
    rng = np.random.default_rng(2000 * p + 200 * q + 20 * rational + seed)
    s = random_surface(rng, p, q, rational)
    u, v = surface_params(rng, s)          # every knot crossing (C0 and C1 ones too), corners, random points
    ours = surface_second_derivatives(s, u, v)
    theirs = _kernel_second(record_to_surface(s), u, v)
    floor = float(np.abs(s.poles).max())
    for a, b in zip(ours, theirs):
        assert a.shape == (len(u), 3)
        err = _rel_err(a, b, floor)
        assert err <= 1e-11, f"relative error {err:.2e}"


def _smooth_surface(rng, p, q, rational):
    """A random surface without repeated interior knots (C^(degree-1) everywhere)."""
    s = random_surface(rng, p, q, rational)
    nu, nv = s.shape
    return BSplineSurface(s.poles, random_knots(rng, nu, p, 0.5, 4.0, repeat=False),
                          random_knots(rng, nv, q, -2.0, -0.25, repeat=False), p, q, s.weights)


@pytest.mark.parametrize("p,q,rational", [c for c in CASES if min(c[0], c[1]) >= 2])
@pytest.mark.parametrize("seed", [0, 1])
def test_mean_curvature_matches_kernel(p, q, rational, seed):
    rng = np.random.default_rng(3000 * p + 300 * q + 30 * rational + seed)
    s = _smooth_surface(rng, p, q, rational)
    u0, u1, v0, v1 = s.domain
    u, v = rng.uniform(u0, u1, 300), rng.uniform(v0, v1, 300)
    ours = mean_curvature(s, u, v)
    theirs = _kernel_mean(record_to_surface(s), u, v)
    assert ours.shape == (300,) and np.isfinite(theirs).all() and np.isfinite(ours).all()
    # per point, relative to the curvature there (floored at 1e-3 of the largest, for near-flat points)
    scale = np.maximum(np.abs(theirs), 1e-3 * np.abs(theirs).max())
    err = np.abs(ours - theirs) / scale
    assert err.max() <= 1e-9, f"relative error {err.max():.2e}"


def test_mean_curvature_of_exact_sphere_and_cylinder():
    """Rational quadrics from the kernel: H = -1/R on a sphere and -1/(2R) on a cylinder (outward normal)."""
    from OCP.Geom import Geom_CylindricalSurface, Geom_RectangularTrimmedSurface, Geom_SphericalSurface
    from OCP.GeomConvert import GeomConvert
    from OCP.gp import gp_Ax3

    from hot2cold.kernel.convert import surface_to_record

    r = 7.5
    sphere = Geom_RectangularTrimmedSurface(Geom_SphericalSurface(gp_Ax3(), r), 0.3, 2.5, -1.2, 1.1)
    cylinder = Geom_RectangularTrimmedSurface(Geom_CylindricalSurface(gp_Ax3(), r), 0.2, 4.0, -3.0, 5.0)
    for geom, expected in ((sphere, -1.0 / r), (cylinder, -0.5 / r)):
        rec = surface_to_record(GeomConvert.SurfaceToBSplineSurface_s(geom))
        assert rec.weights is not None
        rng = np.random.default_rng(5)
        u0, u1, v0, v1 = rec.domain
        u, v = rng.uniform(u0, u1, 200), rng.uniform(v0, v1, 200)
        h = mean_curvature(rec, u, v)
        # the record's normal S_u x S_v points outward here (as the kernel's for these surfaces)
        np.testing.assert_allclose(h, expected, rtol=1e-10)
        np.testing.assert_allclose(h, _kernel_mean(record_to_surface(rec), u, v), rtol=1e-9)


def test_second_derivatives_match_finite_differences_of_first():
    rng = np.random.default_rng(7)
    s = _smooth_surface(rng, 3, 3, True)
    u0, u1, v0, v1 = s.domain
    u, v = rng.uniform(u0 + 0.01, u1 - 0.01, 50), rng.uniform(v0 + 0.01, v1 - 0.01, 50)
    h = 1e-6
    suu, suv, svv = surface_second_derivatives(s, u, v)
    su_p, sv_p = surface_derivatives(s, u + h, v)
    su_m, sv_m = surface_derivatives(s, u - h, v)
    su_vp, sv_vp = surface_derivatives(s, u, v + h)
    su_vm, sv_vm = surface_derivatives(s, u, v - h)
    scale = max(np.abs(suu).max(), np.abs(svv).max())
    assert np.abs((su_p - su_m) / (2 * h) - suu).max() <= 1e-6 * scale
    assert np.abs((sv_vp - sv_vm) / (2 * h) - svv).max() <= 1e-6 * scale
    assert np.abs((sv_p - sv_m) / (2 * h) - suv).max() <= 1e-6 * scale
    assert np.abs((su_vp - su_vm) / (2 * h) - suv).max() <= 1e-6 * scale


def test_plane_is_flat_and_scalar_parameters_broadcast():
    gu, gv = np.meshgrid(np.linspace(0, 30, 4), np.linspace(-5, 5, 5), indexing="ij")
    poles = np.stack([gu, gv, 0.2 * gu - 0.1 * gv + 3.0], axis=2)
    s = BSplineSurface(poles, np.r_[0, 0, 0, 0, 1, 1, 1, 1.0], np.r_[0, 0, 0, 0.4, 0.7, 1, 1, 1.0], 3, 2)
    v = np.linspace(0, 1, 7)
    h = mean_curvature(s, 0.4, v)
    assert h.shape == (7,)
    np.testing.assert_allclose(h, 0.0, atol=1e-14)
    suu, suv, svv = surface_second_derivatives(s, 0.4, v)
    assert suu.shape == suv.shape == svv.shape == (7, 3)
    with pytest.raises(ValueError):
        mean_curvature(s, np.zeros(3), np.zeros(4))
    with pytest.raises(ValueError):
        mean_curvature(s, 2.0, 0.5)


def test_mean_curvature_nan_where_the_normal_is_undefined():
    rng = np.random.default_rng(10)
    s = random_surface(rng, 3, 3, True)
    poles = s.poles.copy()
    poles[0, :, :] = poles[0, 0, :]      # the edge u = u0 collapses to a point
    s = s.with_poles(poles)
    u0, u1, v0, v1 = s.domain
    v = np.linspace(v0, v1, 9)
    assert np.all(np.isnan(surface_normals(s, u0, v)))
    assert np.all(np.isnan(mean_curvature(s, u0, v)))


def test_mean_curvature_on_rotor37_faces_matches_kernel():
    """The real aerofoil surfaces (bicubic, many knots): our H against the kernel's on each face."""
    from hot2cold.kernel.step import read_step
    from hot2cold.pipeline.load import load_part
    from hot2cold.settings import Settings

    part = load_part(read_step(SAMPLES / "rotor37_blade.step"), Settings())
    rng = np.random.default_rng(3)
    for face in part.faces:
        s = face.surface
        u0, u1, v0, v1 = s.domain
        u, v = rng.uniform(u0, u1, 100), rng.uniform(v0, v1, 100)
        ours = mean_curvature(s, u, v)
        theirs = _kernel_mean(record_to_surface(s), u, v)
        ok = np.isfinite(theirs)
        assert np.array_equal(ok, np.isfinite(ours))
        scale = np.maximum(np.abs(theirs[ok]), 1e-3 * np.abs(theirs[ok]).max(initial=1e-12))
        assert (np.abs(ours[ok] - theirs[ok]) / scale).max(initial=0.0) <= 1e-9
