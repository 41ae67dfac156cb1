"""Triangle meshes of the sample parts: every face meshed, outward, closed once vertices are merged."""
from __future__ import annotations

import numpy as np
import trimesh

from hot2cold.kernel.validity import check_solids
from hot2cold.kernel.tessellate import tessellate
from hot2cold.kernel.explore import shape_map


def test_blade_mesh_is_closed_outward_and_close_to_the_volume(blade_shape):
    from OCP.TopAbs import TopAbs_FACE
    mesh = tessellate(blade_shape)
    assert set(mesh.face) == set(range(len(shape_map(blade_shape, TopAbs_FACE))))
    tm = trimesh.Trimesh(mesh.vertices, mesh.triangles, process=True)
    tm.merge_vertices()
    assert tm.is_watertight
    volume = check_solids(blade_shape)[0].volume
    assert 0.98 * volume < tm.volume < 1.001 * volume        # positive: triangles face outward
    assert np.isfinite(mesh.uv).all()


def test_finer_deflection_gives_a_closer_volume(block_shape):
    volume = check_solids(block_shape)[0].volume
    coarse, fine = tessellate(block_shape, 0.5), tessellate(block_shape, 0.01)
    err = [abs(trimesh.Trimesh(m.vertices, m.triangles).volume - volume) for m in (coarse, fine)]
    assert err[1] < err[0] and len(fine.triangles) > len(coarse.triangles)
