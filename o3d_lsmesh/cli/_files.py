"""Mesh files on the command line: read with every defect named, outputs checked before any work."""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .._batch_ops import WRITABLE, read_mesh_file, write_mesh
from .._errors import O3DLSMeshWarning
from .._o3d import has_textures, obj_writable, open3d, read_mesh
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
    """Write a mesh; an OBJ with its ``.mtl`` and texture images beside it (:func:`~o3d_lsmesh._o3d.obj_writable`),
    other formats with a warning when they cannot hold the mesh's UVs and textures."""
    target, suffix = Path(path), Path(path).suffix.lower()
    legacy = isinstance(mesh, open3d().geometry.TriangleMesh)
    uvs = legacy and mesh.has_triangle_uvs()  # (Open3D's OBJ writer writes a material only with UVs)
    if uvs and suffix == ".obj":
        mesh = obj_writable(mesh)
    elif legacy and (uvs or has_textures(mesh)):
        warnings.warn(  # (Open3D's PLY, STL, OFF and glTF writers write neither)
            f"OUTPUT {path!r}: the {suffix} output has no texture coordinates or textures; the input's "
            "are not written (write .obj to keep them)",
            O3DLSMeshWarning,
            stacklevel=2,
        )
    try:
        write_mesh(mesh, target)
    except OSError:
        raise CLIError(f"could not write OUTPUT {path!r}") from None
    if uvs and suffix == ".obj":  # Open3D says it failed only in a native warning
        expected = [target.with_suffix(".mtl")]
        expected += [target.with_name(f"{target.stem}_{i}.png") for i in range(len(mesh.textures))]
        missing = [file.name for file in expected if not file.exists()]
        if missing:
            raise CLIError(f"wrote OUTPUT {path!r} but not its material and textures {', '.join(missing)}")
