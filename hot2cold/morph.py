"""Old import path of the morph (``from hot2cold.morph import morph, MorphResult``): see
:mod:`hot2cold.pipeline.morph`.

Importing this module makes it the attribute ``hot2cold.morph``, where the function is expected
(``hot2cold.morph(hot, field)``), so the module can be called like the function.
"""
import sys
import types

from .pipeline.morph import MorphResult, Progress, check_result, morph

__all__ = ["MorphResult", "Progress", "check_result", "morph"]


class _CallableModule(types.ModuleType):
    def __call__(self, *args, **kwargs):
        return morph(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
