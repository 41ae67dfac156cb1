"""The package as a user installs it: the sdist and the wheel built from the checkout, the wheel installed in a
fresh venv outside the checkout, and the command line and the README's quick start run from there.

The fresh venv borrows the test environment's dependencies (CadQuery, OCP, numpy, ...) through a path entry,
so that the test downloads nothing; not the environment's editable hot2cold, whose import hook lives in a
``.pth`` file that a plain path entry does not run: the hot2cold imported is the wheel's.
"""
from __future__ import annotations

import subprocess
import sys
import sysconfig
import tarfile
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "sample_parts"

#: Files the wheel must carry besides the modules: the 3D view's scripts and three.js's licence.
PACKAGE_DATA = ("hot2cold/views/viewer/three.core.min.js", "hot2cold/views/viewer/three.module.min.js",
                "hot2cold/views/viewer/OrbitControls.js", "hot2cold/views/viewer/viewer.js",
                "hot2cold/views/viewer/LICENSE.three")


def _run(args: list, cwd: Path) -> str:
    done = subprocess.run([str(a) for a in args], cwd=cwd, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"{' '.join(map(str, args))} exited {done.returncode}:\n{done.stderr[-3000:]}"
    return done.stdout


@pytest.mark.slow
def test_the_wheel_installs_and_runs_outside_the_checkout(tmp_path):
    dist = tmp_path / "dist"
    _run([sys.executable, "-m", "build", "--sdist", "--wheel", "--outdir", dist, ROOT], tmp_path)
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
    _run([sys.executable, "-m", "venv", venv], tmp_path)
    python = venv / "bin" / "python"
    site = Path(_run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], tmp_path).strip())
    (site / "borrowed_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    _run([python, "-m", "pip", "install", "-q", "--no-deps", "--no-index", wheel], tmp_path)

    where = Path(_run([python, "-c", "import hot2cold; print(hot2cold.__file__)"], tmp_path).strip())
    assert where.is_relative_to(venv), where
    assert "{morph,batch}" in _run([venv / "bin" / "hot2cold", "--help"], tmp_path)
    assert "FIELD" in _run([venv / "bin" / "hot2cold", "morph", "--help"], tmp_path).upper()
    out = _run([venv / "bin" / "hot2cold", "morph", SAMPLES / "twisted_blade.step",
                SAMPLES / "twisted_blade_field.csv", "-o", "twisted_blade_cold.step", "--report",
                "twisted_blade_report.json"], tmp_path)
    assert out.startswith("tolerance 0.001 mm: met")
    assert (tmp_path / "twisted_blade_cold.step").stat().st_size > 10_000
    assert (tmp_path / "twisted_blade_report.json").is_file()
