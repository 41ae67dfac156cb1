"""Hot (red), cold (blue) and the FE nodes of the bundled twisted blade, for CQ-editor.

Open this file in CQ-editor and press F5 (Render).  It morphs ``twisted_blade.step`` with
``twisted_blade_field.csv`` (both next to this script) and shows

* ``hot``: the hot part, red and see-through;
* ``cold``: the cold part, blue;
* ``nodes``: an even subsample of the FE nodes (at most ``max_nodes``) as points, at their cold positions
  (hot position + ``exaggerate`` x displacement) or, with ``nodes_on = "hot"``, at their hot positions.
  CQ-editor draws points as its default yellow "+" markers (its ``color`` option colours faces only).

Each can be hidden with its check box in CQ-editor's Objects panel.

Parameters (top-level assignments, which CQGI, the script runner CQ-editor uses, picks up; edit them here, or
pass them as ``build_parameters``):

* ``exaggerate``: scales the displacement for display: the part shown as cold is the morph with the field
  times ``exaggerate`` (cold_shown = hot + exaggerate x (cold - hot)).  The bundled field moves the blade by
  1.55 mm at the most, so 1.0 (true scale) looks like a slight offset; try 10.
* ``show_nodes``, ``nodes_on``, ``max_nodes``: the FE nodes (see above).
* ``sample_dir``: the folder with the STEP and the field.  Empty: CQGI runs a script with ``exec`` and
  does not set ``__file__``, so the folder is looked for, in this order, in the environment variable
  ``HOT2COLD_SAMPLES``, next to this file (when ``__file__`` is set), in the current directory and its
  ``sample_parts`` folder, and in the ``sample_parts`` folder of the checkout hot2cold is installed from
  (``pip install -e``).  CQ-editor itself sets ``__file__`` (and by default changes to the script's
  folder), so there the files next to this script are found.

Nothing is cached on disk: each run morphs again (10-20 s).

Runs outside CQ-editor too: ``python sample_parts/view_in_cq_editor.py`` prints what it would show.
"""
import os
from pathlib import Path

import cadquery as cq

import hot2cold
from hot2cold import Settings, morph, read_field

exaggerate = 1.0
show_nodes = True
nodes_on = "cold"
max_nodes = 1500
sample_dir = ""

# (a dict, so that CQGI does not take the file names for parameters)
FILES = {"step": "twisted_blade.step", "field": "twisted_blade_field.csv"}


def find_sample_dir(explicit):
    """The first folder holding both sample files, from the places the module docstring lists."""
    candidates = []
    if explicit:
        candidates.append(Path(explicit))
    if os.environ.get("HOT2COLD_SAMPLES"):
        candidates.append(Path(os.environ["HOT2COLD_SAMPLES"]))
    here = globals().get("__file__")  # not set under CQGI
    if here:
        candidates.append(Path(here).resolve().parent)
    candidates += [Path.cwd(), Path.cwd() / "sample_parts",
                   Path(hot2cold.__file__).resolve().parent.parent / "sample_parts"]
    if explicit:  # a folder the user named must hold the files: no silent fallback
        candidates = candidates[:1]
    for folder in candidates:
        if all((folder / name).is_file() for name in FILES.values()):
            return folder
    raise FileNotFoundError(
        f"{FILES['step']} and {FILES['field']} are in none of: {', '.join(str(c) for c in candidates)}; "
        f"set sample_dir at the top of this script, or the environment variable HOT2COLD_SAMPLES, "
        f"to the hot2cold sample_parts folder")


def node_points(points, displacements, scale, count):
    """A compound of at most ``count`` vertices (an even subsample, always the same) at points + scale x d."""
    step = max(1, -(-len(points) // max(1, int(count))))
    shown = points[::step] + scale * displacements[::step]
    return cq.Compound.makeCompound([cq.Vertex.makeVertex(*map(float, p)) for p in shown])


folder = find_sample_dir(sample_dir)
field = read_field(folder / FILES["field"])
scale = float(exaggerate)
# the field times exaggerate moves the blade farther than a hot-to-cold field does: the bound scales with it
bound = Settings().max_displacement_rel * max(scale, 1.0)
result = morph(folder / FILES["step"], (field.points, scale * field.displacements),
               Settings(max_displacement_rel=bound))

# show_object's options are passed as a fresh dict each time (CQGI's default dict is shared between calls).
# In CQ-editor 0.7 "alpha" is the opacity: 1 opaque, 0 invisible.
if "show_object" not in globals():  # plain python: list what would be shown
    def show_object(obj, name=None, options=None):
        print(f"{name}: {type(obj).__name__}, valid={obj.isValid()}, options={options}")

show_object(result.hot, name="hot", options={"color": "red", "alpha": 0.35})
show_object(result.cold, name="cold", options={"color": "blue", "alpha": 1.0})
if show_nodes:
    at = scale if str(nodes_on).lower() == "cold" else 0.0
    show_object(node_points(field.points, field.displacements, at, max_nodes), name="nodes",
                options={})
