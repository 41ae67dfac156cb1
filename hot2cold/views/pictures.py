"""Pictures of a morph for the HTML report: PNG bytes made with matplotlib's object interface.

* :func:`overlay_png` -- hot (red) and cold (blue) part overlaid, the displacement exaggerated by a stated
  factor so it can be seen (the paper's Fig. 8 and 10), seen along named coordinate axes ("view along -Z
  (top)");
* :func:`error_maps_png` -- per face, the FE nodes coloured by their distance to the cold part (eq. 21), on
  one colour scale for all faces of a result (:func:`error_scale`) with the tolerance marked on it and a
  pass/fail mark per face;
* :func:`curvature_png` -- mean curvature of the hot and the morphed surfaces side by side, and their
  difference, on the largest faces (the paper's Fig. 9 and 11); rounding noise below
  :func:`curvature_floor` drawn as zero.

Each ``*_png`` has a ``*_figure`` twin that returns the :class:`~matplotlib.figure.Figure` (with an Agg canvas)
instead of PNG bytes, for tests and for callers that want to draw more on it.

Only :class:`matplotlib.figure.Figure` and the Agg canvas are used: no pyplot, no backend switching, so
nothing global changes.  Every picture is drawn from one triangle mesh of the hot part
(:func:`hot2cold.kernel.tessellate.tessellate`); because the morph keeps each face's parameterisation, a
mesh vertex at ``(u, v)`` on face ``k`` is at ``S_cold(u, v)`` on the cold part, so hot, cold and anything
in between share one mesh.

Maps of a face are drawn in its *developed* parameters: ``u`` and ``v`` scaled by the median lengths of
``S_u`` and ``S_v`` over the face, so both axes read as approximate millimetres along the surface.
"""
from __future__ import annotations

import io
import logging
from dataclasses import dataclass

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import Colormap, ListedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import FuncFormatter, MaxNLocator

from ..core.bspline import BSplineSurface, clip_uv, evaluate_curve, mean_curvature, surface_derivatives
from ..core.model import Role
from .export import points_on_faces
from ..kernel.tessellate import TriangleMesh, tessellate

log = logging.getLogger(__name__)

#: Colours of the hot and the cold part (the paper's red and blue).
HOT_COLOUR = (0.84, 0.15, 0.16)
COLD_COLOUR = (0.12, 0.30, 0.80)

#: Default exaggeration: the largest displacement is drawn as this fraction of the part's diagonal.
DISPLACEMENT_FRACTION = 0.05

#: Colours of the pass and the fail marks of the error maps.
PASS_COLOUR = (0.10, 0.50, 0.22)
FAIL_COLOUR = (0.78, 0.16, 0.16)

#: A curvature below this share of ``max(1 / part diagonal, the face's largest |H|)`` is rounding noise
#: (:func:`curvature_floor`).
CURVATURE_NOISE = 1e-9

_EDGE_SAMPLES = 64


# ------------------------------------------------------------------------------------------------- helpers
def mesh_of(result, deflection: float | None = None) -> TriangleMesh:
    """The triangle mesh of the hot part that every picture is drawn on (pass it on to draw several)."""
    if deflection is None:
        deflection = 1e-3 * result.part.diagonal
    return tessellate(result.part.kernel.hot, deflection)


def displacement_scale(result, fraction: float = DISPLACEMENT_FRACTION) -> float:
    """Exaggeration factor that draws the largest displacement as ``fraction`` of the part's diagonal
    (1 when nothing moves)."""
    largest = float(result.report.max_displacement)
    if not np.isfinite(largest) or largest <= 0.0:
        return 1.0
    return fraction * float(result.part.diagonal) / largest


def _png(fig: Figure, dpi: int) -> bytes:
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    return buf.getvalue()


def check_scale(scale: float) -> float:
    """``scale`` as a float; ValueError unless it is a positive finite number."""
    scale = float(scale)
    if not np.isfinite(scale) or scale <= 0.0:
        raise ValueError(f"the displacement scale must be a positive number, got {scale!r}")
    return scale


