"""Fields already in memory as the Python FE tools hand them over: a ``meshio.Mesh`` and a pyvista dataset
(PyMAPDL and DPF give their results as pyvista grids) are taken as the field, with the result of the file
route."""
from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest
import pyvista

from hot2cold.errors import FieldError
from hot2cold.io.field import as_field, read_field

SAMPLES = Path(__file__).resolve().parent.parent / "sample_parts"


def _tet_mesh(tmp_path) -> tuple[Path, meshio.Mesh]:
    """A unit cube of 6 tetrahedra with a displacement ``U`` and a temperature at its 8 points, as a .vtu."""
    corners = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    tets = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])
    u = 1e-3 * np.column_stack([corners[:, 0], -corners[:, 1], 0.5 * corners[:, 2]])
    mesh = meshio.Mesh(corners, [("tetra", tets)], point_data={"U": u, "T": np.arange(8.0)})
    path = tmp_path / "cube.vtu"
    meshio.write(path, mesh)
    return path, mesh


def test_a_meshio_mesh_and_a_pyvista_grid_are_the_files_field(tmp_path):
    """The points, displacements and boundary triangles of the mesh in memory are those read from its file;
    ``units`` and ``field_name`` apply as to a file."""
    path, mesh = _tet_mesh(tmp_path)
    from_file = read_field(path)
    grid = pyvista.read(path)
    for given in (mesh, meshio.read(path), grid):
        field = as_field(given)
        np.testing.assert_array_equal(field.points, from_file.points)
        np.testing.assert_array_equal(field.displacements, from_file.displacements)
        np.testing.assert_array_equal(field.triangles, from_file.triangles)
        assert field.triangles is not None and len(field.triangles) == 12      # the cube's boundary, 2 a side
    assert as_field(grid).source == "UnstructuredGrid in memory"
    in_metres = as_field(mesh, units="m")
    np.testing.assert_allclose(in_metres.points, 1000 * from_file.points, rtol=1e-15)
    with pytest.raises(FieldError, match=r"the Mesh given: point field 'T' has shape \(8,\), but a displacement"):
        as_field(mesh, field_name="T")
    with pytest.raises(FieldError, match=r"the PolyData given has no displacement point field named U"):
        as_field(pyvista.Sphere())


def test_morph_takes_them_with_the_files_result(tmp_path):
    """End to end on the bundled blade (every 4th node of its field): the morph of the field as a .vtu file, as
    the ``meshio.Mesh`` and as the pyvista grid read from it gives the same cold part (the same Δmax)."""
    from hot2cold import morph

    table = np.loadtxt(SAMPLES / "twisted_blade_field.csv", delimiter=",", skiprows=1)[::4]
    mesh = meshio.Mesh(table[:, 1:4], [("vertex", np.arange(len(table))[:, None])],
                       point_data={"displacement": table[:, 4:7]})
    path = tmp_path / "blade.vtu"
    meshio.write(path, mesh)
    hot = SAMPLES / "twisted_blade.step"
    results = [morph(hot, given) for given in (path, meshio.read(path), pyvista.read(path))]
    deltas = [r.report.delta_max for r in results]
    assert deltas[0] < 1e-3
    assert deltas[1] == deltas[0] and deltas[2] == deltas[0]
    for r in results[1:]:
        for a, b in zip(r.faces, results[0].faces):
            np.testing.assert_array_equal(a.surface.poles, b.surface.poles)
