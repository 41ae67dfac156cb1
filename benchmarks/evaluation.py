"""Speed of the numeric core's surface evaluation: points, first and second derivatives and normals of a bicubic
B-spline surface, in ns a point, for a few dozen points (a face's edge samples: the calls' fixed cost) up to
hundreds of thousands (Newton's foot points of a large face).

    python benchmarks/evaluation.py [--compare OTHER_CHECKOUT] [--repeat N]

Each figure is the best of N timings (default 7).  With ``--compare`` the same calls run, interleaved, on the
``hot2cold.core.bspline`` of another checkout (e.g. a ``git worktree`` of an older commit), their ratios are
printed, and every array the two give is compared: a change that is meant to be a faster route to the same
numbers says so with ``same to the bit: yes``.
"""
from __future__ import annotations

import argparse
import importlib.util
import sys
import timeit
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

#: Points per call.
SIZES = (10, 60, 600, 16_384, 200_000)
#: The evaluations timed (functions of ``hot2cold.core.bspline`` taking ``(surface, u, v)``).
CALLS = ("evaluate_surface", "surface_first_jet", "surface_jet", "surface_normals")


def _bspline_of(checkout: Path):
    """``hot2cold.core.bspline`` of another checkout, loaded under its own name beside this one's."""
    name = "other_hot2cold"
    spec = importlib.util.spec_from_file_location(name, checkout / "hot2cold" / "__init__.py",
                                                  submodule_search_locations=[str(checkout / "hot2cold")])
    package = importlib.util.module_from_spec(spec)
    sys.modules[name] = package
    spec.loader.exec_module(package)
    return importlib.import_module(f"{name}.core.bspline")


def _surface(module, rng: np.random.Generator):
    """A bicubic surface of 13 x 13 poles on a knot vector of 10 inner knots."""
    knots = np.r_[[0.0] * 4, np.linspace(0.0, 1.0, 12)[1:-1], [1.0] * 4]
    poles = rng.random((len(knots) - 4, len(knots) - 4, 3))
    return module.BSplineSurface(poles=poles, u_knots=knots, v_knots=knots, u_degree=3, v_degree=3)


def _best(fn, number: int, repeat: int) -> float:
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--compare", type=Path, help="another checkout of hot2cold to time against")
    parser.add_argument("--repeat", type=int, default=7, help="timings per figure (the best is printed)")
    args = parser.parse_args(argv)
    from hot2cold.core import bspline

    other = _bspline_of(args.compare.resolve()) if args.compare else None
    header = f"{'call':20s} {'points':>8s} {'ns/point':>10s}"
    if other is not None:
        header += f" {'other':>10s} {'ratio':>6s} same to the bit"
    print(header)
    for size in SIZES:
        rng = np.random.default_rng(size)
        surface = _surface(bspline, rng)
        other_surface = None if other is None else _surface(other, np.random.default_rng(size))
        u, v = rng.random(size), rng.random(size)
        number = max(1, 20_000 // size)
        for call in CALLS:
            ours = getattr(bspline, call)
            line = f"{call:20s} {size:8d}"
            if other is None:
                line += f" {_best(lambda: ours(surface, u, v), number, args.repeat) / size * 1e9:10.1f}"
            else:
                theirs = getattr(other, call)
                times = [[], []]
                for _ in range(args.repeat):     # interleaved: both on the same load
                    times[0].append(_best(lambda: ours(surface, u, v), number, 1))
                    times[1].append(_best(lambda: theirs(other_surface, u, v), number, 1))
                a, b = (min(t) for t in times)
                got, expected = ours(surface, u, v), theirs(other_surface, u, v)
                got = got if isinstance(got, tuple) else (got,)
                expected = expected if isinstance(expected, tuple) else (expected,)
                same = all(np.array_equal(x, y, equal_nan=True) for x, y in zip(got, expected))
                line += f" {a / size * 1e9:10.1f} {b / size * 1e9:10.1f} {a / b:6.2f} {'yes' if same else 'NO'}"
            print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
