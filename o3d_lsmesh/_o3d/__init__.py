"""The only Open3D adapter: meshes to arrays (:func:`read_mesh`: copied, validated, optionally welded) and
back (:func:`new_mesh`: the caller's kind), with the only attribute policy (:data:`ATTRIBUTES`), in full in
``docs/algorithms/attributes.rst``. Files, raycasting and primitives: :mod:`._o3d.io`; pickling:
:mod:`._o3d.state`; attributes of appended elements: :mod:`._o3d.extend`. The open3d import is lazy.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..core.boundary import nonmanifold_vertices
from ..core.errors import InputError, InputTypeError, O3DLSMeshWarning
from ..core.validate import as_indices, collapsed_triangles, mesh_arrays
from .io import has_textures, legacy_mesh, open3d

__all__ = [
    "MeshData",
    "new_mesh",
    "read_mesh",
    "template",
    "tensor_format_of",
    "warn_dropped_attributes",
    "weld_map",
    "welded_triangles",
]


class Attribute(NamedTuple):
    """One row of :data:`ATTRIBUTES`."""

    kind: str  # "legacy" or "tensor"
    group: str  # "vertex" or "triangle" (a legacy mesh's textures: "")
    key: str  # the legacy mesh's property, or the tensor group's key ("*": any other key)
    follows: str  # "vertex" / "triangle" / "corner": per-element data; "texture"; "normals"; "own"
    vector: str = ""  # a legacy array's open3d.utility type
    label: str = ""  # its name in warnings (tensor "*" rows: the key is added)


#: The attribute policy, read by :func:`new_mesh`, :func:`warn_dropped_attributes` and
#: :mod:`.state`. Per-element rows are kept with the connectivity, extended to appended elements
#: and dropped with new connectivity; "texture" (and a tensor mesh's material) stays; "normals" are
#: recomputed when present; "own" rows are the geometry itself.
ATTRIBUTES: tuple[Attribute, ...] = (
    Attribute("legacy", "vertex", "vertex_normals", "normals", "Vector3dVector", "vertex normals"),
    Attribute("legacy", "triangle", "triangle_normals", "normals", "Vector3dVector", "triangle normals"),
    Attribute("legacy", "vertex", "vertex_colors", "vertex", "Vector3dVector", "vertex colors"),
    Attribute("legacy", "triangle", "triangle_uvs", "corner", "Vector2dVector", "triangle UVs"),
    Attribute(
        "legacy", "triangle", "triangle_material_ids", "triangle", "IntVector", "triangle material ids"
    ),
    Attribute("legacy", "", "textures", "texture", "", "textures"),
    Attribute("tensor", "vertex", "positions", "own"),
    Attribute("tensor", "vertex", "normals", "normals", "", "vertex normals"),
    Attribute("tensor", "vertex", "*", "vertex", "", "vertex attribute"),
    Attribute("tensor", "triangle", "indices", "own"),
    Attribute("tensor", "triangle", "normals", "normals", "", "triangle normals"),
    Attribute("tensor", "triangle", "texture_uvs", "corner", "", "triangle attribute"),
    Attribute("tensor", "triangle", "*", "triangle", "", "triangle attribute"),
)
_PER_ELEMENT = ("vertex", "triangle", "corner")


@dataclass(frozen=True)
class MeshData:
    """Arrays copied out of a mesh, plus the mesh itself to rebuild its kind (``split``: when welded)."""

    vertices: np.ndarray  # (n, 3) float64
    triangles: np.ndarray  # (m, 3) int64 (int32 when read with narrow=True)
    source: Any
    kind: str  # "legacy", "tensor" or "arrays"
    split: np.ndarray | None = None  # (n_source,) int64 source vertex -> welded vertex
    # (m_source, 3) int64 the source's triangles, when welded or when some were left out
    split_triangles: np.ndarray | None = None
    # (m,) int64 the source triangle of each of ``triangles``, when some were left out: those repeating a
    # vertex, and those the weld collapsed (zero-area needles, as marching cubes leaves them: two corners
    # at one position)
    rows: np.ndarray | None = None

    def welded_indices(self, indices: Any, *, name: str, merge: bool = False) -> np.ndarray:
        """Check vertex indices of the source's layout; the welded vertices', ``(k,) int64`` (any copy of a
        split vertex means it; ``merge=True``: each once, sorted)."""
        if self.split is None:
            return as_indices(indices, len(self.vertices), name=name)
        welded = self.split[as_indices(indices, len(self.split), name=name)]
        return np.unique(welded) if merge else welded

    def source_indices(self, welded: np.ndarray) -> np.ndarray:
        """Indices of welded vertices in the source's layout: the first copy of each, ``(k,) int64``."""
        if self.split is None:
            return welded
        first = np.unique(self.split, return_index=True)[1]  # welded vertex v is first seen at first[v]
        return first[welded].astype(np.int64)

    def source_positions(self, positions: np.ndarray) -> np.ndarray:
        """Positions of the welded vertices ``(n, 3)`` in the source's layout ``(n_source, 3)``."""
        return positions if self.split is None else positions[self.split]


