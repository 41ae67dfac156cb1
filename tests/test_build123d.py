"""A build123d shape as the hot part: taken as CadQuery's are, and the cold part handed back as build123d's class.

build123d and CadQuery share one environment only where they share one OCP: recent build123d (0.11 on) needs
an OCP build without VTK, which CadQuery's VTK-bound one cannot stand beside.  The test therefore builds a
fresh venv with the pair a user can install together (build123d 0.10 and CadQuery 2.7, both on OCP 7.8; its
``ocp_gordon`` held below 0.2, whose later releases need OCP 8) and the checkout installed in it, and morphs
there: the bundled twisted blade read by build123d against the same file read by hot2cold (the same Δmax, the
same poles), and build123d's own ``Box`` and ``BuildPart`` with a thermal field.  It downloads about 400 MB.
"""
from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import run_outside

ROOT = Path(__file__).resolve().parent.parent

#: The pair of releases that share one OCP (7.8): build123d 0.10 asks for ``cadquery-ocp>=7.8,<7.9``,
#: CadQuery 2.7 takes it.
PINS = ("build123d==0.10.0", "cadquery==2.7.0", "ocp_gordon<0.2")
#: Seconds each command of the test may take (the install downloads about 400 MB).
INSTALL_TIMEOUT = 1500

SCRIPT = textwrap.dedent("""
    import json, sys
    import build123d as b3d
    import numpy as np
    from hot2cold import morph
    from hot2cold.errors import InputError
    from hot2cold.kernel.sampling import fe_surface_nodes
    from hot2cold.testing.synthetic import AffineField

    blade, field = sys.argv[1], sys.argv[2]
    out = {}
    hot = b3d.import_step(blade)
    by_b3d, by_file = morph(hot, field), morph(blade, field)
    out["blade"] = dict(
        hot_type=type(hot).__name__, cold_type=type(by_b3d.cold).__name__, hot_back=type(by_b3d.hot).__name__,
        delta=[by_b3d.report.delta_max, by_file.report.delta_max],
        same_poles=all(np.array_equal(a.surface.poles, b.surface.poles) for a, b in zip(by_b3d.faces, by_file.faces)),
        file_cold_type=type(by_file.cold).__module__.split(".")[0], valid=by_b3d.cold.is_valid)

    thermal = AffineField.thermal(contraction=-0.004, rotation_deg=0.2)
    box = b3d.Box(40, 20, 10)
    nodes, _ = fe_surface_nodes(box.wrapped, 2.0)
    for name, hot in (("box", box), ("builder", None)):
        if hot is None:
            with b3d.BuildPart() as hot:
                b3d.Box(40, 20, 10)
        result = morph(hot, (nodes, thermal(nodes)))
        cold = result.cold
        out[name] = dict(hot_type=type(hot).__name__, cold_type=type(cold).__name__, valid=cold.is_valid,
                         volume=cold.volume, delta=result.report.delta_max)
    with b3d.BuildPart() as empty:
        pass
    try:
        morph(empty, (nodes, thermal(nodes)))
    except InputError as exc:
        out["empty"] = str(exc)
    print(json.dumps(out))
""")


@pytest.mark.slow
def test_a_build123d_part_morphs_as_its_step_file_does_and_comes_back_as_build123d(tmp_path):
    venv = tmp_path / "venv"
    run_outside([sys.executable, "-m", "venv", venv], tmp_path, timeout=INSTALL_TIMEOUT)
    python = venv / "bin" / "python"
    run_outside([python, "-m", "pip", "install", "-q", *PINS, ROOT], tmp_path, timeout=INSTALL_TIMEOUT)
    where = run_outside([python, "-c", "import hot2cold; print(hot2cold.__file__)"], tmp_path, timeout=INSTALL_TIMEOUT)
    assert "site-packages" in where
    (tmp_path / "run.py").write_text(SCRIPT)
    samples = ROOT / "sample_parts"
    out = json.loads(run_outside([python, "run.py", samples / "twisted_blade.step",
                                  samples / "twisted_blade_field.csv"], tmp_path, timeout=INSTALL_TIMEOUT)
                     .strip().splitlines()[-1])

    blade = out["blade"]
    assert (blade["hot_type"], blade["cold_type"], blade["hot_back"]) == ("Solid", "Solid", "Solid")
    assert blade["file_cold_type"] == "cadquery"          # a path gives CadQuery's shapes, as before
    assert blade["delta"][0] == blade["delta"][1] and blade["delta"][0] < 1e-3     # the sample's tolerance
    assert blade["same_poles"] and blade["valid"]

    for name, kind in (("box", "Box"), ("builder", "BuildPart")):
        run = out[name]
        assert run["hot_type"] == kind and run["cold_type"] == "Part" and run["valid"]
        # the thermal field shrinks every length by 0.4 %: the volume by 1.2 % (0.996 ** 3), to its tolerance
        assert run["volume"] == pytest.approx(40 * 20 * 10 * 0.996 ** 3, rel=1e-4)
        assert run["delta"] < 1e-3
    assert out["empty"] == "the build123d BuildPart holds no shape: build the part first"
