"""Old import path of the field readers (``from hot2cold.field import read_field``): see
:mod:`hot2cold.io.field`."""
from .io.field import UNITS, DisplacementField, as_field, read_field

__all__ = ["UNITS", "DisplacementField", "as_field", "read_field"]
