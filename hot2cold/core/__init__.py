"""The numeric core: numpy and scipy only, no kernel import.

Surfaces and curves are plain records (:mod:`.bspline`: poles ``(nu, nv, 3)``, full knot vectors,
degrees); the part is plain records too (:mod:`.model`, with the sides of a parameter domain, ``Side``,
the FE nodes' roles, ``Role``, and where each node takes part, ``Classification``).  Here also the
truncated-SVD least squares (:mod:`.lstsq`), foot points by Newton's method (:mod:`.footpoint`) and
trimmed domains as rasters (:mod:`.domain`, with the one numbering of trim states, ``Trim``), and the
distinct values, runs and places in runs of index arrays (:mod:`.arrays`).
Everything here is tested without OpenCascade and checked against it as an oracle.
"""
