"""Mesh files on the command line: read with every defect named, outputs checked before any work."""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .._batch_ops import WRITABLE, captured_native_output, quiet_open3d, write_mesh
from ._common import CLIError, glb_hint

# Open3D's readers report a file they could not read to the end with these words (and return what they got)
_READ_FAILURE = re.compile(
    r"(?i)(read \w+ failed|rply: error|unable to read|error reading|unexpected end)[^\n]*"
)
_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def _ply_header_counts(path: str) -> dict[str, int]:
    """Element counts of a PLY header (``{"vertex": n, "face": m}``); empty if the header is unreadable."""
    counts = {}
    try:
        with open(path, "rb") as handle:
            if handle.readline().strip() != b"ply":
                return {}
            for _ in range(10_000):
                line = handle.readline()
                if not line or line.strip() == b"end_header":
                    break
                parts = line.split()
                if len(parts) == 3 and parts[0] == b"element":
                    counts[parts[1].decode("ascii", "replace")] = int(parts[2])
    except (OSError, ValueError):
        return {}
    return counts


def read_input(path: str, *, what: str = "INPUT") -> Any:
    """Read a triangle mesh or raise :class:`CLIError` naming the problem (missing, unreadable, truncated, empty)."""
    o3d = quiet_open3d()
    name = f"{what} {path!r}"
    if not os.path.exists(path):
        raise CLIError(f"{name} does not exist")
    if os.path.isdir(path):
        raise CLIError(f"{name} is a folder, not a mesh file")
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Warning)
    try:
        with captured_native_output() as captured:
            mesh = o3d.io.read_triangle_mesh(path)
    finally:
        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    n, m = len(mesh.vertices), len(mesh.triangles)
    failure = _READ_FAILURE.search(_ANSI.sub("", captured[0]))
    if failure and n:
        raise CLIError(
            f"{name} is truncated or corrupt: Open3D read only part of it ({failure.group(0).strip()})"
        )
    header = _ply_header_counts(path) if Path(path).suffix.lower() == ".ply" and n else {}
    # a polygon face gives at least one triangle: fewer triangles than faces means faces were lost
    if header.get("vertex", n) != n or header.get("face", 0) > m:
        raise CLIError(
            f"{name} is truncated or corrupt: its header declares {header.get('vertex')} vertices "
            f"and {header.get('face', 0)} faces, Open3D read {n} and {m} triangles"
        )
    if n == 0:
        raise CLIError(f"{name} could not be read as a triangle mesh (empty, corrupt or unsupported format)")
    if m == 0:
        raise CLIError(f"{name} has {n} vertices but no triangles")
    if Path(path).suffix.lower() == ".stl":
        mesh = mesh.remove_duplicated_vertices()
    # the checks every command would make, made once here so that the message names the file
    # (an index past the vertices is also how a cut-off text file shows: "3 18" read as 182)
    from .._o3d import read_mesh

    try:
        read_mesh(mesh, name=name)
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
