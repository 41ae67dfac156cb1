"""The STEP corpus: real parts from public repositories, listed in ``corpus/manifest.json``.

Run from the repository::

    python benchmarks/corpus.py fetch [--mirror DIR] [--quick]   # bring the missing files into corpus/cache/
    python benchmarks/corpus.py list [--quick]                   # one line a part: source, CAD system, faces, tags
    python benchmarks/corpus.py check                            # SHA-256 of every present file; the missing ones

The manifest is the one list of the whole corpus.  Each entry names a file (``name``), where it comes from
(``repo``, ``commit``, ``path``, ``licence``), its ``sha256`` and ``bytes``, what it holds as read by
:func:`hot2cold.kernel.step.read_step` (``cad_system``, ``solids``, ``faces``, ``surface_kinds``, ``valid``,
``tags``), whether it is in the ``quick`` subset, and its ``source``:

* ``repo-file``: committed in this repository, at ``local`` (``corpus/real_parts/NAME``);
* ``shared``: in the shared data folder beside the repository, ``../shared/data/real_parts/NAME``;
* ``fetch``: not committed; :func:`fetch_missing` brings it into ``corpus/cache/NAME`` (git-ignored), from a
  local mirror of the repository or from ``raw.githubusercontent.com``, and refuses any file whose SHA-256 is not
  the manifest's.

The licences are those of the originating repositories; the fetched files are never committed here.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import urllib.parse
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "corpus" / "manifest.json"
CACHE = ROOT / "corpus" / "cache"
SHARED = ROOT.parent / "shared" / "data" / "real_parts"
RAW_URL = "https://raw.githubusercontent.com/{repo}/{commit}/{path}"
SOURCES = ("repo-file", "shared", "fetch")
#: Seconds allowed for one download.
TIMEOUT = 60


# ---------------------------------------------------------------------------------------------- the manifest

def load_manifest(path: Path = MANIFEST) -> list[dict]:
    """The manifest's entries (a JSON list of objects, sorted by name)."""
    entries = json.loads(Path(path).read_text())
    if not isinstance(entries, list):
        raise ValueError(f"{path}: the manifest must be a JSON list")
    return entries


def select(entries: list[dict], quick: bool = False) -> list[dict]:
    """``entries``, or only those of the quick subset."""
    return [e for e in entries if e.get("quick")] if quick else list(entries)


def local_path(entry: dict, root: Path = ROOT) -> Path:
    """Where the file of ``entry`` is on this machine (whether or not it is there yet)."""
    source = entry["source"]
    if source == "repo-file":
        return root / entry.get("local", Path("corpus") / "real_parts" / entry["name"])
    if source == "shared":
        return root.parent / "shared" / "data" / "real_parts" / entry["name"]
    if source == "fetch":
        return root / "corpus" / "cache" / entry["name"]
    raise ValueError(f"{entry['name']}: unknown source {source!r}: one of {SOURCES}")


def corpus_parts(quick: bool = False, fetch: bool = False) -> list[Path]:
    """Local paths of the corpus files present, in manifest order (the quick subset if ``quick``).

    With ``fetch``, the missing fetchable files are first brought into the cache (:func:`fetch_missing`, from
    the network); those that cannot be had are left out.
    """
    entries = select(load_manifest(), quick)
    if fetch:
        fetch_missing(entries)
    return [p for p in map(local_path, entries) if p.is_file()]


# ------------------------------------------------------------------------------------------------- fetching

def sha256_file(path: Path) -> str:
    """Hex SHA-256 of the file at ``path``."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def git_dir(mirror: Path, repo: str) -> Path | None:
    """The bare git directory of ``repo`` (``owner/name``) inside ``mirror``, laid out as ``owner+name/...``;
    None when the mirror does not hold it."""
    top = Path(mirror) / repo.replace("/", "+")
    if not top.is_dir():
        return None
    for candidate in (top, *sorted(p for p in top.rglob("*") if p.is_dir())):
        if (candidate / "HEAD").is_file() and (candidate / "objects").is_dir():
            return candidate
    return None


def from_mirror(entry: dict, mirror: Path) -> bytes | None:
    """The bytes of ``entry``'s file at its commit in the local mirror; None when the mirror lacks it."""
    gdir = git_dir(mirror, entry["repo"])
    if gdir is None:
        return None
    done = subprocess.run(["git", "--git-dir", str(gdir), "show", f"{entry['commit']}:{entry['path']}"],
                          capture_output=True)
    return done.stdout if done.returncode == 0 else None


def download(entry: dict) -> bytes:
    """The bytes of ``entry``'s file from ``raw.githubusercontent.com`` at its commit."""
    url = RAW_URL.format(repo=entry["repo"], commit=entry["commit"], path=urllib.parse.quote(entry["path"]))
    with urllib.request.urlopen(url, timeout=TIMEOUT) as response:
        return response.read()