def _face_vertices(mesh: TriangleMesh, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertex indices ``(n,)`` of face ``k`` and its triangles ``(m, 3)`` renumbered into them."""
    tris = mesh.triangles[mesh.face == k]
    verts, local = np.unique(tris, return_inverse=True)
    return verts, local.reshape(tris.shape)


def cold_vertices(result, mesh: TriangleMesh) -> np.ndarray:
    """Each mesh vertex moved onto the cold part: ``S_cold(u, v)`` of its face (same parameters as hot,
    :func:`hot2cold.views.export.points_on_faces`); a vertex without ``(u, v)`` or triangle stays where it is."""
    cold = points_on_faces([fm.surface for fm in result.faces], mesh)
    missing = np.isnan(cold).any(axis=1)
    cold[missing] = mesh.vertices[missing]
    return cold


def _edge_polylines(result) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Hot and cold polylines ``(s, 3)`` of every non-degenerate edge, at the same curve parameters."""
    hot, cold = [], []
    for edge, em in zip(result.part.edges, result.edges):
        if edge.curve is None or em.curve is None:
            continue
        lo, hi = edge.curve.domain
        t = np.linspace(lo, hi, _EDGE_SAMPLES)
        hot.append(evaluate_curve(edge.curve, t))
        cold.append(evaluate_curve(em.curve, t))
    return hot, cold


@dataclass(frozen=True)
class _Developed:
    """Map of a face's ``(u, v)`` to approximate millimetres along the surface."""

    u0: float
    v0: float
    lu: float
    lv: float

    @classmethod
    def of(cls, surface: BSplineSurface, uv: np.ndarray) -> "_Developed":
        su, sv = surface_derivatives(surface, uv[:, 0], uv[:, 1])
        lu = float(np.median(np.linalg.norm(su, axis=1))) if len(uv) else 1.0
        lv = float(np.median(np.linalg.norm(sv, axis=1))) if len(uv) else 1.0
        lu, lv = (lu if lu > 0 else 1.0), (lv if lv > 0 else 1.0)
        return cls(float(uv[:, 0].min()), float(uv[:, 1].min()), lu, lv)

    def xy(self, uv: np.ndarray) -> np.ndarray:
        return np.column_stack([(uv[:, 0] - self.u0) * self.lu, (uv[:, 1] - self.v0) * self.lv])

    def uv(self, xy: np.ndarray) -> np.ndarray:
        return np.column_stack([xy[:, 0] / self.lu + self.u0, xy[:, 1] / self.lv + self.v0])


def _set_aspect(ax, xy: np.ndarray) -> None:
    """Equal axes unless the face is a long strip (then it is stretched to stay readable)."""
    ext = np.ptp(xy, axis=0) if len(xy) else np.ones(2)
    ratio = ext[0] / ext[1] if ext[1] > 0 else np.inf
    ax.set_aspect("equal" if 1 / 3 <= ratio <= 3 else "auto")


def _face_areas(mesh: TriangleMesh, n_faces: int) -> np.ndarray:
    v = mesh.vertices[mesh.triangles]
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    return np.bincount(mesh.face, weights=area, minlength=n_faces)


def _grid(n: int, columns: int) -> tuple[int, int]:
    cols = max(1, min(columns, n))
    return (n + cols - 1) // cols, cols


_SMALL = FuncFormatter(lambda x, _pos: f"{x:.2g}")


# ------------------------------------------------------------------------------------------------ overlay
@dataclass(frozen=True)
class View:
    """An orthographic view: looking along ``direction (3,)``, with ``up (3,)`` pointing up on the picture;
    ``name`` says where from ("top"), the titles add the axis ("view along −Z (top)")."""

    name: str
    direction: np.ndarray
    up: np.ndarray

    def basis(self) -> np.ndarray:
        """Rows: right, up, towards the viewer."""
        d = np.asarray(self.direction, float)
        d = d / np.linalg.norm(d)
        up = np.asarray(self.up, float) - np.dot(self.up, d) * d
        up = up / np.linalg.norm(up)
        return np.array([np.cross(d, up), up, -d])


def default_views(points: np.ndarray) -> list[View]:
    """Three views along coordinate axes of ``points (n, 3)``: the top view along -Z (X right, Y up), the
    front view along +Y (X right, Z up) and the right view along -X (Y right, Z up), in the order of the
    points' extent along the view direction: first the view along the axis the part is thinnest along
    (it shows the largest outline), then the middle one, then the longest.

    The axes are named rather than the part's principal axes taken, so that a reader can tell where each
    view looks from; every view's right and up are positive coordinate axes, so its tick labels are the
    part's coordinates."""
    points = np.asarray(points, float).reshape(-1, 3)
    eye = np.eye(3)
    views = [View("top", -eye[2], eye[1]), View("front", eye[1], eye[2]), View("right", -eye[0], eye[2])]
    ext = np.ptp(points, axis=0) if len(points) else np.ones(3)
    depth = [float(np.abs(v.direction) @ ext) for v in views]
    order = sorted(range(len(views)), key=lambda i: depth[i])          # stable: top, front, right on ties
    return [views[i] for i in order]


def _axis_text(d: np.ndarray) -> str:
    """``+X``, ``−Z``, ... for a vector ``(3,)`` along a coordinate axis, else its unit vector in brackets."""
    d = np.asarray(d, float) / np.linalg.norm(d)
    i = int(np.argmax(np.abs(d)))
    if abs(abs(d[i]) - 1.0) < 1e-9:
        return ("+" if d[i] > 0 else "−") + "XYZ"[i]
    return "(" + ", ".join(f"{x:+.2f}" for x in d) + ")"


def _view_title(view: View) -> str:
    """``view along −Z (top)`` and, on a second line, which axes point right, up and towards the viewer."""
    right, up, towards = (_axis_text(b) for b in view.basis())
    along = _axis_text(view.direction)
    name = f" ({view.name})" if view.name and view.name != along else ""
    return f"view along {along}{name}\n{right} right, {up} up, {towards} towards you"


def _shaded_layer(points: np.ndarray, triangles: np.ndarray, basis: np.ndarray, colour, box, size_px) -> np.ndarray:
    """One part rendered opaque (flat-shaded triangles, far ones first) into an RGBA image ``(h, w, 4)``
    covering ``box = (x0, x1, y0, y1)`` of the view; transparent where the part is not.  ``colour``: one RGB
    ``(3,)`` for the part or one per triangle ``(T, 3)``."""
    p = points @ basis.T                                               # x, y, towards the viewer
    tri = p[triangles]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    light = np.array([-0.35, 0.45, 0.82])
    shade = 0.35 + 0.65 * np.abs(normal @ (light / np.linalg.norm(light)))
    rgb = np.clip(shade[:, None] * np.broadcast_to(np.asarray(colour, float), (len(tri), 3)), 0.0, 1.0)
    order = np.argsort(tri[:, :, 2].mean(axis=1))                    # painter's algorithm: far first
    w, h = size_px
    fig = Figure(figsize=(w / 100.0, h / 100.0), dpi=100)
    fig.patch.set_alpha(0.0)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(box[2], box[3])
    ax.add_collection(PolyCollection(tri[order, :, :2], facecolors=rgb[order], edgecolors=rgb[order],
                                     linewidths=0.4))
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba(), dtype=float)[..., :4] / 255.0


