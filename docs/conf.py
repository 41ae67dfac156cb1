"""Sphinx configuration of the hot2cold documentation (``python -m sphinx -W -b html docs docs/_build/html``)."""
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))
sys.path.insert(0, str(HERE.parent))

project = "hot2cold"
author = "the hot2cold developers"
copyright = "2026, the hot2cold developers"
release = version = __import__("hot2cold").__version__

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "options_table",
]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
myst_enable_extensions = ["dollarmath"]
myst_heading_anchors = 3
exclude_patterns = ["_build", "images/README.md", "**.ipynb_checkpoints"]
# the example notebooks are run at every build, in their folder: the pages show what the code gives now, and a
# notebook that fails fails the build
nb_execution_mode = "force"
nb_execution_timeout = 900
nb_execution_raise_on_error = True
nb_execution_show_tb = True
napoleon_numpy_docstring = True
napoleon_google_docstring = False
autodoc_member_order = "bysource"
autodoc_typehints = "none"
html_theme = "alabaster"
html_static_path = []
# the docs are built offline, in CI: no inventory of other projects is fetched
intersphinx_mapping = {}
nitpicky = False
