"""Names and colours of solids and faces: STEP read and written through OCP's XCAF document.

A STEP file may carry names (products, assembly instances, faces) and colours (styled items on solids and
faces).  :func:`read_step_styles` reads the file with ``STEPCAFControl_Reader`` into a ``TDocStd_Document``
and returns the shape the plain reader gives (``STEPControl_Reader.OneShape``, so a file without names reads
exactly as before) together with a :class:`Styles` record: the document's tree of assemblies, instances and
parts, each with its name and colour, and the names and colours of their sub-shapes (faces, solids), each
placed in the shape by its path of child indices and by its index in the part's numbering (``TopExp``
order of the whole shape, 0-based).

The morph changes only geometry: the cold shape has the hot shape's tree, child for child (B-spline
conversion, copy and rebuild keep it), so a path into the hot shape leads to the matching cold sub-shape
and hot face ``k`` is cold face ``k``.  :func:`write_step_styles` builds a new document of the same tree
from the cold shape, puts every name and colour back on the matching cold label and writes it with
``STEPCAFControl_Writer``.  Every prototype is written once per instance (a part instanced twice becomes two
parts of the same name: the cold instances may differ).

OCP notes: ``TDF_Label.FindAttribute`` on a label without that attribute crashes the process, so
``IsAttribute`` is asked first; the reader's and writer's static parameters exist only once a reader or
writer has been created, so they are set after that (and put back afterwards).
"""
from __future__ import annotations

import logging
import os
from dataclasses import dataclass

from OCP.Interface import Interface_Static
from OCP.Quantity import Quantity_ColorRGBA
from OCP.STEPCAFControl import STEPCAFControl_Reader, STEPCAFControl_Writer
from OCP.STEPControl import STEPControl_AsIs
from OCP.TCollection import TCollection_ExtendedString
from OCP.TDataStd import TDataStd_Name
from OCP.TDF import TDF_Label, TDF_LabelSequence
from OCP.TDocStd import TDocStd_Document
from OCP.TopAbs import TopAbs_FACE, TopAbs_SOLID
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS_Iterator, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedMapOfShape
from OCP.XCAFApp import XCAFApp_Application
from OCP.XCAFDoc import (XCAFDoc_ColorCurv, XCAFDoc_ColorGen, XCAFDoc_ColorSurf, XCAFDoc_ColorTool,
                         XCAFDoc_DocumentTool, XCAFDoc_ShapeTool)

from ..errors import KernelError
from .step import check_output_folder, check_step_file, console_quiet, read_through, write_translated
from .explore import index_map

log = logging.getLogger(__name__)

#: An RGBA colour, each channel in [0, 1] as the kernel's ``Quantity_ColorRGBA`` holds it.
RGBA = tuple[float, float, float, float]

#: The XCAF colour kinds kept, by the names used in :attr:`Style.colours`.
_KINDS = (("surface", XCAFDoc_ColorSurf), ("generic", XCAFDoc_ColorGen), ("curve", XCAFDoc_ColorCurv))
_KIND = dict(_KINDS)


@dataclass(frozen=True)
class Style:
    """The name and colours of one label (an assembly, an instance, a part or a sub-shape).

    ``colours`` holds ``(kind, rgba)`` pairs for the kinds set on the label: "surface", "generic" (both)
    or "curve" (edges).
    """

    name: str = ""
    colours: tuple[tuple[str, RGBA], ...] = ()

    @property
    def colour(self) -> RGBA | None:
        """The colour a viewer shows on the faces: surface, else generic, else curve colour."""
        found = dict(self.colours)
        return found.get("surface") or found.get("generic") or found.get("curve")

    def __bool__(self) -> bool:
        return bool(self.name) or bool(self.colours)


@dataclass(frozen=True, eq=False)
class SubShape:
    """A named or coloured sub-shape (face, solid, ...) of a part.

    ``path``: child indices (``TopoDS_Iterator`` order) from the part's shape down to it; ``kind``: "solid",
    "face" or another ``TopAbs`` name in lower case; ``index``: its 0-based index among the whole shape's
    solids or faces (-1 for other kinds, or where it was not found).
    """

    path: tuple[int, ...]
    kind: str
    index: int
    style: Style


