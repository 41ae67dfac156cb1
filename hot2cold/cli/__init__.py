"""The ``hot2cold`` command: :func:`main` (``hot2cold morph``, ``hot2cold batch``).

The only part of hot2cold that talks to the terminal.  :mod:`.commands` parses and runs the commands,
:mod:`.options` is the table of the morph options both commands share, :mod:`.run` is one morph run (report,
check, STEP), :mod:`.batch` runs many morphs from a jobs file in :mod:`.workers` processes.

This package imports nothing at import time: a "spawn" batch worker imports it before its numeric
libraries are set to one thread (:mod:`.workers`), both for the pool's initializer and when it runs the
``hot2cold`` console script (``from hot2cold.cli import main``) again as its main module.
"""


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``hot2cold`` console script; returns the exit code (:func:`.commands.main`)."""
    from .commands import main

    return main(argv)


__all__ = ["main"]
