"""The kernel's volume integrations in a second process, beside the morph (``Settings.kernel_process``).

OCP holds Python's global interpreter lock through each kernel call, so no thread can integrate a solid's
volume while the morph's own work goes on (two integrations in two threads take as long as one after the
other).  A second process can.  On a part of hundreds of faces the morph works a face at a time and leaves a
second core idle, and the volumes of the hot and the cold solids (``BRepGProp`` to
:data:`~hot2cold.kernel.validity.GPROP_EPS`, the slowest single kernel call of such a part) are needed only
when the cold part is checked: the hot one's is integrated while the field is classified and fitted, the cold
one's while the cold part's grids are checked.

The second process is this module's :func:`serve`, started at most once per morph (:class:`KernelSide`);
it reads a binary BRep file per request (``BinTools``: the doubles as they are, so a volume is the one this
process would integrate, to the bit) and answers with a line of text that names the request (:func:`serve`).
Whatever goes wrong with it (it cannot start, it dies, it answers what is no volume), the volumes are integrated
in this process instead, as without it, and the morph goes on.
"""
from __future__ import annotations

import logging
import os
import queue
import shutil
import subprocess
import sys
import tempfile
import threading

from OCP.BinTools import BinTools
from OCP.TopAbs import TopAbs_SOLID
from OCP.TopoDS import TopoDS_Shape

from .explore import shape_map
from .validity import solid_volumes

log = logging.getLogger(__name__)


class Volumes:
    """The volumes of a shape's solids, asked for (:meth:`KernelSide.volumes`); :meth:`result` waits for them."""

    def __init__(self, shape, side: KernelSide | None = None, request: int = -1,
                 volumes: list[float] | None = None):
        self._shape, self._side, self._request, self._volumes = shape, side, request, volumes

    @property
    def known(self) -> bool:
        """The volumes are in (:meth:`result` returns at once)."""
        return self._volumes is not None

    def result(self) -> list[float]:
        """The volume (mm^3) of each solid of the shape, in :func:`~hot2cold.kernel.explore.shape_map`'s
        order: the second process's answer, or integrated here where it gives none."""
        if self._volumes is None:
            answer = self._side.answer(self._request) if self._side is not None else None
            if answer is None or len(answer) != len(shape_map(self._shape, TopAbs_SOLID)):
                answer = solid_volumes(self._shape)           # none, or not one a solid: integrated here
            self._volumes, self._shape, self._side = answer, None, None
        return self._volumes


#: The second process's first line, once it has imported the kernel and takes requests.
_READY = "ready"
#: The folder that holds this ``hot2cold`` package, and the second process's program: it imports the package
#: from there, the one this process runs (``python -m`` would put the working directory first, and a checkout of
#: another version there would answer instead), and takes the folder off the path again before anything else
#: is imported (an installed package's folder is site-packages, which must not come before the standard library).
_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_CHILD = ("import sys; sys.path.insert(0, {root!r}); import hot2cold; sys.path.pop(0); "
          "from hot2cold.kernel.side import serve; serve(sys.stdin, sys.stdout)")