def _composite(layers: list[np.ndarray], opacity: float) -> np.ndarray:
    """White background, each opaque layer laid over it with ``opacity``; where layers overlap their colours
    are averaged, so neither part hides the other."""
    alphas = [layer[..., 3:4] for layer in layers]
    total = np.maximum(sum(alphas), 1e-12)
    mixed = sum(layer[..., :3] * a for layer, a in zip(layers, alphas)) / total
    cover = np.clip(sum(alphas), 0.0, 1.0) * opacity
    return np.concatenate([1.0 - cover + cover * mixed, np.ones_like(cover)], axis=2)


def _dress_view(ax, view: View, box) -> None:
    """Limits ``box = (x0, x1, y0, y1)``, equal aspect, the view's title and its axes named on a view's panel."""
    right, up, _ = view.basis()
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(box[2], box[3])
    ax.set_aspect("equal")
    ax.set_title(_view_title(view), fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_xlabel(f"{_axis_text(right)} [mm]", fontsize=8)
    ax.set_ylabel(f"{_axis_text(up)} [mm]", fontsize=8)


def _view_box(xy: np.ndarray) -> tuple[float, float, float, float]:
    """The box ``(x0, x1, y0, y1)`` a view's panel shows of the projected points ``xy (n, 2)``: their extent and
    4 % of its larger side around it."""
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pad = 0.04 * float(max(hi - lo))
    return (lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad)


def _raster_size(box, height: float, dpi: int) -> tuple[int, int]:
    """Pixels ``(w, h)`` of a shaded layer showing ``box`` in a panel ``height`` inches high at ``dpi``."""
    ratio = (box[3] - box[2]) / (box[1] - box[0])
    panel_px = int(1.5 * dpi * max(height, height / ratio))
    return (panel_px, max(8, int(round(panel_px * ratio)))) if ratio <= 1 else \
        (max(8, int(round(panel_px / ratio))), panel_px)


def _view_panels(fig_width: float, boxes: list) -> tuple[list[float], float]:
    """The width ratios of panels showing ``boxes`` side by side, as wide as their views at one common
    height (no panel squeezed into a tall, empty column), and that height (inches) for ``fig_width``."""
    ratios = [float(np.clip((x1 - x0) / (y1 - y0), 0.75, 2.2)) for x0, x1, y0, y1 in boxes]
    return ratios, float(np.clip(fig_width / sum(ratios), 2.5, 0.8 * fig_width))


def overlay_png(result, scale: float | None = None, *, mesh: TriangleMesh | None = None,
                views: list[View] | None = None, width_in: float = 14.0, dpi: int = 100,
                opacity: float = 0.55) -> bytes:
    """Hot part (red) and cold part (blue) overlaid, from several orthographic views
    (:func:`overlay_figure`).  Returns PNG bytes."""
    return _png(overlay_figure(result, scale, mesh=mesh, views=views, width_in=width_in, dpi=dpi,
                               opacity=opacity), dpi)


def overlay_figure(result, scale: float | None = None, *, mesh: TriangleMesh | None = None,
                   views: list[View] | None = None, width_in: float = 14.0, dpi: int = 100,
                   opacity: float = 0.55) -> Figure:
    """The figure of :func:`overlay_png`: hot part (red) and cold part (blue) overlaid, a panel per view
    (default :func:`default_views`: along -Z, +Y and -X, each titled with its axis and name).

    The cold part is drawn as ``hot + scale * (cold - hot)`` (default scale: :func:`displacement_scale`).
    Each part is rendered shaded (at ``dpi``) and laid over the other translucently (purple where they
    overlap), and the edges of both are drawn on top as lines.  The panels' axes are labelled with the
    coordinate axes they show.
    """
    scale = displacement_scale(result) if scale is None else check_scale(scale)
    mesh = mesh if mesh is not None else mesh_of(result)
    hot = mesh.vertices
    cold = hot + scale * (cold_vertices(result, mesh) - hot)
    hot_edges, cold_edges = _edge_polylines(result)
    cold_edges = [h + scale * (c - h) for h, c in zip(hot_edges, cold_edges)]
    views = views if views is not None else default_views(hot)

    bases = [view.basis() for view in views]
    boxes = [_view_box(np.concatenate([hot @ b[:2].T, cold @ b[:2].T])) for b in bases]
    ratios, height = _view_panels(width_in, boxes)
    fig = Figure(figsize=(width_in, height + 1.4), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(views), squeeze=False, width_ratios=ratios)[0]
    for ax, view, b, box in zip(axes, views, bases, boxes):
        size = _raster_size(box, height, dpi)
        layers = [_shaded_layer(pts, mesh.triangles, b, colour, box, size)
                  for pts, colour in ((hot, HOT_COLOUR), (cold, COLD_COLOUR))]
        ax.imshow(_composite(layers, opacity), extent=box, origin="upper", interpolation="antialiased")
        for lines, colour in ((hot_edges, HOT_COLOUR), (cold_edges, COLD_COLOUR)):
            ax.add_collection(LineCollection([(ln @ b.T)[:, :2] for ln in lines], colors=[colour],
                                             linewidths=0.9))
        _dress_view(ax, view, box)

    def look(colour):                       # a face's colour as the composite shows it (lit, translucent)
        return tuple(1.0 - opacity + opacity * 0.9 * np.asarray(colour))

    both = 0.5 * (np.asarray(HOT_COLOUR) + COLD_COLOUR)
    fig.legend(handles=[Patch(facecolor=look(HOT_COLOUR), edgecolor=HOT_COLOUR, label="hot"),
                        Patch(facecolor=look(COLD_COLOUR), edgecolor=COLD_COLOUR,
                              label=f"cold, displacement × {scale:.3g}"),
                        Patch(facecolor=look(both), edgecolor="none", label="both")],
               loc="outside lower center", ncols=3, fontsize=9, frameon=False)
    return fig


# --------------------------------------------------------------------------------------------- face numbers
def face_numbers_png(result, *, mesh: TriangleMesh | None = None, views: list[View] | None = None,
                     width_in: float = 14.0, dpi: int = 100) -> bytes:
    """The hot part with each face's number on it (:func:`face_numbers_figure`).  Returns PNG bytes."""
    return _png(face_numbers_figure(result, mesh=mesh, views=views, width_in=width_in, dpi=dpi), dpi)


def face_numbers_figure(result, *, mesh: TriangleMesh | None = None, views: list[View] | None = None,
                        width_in: float = 14.0, dpi: int = 100) -> Figure:
    """The hot part, each face in a colour of its own and its number written on it, a panel per view
    (default :func:`default_views`), so that the report's rows ("face 3") can be found on the part.

    A face's number sits at the area-weighted centre of its triangles that face the viewer (the
    tessellation's triangles face out of the solid), drawn over the part; a face turned away from a view is
    not numbered in it, and one turned away from all of them is named under the figure.
    """
    mesh = mesh if mesh is not None else mesh_of(result)
    points, triangles = mesh.vertices, mesh.triangles
    views = views if views is not None else default_views(points)
    palette = colormaps["tab20"](np.arange(20))[:, :3] * 0.55 + 0.45           # light: the numbers read
    colours = palette[mesh.face % 20]
    tri = points[triangles]                                                      # (T, 3, 3)
    centre = tri.mean(axis=1)                                                    # (T, 3)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])              # (T, 3), 2 x area, outward
    n_faces = len(result.part.faces)
    boxes = [_view_box(points @ view.basis()[:2].T) for view in views]
    ratios, height = _view_panels(width_in, boxes)
    fig = Figure(figsize=(width_in, height + 0.9), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(views), squeeze=False, width_ratios=ratios)[0]
    numbered: set[int] = set()
    for ax, view, box in zip(axes, views, boxes):
        b = view.basis()
        size = _raster_size(box, height, dpi)
        facing = np.maximum(cross @ b[2], 0.0)                                   # projected area towards us
        front = facing > 0.0                       # back faces culled: a thin part's far side shows no speckle
        ax.imshow(_shaded_layer(points, triangles[front], b, colours[front], box, size), extent=box,
                  origin="upper", interpolation="antialiased")
        weight = np.bincount(mesh.face, weights=facing, minlength=n_faces)
        for k in np.flatnonzero(weight > 1e-3 * max(weight.max(), 1e-300)):
            numbered.add(int(k))
            mine = mesh.face == k
            at = (centre[mine] * facing[mine, None]).sum(axis=0) / weight[k]
            ax.text(*(at @ b[:2].T), str(k), ha="center", va="center", fontsize=9, fontweight="bold",
                    bbox={"boxstyle": "round,pad=0.15", "facecolor": "white", "edgecolor": "0.3",
                          "linewidth": 0.6, "alpha": 0.9})
        _dress_view(ax, view, box)
    hidden = [k for k in range(n_faces) if k not in numbered]
    if hidden:
        title = getattr(result.part, "face_title", lambda k: "")
        named = ", ".join(f"{k}" + (f" ({title(k)})" if title(k) else "") for k in hidden)
        fig.supxlabel(f"turned away from these views: face {named}", fontsize=9)
    return fig


# --------------------------------------------------------------------------------------------- error maps
def _edge_node_uv(result, face: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes of the face's edges (role EDGE) placed on the face through its pcurves: indices and ``(u, v)``."""
    cls = result.classification
    idx, uvs = [], []
    for use in result.part.faces[face].uses:
        nodes = cls.nodes_of(Role.EDGE, use.edge)
        if not len(nodes) or len(use.t) < 2:
            continue
        t = cls.t[nodes]
        order = np.argsort(use.t)
        ts = use.t[order]
        uv = np.column_stack([np.interp(t, ts, use.uv[order, 0]), np.interp(t, ts, use.uv[order, 1])])
        idx.append(nodes)
        uvs.append(uv)
    if not idx:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 2))
    return np.concatenate(idx), np.concatenate(uvs)


