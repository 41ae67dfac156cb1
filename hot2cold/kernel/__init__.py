"""Every OpenCascade (OCP) and CadQuery import of hot2cold lives in this subpackage.

Kernel failures become :class:`hot2cold.errors.KernelError` (or :class:`~hot2cold.errors.StepReadError`)
here.  Modules: :mod:`.explore` (shape maps, size, B-spline geometry: the base the others build on),
:mod:`.step` and :mod:`.xcaf` (STEP in and out), :mod:`.conversion` (the part in normalised B-spline form) with
:mod:`.repair` (mending the faces the conversion breaks), :mod:`.topology` (decomposition into the core's
records), :mod:`.convert` (records <-> ``Geom_BSpline*``), :mod:`.project`
(the kernel's foot points and trimmed-domain classification), :mod:`.rebuild` (cold poles into a
copy of the hot part's kernel shape), :mod:`.tolerances` (edge and vertex tolerances fitted to the
gaps), :mod:`.validity` (BRepCheck, volumes, self-intersection) with :mod:`.side` (the volumes in a second process
beside the morph), :mod:`.tessellate`, :mod:`.shapes`
(CadQuery <-> TopoDS) and :mod:`.sampling` (points on and in a solid, for tests and benchmarks).
"""
