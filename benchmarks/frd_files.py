"""hot2cold's CalculiX ``.frd`` reader against ccx2paraview on the ``.frd`` files of CalculiX's own test suite.

Run from the repository (issue 39)::

    # ccx2paraview (and the VTK it imports) in an environment of its own, as the pyNastran one
    python3 -m venv /work/venv-ccx2paraview
    /work/venv-ccx2paraview/bin/pip install ccx2paraview==3.2.0 vtk
    # the test suite's reference results (``test/*.frd.ref``, written by ccx 2.21) at the pinned commit
    python benchmarks/frd_files.py --extract GITDIR        # a clone or mirror of ISCPC/CalculiX-ccx-test
    python benchmarks/frd_files.py --json out/frd_files.json
    python benchmarks/frd_files.py --show out/frd_files.json --doc docs/benchmarks/frd_files.md

For each ``.frd``:

(a) ccx2paraview (its ``FRD`` parser, the one its converter uses), in its environment (this file run with
    ``--worker``), writes to ``CACHE/ccx2paraview_npz/<file>.npz`` the node block (numbers, coordinates) and
    every ``DISP`` block it reads (its ``U``): the header's step and value, the node numbers and D1-D3.  It
    fills the nodes a block leaves out with zeros.
(b) hot2cold reads every DISP block of the file (:meth:`hot2cold.io.frd.FrdFile.result`), and the file as a
    user does, :func:`hot2cold.io.field.read_field` (the last block), with its log lines caught;
(c) the two are compared block by block: the same number of DISP blocks with the same step and value; in
    each, hot2cold's nodes among ccx2paraview's, ccx2paraview's other nodes at zero, the same D1-D3 and the
    same coordinates (both read the same 12-character numbers: equal, not close).

Outcomes: ``same``; ``differs`` (why); ``refused`` (hot2cold's message, e.g. a file without displacements);
``crash`` (an exception other than FieldError); ``reference fails`` (ccx2paraview cannot read the file;
hot2cold's reading is reported).  Each row says the file's element kinds and its DISP blocks' steps.

``--doc PAGE`` writes the tables (the outcomes by element kind, and one row per file) into the page's blocks
:data:`DOC_PAGES` (``benchmarks/doc_blocks.py``).
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import sys
from pathlib import Path

import numpy as np

if str(Path(__file__).resolve().parent) not in sys.path:      # doc_blocks, beside this one
    sys.path.insert(0, str(Path(__file__).resolve().parent))
import doc_blocks  # noqa: E402
from reference_runs import Caught, extract, run_reference, short, show, work  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: ISCPC/CalculiX-ccx-test commit whose ``test/*.frd.ref`` are read ("Fix check.sh for ccx_2.21").
COMMIT = "604a5b4b5b5ca5aa8a1c233ce90faa7960d55b4d"
CACHE = ROOT / "corpus" / "cache" / "ccx_tests" / COMMIT
FILES = CACHE / "test"
NPZ = CACHE / "ccx2paraview_npz"
CCX2PARAVIEW_PYTHON = "/work/venv-ccx2paraview/bin/python"
#: float32's relative rounding (2**-23 and some slack): the precision of ccx2paraview's coordinates.
FLOAT32 = 2.0 ** -22


# --------------------------------------------------------------------------------------------------------
# The ccx2paraview side: runs in its environment, imports nothing of hot2cold.
# --------------------------------------------------------------------------------------------------------
def _worker_one(path: str) -> dict:
    from ccx2paraview import common

    logging.disable(logging.CRITICAL)
    with open(path, encoding="latin-1") as handle:
        frd = common.FRD(handle)
        frd.parse_mesh()
        frd.count_increments()
        out: dict = {}
        nodes = sorted(common.renumbered_nodes.items())
        out["node_ids"] = np.array([n for n, _ in nodes], dtype=np.int64)
        out["node_xyz"] = np.array([frd.node_block.points.GetPoint(k) for _, k in nodes], dtype=np.float64)
        blocks = []
        for step, inc in frd.steps_increments:
            for block in frd.parse_results(step, inc):
                if block.name == "U":
                    blocks.append(block)
    out["steps"] = np.array([b.step for b in blocks], dtype=np.int64)
    out["values"] = np.array([b.inc for b in blocks], dtype=np.float64)
    for k, block in enumerate(blocks):
        ids = np.array(sorted(block.results), dtype=np.int64)
        out[f"ids_{k}"] = ids
        out[f"d_{k}"] = np.array([block.results[i][:3] for i in ids], dtype=np.float64).reshape(-1, 3)
    return out


def worker(out_dir: str, files: list[str]) -> int:
    return work(out_dir, files, _worker_one, npz_path)


# --------------------------------------------------------------------------------------------------------
# The hot2cold side
# --------------------------------------------------------------------------------------------------------
def npz_path(frd: Path) -> Path:
    return NPZ / (frd.name + ".npz")


def _kinds(path: Path) -> str:
    """The element kinds of the file's element blocks (CalculiX's names), or "no elements"."""
    from hot2cold.io.frd import FrdFile

    try:
        kinds = FrdFile.read(path).element_kinds()
    except Exception:  # the comparison says what fails to read
        return "?"
    return ",".join(sorted(kinds)) or "no elements"


def _blocks_against(ours: list, ref: dict) -> list[str]:
    """What differs between hot2cold's DISP blocks and ccx2paraview's (empty: nothing), and notes."""
    why, notes = [], []
    if len(ref["steps"]) != len(ours):
        return [f"{len(ours)} DISP blocks against ccx2paraview's {len(ref['steps'])}"], notes
    for k, r in enumerate(ours):
        ids, d = ref[f"ids_{k}"], ref[f"d_{k}"]
        if (r.step, r.value) != (int(ref["steps"][k]), float(ref["values"][k])):
            why.append(f"block {k}: step/value {r.step}/{r.value:g} against {ref['steps'][k]}/{ref['values'][k]:g}")
            continue
        at = np.searchsorted(ids, r.node_ids).clip(0, len(ids) - 1)
        if not np.array_equal(ids[at], r.node_ids):
            why.append(f"block {k}: {int((ids[at] != r.node_ids).sum())} of hot2cold's nodes not in ccx2paraview's")
            continue
        rest = np.ones(len(ids), bool)
        rest[at] = False
        if np.abs(d[rest]).max(initial=0.0) > 0:
            why.append(f"block {k}: nodes hot2cold leaves out are not zero in ccx2paraview")
        if rest.any():
            notes.append(f"block {k}: {int(rest.sum())} nodes without a value (ccx2paraview: zero)")
        if not np.array_equal(r.values[:, :3], d[at]):
            worst = float(np.abs(r.values[:, :3] - d[at]).max())
            why.append(f"block {k}: D1-D3 differ by up to {worst:.3g}")
        pos = np.searchsorted(ref["node_ids"], r.node_ids).clip(0, len(ref["node_ids"]) - 1)
        # ccx2paraview keeps the coordinates in VTK's float32 points: equal to float32's rounding
        size = float(np.abs(r.points).max(initial=0.0))
        if not np.allclose(ref["node_xyz"][pos], r.points, rtol=FLOAT32, atol=FLOAT32 * size):
            worst = float(np.abs(ref["node_xyz"][pos] - r.points).max())
            why.append(f"block {k}: coordinates differ by up to {worst:.3g} (the model's size {size:.3g})")
    return why, notes


def _user_against(user, last) -> tuple[list[str], list[str]]:
    """Whether ``read_field``'s reading is the last DISP block (nodes at one position with one value merged)."""
    order = np.argsort(last.node_ids)
    at = order[np.searchsorted(last.node_ids, user.node_ids, sorter=order).clip(0, len(order) - 1)]
    if not (np.array_equal(last.node_ids[at], user.node_ids) and np.array_equal(user.displacements,
                                                                               last.values[at, :3])):
        return ["read_field's default is not the last DISP block"], []
    if len(user) < len(last.node_ids):
        return [], [f"read_field merged {len(last.node_ids) - len(user)} nodes at the position of another with the "
                    f"same displacement"]
    return [], []


