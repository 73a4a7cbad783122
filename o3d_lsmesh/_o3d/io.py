"""Open3D beyond mesh conversion, for the application: mesh files (read with every defect named, OBJ
written with its ``.mtl`` and textures), images, raycasting, primitives and its thread cap.
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
import re
import sys
import tempfile
import threading
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..core.arrays import mean_edge_length
from ..core.errors import InputError, O3DLSMeshWarning

__all__ = [
    "cap_threads",
    "captured_native_output",
    "cast_rays",
    "distances_to_surface",
    "icosphere",
    "legacy_mesh",
    "mesh_classes",
    "obj_writable",
    "open3d",
    "quiet_open3d",
    "raycasting_scene",
    "read_mesh_file",
    "signed_distances",
    "unwritten_attributes",
    "write_image",
    "write_mesh_file",
]


def open3d() -> Any:
    """Import and return the ``open3d`` module (lazily: the array core works without it)."""
    import open3d as o3d

    return o3d


@functools.cache
def quiet_open3d() -> Any:
    """The ``open3d`` module with its own messages off (ours are clearer and ``--json`` needs stdout clean).
    Set once: a read in another thread raises the (process-wide) level while it captures them."""
    o3d = open3d()
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    return o3d


def mesh_classes() -> tuple[type, type]:
    """Open3D's legacy and tensor triangle-mesh classes."""
    o3d = open3d()
    return o3d.geometry.TriangleMesh, o3d.t.geometry.TriangleMesh


def cap_threads(threads: int) -> None:
    """Cap Open3D's own worker threads at ``threads`` (Open3D versions without the setting: nothing)."""
    o3d = quiet_open3d()
    if hasattr(o3d.utility, "set_max_threads"):
        o3d.utility.set_max_threads(threads)


# descriptors 1 and 2 belong to the process: one capture at a time (threads of a batch worker read at
# once; a second capture would save the first one's sink as "the terminal" and mix their texts)
_CAPTURE = threading.RLock()  # (re-entrant: a capture within a capture of the same thread is no deadlock)


@contextlib.contextmanager
def captured_native_output() -> Iterator[list[str]]:
    """Capture what C/C++ libraries write straight to file descriptors 1 and 2, and Open3D's messages (it
    prints them through Python's ``sys.stdout``: a notebook's or pytest's stream, not descriptor 1): a list
    holding the text at the end. One capture at a time in a process (others wait)."""
    with _CAPTURE:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = [os.dup(1), os.dup(2)]
        captured: list[str] = []
        printed = io.StringIO()
        with tempfile.TemporaryFile() as sink, contextlib.redirect_stdout(printed):
            try:
                os.dup2(sink.fileno(), 1)
                os.dup2(sink.fileno(), 2)
                yield captured
            finally:
                os.dup2(saved[0], 1)
                os.dup2(saved[1], 2)
                for fd in saved:
                    os.close(fd)
                sink.seek(0)
                captured.append(sink.read().decode("utf-8", "replace") + printed.getvalue())


# Open3D's readers report a file they could not read to the end with these words (and return what they got)
_READ_FAILURE = re.compile(
    r"(?i)(read \w+ failed|rply: error|unable to read|error reading|unexpected end)[^\n]*"
)
_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def ply_header(path: str | os.PathLike) -> dict[str, tuple[int, dict[str, str]]]:
    """Each element of a PLY header with its count and its properties' types by name
    (``{"vertex": (n, {"x": "float", ...})}``); empty if the header is unreadable."""
    elements: dict[str, tuple[int, dict[str, str]]] = {}
    try:
        with open(path, "rb") as handle:
            if handle.readline().strip() != b"ply":
                return {}
            for _ in range(10_000):
                parts = handle.readline().decode("ascii", "replace").split()
                if not parts or parts == ["end_header"]:
                    break
                if len(parts) == 3 and parts[0] == "element":
                    elements[parts[1]] = (int(parts[2]), {})
                elif len(parts) >= 3 and parts[0] == "property" and elements:
                    elements[next(reversed(elements))][1][parts[-1]] = parts[-2]
    except (OSError, ValueError):
        return {}
    return elements


