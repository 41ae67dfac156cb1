"""Reading and writing STEP files (shapes only; names and colours: :mod:`hot2cold.kernel.xcaf`).

Output is written whole or not at all: to a temporary file in the target folder, then renamed.
"""
from __future__ import annotations

import logging
import os
from pathlib import Path

from OCP.IFSelect import IFSelect_RetDone
from OCP.STEPControl import STEPControl_AsIs, STEPControl_Reader, STEPControl_Writer
from OCP.TopAbs import TopAbs_SOLID
from OCP.TopExp import TopExp_Explorer
from OCP.TopoDS import TopoDS_Shape

from ..io.atomic import write_atomically
from ..io.inputs import check_input_file
from ..errors import KernelError, StepReadError

log = logging.getLogger(__name__)


def check_step_file(path: str | os.PathLike) -> Path:
    """``path`` as a Path; :class:`StepReadError` when the file is missing, a folder, not readable or empty
    (:func:`hot2cold.io.inputs.check_input_file`)."""
    return check_input_file(Path(path), "STEP file", StepReadError, empty=True)


def check_step_shape(shape: TopoDS_Shape, path: Path) -> TopoDS_Shape:
    """``shape`` as read from ``path``; :class:`StepReadError` when it holds no solid."""
    if shape.IsNull() or not TopExp_Explorer(shape, TopAbs_SOLID).More():
        raise StepReadError(f"STEP file {path} holds no solid: hot2cold morphs solids (export the part as a solid)")
    return shape


def read_step(path: str | os.PathLike) -> TopoDS_Shape:
    """Read a STEP file into one shape (a compound when the file holds several roots).

    Raises :class:`StepReadError` when the file is missing, unreadable or holds no solid.  Names and
    colours are not read: :func:`hot2cold.kernel.xcaf.read_step_styles` reads them with the same shape.
    """
    path = check_step_file(path)
    reader = STEPControl_Reader()
    try:
        status = reader.ReadFile(str(path))
    except Exception as exc:  # the kernel raises Standard_Failure on some corrupt files
        raise StepReadError(f"cannot read STEP file {path}: {exc}") from exc
    if status != IFSelect_RetDone:
        raise StepReadError(f"cannot read STEP file {path}: not a valid STEP file (reader status {status.name})")
    if reader.TransferRoots() == 0:
        raise StepReadError(f"STEP file {path} holds no shape the kernel can transfer")
    shape = check_step_shape(reader.OneShape(), path)
    log.info("read %s", path)
    return shape


def write_step(shape: TopoDS_Shape, path: str | os.PathLike) -> None:
    """Write ``shape`` to ``path`` atomically (temporary file in the same folder, then rename)."""
    path = check_output_folder(path)
    writer = STEPControl_Writer()
    if writer.Transfer(shape, STEPControl_AsIs) != IFSelect_RetDone:
        raise KernelError(f"the kernel could not translate the cold shape to STEP for {path}")
    write_translated(writer, path)


def check_output_folder(path: str | os.PathLike) -> Path:
    """``path`` as a Path; :class:`KernelError` when its folder does not exist."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise KernelError(f"output folder does not exist: {folder}")
    return path


def write_translated(writer, path: Path, note: str = "") -> None:
    """Write what ``writer`` (a ``STEPControl_Writer`` or ``STEPCAFControl_Writer`` holding the translated
    part) holds to ``path``, atomically."""
    def write(tmp: str) -> None:
        if writer.Write(tmp) != IFSelect_RetDone:
            raise KernelError(f"the kernel could not write STEP file {path}")

    write_atomically([(path, write)])
    log.info("wrote %s%s", path, note)
