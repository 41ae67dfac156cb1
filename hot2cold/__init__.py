"""hot2cold: hot-to-cold B-spline morphing of CAD solids from an FE displacement field.

The method is GT2014-26683 (Gaun, Bestle, Huppertz).  Start with :func:`morph`::

    from hot2cold import morph
    result = morph("hot.step", "field.csv")
    result.cold          # cadquery.Shape
    result.report        # accuracy and checks

Several fields (load cases) of one part: ``part = load("hot.step")``, then ``morph(part, field)`` for each.

The package is laid out as the method is:

* :mod:`hot2cold.core`: the numeric core, numpy and scipy only (B-spline records, least squares, foot
  points, trimmed domains, local fits, the part's records with their roles and states);
* :mod:`hot2cold.pipeline`: the morph in the paper's order (load, classify, edge and face fits, artificial
  nodes, refinement, G1, checks, report);
* :mod:`hot2cold.kernel`: every OpenCascade call (STEP, NURBS conversion, projection, rebuild, validity);
* :mod:`hot2cold.io`: field readers, atomic writing, viewer exports;
* :mod:`hot2cold.views`: pictures and the HTML report;
* :mod:`hot2cold.cli`: the ``hot2cold`` command, its options table and batch runs;
* :mod:`hot2cold.fe`: a gmsh + CalculiX pipeline that makes real fields;
* :mod:`hot2cold.testing`: synthetic fields for tests and benchmarks.

Names are imported when first used (as in scipy), so ``import hot2cold`` loads neither the kernel nor
CadQuery.
"""
import importlib

__version__ = "0.1.0"

#: Public name -> the module that defines it.
_LAZY = {
    "morph": "hot2cold.pipeline.morph",
    "load": "hot2cold.pipeline.load",
    "LoadedPart": "hot2cold.pipeline.load",
    "MorphResult": "hot2cold.pipeline.morph",
    "Settings": "hot2cold.settings",
    "DisplacementField": "hot2cold.io.field",
    "read_field": "hot2cold.io.field",
    "Hot2ColdError": "hot2cold.errors",
    "InputError": "hot2cold.errors",
    "StepReadError": "hot2cold.errors",
    "FieldError": "hot2cold.errors",
    "KernelError": "hot2cold.errors",
    "MorphError": "hot2cold.errors",
    "OutputError": "hot2cold.errors",
}

__all__ = [*_LAZY, "__version__"]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'hot2cold' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