#: The full scale of a PLY colour type: Open3D's reader divides every colour by 255, whatever its type
_COLOUR_SCALE = {"char": 127, "int8": 127, "uchar": 255, "uint8": 255, "short": 32767, "int16": 32767}
_COLOUR_SCALE |= {"ushort": 65535, "uint16": 65535, "int": 2**31 - 1, "int32": 2**31 - 1}
_COLOUR_SCALE |= {"uint": 2**32 - 1, "uint32": 2**32 - 1, "float": 1, "float32": 1, "double": 1, "float64": 1}


#: What Open3D's PLY reader keeps of each element (positions, normals, colours; the faces' corners)
_PLY_READ = {"vertex": {"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"}}
_PLY_READ["face"] = {"vertex_indices", "vertex_index"}


def _ply_unread(header: dict[str, tuple[int, dict[str, str]]]) -> list[str]:
    """The properties of a PLY ``header`` (:func:`ply_header`) Open3D's reader leaves out, as ``"element
    property"`` (a whole element it does not read: ``"element"``)."""
    unread = []
    for element, (_, properties) in header.items():
        if element not in _PLY_READ:
            unread.append(element)
        else:
            unread += [f"{element} {name}" for name in properties if name not in _PLY_READ[element]]
    return unread


def read_mesh_file(path: str, *, what: str = "INPUT") -> Any:
    """Read a triangle mesh file as a legacy Open3D mesh (STL files welded: three vertices a triangle).

    Raises ``InputError(param="path")`` naming ``what`` and the file: missing, a folder, empty,
    unreadable, truncated or corrupt (Open3D's warnings, the PLY header's counts), no triangles.
    """
    o3d = quiet_open3d()
    name = f"{what} {path!r}"
    if not os.path.exists(path):
        raise InputError(f"{name} does not exist", param="path")
    if os.path.isdir(path):
        raise InputError(f"{name} is a folder, not a mesh file", param="path")
    if os.path.getsize(path) == 0:
        raise InputError(f"{name} is an empty file", param="path")
    suffix = Path(path).suffix.lower()
    with captured_native_output() as captured:  # (Open3D's verbosity is process-wide too: set within)
        # its OBJ reader says only at Info that it skips polygons of more than three corners
        level = o3d.utility.VerbosityLevel
        o3d.utility.set_verbosity_level(level.Info if suffix == ".obj" else level.Warning)
        try:
            mesh = o3d.io.read_triangle_mesh(path)
        finally:
            o3d.utility.set_verbosity_level(level.Error)
    if suffix == ".obj" and "non-triangle" in captured[0]:
        mesh = _obj_polygons(path, mesh, name)
    n, m = len(mesh.vertices), len(mesh.triangles)
    failure = _READ_FAILURE.search(_ANSI.sub("", captured[0]))
    if failure and n:
        raise InputError(
            f"{name} is truncated or corrupt: Open3D read only part of it ({failure.group(0).strip()})",
            param="path",
        )
    header = ply_header(path) if suffix == ".ply" and n else {}
    counts = {element: count for element, (count, _) in header.items()}
    # a polygon face gives at least one triangle: fewer triangles than faces means faces were lost
    if counts.get("vertex", n) != n or counts.get("face", 0) > m:
        raise InputError(
            f"{name} is truncated or corrupt: its header declares {counts.get('vertex')} vertices "
            f"and {counts.get('face', 0)} faces, Open3D read {n} and {m} triangles",
            param="path",
        )
    colour = header.get("vertex", (0, {}))[1].get("red", "uchar")
    if mesh.has_vertex_colors() and _COLOUR_SCALE.get(colour, 255) != 255:  # (float colours: 0..1/255)
        mesh.vertex_colors = o3d.utility.Vector3dVector(
            np.asarray(mesh.vertex_colors) * (255 / _COLOUR_SCALE[colour])
        )
    if unread := _ply_unread(header):  # a scanner's confidence or intensity, say: gone from every output
        warnings.warn(
            f"{name}: Open3D's PLY reader leaves out {', '.join(unread)}; only positions, normals and "
            "colours are read, so outputs do not hold them",
            O3DLSMeshWarning,
            stacklevel=2,
        )
    if n == 0:
        raise InputError(
            f"{name} could not be read as a triangle mesh (empty, corrupt or unsupported format)",
            param="path",
        )
    if m == 0:
        raise InputError(f"{name} has {n} vertices but no triangles", param="path")
    loss = rounding_loss(mesh, suffix, reading=True)
    if loss > 0.01:  # as for writing: visible
        warnings.warn(
            f"{name}: Open3D reads {suffix} in single precision, which rounds its positions by up to "
            f"{loss:.3g} mean edge lengths (a mesh far from the origin loses most): convert it to .ply",
            O3DLSMeshWarning,
            stacklevel=2,
        )
    # one plain material is a uniform colour (Open3D's own OBJs: white); more tell the faces apart
    if suffix == ".obj" and (plain := _untextured_materials(mesh)) > 1:
        warnings.warn(
            f"{name}: Open3D's OBJ reader keeps a material's texture image, not its colours: the {plain} "
            "materials without an image, which tell the faces apart, are not in any output",
            O3DLSMeshWarning,
            stacklevel=2,
        )
    return mesh.remove_duplicated_vertices() if suffix == ".stl" else mesh


