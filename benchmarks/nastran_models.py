"""hot2cold's Nastran reader against pyNastran on every ``.op2`` (and ``.pch``) of pyNastran's ``models/``.

Run from the repository (issue 39)::

    # pyNastran 1.4.1 needs numpy < 2: its own environment (as for benchmarks/nastran_reference.py)
    python3 -m venv /work/venv-pynastran
    /work/venv-pynastran/bin/pip install pyNastran==1.4.1 "numpy<2"
    # the models, at the pinned commit, into the git-ignored cache (from a clone or mirror of pyNastran)
    git -C PYNASTRAN_GIT ls-tree -r COMMIT models      # then ``git cat-file blob`` each .op2/.pch/.bdf/.dat
    python benchmarks/nastran_models.py --json out/nastran_models.json
    python benchmarks/nastran_models.py --show out/nastran_models.json

``--extract GITDIR`` copies the ``.op2``, ``.pch``, ``.bdf``, ``.dat`` and ``.inc`` files of ``models/`` at
:data:`COMMIT` from a pyNastran git directory into :data:`MODELS` (blobs missing from a partial mirror are
listed and skipped).  ``--pynastran PYTHON`` names the interpreter of the pyNastran environment.

For each ``.op2``:

(a) pyNastran (:func:`read_op2_geom`), in the separate environment (this file run with ``--worker``, one
    process for all files), writes to ``MODELS/../pynastran_npz/<file>.npz`` its last static real SORT1
    displacement table (approach code 1 or 10, the last load step): node ids, grid types (1 GRID, 2 scalar
    point, 3 extra point ...), T1-T3 as the file holds them, and the grids' positions in the basic frame
    (``get_displacement_index_xyz_cp_cd`` + ``transform_xyzcp_to_xyz_cid``), CD systems, and the origin,
    axes (``beta()``) and kind of each CD system; also the kind of its last displacement table of any kind;
(b) hot2cold reads the file as a user does, :func:`hot2cold.io.field.read_field` (an OP2 without GRID
    records: with ``points_from`` the model's ``.bdf``/``.dat`` of the same name, when there is one), with its
    log lines caught;
(c) the two are compared: the same GRID ids in the same order, and the same T1-T3 to 1e-6 of the largest
    magnitude (float32 files) after pyNastran's vectors are taken to the basic frame in their CD systems
    (hot2cold writes basic-frame vectors), and the same positions to 1e-6 of the model's size.

A ``.pch`` (pyNastran does not read punch displacements) is compared with pyNastran's reading of the
``.op2`` of the same name in the same folder, in the CD systems (a punch holds no positions); without one,
hot2cold's reading is reported.

Outcomes: ``same``; ``differs`` (why); ``refused`` (hot2cold's message); ``crash`` (an exception other than
FieldError); ``no displacements in pyNastran`` (hot2cold's reading is reported).  The notes say what was
left out (scalar/extra points, which hot2cold must log) and whether a CD rotation was needed.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

if str(Path(__file__).resolve().parent) not in sys.path:      # reference_runs, beside this one
    sys.path.insert(0, str(Path(__file__).resolve().parent))
from reference_runs import Caught, extract, run_reference, short, show, work  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: pyNastran commit whose ``models/`` are read (SteveDoyle2/pyNastran, 2026-08-21 "fixing import").
COMMIT = "1d25a92442a76cd1b24bfd0bd4008644b79322b2"
CACHE = ROOT / "corpus" / "cache" / "pynastran_models" / COMMIT
MODELS = CACHE / "models"
NPZ = CACHE / "pynastran_npz"
PYNASTRAN_PYTHON = "/work/venv-pynastran/bin/python"
EXTENSIONS = (".op2", ".pch", ".bdf", ".dat", ".inc")
RTOL = 1e-6


# --------------------------------------------------------------------------------------------------------
# The pyNastran side: runs in the pyNastran environment (numpy < 2), imports nothing of hot2cold.
# --------------------------------------------------------------------------------------------------------
def _worker_one(path: str) -> dict:
    from pyNastran.op2.op2 import read_op2
    from pyNastran.op2.op2_geom import read_op2_geom

    out: dict = {}
    try:
        model = read_op2_geom(path, debug=None, build_dataframe=False)
    except Exception as exc:  # its geometry checks fail: the results alone
        out["geom_error"] = np.array(f"{type(exc).__name__}: {exc}".splitlines()[0][:300])
        model = read_op2(path, debug=None, build_dataframe=False)
    tables = list(model.displacements.values())
    out["n_tables"] = np.array(len(tables))
    if not tables:
        return out
    last = tables[-1]
    out["last_kind"] = np.array(f"{last.table_name} {type(last).__name__} analysis_code {last.analysis_code}")
    static = [d for d in tables if d.analysis_code in (1, 10) and d.is_real and d.is_sort1]
    if not static:
        return out
    disp = static[-1]
    out["table"] = np.array(f"{disp.table_name} subcase {disp.isubcase} analysis_code {disp.analysis_code} "
                            f"steps {disp.data.shape[0]}")
    out["subcase"] = np.array(int(disp.isubcase))
    if disp.analysis_code == 10:
        out["load"] = np.array(float(disp._times[-1]))
    out["ids"] = disp.node_gridtype[:, 0].astype(np.int64)
    out["gridtype"] = disp.node_gridtype[:, 1].astype(np.int64)
    out["t"] = disp.data[-1, :, :3].astype(np.float64)
    try:
        unused_icd, icp, xyz_cp, nid_cp_cd = model.get_displacement_index_xyz_cp_cd()
        xyz = model.transform_xyzcp_to_xyz_cid(xyz_cp, nid_cp_cd[:, 0], icp, cid=0)
        out["pos_ids"] = nid_cp_cd[:, 0].astype(np.int64)
        out["pos_cd"] = nid_cp_cd[:, 2].astype(np.int64)
        out["pos_xyz"] = np.asarray(xyz, dtype=np.float64)
        cids = sorted({int(c) for c in nid_cp_cd[:, 2] if c > 0})
        out["cids"] = np.array(cids, dtype=np.int64)
        out["cid_kind"] = np.array([model.coords[c].Type for c in cids] or [""])
        out["cid_origin"] = np.array([model.coords[c].origin for c in cids], dtype=np.float64).reshape(-1, 3)
        out["cid_beta"] = np.array([model.coords[c].beta() for c in cids], dtype=np.float64).reshape(-1, 3, 3)
    except Exception as exc:  # no geometry, or systems pyNastran cannot build
        out["pos_error"] = np.array(f"{type(exc).__name__}: {exc}".splitlines()[0][:300])
    return out


def worker(out_dir: str, files: list[str]) -> int:
    import warnings

    warnings.simplefilter("ignore")
    return work(out_dir, files, _worker_one, npz_path)


# --------------------------------------------------------------------------------------------------------
# The hot2cold side
# --------------------------------------------------------------------------------------------------------
def npz_path(op2: Path) -> Path:
    return NPZ / (op2.relative_to(MODELS).as_posix().replace("/", "__") + ".npz")


def run_pynastran(files: list[Path], python: str) -> None:
    """pyNastran's reading of the ``files`` not read yet, in its environment (:func:`reference_runs.run_reference`)."""
    run_reference(files, python, __file__, NPZ, npz_path, "pyNastran")


