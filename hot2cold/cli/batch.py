"""Many morphs from one jobs file: a compressor map's operating points, one cold part each.

A jobs file is CSV (a header, then one row per job) or TOML (``[[jobs]]`` tables and an optional
``[defaults]`` table that every job starts from).  Each job names ``hot`` (STEP), ``field`` and ``output``
(the cold STEP), and may give a ``report`` (JSON), viewer files (``vtu``, ``stl``, ``glb``, ``html``, as
``hot2cold morph``'s flags of those names), a ``name`` for the summary (default: the output path as written)
and the options of ``hot2cold morph`` (:class:`~hot2cold.cli.options.MorphOptions`:
``field_units``, ``tolerance``...).  Relative paths are relative to the jobs file's folder; option names
may be written with ``-`` or ``_``.

:func:`read_jobs` checks the whole file before anything runs; :func:`run_jobs` runs the jobs in a local
process pool or on a Dask cluster and yields one result dict per job (:func:`run_job` is what a worker
runs: the morph, report, check and cold STEP of :mod:`hot2cold.cli.run`, as ``hot2cold morph``).  A job
whose cold STEP exists with a record beside it (``<output>.hot2cold.json``, written after the STEP) stating
the same inputs (SHA-256 of the hot STEP and the field, the options, the hot2cold version) and the same
outputs (size and SHA-256 of the STEP, the report and the viewer files) is skipped.

Library code: nothing here prints; it logs and raises :class:`~hot2cold.errors.Hot2ColdError`.
"""
from __future__ import annotations

import csv
import hashlib
import json
import logging
import multiprocessing
import os
import socket
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from .. import __version__
from ..errors import Hot2ColdError, InputError, one_line
from ..io.inputs import check_input_file
from .options import MorphOptions, in_words, to_path, to_text
from .run import VIEWS, run_morph, tolerance_missed, view_outputs, write_cold, write_json, write_views
from .workers import one_thread_each

log = logging.getLogger(__name__)

#: Columns (CSV) or keys (TOML) every job has.
REQUIRED = ("hot", "field", "output")

#: What a job's result ``status`` can be; "not-run" only in the summary of an interrupted batch.
STATUSES = ("ok", "tolerance-missed", "failed", "skipped", "not-run")

#: Exit code recorded for a job whose worker process died (a crash in the kernel, the memory killer).
DIED = 70

#: A job's record of what it was made from, beside its cold STEP.
RECORD_SUFFIX = ".hot2cold.json"


@dataclass(frozen=True)
class Job:
    """One morph of a batch: absolute paths and the options of ``hot2cold morph``."""

    name: str
    hot: Path
    field: Path
    output: Path
    report: Path | None = None
    options: MorphOptions = MorphOptions()
    vtu: Path | None = None
    stl: Path | None = None
    glb: Path | None = None
    html: Path | None = None

    @property
    def record(self) -> Path:
        """The record written after the cold STEP: the inputs and outputs of the run that made it."""
        return self.output.with_name(self.output.name + RECORD_SUFFIX)

    def views(self) -> dict[str, Path | None]:
        """The viewer files asked for (``hot2cold morph``'s ``--vtu``, ``--stl``, ``--glb``, ``--html``)."""
        return {what: getattr(self, what) for what in VIEWS}

    def outputs(self) -> list[tuple[str, Path]]:
        """The files the job writes, as (what, path); the record comes last, as it is written last."""
        out = [("output", self.output)] + ([("report", self.report)] if self.report else [])
        return out + view_outputs(self.views()) + [("record", self.record)]

    def inputs(self) -> list[tuple[str, Path]]:
        """The files the job reads, as (what, path): the hot STEP, the field and where given the field's
        node positions (``--field-points``)."""
        points = self.options.field_points
        return [("hot", self.hot), ("field", self.field)] + ([("field_points", Path(points))] if points else [])


#: A job's own columns (CSV) or keys (TOML), before the morph options.
JOB_KEYS = ("name", "hot", "field", "output", "report", *VIEWS)

#: Every column or key a job may have, in the order the messages list them.
OPTIONS = JOB_KEYS + MorphOptions.names()


