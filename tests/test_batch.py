"""hot2cold batch: real morphs of the bundled blade (fields subsampled to keep them quick) in the local
process pool and on a real Dask LocalCluster, skipping what is done, and every refusal of a bad jobs file."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from dataclasses import replace

import meshio
import pytest

from hot2cold.cli import batch, main
from hot2cold.cli.workers import ONE_THREAD
from hot2cold.io.field import read_field
from hot2cold.kernel.validity import check_solids
from hot2cold.kernel.step import read_step

from conftest import SAMPLES

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def fields(tmp_path_factory):
    """Two quick fields on the blade: every 4th node of the bundled field, from two offsets (~4800 nodes)."""
    folder = tmp_path_factory.mktemp("fields")
    lines = (SAMPLES / "twisted_blade_field.csv").read_text().splitlines()
    out = []
    for offset in (0, 2):
        path = folder / f"op{offset}.csv"
        path.write_text("\n".join([lines[0]] + lines[1 + offset::4]) + "\n")
        out.append(path)
    return out


@pytest.fixture
def project(tmp_path, fields):
    """A jobs folder: the hot blade, two fields, a field that fails when read (no dz), a folder for the cold
    parts."""
    shutil.copy(SAMPLES / "twisted_blade.step", tmp_path / "hot.step")
    (tmp_path / "bad.csv").write_text("x,y,z,dx,dy\n0,0,0,0,0\n")
    for path in fields:
        shutil.copy(path, tmp_path / path.name)
    (tmp_path / "cold").mkdir()
    return tmp_path


def _jobs_csv(folder, rows, header="name,hot,field,output,report"):
    path = folder / "jobs.csv"
    path.write_text("\n".join([header] + rows) + "\n")
    return path


THREE_JOBS = ["a,hot.step,op0.csv,cold/a.step,cold/a_report.json",
              "b,hot.step,op2.csv,cold/b.step,",
              "c,hot.step,bad.csv,cold/c.step,"]


def _valid_step(path):
    checks = check_solids(read_step(path))
    return bool(checks) and all(c.valid and c.closed for c in checks)


def _summary(path):
    data = json.loads(path.read_text())
    return data, {r["name"]: r for r in data["jobs"]}


def _check_two_ok_one_failed(project, data, by_name):
    assert data["exit_code"] == 1 and data["counts"] == {"ok": 2, "failed": 1}
    assert [r["name"] for r in data["jobs"]] == ["a", "b", "c"]
    for name in "ab":
        assert by_name[name]["status"] == "ok" and by_name[name]["exit_code"] == 0
        assert 0 < by_name[name]["delta_max"] < 1e-3 and by_name[name]["seconds"] > 0
        assert _valid_step(project / "cold" / f"{name}.step")
        assert (project / "cold" / f"{name}.step.hot2cold.json").is_file()
    assert json.loads((project / "cold" / "a_report.json").read_text())["valid"]
    failed = by_name["c"]
    assert failed["status"] == "failed" and failed["exit_code"] == 2
    assert "bad.csv" in failed["message"] and "lacks column(s) dz" in failed["message"]
    assert "\n" not in failed["message"]
    assert not (project / "cold" / "c.step").exists()
    assert not list(project.rglob("*.tmp"))


def test_pool_runs_skips_done_jobs_and_force_reruns(project, capsys, monkeypatch):
    jobs = _jobs_csv(project, THREE_JOBS)
    monkeypatch.chdir(project / "cold")     # relative paths are the jobs file's, not the working folder's
    start = time.perf_counter()
    assert main(["batch", str(jobs)]) == 1
    first = time.perf_counter() - start
    out, err = capsys.readouterr()
    data, by_name = _summary(project / "jobs_summary.json")
    _check_two_ok_one_failed(project, data, by_name)
    assert data["workers"] == 2 or data["workers"] == min(3, batch.cores())
    assert "batch: 3/3" in err
    assert "failed" in out and "bad.csv" in out and "Δmax" in out

    # Re-run: the done jobs are skipped, their files untouched; the failed one runs (and fails) again.
    stamps = {p: p.stat().st_mtime_ns for p in (project / "cold").iterdir()}
    start = time.perf_counter()
    assert main(["batch", str(jobs), "-q"]) == 1
    again = time.perf_counter() - start
    out, err = capsys.readouterr()
    assert out == "" and err.strip().splitlines() == [
        f"hot2cold: job c failed: {by_name['c']['message']}"]
    data, by_name = _summary(project / "jobs_summary.json")
    assert [by_name[n]["status"] for n in "abc"] == ["skipped", "skipped", "failed"]
    assert by_name["a"]["delta_max"] == pytest.approx(data["jobs"][0]["delta_max"])
    assert {p: p.stat().st_mtime_ns for p in (project / "cold").iterdir()} == stamps
    assert again < first

    # Without the failing job everything is skipped: exit 0, and no worker is started at all.
    ok_jobs = _jobs_csv(project, THREE_JOBS[:2])
    start = time.perf_counter()
    assert main(["batch", str(ok_jobs), "-q", "--summary", str(project / "ok.json")]) == 0
    assert time.perf_counter() - start < 2.0
    assert _summary(project / "ok.json")[0]["counts"] == {"skipped": 2}

    # --force runs them again.
    assert main(["batch", str(ok_jobs), "--force", "-q", "--workers", "1"]) == 0
    data, by_name = _summary(project / "jobs_summary.json")
    assert data["workers"] == 1 and [by_name[n]["status"] for n in "ab"] == ["ok", "ok"]
    for name in "ab":
        path = project / "cold" / f"{name}.step"
        assert path.stat().st_mtime_ns > stamps[path] and _valid_step(path)


def test_dask_local_cluster_runs_a_toml_jobs_file(project, capsys):
    from distributed import LocalCluster

    jobs = project / "jobs.toml"
    jobs.write_text('[defaults]\nhot = "hot.step"\nfield-units = "mm"\n\n'
                    '[[jobs]]\nname = "a"\nfield = "op0.csv"\noutput = "cold/a.step"\nreport = "cold/a_report.json"\n\n'
                    '[[jobs]]\nname = "b"\nfield = "op2.csv"\noutput = "cold/b.step"\n\n'
                    '[[jobs]]\nname = "c"\nfield = "bad.csv"\noutput = "cold/c.step"\n')
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        start = time.perf_counter()
        assert main(["batch", str(jobs), "--scheduler", cluster.scheduler_address]) == 1
        seconds = time.perf_counter() - start
        data, by_name = _summary(project / "jobs_summary.json")
        _check_two_ok_one_failed(project, data, by_name)
        assert data["scheduler"] == cluster.scheduler_address
        workers = {by_name[n]["worker"].split(":")[1] for n in "abc"}
        assert str(os.getpid()) not in workers          # the jobs ran in the cluster's worker processes
        # the done jobs are skipped on the cluster too
        assert main(["batch", str(jobs), "--scheduler", cluster.scheduler_address, "-q"]) == 1
        assert [r["status"] for r in _summary(project / "jobs_summary.json")[0]["jobs"]] == \
            ["skipped", "skipped", "failed"]
    print(f"dask LocalCluster: 3 jobs in {seconds:.1f} s", file=sys.stderr)


def test_scheduler_without_distributed_is_refused(project, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)    # what `import distributed` meets uninstalled
    jobs = _jobs_csv(project, THREE_JOBS[:1])
    assert main(["batch", str(jobs), "--scheduler", "tcp://127.0.0.1:8786"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hot2cold: error: ") and "distributed" in err[0]
    assert not (project / "cold" / "a.step").exists() and not (project / "jobs_summary.json").exists()


@pytest.mark.parametrize("header, rows, words", [
    ("name,hot,output", ["a,hot.step,cold/a.step"], ["missing column 'field'"]),
    ("hot,field,output,tolerence", ["hot.step,op0.csv,cold/a.step,1e-3"], ["unknown column 'tolerence'"]),
    ("hot,field,output", ["hot.step,op0.csv,cold/a.step", "hot.step,op2.csv,cold/../cold/a.step"],
     ["line 3", "also the output of"]),
    ("hot,field,output", ["hot.step,op0.csv,cold/a.step", "hot.step,op2.csv,op0.csv"],
     ["line 3", "the field of", "must not overwrite an input"]),
    ("hot,field,output,report", ["hot.step,op0.csv,cold/a.step,hot.step"], ["report", "must not overwrite"]),
    ("hot,field,output,tolerance", ["hot.step,op0.csv,cold/a.step,-1"], ["line 2", "tolerance"]),
    ("hot,field,output,invert", ["hot.step,op0.csv,cold/a.step,maybe"], ["invert"]),
    ("hot,field,output,field_units", ["hot.step,op0.csv,cold/a.step,inch"], ["field_units"]),
    ("hot,field,output", ["hot.step,op0.csv,nowhere/a.step"], ["nowhere", "does not exist"]),
    ("hot,field,output", ["hot.step,,cold/a.step"], ["line 2", "no field"]),
    ("hot,field,output", [], ["no job"]),
    ("name,hot,field,output", ["a,hot.step,op0.csv,cold/a.step", "a,hot.step,op2.csv,cold/b.step"],
     ["line 3", "name 'a'"]),
    ("hot,field,output", ["hot.step,op0.csv,cold/a.step,extra"], ["4 cells but 3 columns"]),
])
def test_bad_jobs_file_is_refused_before_anything_runs(project, capsys, header, rows, words):
    jobs = _jobs_csv(project, rows, header)
    assert main(["batch", str(jobs)]) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hot2cold: error: "), lines
    for word in words:
        assert word in lines[0]
    assert out == "" and not list((project / "cold").iterdir()) and not (project / "jobs_summary.json").exists()


@pytest.mark.parametrize("text, words", [
    ('[[jobs]]\nhot = "hot.step"\nfield = "op0.csv"\noutput = "cold/a.step"\nspeed = 3\n', ["job 1", "'speed'"]),
    ('[defaults]\nhot = "hot.step"\n[[jobs]]\nfield = "op0.csv"\n', ["job 1", "missing option 'output'"]),
    ('[job]\nhot = "hot.step"\n', ["unknown table 'job'"]),
    ('[[jobs]]\nhot = "hot.step"\nfield = \n', ["not valid TOML"]),
])
def test_bad_toml_jobs_file_is_refused(project, capsys, text, words):
    jobs = project / "jobs.toml"
    jobs.write_text(text)
    assert main(["batch", str(jobs), "--summary", str(project / "s.json")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and all(w in lines[0] for w in words), lines
    assert not (project / "s.json").exists()


def test_csv_and_toml_give_the_same_jobs(project):
    csv_jobs = batch.read_jobs(_jobs_csv(project, ["a,hot.step,op0.csv,cold/a.step,cold/a.json,m,true,1e-3,2"],
                                         "name,hot,field,output,report,field-units,invert,tolerance,"
                                         "max_refinements"))
    toml = project / "jobs.toml"
    toml.write_text('[defaults]\nfield_units = "m"\ninvert = true\n\n[[jobs]]\nname = "a"\nhot = "hot.step"\n'
                    'field = "op0.csv"\noutput = "cold/a.step"\nreport = "cold/a.json"\ntolerance = 1e-3\n'
                    'max-refinements = 2\n')
    assert batch.read_jobs(toml) == csv_jobs
    assert set(batch._CONVERT) == set(batch.OPTIONS)        # every option of a Job is read
    job = csv_jobs[0]
    assert job.hot == project / "hot.step" and job.report == project / "cold" / "a.json"
    assert (job.options.field_units, job.options.invert, job.options.tolerance, job.options.max_refinements) == \
        ("m", True, 1e-3, 2)
    assert job.options.to_settings().tolerance == 1e-3
    assert not job.options.to_settings().extrapolate


def test_extrapolate_reaches_the_settings_of_a_job(project):
    (job,) = batch.read_jobs(_jobs_csv(project, ["x,hot.step,op0.csv,cold/x.step,true"],
                                       "name,hot,field,output,extrapolate"))
    assert job.options.extrapolate and job.options.to_settings().extrapolate and \
        job.options.as_dict()["extrapolate"] is True


def test_stale_or_half_written_output_is_not_skipped(project):
    """The record vouches for the outputs only while inputs, options and outputs are what it states."""
    (job,) = batch.read_jobs(_jobs_csv(project, THREE_JOBS[:1]))
    assert batch.done_before(job) is None
    result = batch.run_job(job)
    assert result["status"] == "ok" and result["warnings"] == []
    assert batch.done_before(job)["status"] == "ok"

    step = job.output.read_bytes()
    job.output.write_bytes(step[: len(step) // 2])              # a half-written (or replaced) STEP
    assert batch.done_before(job) is None
    job.output.write_bytes(step)
    assert batch.done_before(job) is not None

    field = job.field.read_bytes()
    job.field.write_bytes(field.replace(b"0.0", b"0.1", 1))     # the field changed since
    assert batch.done_before(job) is None
    job.field.write_bytes(field)
    assert batch.done_before(job) is not None

    assert batch.done_before(replace(job, options=replace(job.options, tolerance=1e-3))) is None  # other options
    job.report.unlink()                                            # an output missing
    assert batch.done_before(job) is None

    # A run that fails removes the record: the old STEP is no longer vouched for.
    bad = replace(job, field=project / "missing.csv")
    assert batch.run_job(bad)["status"] == "failed" and not job.record.exists()
    assert batch.done_before(job) is None


def test_a_job_writes_its_viewer_files(project, capsys):
    """Issue 17: a job's ``html``, ``vtu`` and ``stl`` columns write those files as ``hot2cold morph``'s flags
    do; the record vouches for them, so a rerun skips the job until one of them is gone."""
    jobs = _jobs_csv(project, ["a,hot.step,op0.csv,cold/a.step,cold/a.html,cold/a.vtu,cold/a.stl"],
                     header="name,hot,field,output,html,vtu,stl")
    assert main(["batch", str(jobs), "-q", "--workers", "1"]) == 0
    cold = project / "cold"
    assert sorted(p.name for p in cold.iterdir()) == ["a.html", "a.step", "a.step.hot2cold.json", "a.stl", "a.vtu",
                                                       "a_surface.vtu"]
    assert "<html" in (cold / "a.html").read_text()[:200].lower()
    assert len(meshio.read(cold / "a.vtu").points) == len(read_field(project / "op0.csv"))
    record = json.loads((cold / "a.step.hot2cold.json").read_text())
    assert set(record["outputs"]) == {"output", "html", "vtu", "vtu surface", "stl"}
    assert main(["batch", str(jobs), "-q"]) == 0
    assert _summary(project / "jobs_summary.json")[1]["a"]["status"] == "skipped"
    (cold / "a_surface.vtu").unlink()
    assert main(["batch", str(jobs), "-q", "--workers", "1"]) == 0
    assert _summary(project / "jobs_summary.json")[1]["a"]["status"] == "ok" and (cold / "a_surface.vtu").is_file()
    same = _jobs_csv(project, ["a,hot.step,op0.csv,cold/a.step,cold/a.step"], header="name,hot,field,output,stl")
    assert main(["batch", str(same), "-q"]) == 2
    assert "every output needs its own path" in capsys.readouterr().err


def test_field_points_count_by_content_not_by_path(project, tmp_path_factory):
    """A job's ``field_points`` file is one of its inputs: its content decides a rerun, its path does not (a
    moved project folder keeps its runs, as for the hot STEP and the field)."""
    from hot2cold.cli.options import MorphOptions

    other = tmp_path_factory.mktemp("moved")
    for folder in (project, other):
        (folder / "nodes.bdf").write_text("GRID,1,,0.,0.,0.\n")
    jobs = [batch.Job("a", project / "hot.step", project / "op0.csv", project / "cold" / "a.step",
                      options=MorphOptions(field_points=folder / "nodes.bdf")) for folder in (project, other)]
    assert batch.fingerprint(jobs[0]) == batch.fingerprint(jobs[1])
    (other / "nodes.bdf").write_text("GRID,1,,0.,0.,1.\n")
    assert batch.fingerprint(jobs[0]) != batch.fingerprint(jobs[1])


def test_missing_inputs_are_refused_before_any_job_runs(project, capsys):
    """Issue 17: a jobs file naming an input that is not there is refused as a whole, at once (it was found only
    when that job ran, after the others), naming the line; nothing is written."""
    jobs = _jobs_csv(project, THREE_JOBS[:2] + ["c,hot.step,missing.csv,cold/c.step,"])
    start = time.perf_counter()
    assert main(["batch", str(jobs), "-q"]) == 2
    assert time.perf_counter() - start < 5.0
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1, err
    assert re.search(r"line 4: field file not found: .*missing\.csv; check the path$", err.strip()), err
    assert not list((project / "cold").iterdir()) and not (project / "jobs_summary.json").exists()
    points = _jobs_csv(project, ["a,hot.step,op0.csv,cold/a.step,"], header="name,hot,field,output,field_points")
    points.write_text(points.read_text().rstrip("\n") + "nodes.bdf\n")
    assert main(["batch", str(points), "-q"]) == 2
    assert re.search(r"line 2: field points file not found: .*nodes\.bdf", capsys.readouterr().err)


def _crash_or_quick(job):
    """A runner for the pool's crash handling: the job named "crash" kills its worker, the others are
    recorded ok at once (no morph: this is about the pool)."""
    if job.name == "crash":
        os._exit(3)
    return batch._result(job, "ok", 0, seconds=0.01)


def test_a_worker_that_dies_fails_its_job_only(project):
    jobs = batch.read_jobs(_jobs_csv(project, [f"{n},hot.step,op0.csv,cold/{n}.step," for n in
                                               ("x", "crash", "y", "z")]))
    results = {r["name"]: r for r in batch.run_jobs(jobs, workers=2, runner=_crash_or_quick)}
    assert set(results) == {"x", "crash", "y", "z"}
    assert results["crash"]["status"] == "failed" and results["crash"]["exit_code"] == batch.DIED
    assert "worker process died" in results["crash"]["message"]
    assert all(results[n]["status"] == "ok" for n in "xyz")


def test_jobs_start_part_by_part_and_the_summary_keeps_the_files_order(project):
    shutil.copy(project / "hot.step", project / "other.step")
    rows = [f"{n},{hot},op0.csv,cold/{n}.step," for n, hot in
            (("p", "other.step"), ("q", "hot.step"), ("r", "other.step"), ("s", "hot.step"))]
    jobs = batch.read_jobs(_jobs_csv(project, rows))
    results = list(batch.run_jobs(jobs, workers=1, runner=_crash_or_quick))
    assert [r["name"] for r in results] == ["q", "s", "p", "r"]   # hot.step's, then other.step's, in file order
    data = batch.summary(project / "jobs.csv", jobs, results)
    assert [r["name"] for r in data["jobs"]] == ["p", "q", "r", "s"]


def test_missed_tolerance_is_written_recorded_and_exit_code_5(project):
    (job,) = batch.read_jobs(_jobs_csv(project, ["t,hot.step,op0.csv,cold/t.step,"]))
    job = replace(job, options=replace(job.options, tolerance=1e-9, max_refinements=0))
    result = batch.run_job(job)
    assert result["status"] == "tolerance-missed" and result["exit_code"] == 5
    assert "not met" in result["message"] and result["delta_max"] > 1e-9
    assert _valid_step(job.output)
    record = batch.done_before(job)
    assert record["status"] == "tolerance-missed"
    assert batch.skipped(job, record)["message"] == "done before (tolerance-missed); inputs unchanged"
    assert batch.exit_code([result]) == 5
    assert batch.exit_code([result, {"status": "failed"}]) == 1
    assert batch.exit_code([{"status": "skipped"}, {"status": "ok"}]) == 0
    assert batch.exit_code([result, {"status": "not-run"}]) == 130


def _threads_of_the_worker(job):
    """A runner that reports the worker's thread settings instead of morphing (numpy loaded by then, as a
    job's imports load it)."""
    import numpy  # noqa: F401
    from threadpoolctl import threadpool_info

    blas = sorted({lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"})
    return batch._result(job, "ok", 0, environment={k: os.environ.get(k) for k in ONE_THREAD}, blas=blas)


def test_pool_workers_run_at_one_thread_and_this_environment_is_left_alone(project, monkeypatch):
    for key in ONE_THREAD:
        monkeypatch.delenv(key, raising=False)
    before = dict(os.environ)
    jobs = batch.read_jobs(_jobs_csv(project, [f"{n},hot.step,op0.csv,cold/{n}.step," for n in "xy"]))
    running = batch.run_jobs(jobs, workers=1, runner=_threads_of_the_worker)
    results = [next(running)]
    assert dict(os.environ) == before           # while the pool runs
    results += list(running)
    assert dict(os.environ) == before
    assert [r["status"] for r in results] == ["ok", "ok"]
    for r in results:
        assert r["environment"] == ONE_THREAD and r["blas"] == [1]


def test_the_worker_initializer_imports_no_numpy():
    """A spawn worker imports hot2cold.cli.workers (and hot2cold.cli) for its initializer before its first
    job: numpy must not be loaded by then, or it would start its threads before they are set to one."""
    code = "import sys, hot2cold.cli.workers; print(sorted({'numpy', 'hot2cold.cli.commands'} & set(sys.modules)))"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.strip() == "[]"


def test_a_jobs_messages_name_the_options_in_the_jobs_files_words(project, fields):
    """A job refused for a field in metres is told to set its jobs-file column, not a command-line flag or a
    Python setting (the library's messages name options in Python's words; a batch says them in its own)."""
    import numpy as np

    from hot2cold.cli.batch import read_jobs, run_job

    table = np.loadtxt(fields[0], delimiter=",", skiprows=1)
    table[:, 1:] *= 1e-3
    np.savetxt(project / "metres.csv", table, delimiter=",", header="id,x,y,z,dx,dy,dz", comments="")
    (job,) = read_jobs(_jobs_csv(project, ["m,hot.step,metres.csv,cold/m.step,"]))
    result = run_job(job)
    assert result["status"] == "failed" and result["exit_code"] == 2
    assert result["message"].endswith("the field looks like metres: use field_units = m in the jobs file"), \
        result["message"]
    assert "--field-units" not in result["message"] and "morph(" not in result["message"]
