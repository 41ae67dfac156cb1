"""Shared fixtures: the bundled sample parts and FE-like node sets on them."""
from __future__ import annotations

import contextlib
import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hot2cold.core.bspline import evaluate_surface
from hot2cold.kernel.sampling import face_samples, fe_surface_nodes, volume_nodes
from hot2cold.kernel.step import read_step

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "sample_parts"


@pytest.fixture(scope="session")
def blade_step() -> Path:
    return SAMPLES / "twisted_blade.step"


@pytest.fixture(scope="session")
def block_step() -> Path:
    return SAMPLES / "filleted_block.step"


@pytest.fixture(scope="session")
def blade_shape(blade_step):
    return read_step(blade_step)


@pytest.fixture(scope="session")
def block_shape(block_step):
    return read_step(block_step)


@pytest.fixture(scope="session")
def blade_nodes(blade_shape) -> np.ndarray:
    """FE-like surface nodes on the blade, 0.6 mm apart (about 25 000): every knot-span patch holds nodes."""
    return fe_surface_nodes(blade_shape, 0.6, seed=1)[0]


@pytest.fixture(scope="session")
def block_nodes(block_shape) -> np.ndarray:
    return fe_surface_nodes(block_shape, 1.5, seed=2)[0]


@pytest.fixture(scope="session")
def blade_volume_nodes(blade_shape) -> np.ndarray:
    return volume_nodes(blade_shape, 300, seed=3)


def face_deviation(result, exact_map, spacing: float) -> list[np.ndarray]:
    """Per face, distances ``(m,)`` between the cold surface and ``exact_map`` of the hot surface at the same
    parameters, on points sampled over the face's trimmed domain.

    The morph fits ``S_cold(u_k, v_k) = S_hot(u_k, v_k) + dd_k`` (eq. 30), so this parametric distance is the
    error of the fit, and an upper bound of the distance between the two surfaces.
    """
    out = []
    for (uv, _), face, morphed in zip(face_samples(result.hot.wrapped, spacing), result.part.faces,
                                      result.faces):
        hot = evaluate_surface(face.surface, uv[:, 0], uv[:, 1])
        cold = evaluate_surface(morphed.surface, uv[:, 0], uv[:, 1])
        out.append(np.linalg.norm(cold - exact_map(hot), axis=1))
    return out


@pytest.fixture(scope="session")
def blade():
    """The twisted blade morphed with its bundled field (19 182 nodes, 500 of them off the part); read-only,
    shared by the tests of the report, its pictures and the viewer exports."""
    from hot2cold.pipeline.morph import morph
    return morph(SAMPLES / "twisted_blade.step", SAMPLES / "twisted_blade_field.csv")



@contextlib.contextmanager
def benchmark_module(name: str):
    """``benchmarks/<name>.py`` imported as the module ``name`` for the duration (a benchmark script is no
    package module); it and the benchmark module it imports (``real_parts``) are forgotten afterwards."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module          # dataclasses look their module up while it is made
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)
        sys.modules.pop("real_parts", None)


def run_outside(args: list, cwd: Path, timeout: float = 900) -> str:
    """``args`` run in ``cwd`` as a fresh shell would run them, their stdout returned (a non-zero exit fails the
    test with its stderr): without this process's PYTHONPATH or PYTHONHOME, which would put a checkout's
    hot2cold before the one installed where ``args`` run (the wheel's, a fresh venv's)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    done = subprocess.run([str(a) for a in args], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)
    assert done.returncode == 0, f"{' '.join(map(str, args))} exited {done.returncode}:\n{done.stderr[-3000:]}"
    return done.stdout


@pytest.fixture(scope="module")
def real_parts():
    """``benchmarks/real_parts.py`` as a module (:func:`benchmark_module`): its functions and its tables are
    tested in ``test_real_parts.py`` and ``test_doc_blocks.py``."""
    with benchmark_module("real_parts") as module:
        yield module


#: Debian's Chromium, for the 3D report's tests.
CHROMIUM = "chromium"
#: What makes WebGL work in headless Chromium without a GPU: SwiftShader, allowed explicitly.
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--disable-background-networking", "--disable-component-update", "--no-first-run"]


@pytest.fixture(scope="session")
def browser():
    """Headless Debian Chromium through Playwright: a failure, not a skip, when either is missing."""
    executable = "/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else shutil.which(CHROMIUM)
    if not executable:
        pytest.fail("the 3D report test needs Chromium (Debian: apt-get install -y chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.fail("the 3D report test needs Playwright for Python: pip install playwright "
                    "(Debian's chromium is used; no 'playwright install')")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=CHROMIUM_ARGS)
        yield browser
        browser.close()


#: Markers that keep a test out of the quick tier (pyproject.toml lists what each means).
FULL_SUITE_ONLY = ("heavy", "slow", "gmsh", "calculix", "browser", "real_parts")


def pytest_collection_modifyitems(config, items):
    """A test that renders in the browser is marked ``browser``; a test with none of ``FULL_SUITE_ONLY`` is
    marked ``quick``, so that ``pytest -m quick`` runs the quick tier."""
    for item in items:
        if "browser" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.browser)
        if not any(item.get_closest_marker(name) for name in FULL_SUITE_ONLY):
            item.add_marker(pytest.mark.quick)
