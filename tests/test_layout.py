"""The package's layout as a maintainer relies on it: the numeric core runs without the kernel, importing
hot2cold is cheap, the morph path loads neither CadQuery nor VTK, and the old import paths still work.

Each check runs in a fresh interpreter (``sys.modules`` of the test process already holds the kernel).
"""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

#: Placed first on ``sys.meta_path``: any import of these packages fails as if they were not installed.
BLOCKER = """
import sys
class _Blocked:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ImportError(f"{name} is made unimportable by this test")
        return None
sys.meta_path.insert(0, _Blocked())
"""


def _run(code: str, blocked: tuple[str, ...] = ()) -> str:
    """Run ``code`` in a fresh interpreter with ``blocked`` packages unimportable; its stdout."""
    source = f"BLOCKED = {blocked!r}\n{BLOCKER}\n{textwrap.dedent(code)}"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", source], capture_output=True, text=True, env=env, cwd=ROOT,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_core_imports_and_computes_without_the_kernel():
    out = _run("""
        import importlib, pkgutil
        import numpy as np
        import hot2cold.core
        names = [m.name for m in pkgutil.iter_modules(hot2cold.core.__path__, "hot2cold.core.")]
        for name in names:
            importlib.import_module(name)
        from hot2cold.core.bspline import BSplineSurface, evaluate_surface
        from hot2cold.core.footpoint import project_to_surface
        from hot2cold.core.lstsq import solve_tsvd
        # a bilinear patch z = x * y / 10 over [0, 10]^2: evaluate, project onto it, fit a line
        x = np.array([0.0, 10.0])
        poles = np.array([[[a, b, a * b / 10] for b in x] for a in x])
        surface = BSplineSurface(poles, [0, 0, 1, 1], [0, 0, 1, 1], 1, 1)
        p = evaluate_surface(surface, [0.5], [0.25])[0]
        assert np.allclose(p, [5.0, 2.5, 1.25])
        foot = project_to_surface(surface, p[None] + [0, 0, 1e-3], np.array([[0.4, 0.4]]))
        assert np.allclose(foot.uv, [[0.5, 0.25]], atol=1e-3)
        A = np.column_stack([np.ones(5), np.arange(5.0)])
        sol = solve_tsvd(A, (2.0 + 3.0 * np.arange(5.0))[:, None])
        assert np.allclose(sol.x.ravel(), [2.0, 3.0])
        import sys
        print(len(names), sorted(m for m in sys.modules if m.split(".")[0] in ("OCP", "cadquery")))
    """, blocked=("OCP", "cadquery", "vtk"))
    count, loaded = out.split(" ", 1)
    assert int(count) >= 5 and loaded.strip() == "[]"


def test_importing_hot2cold_and_the_cli_loads_no_kernel():
    out = _run("""
        import sys
        import hot2cold, hot2cold.cli, hot2cold.errors, hot2cold.settings
        print(sorted({m.split(".")[0] for m in sys.modules} & {"OCP", "cadquery", "vtk", "matplotlib", "scipy"}))
    """)
    assert out.strip() == "[]"


def test_help_runs_without_the_kernel():
    out = _run("""
        from hot2cold.cli import main
        try:
            main(["--help"])
        except SystemExit as exc:
            assert exc.code == 0
    """, blocked=("OCP", "cadquery", "vtk"))
    assert "morph" in out and "batch" in out


@pytest.mark.heavy
def test_the_morph_path_loads_neither_cadquery_nor_vtk():
    out = _run("""
        import sys
        import hot2cold.pipeline.morph
        print(sorted({m.split(".")[0] for m in sys.modules} & {"cadquery", "vtk", "matplotlib", "trimesh"}))
    """)
    assert out.strip() == "[]"


@pytest.mark.heavy
def test_a_command_line_morph_loads_neither_cadquery_nor_vtk(tmp_path):
    args = ["morph", str(ROOT / "sample_parts" / "filleted_block.step"),
            str(ROOT / "sample_parts" / "filleted_block_field.csv"), "-o", str(tmp_path / "cold.step"), "-q"]
    out = _run(f"""
        import sys
        from hot2cold.cli import main
        code = main({args!r})
        print(code, sorted({{m.split(".")[0] for m in sys.modules}} & {{"cadquery", "vtk"}}))
    """)
    # (the kernel's STEP writer prints its own statistics first)
    assert out.strip().splitlines()[-1] == "0 []" and (tmp_path / "cold.step").exists()


def test_the_package_names_are_the_library_s_and_the_old_paths_are_gone():
    """``hot2cold.morph`` is the function, whatever was imported before; the shims of the unreleased 0.1.0's
    flat layout (``hot2cold/morph.py``, ``hot2cold/field.py``) are gone, so no module shadows a name."""
    out = _run("""
        import importlib.util
        import hot2cold
        import hot2cold.pipeline.morph, hot2cold.io.field
        from hot2cold.pipeline.morph import morph
        from hot2cold.io.field import read_field
        assert hot2cold.morph is morph and hot2cold.read_field is read_field
        assert importlib.util.find_spec("hot2cold.field") is None and importlib.util.find_spec("hot2cold.morph") is None
        print("ok")
    """)
    assert out.strip() == "ok"


@pytest.mark.parametrize("name", ["morph", "Settings", "DisplacementField", "read_field", "MorphError"])
def test_lazy_names_are_listed(name):
    import hot2cold

    assert name in hot2cold.__all__ and name in dir(hot2cold)


@pytest.mark.heavy
def test_readme_python_example_runs_as_written(tmp_path):
    """The README's "From Python" example, run in a fresh interpreter (bundled paths made absolute): it
    morphs, prints the table and writes the cold STEP."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    section = readme[readme.index("## From Python"):]
    code = section[section.index("```python") + len("```python"):section.index("```", section.index("```python") + 3)]
    code = code.replace('"sample_parts/', f'"{ROOT / "sample_parts"}/')
    code = code.replace('"cold.step"', f'"{tmp_path / "cold.step"}"')
    out = _run(code)
    assert "Δmax" in out
    assert (tmp_path / "cold.step").stat().st_size > 10_000


def test_readme_is_for_users_and_its_test_command_is_the_ci_one():
    """The README stays a page a user reads through (about 200 lines; the rest lives in ``docs/``), and its
    test command is the one ``.ci/run`` runs, word for word."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 200
    command = [line for line in readme.splitlines() if line.startswith("apt-get update")]
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()[-1]
    assert command == [ci]