# --------------------------------------------------------------------------------------------------------
# The jobs file
# --------------------------------------------------------------------------------------------------------
def read_jobs(path: str | os.PathLike, summary: str | os.PathLike | None = None) -> list[Job]:
    """The jobs of a CSV or TOML jobs file, checked as a whole: required columns, known options, valid
    values, unique names, no output twice, no output equal to an input (or to ``summary``), every output
    folder present.  Raises :class:`InputError` with one line (where in the file, what is wrong)."""
    path = check_input_file(path, "jobs file", InputError)
    kind = path.suffix.lower()
    if kind == ".toml":
        rows = _toml_rows(path)
    elif kind in (".csv", ".txt"):
        rows = _csv_rows(path)
    else:
        raise InputError(f"jobs file {path}: give a .csv or a .toml file")
    if not rows:
        raise InputError(f"jobs file {path} lists no job")
    folder = Path(os.path.abspath(path.parent))
    jobs = [_job(where, row, folder) for where, row in rows]
    _check_jobs(path, [where for where, _ in rows], jobs, summary)
    log.info("%s: %d jobs", path, len(jobs))
    return jobs


def _key(name: str) -> str:
    return name.strip().lower().replace("-", "_")


def _check_keys(where: str, keys, what: str) -> None:
    unknown = [k for k in keys if k not in OPTIONS]
    if unknown:
        raise InputError(f"{where}: unknown {what} {unknown[0]!r} (known: {', '.join(OPTIONS)})")
    missing = [k for k in REQUIRED if k not in keys]
    if missing:
        raise InputError(f"{where}: missing {what} {missing[0]!r} (every job needs {', '.join(REQUIRED)})")


