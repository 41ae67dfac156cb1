"""The ``hot2cold`` command line.  The only module that talks to the terminal.

    hot2cold morph HOT.step FIELD.csv -o COLD.step --report REPORT.json [--vtu NODES.vtu] [--stl COLD.stl]
        [--glb COLD.glb] [--html REPORT.html [--scale FACTOR]] [-q | -v]
    hot2cold batch JOBS.csv|JOBS.toml [--workers N | --scheduler ADDRESS] [--force] [--summary PATH] [-q | -v]

Every output is checked before the morph starts (its folder exists and is writable, it is neither input
nor another output) and written whole or not at all.

Exit codes: 0 success; 2 unusable input (file, field, option, output path; docs/guide/bad_input.md lists them);
3 kernel failure; 4 the cold part is not a valid closed solid, or it folds or crosses itself, or its STEP file
does not read back as the valid closed solids written (nothing written but the report); 5 written, but
--tolerance not met (the report written too, beside the STEP as COLD.report.json when --report was not
given); 6 an output could not be written (none of it is left; the message says what else is written); 70
internal error; 130 interrupted.

Exit codes of batch: 0 every job ok or skipped (done before from the same inputs); 1 a job failed (the
others ran; the summary says why); 5 none failed but a job missed its --tolerance; 2 unusable jobs file
or options (one line, nothing run: a missing column, an unknown option, a bad value, an output twice or
equal to an input, no folder for an output, --scheduler without the package distributed or out of
reach); 130 interrupted (the summary lists what was done).
"""
from __future__ import annotations

import argparse
import logging
import math
import os
import sys
import time
from pathlib import Path

from .. import __version__
from ..errors import Hot2ColdError, InputError, OutputError, StepReadError
from ..io.field import FIELD_FORMATS
from ..io.inputs import check_input_file
from .options import MorphOptions, in_words

log = logging.getLogger("hot2cold")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="hot2cold", description="Hot-to-cold B-spline morphing of CAD solids "
                                     "from an FE displacement field (GT2014-26683).")
    parser.add_argument("--version", action="version", version=f"hot2cold {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    m = sub.add_parser("morph", help="morph a hot STEP solid into a cold one",
                       description="Morph HOT (STEP) with the displacement field FIELD into the cold part.")
    m.add_argument("hot", type=Path, help="hot part, STEP file with one or more solids")
    m.add_argument("field", type=Path, help="FE field, hot positions and hot-to-cold displacements at the nodes: "
                   + "; ".join(FIELD_FORMATS))
    outputs = m.add_argument_group("outputs")
    outputs.add_argument("-o", "--output", type=Path, required=True, help="cold part, STEP file to write")
    outputs.add_argument("--report", type=Path, help="write the accuracy report as JSON here")
    MorphOptions.add_arguments(m)
    views = m.add_argument_group("viewer exports (written after the cold STEP)")
    views.add_argument("--vtu", type=Path, metavar="NODES.vtu",
                       help="for ParaView: two files, NODES.vtu = the FE nodes at their hot positions with point "
                       "data displacement (hot to cold, mm), error (mm, NaN where ignored), role (-1 ignored, 0 "
                       "face, 1 edge, 2 vertex) and owner (its face/edge/vertex), and NODES_surface.vtu = the "
                       "cold surface as triangles with cell data face and point data displacement (hot to cold) "
                       "and uv. Two files, not two cell blocks of one, because VTU point data covers every "
                       "point of a file: the nodes' error would otherwise paint the surface NaN. Warp By Vector "
                       "(displacement) takes the nodes onto the cold surface")
    views.add_argument("--stl", type=Path, metavar="PATH", help="the cold part as a binary STL (mm)")
    views.add_argument("--glb", type=Path, metavar="PATH",
                       help="the cold part as binary glTF (metres, Y up, as glTF viewers expect)")
    views.add_argument("--html", type=Path, metavar="PATH", help="a self-contained HTML report with pictures")
    views.add_argument("--scale", type=float, metavar="FACTOR",
                       help="displacement magnification of the --html pictures (default: chosen by the report)")
    said = m.add_argument_group("messages")
    said.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    said.add_argument("-v", "--verbose", action="store_true", help="log each step")
    b = sub.add_parser("batch", help="morph the jobs of a CSV or TOML jobs file, in parallel",
                       description="Run the morphs listed in JOBS (CSV: a header hot,field,output[,options] and a "
                       "row per job; TOML: [[jobs]] tables and an optional [defaults] table). Options as for "
                       f"morph: {', '.join(('name', 'report') + MorphOptions.names())}. Relative paths are "
                       "relative to JOBS' folder. A job whose cold STEP and record (OUTPUT.hot2cold.json) show "
                       "the same inputs is skipped. Exit code "
                       "0: all ok or skipped; 1: a job failed; 5: a tolerance missed; 2: unusable JOBS.")
    b.add_argument("jobs", type=Path, metavar="JOBS", help="jobs file, .csv or .toml")
    where = b.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="local worker processes (default: one per core)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run the jobs on this Dask distributed scheduler (e.g. tcp://10.0.0.5:8786; needs the "
                       "package distributed and the same paths on its workers)")
    b.add_argument("--force", action="store_true", help="run every job, also those done before")
    b.add_argument("--summary", type=Path, metavar="PATH",
                   help="summary JSON (default: JOBS_summary.json beside JOBS)")
    b.add_argument("-q", "--quiet", action="store_true", help="no progress and no table; only errors")
    b.add_argument("-v", "--verbose", action="store_true", help="log each step")
    return parser


