"""The ``hot2cold`` command: :func:`main` (``hot2cold morph``, ``hot2cold batch``).

The only part of hot2cold that talks to the terminal.  :mod:`.commands` parses and runs the commands,
:mod:`.batch` runs many morphs from a jobs file.
"""
from .commands import main

__all__ = ["main"]
