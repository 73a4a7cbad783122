"""The one place that converts between Open3D meshes and arrays.

Every public function reads its mesh with :func:`read_mesh` and builds its
result with :func:`new_mesh`, so the attribute policy lives here alone:

* the result is a new mesh of the kind the caller gave (legacy
  ``open3d.geometry.TriangleMesh``, tensor ``open3d.t.geometry.TriangleMesh``,
  or a ``(vertices, triangles)`` tuple of arrays);
* the input is never modified: vertices and triangles are copied out;
* with the connectivity unchanged, vertex colors (and, for tensor meshes, every
  other per-vertex and per-triangle attribute except normals) are kept;
* vertex and triangle normals are recomputed when the input had them;
* a tensor mesh keeps its device and its position and index dtypes (integer
  positions come back as float64: computed positions rounded to integers would
  be a wrong answer).

The open3d import is lazy so that the array core works without it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ._validate import as_triangle_array, as_vertex_array, check_mesh_arrays

__all__ = ["MeshData", "read_mesh", "new_mesh", "open3d", "mesh_state", "mesh_from_state"]

_NORMAL_KEYS = ("normals",)


def open3d():
    """Import and return the ``open3d`` module (lazily)."""
    import open3d as o3d

    return o3d


@dataclass(frozen=True)
class MeshData:
    """Arrays copied out of a mesh, plus the mesh itself to rebuild its kind."""

    vertices: np.ndarray  # (n, 3) float64
    triangles: np.ndarray  # (m, 3) int64
    source: Any
    kind: str  # "legacy", "tensor" or "arrays"


def _kind(mesh: Any, *, name: str = "mesh") -> str:
    if isinstance(mesh, tuple) and len(mesh) == 2:
        return "arrays"
    module = type(mesh).__module__ or ""
    if module.startswith("open3d"):
        o3d = open3d()
        if isinstance(mesh, o3d.geometry.TriangleMesh):
            return "legacy"
        if isinstance(mesh, o3d.t.geometry.TriangleMesh):
            return "tensor"
    raise TypeError(
        f"{name} must be an open3d.geometry.TriangleMesh, an open3d.t.geometry.TriangleMesh "
        f"or a (vertices, triangles) tuple, got {type(mesh).__name__}"
    )


def read_mesh(mesh: Any, *, name: str = "mesh", allow_isolated: bool = True) -> MeshData:
    """Copy ``mesh`` into ``(n,3) float64`` vertices and ``(m,3) int64`` triangles and validate them.

    Every kind goes through the same checks (:func:`~o3d_lsmesh._validate.as_vertex_array`,
    :func:`~o3d_lsmesh._validate.as_triangle_array`): positions of a real
    dtype (integers are converted exactly) and indices of an integer dtype,
    each of shape ``(k, 3)`` exactly (never reshaped), indices range-checked
    before any cast.

    Raises
    ------
    TypeError
        ``mesh`` is not a supported mesh kind; positions that are not real
        numbers (bool, complex, strings, objects); indices that are not
        integers (a float index would be truncated).
    ValueError
        Positions or indices not of shape ``(k, 3)``; empty mesh, no
        triangles, non-finite coordinates, coordinates beyond
        :data:`~o3d_lsmesh._validate.COORDINATE_LIMIT` (``1e30``), out-of-range
        indices, triangles repeating a vertex, or unreferenced vertices when
        not allowed.
    """
    kind = _kind(mesh, name=name)
    # every kind goes through the same two checks: real-number (n, 3) positions and
    # integer (m, 3) indices in range, checked before any cast (never reshaped or truncated)
    if kind == "legacy":
        raw_v, raw_t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    elif kind == "tensor":
        if "positions" not in mesh.vertex:
            raise ValueError(f"{name} must have vertex positions, got an empty mesh")
        raw_v = mesh.vertex.positions.cpu().numpy()
        raw_t = mesh.triangle.indices.cpu().numpy() if "indices" in mesh.triangle else np.zeros((0, 3), np.int64)
    else:
        raw_v, raw_t = mesh
    vertices = as_vertex_array(raw_v, name=name)
    triangles = as_triangle_array(raw_t, len(vertices), name=name)
    check_mesh_arrays(vertices, triangles, name=name, allow_isolated=allow_isolated)
    return MeshData(vertices, triangles, mesh, kind)


def source_triangles(data: MeshData) -> np.ndarray:
    """The triangles of ``data.source`` read again, without validation, ``(m, 3)``.

    For callers that drop ``data.triangles`` while they hold large state (the
    source was validated by :func:`read_mesh` and is not modified by us).
    """
    if data.kind == "legacy":
        return np.asarray(data.source.triangles).reshape(-1, 3)
    if data.kind == "tensor":
        return data.source.triangle.indices.cpu().numpy().reshape(-1, 3)
    return np.asarray(data.source[1]).reshape(-1, 3)


def new_mesh(data: MeshData, vertices: np.ndarray, triangles: np.ndarray | None = None) -> Any:
    """Build a new mesh of ``data``'s kind with ``vertices`` (and ``triangles``, if they changed).

    ``triangles=None`` means the connectivity of ``data`` is kept, and so are
    its per-vertex and per-triangle attributes (see the module docstring).
    """
    same_topology = triangles is None
    if triangles is None:
        triangles = data.triangles
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    if data.kind == "arrays":
        return vertices.copy(), triangles.copy()
    o3d = open3d()
    src = data.source
    if data.kind == "legacy":
        out = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(triangles.astype(np.int32))
        )
        if same_topology and src.has_vertex_colors():
            out.vertex_colors = o3d.utility.Vector3dVector(np.asarray(src.vertex_colors).copy())
        if src.has_vertex_normals():
            out.compute_vertex_normals()
        if src.has_triangle_normals():
            out.compute_triangle_normals()
        return out
    device = src.vertex.positions.device
    position_dtype = src.vertex.positions.dtype
    if position_dtype not in (o3d.core.float32, o3d.core.float64):
        # integer positions in, computed positions out: rounding them back would give a wrong answer
        position_dtype = o3d.core.float64
    index_dtype = src.triangle.indices.dtype if "indices" in src.triangle else o3d.core.int64
    out = o3d.t.geometry.TriangleMesh(device)
    out.vertex.positions = o3d.core.Tensor(vertices, device=device).to(position_dtype)
    out.triangle.indices = o3d.core.Tensor(triangles, device=device).to(index_dtype)
    if same_topology:
        for key in src.vertex:
            if key not in ("positions",) + _NORMAL_KEYS:
                out.vertex[key] = src.vertex[key].clone()
        for key in src.triangle:
            if key not in ("indices",) + _NORMAL_KEYS:
                out.triangle[key] = src.triangle[key].clone()
    had_vertex_normals = "normals" in src.vertex
    had_triangle_normals = "normals" in src.triangle
    if had_vertex_normals or had_triangle_normals:
        out.compute_vertex_normals() if had_vertex_normals else out.compute_triangle_normals()
        if had_vertex_normals and not had_triangle_normals and "normals" in out.triangle:
            del out.triangle["normals"]
    return out


def mesh_state(data: MeshData) -> dict:
    """A picklable description of ``data`` (Open3D meshes do not pickle) that :func:`mesh_from_state` rebuilds.

    It keeps the arrays, the kind and what :func:`new_mesh` takes from the
    source: per-vertex and per-triangle attributes, normals present, and for
    tensor meshes the device and dtypes. The result of :func:`new_mesh` on the
    rebuilt data is then the same as on the original.
    """
    state = {"vertices": data.vertices, "triangles": data.triangles, "kind": data.kind}
    src = data.source
    if data.kind == "legacy" and src is not None:
        state["vertex_colors"] = np.asarray(src.vertex_colors).copy() if src.has_vertex_colors() else None
        state["vertex_normals"] = bool(src.has_vertex_normals())
        state["triangle_normals"] = bool(src.has_triangle_normals())
    elif data.kind == "tensor" and src is not None:
        state["device"] = str(src.vertex.positions.device)
        state["vertex"] = {key: (src.vertex[key].cpu().numpy().copy(), str(src.vertex[key].dtype)) for key in src.vertex}
        state["triangle"] = {
            key: (src.triangle[key].cpu().numpy().copy(), str(src.triangle[key].dtype)) for key in src.triangle
        }
    return state


def _o3d_dtype(name: str) -> Any:
    o3d = open3d()
    return getattr(o3d.core, name.lower())


def mesh_from_state(state: dict) -> MeshData:
    """Rebuild the :class:`MeshData` described by :func:`mesh_state`, with a source mesh of the same kind."""
    vertices, triangles, kind = state["vertices"], state["triangles"], state["kind"]
    if vertices is None:  # arrays released (see LSMeshSolver's _release_arrays): nothing to rebuild
        return MeshData(None, None, None, kind)
    if kind == "arrays" or ("device" not in state and "vertex_normals" not in state):
        return MeshData(vertices, triangles, (vertices, triangles), kind if kind == "arrays" else "arrays")
    o3d = open3d()
    if kind == "legacy":
        source = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(triangles.astype(np.int32))
        )
        if state["vertex_colors"] is not None:
            source.vertex_colors = o3d.utility.Vector3dVector(state["vertex_colors"])
        if state["vertex_normals"]:
            source.compute_vertex_normals()
        if state["triangle_normals"]:
            source.compute_triangle_normals()
        return MeshData(vertices, triangles, source, kind)
    device = o3d.core.Device(state["device"])
    source = o3d.t.geometry.TriangleMesh(device)
    for group, attributes in (("vertex", state["vertex"]), ("triangle", state["triangle"])):
        target = getattr(source, group)
        for key, (array, dtype) in attributes.items():
            target[key] = o3d.core.Tensor(array, device=device).to(_o3d_dtype(dtype))
    return MeshData(vertices, triangles, source, kind)