def _obj_polygons(path: str, mesh: Any, name: str) -> Any:
    """An OBJ whose polygons (more than three corners) Open3D's legacy reader skipped, read by its tensor
    reader, which fans them out; where it holds more triangles. That reader keeps one material and no
    texture image: said, where the legacy reader found them."""
    with captured_native_output():
        polygons = open3d().t.io.read_triangle_mesh(path)
    if len(polygons.triangle.indices) <= len(mesh.triangles):
        return mesh
    if has_textures(mesh) or len(set(np.asarray(mesh.triangle_material_ids).tolist())) > 1:
        warnings.warn(
            f"{name}: Open3D's OBJ reader skips faces of more than three corners; read by its tensor "
            "reader, which keeps their texture coordinates but not the materials' images",
            O3DLSMeshWarning,
            stacklevel=3,
        )
    return polygons.to_legacy()


def _untextured_materials(mesh: Any) -> int:
    """How many materials the triangles of a legacy mesh read from an OBJ use without a texture image (its
    reader's slot 0, faces without a material, left out): their colours were not read."""
    if not mesh.has_triangle_material_ids():
        return 0
    used = np.unique(np.asarray(mesh.triangle_material_ids))
    return sum(1 for i in used if i > 0 and (i >= len(mesh.textures) or mesh.textures[i].is_empty()))


class ShortWrite(OSError):
    """A mesh file that reads back with fewer triangles than were written (a full disk)."""


def write_mesh_file(mesh: Any, path: str | os.PathLike) -> list[str]:
    """Write a mesh file (an OBJ with UVs with its ``.mtl`` and images: :func:`obj_writable`); ``OSError`` if
    Open3D could not (:class:`ShortWrite` if it wrote less than all). Returns the names of the ``.mtl``
    and images it did not write (said only natively)."""
    o3d = quiet_open3d()
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".stl":
        mesh = o3d.geometry.TriangleMesh(mesh)
        mesh.compute_triangle_normals()  # Open3D's STL writer refuses a mesh without them
    textured = suffix == ".obj" and isinstance(mesh, o3d.geometry.TriangleMesh) and mesh.has_triangle_uvs()
    if textured:
        mesh = obj_writable(mesh)
    with captured_native_output():
        written = o3d.io.write_triangle_mesh(str(path), mesh)
    if not written or not path.exists() or path.stat().st_size == 0:
        raise OSError(f"Open3D could not write {str(path)!r}")
    # Open3D's writers do not check their writes: a full disk or a file-size limit leaves a short file
    # reported as written. Read back, it holds fewer triangles (or none)
    with captured_native_output():
        back = o3d.io.read_triangle_mesh(str(path))
    count = len(mesh.triangles) if isinstance(mesh, o3d.geometry.TriangleMesh) else len(mesh.triangle.indices)
    if len(back.triangles) != count:
        path.unlink()  # not left to be taken for the result
        raise ShortWrite(
            f"Open3D wrote it short: it reads back with {len(back.triangles)} of {count} triangles (a full "
            "disk or a file-size limit?)"
        )
    if not textured:
        return []
    expected = [path.with_suffix(".mtl")]
    expected += [path.with_name(f"{path.stem}_{i}.png") for i in range(len(mesh.textures))]
    return [file.name for file in expected if not file.exists()]


