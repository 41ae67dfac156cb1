"""Reference displacements of the Nastran corpus, read by pyNastran, for tests/test_nastran.py.

pyNastran 1.4.1 needs numpy < 2 and hot2cold numpy >= 2, so this script runs in its own environment, never
in the project's venv.  To regenerate ``corpus/solver_results/nastran/reference.npz``::

    python3 -m venv /work/venv-pynastran
    /work/venv-pynastran/bin/pip install pyNastran==1.4.1 "numpy<2"
    /work/venv-pynastran/bin/python benchmarks/nastran_reference.py

For each OP2 of the corpus and each displacement subcase the npz holds, under ``<file>/subcase <id>/``:
``node_ids`` (N,), ``displacements`` (N, 3) T1-T3 as the OP2 holds them (in each grid's CD system),
``cd`` (N,) those systems, and ``points`` (N, 3) the basic-frame positions of the OP2's GRIDs
(``transform_xyzcp_to_xyz_cid``).  Under ``<file>.bdf/``: ``node_ids`` and ``points`` of the GRIDs of the
bulk data files whose grids are in the basic frame, read by pyNastran's BDF reader.

The displacements are not taken to the basic frame here: pyNastran 1.4.1's
``transform_displacements_to_global`` gets the grids in the cylindrical CD system of
``static_solid_shell_bar_global_radial_cd.op2`` wrong (its vectors differ from those of
``static_solid_shell_bar.op2``, the same model run by Nastran with CD 0, by a 90 degree turn).  The tests
compare hot2cold's basic-frame vectors of the CD run with that basic run, which is Nastran's own answer.

pyNastran does not read punch displacements: the tests compare the punch file with the OP2 of the same run
(``cbush.op2``).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

CORPUS = Path(__file__).resolve().parents[1] / "corpus" / "solver_results" / "nastran"
OP2_FILES = ["solid_bending.op2", "ctetra.op2", "static_solid_shell_bar.op2",
             "static_solid_shell_bar_global_radial_cd.op2", "static.op2", "cbush.op2"]
BDF_FILES = ["solid_bending.bdf", "ctetra.bdf", "static.bdf"]


def op2_reference(path: Path) -> dict[str, np.ndarray]:
    from pyNastran.op2.op2_geom import read_op2_geom

    model = read_op2_geom(str(path), debug=None, build_dataframe=False)
    unused_icd, icp, xyz_cp, nid_cp_cd = model.get_displacement_index_xyz_cp_cd()
    xyz_cid0 = model.transform_xyzcp_to_xyz_cid(xyz_cp, nid_cp_cd[:, 0], icp, cid=0)
    position = {int(nid): xyz for nid, xyz in zip(nid_cp_cd[:, 0], xyz_cid0)}
    cd = {int(nid): int(c) for nid, c in zip(nid_cp_cd[:, 0], nid_cp_cd[:, 2])}
    out = {}
    for subcase, disp in model.displacements.items():
        grid = disp.node_gridtype[:, 1] == 1
        ids = disp.node_gridtype[grid, 0].astype(np.int64)
        for itime in range(disp.data.shape[0]):
            key = f"{path.name}/subcase {subcase}" + (f"/{itime}" if disp.data.shape[0] > 1 else "")
            out[f"{key}/node_ids"] = ids
            out[f"{key}/displacements"] = disp.data[itime, grid, :3].astype(np.float64)
            out[f"{key}/points"] = np.array([position[i] for i in ids], dtype=np.float64)
            out[f"{key}/cd"] = np.array([cd[i] for i in ids], dtype=np.int64)
    return out


def bdf_reference(path: Path) -> dict[str, np.ndarray]:
    from pyNastran.bdf.bdf import read_bdf

    model = read_bdf(str(path), debug=None, xref=True)
    ids = np.array(sorted(model.nodes), dtype=np.int64)
    return {f"{path.name}/node_ids": ids,
            f"{path.name}/points": np.array([model.nodes[i].get_position() for i in ids], dtype=np.float64)}


def main() -> int:
    arrays: dict[str, np.ndarray] = {}
    for name in OP2_FILES:
        arrays.update(op2_reference(CORPUS / name))
    for name in BDF_FILES:
        arrays.update(bdf_reference(CORPUS / name))
    np.savez_compressed(CORPUS / "reference.npz", **arrays)
    for key, value in arrays.items():
        sys.stdout.write(f"{key}: {value.shape}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