@dataclass(frozen=True, eq=False)
class Node:
    """A shape of the document: an assembly (``children``) or a part (a shape of its own).

    A part records ``path``, where its instance lies in the whole shape (child indices from the top), the
    prototype's own ``location`` (a ``TopLoc_Location``), the 0-based indices of its ``solids`` in the whole
    shape and its named or coloured ``subshapes``.
    """

    style: Style
    children: tuple["Instance", ...] = ()
    path: tuple[int, ...] | None = None
    location: object = None
    solids: tuple[int, ...] = ()
    subshapes: tuple[SubShape, ...] = ()

    @property
    def assembly(self) -> bool:
        return bool(self.children) or self.path is None


@dataclass(frozen=True, eq=False)
class Instance:
    """A use of a :class:`Node`: an assembly component or a free shape of the document.

    ``location`` (a ``TopLoc_Location``) places it in its parent; ``reference`` says the document held it
    as a reference label (every component; a free shape only when it was placed or named apart from its
    prototype).
    """

    style: Style
    location: object
    node: Node
    reference: bool = True


@dataclass(frozen=True, eq=False)
class Styles:
    """What the XCAF document said about the shape.

    Attributes
    ----------
    roots : the document's free shapes, in order.
    solids : one Style per solid of the shape (0-based, ``TopExp`` order): the name and colour it shows
        (its own label's, else its instance's, else its part's; colours also from enclosing assemblies).
    faces : one Style per face (empty Style where the face has no label of its own).
    placed : every part of the document was found in the shape and they hold all of its faces: only then
        can the cold shape be written with the document's tree.
    """

    roots: tuple[Instance, ...]
    solids: tuple[Style, ...]
    faces: tuple[Style, ...]
    placed: bool = True

    @property
    def carried(self) -> bool:
        """Whether the file carried any name or colour (else the plain writer is as good)."""
        def any_style(instance: Instance) -> bool:
            node = instance.node
            return (bool(instance.style) or bool(node.style) or any(s.style for s in node.subshapes)
                    or any(any_style(c) for c in node.children))
        return any(any_style(r) for r in self.roots)


# ----------------------------------------------------------------------------------------------------------
# Labels
# ----------------------------------------------------------------------------------------------------------
def _name(label: TDF_Label) -> str:
    if not label.IsAttribute(TDataStd_Name.GetID_s()):
        return ""
    attribute = TDataStd_Name()
    label.FindAttribute(TDataStd_Name.GetID_s(), attribute)
    return str(attribute.Get().ToExtString())


def _style(label: TDF_Label) -> Style:
    colours = []
    for kind, xcaf_kind in _KINDS:
        colour = Quantity_ColorRGBA()
        if XCAFDoc_ColorTool.GetColor_s(label, xcaf_kind, colour):
            rgb = colour.GetRGB()
            colours.append((kind, (float(rgb.Red()), float(rgb.Green()), float(rgb.Blue()), float(colour.Alpha()))))
    return Style(_name(label), tuple(colours))


def _set_style(label: TDF_Label, style: Style, colour_tool) -> None:
    if style.name:
        TDataStd_Name.Set_s(label, TCollection_ExtendedString(style.name))
    for kind, (r, g, b, a) in style.colours:
        colour = Quantity_ColorRGBA(float(r), float(g), float(b), float(a))
        colour_tool.SetColor(label, colour, _KIND[kind])


def _labels(sequence: TDF_LabelSequence) -> list[TDF_Label]:
    return [sequence.Value(i) for i in range(1, sequence.Length() + 1)]


def _new_document() -> TDocStd_Document:
    document = TDocStd_Document(TCollection_ExtendedString("XmlXCAF"))
    XCAFApp_Application.GetApplication_s().InitDocument(document)
    return document


# ----------------------------------------------------------------------------------------------------------
# Paths of child indices
# ----------------------------------------------------------------------------------------------------------
def _children(shape: TopoDS_Shape) -> list[TopoDS_Shape]:
    out, iterator = [], TopoDS_Iterator(shape)
    while iterator.More():
        out.append(iterator.Value())
        iterator.Next()
    return out


class _Follower:
    """The sub-shapes of one ``top`` shape at paths of child indices (called with a path), located as
    ``TopoDS_Iterator`` places them; each shape's children are listed once: the named and coloured faces of a
    part are children of one shell, and walking every path afresh would list all the shell's faces once a face."""

    def __init__(self, top: TopoDS_Shape):
        self._top = top
        self._children: dict[tuple[int, ...], list[TopoDS_Shape]] = {}     # by the path to their parent

    def __call__(self, path: tuple[int, ...]) -> TopoDS_Shape:
        shape = self._top
        for depth, i in enumerate(path):
            children = self._children.get(path[:depth])
            if children is None:
                children = self._children[path[:depth]] = _children(shape)
            if not 0 <= i < len(children):
                raise KernelError(f"the cold shape has no child {i} where the hot shape had one")
            shape = children[i]
        return shape