class _Progress:
    """Stage-by-stage progress on stderr: when a stage begins, its count as it goes (at each tenth) and its
    time when it ends.  A terminal gets one rewritten line; a pipe a line for each."""

    def __init__(self, stream, clock=time.perf_counter):
        self.stream = stream
        self.tty = stream.isatty()
        self.clock = clock
        self.started: dict[str, float] = {}
        self.shown: tuple[str, int] = ("", 0)

    def __call__(self, stage: str, done: int, total: int) -> None:
        now = self.clock()
        if done <= 0:
            self.started[stage] = now
            self.shown = (stage, 0)
            self._write(f"{stage} ...")
            return
        spent = now - self.started.get(stage, now)
        if done >= total:
            count = f"{total}/{total} " if total > 1 else ""
            self._write(f"{stage}: {count}done in {spent:.1f} s", final=stage == "report")
            return
        tenth = done * 10 // total
        if (stage, tenth) != self.shown:
            self.shown = (stage, tenth)
            self._write(f"{stage}: {done}/{total}")

    def _write(self, text: str, final: bool = False) -> None:
        if self.tty:
            self.stream.write(f"\r\033[K{text}" + ("\n" if final else ""))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()


class _BatchProgress:
    """Jobs done of total on stderr: one rewritten line on a terminal, a line per job otherwise."""

    def __init__(self, stream, total: int):
        self.stream, self.total, self.done, self.failed = stream, total, 0, 0
        self.tty = stream.isatty()
        stream.write(f"batch: 0/{total} jobs done" + ("" if self.tty else "\n"))
        stream.flush()

    def __call__(self, result: dict) -> None:
        self.done += 1
        self.failed += result["status"] == "failed"
        if self.tty:
            failed = f" ({self.failed} failed)" if self.failed else ""
            self.stream.write(f"\r\033[Kbatch: {self.done}/{self.total} jobs done{failed}, last {result['name']}: "
                              f"{result['status']}" + ("\n" if self.done == self.total else ""))
        else:
            self.stream.write(f"batch: {self.done}/{self.total} {result['name']}: {result['status']} "
                              f"({result['seconds']:.1f} s)\n")
        self.stream.flush()


def _check_output(inputs, output: Path, what: str) -> None:
    """Refuse ``output`` before the long run: it is one of ``inputs`` (a path or paths), or its folder is
    missing or not writable."""
    for given in [inputs] if isinstance(inputs, (str, os.PathLike)) else inputs:
        if given is not None and output.exists() and Path(given).exists() and \
                output.resolve() == Path(given).resolve():
            raise InputError(f"{what} {output} is the input file: choose another name")
    folder = output.parent if str(output.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"folder for {what} {output} does not exist: create it first")
    if not os.access(folder, os.W_OK):
        raise InputError(f"folder for {what} {output} is not writable: choose another folder or fix its permissions")
    if output.is_dir():
        raise InputError(f"{what} {output} is a folder: give a file name")