def error_faces(result, max_faces: int = 12) -> list[int]:
    """The faces :func:`error_maps_png` draws by default: those with FE nodes, most nodes first."""
    counts = [(f.nodes, f.index) for f in result.report.faces if f.nodes > 0]
    return sorted(k for _, k in sorted(counts, reverse=True)[:max_faces])


@dataclass(frozen=True)
class ErrorScale:
    """The one colour scale of a result's error maps: 0 to ``top``, the larger of ``largest``, the largest
    node error of the result (mm), and the limit.

    ``tolerance`` (mm, None when none was set) and ``allowance``, what the field's scatter adds to it at the
    nodes (mm), give the ``limit`` a node's error is judged against, as
    :attr:`hot2cold.pipeline.report.Report.tolerance_met` judges.  Errors up to the limit take viridis,
    errors above it a red ramp, so a map tells at a glance whether anything misses.  The allowance is named
    in the texts only where it matters, as the report page does (above a tenth of the tolerance), or where
    an error passes only thanks to it.
    """

    largest: float
    tolerance: float | None
    allowance: float = 0.0

    @property
    def top(self) -> float:
        top = max(self.largest, self.limit or 0.0)
        return top if top > 0.0 else 1.0

    @property
    def limit(self) -> float | None:
        return None if self.tolerance is None else self.tolerance + self.allowance

    def label(self, largest: float | None = None) -> str:
        """``tolerance 0.001 mm``, or ``tolerance 0.001 + 0.0002 mm`` where the scatter allowance counts for
        errors up to ``largest`` mm (default: the result's largest)."""
        if self.tolerance is None:
            return "no tolerance set"
        largest = self.largest if largest is None else largest
        if self.allowance > 0.1 * self.tolerance or (self.allowance > 0.0 and
                                                     self.tolerance < largest <= self.tolerance + self.allowance):
            return f"tolerance {self.tolerance:.3g} + {self.allowance:.2g} mm"
        return f"tolerance {self.tolerance:.3g} mm"

    @property
    def norm(self) -> Normalize:
        return Normalize(0.0, self.top)

    @property
    def cmap(self) -> Colormap:
        low, limit = colormaps["viridis"], self.limit
        if limit is None or self.top <= limit:
            return low
        n = 1024
        n_low = int(np.clip(round(n * limit / self.top), 1, n - 1))
        colours = np.vstack([low(np.linspace(0.0, 1.0, n_low)),
                             colormaps["Reds"](np.linspace(0.55, 1.0, n - n_low))])
        return ListedColormap(colours, name="error above tolerance")

    def verdict(self, largest: float) -> tuple[str, tuple[float, float, float] | str]:
        """The pass/fail mark of a map whose largest error is ``largest`` (mm): its text and colour."""
        limit = self.limit
        if not np.isfinite(largest):
            return "no node measured", "0.4"
        if limit is None:
            return f"Δmax {largest:.2g} mm, no tolerance set", "0.2"
        if largest <= limit:
            return f"Δmax {largest:.2g} mm ≤ {self.label(largest)} ✓", PASS_COLOUR
        return f"Δmax {largest:.2g} mm > {self.label(largest)} ✗", FAIL_COLOUR