class _Paths:
    """Every sub-shape of a shape with the path to it (the first path where a shared one is met)."""

    def __init__(self, shape: TopoDS_Shape):
        self.map = TopTools_IndexedMapOfShape()
        self.paths: list[tuple[int, ...]] = []
        stack = [(shape, ())]
        while stack:
            current, path = stack.pop()
            if self.map.Add(current) > len(self.paths):
                self.paths.append(path)
                stack.extend(reversed([(c, path + (i,)) for i, c in enumerate(_children(current))]))

    def path(self, shape: TopoDS_Shape) -> tuple[int, ...] | None:
        i = self.map.FindIndex(shape)
        return self.paths[i - 1] if i else None


def _same_place(a: TopoDS_Shape, b: TopoDS_Shape) -> bool:
    """Same shape at the same place: ``IsSame``, or the same TShape under an equal transformation (two
    chains of locations that multiply to the same matrix)."""
    if a.IsSame(b):
        return True
    if not a.IsPartner(b):
        return False
    ta, tb = a.Location().Transformation(), b.Location().Transformation()
    return all(abs(ta.Value(r, c) - tb.Value(r, c)) <= 1e-12 * (1.0 + abs(ta.Value(r, c)))
               for r in range(1, 4) for c in range(1, 5))


def _find(top: TopoDS_Shape, shape: TopoDS_Shape) -> tuple[int, ...] | None:
    """Path from ``top`` to ``shape`` through compounds (assembly levels), or None."""
    stack = [(top, ())]
    while stack:
        current, path = stack.pop()
        if _same_place(current, shape):
            return path
        if current.ShapeType().name == "TopAbs_COMPOUND":
            stack.extend(reversed([(c, path + (i,)) for i, c in enumerate(_children(current))]))
    return None