def rotate_to_basic(t: np.ndarray, xyz: np.ndarray, kind: str, origin: np.ndarray, beta: np.ndarray):
    """Vectors ``t (M, 3)`` given in the CD system (``beta`` rows = its axes in basic) at basic points ``xyz``."""
    local = (xyz - origin) @ beta.T
    if kind == "R":
        comp = t
    else:
        x, y, z = local.T
        phi = np.where(np.hypot(x, y) <= 1e-9 * np.maximum(np.abs(local).max(axis=1), 1.0), 0.0, np.arctan2(y, x))
        cp, sp = np.cos(phi), np.sin(phi)
        if kind == "C":
            e1, e2, e3 = (np.column_stack([cp, sp, 0 * cp]), np.column_stack([-sp, cp, 0 * cp]),
                          np.column_stack([0 * cp, 0 * cp, 1 + 0 * cp]))
        else:
            th = np.arctan2(np.hypot(x, y), z)
            ct, st = np.cos(th), np.sin(th)
            e1, e2, e3 = (np.column_stack([st * cp, st * sp, ct]), np.column_stack([ct * cp, ct * sp, -st]),
                          np.column_stack([-sp, cp, 0 * cp]))
        comp = t[:, :1] * e1 + t[:, 1:2] * e2 + t[:, 2:3] * e3
    return comp @ beta