def _outputs(args) -> list[tuple[str, Path]]:
    """Every file the run will write, as (what, path)."""
    from .run import VIEWS, view_outputs

    out = [("output", args.output)]
    if args.report:
        out.append(("report", args.report))
    return out + [(f"--{what}", path) for what, path in view_outputs({w: getattr(args, w) for w in VIEWS})]


def _check_outputs(args) -> None:
    seen: dict[Path, str] = {}
    for what, path in _outputs(args):
        _check_output((args.hot, args.field), path, what)
        key = path.resolve()
        if key in seen:
            raise InputError(f"{what} and {seen[key]} are the same file {path}: choose another name")
        seen[key] = what


def _check_options(args) -> None:
    if args.scale is not None:
        if not args.html:
            raise InputError("--scale magnifies the --html pictures: give --html too")
        if not (math.isfinite(args.scale) and args.scale > 0):
            raise InputError(f"--scale must be a positive number, got {args.scale}")


def _html_writer():
    """``write_html`` of :mod:`hot2cold.views.page`, or an :class:`InputError` if it cannot be imported."""
    try:
        from ..views.page import write_html
    except ImportError as exc:
        raise InputError(f"--html is not available in this installation: {exc}") from exc
    return write_html


def _write_exports(args, result):
    """Write the viewer exports asked for, yielding each path as soon as it is written."""
    from .run import VIEWS, write_views

    if args.html and not args.quiet:       # the page takes seconds: say so
        print(f"writing {args.html} ...", file=sys.stderr, flush=True)
    yield from write_views(result, {what: getattr(args, what) for what in VIEWS}, scale=args.scale)


def _morph(args) -> int:
    from threadpoolctl import threadpool_limits

    from .batch import cores
    from .run import run_morph, tolerance_missed, write_cold, write_json

    check_input_file(args.hot, "STEP file")            # refused before anything is loaded
    check_input_file(args.field, "field file")
    if args.field_points is not None:
        check_input_file(args.field_points, "field points file")
    _check_outputs(args)
    _check_options(args)
    if args.html:
        _html_writer()
    progress = None if args.quiet else _Progress(sys.stderr)
    try:
        with threadpool_limits(1, "blas"):  # this process's BLAS: the small fits gain nothing from threads,
            # but the faces do, side by side (Settings.threads)
            result = run_morph(args.hot, args.field, MorphOptions.from_args(args), progress, threads=cores())
    except StepReadError as exc:
        raise _no_solid(args.hot, exc) from exc
    if not args.quiet:
        _say(in_words(result.report.table()))     # the verdict its first line
    missed = tolerance_missed(result)
    written = args.written = []         # for the messages of a failure or an interruption from here on
    what = {path: name for name, path in _outputs(args)}
    try:
        for path in write_cold(result, args.output, args.report):   # report, check, STEP; atomic each
            written.append(path)
            if not args.quiet:
                _say(_wrote(path, what.get(path, "")))
        if missed and args.report is None:  # a part written off its tolerance is not left without its verdict
            args.report = Path(args.output).with_suffix(".report.json")
            write_json(result.report.to_dict(), args.report)
            written.append(args.report)
            if not args.quiet:
                _say(_wrote(args.report, "report"))
        for path in _write_exports(args, result):
            written.append(path)
            if not args.quiet:
                _say(_wrote(path, what.get(path, "")))
    except OutputError as exc:
        raise OutputError(f"{exc} ({', '.join(map(str, written)) or 'nothing'} written)") from exc
    if missed:
        print(f"hot2cold: {missed}; the verdict and every figure: {args.report}", file=sys.stderr)
        return 5
    return 0


#: What each file ``hot2cold morph`` writes is, by the name :func:`_outputs` gives it.
_WHAT = {"output": "the cold part (STEP; read back and checked as valid closed solids)",
         "report": "the report (JSON; the verdict first, then every figure printed above)",
         "--html": "the report page (HTML, the verdict first, a 3D view; opens in a browser, offline)",
         "--vtu": "the FE nodes with their displacement, error and role (VTU, for ParaView)",
         "--vtu surface": "the cold surface with its displacement (VTU, for ParaView)",
         "--stl": "the cold part as triangles (binary STL, mm)",
         "--glb": "the cold part for glTF viewers (binary glTF, metres, Y up)"}


