"""Old path of the command line, :mod:`o3d_lsmesh.app.cli` (``python -m o3d_lsmesh.cli`` still runs it)."""

from ..app.cli import CLIError, build_parser, main
from ..app.commands import parse_index_spec

__all__ = ["CLIError", "build_parser", "main", "parse_index_spec"]