# ----------------------------------------------------------------------------------------------------------
# Reading
# ----------------------------------------------------------------------------------------------------------
class _Reader:
    """Walks the document's tree and places every label in ``shape``."""

    def __init__(self, document: TDocStd_Document, shape: TopoDS_Shape):
        self.tool = XCAFDoc_DocumentTool.ShapeTool_s(document.Main())
        self.shape = shape
        self.placed = _Follower(shape)
        self.solid_map = index_map(shape, TopAbs_SOLID)
        self.face_map = index_map(shape, TopAbs_FACE)
        self.solid_styles: list[tuple[list[Style], list[Style]]] = [([], [])] * self.solid_map.Size()
        self.face_styles = [Style()] * self.face_map.Size()
        self.covered: set[int] = set()
        self.lost = 0

    def roots(self) -> tuple[Instance, ...]:
        free = TDF_LabelSequence()
        self.tool.GetFreeShapes(free)
        roots = []
        for label in _labels(free):
            if XCAFDoc_ShapeTool.IsReference_s(label):
                location = XCAFDoc_ShapeTool.GetLocation_s(label)
                referred = TDF_Label()
                XCAFDoc_ShapeTool.GetReferredShape_s(label, referred)
                style = _style(label)
                roots.append(Instance(style, location, self.node(referred, location, [style]), True))
            else:
                roots.append(Instance(Style(), TopLoc_Location(), self.node(label, TopLoc_Location(), []), False))
        return tuple(roots)

    def node(self, label: TDF_Label, placed: TopLoc_Location, outer: list[Style]) -> Node:
        """``label`` placed in the whole shape by ``placed``; ``outer``: the styles of the assemblies and
        instances around it, innermost last (the instance of ``label`` itself last, if it has one)."""
        style = _style(label)
        if XCAFDoc_ShapeTool.IsAssembly_s(label):
            components = TDF_LabelSequence()
            XCAFDoc_ShapeTool.GetComponents_s(label, components, False)
            children = []
            for component in _labels(components):
                location = XCAFDoc_ShapeTool.GetLocation_s(component)
                referred = TDF_Label()
                XCAFDoc_ShapeTool.GetReferredShape_s(component, referred)
                instance_style = _style(component)
                child = self.node(referred, placed.Multiplied(location), outer + [style, instance_style])
                children.append(Instance(instance_style, location, child))
            return Node(style, children=tuple(children))
        return self.part(label, placed, outer, style)

    def part(self, label: TDF_Label, placed: TopLoc_Location, outer: list[Style], style: Style) -> Node:
        prototype = XCAFDoc_ShapeTool.GetShape_s(label)
        path = _find(self.shape, prototype.Moved(placed))
        if path is None:
            log.warning("a part of the STEP document (%s) is not in the shape read: the cold STEP will be "
                        "written without names and colours", style.name or "no name")
            self.lost += 1
            return Node(style, path=None, location=prototype.Location())
        instance = self.placed(path)
        for face in _sub_shapes(instance, TopAbs_FACE):
            self.covered.add(self.face_map.FindIndex(face) - 1)
        # names: the instance's, else the part's; colours: also from the assemblies around it
        own = outer[-1:] + [style]
        solids = []
        for solid in _sub_shapes(instance, TopAbs_SOLID):
            s = self.solid_map.FindIndex(solid) - 1
            if s >= 0:
                solids.append(s)
                self.solid_styles[s] = (own, outer[-2::-1])
        subshapes = []
        labels = TDF_LabelSequence()
        XCAFDoc_ShapeTool.GetSubShapes_s(label, labels)
        paths = _Paths(prototype) if labels.Length() else None
        below = _Follower(instance)
        for sub_label in _labels(labels):
            sub_style = _style(sub_label)
            if not sub_style:
                continue
            sub_path = paths.path(XCAFDoc_ShapeTool.GetShape_s(sub_label))
            if sub_path is None:
                self.lost += 1
                continue
            sub = below(sub_path)
            kind = sub.ShapeType().name.removeprefix("TopAbs_").lower()
            index = -1
            if kind == "face":
                index = self.face_map.FindIndex(sub) - 1
                if index >= 0:
                    self.face_styles[index] = sub_style
            elif kind == "solid":
                index = self.solid_map.FindIndex(sub) - 1
                if index >= 0:
                    names, around = self.solid_styles[index]
                    self.solid_styles[index] = ([sub_style] + names, around)
            subshapes.append(SubShape(sub_path, kind, index, sub_style))
        return Node(style, path=path, location=prototype.Location(), solids=tuple(solids),
                    subshapes=tuple(subshapes))

    def styles(self) -> Styles:
        roots = self.roots()
        solids = []
        for names, around in self.solid_styles:
            name = next((s.name for s in names if s.name), "")
            colours = next((s.colours for s in names + around if s.colours), ())
            solids.append(Style(name, colours))
        placed = self.lost == 0 and self.covered >= set(range(self.face_map.Size()))
        if not placed and not self.lost:
            log.warning("the STEP document's parts do not hold every face of the shape read; the cold STEP "
                        "will be written without names and colours")
        return Styles(roots=roots, solids=tuple(solids), faces=tuple(self.face_styles), placed=placed)


def _sub_shapes(shape: TopoDS_Shape, kind) -> list[TopoDS_Shape]:
    m = index_map(shape, kind)
    return [m.FindKey(i) for i in range(1, m.Size() + 1)]


class _Statics:
    """Set some of the translators' static parameters for a while, then put them back."""

    def __init__(self, **values: int):
        self.values = {k.replace("__", "."): v for k, v in values.items()}
        self.saved: dict[str, int] = {}

    def __enter__(self):
        for key, value in self.values.items():
            self.saved[key] = Interface_Static.IVal_s(key)
            Interface_Static.SetIVal_s(key, value)
        self.naming = XCAFDoc_ShapeTool.AutoNaming_s()
        XCAFDoc_ShapeTool.SetAutoNaming_s(False)      # no made-up names ("SOLID", ...) on new labels
        return self

    def __exit__(self, *exc):
        for key, value in self.saved.items():
            Interface_Static.SetIVal_s(key, value)
        XCAFDoc_ShapeTool.SetAutoNaming_s(self.naming)
        return False


