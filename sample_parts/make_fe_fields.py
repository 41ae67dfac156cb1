"""Real FE fields for the sample parts: gmsh second-order tetrahedra, CalculiX, hot-to-cold load case.

Writes ``rotor37_blade_field.npz`` and ``mixer_segment_field.npz`` (surface nodes of the FE mesh with their
hot-to-cold displacements, mm) next to this script, so that tests and users need no solver.  Needs gmsh
(the ``fe`` extra) and CalculiX ``ccx`` (Debian package ``calculix-ccx``).

* Rotor 37 blade: Ti-6Al-4V, running at 1800 rad/s (17 189 rpm, NASA design speed) about the z axis and
  at 420 K (hub) to 480 K (tip), back to rest at 293 K; the hub face is fixed (the root).
* Mixer segment: a static part (no rotation) in exhaust gas, hot from 700 K at the inlet to 850 K at the
  exit along its x axis, back to 293 K; the inlet face is fixed.

Run: ``python sample_parts/make_fe_fields.py``
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from hot2cold.core.bspline import evaluate_surface
from hot2cold.fe.calculix import LoadCase, MeshOptions, hot_to_cold_field
from hot2cold.kernel.step import read_step
from hot2cold.kernel.topology import decompose

HERE = Path(__file__).resolve().parent


def _face_nearest(step: Path, axis: int, lowest: bool = True) -> int:
    """The face whose centre has the smallest (or largest) coordinate along ``axis``."""
    part = decompose(read_step(step))
    centres = []
    for face in part.faces:
        u0, u1, v0, v1 = face.uv_box
        centres.append(evaluate_surface(face.surface, [(u0 + u1) / 2], [(v0 + v1) / 2])[0, axis])
    return int(np.argmin(centres) if lowest else np.argmax(centres))


def mixer_temperature(points: np.ndarray) -> np.ndarray:
    """Hot temperature (K) of the mixer's nodes ``(N, 3)``: 700 K at the inlet (x = 0) to 850 K at x = 250."""
    return 700.0 + 150.0 * np.clip(points[:, 0] / 250.0, 0.0, 1.0)


def main() -> int:
    jobs = [
        ("rotor37_blade", dict(mesh=MeshOptions(size=1.5, min_size=0.15),
                               load=LoadCase(omega=1800.0, axis_point=(0, 0, 0), axis_direction=(0, 0, 1)))),
        ("mixer_segment", dict(mesh=MeshOptions(size=4.0, min_size=0.6),
                               load=LoadCase(omega=0.0, axis_point=(0, 0, 0), axis_direction=(1, 0, 0),
                                             hot_temperature=mixer_temperature,
                                             fixed_faces=[_face_nearest(HERE / "mixer_segment.step", 0)]))),
    ]
    for name, options in jobs:
        start = time.perf_counter()
        field = hot_to_cold_field(HERE / f"{name}.step", HERE / f"{name}_field.npz", **options)
        size = (HERE / f"{name}_field.npz").stat().st_size / 1e6
        largest = np.linalg.norm(field.displacements, axis=1).max()
        print(f"{name}: {len(field)} surface nodes, max |d| {largest:.4f} mm, "
              f"{time.perf_counter() - start:.1f} s, {size:.2f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
