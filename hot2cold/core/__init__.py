"""The numeric core: numpy and scipy only, no kernel import.

Surfaces and curves are plain records (:mod:`.bspline`: poles ``(nu, nv, 3)``, full knot vectors,
degrees); the part is plain records too (:mod:`.model`).  Here also the truncated-SVD least squares
(:mod:`.lstsq`), foot points by Newton's method (:mod:`.footpoint`) and trimmed domains as rasters
(:mod:`.domain`).  Everything here is tested without OpenCascade and checked against it as an oracle.
"""
