"""Mesh files of the application: inputs, output paths strictly inside OUTDIR, atomic writes, digests
(``docs/batch.md``)."""

from __future__ import annotations

import glob
import hashlib
import os
import re
import shutil
import uuid
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from .._o3d import read_mesh
from .._o3d.io import ShortWrite, read_mesh_file, rounding_loss, unwritten_attributes, write_mesh_file
from ..core.errors import InputError, InputTypeError, O3DLSMeshWarning

__all__ = [
    "READABLE",
    "TEMPORARY",
    "WRITABLE",
    "CLIError",
    "check_output",
    "collect_inputs",
    "digest",
    "inside",
    "output_path",
    "read_input",
    "read_mesh_file",
    "write_atomic",
    "write_output",
]

#: Mesh files a folder INPUT is searched for.
READABLE = (".ply", ".obj", ".stl", ".off", ".gltf", ".glb")
#: Extensions Open3D 0.20 writes back readably (its .glb writer produces files it cannot read back).
WRITABLE = (".ply", ".obj", ".stl", ".off", ".gltf")
#: Hidden temporary names of :func:`write_atomic` (and of older versions: ``.<stem>.<hex>.tmp.<ext>``
#: files, ``.<name>.<hex>.old`` folders): what a killed batch may leave; never taken as inputs.
TEMPORARY = re.compile(r"\..*\.[0-9a-f]{12}\.(tmp|old)(\.[^.]+)?")
_GLOB_CHARACTERS = set("*?[")


class _Incomplete(OSError):
    """Open3D wrote an OBJ but not its material and textures."""


def _write_mesh(mesh: Any, path: Path, shown: str | os.PathLike) -> None:
    """Write a mesh file (an OBJ with its ``.mtl`` and textures), with a warning naming ``shown`` when the
    format cannot hold the mesh's UVs and textures; ``OSError`` if Open3D cannot write it all."""
    suffix = path.suffix.lower()
    lost = unwritten_attributes(mesh, suffix)
    if lost:
        keep = "write .obj to keep them" if suffix != ".obj" else "an OBJ holds textures only with UVs"
        warnings.warn(
            f"OUTPUT {str(shown)!r}: the {suffix} output has no {' or '.join(lost)}; the input's are not "
            f"written ({keep})",
            O3DLSMeshWarning,
            stacklevel=3,
        )
    loss = rounding_loss(mesh, suffix)
    if loss > 0.01:  # visible: a hundredth of an edge
        warnings.warn(
            f"OUTPUT {str(shown)!r}: the {suffix} file rounds the positions by up to {loss:.3g} mean edge "
            "lengths (6 significant digits, or single precision; a mesh far from the origin loses most): "
            "write .ply to keep them",
            O3DLSMeshWarning,
            stacklevel=3,
        )
    missing = write_mesh_file(mesh, path)
    if missing:  # Open3D says it failed only in a native warning
        raise _Incomplete(
            f"wrote OUTPUT {str(shown)!r} but not its material and textures {', '.join(missing)}"
        )


def _write_item(value: Any, path: Path, shown: Path) -> None:
    """Write bytes, or a mesh file as :func:`write_output` does (``shown``: its name in messages)."""
    path.write_bytes(value) if isinstance(value, (bytes, bytearray)) else _write_mesh(value, path, shown)


def digest(path: Path) -> dict:
    """Size and sha256 of a written file: what ``resume`` checks an output against."""
    hasher = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            hasher.update(block)
    return {"bytes": path.stat().st_size, "sha256": hasher.hexdigest()}


def inside(path: str | os.PathLike, root: str | os.PathLike) -> bool:
    """Whether ``path`` resolves (symbolic links followed) to a place strictly below ``root``."""
    real, base = Path(os.path.realpath(path)), Path(os.path.realpath(root))
    return base in real.parents


