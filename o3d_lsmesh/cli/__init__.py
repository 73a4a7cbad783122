"""The ``o3d-lsmesh`` command line (``python -m o3d_lsmesh.cli``), one module per subcommand family.

Reads and writes every triangle-mesh format Open3D reads and writes (PLY, OBJ,
STL, OFF, glTF; ``.glb`` is read but not written: Open3D cannot read back the
``.glb`` files it writes). Every subcommand takes ``--quiet`` (no progress, no
report) and ``--json`` (the metrics as one JSON object on stdout, nothing else
goes there), each that writes next to its inputs ``--force`` (allow OUTPUT to
be an input file), and its ``--help`` shows a description, every default and
an example.

Exit codes: 0 success; 2 for a user error, with one line on stderr naming the
CLI flag or the file: a missing, unreadable, truncated or empty mesh file, an
output that cannot be written, bad arguments, a request too large for memory,
or input the library's own checks reject (a ``ValueError``/``TypeError``
raised by a ``raise`` statement in o3d_lsmesh); 1 when a picture could not be
drawn, and 1 with the traceback for anything else (a bug: please report it).

STL files store every triangle with its own three vertices; they are read
with duplicated vertices merged, so the algorithms see one surface. Other
formats keep the layout Open3D reads (OBJ and glTF split vertices at UV
seams): fairing welds exactly coincident vertices itself and writes the
input's layout back, so seams stay closed and UVs stay valid.
"""

from __future__ import annotations

import argparse
import textwrap
from collections.abc import Sequence

from . import batch, compare, demo, fairing, fill, hierarchy, lsmesh
from ._common import PROG, CLIError, Parser, run_handler
from .lsmesh import parse_index_spec

__all__ = ["CLIError", "build_parser", "main", "parse_index_spec"]


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog=PROG,
        description=textwrap.fill(
            "Least-squares meshes and constrained fairing for Open3D meshes. Reads and writes every "
            "triangle-mesh format Open3D does (PLY, OBJ, STL, OFF, glTF). Each call imports Open3D "
            f"(about 2 s): for many files use '{PROG} batch', which pays that once per worker.",
            79,
        ),
        epilog=f"example:\n  {PROG} denoise scan.ply smooth.ply\n  {PROG} denoise --help",
    )
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--quiet", action="store_true", help="no progress bars and no report")
    common.add_argument("--json", action="store_true", help="print the metrics as one JSON object on stdout")
    writing = argparse.ArgumentParser(add_help=False, parents=[common])
    writing.add_argument("--force", action="store_true", help="allow overwriting an input file")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser, required=True)
    for family in (fairing, fill, lsmesh, hierarchy, compare, batch):
        family.add_parsers(sub, writing)
    demo.add_parsers(sub, common)  # it reads no file: --force would mean nothing there
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``o3d-lsmesh`` with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    Exit codes: 0 success, 2 a user error (one line on stderr), 1 a picture
    that could not be drawn or an internal error (with its traceback), 130 an
    interrupt.
    """
    return run_handler(build_parser(), argv)