def store(data: bytes, target: Path) -> None:
    """Write ``data`` to ``target`` whole or not at all (a temporary file in the same folder, renamed)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def fetch_missing(entries: list[dict], mirror: Path | None = None) -> list[tuple[str, str]]:
    """Bring every missing ``fetch`` entry of ``entries`` into the cache.

    Each file comes from the local git ``mirror`` when given and holding it (a folder of ``owner+name/`` bare
    git directories), else from ``raw.githubusercontent.com``.  A file whose SHA-256 is not the manifest's is
    refused (not written).  Returns ``(name, outcome)`` for every ``fetch`` entry, ``outcome`` one of
    ``present``, ``mirror``, ``download`` or ``error: <one line>``.
    """
    outcomes = []
    for entry in entries:
        if entry["source"] != "fetch":
            continue
        name, target = entry["name"], local_path(entry)
        if target.is_file() and sha256_file(target) == entry["sha256"]:
            outcomes.append((name, "present"))
            continue
        data, how = (from_mirror(entry, mirror), "mirror") if mirror is not None else (None, "")
        if data is None:
            try:
                data, how = download(entry), "download"
            except OSError as exc:
                outcomes.append((name, f"error: cannot download {entry['repo']}:{entry['path']}: {exc}"))
                continue
        digest = hashlib.sha256(data).hexdigest()
        if digest != entry["sha256"]:
            outcomes.append((name, f"error: SHA-256 mismatch from {how} ({digest[:12]}... is not "
                                   f"{entry['sha256'][:12]}...): refused"))
            continue
        store(data, target)
        outcomes.append((name, how))
    return outcomes


def check(entries: list[dict]) -> list[tuple[str, str]]:
    """``(name, status)`` for every entry: ``ok`` (present, SHA-256 as listed), ``mismatch`` or ``missing``."""
    out = []
    for entry in entries:
        path = local_path(entry)
        if not path.is_file():
            out.append((entry["name"], "missing"))
        else:
            out.append((entry["name"], "ok" if sha256_file(path) == entry["sha256"] else "mismatch"))
    return out


# ------------------------------------------------------------------------------------------------------- CLI

def describe(entry: dict) -> str:
    """One line for ``entry``: name, source, CAD system, solids / faces, tags, and a mark if missing."""
    mark = " " if local_path(entry).is_file() else "-"
    quick = "q" if entry.get("quick") else " "
    return (f"{mark}{quick} {entry['name']:<44} {entry['source']:<9} {entry.get('cad_system', ''):<28} "
            f"{entry.get('solids', 0):>4} / {entry.get('faces', 0):<5} {','.join(entry.get('tags', []))}")


def main(argv: list[str] | None = None) -> int:
    """The command line; returns the exit code (1 when a file is missing, refused or does not match)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    fetch = sub.add_parser("fetch", help="bring the missing files into corpus/cache/")
    fetch.add_argument("--mirror", type=Path, help="a folder of owner+name/ bare git mirrors to take them from")
    fetch.add_argument("--quick", action="store_true", help="only the quick subset")
    listing = sub.add_parser("list", help="one line a part ('-': not present, 'q': quick subset)")
    listing.add_argument("--quick", action="store_true", help="only the quick subset")
    sub.add_parser("check", help="verify the SHA-256 of every present file; report the missing ones")
    args = parser.parse_args(argv)

    entries = load_manifest()
    if args.command == "fetch":
        outcomes = fetch_missing(select(entries, args.quick), args.mirror)
        for name, outcome in outcomes:
            if outcome != "present":
                print(f"{name}: {outcome}")
        counts = {k: sum(o == k for _, o in outcomes) for k in ("present", "mirror", "download")}
        errors = sum(o.startswith("error") for _, o in outcomes)
        print(f"{len(outcomes)} fetchable: {counts['present']} already present, {counts['mirror']} from the mirror, "
              f"{counts['download']} downloaded, {errors} failed")
        return 1 if errors else 0
    if args.command == "list":
        chosen = select(entries, args.quick)
        for entry in chosen:
            print(describe(entry))
        print(f"{len(chosen)} parts")
        return 0
    results = check(entries)
    for name, status in results:
        if status != "ok":
            print(f"{name}: {status}")
    ok = sum(s == "ok" for _, s in results)
    print(f"{len(results)} parts: {ok} ok, {sum(s == 'missing' for _, s in results)} missing, "
          f"{sum(s == 'mismatch' for _, s in results)} mismatched")
    return 0 if ok == len(results) else 1


if __name__ == "__main__":
    sys.exit(main())
