"""Hard cases: fields a new user brings, built from analytic displacements so that the exact cold part is known,
each morphed by the command line and scored against the exact cold geometry.

Run from the repository::

    python benchmarks/hard_cases.py                         # every case, two at a time
    python benchmarks/hard_cases.py --cases blade_scatter_volume,mixer_hotspot --jobs 1
    python benchmarks/hard_cases.py --json out/hard_cases.json

What a case is: a bundled part (``sample_parts/``, or one built from it: the thin blade cut by two cylinders),
a node set, an analytic field, and what spoils it: normal noise in the node positions (``sigma_position``, mm
per axis, the values taken at the scattered positions) and in the values (``sigma_value``, mm per component),
and volume nodes inside the part (:func:`hot2cold.kernel.sampling.volume_nodes`, their values the field's at
their own positions).  Node sets: ``fe``, FE-like surface nodes
(:func:`hot2cold.kernel.sampling.fe_surface_nodes`); ``tess``, the vertices of the kernel's triangulation only
(an STL or CFD surface mesh: nothing inside a plane).

For each case, in a fresh process: the morph (``hot2cold morph hot field.npz -o cold.step --report r.json``),
its exit code and the verdict of its report (met or not, the largest error it found at the nodes and between
them, the faces it says it did not measure); on a written part (exit 0 or 5) the error against the exact cold
geometry: dense samples over every hot face (half the node spacing), mapped by the analytic field, each one's
distance to the cold face (:func:`real_parts.face_errors`), overall and over the faces the tool says it
measured.

The promise checked: a run ends with exit 0 only where the cold part is within the tolerance plus the field's
true scatter of the exact geometry, everywhere the tool says it measured.  The true scatter is the allowance
the tool's own rule gives for the noise the case really put in the values
(:func:`hot2cold.pipeline.refine.noise_allowance` with ``sigma_value`` and the node count); a row above it
with exit 0 is a **silent miss**.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import resource
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))     # real_parts beside this one

import real_parts as rp  # noqa: E402

ROOT = rp.ROOT
SAMPLES = rp.SAMPLES
TOLERANCE = 1e-3
SEED = 0


# ---------------------------------------------------------------------------------------------- the fields

class _Field:
    """An analytic field: ``self(p)`` the displacements ``(N, 3)`` at ``p (N, 3)`` (mm)."""

    def exact_map(self, p: np.ndarray) -> np.ndarray:
        """The exact cold positions ``(N, 3)`` of the hot points ``p (N, 3)``."""
        return p + self(p)


@dataclass(frozen=True)
class _Blade(_Field):
    """A field over a part of bounding box ``lo``, ``hi`` (3,), its ``span`` the longest direction and ``side``
    the one it bends in."""

    lo: np.ndarray
    hi: np.ndarray
    span: int
    side: int


@dataclass(frozen=True)
class Bend(_Blade):
    """A blade bent about its span: the tip moves ``amp`` mm along ``side``, plane sections stay plane (the
    span displacement is linear through the wall, so volume nodes carry other values than the surface's)."""

    amp: float

    def __call__(self, p: np.ndarray) -> np.ndarray:
        length = self.hi[self.span] - self.lo[self.span]
        z = (p[:, self.span] - self.lo[self.span]) / length
        d = np.zeros_like(p)
        d[:, self.side] = self.amp * z ** 2
        mid = 0.5 * (self.lo[self.side] + self.hi[self.side])
        d[:, self.span] = -self.amp * 2.0 * z / length * (p[:, self.side] - mid)
        return d



@dataclass(frozen=True)
class WallGradient(_Blade):
    """A temperature difference across a thin wall: the wall bends and thickens, the displacement along the
    thickness direction ``side`` quadratic in that coordinate (``amp`` mm at the wall's faces, relative to its
    mid-plane ``mid``), times a smooth profile along the span."""

    amp: float

    def __call__(self, p: np.ndarray) -> np.ndarray:
        length = self.hi[self.span] - self.lo[self.span]
        z = (p[:, self.span] - self.lo[self.span]) / length
        mid = 0.5 * (self.lo[self.side] + self.hi[self.side])
        half = 0.5 * (self.hi[self.side] - self.lo[self.side])
        s = (p[:, self.side] - mid) / half
        d = np.zeros_like(p)
        d[:, self.side] = self.amp * (s ** 2 + 0.5 * s) * (0.5 + z)
        d[:, self.span] = self.amp * 0.3 * s * z
        return d



@dataclass(frozen=True)
class ThermalFront(_Field):
    """A sharp thermal front across the span at ``z0`` (width ``width`` mm): the strain ``strain`` on its hot
    side, none on the other; the displacement is the strain integrated (a smooth step of the slope)."""

    lo: np.ndarray
    hi: np.ndarray
    span: int
    strain: float
    width: float

    def __call__(self, p: np.ndarray) -> np.ndarray:
        z0 = 0.5 * (self.lo[self.span] + self.hi[self.span])
        centre = 0.5 * (self.lo + self.hi)
        x = (p[:, self.span] - z0) / self.width
        # the strain rises from 0 to ``strain`` across the front: its integral along the span
        ramp = 0.5 * self.strain * self.width * (x + np.logaddexp(x, -x) - math.log(2.0))
        share = 0.5 * self.strain * (1.0 + np.tanh(x))
        d = (p - centre) * share[:, None]
        d[:, self.span] = ramp
        return d



@dataclass(frozen=True)
class Clamped(_Blade):
    """A flank clamped below ``z0``: nothing moves there, above it the part swings by ``amp`` mm at the far end,
    quadratic in the distance from the clamp (the field's curvature jumps at ``z0``)."""

    amp: float
    at: float = 0.3

    def __call__(self, p: np.ndarray) -> np.ndarray:
        z0 = self.lo[self.span] + self.at * (self.hi[self.span] - self.lo[self.span])
        t = np.maximum(p[:, self.span] - z0, 0.0) / (self.hi[self.span] - z0)
        d = np.zeros_like(p)
        d[:, self.side] = self.amp * t ** 2
        return d



@dataclass(frozen=True)
class HotSpot(_Field):
    """A hot spot: thermal expansion about the part's centre, ``strain`` at a Gaussian spot of radius
    ``radius`` mm around ``spot`` and a tenth of it elsewhere."""

    centre: np.ndarray
    spot: np.ndarray
    strain: float
    radius: float

    def __call__(self, p: np.ndarray) -> np.ndarray:
        w = 0.1 + 0.9 * np.exp(-np.sum((p - self.spot) ** 2, axis=1) / self.radius ** 2)
        return self.strain * w[:, None] * (p - self.centre)



def make_field(kind: str, lo: np.ndarray, hi: np.ndarray, surface: np.ndarray):
    """The analytic field ``kind`` over a part of bounding box ``lo``, ``hi`` (3,) whose surface nodes are
    ``surface (N, 3)``."""
    span = int(np.argmax(hi - lo))
    side = int(np.argmin(hi - lo))
    if kind in ("affine", "smooth"):
        return rp.make_field(kind, lo, hi)
    if kind == "bend":
        return Bend(lo, hi, span, side, amp=0.5)
    if kind == "wall":
        return WallGradient(lo, hi, span, side, amp=0.02)
    if kind == "front":
        return ThermalFront(lo, hi, span, strain=-2e-3, width=0.02 * float(hi[span] - lo[span]))
    if kind == "clamped":
        return Clamped(lo, hi, span, (span + 1) % 3, amp=0.5)
    if kind == "hotspot":
        centre = 0.5 * (lo + hi)
        spot = surface[int(np.argmax(surface[:, span]))]       # a spot on the surface, at its far end
        return HotSpot(centre, spot, strain=-3e-3, radius=0.1 * float(np.linalg.norm(hi - lo)))
    raise ValueError(f"unknown field {kind!r}")


# ----------------------------------------------------------------------------------------------- the cases

#: Mistakes a user makes with a right field (node positions ``x``, hot-to-cold displacements ``d``): what the
#: field file then holds.
MISTAKES = {
    "cold_positions": "the cold positions x + d with the displacements d",
    "cold_to_hot": "the cold positions x + d with the cold-to-hot displacements -d",
    "metres": "positions and displacements in metres",
    "other_part": "another part's field (the twisted blade's on the filleted block)",
}


def make_mistake(kind: str, points: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The field ``points (N, 3)``, ``values (N, 3)`` as the mistake ``kind`` writes it."""
    if kind == "cold_positions":
        return points + values, values
    if kind == "cold_to_hot":
        return points + values, -values
    if kind == "metres":
        return points * 1e-3, values * 1e-3
    raise ValueError(f"unknown mistake {kind!r}")



@dataclass(frozen=True)
class Case:
    """One hard case; see the module docstring."""

    part: str                       # a sample part's file name, or "trimmed_blade" (built)
    nodes: str                      # fe | tess
    field: str                      # a kind of :func:`make_field`
    per_diagonal: float = 80.0      # node spacing: the diagonal / this
    sigma_position: float = 0.0     # mm per axis
    sigma_value: float = 0.0        # mm per component
    volume: int = 0                 # volume nodes inside the part
    volume_margin: float = 0.02     # mm, the least distance of a volume node from the surface
    args: tuple = ()                # extra morph options
    mistake: str = ""               # a user's mistake made of the field (:data:`MISTAKES`), or none
    why: str = ""


CASES = {
    "blade_scatter_volume": Case("thin_blade.step", "fe", "bend", sigma_position=0.0017, volume=300,
                                 why="the issue's: positions scattered, volume nodes in a thin blade"),
    "blade_wall_volume": Case("thin_blade.step", "fe", "wall", volume=300,
                              why="a temperature gradient across the wall, volume nodes"),
    "blade_value_noise": Case("twisted_blade.step", "fe", "smooth", sigma_value=2e-4,
                              why="noise in the values"),
    "blade_noise_both": Case("thin_blade.step", "fe", "bend", sigma_position=0.005, sigma_value=1e-4, volume=300,
                             why="noise in positions and values, volume nodes"),
    "trimmed_blade_tess": Case("trimmed_blade", "tess", "smooth",
                               why="blade cut by two cylinders, tessellation vertices only"),
    "blade_tess": Case("thin_blade.step", "tess", "bend", why="tessellation vertices only"),
    "blade_front": Case("thin_blade.step", "fe", "front", why="a sharp thermal front across the span"),
    "blade_clamped": Case("twisted_blade.step", "fe", "clamped", why="a clamped flank: curvature jumps"),
    "mixer_hotspot_tess": Case("mixer_segment.step", "tess", "hotspot",
                               why="lobed mixer, hot spot, tessellation vertices"),
    "mixer_front": Case("mixer_segment.step", "fe", "front", sigma_position=0.01, why="mixer, thermal front"),
    "block_tess": Case("filleted_block.step", "tess", "smooth", why="planes with nodes only on their borders"),
    "blade_front_sparse": Case("thin_blade.step", "fe", "front", per_diagonal=30,
                               why="a sharp thermal front, few nodes across it"),
    "mixer_hotspot_volume": Case("mixer_segment.step", "fe", "hotspot", sigma_value=3e-4, volume=500,
                                 volume_margin=0.05, why="mixer, hot spot, noisy values, volume nodes"),
    "rotor37_clamped_noise": Case("rotor37_blade.step", "fe", "clamped", sigma_value=1e-4,
                                  why="rotor blade, clamped, noisy values"),
    # the mistakes: each should be refused (exit 2) in a few seconds, named for what it is, nothing written
    "mixup_cold_positions": Case("twisted_blade.step", "fe", "smooth", mistake="cold_positions",
                                 why=MISTAKES["cold_positions"]),
    "mixup_cold_to_hot": Case("twisted_blade.step", "fe", "smooth", mistake="cold_to_hot",
                              why=MISTAKES["cold_to_hot"]),
    "field_in_metres": Case("twisted_blade.step", "fe", "smooth", mistake="metres", why=MISTAKES["metres"]),
    "other_part_field": Case("filleted_block.step", "fe", "smooth", mistake="other_part",
                             why=MISTAKES["other_part"]),
}


@dataclass
class Result:
    case: str
    why: str = ""
    nodes: int = 0
    volume_nodes: int = 0
    exit_code: int | None = None
    message: str = ""
    met: bool | None = None
    state: str = ""                         # the report's verdict: met, partly measured, not met
    measured: float | None = None           # the share of the part's area it measured
    delta_nodes: float | None = None        # the tool's largest error at the nodes, mm
    delta_between: float | None = None      # ... between them
    allowance: float | None = None          # the tool's allowance for scatter, mm
    unmeasured: list[int] = field(default_factory=list)
    exact_max: float | None = None          # against the exact cold geometry, every face, mm
    exact_face: int = -1
    exact_measured: float | None = None     # over the faces the tool says it measured
    limit: float = TOLERANCE                # the tolerance plus the true scatter's allowance
    seconds: float = 0.0
    peak_mb: float = 0.0
    written: list[str] = field(default_factory=list)     # the files the morph left (none on a refusal)

    @property
    def silent_miss(self) -> bool:
        return self.exit_code == 0 and self.exact_measured is not None and self.exact_measured > self.limit


def trimmed_blade(path: Path) -> Path:
    """The thin blade cut by two cylinders across its span, written to ``path``: trimmed B-spline faces."""
    import cadquery as cq

    blade = cq.importers.importStep(str(SAMPLES / "thin_blade.step"))
    lo, hi = (np.array(v) for v in ((blade.val().BoundingBox().xmin, blade.val().BoundingBox().ymin,
                                     blade.val().BoundingBox().zmin),
                                    (blade.val().BoundingBox().xmax, blade.val().BoundingBox().ymax,
                                     blade.val().BoundingBox().zmax)))
    centre = 0.5 * (lo + hi)
    chord = float(hi[0] - lo[0])
    cut = blade
    for x, z in ((lo[0], 0.3 * hi[2]), (hi[0], 0.7 * hi[2])):
        tool = cq.Workplane("XZ").center(x, z).circle(0.25 * chord).extrude(50.0, both=True)
        cut = cut.cut(tool.translate((0, centre[1], 0)))
    cq.exporters.export(cut, str(path))
    return path


def run_case(name: str, workdir: Path) -> Result:
    """One case in this process."""
    from hot2cold.cli import main as cli_main
    from hot2cold.kernel.explore import diagonal
    from hot2cold.kernel.sampling import volume_nodes
    from hot2cold.kernel.step import read_step
    from hot2cold.kernel.validity import face_areas
    from hot2cold.pipeline.refine import noise_allowance

    case = CASES[name]
    result = Result(case=name, why=case.why)
    path = trimmed_blade(workdir / "trimmed_blade.step") if case.part == "trimmed_blade" else SAMPLES / case.part
    hot = read_step(path)
    faces = rp.solid_faces(hot)
    lo, hi = rp.box(hot)
    diag = diagonal(hot)
    spacing = max(diag / case.per_diagonal, math.sqrt(float(face_areas(faces).sum()) / rp.NODE_RANGE[1]))
    surface = rp.node_set(hot, case.nodes, spacing)
    analytic = make_field(case.field, lo, hi, surface)
    rng = np.random.default_rng(SEED)
    points = surface + rng.normal(0.0, case.sigma_position, surface.shape) if case.sigma_position else surface
    if case.volume:
        inside = volume_nodes(hot, case.volume, seed=SEED, margin=case.volume_margin)
        points = np.vstack([points, inside])
        result.volume_nodes = len(inside)
    values = analytic(points)
    if case.sigma_value:
        values = values + rng.normal(0.0, case.sigma_value, values.shape)
    if case.mistake == "other_part":
        blade = read_step(SAMPLES / "twisted_blade.step")
        blade_lo, blade_hi = rp.box(blade)
        points = rp.node_set(blade, "fe", spacing)
        values = make_field(case.field, blade_lo, blade_hi, points)(points)
    elif case.mistake:
        points, values = make_mistake(case.mistake, points, values)
    result.nodes = len(points)
    result.limit = TOLERANCE + noise_allowance(case.sigma_value, len(points))
    field_path, cold_path, report_path = workdir / "field.npz", workdir / "cold.step", workdir / "report.json"
    np.savez(field_path, points=points, displacements=values)

    stderr = io.StringIO()
    start = time.perf_counter()
    with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(io.StringIO()):
        result.exit_code = cli_main(["morph", str(path), str(field_path), "-o", str(cold_path), "--report",
                                     str(report_path), "--tolerance", f"{TOLERANCE:g}", "-q", *case.args])
    result.seconds = time.perf_counter() - start
    result.peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    result.message = rp.one_line(stderr.getvalue()).replace(f"{workdir}/", "")
    result.written = sorted(p.name for p in (cold_path, report_path) if p.exists())
    if report_path.exists():
        data = json.loads(report_path.read_text())
        result.met = data.get("tolerance_met")
        edge_max = max((e["delta_max"] for e in data.get("edges", []) if e.get("delta_max") is not None),
                       default=0.0)
        result.delta_nodes = max(data.get("delta_max") or 0.0, edge_max)
        result.delta_between = data.get("delta_between")
        result.allowance = data.get("allowance")
        # the faces the tool does not vouch for: those it names as unmeasured, and on a run it calls partly
        # measured, every face with any share unmeasured
        partly = (data.get("verdict") or {}).get("state") not in (None, "met")
        result.unmeasured = sorted(set(data.get("unsupported_faces", [])) | {
            f["index"] for f in data.get("faces", []) if partly and (f.get("unsupported") or 0.0) > 0.0})
        result.state = (data.get("verdict") or {}).get("state", "")
        result.measured = (data.get("verdict") or {}).get("measured")
    if result.exit_code not in rp.WRITTEN or not cold_path.exists():
        return result
    cold = read_step(cold_path)
    errors = rp.face_errors(hot, cold, analytic.exact_map, spacing / 2)
    worst = [float(e.max()) if len(e) else 0.0 for e in errors]
    result.exact_face = int(np.argmax(worst))
    result.exact_max = max(worst)
    result.exact_measured = max((w for k, w in enumerate(worst) if k not in result.unmeasured), default=0.0)
    return result


def run_child(name: str, timeout: float) -> Result:
    """:func:`run_case` in a fresh process (its peak memory its own, a crash recorded)."""
    with tempfile.TemporaryDirectory(prefix="hard_cases_") as tmp:
        tmp = Path(tmp)
        out = tmp / "result.json"
        status, usage, seconds = rp.spawn([sys.executable, __file__, "--one", name, "--workdir", str(tmp),
                                           "--json", str(out)], timeout, None, tmp / "stderr.txt")
        if out.exists():
            return Result(**json.loads(out.read_text()))
        return Result(case=name, why=CASES[name].why, message=rp.died(status, timeout, tmp / "stderr.txt"),
                      seconds=seconds, peak_mb=usage.ru_maxrss / 1024.0)


def _mm(x) -> str:
    return "-" if x is None else f"{x:.2e}"


def table(results: list[Result]) -> str:
    """The results as a Markdown table, then the count of silent misses."""
    lines = ["| case | nodes (volume) | exit | verdict | at nodes | between | unmeasured faces | exact, measured "
             "faces | exact, all | limit | silent miss | s |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in results:
        verdict = r.state or {True: "met", False: "not met", None: "-"}[r.met]
        if r.measured is not None and r.measured < 0.995:
            verdict += f" ({100 * r.measured:.0f} % measured)"
        lines.append(f"| {r.case} | {r.nodes} ({r.volume_nodes}) | {r.exit_code} | {verdict} | "
                     f"{_mm(r.delta_nodes)} | {_mm(r.delta_between)} | "
                     f"{', '.join(map(str, r.unmeasured)) or '-'} | {_mm(r.exact_measured)} | "
                     f"{_mm(r.exact_max)} (face {r.exact_face}) | {r.limit:.2e} | "
                     f"{'**yes**' if r.silent_miss else 'no'} | {r.seconds:.0f} |")
    misses = sum(r.silent_miss for r in results)
    lines.append("")
    lines.append(f"{len(results)} cases, {sum(r.exit_code == 0 for r in results)} exit 0, "
                 f"{sum(r.exit_code == 5 for r in results)} exit 5, silent misses: {misses}")
    for r in results:
        if r.exit_code not in (0, 5):
            written = "" if not r.written else f" (written: {', '.join(r.written)})"
            lines.append(f"- {r.case} ({r.why}): exit {r.exit_code} after {r.seconds:.1f} s{written}: {r.message}")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", help="comma-separated case names (default: all): " + ", ".join(CASES))
    parser.add_argument("--jobs", type=int, default=2, help="cases run at once (default 2)")
    parser.add_argument("--timeout", type=float, default=900.0, help="seconds a case may take (default 900)")
    parser.add_argument("--json", type=Path, help="write the results here")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    parser.add_argument("--workdir", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        result = run_case(args.one, args.workdir)
        args.json.write_text(json.dumps(asdict(result)))
        return 0
    names = args.cases.split(",") if args.cases else list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        parser.error(f"unknown case(s) {', '.join(unknown)}: one of {', '.join(CASES)}")
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        results = list(pool.map(lambda n: run_child(n, args.timeout), names))
    print(table(results))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps([asdict(r) for r in results], indent=2) + "\n")
    return 1 if any(r.silent_miss for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
