"""The package as a user installs it: the sdist and the wheel built from the checkout, the wheel installed in a
fresh venv outside the checkout, and the command line and the README's quick start run from there.

The fresh venv borrows the test environment's dependencies (CadQuery, OCP, numpy, ...) through a path entry,
so that the test downloads nothing; not the environment's editable hot2cold, whose import hook lives in a
``.pth`` file that a plain path entry does not run: the hot2cold imported is the wheel's.
"""
from __future__ import annotations

import io
import sys
import sysconfig
import tarfile
import zipfile
from pathlib import Path

import pytest
from conftest import run_outside

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "sample_parts"

#: Files the wheel must carry besides the modules: the 3D view's scripts and three.js's licence.
PACKAGE_DATA = ("hot2cold/views/viewer/three.core.min.js", "hot2cold/views/viewer/three.module.min.js",
                "hot2cold/views/viewer/OrbitControls.js", "hot2cold/views/viewer/viewer.js",
                "hot2cold/views/viewer/LICENSE.three")


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """The sdist and the wheel built, checked, and the wheel installed in a fresh venv (its folder)."""
    tmp_path = tmp_path_factory.mktemp("wheel")
    dist = tmp_path / "dist"
    run_outside([sys.executable, "-m", "build", "--sdist", "--wheel", "--outdir", dist, ROOT], tmp_path)
    (wheel,), (sdist,) = list(dist.glob("*.whl")), list(dist.glob("*.tar.gz"))
    names = set(zipfile.ZipFile(wheel).namelist())
    assert set(PACKAGE_DATA) <= names and "hot2cold/cli/__init__.py" in names
    assert not any(n.startswith(("tests/", "benchmarks/", "sample_parts/")) for n in names)
    entry_points = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    assert "hot2cold = hot2cold.cli:main" in zipfile.ZipFile(wheel).read(entry_points).decode()
    with tarfile.open(sdist) as archive:
        members = {Path(m).relative_to(Path(m).parts[0]).as_posix() for m in archive.getnames() if "/" in m}
    assert {"pyproject.toml", "README.md", "hot2cold/__init__.py"} <= members
    assert set(PACKAGE_DATA) <= members

    venv = tmp_path / "venv"
    run_outside([sys.executable, "-m", "venv", venv], tmp_path)
    python = venv / "bin" / "python"
    site = Path(run_outside([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                            tmp_path).strip())
    (site / "borrowed_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    run_outside([python, "-m", "pip", "install", "-q", "--no-deps", "--no-index", wheel], tmp_path)
    where = Path(run_outside([python, "-c", "import hot2cold; print(hot2cold.__file__)"], tmp_path).strip())
    assert where.is_relative_to(venv), where
    return venv


@pytest.mark.slow
def test_the_wheel_runs_the_quick_start_outside_the_checkout(installed, tmp_path):
    venv = installed
    assert "{morph,batch}" in run_outside([venv / "bin" / "hot2cold", "--help"], tmp_path)
    assert "FIELD" in run_outside([venv / "bin" / "hot2cold", "morph", "--help"], tmp_path).upper()
    out = run_outside([venv / "bin" / "hot2cold", "morph", SAMPLES / "twisted_blade.step",
                SAMPLES / "twisted_blade_field.csv", "-o", "twisted_blade_cold.step", "--report",
                "twisted_blade_report.json"], tmp_path)
    assert out.startswith("tolerance 0.001 mm: met")
    assert (tmp_path / "twisted_blade_cold.step").stat().st_size > 10_000
    assert (tmp_path / "twisted_blade_report.json").is_file()


#: Runs a notebook with the interpreter it is run by (its kernel: ipykernel's, of the same interpreter) and
#: writes it back with its outputs: ``python - NOTEBOOK OUT``.
_EXECUTE = """
import sys
from pathlib import Path

import nbclient
import nbformat

source, out = map(Path, sys.argv[1:3])
notebook = nbformat.read(source, as_version=4)
nbclient.NotebookClient(notebook, kernel_name="python3", timeout=900,
                        resources={"metadata": {"path": str(source.parent)}}).execute()
nbformat.write(notebook, out)
"""


@pytest.mark.slow
def test_the_docs_notebook_from_the_wheel_shows_the_cold_blade_at_load(installed, tmp_path, browser):
    """The docs' blade notebook, run by the wheel's venv, shows the result: in headless Chromium, at load, the
    verdict and beside it the 3D view of the cold blade coloured by its displacement."""
    import nbformat
    import numpy as np
    from matplotlib.image import imread

    executed = tmp_path / "blade.ipynb"
    script = tmp_path / "execute.py"
    script.write_text(_EXECUTE)
    run_outside([installed / "bin" / "python", script, ROOT / "docs" / "examples" / "blade.ipynb", executed], tmp_path)
    notebook = nbformat.read(executed, as_version=4)
    shown = [o["data"]["text/html"] for cell in notebook.cells if cell.cell_type == "code"
             for o in cell.get("outputs", []) if o.get("output_type") == "execute_result"
             and "text/html" in o.get("data", {}) and "<iframe" in o["data"]["text/html"]]
    assert len(shown) == 1, "the notebook shows its result once"
    context = browser.new_context(viewport={"width": 1200, "height": 1100})
    try:
        page = context.new_page()
        page.set_content(f"<!DOCTYPE html><html><body>{shown[0]}</body></html>", wait_until="load")
        frame = page.frames[1]
        assert frame.get_attribute("#v3-stage", "data-ready") == "true"
        assert frame.input_value("#v3-colour") == "displacement"
        assert frame.text_content("#verdict").startswith("tolerance 0.001 mm: met")
        assert frame.is_visible("#verdict") and frame.is_visible("#v3-canvas")
        shot = tmp_path / "notebook.png"
        page.screenshot(path=str(shot), full_page=False)
        rgb = imread(io.BytesIO(frame.locator("#v3-canvas").screenshot()), format="png")[..., :3]
        drawn = rgb[:, : int(0.8 * rgb.shape[1])]
        coloured = (drawn.max(axis=2) - drawn.min(axis=2) > 0.15) & (
            np.maximum(drawn[..., 1], drawn[..., 2]) > drawn[..., 0])
        assert coloured.mean() > 0.02 and shot.stat().st_size > 10_000
    finally:
        context.close()
