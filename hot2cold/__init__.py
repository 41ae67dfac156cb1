"""hot2cold: hot-to-cold B-spline morphing of CAD solids from an FE displacement field.

The method is GT2014-26683 (Gaun, Bestle, Huppertz).  Start with :func:`morph`::

    from hot2cold import morph
    result = morph("hot.step", "field.csv")
    result.cold          # cadquery.Shape
    result.report        # accuracy and checks
"""
__version__ = "0.1.0"

from .errors import FieldError, Hot2ColdError, InputError, KernelError, MorphError, StepReadError
from .field import DisplacementField, read_field
from .morph import MorphResult, morph
from .settings import Settings

__all__ = ["morph", "MorphResult", "Settings", "DisplacementField", "read_field", "Hot2ColdError",
           "InputError", "StepReadError", "FieldError", "KernelError", "MorphError", "__version__"]
