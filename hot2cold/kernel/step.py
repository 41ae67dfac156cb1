"""Reading and writing STEP files (shapes only; names and colours: :mod:`hot2cold.kernel.xcaf`).

The kernel reads every file in millimetres, whatever length unit the file states, and hot2cold writes in
millimetres: a file in another unit (inch, metre) is said to come out in millimetres (a warning).

Output is written whole or not at all: to a temporary file in the target folder, then renamed.  A cold part
is read back from that temporary file before the rename (``verify``): its solids must come back valid,
closed and with the faces that were written, or nothing is written (:class:`~hot2cold.errors.MorphError`).
"""
from __future__ import annotations

import logging
import os
from contextlib import contextmanager
from pathlib import Path

from OCP.IFSelect import IFSelect_RetDone
from OCP.Message import Message, Message_Gravity
from OCP.STEPControl import STEPControl_AsIs, STEPControl_Reader, STEPControl_Writer
from OCP.TColStd import TColStd_SequenceOfAsciiString
from OCP.TopAbs import TopAbs_FACE, TopAbs_SOLID
from OCP.TopExp import TopExp_Explorer
from OCP.TopoDS import TopoDS_Shape

from ..io.atomic import write_atomically
from ..io.inputs import check_input_file
from ..errors import KernelError, MorphError, StepReadError
from .explore import shape_map
from .faults import solid_faults
from .validity import check_solids

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


#: The first line of every STEP file (ISO 10303-21).
_MAGIC = "ISO-10303-21;"


def refused(path: Path, status) -> StepReadError:
    """The error for a STEP file the kernel's reader refused with ``status`` (an ``IFSelect_ReturnStatus``):
    what its first line tells (it does not begin as a STEP file must, line 1 quoted), else "not a valid STEP
    file"; for this module's reader and :mod:`hot2cold.kernel.xcaf`'s alike."""
    return StepReadError(f"cannot read STEP file {path}: {_what_is_wrong(path)} (reader status {status.name})")


def _what_is_wrong(path: Path) -> str:
    """Why a reader refused ``path``, as far as its first line tells: it does not begin as a STEP file must
    (line 1 quoted), or "not a valid STEP file"."""
    with open(path, "rb") as fh:
        head = fh.read(256)
    first = head.lstrip(b"\xef\xbb\xbf \t\r\n").split(b"\n", 1)[0].strip()
    if not first.startswith(_MAGIC.encode()):
        shown = first[:40].decode("ascii", "replace")
        return f"line 1 is {shown!r}, where a STEP file begins with {_MAGIC!r}"
    return "not a valid STEP file"


def read_step(path: str | os.PathLike) -> TopoDS_Shape:
    """Read a STEP file into one shape (a compound when the file holds several roots).

    Raises :class:`StepReadError` when the file is missing, unreadable or holds no solid.  Names and
    colours are not read: :func:`hot2cold.kernel.xcaf.read_step_styles` reads them with the same shape.
    """
    path = check_step_file(path)
    reader = STEPControl_Reader()
    shape = read_through(reader, path, lambda: reader.TransferRoots() > 0, reader.OneShape)
    log.info("read %s", path)
    return shape


def read_through(reader, path: Path, transfer, one_shape) -> TopoDS_Shape:
    """The one way a STEP file is read, plain (:func:`read_step`) or through XCAF
    (:func:`hot2cold.kernel.xcaf.read_step_styles`): ``reader.ReadFile``, then ``transfer()`` (True when it
    transferred a shape), then ``one_shape()``, checked to hold a solid; every failure of the kernel on the way
    a :class:`StepReadError` in the same words."""
    try:
        status = reader.ReadFile(str(path))
    except Exception as exc:  # the kernel raises Standard_Failure on some corrupt files
        raise StepReadError(f"cannot read STEP file {path}: {exc}") from exc
    if status != IFSelect_RetDone:
        raise refused(path, status)
    _say_length_unit(getattr(reader, "Reader", lambda: reader)(), path)
    try:
        transferred = transfer()
    except Exception as exc:
        raise StepReadError(f"cannot read STEP file {path}: {exc}") from exc
    if not transferred:
        raise StepReadError(f"STEP file {path} holds no shape the kernel can transfer")
    return check_step_shape(one_shape(), path)


#: The length unit names the kernel gives for millimetres (``FileUnits``).
_MILLIMETRES = ("millimetre", "millimeter", "mm")


def length_unit(reader: STEPControl_Reader) -> str | None:
    """The length unit a read STEP file states (``"millimetre"``, ``"metre"``, ``"INCH"``, ... as the kernel
    names it), None where it states none."""
    lengths, angles, solid_angles = (TColStd_SequenceOfAsciiString() for _ in range(3))
    reader.FileUnits(lengths, angles, solid_angles)
    return lengths.Value(1).ToCString() if lengths.Length() else None


