"""Mesh files on the command line: read with every defect named, outputs checked before any work."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .._batch_ops import WRITABLE, read_mesh_file, write_mesh
from .._o3d import read_mesh
from ._common import CLIError, glb_hint


def read_input(path: str, *, what: str = "INPUT") -> Any:
    """Read a triangle mesh (:func:`~o3d_lsmesh._batch_ops.read_mesh_file`) and check its arrays,
    or raise :class:`CLIError` naming the file and the problem."""
    try:
        mesh = read_mesh_file(path, what=what)
        # the checks every command would make, made once here so that the message names the file
        # (an index past the vertices is also how a cut-off text file shows: "3 18" read as 182)
        read_mesh(mesh, name=f"{what} {path!r}")
    except (ValueError, TypeError) as error:
        raise CLIError(str(error)) from None
    return mesh


def _same_file(a: str, b: str) -> bool:
    try:
        return os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b)
    except OSError:
        return False


def check_output(
    path: str, inputs: Sequence[str], *, force: bool, suffixes: Sequence[str] | None = WRITABLE
) -> None:
    """Refuse, before any work, an output that would overwrite an input or cannot be written."""
    for source in inputs:
        if _same_file(path, source) and not force:
            raise CLIError(
                f"OUTPUT {path!r} is the input file {source!r}; refusing to overwrite it (use --force)"
            )
    suffix = Path(path).suffix.lower()
    if suffixes is not None and suffix not in suffixes:
        hint = glb_hint(suffix) if ".gltf" in suffixes else ""
        raise CLIError(f"OUTPUT {path!r} must end in one of {', '.join(suffixes)}{hint}")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise CLIError(f"OUTPUT folder {folder!r} does not exist")


def write_output(path: str, mesh: Any) -> None:
    try:
        write_mesh(mesh, Path(path))
    except OSError:
        raise CLIError(f"could not write OUTPUT {path!r}") from None