def _left_out_logged(lines: list[str]) -> list[str]:
    return [line.split(": ", 1)[-1] for line in lines if "left out" in line]


def hot2cold_read(path: Path):
    """(reader's result or None, outcome or None, message, log lines, read_field note).

    The reader (:func:`read_op2` / :func:`read_punch`) is what is compared; ``read_field``, the public route,
    is run too and its outcome noted (it merges coincident duplicate nodes of equal displacements and refuses
    those of different ones, :func:`hot2cold.io.field.merge_duplicates`)."""
    from hot2cold.errors import FieldError
    from hot2cold.io.field import read_field
    from hot2cold.io.nastran import read_op2, read_punch

    with Caught("hot2cold.io") as catch:
        try:
            result = read_punch(str(path)) if path.suffix.lower() == ".pch" else read_op2(str(path))
        except FieldError as exc:
            return None, "refused", str(exc), catch.lines, ""
        except Exception as exc:   # noqa: BLE001 - a crash is an outcome
            return None, "crash", f"{type(exc).__name__}: {exc}", catch.lines, ""
        lines = list(catch.lines)
        if path.suffix.lower() == ".pch":
            return result, None, "", lines, ""
        deck = next((p for p in (path.with_suffix(s) for s in (".bdf", ".dat")) if p.exists()), None)
        try:
            if result.points is None and deck is not None:
                field, how = read_field(path, points_from=deck), f" (positions from {deck.name})"
            else:
                field, how = read_field(path), ""
            merged = len(result.node_ids) - len(field.node_ids)
            note = f"read_field: {len(field.node_ids)} nodes{how}" + (
                f", {merged} coincident duplicates of equal displacement merged" if merged else "")
        except FieldError as exc:
            note = f"read_field refuses: {exc}"
        except Exception as exc:   # noqa: BLE001
            note = f"read_field CRASH: {type(exc).__name__}: {exc}"
        return result, None, "", lines, note.replace(str(path), path.name)