def has_textures(mesh: Any) -> bool:
    """Whether a legacy mesh holds a texture image (Open3D's ``has_textures`` is False when one of them
    is empty, as the empty first slot its OBJ reader adds for faces without a material)."""
    return any(not texture.is_empty() for texture in mesh.textures)


def unwritten_attributes(mesh: Any, suffix: str) -> list[str]:
    """What of a legacy ``mesh`` a mesh file ending in ``suffix`` does not hold: Open3D's PLY, STL, OFF and
    glTF writers write no texture coordinates or textures, its OBJ writer no textures without them, its
    STL writer no vertex colours."""
    if not isinstance(mesh, open3d().geometry.TriangleMesh):
        return []
    uvs, textures, suffix = mesh.has_triangle_uvs(), has_textures(mesh), suffix.lower()
    lost = ["vertex colours"] if suffix == ".stl" and mesh.has_vertex_colors() else []
    if suffix == ".obj":
        return lost + (["textures"] if textures and not uvs else [])
    return lost + (["texture coordinates or textures"] if uvs or textures else [])


#: How Open3D keeps positions, per file suffix: its writers (OBJ and OFF print ``%g``, 6 significant digits;
#: STL and glTF hold single precision; PLY double, left out) and its readers (OBJ and OFF: single).
_WRITTEN = {".obj": "digits", ".off": "digits", ".stl": "single", ".gltf": "single"}
_READ = {".obj": "single", ".off": "single"}


def rounding_loss(mesh: Any, suffix: str, *, reading: bool = False) -> float:
    """How far a mesh file ending in ``suffix`` moves ``mesh``'s positions (``reading``: how far reading
    it does), in mean edge lengths (:data:`_WRITTEN`, :data:`_READ`). A mesh far from the origin
    (georeferenced: 4.2e6 m) loses metres."""
    kept = (_READ if reading else _WRITTEN).get(suffix.lower())
    if kept is None:
        return 0.0
    legacy = isinstance(mesh, open3d().geometry.TriangleMesh)
    vertices = np.asarray(mesh.vertices) if legacy else mesh.vertex.positions.cpu().numpy()
    triangles = np.asarray(mesh.triangles) if legacy else mesh.triangle.indices.cpu().numpy()
    vertices = np.asarray(vertices, dtype=np.float64)
    if not len(triangles) or not len(vertices):
        return 0.0
    if kept == "single":  # a unit in the last place (the writers' own float arithmetic included)
        worst = float(np.spacing(np.abs(vertices).astype(np.float32)).max())
    else:  # %g: 6 significant digits (zeros print exactly)
        magnitude = np.abs(vertices)
        unit = 10.0 ** (np.floor(np.log10(np.where(magnitude > 0, magnitude, 1.0))) - 5)
        worst = float(np.abs(np.round(vertices / unit) * unit - vertices).max())
    edge = mean_edge_length(vertices, triangles)
    return worst / edge if edge > 0 else (np.inf if worst > 0 else 0.0)


