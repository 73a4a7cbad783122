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
* a tensor mesh keeps its device and its position and index dtypes.

The open3d import is lazy so that the array core works without it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ._validate import check_mesh_arrays

__all__ = ["MeshData", "read_mesh", "new_mesh", "open3d"]

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


def _kind(mesh: Any) -> str:
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
        "mesh must be an open3d.geometry.TriangleMesh, an open3d.t.geometry.TriangleMesh "
        f"or a (vertices, triangles) tuple, got {type(mesh).__name__}"
    )


def read_mesh(mesh: Any, *, name: str = "mesh", allow_isolated: bool = True) -> MeshData:
    """Copy ``mesh`` into ``(n,3) float64`` vertices and ``(m,3) int64`` triangles and validate them.

    Raises
    ------
    TypeError
        ``mesh`` is not a supported mesh kind.
    ValueError
        Empty mesh, no triangles, non-finite coordinates, out-of-range indices,
        triangles repeating a vertex, or unreferenced vertices when not allowed.
    """
    kind = _kind(mesh)
    if kind == "legacy":
        vertices = np.array(mesh.vertices, dtype=np.float64).reshape(-1, 3)
        triangles = np.array(mesh.triangles, dtype=np.int64).reshape(-1, 3)
    elif kind == "tensor":
        if "positions" not in mesh.vertex:
            raise ValueError(f"{name} must have vertex positions, got an empty mesh")
        vertices = mesh.vertex.positions.cpu().numpy().astype(np.float64).reshape(-1, 3)
        if "indices" in mesh.triangle:
            triangles = mesh.triangle.indices.cpu().numpy().astype(np.int64).reshape(-1, 3)
        else:
            triangles = np.zeros((0, 3), dtype=np.int64)
    else:
        raw_v, raw_t = mesh
        try:
            vertices = np.array(raw_v, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise TypeError(f"{name} vertices must be an (n, 3) float array, got {type(raw_v).__name__}") from error
        triangles = np.asarray(raw_t)
        if triangles.size and not np.issubdtype(triangles.dtype, np.integer):
            raise TypeError(f"{name} triangles must be an (m, 3) integer array, got dtype {triangles.dtype}")
        triangles = triangles.astype(np.int64)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise ValueError(f"{name} vertices must have shape (n, 3), got {vertices.shape}")
        if triangles.size == 0:
            triangles = triangles.reshape(0, 3)
        if triangles.ndim != 2 or triangles.shape[1] != 3:
            raise ValueError(f"{name} triangles must have shape (m, 3), got {triangles.shape}")
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