def _say_length_unit(reader: STEPControl_Reader, path: Path) -> None:
    """Warn where the file at ``path`` states its lengths in another unit than millimetres (the kernel reads
    them in millimetres, and the cold part is written in millimetres)."""
    unit = length_unit(reader)
    if unit is not None and unit.lower() not in _MILLIMETRES:
        log.warning("%s states its lengths in %s: hot2cold reads and writes in millimetres, so the cold part is "
                    "in millimetres", path.name, unit.lower())


def write_step(shape: TopoDS_Shape, path: str | os.PathLike, verify: bool = False) -> None:
    """Write ``shape`` to ``path`` atomically (temporary file in the same folder, then rename); with
    ``verify``, only once the file reads back as ``shape``'s valid closed solids (:func:`read_back`)."""
    path = check_output_folder(path)
    writer = STEPControl_Writer()
    with console_quiet():
        if writer.Transfer(shape, STEPControl_AsIs) != IFSelect_RetDone:
            raise KernelError(f"the kernel could not translate the cold shape to STEP for {path}")
        write_translated(writer, path, written=shape if verify else None)


def check_output_folder(path: str | os.PathLike) -> Path:
    """``path`` as a Path; :class:`KernelError` when its folder does not exist."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise KernelError(f"output folder does not exist: {folder}")
    return path


@contextmanager
def console_quiet():
    """Hold the kernel's console printers to warnings while the block runs, then give them their levels back.

    The STEP writer prints a banner of transfer statistics at the "info" level straight to the process's
    standard output (``Message_PrinterOStream``), past Python's streams: a ``hot2cold morph`` run, even with
    ``-q``, printed it into its table on stdout.  Warnings and failures still print.  Around the STEP
    writers' ``Transfer`` and ``Write`` (:func:`write_step`, :func:`hot2cold.kernel.xcaf.write_step_styles`)."""
    printers = list(Message.DefaultMessenger_s().Printers())
    levels = [printer.GetTraceLevel() for printer in printers]
    for printer, level in zip(printers, levels):
        if level.value < Message_Gravity.Message_Warning.value:
            printer.SetTraceLevel(Message_Gravity.Message_Warning)
    try:
        yield
    finally:
        for printer, level in zip(printers, levels):
            printer.SetTraceLevel(level)


def write_translated(writer, path: Path, note: str = "", written: TopoDS_Shape | None = None) -> None:
    """Write what ``writer`` (a ``STEPControl_Writer`` or ``STEPCAFControl_Writer`` holding the translated
    part) holds to ``path``, atomically; when ``written`` (the shape translated) is given, the temporary file
    is read back and checked against it first (:func:`read_back`)."""
    def write(tmp: str) -> None:
        if writer.Write(tmp) != IFSelect_RetDone:
            raise KernelError(f"the kernel could not write STEP file {path}")
        if written is not None:
            read_back(tmp, written, path)

    write_atomically([(path, write)])
    log.info("wrote %s%s", path, note)


def read_back(file: str | os.PathLike, written: TopoDS_Shape, path: str | os.PathLike) -> None:
    """Raise :class:`MorphError` unless the STEP ``file`` holds ``written``'s solids as valid closed solids
    (``BRepCheck_Analyzer``, no free edge) with the same numbers of faces (compared as sorted lists: an
    assembly's instances need not come back in the order they were written).  ``path`` names the output in
    the message.  What a morph's own checks pass can still fail here: the STEP writer approximates, and a
    tolerance the kernel accepted in memory may not survive the file."""
    reader = STEPControl_Reader()
    if reader.ReadFile(str(file)) != IFSelect_RetDone or reader.TransferRoots() == 0:
        raise MorphError(f"the cold STEP for {path} does not read back (reader status); not written")
    shape = reader.OneShape()
    back = check_solids(shape, volumes=False)
    sent = sorted(len(shape_map(solid, TopAbs_FACE)) for solid in shape_map(written, TopAbs_SOLID))
    if sorted(c.faces for c in back) != sent:
        raise MorphError(f"the cold STEP for {path} reads back with {len(back)} solids of "
                         f"{sorted(c.faces for c in back)} faces, not the {len(sent)} of {sent} written; not written")
    for s, check in enumerate(back):
        if not check.valid or not check.closed:
            what = "not valid (BRepCheck)" if not check.valid else f"open ({check.free_edges} free edges)"
            detail = ""
            if not check.valid:
                solid = shape_map(shape, TopAbs_SOLID)[s]
                faults = solid_faults(solid, list(enumerate(shape_map(solid, TopAbs_FACE))))
                detail = ": " + "; ".join(map(str, faults[:3])) + ("; ..." if len(faults) > 3 else "")
            raise MorphError(f"cold solid {s} of {path} is {what} when its STEP file is read back{detail}; "
                             "not written")
    log.info("read back %s: %d valid closed solids", path, len(back))
