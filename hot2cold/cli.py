"""The ``hot2cold`` command line.  The only module that talks to the terminal.

    hot2cold morph HOT.step FIELD.csv -o COLD.step --report REPORT.json

Exit codes: 0 success; 2 unusable input (file, field, option); 3 kernel failure; 4 the cold part is not a
valid closed solid (nothing written); 5 written, but --tolerance not met; 70 internal error; 130
interrupted.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import tempfile
from pathlib import Path

from . import __version__
from .errors import Hot2ColdError, InputError
from .field import UNITS

log = logging.getLogger("hot2cold")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="hot2cold", description="Hot-to-cold B-spline morphing of CAD solids "
                                     "from an FE displacement field (GT2014-26683).")
    parser.add_argument("--version", action="version", version=f"hot2cold {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    m = sub.add_parser("morph", help="morph a hot STEP solid into a cold one",
                       description="Morph HOT (STEP) with the displacement field FIELD into the cold part.")
    m.add_argument("hot", type=Path, help="hot part, STEP file with one or more solids")
    m.add_argument("field", type=Path, help="FE field: CSV/TXT with columns x,y,z,dx,dy,dz (hot positions, "
                   "hot-to-cold displacements), or .npz with arrays points and displacements")
    m.add_argument("-o", "--output", type=Path, required=True, help="cold part, STEP file to write")
    m.add_argument("--report", type=Path, help="write the accuracy report as JSON here")
    m.add_argument("--field-units", choices=sorted(UNITS), default="mm",
                   help="length unit of the field file (default mm)")
    m.add_argument("--field-name", metavar="NAME",
                   help="displacement point field in a VTK/VTU file (default: U, displacement or DISP)")
    m.add_argument("--invert", action="store_true",
                   help="the field goes cold to hot (at the hot mesh's nodes): invert it by fixed-point iteration")
    m.add_argument("--tolerance", type=float, metavar="MM",
                   help="largest accepted error: faces that miss it are refined by knot insertion; exit code 5 "
                   "when it still is not met")
    m.add_argument("--node-distance", type=float, metavar="MM",
                   help="nodes farther than this from every face are ignored (default 0.1%% of the part size)")
    m.add_argument("--edge-distance", type=float, metavar="MM",
                   help="nodes this close to an edge feed the edge (default 0.01%% of the part size)")
    m.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    m.add_argument("-v", "--verbose", action="store_true", help="log each step")
    return parser


class _Progress:
    """Stage-by-stage progress on stderr (a single rewritten line on a terminal)."""

    def __init__(self, stream):
        self.stream = stream
        self.tty = stream.isatty()

    def __call__(self, stage: str, done: int, total: int) -> None:
        text = f"{stage}: {done}/{total}" if total > 1 else f"{stage}: done"
        if self.tty:
            self.stream.write(f"\r\033[K{text}")
            if stage == "report":
                self.stream.write("\n")
        elif total == 1 or done == total:
            self.stream.write(text + "\n")
        self.stream.flush()


def _check_output(hot: Path, output: Path, what: str) -> None:
    if output.exists() and hot.exists() and output.resolve() == hot.resolve():
        raise InputError(f"{what} {output} is the input file: choose another name")
    folder = output.parent if str(output.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"folder for {what} {output} does not exist: create it first")
    if not os.access(folder, os.W_OK):
        raise InputError(f"folder for {what} {output} is not writable")


def _write_json_atomically(data: dict, path: Path) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent if str(path.parent) else ".")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(data, fh, indent=2)
            fh.write("\n")
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _morph(args) -> int:
    from .morph import check_result, morph
    from .settings import Settings

    _check_output(args.hot, args.output, "output")
    if args.report:
        _check_output(args.hot, args.report, "report")
    try:
        settings = Settings(node_distance=args.node_distance, edge_distance=args.edge_distance,
                            tolerance=args.tolerance)
    except ValueError as exc:
        raise InputError(str(exc)) from exc
    progress = None if args.quiet else _Progress(sys.stderr)
    result = morph(args.hot, args.field, settings, units=args.field_units, field_name=args.field_name,
                   invert=args.invert, progress=progress)
    if not args.quiet:
        print(result.report.table())
    if args.report:
        _write_json_atomically(result.report.to_dict(), args.report)
    check_result(result)
    result.write_step(args.output)
    if not args.quiet:
        print(f"wrote {args.output}")
    if result.report.tolerance_met is False:
        print(f"hot2cold: tolerance {args.tolerance} mm not met (Δmax {result.report.delta_max:.3g} mm); "
              f"the cold part is written", file=sys.stderr)
        return 5
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``hot2cold`` console script; returns the exit code."""
    args = _parser().parse_args(argv)
    level = logging.INFO if args.verbose else logging.WARNING
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)
    try:
        return _morph(args)
    except Hot2ColdError as exc:
        print(f"hot2cold: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("hot2cold: interrupted; nothing written", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug: one line, the traceback only with -v
        if args.verbose:
            log.exception("internal error")
        print(f"hot2cold: internal error: {type(exc).__name__}: {exc} (run with -v for the traceback)",
              file=sys.stderr)
        return 70


if __name__ == "__main__":
    sys.exit(main())