def compare(path: Path) -> dict:
    from hot2cold.errors import FieldError
    from hot2cold.io.field import read_field
    from hot2cold.io.frd import FrdFile

    row = {"file": path.name.removesuffix(".ref"), "outcome": None, "why": "", "notes": [], "kinds": _kinds(path),
           "blocks": []}
    ref = dict(np.load(npz_path(path), allow_pickle=False))
    ours, user = [], None
    with Caught("hot2cold") as caught:
        try:
            frd = FrdFile.read(path)
            ours = [frd.result("DISP", k) for k in range(frd.count("DISP"))]
            user = read_field(path)
        except FieldError as exc:
            row.update(outcome="refused", why=short(exc, 220))
        except Exception as exc:
            row.update(outcome="crash", why=short(f"{type(exc).__name__}: {exc}", 220))
            return row
    row["notes"] += [f"{level} {message}" for level, message in caught.records if level == "WARNING"]
    row["blocks"] = [r.label for r in ours]
    if "error" in ref:
        row["notes"].append(f"ccx2paraview: {ref['error']}")
        if row["outcome"] is None:
            row.update(outcome="reference fails", why=f"hot2cold read {len(ours)} DISP block(s)")
        return row
    why, notes = _blocks_against(ours, ref)
    if user is not None:
        more, also = _user_against(user, ours[-1])
        why, notes = why + more, notes + also
        row["notes"].append(f"{len(ours)} DISP block(s), {len(user)} nodes read; read_field takes: {user.result_set}")
    row["notes"] += notes
    if row["outcome"] == "refused":       # read_field's refusal; its blocks against ccx2paraview's
        if ours or len(ref["steps"]):
            row["notes"].append(f"its {len(ours)} DISP block(s) against ccx2paraview's: "
                                f"{'; '.join(why) if why else 'the same'}")
        return row
    row.update(outcome="differs" if why else "same", why="; ".join(why))
    return row


