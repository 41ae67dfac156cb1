"""The tolerances and switches of a morph, in one explicit, documented record.

A :class:`Settings` is passed down through every step; no step reads module-level state, and nothing here
touches OpenCascade's global settings (nor, by default, the process's BLAS threads: ``blas_threads``).
Lengths are in millimetres.  Where a length is ``None`` it is taken relative to the part: the ``*_rel``
factor times the diagonal of the part's bounding box.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

#: Single-precision machine epsilon, the paper's FLT_EPSILON in the SVD cut-off of eq. (20).
FLT_EPSILON = float(np.finfo(np.float32).eps)


class Continuity(enum.Enum):
    """How smooth the morph keeps the edges along which the hot faces met smoothly."""

    G1 = "g1"      #: tangent planes restored along tangent edges (paper section 5, eq. 56-75)
    G2 = "g2"      #: and the normal curvature across edges that were curvature-continuous when hot


@dataclass(frozen=True)
class Settings:
    """Tolerances of the hot-to-cold morph.

    Attributes
    ----------
    node_distance : float or None
        A node whose distance to every face exceeds this (mm) takes no part (volume nodes, other parts).
        ``None``: ``node_distance_rel`` x part diagonal.
    node_distance_rel : float
        Relative default of ``node_distance``.
    edge_distance : float or None
        A node within this distance (mm) of an edge curve feeds that edge (METHOD step 3) rather than the
        face interior.  ``None``: ``edge_distance_rel`` x part diagonal.
    edge_distance_rel : float
        Relative default of ``edge_distance``.
    svd_epsilon : float
        The machine-precision factor of the truncated SVD cut-off: singular values below
        ``sigma_1 * n * svd_epsilon`` are dropped, ``n`` the unknowns (eq. 20 with the paper's FLT_EPSILON,
        but the paper's ``s - 1`` rows made the rank depend on the node count: :mod:`hot2cold.core.lstsq`).
    vertex_neighbours : int
        How many nearest foot points estimate a vertex displacement by a local least-squares fit when no
        node sits on the vertex.
    artificial_weight : float
        Weight of an artificial node's row in a fit, against 1 for an FE node: artificial nodes settle the
        poles the FE nodes leave open (empty or thin knot spans, trimmed-away parts) without pulling the
        surface away from the FE nodes where both are present.
    tolerance : float or None
        The largest error (mm) accepted, at the nodes and between them where the nodes tell the field
        (:mod:`hot2cold.pipeline.refine`), beyond what the field's own scatter allows.  Faces and edges whose
        fit misses it are refined by knot insertion and degree elevation (the hot shape is kept exactly) and
        fitted again.  The default, 1e-3 mm, is the paper's accuracy on its aerofoil (Table 1: Δmax 1e-4 to 2e-3
        mm, Δmean 6e-6 to 9e-5) and a tenth of the tightest profile tolerances of compressor aerofoils (about
        0.01 mm): a fixed length rather than a share of the displacement, since what manufacturing accepts
        does not grow with how far the part moves.  None: no tolerance (nothing refined, nothing checked).
    keep_knots : bool
        Keep every degree and knot vector of the hot part, as the paper does (its strict same-structure
        mode): nothing is refined; the tolerance is still checked and reported.
    smooth : bool
        Fit the field's signal, not its noise: where the nodes scatter about a smooth field (noise, volume
        nodes beside the surface; :func:`hot2cold.core.localfit.scatter`) by more than a hundredth of the
        tolerance, every edge and face fit is smoothed towards the field's local estimate until it leaves
        that scatter at the nodes (Tikhonov regularisation with its weight chosen by the discrepancy
        principle, :func:`hot2cold.core.lstsq.solve_tsvd`).  A plain fit follows the noise, most where few
        nodes decide a pole (a thin leading edge).
    max_refinements : int
        Rounds of refinement a face gets at the most.  Each halves the spans that miss, so 8 rounds can cut a
        hot span into 256; the refinement stops sooner where the spans reach the nodes' spacing.  (A real FE
        field next to a clamped face can need more than half of them to meet the default tolerance.)
    g1_angle : float or None
        Edges where the hot faces meet within this angle (degrees) are tangent; after the morph their
        kink is corrected (paper section 5).  None: no G1 correction.
    continuity : Continuity
        ``Continuity.G2`` (or "g2") also restores curvature continuity, the paper's outlook: across tangent
        edges where the hot faces' normal curvatures agreed within ``g2_tolerance``, the faces are fitted
        again with their curvature across the edge asked to be common (:mod:`hot2cold.pipeline.g2`), where
        that keeps them within the tolerance (or 10 % of their plain fit's distance from the field, where
        that is farther).  With G1 (the default) the curvature jumps are measured and reported only.
    g2_tolerance : float
        The largest jump of the normal curvature across an edge, as a share of the edge's largest curvature
        (or of one over the part's diagonal, for nearly flat faces), at which the faces count as
        curvature-continuous; the G2 correction aims to keep the cold jump within it.
    edge_samples_per_span : int
        Points per knot span at which a morphed edge that is not an iso-curve of a face constrains that
        face's fit (keeps trimmed faces on their edges).
    blas_threads : int or None
        Threads the BLAS/LAPACK library (OpenBLAS, MKL) may use while the morph runs, set through
        ``threadpoolctl`` for the duration of the call.  The limit is process-wide: while it holds, every
        other thread of the process (a Dask worker's other tasks, the caller's own numpy) gets it too.
        The fits are many small dense problems that gain nothing from threads, and on a busy machine the
        threads spin against each other: the fits then take many times longer with the library's default
        threads than with one.
        None (the default) leaves the library as it is; the ``hot2cold`` command holds its own process to
        one thread around its morph.
    threads : int
        Threads the morph's work per face may run in (foot points, grids, fits; the kernel's calls still run one
        at a time), where two faces have ``hot2cold.core.threads.LARGE`` nodes or more (smaller faces' work is
        mostly Python's own, which runs one thread at a time): the results are the same for any count.  The
        ``hot2cold morph`` command takes the process's cores; a batch runs one job per core, each in one
        thread; 1 (the default) for a morph called from Python, which may have other work for the cores.
    kernel_process : bool
        Integrate the volumes of the hot and the cold solids (the volume checks of the cold part) in a second
        Python process while the morph goes on (:mod:`hot2cold.kernel.side`): the kernel holds Python's lock
        through its calls, so a thread cannot run them beside the morph's own work, and on a part of hundreds
        of faces they are its slowest kernel calls.  The volumes are the same to the bit either way; a second
        process that cannot start or fails leaves them to this one.  Only for a part of
        ``hot2cold.pipeline.morph.KERNEL_PROCESS_FACES`` faces or more (a smaller part's volumes take less than
        the process takes to start).  The ``hot2cold morph`` command runs one when it has a second core; False
        (the default) for a morph called from Python, which may run where starting another interpreter
        (``sys.executable``) is unwelcome, and for a batch job, whose cores run other jobs.
    extrapolate : bool
        A face that gets no FE node (a field that covers only part of the solid) is an error (FieldError)
        unless this is True: then such faces are morphed from artificial nodes alone, extrapolated from the
        foot points of the other faces, with a warning.
    element_points : bool
        When the field brings its FE elements (``DisplacementField.triangles``: a ``.frd``, a VTU with cells, an
        ``.npz`` with ``triangles``), the morph also takes the field at 4 points inside each boundary triangle,
        by the triangle's own shape functions (:func:`hot2cold.pipeline.load.element_points`): the solver's
        field between its nodes.  Not for a field that scatters by more than a tenth of the tolerance (noise,
        volume nodes; ``hot2cold.pipeline.morph.NOISY_SHARE``): its fits are smoothed instead.  Off, the morph
        sees the nodes alone and estimates the field between them.
    max_displacement_rel : float
        The largest displacement of a node on the part accepted, as a share of the part's bounding-box
        diagonal; a field that moves a node farther is refused (FieldError) as no hot-to-cold field.  A
        hot-to-cold field is thermal and centrifugal strain, and a part's rigid shift with the parts it sits
        on: the paper's fields move parts of 50 to 300 mm by up to 3 mm (at most 6 %), the bundled sample
        fields by less (``docs/guide/bad_input.md``, "How the checks work").  Cold positions given as
        displacements move a part by about its own size.  0.1 leaves honest fields a margin over the
        paper's largest; raise it for the rare honest field that moves a part farther (a small part carried
        far by a larger one).
    """

    node_distance: float | None = None
    node_distance_rel: float = 1e-3
    edge_distance: float | None = None
    edge_distance_rel: float = 1e-4
    svd_epsilon: float = FLT_EPSILON
    vertex_neighbours: int = 20
    edge_samples_per_span: int = 4
    artificial_weight: float = 0.1
    tolerance: float | None = 1e-3
    keep_knots: bool = False
    smooth: bool = True
    max_refinements: int = 8
    g1_angle: float | None = 1.0
    continuity: Continuity = Continuity.G1
    g2_tolerance: float = 0.01
    blas_threads: int | None = None
    threads: int = 1
    kernel_process: bool = False
    extrapolate: bool = False
    element_points: bool = True
    max_displacement_rel: float = 0.1

    def __post_init__(self):
        try:
            object.__setattr__(self, "continuity", Continuity(self.continuity))
        except ValueError:
            raise ValueError(f"continuity must be one of {', '.join(c.value for c in Continuity)}, "
                             f"got {self.continuity!r}") from None
        if not (np.isfinite(self.g2_tolerance) and self.g2_tolerance > 0):
            raise ValueError(f"g2_tolerance must be a positive share, got {self.g2_tolerance!r}")
        for name in ("node_distance", "edge_distance", "tolerance"):
            value = getattr(self, name)
            if value is not None and not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive length in mm, got {value!r}")
        for name in ("node_distance_rel", "edge_distance_rel", "svd_epsilon", "artificial_weight",
                     "max_displacement_rel"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive, got {value!r}")
        if self.vertex_neighbours < 4:
            raise ValueError(f"vertex_neighbours must be at least 4, got {self.vertex_neighbours}")
        if self.max_refinements < 0:
            raise ValueError(f"max_refinements must be at least 0, got {self.max_refinements}")
        if self.blas_threads is not None and self.blas_threads < 1:
            raise ValueError(f"blas_threads must be at least 1 or None, got {self.blas_threads}")
        if self.threads < 1:
            raise ValueError(f"threads must be at least 1, got {self.threads}")
        if self.edge_samples_per_span < 1:
            raise ValueError(f"edge_samples_per_span must be at least 1, got {self.edge_samples_per_span}")

    def lengths(self, diagonal: float) -> tuple[float, float]:
        """``(node_distance, edge_distance)`` in mm for a part whose bounding box diagonal is ``diagonal``."""
        node = self.node_distance if self.node_distance is not None else self.node_distance_rel * diagonal
        edge = self.edge_distance if self.edge_distance is not None else self.edge_distance_rel * diagonal
        return node, edge


#: The options a message may name that are keywords of :func:`hot2cold.morph`, not fields of :class:`Settings`
#: (option name -> keyword); the option names are the command line's (``--field-units``: ``field_units``).
MORPH_KEYWORDS = {"field": "field", "field_units": "units", "field_name": "field_name", "field_step": "field_step",
                  "columns": "columns", "field_points": "field_points", "invert": "invert"}

#: A message's option in Python words (:func:`option`): ``morph(units='m')``, ``Settings(extrapolate=True)``.
OPTION_WORDS = r"\b(morph|Settings)\((\w+)=([^()]*)\)"


def option(name: str, value=...) -> str:
    """How a message of the library names option ``name`` (the command line's name: ``field_units``,
    ``node_distance``, ``field`` for the field argument) with ``value``: in Python's words, a keyword of
    :func:`hot2cold.morph` (``morph(units='m')``) or a :class:`Settings` field (``Settings(extrapolate=True)``;
    ``...`` for no value).  The command line and a batch say it in their own words
    (:func:`hot2cold.cli.options.in_words` reads :data:`OPTION_WORDS`)."""
    if name in MORPH_KEYWORDS:
        api, keyword = "morph", MORPH_KEYWORDS[name]
    elif name in Settings.__dataclass_fields__:
        api, keyword = "Settings", name
    else:
        raise ValueError(f"no option {name!r}: a keyword of morph ({', '.join(MORPH_KEYWORDS)}) or a Settings field")
    return f"{api}({keyword}={'...' if value is ... else repr(value)})"
