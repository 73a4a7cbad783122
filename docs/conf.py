"""Sphinx configuration: API reference from ``o3d_lsmesh.__all__``, gallery from ``examples/``.

Built by ``make docs`` with warnings as errors. The gallery does not run the
examples (``plot_gallery = False``): each example's picture is the committed
``docs/images/NN_*.png`` that ``python examples/NN_*.py --out docs/images``
writes, used as its thumbnail and shown in its docstring.
"""

from __future__ import annotations

import inspect
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

import o3d_lsmesh

project = "o3d_lsmesh"
author = "The o3d_lsmesh developers"
copyright = "2026, The o3d_lsmesh developers"
release = version = o3d_lsmesh.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "myst_parser",
    "sphinx-mathjax-offline",  # MathJax 3 copied into _static: equations render without a CDN
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py", "**/*.codeobj.json"]
html_theme = "furo"
html_title = f"o3d_lsmesh {release}"
# Offline: no intersphinx, MathJax served from the build (the CI browser check has no CDN).

autodoc_default_options = {"members": True, "inherited-members": False, "show-inheritance": True}
autodoc_typehints = "none"  # numpydoc's Parameters sections carry the types
autodoc_mock_imports = ["sksparse"]  # optional extra; the API pages do not need it
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
# numpydoc validation off: the docstrings follow numpydoc sections but are not
# all validated (see the docs report); a parse error still fails the build.
numpydoc_validation_checks: set[str] = set()

sphinx_gallery_conf = {
    "examples_dirs": str(REPO / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/\d\d_",
    "plot_gallery": False,
    "download_all_examples": False,
    "line_numbers": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
}

myst_heading_anchors = 3
suppress_warnings = ["myst.header"]  # benchmark reports start their sections at ##


def _api_pages() -> None:
    """One page per name in ``o3d_lsmesh.__all__`` under ``api/`` plus an index.

    Generated at every build so a function added to ``__all__`` gets its page
    without touching the docs.
    """
    out = HERE / "api"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    rows = []
    for name in o3d_lsmesh.__all__:
        obj = getattr(o3d_lsmesh, name)
        if inspect.ismodule(obj):
            directive = f".. automodule:: {obj.__name__}\n   :members:\n"
            kind = "module"
        elif inspect.isclass(obj):
            directive = f".. autoclass:: o3d_lsmesh.{name}\n   :members:\n"
            kind = "exception" if issubclass(obj, BaseException) else "class"
        else:
            directive = f".. autofunction:: o3d_lsmesh.{name}\n"
            kind = "function"
        doc = inspect.getdoc(obj) or ""
        summary = doc.splitlines()[0] if doc else ""
        title = f"{name}"
        (out / f"{name}.rst").write_text(f"{title}\n{'=' * len(title)}\n\n{directive}")
        rows.append((name, kind, summary))
    lines = [
        "API reference",
        "=============",
        "",
        "Every name exported by ``o3d_lsmesh`` (its ``__all__``). Functions take an",
        "``open3d.geometry.TriangleMesh``, an ``open3d.t.geometry.TriangleMesh`` or a",
        "``(vertices, triangles)`` tuple and return a new mesh of the same kind.",
        "",
        ".. toctree::",
        "   :hidden:",
        "",
        *[f"   {name}" for name, _, _ in rows],
        "",
        ".. list-table::",
        "   :header-rows: 1",
        "   :widths: 25 12 63",
        "",
        "   * - name",
        "     - kind",
        "     - summary",
    ]
    for name, kind, summary in rows:
        lines += [f"   * - :doc:`{name}`", f"     - {kind}", f"     - {summary}"]
    (out / "index.rst").write_text("\n".join(lines) + "\n")


def _benchmark_pages() -> None:
    """Copy ``benchmarks/results/*.md`` to ``benchmarks/`` so the reports are pages."""
    out = HERE / "benchmarks"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    for md in sorted((REPO / "benchmarks" / "results").glob("*.md")):
        shutil.copyfile(md, out / md.name)


_api_pages()
_benchmark_pages()
