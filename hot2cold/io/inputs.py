"""Input files refused before anything is read from them, with one wording for every caller.

The words are the command line's, which the "Bad input" table of the docs (``docs/guide/bad_input.md``) documents:
``WHAT not found: PATH; check the path``, ``WHAT PATH is a folder: give the file itself``, ``cannot read WHAT PATH:
permission denied; check its permissions`` and (where the caller asks) ``WHAT is empty: PATH``.  The error keeps the
caller's class: :class:`~hot2cold.errors.StepReadError` for STEP files, :class:`~hot2cold.errors.FieldError` for
fields, :class:`~hot2cold.errors.InputError` on the command line.
"""
from __future__ import annotations

import os
from pathlib import Path

from ..errors import InputError, one_line


def _unreadable(what: str, path, reason: str) -> str:
    return f"cannot read {what} {path}: {reason}"


def check_input_file(path: str | os.PathLike, what: str, error: type[InputError] = InputError,
                     empty: bool = False) -> Path:
    """``path`` as a Path, once it names a readable file; else ``error`` saying it is missing, a folder, not
    readable or (if ``empty``) empty.  ``what`` names the file in the message ("STEP file", "field file");
    the path is shown as given."""
    shown, path = os.fspath(path), Path(path)
    if not path.exists():
        raise error(f"{what} not found: {shown}; check the path")
    if path.is_dir():
        raise error(f"{what} {shown} is a folder: give the file itself")
    if not os.access(path, os.R_OK):
        raise error(_unreadable(what, shown, "permission denied; check its permissions"))
    if empty and path.stat().st_size == 0:
        raise error(f"{what} is empty: {shown}")
    return path


def read_input_bytes(path: str | os.PathLike, what: str, error: type[InputError] = InputError) -> bytes:
    """The bytes of the file ``path`` after :func:`check_input_file`; a failure of the read itself (permission
    refused although ``os.access`` allowed it, an I/O error) is ``error`` too, in the same words."""
    check_input_file(path, what, error)
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except PermissionError:
        raise error(_unreadable(what, os.fspath(path), "permission denied; check its permissions")) from None
    except OSError as exc:
        raise error(_unreadable(what, os.fspath(path), one_line(exc))) from None
