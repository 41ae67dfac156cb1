"""Start-up cost of hot2cold: how long `import hot2cold`, `hot2cold --help` and the imports of a morph take.

    python benchmarks/startup.py [--repeat N] [--compare OTHER_CHECKOUT]

Each figure is the median wall time of N fresh interpreters (default 5).  With ``--compare`` the same
commands run, interleaved, against another checkout of hot2cold (e.g. a ``git worktree`` of an older
commit), and the ratios of the two are printed: both measured in the same run, on the same load.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "sample_parts"

#: What is timed: a name and the Python code run in a fresh interpreter.
CASES = {
    "import hot2cold": "import hot2cold",
    "hot2cold --help": "import sys; sys.argv = ['hot2cold', '--help']\n"
                       "from hot2cold.cli import main\n"
                       "try:\n    main(['--help'])\nexcept SystemExit:\n    pass",
    # (the old flat layout too, for --compare with a checkout from before the core/ and pipeline/ folders)
    "import the numeric core": "try:\n    import hot2cold.core.bspline, hot2cold.core.lstsq\n"
                               "except ImportError:\n    import hot2cold.bspline, hot2cold.lstsq",
    "import what a morph needs": "try:\n    import hot2cold.pipeline.morph\n"
                                 "except ImportError:\n    import hot2cold.morph",
    "morph the filleted block (CLI)": "from hot2cold.cli import main\n"
                                      f"main(['morph', {str(SAMPLES / 'filleted_block.step')!r}, "
                                      f"{str(SAMPLES / 'filleted_block_field.csv')!r}, '-o', OUT, '-q'])",
}


def _time(checkout: Path, code: str, out: Path) -> float:
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    start = time.perf_counter()
    subprocess.run([sys.executable, "-c", f"OUT = {str(out)!r}\n{code}"], env=env, cwd=checkout, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--compare", type=Path, help="another checkout of hot2cold to time beside this one")
    args = parser.parse_args()
    trees = {"this": ROOT} | ({"other": args.compare.resolve()} if args.compare else {})
    out = Path(os.environ.get("TMPDIR", "/tmp")) / f"hot2cold_startup_{os.getpid()}.step"
    print(f"median of {args.repeat} fresh interpreters, s" + (f" (other: {args.compare})" if args.compare else ""))
    header = f"{'':32}" + "".join(f"{name:>10}" for name in trees) + ("     ratio" if args.compare else "")
    print(header)
    for case, code in CASES.items():
        times = {name: [] for name in trees}
        for _ in range(args.repeat):
            for name, tree in trees.items():        # interleaved: both see the same load
                times[name].append(_time(tree, code, out))
        medians = {name: statistics.median(t) for name, t in times.items()}
        row = f"{case:32}" + "".join(f"{m:>10.2f}" for m in medians.values())
        if args.compare:
            row += f"{medians['other'] / medians['this']:>9.1f}x"
        print(row)
    out.unlink(missing_ok=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
