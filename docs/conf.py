"""Sphinx configuration: API reference from ``o3d_lsmesh.__all__``, CLI reference from its parser,
an executed gallery from ``examples/``.

Built by ``make docs`` with warnings as errors. The gallery runs every example
(``plot_gallery = True``) with ``--out``, and their pictures become the pages'
figures (``docs/_gallery.py``). The committed ``docs/images/NN_*.png`` (written by
``python examples/NN_*.py --out docs/images``) are for the README and the
algorithm pages.
"""

from __future__ import annotations

import contextlib
import inspect
import io
import re
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(HERE))

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
html_static_path = ["_static"]
html_css_files = ["wide_tables.css"]
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
    "plot_gallery": "True",
    "reset_argv": "_gallery.reset_argv",
    "image_scrapers": ("_gallery.png_scraper",),
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
    """Copy ``benchmarks/results/*.md`` (and their pictures) to ``benchmarks/`` so the reports are pages."""
    out = HERE / "benchmarks"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    for path in sorted((REPO / "benchmarks" / "results").glob("*")):
        if path.suffix in (".md", ".png"):
            shutil.copyfile(path, out / path.name)


def _cli_page() -> None:
    """``cli.rst``: every subcommand's ``--help`` as the parser prints it (the one declaration of its options)."""
    import os

    from o3d_lsmesh.app.cli import build_parser

    os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal: one width for the page
    parser = build_parser()
    # the subcommands as the top-level help lists them, one per line under COMMAND
    listing = parser.format_help().split("COMMAND\n", 1)[1].split("\n\n", 1)[0]
    names = re.findall(r"^    ([a-z][\w-]*)", listing, flags=re.M)
    lines = [
        "Command line and batch reference",
        "================================",
        "",
        ".. include:: cli_intro.md",
        "   :parser: myst_parser.sphinx_",
        "",
    ]
    for name in names:
        out = io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
            build_parser().parse_args([name, "--help"])
        lines += [name, "-" * len(name), "", ".. code-block:: text", ""]
        lines += ["   " + line if line else "" for line in out.getvalue().splitlines()]
        lines.append("")
    (HERE / "cli.rst").write_text("\n".join(lines) + "\n")


_api_pages()
_benchmark_pages()
_cli_page()
