"""hot2cold: hot-to-cold B-spline morphing of CAD solids from an FE displacement field.

The method is GT2014-26683 (Gaun, Bestle, Huppertz); see ``METHOD.md`` in the shared folder.
"""
__version__ = "0.1.0"
