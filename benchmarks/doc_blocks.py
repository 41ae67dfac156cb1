"""The docs' generated blocks: where a benchmark script writes a table into a page of the docs.

A block is the text between two HTML comments, each on a line of its own::

    <!-- doc_tables: NAME -->
    | a | table | made by a script |
    <!-- /doc_tables -->

``NAME`` is a word (letters, digits, ``_``).  The markers may be indented (a table inside a list item); the
closing marker has the opening one's indentation, and the text between them is written with it.  The
comments are invisible in the rendered page and do not break a markdown table next to them.  One syntax for
every script: ``benchmarks/doc_tables.py`` (the bundled parts' tables), ``real_parts.py --doc`` and
``scale.py --doc``.

:func:`blocks` finds a page's blocks, :func:`names` lists their names, :func:`missing` says which of some
names a page lacks, :func:`replace` writes new text into a block (and :func:`replace_all` into several),
:func:`write` does a script's ``--doc``: every table into the block of its name in the pages given, an
error naming the block where a page has none (:class:`MissingBlocks`), never a silent no-op.
"""
from __future__ import annotations

import re
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The markers of block ``NAME``.
OPEN, CLOSE = "<!-- doc_tables: {name} -->", "<!-- /doc_tables -->"
#: A block: its opening marker (indentation, name), the text between, the closing marker at the same indentation.
_BLOCK = re.compile(r"^(( *)<!-- doc_tables: (\w+) -->\n)(.*?)(^\2<!-- /doc_tables -->)", re.S | re.M)


class MissingBlocks(LookupError):
    """Blocks that a page (or none of several pages) has: ``names``, ``pages``."""

    def __init__(self, names: list[str], pages: list[str]):
        self.names, self.pages = list(names), list(pages)
        super().__init__(f"no block {', '.join(self.names)} in {' or '.join(self.pages) or 'the page'} (between "
                         f"{OPEN.format(name='NAME')} and {CLOSE})")


@dataclass(frozen=True)
class Block:
    """One block of a page: its ``name``, the ``indent`` of its markers, its ``body`` (the text between the
    marker lines, each line with its indentation), and where that body is in the page's text
    (``text[start:end] == body``)."""

    name: str
    indent: str
    body: str
    start: int
    end: int


def blocks(text: str) -> list[Block]:
    """The blocks of a page's ``text``, in order."""
    return [Block(m.group(3), m.group(2), m.group(4), m.start(4), m.end(4)) for m in _BLOCK.finditer(text)]


def names(text: str) -> list[str]:
    """The names of the blocks of ``text``, in order."""
    return [b.name for b in blocks(text)]


def missing(text: str, wanted) -> list[str]:
    """Those of the names ``wanted`` that no block of ``text`` has, in their order."""
    present = set(names(text))
    return [n for n in wanted if n not in present]


def indented(body: str, indent: str) -> str:
    """``body`` as a block holds it: each non-blank line after ``indent``, ending in a newline (none when
    ``body`` is empty)."""
    if body and not body.endswith("\n"):
        body += "\n"
    return "".join(indent + line if line.strip() else line for line in body.splitlines(keepends=True))


def replace_all(text: str, bodies: dict[str, str]) -> str:
    """``text`` with the body of every block named in ``bodies`` replaced by its new text (indented as the
    block's markers: :func:`indented`), markers and everything outside the blocks kept.  A name with two blocks
    gets the text in both.  Raises :class:`MissingBlocks` for names no block of ``text`` has."""
    absent = missing(text, bodies)
    if absent:
        raise MissingBlocks(absent, [])
    return _BLOCK.sub(lambda m: m.group(1) + (indented(bodies[m.group(3)], m.group(2)) if m.group(3) in bodies
                                              else m.group(4)) + m.group(5), text)


def replace(text: str, name: str, body: str) -> str:
    """``text`` with the body of block ``name`` replaced by ``body`` (:func:`replace_all`)."""
    return replace_all(text, {name: body})


def shown(page: Path) -> str:
    """``page`` as a path from the repository when it lies in it, else as given."""
    page = Path(page).resolve()
    return str(page.relative_to(ROOT)) if page.is_relative_to(ROOT) else str(page)


def check(pages, table_names) -> None:
    """Raise :class:`MissingBlocks` for those of ``table_names`` that no page of ``pages`` has a block of
    (:func:`write` would refuse them): check before a long run, not after it.  A page that cannot be read
    raises ``OSError``."""
    present = {n for page in pages for n in names(Path(page).read_text(encoding="utf-8"))}
    absent = [n for n in table_names if n not in present]
    if absent:
        raise MissingBlocks(absent, [shown(p) for p in pages])


def write(pages, tables: dict[str, str]) -> list[tuple[str, list[str], bool]]:
    """A script's ``--doc``: each table of ``tables`` (name -> text) into its block in ``pages`` (the first
    page that has a block of its name).

    Every table must have its block in one of the pages, else :class:`MissingBlocks` names those without and
    no page is written.  A page is written only where its text changes, so a second run with the same tables
    leaves it as it is.  Returns, per page written into: the page (as :func:`shown`), the names of its blocks
    written, and whether its text changed."""
    texts = {Path(p): Path(p).read_text(encoding="utf-8") for p in pages}
    where = {}
    for page, text in texts.items():
        for n in names(text):
            where.setdefault(n, page)
    absent = [n for n in tables if n not in where]
    if absent:
        raise MissingBlocks(absent, [shown(p) for p in texts])
    written = []
    for page, text in texts.items():
        mine = {n: body for n, body in tables.items() if where[n] == page}
        if not mine:
            continue
        new = replace_all(text, mine)
        if new != text:
            page.write_text(new, encoding="utf-8")
        written.append((shown(page), list(mine), new != text))
    return written


def report(written: list[tuple[str, list[str], bool]]) -> str:
    """What :func:`write` did, one line per page: ``PAGE: wrote NAME, NAME`` (``(unchanged)`` where the page
    held these tables already)."""
    return "\n".join(f"{page}: wrote {', '.join(n)}{'' if changed else ' (unchanged)'}"
                     for page, n, changed in written)


def add_doc_argument(parser, tables: str) -> None:
    """A script's ``--doc PAGE [PAGE ...]`` option; ``tables`` says which tables it writes (for its help)."""
    parser.add_argument("--doc", type=Path, nargs="+", metavar="PAGE",
                        help=f"write {tables} into the blocks of their names in these pages of the docs "
                             f"({OPEN.format(name='NAME')} ... {CLOSE}); a table without its block is an error")


def doc_main(pages, tables: dict[str, str] | None = None, table_names=None) -> int:
    """``--doc`` for a script's ``main``: :func:`write` ``tables`` into ``pages`` and say which blocks it wrote
    (stdout); or with ``table_names`` instead, only :func:`check` that the pages have their blocks (before a
    run).  Returns the exit code: 0, or 2 with the blocks missing or the page unreadable said on stderr."""
    try:
        if tables is None:
            check(pages, table_names)
            return 0
        print(report(write(pages, tables)))
    except (MissingBlocks, OSError) as e:
        print(f"--doc: {e}", file=sys.stderr)
        return 2
    return 0
