"""What the benchmarks comparing hot2cold's readers with another project's reader share
(``nastran_models.py`` against pyNastran, ``frd_files.py`` against ccx2paraview): the test files of a
repository at a pinned commit copied out of git, the reference reader run in its own environment (one process
for all files; a file that kills it is recorded and skipped), hot2cold's log caught while it reads a file, and
the rows printed.

Standard library and numpy only: the reference environments import it too.
"""
from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path
from typing import Callable

import numpy as np


def extract(gitdir: str, commit: str, folder: str, keep: Callable[[str], bool], cache: Path) -> None:
    """Copy the files under ``folder`` of ``gitdir`` at ``commit`` whose path ``keep`` accepts into ``cache``
    (same relative paths; files already there are kept); blobs missing from a partial mirror are listed."""
    listing = subprocess.run(["git", "-C", gitdir, "ls-tree", "-r", commit, folder], capture_output=True,
                             text=True, check=True).stdout
    for line in listing.splitlines():
        meta, name = line.split("\t", 1)
        target = cache / name
        if not keep(name) or target.exists():
            continue
        blob = subprocess.run(["git", "-C", gitdir, "cat-file", "blob", meta.split()[2]], capture_output=True,
                              check=False)
        if blob.returncode:
            sys.stdout.write(f"missing in {gitdir}: {name}\n")
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(blob.stdout)


def run_reference(files: list[Path], python: str, script: str, out_dir: Path,
                  npz_path: Callable[[Path], Path], who: str) -> None:
    """Run ``script --worker OUT_DIR FILE ...`` with the reference environment's ``python`` for the ``files``
    whose ``npz_path`` is missing.  The worker reads them in order and writes one ``.npz`` each; where its
    process dies, the first file it left is recorded as the cause (an ``error`` naming ``who``) and the rest run
    again."""
    todo = [f for f in files if not npz_path(f).exists()]
    out_dir.mkdir(parents=True, exist_ok=True)
    while todo:
        proc = subprocess.run([python, script, "--worker", str(out_dir), *map(str, todo)], capture_output=True,
                              text=True, check=False)
        rest = [f for f in todo if not npz_path(f).exists()]
        if rest:
            np.savez_compressed(npz_path(rest[0]), error=np.array(
                f"{who} process died (rc {proc.returncode}): {proc.stderr.strip().splitlines()[-1:]}"))
            rest = rest[1:]
        todo = rest


def work(out_dir: str, files: list[str], read_one: Callable[[str], dict], npz_path: Callable[[Path], Path]) -> int:
    """The worker's side of :func:`run_reference`, in the reference environment: ``read_one(path)`` (a dict of
    arrays) of each file written to ``out_dir`` under the name of its ``npz_path``; an exception becomes the
    file's ``error``.  Each file's name is printed when written."""
    for path in files:
        target = Path(out_dir) / npz_path(Path(path)).name
        try:
            arrays = read_one(path)
        except Exception as exc:
            arrays = {"error": np.array(f"{type(exc).__name__}: {exc}".splitlines()[0][:300] if str(exc)
                                        else type(exc).__name__)}
        np.savez_compressed(target, **arrays)
        sys.stdout.write(f"{target.name}\n")
        sys.stdout.flush()
    return 0


class Caught:
    """Collects the log records of the logger ``name`` (at INFO and above) while the ``with`` block runs:
    ``records``, ``(levelname, message)`` each; the logger's level is restored after."""

    def __init__(self, name: str):
        self.logger = logging.getLogger(name)
        self.records: list[tuple[str, str]] = []

    def __enter__(self) -> Caught:
        caught = self

        class _Handler(logging.Handler):
            def emit(self, record):
                caught.records.append((record.levelname, record.getMessage()))

        self.handler, self.level = _Handler(logging.INFO), self.logger.level
        self.logger.setLevel(logging.INFO)
        self.logger.addHandler(self.handler)
        return self

    def __exit__(self, *exc) -> None:
        self.logger.removeHandler(self.handler)
        self.logger.setLevel(self.level)

    @property
    def lines(self) -> list[str]:
        """The messages, in order."""
        return [message for _, message in self.records]


def short(text, n: int = 200) -> str:
    """``text`` on one line (its whitespace runs made single blanks), cut to ``n`` characters."""
    text = " ".join(str(text).split())
    return text if len(text) <= n else text[:n - 3] + "..."


def show(rows: list[dict], order: tuple[str, ...], tag: Callable[[dict], str] | None = None,
         out=sys.stdout) -> None:
    """Print ``rows`` (``file``, ``outcome``, ``why``, ``notes``), each with ``tag(row)`` before its reason where
    given, then how many rows have each outcome of ``order``, and the total."""
    width = max(len(r["file"]) for r in rows)
    for r in rows:
        middle = f"[{tag(r)}]  " if tag is not None else ""
        out.write(f"{r['file']:<{width}}  {r['outcome']:<8}  {middle}{r['why']}\n")
        for note in r["notes"]:
            out.write(f"{'':<{width}}    - {note}\n")
    out.write("\n")
    for kind in order:
        n = sum(r["outcome"] == kind for r in rows)
        if n:
            out.write(f"{kind}: {n}\n")
    out.write(f"total: {len(rows)}\n")
