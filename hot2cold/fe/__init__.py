"""A real FE pipeline for hot2cold: gmsh mesh -> CalculiX hot-to-cold run -> displacement field.

* :func:`mesh_step` (:mod:`.mesh`): second-order tetrahedra of a STEP solid with gmsh, a :class:`TetMesh`.
* :func:`write_deck`, :func:`run_ccx`, :func:`read_hot_to_cold`, :func:`hot_to_cold_field` (its options in
  records: :class:`MeshOptions`, :class:`LoadCase`, :class:`SolverOptions`)
  (:mod:`.calculix`): the hot-to-cold load case (cool down, stop rotating, root fixed) with CalculiX.
* :func:`read_frd`, :class:`FrdFile` (:mod:`.frd`): CalculiX ``.frd`` results; ``hot2cold.read_field``
  reads them too.

Needs the ``fe`` extra (``pip install 'hot2cold[fe]'``: gmsh, meshio) and CalculiX's ``ccx`` on the PATH
(Debian/Ubuntu: ``apt-get install calculix-ccx``).  gmsh is imported only when a mesh is made, and nothing
here is imported by ``import hot2cold``.
"""
from .calculix import (ROOM_TEMPERATURE, ROTOR37_OMEGA, TI6AL4V, LoadCase, Material, MeshOptions, SolverOptions,
                       blade_temperature, hot_to_cold_field, hub_faces, read_hot_to_cold, run_ccx, write_deck)
from ..io.frd import FrdFile, FrdResult, read_frd
from .mesh import SolverError, TetMesh, mesh_step

__all__ = ["SolverError", "TetMesh", "mesh_step", "Material", "TI6AL4V", "ROOM_TEMPERATURE", "ROTOR37_OMEGA",
           "write_deck", "run_ccx", "read_hot_to_cold", "hot_to_cold_field", "MeshOptions", "LoadCase",
           "SolverOptions", "blade_temperature", "hub_faces",
           "FrdFile", "FrdResult", "read_frd"]