def compare(path: Path) -> dict:
    rel = path.relative_to(MODELS).as_posix()
    row = {"file": rel, "outcome": "", "why": "", "notes": []}
    src = path
    if path.suffix.lower() == ".pch":
        src = path.with_suffix(".op2")
        if not src.exists():
            src = None
    ref = dict(np.load(npz_path(src), allow_pickle=False)) if src is not None else {}
    got, outcome, message, lines, field_note = hot2cold_read(path)
    message = message.replace(str(path), path.name)
    left = _left_out_logged(lines)
    if left:
        row["notes"].append("hot2cold logged: " + "; ".join(left))
    if field_note:
        row["notes"].append(short(field_note, 240))
    if outcome == "crash":
        row.update(outcome="crash", why=short(message))
        return row
    if src is None:
        row.update(outcome="same" if got is not None else "refused",
                   why="no .op2 of this run to compare with" if got is not None else short(message))
        if got is not None:
            row["outcome"] = "not compared"
            row["notes"].append(f"hot2cold read {len(got.node_ids)} grids")
        return row
    if "error" in ref:
        row["notes"].append(f"pyNastran failed: {ref['error']}")
    if "geom_error" in ref:
        row["notes"].append(f"pyNastran's read_op2_geom failed ({short(str(ref['geom_error']), 120)}): "
                            f"results read without geometry, compared as the file holds them (CD frames)")
    if "ids" not in ref:
        what = str(ref.get("last_kind", "no displacement table"))
        if outcome == "refused":
            row.update(outcome="refused", why=short(message))
            row["notes"].append(f"pyNastran: no static displacements ({what})")
        else:
            row.update(outcome="no displacements in pyNastran",
                       why=f"pyNastran: {ref.get('error', what)}; hot2cold read {len(got.node_ids)} grids")
        return row
    if ref.get("last_kind") is not None and "analysis_code 1" not in str(ref["last_kind"]).replace(
            "analysis_code 10", "analysis_code 1"):
        row["notes"].append(f"pyNastran's last displacement table is {ref['last_kind']}; compared its last "
                            f"static one")
    if got is not None and "subcase" in ref:   # pyNastran's dict is not in file order: take its set
        want = f"subcase {int(ref['subcase'])}" + (f" load {float(np.float32(ref['load'])):g}" if "load" in ref
                                                    else "")
        steps = [i for i, n in enumerate(got.available) if n == want or n.startswith(want + " (")]
        if steps and steps[-1] != len(got.available) - 1:
            from hot2cold.io.nastran import read_op2, read_punch

            got = (read_punch if path.suffix.lower() == ".pch" else read_op2)(str(path), step=steps[-1])
            row["notes"].append(f"hot2cold's last set is not pyNastran's last table: compared {want}")
    ids, gt, t = ref["ids"], ref["gridtype"], ref["t"]
    kinds = {int(k): int((gt == k).sum()) for k in np.unique(gt) if k != 1}
    if kinds:
        names = {2: "scalar", 3: "extra"}
        row["notes"].append("pyNastran non-GRID points: " + ", ".join(f"{n} {names.get(k, f'type {k}')}"
                                                                       for k, n in kinds.items()))
        if not left and outcome is None:
            row["notes"].append("NOT LOGGED by hot2cold")
    if outcome == "refused" and got is None:
        row.update(outcome="refused", why=short(message))
        return row
    grid = gt == 1
    gids, gt_t = ids[grid], t[grid]
    h_ids = np.asarray(got.node_ids, dtype=np.int64)
    h_t = np.asarray(got.displacements, dtype=np.float64)
    if outcome == "refused":
        row.update(outcome="refused", why=short(message))
    if not np.array_equal(h_ids, gids):
        extra, missing = np.setdiff1d(h_ids, gids), np.setdiff1d(gids, h_ids)
        why = f"node count {len(h_ids)} vs pyNastran {len(gids)}"
        if len(missing):
            why += f"; {len(missing)} GRIDs missing in hot2cold (first {missing[:5].tolist()})"
        if len(extra):
            why += f"; {len(extra)} extra in hot2cold (first {extra[:5].tolist()})"
        if not len(missing) and not len(extra):
            why = "same ids in another order"
        if outcome is None:
            row.update(outcome="differs", why=why)
        else:
            row["notes"].append(why)
        return row
    raw = path.suffix.lower() == ".pch" or getattr(got, "points", None) is None
    basic_table = str(ref["table"]).startswith("B")     # B... tables: already in the basic frame
    expected = gt_t.copy()
    scale = max(float(np.abs(gt_t).max()) if gt_t.size else 0.0, 1e-30)
    if not raw and "pos_ids" in ref:
        order = np.argsort(ref["pos_ids"])
        at = order[np.searchsorted(ref["pos_ids"][order], gids).clip(0, len(order) - 1)]
        known = ref["pos_ids"][at] == gids
        cd = np.where(known, ref["pos_cd"][at], 0)
        xyz = ref["pos_xyz"][at]
        rotated = []
        for k, cid in enumerate(ref["cids"]):
            sel = cd == cid
            if sel.any() and not basic_table:
                expected[sel] = rotate_to_basic(gt_t[sel], xyz[sel], str(ref["cid_kind"][k]), ref["cid_origin"][k],
                                                ref["cid_beta"][k])
                rotated.append(f"{int(sel.sum())} in CD {int(cid)} ({ref['cid_kind'][k]})")
        if rotated:
            row["notes"].append("pyNastran's vectors rotated to basic: " + ", ".join(rotated))
        pts = np.asarray(got.points, dtype=np.float64)
        size = max(float(np.ptp(xyz[known], axis=0).max()) if known.any() else 0.0, 1e-30)
        off = np.abs(pts[known] - xyz[known]).max(initial=0.0) / size
        if off > 1e-5:
            row["notes"].append(f"positions differ by {off:.2g} of the model size")
        if not known.all():
            row["notes"].append(f"{int((~known).sum())} GRIDs without position in pyNastran")
    elif not raw:
        row["notes"].append(f"pyNastran positions: {ref.get('pos_error', 'none')}")
    err = np.abs(h_t - expected).max(initial=0.0) / scale
    err_raw = np.abs(h_t - gt_t).max(initial=0.0) / scale
    if outcome == "refused":
        row["notes"].append(f"its displacements: {'same' if err <= RTOL else f'differ {err:.2g}'} as pyNastran")
        return row
    if err <= RTOL:
        row["outcome"] = "same"
    elif err_raw <= RTOL:
        row.update(outcome="differs", why=f"hot2cold rotated but pyNastran's rotation differs ({err:.2g})")
    elif "pos_ids" not in ref and np.allclose(np.linalg.norm(h_t, axis=1), np.linalg.norm(gt_t, axis=1), rtol=0,
                                              atol=RTOL * scale):
        row.update(outcome="differs", why="output coordinate system: pyNastran read no geometry, so its vectors "
                                          "stay in the CD frames; hot2cold's basic-frame vectors have the same "
                                          "length at every grid")
    else:
        k = int(np.abs(h_t - expected).max(axis=1).argmax())
        row.update(outcome="differs", why=f"values: max |diff| {err:.2g} of max |u| (raw {err_raw:.2g}); grid "
                                          f"{int(gids[k])}: hot2cold {h_t[k].tolist()} pyNastran "
                                          f"{expected[k].tolist()}")
    row["notes"].append(f"{len(gids)} grids, {ref['table']}" + (" (CD frame, raw)" if raw else ""))
    return row