def _say(text: str) -> None:
    """Print ``text`` on stdout.  A reader that stops reading (``hot2cold morph ... | head -1``) stops the
    printing, not the work: stdout then goes to the null device, and the files are written as without it."""
    try:
        print(text, flush=True)
    except BrokenPipeError:
        try:
            quiet = os.open(os.devnull, os.O_WRONLY)
            os.dup2(quiet, sys.stdout.fileno())    # also the interpreter's last flush at exit finds no pipe
            os.close(quiet)
        except (OSError, ValueError):             # a stdout without a file descriptor: nothing to redirect
            pass


def _wrote(path: Path, what: str) -> str:
    """The line naming a file written and what it is."""
    return f"wrote {path}: {_WHAT[what]}" if what in _WHAT else f"wrote {path}"


def _no_solid(path: Path, exc: StepReadError) -> StepReadError:
    """``exc``, or where the STEP file holds shells or faces but no solid, an error that says what it holds."""
    if "no solid" not in str(exc):     # read_step's words for a file it read that holds no solid
        return exc
    from ..kernel.validity import step_content

    content = step_content(path)
    if content is None:
        return exc
    todo = ("make a solid of it" if content.endswith(", closed") else
            "close it (sew it, add the missing faces) and make a solid of it")
    return StepReadError(f"STEP file {path} holds no solid, only {content}: hot2cold morphs closed solids; "
                         f"{todo} in CAD")


def _batch(args) -> int:
    from . import batch
    from .run import write_json

    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be at least 1, got {args.workers}")
    summary = args.summary or args.jobs.with_name(f"{args.jobs.stem}_summary.json")
    jobs = batch.read_jobs(args.jobs, summary)
    backend = {"scheduler": args.scheduler} if args.scheduler else \
        {"workers": min(args.workers or batch.cores(), len(jobs))}
    results, start = [], time.perf_counter()
    running = batch.run_jobs(jobs, workers=args.workers, scheduler=args.scheduler, force=args.force)
    progress = None if args.quiet else _BatchProgress(sys.stderr, len(jobs))

    def write_summary() -> dict:
        data = batch.summary(args.jobs, jobs, results, **backend, force=args.force,
                             wall_seconds=round(time.perf_counter() - start, 2))
        write_json(data, summary)
        return data

    try:
        for result in running:
            results.append(result)
            for line in result.get("warnings", []):
                log.warning("job %s: %s", result["name"], line)
            if progress:
                progress(result)
    except KeyboardInterrupt:
        write_summary()                 # the jobs done so far, the others "not-run"
        args.written = [summary]
        raise
    data = write_summary()
    if args.quiet:
        for r in data["jobs"]:
            if r["status"] == "failed":
                print(f"hot2cold: job {r['name']} failed: {r['message']}", file=sys.stderr)
    else:
        _say(batch.summary_table(data))
        _say(f"wrote {summary}")
    return data["exit_code"]


class _InWords(logging.Formatter):
    """The log lines of a run, the options they name in the command line's words (:func:`.options.in_words`)."""

    def format(self, record: logging.LogRecord) -> str:
        return in_words(super().format(record))


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``hot2cold`` console script; returns the exit code."""
    args = _parser().parse_args(argv)
    # hot2cold's log records go to this run's stderr: -q errors only, default warnings too, -v every step.
    # The handler is hot2cold's own, for this call only; the root logger is left to the application.
    level = logging.ERROR if args.quiet else logging.INFO if args.verbose else logging.WARNING
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_InWords("%(levelname)s %(name)s: %(message)s"))
    handler.setLevel(level)
    saved = log.level
    log.addHandler(handler)
    log.setLevel(level)
    try:
        return _run(args)
    finally:
        log.removeHandler(handler)
        log.setLevel(saved)


def _run(args) -> int:
    try:
        return _batch(args) if args.command == "batch" else _morph(args)
    except Hot2ColdError as exc:
        print(f"hot2cold: error: {in_words(str(exc))}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        written = getattr(args, "written", [])
        print(f"hot2cold: interrupted; {', '.join(map(str, written)) or 'nothing'} written", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug: one line, the traceback only with -v
        if args.verbose:
            log.exception("internal error")
        print(f"hot2cold: internal error: {type(exc).__name__}: {exc} (run with -v for the traceback)",
              file=sys.stderr)
        return 70


if __name__ == "__main__":
    sys.exit(main())