def _csv_rows(path: Path) -> list[tuple[str, dict]]:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read jobs file {path}: {exc}") from exc
    lines = [(n, line) for n, line in enumerate(text.splitlines(), 1)
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise InputError(f"jobs file {path} is empty: it needs a header ({', '.join(REQUIRED)}, options) "
                         f"and a row per job")
    first = lines[0][1]
    delimiter = ";" if ";" in first and "," not in first else ","
    table = list(csv.reader([line for _, line in lines], delimiter=delimiter, skipinitialspace=True))
    header = [_key(h) for h in table[0]]
    _check_keys(f"{path} header (line {lines[0][0]})", header, "column")
    if len(set(header)) < len(header):
        twice = next(h for h in header if header.count(h) > 1)
        raise InputError(f"{path} header (line {lines[0][0]}): column {twice!r} appears twice")
    rows = []
    for (n, _), cells in zip(lines[1:], table[1:]):
        where = f"{path} line {n}"
        if len(cells) > len(header):
            raise InputError(f"{where}: {len(cells)} cells but {len(header)} columns")
        rows.append((where, dict(zip(header, cells))))
    return rows


def _toml_rows(path: Path) -> list[tuple[str, dict]]:
    try:
        import tomllib
    except ImportError:  # Python 3.10
        try:
            import tomli as tomllib
        except ImportError:
            raise InputError(f"jobs file {path}: reading TOML needs Python 3.11 or the package tomli "
                             f"(pip install tomli); or give the jobs as CSV") from None
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as exc:
        raise InputError(f"cannot read jobs file {path}: {exc}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"jobs file {path} is not valid TOML: {exc}") from exc
    extra = sorted(set(data) - {"defaults", "jobs"})
    if extra:
        raise InputError(f"{path}: unknown table {extra[0]!r} (a jobs file has [defaults] and [[jobs]])")
    defaults, jobs = data.get("defaults", {}), data.get("jobs", [])
    if not isinstance(defaults, dict) or not isinstance(jobs, list) or not all(isinstance(j, dict) for j in jobs):
        raise InputError(f"{path}: write the jobs as [[jobs]] tables and the defaults as one [defaults] table")
    defaults = {_key(k): v for k, v in defaults.items()}
    _check_keys(f"{path} [defaults]", list(defaults) + list(REQUIRED), "option")
    rows = []
    for n, job in enumerate(jobs, 1):
        where = f"{path} job {n}"
        row = {**defaults, **{_key(k): v for k, v in job.items()}}
        _check_keys(where, row, "option")
        rows.append((where, row))
    return rows


def _job(where: str, row: dict, folder: Path) -> Job:
    """A :class:`Job` from one row of strings (CSV) or TOML values; :class:`InputError` naming ``where``."""
    values = {}
    try:
        for key, value in row.items():
            if value is None or (isinstance(value, str) and not value.strip()):
                continue
            try:
                values[key] = _CONVERT[key](value.strip() if isinstance(value, str) else value, folder)
            except ValueError as exc:
                raise ValueError(f"{key} {exc}") from None
        for key in REQUIRED:
            if key not in values:
                raise ValueError(f"no {key} given")
        options = MorphOptions(**{k: v for k, v in values.items() if k not in JOB_KEYS})
        options.to_settings()           # a bad value is refused here, with the file's line
        own = {k: v for k, v in values.items() if k in JOB_KEYS}
        job = Job(**{"name": str(row["output"]).strip(), **own}, options=options)
    except (ValueError, TypeError) as exc:  # InputError is a ValueError
        raise InputError(f"{where}: {exc}") from None
    return job


#: The converter of each column or key: a CSV cell (stripped text) or a TOML value -> the job's value.
_CONVERT: dict[str, Callable] = {"name": to_text, "hot": to_path, "field": to_path, "output": to_path,
                                 "report": to_path, **{what: to_path for what in VIEWS},
                                 **{name: opt.convert for name, opt in MorphOptions.table().items()}}


#: How each input of a job is named in messages (:func:`~hot2cold.io.inputs.check_input_file`'s words).
_INPUT_WORDS = {"hot": "STEP file", "field": "field file", "field_points": "field points file"}


def _check_jobs(path: Path, wheres: list[str], jobs: list[Job], summary) -> None:
    """Unique names; every file written by one job only and read by none; output folders present."""
    inputs = {path.resolve(): f"{path} (the jobs file)"}
    for where, job in zip(wheres, jobs):
        for what, given in job.inputs():
            try:
                check_input_file(given, _INPUT_WORDS[what])
            except InputError as exc:
                raise InputError(f"{where}: {exc}") from None
            inputs.setdefault(given.resolve(), f"the {what} of {where}")
    written: dict[Path, str] = {}
    extra = [("--summary", None, Path(summary))] if summary is not None else []
    for where, what, out in [(w, what, p) for w, job in zip(wheres, jobs) for what, p in job.outputs()] + extra:
        place = f"{where}: {what}" if where else what
        key = out.resolve()
        if key in inputs:
            raise InputError(f"{place} {out} is {inputs[key]}: an output must not overwrite an input")
        if key in written:
            raise InputError(f"{place} {out} is also {written[key]}: every output needs its own path")
        written[key] = f"the {what} of {where}" if where else what
        folder = out.parent
        if not folder.is_dir():
            raise InputError(f"{place}: folder {folder} does not exist: create it first")
        if out.is_dir():
            raise InputError(f"{place} {out} is a folder: give a file name")
    names: dict[str, str] = {}
    for where, job in zip(wheres, jobs):
        if job.name in names:
            raise InputError(f"{where}: job name {job.name!r} is also the name of {names[job.name]}")
        names[job.name] = where


# --------------------------------------------------------------------------------------------------------
# What a run was made from: skip what is done
# --------------------------------------------------------------------------------------------------------
def _digest(path: Path, cache: dict | None = None) -> dict:
    """Size and SHA-256 of a file (``cache``: by path, size and mtime, for the files many jobs share)."""
    st = os.stat(path)
    key = (str(path), st.st_size, st.st_mtime_ns)
    if cache is not None and key in cache:
        return cache[key]
    sha = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            sha.update(block)
    out = {"size": st.st_size, "sha256": sha.hexdigest()}
    if cache is not None:
        cache[key] = out
    return out


def fingerprint(job: Job, cache: dict | None = None) -> dict:
    """What the job's cold part depends on: the contents of its inputs, its options, the hot2cold version.
    Paths are not part of it (a moved project folder keeps its runs).  Raises OSError for a missing input."""
    options = {k: v for k, v in job.options.as_dict().items() if k != "field_points"}   # a path: its content
    return {"hot2cold": __version__, **{what: _digest(given, cache) for what, given in job.inputs()},  # is here
            "options": options, "report": job.report is not None}


def done_before(job: Job, cache: dict | None = None) -> dict | None:
    """The job's record if its outputs are there, whole, and made from the same inputs; else None."""
    try:
        record = json.loads(job.record.read_text(encoding="utf-8"))
        if record.get("inputs") != fingerprint(job, cache):
            return None
        made = record.get("outputs", {})
        for what, path in job.outputs()[:-1]:
            if made.get(what) != _digest(path, cache):
                return None
        return record if record.get("status") in ("ok", "tolerance-missed") else None
    except (OSError, ValueError, AttributeError):
        return None


# --------------------------------------------------------------------------------------------------------
# Running
# --------------------------------------------------------------------------------------------------------
def _result(job: Job, status: str, exit_code: int | None, message: str = "", delta_max: float | None = None,
            seconds: float = 0.0, verdict: str | None = None, verdict_text: str | None = None, **more) -> dict:
    """A job's result: ``verdict`` is its report's verdict state (:class:`~hot2cold.pipeline.report.VerdictState`'s
    value: met, partly measured, NOT met, no tolerance; None where no part was made) and ``verdict_text`` the
    report's first line."""
    return {"name": job.name, "status": status, "verdict": verdict, "exit_code": exit_code, "message": message,
            "verdict_text": verdict_text, "delta_max": delta_max, "seconds": round(seconds, 3), "hot": str(job.hot),
            "field": str(job.field),
            "output": str(job.output), "report": None if job.report is None else str(job.report), **more}


class _Warnings(logging.Handler):
    """The hot2cold warnings of this thread, kept for the job's result (a worker has no terminal)."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.thread = threading.get_ident()
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.thread == self.thread:
            self.lines.append(in_words(f"{record.name}: {record.getMessage()}", jobs=True))


class _KeptPart:
    """The hot part a worker process loaded last (:func:`~hot2cold.pipeline.load.load`), kept for its next job on
    the same STEP file: a batch of load cases of one part reads and converts it once per worker, not once per
    job (the morph of a loaded part is that of the file).  Found by the file's path and content (size and
    SHA-256, the job's fingerprint: a file changed between jobs is loaded again) and the settings the load reads;
    one part at a time, so a batch of many parts holds no more than one."""

    def __init__(self):
        self._key: tuple | None = None
        self._part = None
        self._lock = threading.Lock()          # a Dask worker may run jobs in threads

    def get(self, job: Job, digest: dict | None):
        """What to morph for ``job``: its loaded hot part (kept, or loaded now and kept), or the STEP path where
        its ``digest`` is unknown (a missing file: the morph says so)."""
        if digest is None:
            return job.hot
        from ..pipeline.load import load

        settings = job.options.to_settings()
        key = (str(job.hot), digest.get("size"), digest.get("sha256"), settings.edge_samples_per_span)
        with self._lock:
            if key != self._key:
                self._key, self._part = None, None         # the last part is let go before the next one is read
                self._part = load(job.hot, settings)
                self._key = key
            else:
                log.info("job %s: %s loaded before, taken as it is", job.name, job.hot)
            return self._part


#: This process's :class:`_KeptPart` (a worker's, or the command's own where the jobs run in it).
_KEPT = _KeptPart()


def run_job(job: Job) -> dict:
    """Run one job as ``hot2cold morph`` would (morph, report, check, cold STEP), then write its record.

    Never raises for the job's own failure: the result dict says ``status`` (ok, tolerance-missed,
    failed), ``exit_code`` (that of ``hot2cold morph``), ``message`` (one line), ``delta_max`` (mm),
    ``seconds`` (wall), ``cpu_seconds`` (the worker process's, when it ran), ``warnings`` (the hot2cold log
    warnings) and ``worker`` (host:pid).
    """
    start, cpu = time.perf_counter(), time.process_time()
    warnings = _Warnings()
    logger = logging.getLogger("hot2cold")
    logger.addHandler(warnings)
    where = {"worker": f"{socket.gethostname()}:{os.getpid()}", "warnings": warnings.lines}
    try:
        if job.record.exists():     # the old record no longer vouches for what this run leaves
            job.record.unlink()
        try:
            inputs = fingerprint(job)   # before the inputs are read: a change during the run shows next time
        except OSError:
            inputs = None               # a missing input: the morph says which
        result = run_morph(_KEPT.get(job, None if inputs is None else inputs.get("hot")), job.field, job.options)
        for _ in write_cold(result, job.output, job.report):
            pass
        for _ in write_views(result, job.views()):
            pass
        missed = tolerance_missed(result)
        status, code = ("tolerance-missed", 5) if missed else ("ok", 0)
        verdict = result.report.verdict
        out = _result(job, status, code, in_words(missed or "", jobs=True), result.report.delta_max,
                      time.perf_counter() - start,
                      verdict=verdict.state.value, verdict_text=verdict.text,
                      cpu_seconds=round(time.process_time() - cpu, 3), **where)
        if inputs is not None:
            made = {what: _digest(path) for what, path in job.outputs()[:-1]}
            # the verdict first: the record beside the cold STEP is what a job without a report leaves there
            write_json({"verdict": verdict.to_dict(), "inputs": inputs, "outputs": made,
                        "paths": {w: str(p) for w, p in job.outputs()},
                        **{k: out[k] for k in ("status", "message", "delta_max", "seconds")},
                        "written": time.strftime("%Y-%m-%dT%H:%M:%S%z")}, job.record)
        log.info("job %s: %s in %.1f s", job.name, status, out["seconds"])
        return out
    except Hot2ColdError as exc:
        return _result(job, "failed", exc.exit_code, in_words(one_line(exc), jobs=True),
                       seconds=time.perf_counter() - start, **where)
    except Exception as exc:    # a bug or the unexpected: recorded like `hot2cold morph`'s internal error
        log.debug("job %s: internal error", job.name, exc_info=True)
        return _result(job, "failed", 70, f"internal error: {type(exc).__name__}: {one_line(exc)}",
                       seconds=time.perf_counter() - start, **where)
    finally:
        logger.removeHandler(warnings)


def skipped(job: Job, record: dict, seconds: float = 0.0) -> dict:
    """The result of a job left alone because :func:`done_before` gave its ``record``."""
    verdict = record.get("verdict") if isinstance(record.get("verdict"), dict) else {}
    return _result(job, "skipped", 0, f"done before ({record.get('status')}); inputs unchanged",
                   record.get("delta_max"), seconds, previous=record.get("status"),
                   verdict=verdict.get("state"), verdict_text=verdict.get("text"))


def run_jobs(jobs: list[Job], *, workers: int | None = None, scheduler: str | None = None, force: bool = False,
             runner: Callable[[Job], dict] = run_job) -> Iterator[dict]:
    """Run ``jobs``, yielding each result as it comes: first the skipped ones (done before with the same
    inputs, unless ``force``), then the others as they finish, started part by part (the jobs of one hot STEP
    one after the other, in the file's order among them: a worker loads a part once for its jobs on it).

    workers : local worker processes ("spawn", one thread each; default one per core).
    scheduler : the address of a Dask distributed scheduler to run the jobs on instead (paths must be the
        same on its workers).  :class:`InputError` if ``distributed`` is missing or the scheduler cannot
        be reached.
    runner : what a worker calls with a job (default :func:`run_job`); importable by the workers.

    A missing ``distributed`` is found here, at the call, before anything is yielded.
    """
    dask = _distributed() if scheduler else None
    return _run_jobs(jobs, workers, scheduler, force, runner, dask)


def _run_jobs(jobs, workers, scheduler, force, runner, dask) -> Iterator[dict]:
    todo, cache = [], {}
    for job in jobs:
        start = time.perf_counter()
        record = None if force else done_before(job, cache)
        if record is None:
            todo.append(job)
        else:
            yield skipped(job, record, time.perf_counter() - start)
    if not todo:
        return
    # the jobs of one part one after the other (the file's order kept among them; the summary keeps the file's
    # order): a worker keeps the last part it loaded for its next job on it (_KeptPart)
    todo.sort(key=lambda job: str(job.hot))
    if dask:
        yield from _on_dask(todo, scheduler, runner, *dask)
    else:
        yield from _in_pool(todo, workers or cores(), runner)


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _died(job: Job, exc: BaseException) -> dict:
    return _result(job, "failed", DIED, f"the worker process died running this job ({one_line(exc)}): "
                   f"a crash in the kernel or out of memory?")


def _in_pool(jobs: list[Job], workers: int, runner) -> Iterator[dict]:
    """The jobs in local "spawn" processes, at most ``workers`` at a time, each process at one thread
    (:func:`~hot2cold.cli.workers.one_thread_each`; this process's environment is left alone).  A worker
    that dies breaks the pool: the jobs that were running then are run again one by one (so the job that
    kills its worker is the one that fails), the rest in a new pool."""
    queue, suspects = list(jobs), []
    context = multiprocessing.get_context("spawn")
    while queue or suspects:
        alone = bool(suspects)
        todo = [suspects.pop(0)] if alone else queue
        size = 1 if alone else min(workers, len(queue))
        pool = ProcessPoolExecutor(size, mp_context=context, initializer=one_thread_each)
        clean = False
        try:
            running: dict = {}
            broken = False
            while (todo or running) and not broken:
                try:
                    while todo and len(running) < size:
                        running[pool.submit(runner, todo[0])] = todo[0]
                        todo.pop(0)
                except BrokenProcessPool:   # a worker died since the last wait: the job stays queued
                    broken = True
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                broken = broken or any(isinstance(f.exception(), BrokenProcessPool) for f in done)
                if broken:
                    done, _ = wait(running)   # every running job ends with the pool
                for future in done:
                    job = running.pop(future)
                    exc = future.exception()
                    if isinstance(exc, BrokenProcessPool):
                        if alone:
                            yield _died(job, exc)
                        else:
                            log.warning("a worker process died; job %s is run again on its own", job.name)
                            suspects.append(job)
                    elif exc is not None:   # the runner could not be called (pickling) or raised
                        yield _result(job, "failed", 70, f"internal error: {type(exc).__name__}: "
                                      f"{one_line(exc)}")
                    else:
                        yield future.result()
            clean = True
        finally:
            pool.shutdown(wait=clean, cancel_futures=True)


def _distributed():
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise InputError("--scheduler needs the package distributed: pip install 'hot2cold[dask]'") from None
    return Client, as_completed


def _on_dask(jobs: list[Job], address: str, runner, Client, as_completed) -> Iterator[dict]:
    """The jobs on the Dask cluster at ``address``, each a task of its own (pure=False: run every time)."""
    try:
        client = Client(address, timeout="20s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(f"cannot reach the Dask scheduler at {address}: {one_line(exc)}") from exc
    with client:
        futures = {client.submit(runner, job, pure=False): job for job in jobs}
        try:
            for future in as_completed(futures):
                job = futures[future]
                try:
                    yield future.result()
                except Exception as exc:    # KilledWorker (its worker died too often), a lost connection
                    yield _result(job, "failed", DIED, f"Dask: {type(exc).__name__}: {one_line(exc)}")
        finally:
            client.cancel(list(futures))


# --------------------------------------------------------------------------------------------------------
# The summary
# --------------------------------------------------------------------------------------------------------
def exit_code(results: list[dict]) -> int:
    """130 when a job was not run (interrupted), else 1 when a job failed, else 5 when a job missed its
    tolerance, else 0 (all ok or skipped)."""
    statuses = {r["status"] for r in results}
    for status, code in (("not-run", 130), ("failed", 1), ("tolerance-missed", 5)):
        if status in statuses:
            return code
    return 0


def summary(jobs_file: str | os.PathLike, jobs: list[Job], results: list[dict], **info) -> dict:
    """The batch as JSON: every job in the jobs file's order (one without a result is "not-run"), the
    counts per status, the exit code and ``info`` (backend, wall time...)."""
    by_name = {r["name"]: r for r in results}
    rows = [by_name.get(job.name) or _result(job, "not-run", None) for job in jobs]
    counts = {s: n for s in STATUSES if (n := sum(r["status"] == s for r in rows))}
    return {"jobs_file": str(jobs_file), "hot2cold": __version__, **info, "counts": counts,
            "exit_code": exit_code(rows), "jobs": rows}


def summary_table(data: dict) -> str:
    """The summary as a text table: job, status, verdict (met, partly measured, NOT met, no tolerance; "-"
    where no part was made), Δmax, time, message."""
    rows = data["jobs"]
    width = max([3] + [len(r["name"]) for r in rows])
    lines = [f"{'job':<{width}}  {'status':<16} {'verdict':<15} {'Δmax [mm]':>10} {'time [s]':>9}  message"]
    for r in rows:
        delta = "-" if r["delta_max"] is None else f"{r['delta_max']:.3g}"
        verdict = r.get("verdict") or "-"
        lines.append(f"{r['name']:<{width}}  {r['status']:<16} {verdict:<15} {delta:>10} {r['seconds']:>9.1f}  "
                     f"{r['message']}")
    counts = ", ".join(f"{n} {s}" for s, n in data["counts"].items())
    wall = f"; {data['wall_seconds']:.1f} s wall" if "wall_seconds" in data else ""
    lines.append(f"{len(rows)} jobs: {counts}{wall}")
    return "\n".join(lines)