def write_atomic(value: Any, final: Path, *, kind: str, suffix: str, root: Path) -> dict[str, dict]:
    """Write ``value`` as ``final`` (strictly inside ``root``); return ``{path below root: size and sha256}``.

    Everything is written into a hidden temporary folder beside ``final`` (the only thing this
    removes), then moved into place file by file, so companion files (an OBJ's ``.mtl`` and
    textures) are named after ``final``. A new folder output moves into place whole; into an
    existing folder, file by file: nothing already there is removed.
    """
    if not inside(final, root):
        message = f"output {str(final)!r} does not resolve to a place inside OUTDIR {str(root)!r}"
        raise InputError(message, param="outdir")  # a symbolic link made while the batch ran
    final.parent.mkdir(parents=True, exist_ok=True)
    temporary = final.with_name(f".{final.name}.{uuid.uuid4().hex[:12]}.tmp")
    temporary.mkdir()
    try:
        for name, item in value.items() if kind == "files" else [(final.name, value)]:
            # a bytes output's file name has its suffix
            mesh = kind == "files" and not isinstance(item, (bytes, bytearray))
            name = name + suffix if mesh else name
            _write_item(item, temporary / name, final / name if kind == "files" else final)
        where = final if kind == "files" else final.parent
        base = Path(os.path.relpath(where, root))
        files = {(base / p.name).as_posix(): digest(p) for p in sorted(temporary.iterdir())}
        if kind == "files" and not os.path.lexists(final):
            os.replace(temporary, final)
        else:
            for path in sorted(temporary.iterdir()):
                os.replace(path, where / path.name)
    finally:
        shutil.rmtree(temporary, ignore_errors=True)
    return files


def _safe_name(part: str) -> str:
    # '', '.' and '..' would name OUTDIR itself or its parent (#40: a file '..ply'): a visible fixed name
    return {"": "_", ".": "_dot", "..": "_dotdot"}.get(part, part)


def output_path(outdir: Path, relative: str, op: Any, suffix: str) -> Path | None:
    """Where the result of ``op`` on the input named ``relative`` goes (None for metrics-only ops).

    The stem names the output; a folder or stem that is empty, ``.`` or ``..`` (the file
    ``..ply``) becomes ``_``, ``_dot`` or ``_dotdot``, so every output lies strictly inside ``outdir``.
    """
    if op.output == "none":
        return None
    path = Path(relative)
    parts = [
        _safe_name(part) for part in (*path.parent.parts, path.name[: len(path.name) - len(path.suffix)])
    ]
    ending = {"mesh": suffix, "bytes": op.extension}.get(op.output, "")
    return outdir.joinpath(*parts[:-1], parts[-1] + ending)


def collect_inputs(
    inputs: str | os.PathLike | Iterable[str | os.PathLike], *, exclude: str | os.PathLike | None = None
) -> list[tuple[str, str]]:
    """Expand files, folders and glob patterns into ``(path, relative name)`` pairs, in a stable order.

    A folder is searched recursively for the :data:`READABLE` files, each keeping its path below the
    folder as its relative name (outputs mirror the tree); a file or glob match keeps its base name.
    A path given twice is taken once. Searches leave out the folder ``exclude`` (the batch's OUTDIR)
    and :data:`TEMPORARY` names; a folder that is ``exclude`` or lies inside it is refused.
    """
    inputs = [inputs] if isinstance(inputs, (str, os.PathLike)) else list(inputs)
    skip = None if exclude is None else os.path.realpath(exclude)

    def excluded(match: Any) -> bool:
        return skip is not None and (os.path.realpath(match) == skip or inside(match, skip))

    # by absolute path: a path given twice is taken once; links are names of their own (two names of one
    # file, as dataset splits make them, each write their output)
    found: dict[str, tuple[str, str]] = {}
    for item in inputs:
        if not isinstance(item, (str, os.PathLike)):
            raise InputTypeError(
                f"inputs must be paths or glob patterns, got {type(item).__name__}", param="inputs"
            )
        text = os.fspath(item)
        if os.path.isdir(text) or os.path.isfile(text):
            matches = [text]
        elif _GLOB_CHARACTERS & set(text):
            matches = sorted(glob.glob(text, recursive=True))
            if not matches:
                raise InputError(f"INPUT {text!r} matches no file", param="inputs")
            matches = [m for m in matches if not excluded(m) and not TEMPORARY.fullmatch(os.path.basename(m))]
        else:
            raise InputError(
                f"INPUT {text!r} does not exist (expected a file, a folder or a glob pattern)", param="inputs"
            )
        for match in map(Path, matches):
            if match.is_dir():
                if excluded(match):
                    raise InputError(
                        f"INPUT folder {str(match)!r} lies inside OUTDIR {str(exclude)!r} (or is it): "
                        "the outputs would be read as inputs; use an OUTDIR outside it",
                        param="inputs",
                    )
                pairs = [(path, str(path.relative_to(match))) for path in _search(match, skip)]
            else:
                pairs = [(match, match.name)]
            for path, relative in pairs:
                found.setdefault(os.path.abspath(path), (str(path), relative))
    if not found:
        raise InputError(
            f"INPUT must name at least one mesh file ({', '.join(READABLE)}), got none in {inputs!r}",
            param="inputs",
        )
    return list(found.values())


