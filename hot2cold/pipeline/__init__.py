"""The hot-to-cold morph in the paper's order (GT2014-26683); :func:`.morph.morph` runs it.

:mod:`.load` (read, convert to B-splines, decompose) -> :mod:`.classify` (foot points; face, edge, vertex
or ignored, eq. 4, 27, 33-37) -> :mod:`.edge_fit` (eq. 1-22) -> :mod:`.face_fit` (eq. 23-38) with
:mod:`.artificial` nodes (eq. 39) -> :mod:`.refine` (to the tolerance, by default) -> :mod:`.g1` (eq. 56-75) ->
rebuild and tolerances (:mod:`hot2cold.kernel`) -> :mod:`.checks` -> :mod:`.report` (eq. 21-22).
:mod:`.invert` turns a cold-to-hot field around first.
"""