def error_scale(result) -> ErrorScale:
    """The colour scale every error map of ``result`` uses, whichever faces it shows: 0 to the larger of
    the largest node error of the result (``result.node_errors (N,)``, NaN ignored) and the tolerance
    (``result.report.tolerance`` plus the field's scatter ``allowance``).  One scale for all faces, so that
    a face with errors of 1e-13 mm looks calm next to one at 1e-3 mm."""
    rep = result.report
    err = np.asarray(result.node_errors, float)
    finite = err[np.isfinite(err)]
    largest = float(finite.max()) if len(finite) else 0.0
    if rep.tolerance is None:
        return ErrorScale(largest, None)
    return ErrorScale(largest, float(rep.tolerance), float(rep.allowance or 0.0))


def _error_colourbar(fig: Figure, axes, scale: ErrorScale) -> None:
    """One colour bar for all ``axes``, the limit drawn across it as a black line and named at its tick."""
    cb = fig.colorbar(ScalarMappable(norm=scale.norm, cmap=scale.cmap), ax=list(axes), shrink=0.9,
                      aspect=35)
    cb.set_label("distance to cold part [mm]", fontsize=9)
    cb.ax.tick_params(labelsize=7)
    limit = scale.limit
    if limit is None:
        cb.ax.yaxis.set_major_formatter(_SMALL)
        return
    ticks = [float(t) for t in MaxNLocator(6).tick_values(0.0, scale.top)
             if 0.0 <= t <= scale.top and abs(t - limit) > 0.08 * scale.top]
    values = sorted(ticks + [limit])
    named = scale.label().replace("tolerance ", "tolerance\n", 1).replace(" + ", "\n+ ", 1)
    cb.set_ticks(values, labels=[named if v == limit else f"{v:.2g}" for v in values])
    for text, v in zip(cb.ax.get_yticklabels(), values):
        if v == limit:
            text.set_fontweight("bold")
            text.set_fontsize(8)
    cb.ax.axhline(limit, color="k", linewidth=2.0)