class KernelSide:
    """A second process that integrates solids' volumes while this one goes on (see the module docstring);
    ``start=False``: none until :meth:`start`, every volume integrated here when asked for until then.  A
    context manager: leaving it ends the process and removes its files.

    A thread reads the process's answers as they come.  A volume asked for before the process is ready (it
    takes about as long to import the kernel as this one did: a small part's morph may be done by then) is
    integrated here instead, its answer dropped when it comes."""

    def __init__(self, start: bool = True):
        self._process: subprocess.Popen | None = None
        self._folder: str | None = None
        self._asked = 0
        self._answers: dict[int, list[float] | None] = {}
        self._lines: queue.Queue[str | None] = queue.Queue()
        self._ready = False
        if start:
            self.start()

    def start(self) -> None:
        """Start the second process (if it is not there yet)."""
        if self._process is not None:
            return
        try:
            self._folder = tempfile.mkdtemp(prefix="hot2cold-side-")
            self._process = subprocess.Popen([sys.executable, "-c", _CHILD.format(root=_ROOT)], stdin=subprocess.PIPE,
                                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        except OSError as exc:
            self._stop(f"it could not start ({exc})")
        else:
            threading.Thread(target=_read_lines, args=(self._process.stdout, self._lines), daemon=True,
                             name="hot2cold-side").start()

    @property
    def running(self) -> bool:
        """Whether the second process is there (ready or still starting)."""
        return self._process is not None

    def ready(self, wait: float = 0.0) -> bool:
        """Whether the second process takes requests, waiting up to ``wait`` seconds for it to say so."""
        try:
            while not self._ready and self._process is not None:
                self._take(block=True, timeout=wait)
        except queue.Empty:
            pass
        return self._ready and self._process is not None

    def volumes(self, shape) -> Volumes:
        """The volumes of ``shape``'s solids, integrated by the second process while this one goes on, or
        here and now where there is none."""
        if self._process is not None:
            path = os.path.join(self._folder, f"{self._asked}.bin")
            try:
                if BinTools.Write_s(shape, path):
                    self._process.stdin.write(path + "\n")
                    self._process.stdin.flush()
                    self._asked += 1
                    return Volumes(shape, self, self._asked - 1)
                self._stop("the shape could not be written for it")
            except Exception as exc:      # noqa: BLE001 - a pipe, a file or the kernel's writer: integrated here
                self._stop(f"it could not be asked ({exc})")
        return Volumes(shape, volumes=solid_volumes(shape))

    def answer(self, request: int) -> list[float] | None:
        """The answer to ``request``: the volumes, or None where the second process gives none (it failed, or
        it is not ready yet: the caller integrates them; or it was never asked)."""
        if not 0 <= request < self._asked:
            return None
        self._take(block=False)
        if not self._ready and self._process is not None:
            log.debug("volumes %d integrated in this process: the second process is not ready yet", request)
        while request not in self._answers and self._process is not None and self._ready:
            self._take(block=True)
        return self._answers.pop(request, None)

    def _take(self, block: bool, timeout: float | None = None) -> None:
        """Read the answers that came (``block``: wait for one more line, up to ``timeout`` seconds, else
        :class:`queue.Empty`)."""
        while self._process is not None:
            try:
                line = self._lines.get(block=block, timeout=timeout if block else None)
            except queue.Empty:
                if block:
                    raise
                return
            if line is None:
                self._stop("ended")
                return
            found = _answer(line)
            if not self._ready and line.strip() == _READY:
                self._ready = True
            elif self._ready and found is not None:
                self._answers[found[0]] = found[1]
            else:
                continue                         # no answer (a line the kernel printed, say): read on
            block = False

    def close(self) -> None:
        """End the second process and remove its files (its work left undone: every answer that counts has
        been read)."""
        self._stop(None)

    def _stop(self, why: str | None) -> None:
        if why is not None:
            log.info("the volumes are integrated in this process: the second process %s", why)
        process, self._process = self._process, None
        if process is not None:
            process.kill()
            process.wait()
            for pipe in (process.stdin, process.stdout):
                try:
                    pipe.close()
                except OSError:
                    pass
        if self._folder is not None:
            shutil.rmtree(self._folder, ignore_errors=True)
            self._folder = None

    def __enter__(self) -> KernelSide:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _read_lines(stream, lines: queue.Queue) -> None:
    """Put each line of ``stream`` on ``lines``, then None at its end (the reading thread)."""
    try:
        for line in iter(stream.readline, ""):
            lines.put(line)
    except (OSError, ValueError):
        pass
    lines.put(None)


def _answer(line: str) -> tuple[int, list[float] | None] | None:
    """The request and its volumes of an answer line (``ok <request> v0 v1 ...``; None for the volumes of
    ``error <request> ...``); None for any other line."""
    words = line.split()
    if len(words) < 2 or words[0] not in ("ok", "error") or not words[1].isdigit():
        return None
    if words[0] == "error":
        return int(words[1]), None
    try:
        return int(words[1]), [float(w) for w in words[2:]]
    except ValueError:
        return int(words[1]), None


def serve(requests, answers) -> None:
    """The second process: :data:`_READY` on ``answers``, then for each line of ``requests`` (the path of a
    binary BRep file named ``<request>.bin``) the volumes of the shape's solids as ``ok <request> v0 v1 ...``
    (``repr``: read back to the bit) or ``error <request> <why>``, one line each (the request named, so that
    a line the kernel prints among them is no answer); the file is removed once read."""
    answers.write(_READY + "\n")
    answers.flush()
    for line in iter(requests.readline, ""):
        path = line.strip()
        request = os.path.splitext(os.path.basename(path))[0]
        try:
            shape = TopoDS_Shape()
            if not BinTools.Read_s(shape, path):
                raise ValueError(f"{path} could not be read")
            answer = f"ok {request} " + " ".join(repr(v) for v in solid_volumes(shape))
        except Exception as exc:          # noqa: BLE001 - the other process integrates it itself
            answer = f"error {request} " + " ".join(str(exc).split())
        finally:
            try:
                os.remove(path)
            except OSError:
                pass
        answers.write(answer + "\n")
        answers.flush()
