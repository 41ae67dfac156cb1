"""A part loaded once for several fields (``hot2cold.load``): its morphs are those of its file, and it is read
and converted once."""
from __future__ import annotations

import threading

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

import hot2cold.pipeline.load as loading
import hot2cold.pipeline.morph as morphing
from hot2cold import InputError, Settings, load, morph
from hot2cold.io.field import DisplacementField

pytestmark = pytest.mark.heavy

#: The morphs compared to the bit run with BLAS at one thread (its sums in one order, whatever the machine).
ONE = Settings(blas_threads=1)


def _field(nodes: np.ndarray, scale: float) -> DisplacementField:
    """A small turn and stretch of the block (about 0.03 mm at ``scale`` 1)."""
    x, y, z = nodes.T
    return DisplacementField(nodes, scale * 1e-3 * np.column_stack([y, -x, 0.2 * z]))


def _figures(result) -> dict:
    """The report without its timings: what two morphs of the same part and field must share."""
    return {k: v for k, v in result.report.to_dict().items() if k != "timings"}


@pytest.fixture
def loads(monkeypatch) -> list:
    """Every part :func:`load_part` reads and converts (its arguments), from here on."""
    calls = []
    read = loading.load_part

    def counted(hot, settings):
        calls.append(hot)
        return read(hot, settings)

    monkeypatch.setattr(loading, "load_part", counted)
    return calls


def test_a_loaded_part_morphs_as_its_file_and_is_read_once(block_step, block_nodes, loads):
    part = load(block_step, ONE)
    first = morph(part, _field(block_nodes, 1.0), ONE)
    other = morph(part, _field(block_nodes, -2.0), ONE)     # another load case between, then the first again
    again = morph(part, _field(block_nodes, 1.0), ONE)
    assert loads == [block_step]                            # the three morphs read nothing
    fresh = morph(block_step, _field(block_nodes, 1.0), ONE)
    assert loads == [block_step, block_step]
    assert _figures(first) == _figures(again) == _figures(fresh)
    assert first.report.to_dict()["hot"] == fresh.report.to_dict()["hot"]
    for a, b, c in zip(first.faces, again.faces, fresh.faces):
        np.testing.assert_array_equal(a.surface.poles, b.surface.poles)
        np.testing.assert_array_equal(a.surface.poles, c.surface.poles)
    assert other.report.delta_max != first.report.delta_max     # another field: another morph
    assert first.report.valid and other.report.valid and again.report.valid


def test_a_loaded_part_says_what_it_holds_in_a_line(block_step):
    part = load(block_step)
    assert repr(part) == (f"LoadedPart({str(block_step)!r}: 1 solid, {len(part.part.faces)} faces, "
                          f"{len(part.part.edges)} edges)")


def test_a_morph_with_other_load_settings_is_refused(block_step, block_nodes):
    part = load(block_step, Settings(edge_samples_per_span=8))
    with pytest.raises(InputError, match="edge_samples_per_span 8, the morph asks for"):
        morph(part, _field(block_nodes, 1.0))
    assert load(part, Settings(edge_samples_per_span=8)) is part       # loaded already: as it is
    with pytest.raises(InputError, match="edge_samples_per_span 8"):
        load(part)


def test_morphs_of_one_loaded_part_from_two_threads_take_turns(block_step, block_nodes, monkeypatch):
    part = load(block_step, ONE)
    alone = morph(part, _field(block_nodes, 1.0), ONE)
    events, inner = [], morphing._morph

    def watched(*args, **kwargs):
        events.append("start")
        try:
            return inner(*args, **kwargs)
        finally:
            events.append("end")

    monkeypatch.setattr(morphing, "_morph", watched)
    results: dict[int, object] = {}

    def run(k: int) -> None:
        results[k] = morph(part, _field(block_nodes, 1.0), ONE)

    threads = [threading.Thread(target=run, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert events == ["start", "end", "start", "end"]        # one after the other, never side by side
    assert _figures(results[0]) == _figures(results[1]) == _figures(alone)


def test_a_batch_worker_loads_a_part_once_for_its_load_cases(tmp_path, block_step, block_nodes, loads, monkeypatch):
    from hot2cold.cli import batch

    monkeypatch.setattr(batch, "_KEPT", batch._KeptPart())        # this process as a fresh worker
    hot = tmp_path / "hot.step"
    hot.write_bytes(block_step.read_bytes())
    for name, scale in (("a", 1.0), ("b", -2.0)):
        field = _field(block_nodes, scale)
        np.savetxt(tmp_path / f"{name}.csv", np.column_stack([field.points, field.displacements]), delimiter=",",
                   header="x,y,z,dx,dy,dz", comments="")
    (tmp_path / "jobs.csv").write_text("name,hot,field,output\n" + "".join(
        f"{job},hot.step,{field}.csv,{job}_cold.step\n" for job, field in (("a", "a"), ("b", "b"), ("c", "a"))))
    a, b, c = batch.read_jobs(tmp_path / "jobs.csv")
    with threadpool_limits(1, "blas"):                             # as a worker runs them
        done = [batch.run_job(a), batch.run_job(b)]
        assert [r["status"] for r in done] == ["ok", "ok"]
        assert loads == [hot]                                      # both load cases from one load
        hot.write_bytes(block_step.read_bytes() + b"\n")          # the same path, another file: loaded again
        again = batch.run_job(c)
    assert again["status"] == "ok" and loads == [hot, hot]
    assert again["delta_max"] == done[0]["delta_max"]             # job c is job a again
    assert again["verdict_text"] == done[0]["verdict_text"]