def _worst_node_legend(ax, pts: np.ndarray, vals: np.ndarray) -> None:
    """Ring the node of ``pts (n, 2)`` with the largest of ``vals (n,)`` (black on a white halo, visible on
    every colour) and name it in a legend, in the corner of the axes that covers the fewest nodes and not
    the ringed one (matplotlib's "best" place costs seconds on thousands of nodes).  Call after the axes'
    limits are set."""
    worst = int(np.argmax(vals))
    for width, colour in ((3.0, "white"), (1.4, "black")):
        ax.scatter(pts[worst, :1], pts[worst, 1:], s=120, facecolors="none", edgecolors=colour,
                   linewidths=width, zorder=5)
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    frac = (pts - [x0, y0]) / [(x1 - x0) or 1.0, (y1 - y0) or 1.0]          # (n, 2) in axes fraction
    corners = {"upper right": (1, 1), "upper left": (0, 1), "lower left": (0, 0), "lower right": (1, 0)}

    def covered(corner: tuple[int, int]) -> float:
        near = (np.abs(frac[:, 0] - corner[0]) < 0.6) & (np.abs(frac[:, 1] - corner[1]) < 0.12)
        return float(near.sum()) + (np.inf if near[worst] else 0.0)

    loc = min(corners, key=lambda name: covered(corners[name]))
    handle = Line2D([], [], linestyle="none", marker="o", markersize=10, markerfacecolor="none",
                    markeredgecolor="black", markeredgewidth=1.4, label=f"worst node: {vals[worst]:.2e} mm")
    ax.legend(handles=[handle], loc=loc, fontsize=7, framealpha=0.85, handletextpad=0.3, borderpad=0.3)


def error_maps_png(result, faces: list[int] | None = None, *, mesh: TriangleMesh | None = None,
                   columns: int = 3, panel_in: float = 4.2, dpi: int = 100) -> bytes:
    """Per face, its FE nodes coloured by their distance to the cold part (:func:`error_maps_figure`).
    Returns PNG bytes."""
    return _png(error_maps_figure(result, faces, mesh=mesh, columns=columns, panel_in=panel_in), dpi)


def error_maps_figure(result, faces: list[int] | None = None, *, mesh: TriangleMesh | None = None,
                      columns: int = 3, panel_in: float = 4.2) -> Figure:
    """The figure of :func:`error_maps_png`: a panel per face (default :func:`error_faces`), its FE nodes
    (circles) and the nodes of its edges (diamonds) coloured by their distance to the cold part (mm,
    eq. 21), over the face in developed parameters.

    All panels, and every error map of the same result, share :func:`error_scale` and one colour bar with
    the tolerance marked on it.  Each panel's title gives its nodes and errors and a pass/fail mark
    (green ✓ / red ✗) of the largest error it shows against the tolerance; the worst node is ringed and
    named in a legend.
    """
    faces = error_faces(result) if faces is None else list(faces)
    if not faces:
        raise ValueError("no face to draw")
    mesh = mesh if mesh is not None else mesh_of(result)
    cls = result.classification
    err = np.asarray(result.node_errors, float)
    scale = error_scale(result)
    norm, cmap = scale.norm, scale.cmap
    rows, cols = _grid(len(faces), columns)
    fig = Figure(figsize=(panel_in * cols + 1.0, panel_in * 1.02 * rows), layout="constrained")
    FigureCanvasAgg(fig)
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for ax in axes[len(faces):]:
        ax.set_axis_off()
    for ax, k in zip(axes, faces):
        surface = result.part.faces[k].surface
        verts, tris = _face_vertices(mesh, k)
        dev = _Developed.of(surface, clip_uv(surface, mesh.uv[verts]))
        xy = dev.xy(mesh.uv[verts])
        ax.add_collection(PolyCollection(xy[tris], facecolors="0.9", edgecolors="0.9", linewidths=0.3))
        face_nodes = cls.nodes_of(Role.FACE, k)
        edge_nodes, edge_uv = _edge_node_uv(result, k)
        pts = np.concatenate([dev.xy(cls.uv[face_nodes]), dev.xy(edge_uv)])
        vals = np.concatenate([err[face_nodes], err[edge_nodes]])
        marker = np.r_[np.zeros(len(face_nodes), bool), np.ones(len(edge_nodes), bool)]
        ok = np.isfinite(vals)
        pts, vals, marker = pts[ok], vals[ok], marker[ok]
        size = float(np.clip(3000.0 / max(len(vals), 1), 1.5, 25.0))
        for m, sym, s in ((False, "o", size), (True, "D", 1.6 * size)):
            sel = marker == m
            order = np.argsort(vals[sel])                              # largest errors on top
            if sel.any():
                ax.scatter(pts[sel][order, 0], pts[sel][order, 1], c=vals[sel][order], cmap=cmap, norm=norm,
                           s=s, marker=sym, linewidths=0)
        rep = result.report.faces[k]
        on_edges = err[edge_nodes]
        on_edges = on_edges[np.isfinite(on_edges)]
        edge_text = (f"{len(on_edges)} nodes of its edges: Δmax {on_edges.max():.1e} mm" if len(on_edges)
                     else "no nodes on its edges")
        ax.set_title(f"face {k}: {rep.nodes} nodes, Δmax {rep.delta_max:.1e}, Δmean {rep.delta_mean:.1e} mm\n"
                     f"{edge_text}", fontsize=8, pad=17)
        mark, colour = scale.verdict(float(vals.max()) if len(vals) else float("nan"))
        ax.annotate(mark, (0.5, 1.0), xycoords="axes fraction", xytext=(0, 3), textcoords="offset points",
                    ha="center", va="bottom", fontsize=8, fontweight="bold", color=colour)
        allxy = np.concatenate([xy, pts]) if len(pts) else xy
        lo, hi = allxy.min(axis=0), allxy.max(axis=0)
        pad = 0.03 * (hi - lo) + 1e-9
        ax.set_xlim(lo[0] - pad[0], hi[0] + pad[0])
        ax.set_ylim(lo[1] - pad[1], hi[1] + pad[1])
        _set_aspect(ax, allxy)
        if len(vals):
            _worst_node_legend(ax, pts, vals)
        ax.set_xlabel("along u [mm]", fontsize=8)
        ax.set_ylabel("along v [mm]", fontsize=8)
        ax.tick_params(labelsize=7)
    _error_colourbar(fig, axes, scale)
    return fig


