"""Support for tests and benchmarks, not used by the morph: analytic displacement fields
(:mod:`.synthetic`).  Sampling a solid's faces and volume with the kernel is
:mod:`hot2cold.kernel.sampling` (it calls OpenCascade, so it lives with the kernel)."""