def obj_writable(mesh: Any) -> Any:
    """A legacy mesh Open3D's OBJ writer writes with every texture (``mesh`` itself if it already is): the
    writer stops at an empty slot, so unused empty slots go (ids renumbered), used ones turn 1x1 white."""
    textures = list(mesh.textures)
    empty = np.array([texture.is_empty() for texture in textures], dtype=bool)
    if not empty.any() or not mesh.has_triangle_uvs():  # (without UVs the writer writes no material)
        return mesh
    o3d = open3d()
    ids = (
        np.asarray(mesh.triangle_material_ids) if mesh.has_triangle_material_ids() else np.zeros(1, np.int32)
    )
    used = np.zeros(len(textures) + 1, dtype=bool)  # (the last: ids past the textures)
    used[np.clip(ids[ids >= 0], 0, len(textures))] = True
    keep = used[:-1] | ~empty
    out = o3d.geometry.TriangleMesh(mesh)
    white = o3d.geometry.Image(np.full((1, 1, 3), 255, dtype=np.uint8))
    out.textures = [white if empty[i] else textures[i] for i in np.flatnonzero(keep)]
    if mesh.has_triangle_material_ids():
        dropped_before = np.concatenate([[0], np.cumsum(~keep)])  # slots dropped before each id
        renumbered = ids - dropped_before[np.clip(ids, 0, len(textures))]
        out.triangle_material_ids = o3d.utility.IntVector(
            np.where(ids >= 0, renumbered, ids).astype(np.int32)
        )
    return out


def write_image(path: str, image: np.ndarray) -> bool:
    """Write an ``(h, w, 3) uint8`` picture (PNG by the name); whether Open3D wrote it."""
    o3d = quiet_open3d()
    return bool(o3d.io.write_image(path, o3d.geometry.Image(np.ascontiguousarray(image))))


def legacy_mesh(vertices: np.ndarray, triangles: np.ndarray) -> Any:
    """A legacy ``open3d.geometry.TriangleMesh`` of ``(n, 3)`` vertices and ``(m, 3)`` triangles."""
    o3d = open3d()
    return o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.asarray(vertices, dtype=np.float64)),
        o3d.utility.Vector3iVector(np.asarray(triangles).astype(np.int32)),
    )


def icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Open3D's unit icosahedron midpoint-subdivided ``subdivisions`` times: ``(n, 3)`` vertices, ``(m, 3)`` triangles."""
    mesh = open3d().geometry.TriangleMesh.create_icosahedron(radius=1.0)
    if subdivisions:
        mesh = mesh.subdivide_midpoint(number_of_iterations=int(subdivisions))
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.triangles)


def raycasting_scene(vertices: np.ndarray, triangles: np.ndarray) -> Any:
    """Open3D's ``RaycastingScene`` (single precision) holding the surface ``(vertices, triangles)``."""
    o3d = open3d()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(triangles.astype(np.uint32))
    )
    return scene


def cast_rays(scene: Any, rays: np.ndarray) -> dict[str, np.ndarray]:
    """Rays ``(..., 6)`` (origin, direction) cast into ``scene``: its answer's arrays (``t_hit`` inf: no hit)."""
    answer = scene.cast_rays(open3d().core.Tensor(np.asarray(rays, dtype=np.float32)))
    return {
        key: answer[key].numpy() for key in ("t_hit", "primitive_ids", "primitive_uvs", "primitive_normals")
    }


def signed_distances(scene: Any, points: np.ndarray) -> np.ndarray:
    """Signed distance ``(p,)`` float64 of each of ``points (p, 3)`` to the surface in ``scene`` (negative inside)."""
    tensor = open3d().core.Tensor(points.astype(np.float32))
    return scene.compute_signed_distance(tensor).numpy().astype(np.float64)


def distances_to_surface(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Distance ``(p,)`` from ``points (p, 3)`` to the surface ``(vertices, triangles)``, in float32 (pass a unit frame)."""
    tensor = open3d().core.Tensor(points.astype(np.float32))
    return raycasting_scene(vertices, triangles).compute_distance(tensor).numpy().astype(np.float64)