# -------------------------------------------------------------------------------------------- curvature
def curvature_faces(result, n_faces: int = 4, mesh: TriangleMesh | None = None) -> list[int]:
    """The largest faces by area (most first), for :func:`curvature_png`."""
    mesh = mesh if mesh is not None else mesh_of(result)
    area = _face_areas(mesh, len(result.part.faces))
    return [int(k) for k in np.argsort(-area, kind="stable")[:n_faces] if area[k] > 0]


def _inside_mask(xy: np.ndarray, triangles: np.ndarray, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """Which nodes of the regular grid ``gx`` (nx,) x ``gy`` (ny,) lie in one of the triangles (a face's
    trimmed domain from its mesh): a mask ``(ny, nx)``.  The triangles are rasterised by Agg (no
    antialiasing) on three pixels per grid step, and a node is in when the pixel centred on it is: the
    rasteriser's edge rounding then reaches a third of a grid step at most."""
    nx, ny, sub = len(gx), len(gy), 3
    dx = (gx[-1] - gx[0]) / max(nx - 1, 1) or 1.0
    dy = (gy[-1] - gy[0]) / max(ny - 1, 1) or 1.0
    fig = Figure(figsize=(sub * nx, sub * ny), dpi=1)             # whole pixels, exactly
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    ax.set_xlim(gx[0] - dx / 2, gx[-1] + dx / 2)
    ax.set_ylim(gy[0] - dy / 2, gy[-1] + dy / 2)
    ax.add_collection(PolyCollection(xy[triangles], facecolors="k", edgecolors="none", linewidths=0.0,
                                     antialiaseds=False))
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    red = np.asarray(canvas.buffer_rgba())[..., 0]                 # black triangles on the white figure
    if red.shape != (sub * ny, sub * nx):
        raise RuntimeError(f"rasterised mask is {red.shape}, expected {(sub * ny, sub * nx)}")
    return red[::-1][sub // 2::sub, sub // 2::sub] < 128


def _outward_sign(surface: BSplineSurface, mesh: TriangleMesh, verts: np.ndarray, tris: np.ndarray) -> float:
    """+1 when the surface normal ``S_u x S_v`` points out of the solid on this face, -1 when inward (the
    mesh's triangles face outward)."""
    p = mesh.vertices[verts][tris]
    outward = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    uv = clip_uv(surface, mesh.uv[verts][tris].mean(axis=1))
    su, sv = surface_derivatives(surface, uv[:, 0], uv[:, 1])
    return 1.0 if np.nansum(np.einsum("ij,ij->i", np.cross(su, sv), outward)) >= 0 else -1.0


def _curvature_norm(values: np.ndarray, floor: float) -> Normalize:
    """Colour scale of a curvature map, symmetric about zero (white; on the diverging map red is convex and
    blue concave): up to the 99th percentile of ``|values|`` (a sharp leading edge does not wash out the
    rest), at least ``floor`` (a map that is all zero stays white)."""
    finite = np.abs(values[np.isfinite(values)])
    top = float(np.percentile(finite, 99)) if len(finite) else 0.0
    top = max(top, floor)
    return Normalize(-top, top)


def curvature_floor(result, fc: "FaceCurvature") -> float:
    """The noise floor (1/mm) of the curvatures of ``fc``: ``CURVATURE_NOISE * max(1 / diagonal, largest
    |H| of the face hot or cold)``; a curvature, or a change of curvature, smaller than it is drawn as 0.

    Why both terms: on a plane the face's own largest |H| is the rounding noise itself, so a floor relative
    to it alone would draw noise as a full colour ramp; the part's size sets an absolute floor instead -- a
    radius of curvature of 1e9 diagonals sags 5e-10 diagonals over the whole part, far below any tolerance,
    while rounding in H stays some 1e-16 of
    ``1 / size``.  On a strongly curved face rounding grows with |H|, hence the relative term, which still
    leaves a change of 1e-9 of the face's curvature visible."""
    largest = [np.nanmax(np.abs(v[fc.inside])) for v in (fc.hot, fc.cold)
               if fc.inside.any() and np.isfinite(v[fc.inside]).any()]
    return CURVATURE_NOISE * max([1.0 / float(result.part.diagonal), *map(float, largest)])


def _flushed(values: np.ndarray, floor: float) -> np.ndarray:
    """``values`` with every entry below ``floor`` in size set to 0 (NaN kept)."""
    with np.errstate(invalid="ignore"):
        return np.where(np.abs(values) < floor, 0.0, values)


@dataclass(frozen=True, eq=False)
class FaceCurvature:
    """Mean curvature of a face on a regular grid over its trimmed domain, in developed parameters.

    ``extent = (x0, x1, y0, y1)`` in mm; ``hot`` and ``cold`` ``(ny, nx)`` in 1/mm, NaN outside the face
    (``inside`` False).  The sign is taken with the outward normal of the solid and flipped, so H > 0
    where the face is convex (bulges outward) and H < 0 where it is concave.
    """

    face: int
    extent: tuple[float, float, float, float]
    inside: np.ndarray
    hot: np.ndarray
    cold: np.ndarray
    equal_aspect: bool


def face_curvature(result, k: int, mesh: TriangleMesh | None = None, grid_points: int = 40000) -> FaceCurvature:
    """Mean curvature of the hot and the morphed surface of face ``k`` at the same parameters."""
    mesh = mesh if mesh is not None else mesh_of(result)
    hot_s, cold_s = result.part.faces[k].surface, result.faces[k].surface
    verts, tris = _face_vertices(mesh, k)
    if not len(verts):
        raise ValueError(f"face {k} has no triangles")
    uv0 = clip_uv(hot_s, mesh.uv[verts])
    dev = _Developed.of(hot_s, uv0)
    xy = dev.xy(uv0)
    ext = np.maximum(np.ptp(xy, axis=0), 1e-12)
    ratio = ext[0] / ext[1]
    equal = bool(1 / 3 <= ratio <= 3)
    if equal:                                   # drawn to scale: square grid cells
        nx = int(np.clip(np.sqrt(grid_points * ratio), 16, 1000))
        ny = int(np.clip(grid_points / nx, 16, 1000))
    else:                                       # a strip, drawn stretched
        nx = ny = int(np.clip(np.sqrt(grid_points), 16, 1000))
    gx = np.linspace(xy[:, 0].min(), xy[:, 0].min() + ext[0], nx)
    gy = np.linspace(xy[:, 1].min(), xy[:, 1].min() + ext[1], ny)
    inside = _inside_mask(xy, tris, gx, gy)
    px, py = np.meshgrid(gx, gy)
    uv = clip_uv(hot_s, dev.uv(np.column_stack([px[inside], py[inside]])))
    sign = -_outward_sign(hot_s, mesh, verts, tris)                 # convex positive
    values = []
    for surf in (hot_s, cold_s):
        grid = np.full(inside.shape, np.nan)
        grid[inside] = sign * mean_curvature(surf, uv[:, 0], uv[:, 1])
        values.append(grid)
    return FaceCurvature(k, (float(gx[0]), float(gx[-1]), float(gy[0]), float(gy[-1])), inside, values[0],
                         values[1], equal)


def curvature_png(result, faces: list[int] | None = None, *, mesh: TriangleMesh | None = None,
                  panel_in: float = 4.0, dpi: int = 100, grid_points: int = 40000) -> bytes:
    """Mean curvature of the hot and the morphed surface of each face (:func:`curvature_figure`).
    Returns PNG bytes."""
    return _png(curvature_figure(result, faces, mesh=mesh, panel_in=panel_in, grid_points=grid_points), dpi)


def curvature_figure(result, faces: list[int] | None = None, *, mesh: TriangleMesh | None = None,
                     panel_in: float = 4.0, grid_points: int = 40000) -> Figure:
    """The figure of :func:`curvature_png`: a row per face (default the four largest), the mean curvature
    ``(ny, nx)`` of the hot and the morphed surface and cold minus hot, from :func:`face_curvature` (H > 0
    where convex).

    Values below :func:`curvature_floor` are drawn as 0, and a panel that is all below it says so in its
    title ("flat", or "no change" for the difference).  Hot and cold share one colour scale, symmetric about
    zero; the difference has its own, also symmetric.
    """
    mesh = mesh if mesh is not None else mesh_of(result)
    faces = curvature_faces(result, mesh=mesh) if faces is None else list(faces)
    if not faces:
        raise ValueError("no face to draw")
    fig = Figure(figsize=(panel_in * 3, panel_in * 0.95 * len(faces)), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(faces), 3, squeeze=False)
    for row, k in zip(axes, faces):
        fc = face_curvature(result, k, mesh, grid_points)
        inside = fc.inside
        floor = curvature_floor(result, fc)
        hot, cold = _flushed(fc.hot, floor), _flushed(fc.cold, floor)
        diff = _flushed(fc.cold - fc.hot, floor)
        norm = _curvature_norm(np.concatenate([hot[inside], cold[inside]]), floor)
        dnorm = _curvature_norm(diff[inside], floor)
        panels = ((hot, norm, "hot", "H"), (cold, norm, "cold (morphed)", "H"), (diff, dnorm, "cold − hot", "ΔH"))
        for ax, (vals, nrm, label, sym) in zip(row, panels):
            cmap = "RdBu_r" if sym == "H" else "PuOr_r"
            im = ax.imshow(vals, origin="lower", extent=fc.extent, cmap=cmap, norm=nrm, interpolation="nearest")
            cb = fig.colorbar(im, ax=ax, shrink=0.9, format=_SMALL, extend="both")
            cb.set_label(f"mean curvature {sym} [1/mm]", fontsize=8)
            cb.ax.tick_params(labelsize=7)
            shown = vals[inside]
            shown = shown[np.isfinite(shown)]
            if not len(shown):
                span = f"{sym} undefined"
            elif not shown.any():
                span = (f"{'flat' if sym == 'H' else 'no change'}: |{sym}| < {floor:.1e} 1/mm "
                        f"(noise floor) everywhere")
            else:
                span = f"{sym} {shown.min():.3g} … {shown.max():.3g} 1/mm"
            ax.set_title(f"face {k}, {label}\n{span}", fontsize=9)
            ax.set_aspect("equal" if fc.equal_aspect else "auto")
            ax.set_xlabel("along u [mm]", fontsize=8)
            ax.set_ylabel("along v [mm]", fontsize=8)
            ax.tick_params(labelsize=7)
    return fig
