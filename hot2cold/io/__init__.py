"""Reading and writing: FE displacement fields (:mod:`.field`), outputs written whole or not at all
(:mod:`.atomic`).  STEP files are
read and written by :mod:`hot2cold.kernel.step` and :mod:`hot2cold.kernel.xcaf`."""