def read_step_styles(path: str | os.PathLike) -> tuple[TopoDS_Shape, Styles]:
    """Read a STEP file through XCAF: the shape (as :func:`~hot2cold.kernel.step.read_step` gives it) and
    the names and colours of its assemblies, instances, parts, solids and faces.

    Raises :class:`StepReadError` as ``read_step`` does (missing, empty, unreadable, no solid).
    """
    path = check_step_file(path)
    reader = STEPCAFControl_Reader()              # creating it sets up the statics changed below
    reader.SetNameMode(True)
    reader.SetColorMode(True)
    for mode in ("SetLayerMode", "SetPropsMode", "SetGDTMode", "SetMatMode", "SetViewMode", "SetMetaMode"):
        if hasattr(reader, mode):                 # the metadata mode came with OCCT 7.9
            getattr(reader, mode)(False)
    document = _new_document()
    with _Statics(read__stepcaf__subshapes__name=1):
        shape = read_through(reader, path, lambda: reader.Transfer(document) and reader.Reader().NbShapes() > 0,
                             lambda: reader.Reader().OneShape())
    try:
        walker = _Reader(document, shape)
        styles = walker.styles()
    except KernelError:
        raise
    except Exception as exc:
        raise KernelError(f"reading the names and colours of {path} failed: {exc}") from exc
    named = sum(bool(s) for s in styles.solids) + sum(bool(s) for s in styles.faces)
    log.info("read %s through XCAF: %d solid(s), %d named or coloured solids and faces%s", path,
             len(styles.solids), named, f", {walker.lost} labels not placed" if walker.lost else "")
    return shape, styles


# ----------------------------------------------------------------------------------------------------------
# Writing
# ----------------------------------------------------------------------------------------------------------
def _build(node: Node, cold: _Follower, tool, colours) -> TDF_Label:
    """``node``'s label in the cold document, its parts found in the cold shape by their paths (``cold``)."""
    if node.assembly:
        label = tool.NewShape()
        for instance in node.children:
            child = _build(instance.node, cold, tool, colours)
            component = tool.AddComponent(label, child, instance.location)
            if component.IsNull():
                raise KernelError("the kernel could not add an assembly component to the cold document")
            _set_style(component, instance.style, colours)
    else:
        prototype = cold(node.path).Located(node.location)
        label = tool.NewShape()
        tool.SetShape(label, prototype)
        below = _Follower(prototype)
        for sub in node.subshapes:
            sub_label = tool.AddSubShape(label, below(sub.path))
            if sub_label.IsNull():
                log.warning("a %s of the cold part could not be labelled; its name and colour are not written",
                            sub.kind)
                continue
            _set_style(sub_label, sub.style, colours)
    _set_style(label, node.style, colours)
    return label


def cold_document(cold: TopoDS_Shape, styles: Styles) -> TDocStd_Document:
    """A new XCAF document holding ``cold`` (the morphed shape, same tree as the hot one) with the hot
    document's tree, names and colours."""
    document = _new_document()
    tool = XCAFDoc_DocumentTool.ShapeTool_s(document.Main())
    colours = XCAFDoc_DocumentTool.ColorTool_s(document.Main())
    in_cold = _Follower(cold)
    for root in styles.roots:
        label = _build(root.node, in_cold, tool, colours)
        if root.reference:
            placed = TDF_Label()
            tool.SetLocation(label, root.location, placed)
            if not placed.IsNull() and not placed.IsEqual(label):
                _set_style(placed, root.style, colours)
    tool.UpdateAssemblies()
    return document


def write_step_styles(cold: TopoDS_Shape, styles: Styles, path: str | os.PathLike, verify: bool = False) -> None:
    """Write ``cold`` to ``path`` through XCAF with the names and colours of ``styles``, atomically; with
    ``verify``, only once it reads back as ``cold``'s valid closed solids (:func:`.step.read_back`).

    Raises :class:`KernelError` when the kernel cannot build or translate the document, :class:`OutputError`
    when the file cannot be written.
    """
    path = check_output_folder(path)
    writer = STEPCAFControl_Writer()              # creating it sets up the statics changed below
    writer.SetNameMode(True)
    writer.SetColorMode(True)
    writer.SetLayerMode(False)
    with _Statics(write__stepcaf__subshapes__name=1), console_quiet():
        try:
            document = cold_document(cold, styles)
            transferred = writer.Transfer(document, STEPControl_AsIs)
        except KernelError:
            raise
        except Exception as exc:
            raise KernelError(f"the kernel could not translate the cold part to STEP for {path}: {exc}") from exc
        if not transferred:
            raise KernelError(f"the kernel could not translate the cold part to STEP for {path}")
        write_translated(writer, path, " with the hot file's names, colours and assembly tree",
                         written=cold if verify else None)
