"""Outputs written whole or not at all: a temporary file beside the target, then ``os.replace``."""
from __future__ import annotations

import os
import uuid
from pathlib import Path
from typing import Callable

from ..errors import OutputError


def write_atomically(jobs: list[tuple[Path, Callable[[str], object]]]) -> None:
    """Run each ``write(tmp)`` of ``jobs`` (path, write) into a temporary file beside its path (with the
    umask's permissions), then rename them all; on any failure remove the temporaries and raise
    :class:`OutputError` (an OSError) or let the writer's own error through."""
    temps, current = [], jobs[0][0] if jobs else None
    try:
        for path, write in jobs:
            path = Path(path)
            current = path
            folder = path.parent if str(path.parent) else Path(".")
            # opened with open(): unlike mkstemp's 0600, the file gets the umask's permissions
            tmp = folder / f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp"
            temps.append(tmp)           # before it exists: an interrupt right after open() leaves nothing
            with open(tmp, "xb"):
                pass
            write(str(tmp))
        for (path, _), tmp in zip(jobs, temps):
            current = path
            os.replace(tmp, path)
    except OSError as exc:
        raise OutputError(f"cannot write {current}: {exc.strerror or exc}") from exc
    finally:
        for tmp in temps:
            if os.path.exists(tmp):
                os.unlink(tmp)