def _search(folder: Path, skip: str | None) -> list[Path]:
    """Mesh files below ``folder`` (links to folders not followed), without ``skip`` and temporary names."""
    files = []
    for root, folders, names in os.walk(folder):
        folders[:] = [
            name
            for name in folders
            if not TEMPORARY.fullmatch(name) and os.path.realpath(os.path.join(root, name)) != skip
        ]
        files += [
            Path(root, name)
            for name in names
            if Path(name).suffix.lower() in READABLE and not TEMPORARY.fullmatch(name)
        ]
    return sorted(path for path in files if path.is_file())


# --------------------------------------------------------------------------- files named on the command line


class CLIError(Exception):
    """A user error of the command line: reported as one line on stderr with exit code 2."""


def glb_hint(suffix: str) -> str:
    return " (Open3D writes .glb files it cannot read back: use .gltf)" if suffix == ".glb" else ""


def mesh_suffix(text: str) -> str:
    """Parser of an output format (``ply`` or ``.ply``); ``.glb`` is refused with the way out."""
    suffix = "." + text.lstrip(".").lower()
    if suffix not in WRITABLE:
        raise ValueError(f"must be one of {', '.join(WRITABLE)}{glb_hint(suffix)}, got {text!r}")
    return suffix


def read_input(path: str, *, what: str = "INPUT") -> Any:
    """Read a mesh file and check its arrays once, or raise :class:`CLIError` naming the file.

    Returns the checked arrays (a ``MeshData``, which the operations and metrics take without a
    second check); the checks are made here so that the message names the file (an index past the
    vertices is also how a cut-off text file shows: "3 18" read as 182).
    """
    try:
        return read_mesh(read_mesh_file(path, what=what), name=f"{what} {path!r}")
    except (ValueError, TypeError) as error:
        raise CLIError(str(error)) from None


def same_file(a: str, b: str) -> bool:
    try:
        return os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b)
    except OSError:
        return False


def check_output(
    path: str,
    inputs: Sequence[str],
    *,
    force: bool,
    suffixes: Sequence[str] | None = WRITABLE,
    what: str = "OUTPUT",
) -> None:
    """Refuse, before any work, an output that would overwrite an input or cannot be written (``what``: the
    argument that names it, ``--render`` say)."""
    for source in inputs:
        if same_file(path, source) and not force:
            raise CLIError(
                f"{what} {path!r} is the input file {source!r}; refusing to overwrite it (use --force)"
            )
    suffix = Path(path).suffix.lower()
    if suffixes is not None and suffix not in suffixes:
        hint = glb_hint(suffix) if ".gltf" in suffixes else ""
        raise CLIError(f"{what} {path!r} must end in one of {', '.join(suffixes)}{hint}")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise CLIError(f"{what} folder {folder!r} does not exist")


def write_output(path: str, mesh: Any) -> None:
    """Write a mesh; an OBJ with its ``.mtl`` and textures, other formats with a warning when they
    cannot hold the mesh's UVs and textures."""
    try:
        _write_mesh(mesh, Path(path), path)
    except _Incomplete as error:
        raise CLIError(str(error)) from None
    except ShortWrite as error:
        raise CLIError(f"could not write OUTPUT {path!r}: {error}") from None
    except OSError:
        raise CLIError(f"could not write OUTPUT {path!r}") from None