def _may_have_duplicates(vertices: np.ndarray) -> bool:
    """False when no two rows of ``vertices`` are equal (exact): a sort of one 64-bit hash per row,
    cheaper than the exact row sort; a shared hash only sends the caller to the exact check."""
    # column by column (+0.0 maps -0.0 to 0.0), each mixed in by MurmurHash3's finalizer: its shifts
    # carry the high bits down, so coordinates with few low mantissa bits do not collide
    key = np.zeros(len(vertices), dtype=np.uint64)
    for c in range(3):
        key ^= (vertices[:, c] + 0.0).view(np.uint64)
        for multiplier in (0xFF51AFD7ED558CCD, 0xC4CEB9FE1A85EC53, None):
            key ^= key >> np.uint64(33)
            if multiplier is not None:
                key *= np.uint64(multiplier)
    key.sort()
    return bool(np.any(key[1:] == key[:-1]))


def weld_map(
    vertices: np.ndarray, triangles: np.ndarray, *, guarded: np.ndarray | None = None
) -> np.ndarray | None:
    """Map each vertex to the first vertex at exactly the same coordinates, ``(n,)`` int64, or None.

    Vertices ``guarded`` (positions that may be placeholders, all equal: unknown ones) merge only into
    one fan of the welded surface (copies matched across a cut, as a seam the reader split leaves them)
    and where no triangle then loses a corner; the others each stay alone. None when no two vertices merge,
    or when every triangle would lose a corner (positions that say nothing of the surface). Welded
    vertices are numbered in order of first occurrence.
    """
    n = len(vertices)
    if n == 0 or not _may_have_duplicates(vertices):
        return None
    # a stable sort by (x, y, z): equal rows become neighbours, each group's first row first
    order = np.lexsort(vertices.T[::-1])
    ordered = vertices[order]
    starts = np.ones(n, dtype=bool)
    starts[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    group = np.empty(n, dtype=np.int64)
    group[order] = np.cumsum(starts) - 1  # group of each vertex, groups in sorted order
    first = order[starts]  # first occurrence of each group
    collapsed = collapsed_triangles(group[triangles])
    if guarded is not None and len(guarded):
        # guarded copies merge only into one fan of the welded surface (copies matched across a cut, as a
        # seam's are) and where no triangle loses a corner: placeholders among known neighbours, or far
        # apart on a rim, each stay alone; the groups numbered again
        faces = group[triangles[~collapsed]]
        one_fan = np.zeros(n, dtype=bool)  # per group: its triangles are one fan
        one_fan[faces.ravel()] = True
        one_fan[nonmanifold_vertices(faces, n)] = False
        alone = ~one_fan[group]
        alone[triangles[collapsed].ravel()] = True
        is_guarded = np.zeros(n, dtype=bool)
        is_guarded[guarded] = True
        alone &= is_guarded
        _, first, group = np.unique(
            np.where(alone, n + np.arange(n), group), return_index=True, return_inverse=True
        )
        group = group.ravel()
        collapsed = collapsed_triangles(group[triangles])
    if len(first) == n or (len(triangles) and collapsed.all()):
        return None
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[group]


def welded_triangles(split: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """The triangles on the welded vertices of ``split`` (:func:`weld_map`) without those that lose a
    corner (zero-area needles: their neighbours meet across them; a result keeps them, their corners at
    one welded position), and the source row of each, ``(m,)`` int64 (None when none is left out)."""
    faces = split[triangles]
    kept = ~collapsed_triangles(faces)
    return (faces, None) if kept.all() else (faces[kept], np.flatnonzero(kept))


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
    raise InputTypeError(
        f"{name} must be an open3d.geometry.TriangleMesh, an open3d.t.geometry.TriangleMesh "
        f"or a (vertices, triangles) tuple, got {type(mesh).__name__}",
        param=name,
    )


def read_mesh(
    mesh: Any,
    *,
    name: str = "mesh",
    weld: bool = False,
    narrow: bool = False,
    guarded: np.ndarray | None = None,
) -> MeshData:
    """Copy ``mesh`` into ``(n,3) float64`` vertices and ``(m,3) int64`` triangles and validate them.

    Triangles repeating a vertex (a raw scan's, an STL soup's once merged) have no surface: they are
    left out of ``triangles`` and kept in a result of the same connectivity (:attr:`MeshData.rows`).
    ``weld=True`` merges vertices at equal coordinates (:func:`weld_map`) and leaves out the triangles
    that lose a corner so (``guarded``: :func:`weld_map`); ``narrow=True``: int32 triangles shared with
    a legacy source (read-only callers). A :class:`MeshData` is not checked again (its positions are
    copied; welded if asked).

    Raises
    ------
    InputTypeError
        ``mesh`` is not a supported mesh kind.
    InputError
        A tensor mesh without positions; see :func:`~o3d_lsmesh.core.validate.mesh_arrays`.
    """
    if isinstance(mesh, MeshData):  # read and validated once already (the application's pipeline)
        if not weld or mesh.split is not None:  # its own positions: callers may write to theirs
            return dataclasses.replace(mesh, vertices=mesh.vertices.copy())
        vertices, source, kind = mesh.vertices.copy(), mesh.source, mesh.kind
        triangles = mesh.triangles if mesh.split_triangles is None else mesh.split_triangles
        triangles = triangles.astype(np.int64, copy=False)
    else:
        kind, source = _kind(mesh, name=name), mesh
        if kind == "legacy":
            raw_v, raw_t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
        elif kind == "tensor":
            if "positions" not in mesh.vertex:
                raise InputError(f"{name} must have vertex positions, got an empty mesh", param=name)
            raw_v = mesh.vertex.positions.cpu().numpy()
            indices = mesh.triangle.indices.cpu().numpy() if "indices" in mesh.triangle else None
            raw_t = np.zeros((0, 3), np.int64) if indices is None else indices
        else:
            raw_v, raw_t = mesh
        vertices, triangles = mesh_arrays(raw_v, raw_t, name=name, narrow=narrow, collapsed=True)
    kept = ~collapsed_triangles(triangles)
    if not kept.any():
        raise InputError(
            f"{name} must have a triangle of three distinct vertices, got {len(triangles)} triangles that "
            "each repeat a vertex",
            param=name,
        )
    rows = None if kept.all() else np.flatnonzero(kept)
    faces = triangles if rows is None else triangles[rows]
    split = weld_map(vertices, faces, guarded=guarded) if weld else None
    if split is not None:
        welded = np.zeros((int(split.max()) + 1, 3))
        welded[split] = vertices  # duplicates hold the same coordinates: any writer gives the same row
        faces, left = welded_triangles(split, faces)
        if left is not None:
            rows = left if rows is None else rows[left]
        return MeshData(welded, faces, source, kind, split, triangles, rows)
    return MeshData(vertices, faces, source, kind, None, None if rows is None else triangles, rows)


def template(kind: str, tensor_format: tuple = ()) -> MeshData:
    """An empty stand-in source of ``kind`` for :func:`new_mesh` (``tensor_format``: device, position and
    index dtype names, e.g. ``("CPU:0", "Float64", "Int64")``)."""
    empty_v, empty_t = np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    if kind == "arrays":
        return MeshData(empty_v, empty_t, None, "arrays")
    o3d = open3d()
    if kind == "legacy":
        return MeshData(empty_v, empty_t, o3d.geometry.TriangleMesh(), "legacy")
    device, positions, indices = o3d.core.Device(tensor_format[0]), *tensor_format[1:]
    source = o3d.t.geometry.TriangleMesh(device)
    source.vertex.positions = o3d.core.Tensor(empty_v, getattr(o3d.core, positions.lower()), device)
    source.triangle.indices = o3d.core.Tensor(empty_t, getattr(o3d.core, indices.lower()), device)
    return MeshData(empty_v, empty_t, source, "tensor")


def tensor_format_of(data: MeshData) -> tuple:
    """The :func:`template` format of a tensor mesh's source (empty for other kinds)."""
    if data.kind != "tensor":
        return ()
    positions = data.source.vertex.positions  # (and triangles: read_mesh refuses a mesh without them)
    return (str(positions.device), str(positions.dtype), str(data.source.triangle.indices.dtype))


def present_attributes(data: MeshData) -> list[tuple[Attribute, str]]:
    """The rows of :data:`ATTRIBUTES` that ``data``'s source holds, each with its key, in table order
    (a tensor mesh: its own order, vertex group first)."""
    mesh = data.source
    if data.kind == "legacy":
        return [
            (row, row.key)
            for row in ATTRIBUTES
            if row.kind == "legacy"
            and (has_textures(mesh) if row.follows == "texture" else getattr(mesh, f"has_{row.key}")())
        ]
    if data.kind == "tensor":
        rows = {(row.group, row.key): row for row in ATTRIBUTES if row.kind == "tensor"}  # else "*"
        return [(rows.get((g, k), rows[g, "*"]), k) for g in ("vertex", "triangle") for k in getattr(mesh, g)]
    return []


def _mismatched(data: MeshData) -> list[tuple[Attribute, str]]:
    """The per-element attributes ``(row, key)`` of ``data``'s source that are not one value per vertex or
    triangle (a legacy mesh's ``has_*()`` says it has none)."""
    src = data.source
    if data.kind == "legacy":
        return [
            (row, row.key)
            for row in ATTRIBUTES
            if row.kind == "legacy" and row.follows in _PER_ELEMENT and len(getattr(src, row.key))
            if not getattr(src, f"has_{row.key}")()
        ]
    if data.kind != "tensor":
        return []
    count = {"vertex": len(src.vertex.positions), "triangle": len(src.triangle.indices)}
    return [
        (row, key)
        for row, key in present_attributes(data)
        if row.follows in _PER_ELEMENT and len(getattr(src, row.group)[key]) != count[row.group]
    ]


def warn_dropped_attributes(
    data: MeshData, reason: str, *, stacklevel: int = 3, normals: bool = False
) -> None:
    """Warn once (:class:`~o3d_lsmesh.O3DLSMeshWarning`) if ``data``'s source has attributes a new connectivity
    drops (results not built by :func:`new_mesh`; ``normals=True``: normals too)."""
    kinds = (*_PER_ELEMENT, "texture", "normals") if normals else (*_PER_ELEMENT, "texture")
    dropped = [
        f"{row.label} {key!r}" if row.kind == "tensor" and row.follows in _PER_ELEMENT else row.label
        for row, key in present_attributes(data)
        if row.follows in kinds
    ]
    if dropped:
        warnings.warn(
            f"{reason}: {', '.join(dropped)} of the input cannot follow it and were dropped",
            O3DLSMeshWarning,
            stacklevel=stacklevel,
        )


def new_mesh(
    data: MeshData, vertices: np.ndarray, triangles: np.ndarray | None = None, *, appended: bool = False
) -> Any:
    """Build a new mesh of ``data``'s kind with ``vertices`` (and ``triangles``, if they changed).

    ``triangles=None`` keeps every attribute (a welded ``data``: back in the source's layout);
    ``appended=True``: ``data``'s elements then new ones, attributes extended (:mod:`.extend`); other
    new ``triangles`` drop what no longer matches, with one warning.
    """
    same_topology = triangles is None
    extension = None
    if appended and triangles is not None:
        from .extend import Appended

        extension = Appended(data, np.asarray(vertices, dtype=np.float64), np.asarray(triangles))
        vertices, triangles = extension.vertices, extension.triangles
    elif same_topology:
        # a welded source: back to its split layout, every duplicate at its welded vertex's position
        vertices = data.source_positions(np.asarray(vertices, dtype=np.float64))
        triangles = data.triangles if data.split_triangles is None else data.split_triangles
    else:
        warn_dropped_attributes(data, "the result has new connectivity", stacklevel=4)
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    # (a legacy mesh of the same connectivity copies the source's own triangles: no int64 copy here)
    faces = np.asarray(triangles)
    if not (same_topology and data.kind == "legacy"):
        faces = np.ascontiguousarray(faces, dtype=np.int64)
    if data.kind == "arrays":
        return vertices.copy(), faces.copy()
    o3d = open3d()
    src = data.source
    # per-element attributes not one value per element: kept as given with the same connectivity, else
    # dropped with a warning (new connectivity's warning above names a tensor mesh's already)
    stale = (
        []
        if same_topology
        else [k for k in _mismatched(data) if data.kind == "legacy" or extension is not None]
    )
    if stale:
        named = [row.label if data.kind == "legacy" else f"{row.label} {key!r}" for row, key in stale]
        warnings.warn(
            f"the input's {', '.join(named)} do not match its vertices or triangles in number (Open3D's "
            "remove_triangles_by_index leaves the material ids so) and were dropped",
            O3DLSMeshWarning,
            stacklevel=3,
        )
    if data.kind == "legacy":
        if same_topology:
            # Open3D's own copy of the source (one memcpy per attribute) with the new positions written
            # into it: faster at scan sizes than building the vectors from arrays
            out = o3d.geometry.TriangleMesh(src)
            np.asarray(out.vertices)[...] = vertices
            # the source's normals are stale; Open3D < 0.19 would build vertex normals from them
            out.vertex_normals = o3d.utility.Vector3dVector()
            out.triangle_normals = o3d.utility.Vector3dVector()
        else:
            out = legacy_mesh(vertices, faces)
        present = present_attributes(data)
        if extension is not None:
            for row, key in present:
                if row.follows in _PER_ELEMENT:
                    value = np.asarray(getattr(src, key))
                    shape = (-1, 3, 2) if row.follows == "corner" else value.shape
                    value = extension.extend(row.follows, value.reshape(shape)).reshape(-1, *value.shape[1:])
                    setattr(out, key, getattr(o3d.utility, row.vector)(value))
            out.textures = [o3d.geometry.Image(texture) for texture in src.textures]
        for row, key in present:
            if row.follows == "normals":
                getattr(out, f"compute_{key}")()
        return out
    device = src.vertex.positions.device
    position_dtype = src.vertex.positions.dtype
    if position_dtype not in (o3d.core.float32, o3d.core.float64):
        # integer positions in, computed positions out: rounding them back would give a wrong answer
        position_dtype = o3d.core.float64
    out = o3d.t.geometry.TriangleMesh(device)
    out.vertex.positions = o3d.core.Tensor(vertices, device=device).to(position_dtype)
    index_dtype = src.triangle.indices.dtype
    if len(vertices) - 1 > np.iinfo(src.triangle.indices.cpu().numpy().dtype).max:
        index_dtype = o3d.core.int64  # new vertices past what the input's indices hold: wrapped otherwise
    out.triangle.indices = o3d.core.Tensor(faces, device=device).to(index_dtype)
    normals = set()
    for row, key in present_attributes(data):
        source, target = getattr(src, row.group), getattr(out, row.group)
        if row.follows == "normals":
            normals.add(row.group)
        elif row.follows not in _PER_ELEMENT or not (same_topology or extension is not None):
            continue
        elif (row, key) in stale:
            continue
        elif extension is None:
            target[key] = source[key].clone()
        else:
            value = extension.extend(row.follows, source[key].cpu().numpy())
            target[key] = o3d.core.Tensor(value, device=device).to(source[key].dtype)
    if src.has_valid_material():
        # a copy: the caller's material must not change when the result's is edited
        out.material = o3d.visualization.Material(src.material)
    if normals:
        out.compute_vertex_normals() if "vertex" in normals else out.compute_triangle_normals()
        if normals == {"vertex"} and "normals" in out.triangle:
            del out.triangle["normals"]
    return out
