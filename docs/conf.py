"""Sphinx configuration: the guides (Markdown), the notebooks (stored, never executed) and the API reference.

Build: ``sphinx-build -W --keep-going -b html docs docs/_build/html`` (``tests/test_docs.py`` runs it).
"""

import os
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(HERE / "_ext"))

os.environ.setdefault("JAX_PLATFORMS", "cpu")  # importing the modules is all autodoc needs

project = "ijoy_jax"
author = "ijoy_jax authors"
copyright = "the ijoy_jax authors, Apache-2.0"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "myst_nb",  # Markdown pages (MyST) and notebooks
    "ijoy_api",
]

root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]
html_theme = "alabaster"
html_static_path: list[str] = []
html_theme_options = {"page_width": "1200px", "sidebar_width": "240px"}

# Markdown: headings get anchors so that links such as sweeps.md#several-processes... resolve.
myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence"]

# Notebooks: shown with whatever outputs they store; the docs build never runs them (minutes of
# compilation each; the test suite runs them with nbmake).
nb_execution_mode = "off"
nb_merge_streams = True

autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False
napoleon_use_ivar = True  # an Attributes: section as fields, not a second description of each field

# The notebooks live in notebooks/ (where the tests run them); copy them into the source tree at each build.
_NB_SRC, _NB_DST = REPO / "notebooks", HERE / "notebooks"
_NB_DST.mkdir(exist_ok=True)
for _nb in sorted(_NB_SRC.glob("*.ipynb")):
    _dst = _NB_DST / _nb.name
    if not _dst.exists() or _dst.read_bytes() != _nb.read_bytes():
        shutil.copy2(_nb, _dst)

# Pages included from the repository's own Markdown files (README.md, BENCHMARKS.md, sweeps/README.md)
# keep their GitHub links; in the docs those links point to the pages that include them.
_LINKS = {
    "](docs/": "](",
    "](sweeps/README.md": "](sweeps.md",
    "](BENCHMARKS.md": "](benchmarks.md",
}


def _relink(app, relative_path, parent_docname, content):
    for old, new in _LINKS.items():
        content[0] = content[0].replace(old, new)


# The docs pages link the repository's Markdown files as on GitHub (../BENCHMARKS.md); here, their pages.
_PAGE_LINKS = {
    "](../BENCHMARKS.md": "](benchmarks.md",
    "](../README.md": "](readme.md",
    "](../sweeps/README.md": "](sweeps.md",
}


def _relink_page(app, docname, content):
    for old, new in _PAGE_LINKS.items():
        content[0] = content[0].replace(old, new)


def setup(app):
    app.connect("include-read", _relink)
    app.connect("source-read", _relink_page)