# --------------------------------------------------------------------------------------------------------
# Running, printing
# --------------------------------------------------------------------------------------------------------
ORDER = ("same", "differs", "refused", "crash", "no displacements in pyNastran", "not compared")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", type=Path, help="save the rows here")
    parser.add_argument("--show", type=Path, help="print the rows of a saved run")
    parser.add_argument("--extract", metavar="GITDIR", help="copy models/ at COMMIT from a pyNastran git dir")
    parser.add_argument("--pynastran", default=PYNASTRAN_PYTHON, help="python of the pyNastran environment")
    parser.add_argument("--only", default="", help="only files whose path holds this text")
    parser.add_argument("--worker", nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        return worker(args.worker[0], args.worker[1:])
    if args.show:
        show(json.loads(args.show.read_text()), ORDER)
        return 0
    if args.extract:
        extract(args.extract, COMMIT, "models", lambda name: name.lower().endswith(EXTENSIONS), CACHE)
    if not MODELS.is_dir():
        sys.stderr.write(f"{MODELS} is missing: run with --extract PYNASTRAN_GITDIR first\n")
        return 2
    files = sorted(p for p in MODELS.rglob("*") if p.suffix.lower() in (".op2", ".pch") and args.only in str(p))
    run_pynastran([p for p in files if p.suffix.lower() == ".op2"], args.pynastran)
    rows = [compare(p) for p in files]
    show(rows, ORDER)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    sys.exit(main())