# --------------------------------------------------------------------------------------------------------
# Running, printing
# --------------------------------------------------------------------------------------------------------
ORDER = ("same", "differs", "refused", "crash", "reference fails")
#: The blocks of the docs that ``--doc`` writes (:func:`doc_tables`), each with its page.
DOC_PAGES = {"frd_files_outcomes": ROOT / "docs" / "benchmarks" / "frd_files.md",
             "frd_files_rows": ROOT / "docs" / "benchmarks" / "frd_files.md"}


def _tag(row: dict) -> str:
    """What :func:`reference_runs.show` prints before a row's reason: the file's element kinds."""
    return row["kinds"]


def _cell(text: str) -> str:
    return text.replace("|", "/").replace(str(FILES) + "/", "")


def doc_tables(rows: list[dict]) -> dict[str, str]:
    """The tables for the docs: ``frd_files_outcomes``, files and DISP blocks by outcome and by the element
    kinds of the file; ``frd_files_rows``, one row per file (its kinds, DISP blocks, outcome and why)."""
    kinds = sorted({k for r in rows for k in r["kinds"].split(",")})
    head = "| outcome | files | DISP blocks | " + " | ".join(kinds) + " |"
    lines = [head, "|---|---:|---:|" + "---:|" * len(kinds)]
    for outcome in ORDER:
        some = [r for r in rows if r["outcome"] == outcome]
        if some:
            per_kind = [str(sum(k in r["kinds"].split(",") for r in some)) for k in kinds]
            lines.append(f"| {outcome} | {len(some)} | {sum(len(r['blocks']) for r in some)} | "
                         + " | ".join(per_kind) + " |")
    lines.append(f"| total | {len(rows)} | {sum(len(r['blocks']) for r in rows)} | "
                 + " | ".join(str(sum(k in r["kinds"].split(",") for r in rows)) for k in kinds) + " |")
    files = ["| file | element kinds | DISP blocks | last block | outcome | why |", "|---|---|---:|---|---|---|"]
    for r in rows:
        last = r["blocks"][-1] if r["blocks"] else ""
        files.append(f"| `{r['file']}` | {r['kinds']} | {len(r['blocks'])} | {_cell(last)} | {r['outcome']} | "
                     f"{_cell(r['why'])} |")
    return {"frd_files_outcomes": "\n".join(lines) + "\n", "frd_files_rows": "\n".join(files) + "\n"}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", type=Path, help="save the rows here")
    parser.add_argument("--show", type=Path, help="print the rows of a saved run")
    parser.add_argument("--extract", metavar="GITDIR", help="copy test/*.frd.ref at COMMIT from a git dir")
    parser.add_argument("--reference", default=CCX2PARAVIEW_PYTHON, help="python of the ccx2paraview environment")
    parser.add_argument("--only", default="", help="only files whose name holds this text")
    parser.add_argument("--worker", nargs="+", help=argparse.SUPPRESS)
    doc_blocks.add_doc_argument(parser, "the outcomes and the files' table (blocks frd_files_outcomes, _rows)")
    args = parser.parse_args(argv)
    if args.worker:
        return worker(args.worker[0], args.worker[1:])
    if args.show:
        rows = json.loads(args.show.read_text())
        show(rows, ORDER, _tag)
        return doc_blocks.doc_main(args.doc, doc_tables(rows)) if args.doc else 0
    if args.doc and doc_blocks.doc_main(args.doc, table_names=list(DOC_PAGES)):
        return 2
    if args.extract:
        extract(args.extract, COMMIT, "test", lambda name: name.endswith(".frd.ref"), CACHE)
    if not FILES.is_dir():
        sys.stderr.write(f"{FILES} is missing: run with --extract GITDIR first\n")
        return 2
    files = sorted(p for p in FILES.glob("*.frd.ref") if args.only in p.name)
    run_reference(files, args.reference, __file__, NPZ, npz_path, "ccx2paraview")
    rows = [compare(p) for p in files]
    show(rows, ORDER, _tag)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1))
    return doc_blocks.doc_main(args.doc, doc_tables(rows)) if args.doc else 0


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    sys.exit(main())
