"""The one place that converts between Open3D meshes and arrays.

Every public function reads its mesh with :func:`read_mesh` and builds its
result with :func:`new_mesh`, so the attribute policy lives here alone:

* the result is a new mesh of the kind the caller gave (legacy
  ``open3d.geometry.TriangleMesh``, tensor ``open3d.t.geometry.TriangleMesh``,
  or a ``(vertices, triangles)`` tuple of arrays);
* the input is never modified: vertices and triangles are copied out;
* with the connectivity unchanged, every attribute is kept: vertex colors,
  triangle UVs, triangle material ids and textures of legacy meshes; every
  per-vertex and per-triangle attribute except normals, and the material, of
  tensor meshes;
* where new vertices and triangles are appended after the input's (hole
  filling: ``new_mesh(..., appended=True)``), every attribute is kept on the old
  elements and extended to the new ones: per-vertex values (colors, any tensor
  vertex attribute) are harmonic in the new vertices (cotangent weights, so
  affine data on a flat patch stays affine; integer ones rounded); per-corner
  UVs (legacy ``triangle_uvs``, tensor ``triangle.texture_uvs``) likewise, where
  the chart is continuous around the patch (each loop vertex has one UV in the
  loop's triangles), else every new corner takes the UV of one loop corner of a
  neighbouring triangle (a texel next to the hole); material ids and other
  per-triangle values are those of that neighbouring triangle; textures and the
  material stay. With a welded mesh, the result has the source's split layout
  with the new vertices after it, and a new triangle uses the copy of a seam
  vertex that its loop's triangle uses;
* where the connectivity changes otherwise (hierarchy levels), per-triangle
  and per-corner data (UVs, material ids, textures, tensor triangle attributes)
  and per-vertex colors no longer match the new triangles and are dropped, with
  one :class:`~o3d_lsmesh.O3DLSMeshWarning` per call naming what was dropped (a
  tensor mesh keeps its material, which does not depend on connectivity);
* with ``read_mesh(..., weld=True)``, vertices at exactly equal coordinates
  (the two sides of a UV seam or a normal crease as Open3D's OBJ, glTF and
  STL readers split them) are merged before the algorithm runs, and the result
  gets the input's split layout back, the welded position copied to every
  duplicate, so seams stay closed and UVs stay valid. Only bit-for-bit equal
  coordinates are merged: a tolerance would also merge distinct nearby
  vertices of a dense scan and change its topology. Vertex indices that the
  caller gives or gets (control points, unknown vertices) stay in the input's
  split layout: :meth:`MeshData.welded_indices` maps them in (an index to
  any copy of a split vertex means the welded vertex) and
  :meth:`MeshData.source_indices` maps results back (to the first copy);
* vertex and triangle normals are recomputed when the input had them;
* a tensor mesh keeps its device and its position and index dtypes (integer
  positions come back as float64: computed positions rounded to integers would
  be a wrong answer).

The open3d import is lazy so that the array core works without it.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._collapsed import collapsed_triangles
from ._errors import O3DLSMeshWarning
from ._solvers import solve_spd
from ._validate import as_indices, mesh_arrays
from .topology import connected_components

__all__ = [
    "MeshData",
    "has_textures",
    "mesh_from_state",
    "mesh_state",
    "new_mesh",
    "obj_writable",
    "open3d",
    "read_mesh",
    "warn_dropped_attributes",
    "weld_map",
]

#: A tensor mesh's attributes that are not carried over as they are (rebuilt or recomputed).
_OWN_KEYS = {"vertex": ("positions", "normals"), "triangle": ("indices", "normals")}
#: A legacy mesh's per-vertex and per-triangle arrays and their ``open3d.utility`` vector types.
_LEGACY_ARRAYS = (
    ("vertex_colors", "Vector3dVector"),
    ("triangle_uvs", "Vector2dVector"),
    ("triangle_material_ids", "IntVector"),
)


def open3d():
    """Import and return the ``open3d`` module (lazily)."""
    import open3d as o3d

    return o3d


@dataclass(frozen=True)
class MeshData:
    """Arrays copied out of a mesh, plus the mesh itself to rebuild its kind.

    When the mesh was welded (``read_mesh(..., weld=True)`` found exact
    duplicates), ``vertices`` and ``triangles`` are the welded surface,
    ``split`` maps each of the source's vertices to its welded vertex
    ``(n_source,)`` and ``split_triangles`` are the source's triangles
    ``(m, 3)`` (what :func:`new_mesh` gives back); otherwise both are None.
    """

    vertices: np.ndarray  # (n, 3) float64
    triangles: np.ndarray  # (m, 3) int64 (int32 when read with narrow=True)
    source: Any
    kind: str  # "legacy", "tensor" or "arrays"
    split: np.ndarray | None = None  # (n_source,) int64 source vertex -> welded vertex
    split_triangles: np.ndarray | None = None  # (m, 3) int64 the source's triangles, when welded

    def welded_indices(self, indices: Any, *, name: str, merge: bool = False) -> np.ndarray:
        """Check vertex indices given in the source's layout and return the welded vertices', ``(k,) int64``.

        An index to any copy of a split vertex means the welded vertex. Indices
        must lie in ``[0, n_source)`` without repetition (:func:`~o3d_lsmesh._validate.as_indices`);
        two copies of one vertex give it twice (a list aligned with per-index data
        such as positions keeps its length), or once with ``merge=True`` (a set
        of vertices, e.g. the unknown ones; sorted).
        """
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
    """False when no two rows of ``vertices`` are equal (exact): a sort of one 64-bit hash per row.

    Equal rows have equal hashes, so distinct hashes prove there is nothing to
    weld at the cost of one plain integer sort, a tenth of ``np.unique``'s row
    sort on large scans; a shared hash only sends the caller to the exact check.
    """
    # one column at a time (two (n,) temporaries, not an (n, 3) copy); adding 0.0 maps -0.0 to 0.0,
    # so equal coordinates have equal bits. Each column is mixed in by MurmurHash3's finalizer (a
    # bijection of 64 bits whose shifts carry the high bits down): a bare multiply-and-xor let a
    # midpoint-subdivided mesh's coordinates (few low mantissa bits) collide, and sent 10M distinct
    # vertices to the exact row sort (7 s)
    key = np.zeros(len(vertices), dtype=np.uint64)
    column = np.empty(len(vertices))
    shifted = np.empty(len(vertices), dtype=np.uint64)
    for c in range(3):
        np.add(vertices[:, c], 0.0, out=column)
        key ^= column.view(np.uint64)
        for multiplier in (0xFF51AFD7ED558CCD, 0xC4CEB9FE1A85EC53, None):
            np.right_shift(key, np.uint64(33), out=shifted)
            key ^= shifted
            if multiplier is not None:
                key *= np.uint64(multiplier)
    del column, shifted
    # the keys' high halves sort in half the time of the whole keys; only the rows whose high half
    # another row shares (by chance about n^2 / 2^33 of them: a few thousand at 10M) have their whole
    # keys compared
    high = (key >> np.uint64(32)).astype(np.uint32)
    ordered = np.sort(high)
    shared = ordered[1:][ordered[1:] == ordered[:-1]]
    del ordered
    if not len(shared):
        return False
    # a 2^20-bucket filter on the shared high halves picks the candidates in one pass over the keys
    bucket = np.zeros(1 << 20, dtype=bool)
    bucket[shared >> np.uint32(12)] = True
    del high
    candidates = key[bucket[(key >> np.uint64(44)).view(np.int64)]]  # (an intp index: no converted copy)
    candidates.sort()
    return bool(np.any(candidates[1:] == candidates[:-1]))


def weld_map(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray | None:
    """Map each vertex to the first vertex at exactly the same coordinates, ``(n,)`` int64, or None.

    None when no two vertices coincide, or when merging them would make a
    triangle repeat a vertex (a triangle with two coincident corners: welding
    it would need removing it, which changes connectivity; such a mesh is
    processed as it is). Welded vertices are numbered in order of first
    occurrence, so a mesh without duplicates keeps its numbering.
    """
    n = len(vertices)
    if n == 0 or not _may_have_duplicates(vertices):
        return None
    # rows sorted by (x, y, z): equal rows become neighbours (a stable sort keeps each group in
    # index order, so its first row is its first occurrence); -0.0 and 0.0 compare equal
    order = np.lexsort(vertices.T[::-1])
    ordered = vertices[order]
    starts = np.ones(n, dtype=bool)
    starts[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    if starts.all():
        return None
    group = np.empty(n, dtype=np.int64)
    group[order] = np.cumsum(starts) - 1  # group of each vertex, groups in sorted order
    first = order[starts]  # first occurrence of each group
    # renumber the groups by first occurrence
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    split = rank[group]
    welded = split[triangles]  # (m, 3)
    if collapsed_triangles(welded).any():
        return None
    return split


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


def read_mesh(mesh: Any, *, name: str = "mesh", weld: bool = False, narrow: bool = False) -> MeshData:
    """Copy ``mesh`` into ``(n,3) float64`` vertices and ``(m,3) int64`` triangles and validate them.

    ``weld=True`` merges vertices at exactly equal coordinates (see
    :func:`weld_map`); :func:`new_mesh` then restores the source's split
    layout. Functions whose arguments or results hold vertex indices map them
    with :meth:`MeshData.welded_indices` and :meth:`MeshData.source_indices`
    (an index given in the split layout would otherwise name another vertex).
    ``narrow=True``: int32 triangles, shared with the source when it holds them so (a legacy Open3D
    mesh), for callers that only read them (see :func:`~o3d_lsmesh._validate.as_triangle_array`).
    Every kind goes through the same checks, :func:`~o3d_lsmesh._validate.mesh_arrays`.

    Raises
    ------
    TypeError
        ``mesh`` is not a supported mesh kind; see :func:`~o3d_lsmesh._validate.mesh_arrays`.
    ValueError
        A tensor mesh without positions; see :func:`~o3d_lsmesh._validate.mesh_arrays`.
    """
    kind = _kind(mesh, name=name)
    if kind == "legacy":
        raw_v, raw_t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    elif kind == "tensor":
        if "positions" not in mesh.vertex:
            raise ValueError(f"{name} must have vertex positions, got an empty mesh")
        raw_v = mesh.vertex.positions.cpu().numpy()
        raw_t = (
            mesh.triangle.indices.cpu().numpy() if "indices" in mesh.triangle else np.zeros((0, 3), np.int64)
        )
    else:
        raw_v, raw_t = mesh
    vertices, triangles = mesh_arrays(raw_v, raw_t, name=name, narrow=narrow)
    split = weld_map(vertices, triangles) if weld else None
    if split is not None:
        welded = np.zeros((int(split.max()) + 1, 3))
        welded[split] = vertices  # duplicates hold the same coordinates: any writer gives the same row
        return MeshData(welded, split[triangles], mesh, kind, split, triangles)
    return MeshData(vertices, triangles, mesh, kind)


def has_textures(mesh: Any) -> bool:
    """Whether a legacy mesh holds a texture image (Open3D's ``has_textures`` is False when one of them
    is empty, as the empty first slot its OBJ reader adds for faces without a material)."""
    return any(not texture.is_empty() for texture in mesh.textures)


def _dropped(data: MeshData, *, normals: bool = False) -> list[str]:
    """Names of the source's attributes that a result with new connectivity cannot keep (``normals``: its
    normals too, for results that do not recompute them)."""
    src = data.source
    if src is None or data.kind == "arrays":
        return []
    if data.kind == "legacy":
        checks = (
            ("vertex normals", normals and src.has_vertex_normals()),
            ("triangle normals", normals and src.has_triangle_normals()),
            ("vertex colors", src.has_vertex_colors()),
            ("triangle UVs", src.has_triangle_uvs()),
            ("triangle material ids", src.has_triangle_material_ids()),
            ("textures", has_textures(src)),
        )
        return [label for label, present in checks if present]
    return [
        f"{group} normals" if key == "normals" else f"{group} attribute {key!r}"
        for group, own in _OWN_KEYS.items()
        for key in getattr(src, group)
        if key not in own or (normals and key == "normals")
    ]


def warn_dropped_attributes(
    data: MeshData, reason: str, *, stacklevel: int = 3, normals: bool = False
) -> bool:
    """Warn once (:class:`~o3d_lsmesh.O3DLSMeshWarning`) if ``data``'s source has attributes a new connectivity drops.

    For functions whose results have new triangles but are not built by
    :func:`new_mesh` from ``data`` (hierarchy levels): call it once per call
    with the reason, e.g. ``"hierarchy levels have new connectivity"``.
    Returns whether it warned. ``stacklevel=3`` points at the caller of the
    public function that calls this. ``normals=True``: the results carry no
    normals (they are not recomputed), so the source's are named as well.
    """
    dropped = _dropped(data, normals=normals)
    if dropped:
        warnings.warn(
            f"{reason}: {', '.join(dropped)} of the input cannot follow it and were dropped",
            O3DLSMeshWarning,
            stacklevel=stacklevel,
        )
    return bool(dropped)


class _Appended:
    """A result whose vertices and triangles are ``data``'s, then new ones (welded numbering): its arrays
    in the source's layout and each kind of attribute extended to the new elements (module docstring)."""

    def __init__(self, data: MeshData, vertices: np.ndarray, triangles: np.ndarray) -> None:
        nw, m, total = len(data.vertices), len(data.triangles), len(vertices)
        old, new = data.triangles, np.asarray(triangles[m:], dtype=np.int64)
        source_triangles = old if data.split_triangles is None else data.split_triangles
        n_source = nw if data.split is None else len(data.split)
        # the loop corners: both ends of each old triangle's edge that a new triangle shares (only
        # triangles with two corners on new triangles can have one: no sort of the whole mesh's edges)
        touched = np.zeros(total, dtype=bool)
        touched[new] = True
        near = np.flatnonzero(touched[old].sum(axis=1) >= 2)
        row, corner = np.nonzero(np.isin(_edge_keys(old[near], total), _edge_keys(new, total)))
        self.tri = np.concatenate([near[row], near[row]])
        self.corner = np.concatenate([corner, (corner + 1) % 3])
        self.vertex = old[self.tri, self.corner]
        self.loop, self.first = np.unique(self.vertex, return_index=True)
        # each new patch (vertex-connected new triangles: a hole, or holes touching at a vertex) takes
        # its per-triangle defaults from the triangle of its first loop corner
        self.patch = connected_components(new, total)[1]
        reference = np.zeros(total, dtype=np.int64)
        labels, first_corner = np.unique(self.patch[self.vertex], return_index=True)
        reference[labels] = first_corner
        self.owner = reference[self.patch[new[:, 0]]]  # (q,) the reference loop corner of each new triangle
        # an old vertex of a new triangle is the copy its loop triangle uses: the hole's side of a seam
        self.copy = np.asarray(data.source_indices(np.arange(nw)), dtype=np.int64).copy()
        self.copy[self.loop] = source_triangles[self.tri[self.first], self.corner[self.first]]
        to_source = np.concatenate([self.copy, np.arange(n_source, n_source + total - nw)])
        self.vertices = np.concatenate([data.source_positions(vertices[:nw]), vertices[nw:]])
        self.triangles = np.concatenate([source_triangles, to_source[new]])
        self.new, self.nw, self.inner = new, nw, None
        if total > nw:
            # harmonic values of the new vertices, L_uu x_u = -L_ub x_b with the cotangent Laplacian of
            # the new triangles (a new vertex has no other; numbered among their vertices alone, the new
            # ones last): linear precision, so affine data on a flat patch stays affine. L is not
            # symmetric (rows scaled by 1/D): its normal equations
            from .laplacian import cotangent_laplacian  # (laplacian reads meshes through this module)

            local, local_triangles = np.unique(new, return_inverse=True)
            k = int(np.searchsorted(local, nw))
            laplacian = cotangent_laplacian(vertices[local], local_triangles.reshape(-1, 3))
            self.around, self.inner, self.coupling = local[:k], laplacian[k:, k:], laplacian[k:, :k]
            self.normal = (self.inner.T @ self.inner).tocsc()

    def harmonic(self, values: np.ndarray) -> np.ndarray:
        """Values ``(nw, k)`` of the welded vertices extended harmonically to the new ones, ``(p, k)``."""
        if self.inner is None:
            return np.zeros((0, values.shape[1]))
        solution = solve_spd(self.normal, self.inner.T @ -(self.coupling @ values[self.around]))
        return np.asarray(solution).reshape(-1, values.shape[1])

    def per_vertex(self, values: np.ndarray) -> np.ndarray:
        """Per-vertex values ``(n_source, ...)`` followed by the new vertices' (clipped to the input's range;
        integers rounded)."""
        flat = values.reshape(len(values), -1)
        extra = np.clip(self.harmonic(flat[self.copy].astype(np.float64)), flat.min(axis=0), flat.max(axis=0))
        if not np.issubdtype(values.dtype, np.floating):
            extra = np.rint(extra)
        return np.concatenate([values, extra.reshape((-1,) + values.shape[1:]).astype(values.dtype)])

    def per_triangle(self, values: np.ndarray) -> np.ndarray:
        """Per-triangle values ``(m, ...)`` followed by the new triangles': their reference triangle's."""
        return np.concatenate([values, values[self.tri[self.owner]]])

    def per_corner(self, values: np.ndarray) -> np.ndarray:
        """Per-corner values ``(m, 3, d)`` (UVs) followed by the new triangles'."""
        at_corner = values[self.tri, self.corner].astype(np.float64)  # (c, d) the loop corners'
        at = np.zeros((self.nw, values.shape[2]))
        at[self.loop] = at_corner[self.first]
        # a chart is continuous around a patch when every loop vertex has one value in its loop triangles
        torn = np.zeros(len(self.patch), dtype=bool)
        torn[self.patch[self.vertex[(at_corner != at[self.vertex]).any(axis=1)]]] = True
        extended = np.concatenate([at, self.harmonic(at)])[self.new]  # (q, 3, d)
        fallback = torn[self.patch[self.new[:, 0]]]
        extended[fallback] = at_corner[self.owner[fallback]][:, None]
        return np.concatenate([values, extended.astype(values.dtype)])


def _edge_keys(triangles: np.ndarray, n: int) -> np.ndarray:
    """One integer per triangle edge ``(m, 3)``, edge ``c`` from corner ``c`` to ``c + 1``, either way round."""
    nxt = np.roll(triangles, -1, axis=1)
    return np.minimum(triangles, nxt) * n + np.maximum(triangles, nxt)


def new_mesh(
    data: MeshData,
    vertices: np.ndarray,
    triangles: np.ndarray | None = None,
    *,
    warn: bool = True,
    appended: bool = False,
) -> Any:
    """Build a new mesh of ``data``'s kind with ``vertices`` (and ``triangles``, if they changed).

    ``triangles=None`` means the connectivity of ``data`` is kept, and so are
    its per-vertex and per-triangle attributes and its material (see the module
    docstring). If ``data`` was welded, ``vertices`` are the welded vertices
    and the result has the source's split layout, each duplicate at its welded
    vertex's position. ``appended=True``: ``vertices`` and ``triangles`` are
    ``data``'s (welded, unchanged and in order) then new ones; every attribute
    is kept and extended to the new elements (module docstring). Other new
    ``triangles`` (in ``data``'s numbering) drop what no longer matches them,
    with one :class:`~o3d_lsmesh.O3DLSMeshWarning` (``warn=False``: the caller
    warns itself).
    """
    same_topology = triangles is None
    extension = None
    if appended and triangles is not None:
        extension = _Appended(data, np.asarray(vertices, dtype=np.float64), np.asarray(triangles))
        vertices, triangles = extension.vertices, extension.triangles
    elif same_topology and data.split is not None:
        # back to the source's split layout: every duplicate gets its welded vertex's position
        vertices = data.source_positions(np.asarray(vertices, dtype=np.float64))
        triangles = data.split_triangles
    elif triangles is None:
        triangles = data.triangles
    elif data.source is not None and warn and extension is None:
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
    if data.kind == "legacy":
        if same_topology:
            # Open3D's own copy of the source (triangles, colors, UVs, material ids, textures: one
            # memcpy each) with the new positions written into it, several times faster at scan
            # sizes than building the vectors from arrays (the int64 -> int32 triangles above all)
            out = o3d.geometry.TriangleMesh(src)
            np.asarray(out.vertices)[...] = vertices
            # the source's normals are stale; Open3D < 0.19 would build vertex normals from them
            out.vertex_normals = o3d.utility.Vector3dVector()
            out.triangle_normals = o3d.utility.Vector3dVector()
        else:
            out = o3d.geometry.TriangleMesh(
                o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(faces.astype(np.int32))
            )
        if extension is not None:
            if src.has_vertex_colors():
                out.vertex_colors = o3d.utility.Vector3dVector(
                    extension.per_vertex(np.asarray(src.vertex_colors))
                )
            if src.has_triangle_uvs():
                uvs = np.asarray(src.triangle_uvs).reshape(-1, 3, 2)
                out.triangle_uvs = o3d.utility.Vector2dVector(extension.per_corner(uvs).reshape(-1, 2))
            if src.has_triangle_material_ids():
                ids = np.asarray(src.triangle_material_ids)
                out.triangle_material_ids = o3d.utility.IntVector(extension.per_triangle(ids))
            out.textures = [o3d.geometry.Image(texture) for texture in src.textures]
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
    out.triangle.indices = o3d.core.Tensor(faces, device=device).to(index_dtype)
    for group, own in _OWN_KEYS.items() if same_topology or extension is not None else ():
        source, target = getattr(src, group), getattr(out, group)
        for key in source:
            if key in own:
                continue
            if extension is None:
                target[key] = source[key].clone()
                continue
            value = source[key].cpu().numpy()
            if group == "vertex":
                value = extension.per_vertex(value)
            elif key == "texture_uvs" and value.ndim == 3 and value.shape[1] == 3:
                value = extension.per_corner(value)
            else:
                value = extension.per_triangle(value)
            target[key] = o3d.core.Tensor(value, device=device).to(source[key].dtype)
    if src.has_valid_material():
        # a copy: the caller's material must not change when the result's is edited
        out.material = o3d.visualization.Material(src.material)
    had_vertex_normals = "normals" in src.vertex
    had_triangle_normals = "normals" in src.triangle
    if had_vertex_normals or had_triangle_normals:
        out.compute_vertex_normals() if had_vertex_normals else out.compute_triangle_normals()
        if had_vertex_normals and not had_triangle_normals and "normals" in out.triangle:
            del out.triangle["normals"]
    return out


def obj_writable(mesh: Any) -> Any:
    """A legacy mesh that Open3D's OBJ writer writes with every texture (``mesh`` itself if it already is).

    The writer names material ``i`` ``<stem>_i`` and its image ``<stem>_i.png``, and stops at the
    first empty texture slot, leaving the ``.mtl`` without the rest and saying so only in a native
    warning; its own OBJ reader puts an empty slot first (for faces without a material), so a read
    OBJ is written back without its texture. The copy drops the empty slots no triangle uses
    (material ids renumbered) and gives those in use a 1x1 white image (untextured white).
    """
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


def mesh_state(data: MeshData) -> dict:
    """A picklable description of ``data`` (Open3D meshes do not pickle) that :func:`mesh_from_state` rebuilds.

    It keeps the arrays, the kind, the weld and what :func:`new_mesh` takes from the source:
    per-vertex and per-triangle attributes, textures, the tensor material, normals present, and
    for tensor meshes the device and dtypes. The result of :func:`new_mesh` on the rebuilt data is
    then the same as on the original.
    """
    state: dict[str, Any] = {
        "vertices": data.vertices,
        "triangles": data.triangles,
        "kind": data.kind,
        "split": data.split,
        "split_triangles": data.split_triangles,
    }
    src = data.source
    if data.kind == "legacy":
        for key, _ in _LEGACY_ARRAYS:
            state[key] = np.asarray(getattr(src, key)).copy() if getattr(src, f"has_{key}")() else None
        # as new_mesh copies them: only when the mesh has a texture (readers may leave empty images)
        textures = src.textures if has_textures(src) else []
        state["textures"] = [None if t.is_empty() else np.asarray(t).copy() for t in textures]
        state["vertex_normals"] = bool(src.has_vertex_normals())
        state["triangle_normals"] = bool(src.has_triangle_normals())
    elif data.kind == "tensor":
        state["device"] = str(src.vertex.positions.device)
        for group in ("vertex", "triangle"):
            attributes = getattr(src, group)
            state[group] = {
                key: (attributes[key].cpu().numpy().copy(), str(attributes[key].dtype)) for key in attributes
            }
        state["material"] = _material_state(src.material) if src.has_valid_material() else None
    return state


def _material_state(material: Any) -> dict:
    """The fields of an ``open3d.visualization.Material`` (which does not pickle) as plain values."""
    return {
        "name": material.material_name,
        "scalar": dict(material.scalar_properties),
        "vector": {key: np.array(value) for key, value in material.vector_properties.items()},
        "textures": {key: image.as_tensor().numpy().copy() for key, image in material.texture_maps.items()},
    }


def _material_from_state(state: dict) -> Any:
    o3d = open3d()
    material = o3d.visualization.Material(state["name"])
    for key, value in state["scalar"].items():
        material.scalar_properties[key] = value
    for key, value in state["vector"].items():
        material.vector_properties[key] = value
    for key, value in state["textures"].items():
        material.texture_maps[key] = o3d.t.geometry.Image(o3d.core.Tensor(value))
    return material


def mesh_from_state(state: dict) -> MeshData:
    """Rebuild the :class:`MeshData` described by :func:`mesh_state`, with a source mesh of the same kind."""
    vertices, triangles, kind = state["vertices"], state["triangles"], state["kind"]
    split, split_triangles = state["split"], state["split_triangles"]
    # the source's own layout: a welded source's positions are its welded vertices' (they coincide)
    source_v = vertices if split is None else vertices[split]
    source_t = triangles if split is None else split_triangles
    if kind == "arrays":
        return MeshData(vertices, triangles, (source_v, source_t), kind, split, split_triangles)
    o3d = open3d()
    if kind == "legacy":
        source = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(source_v), o3d.utility.Vector3iVector(source_t.astype(np.int32))
        )
        for key, vector in _LEGACY_ARRAYS:
            if state[key] is not None:
                setattr(source, key, getattr(o3d.utility, vector)(state[key]))
        source.textures = [
            o3d.geometry.Image() if texture is None else o3d.geometry.Image(texture)
            for texture in state["textures"]
        ]
        if state["vertex_normals"]:
            source.compute_vertex_normals()
        if state["triangle_normals"]:
            source.compute_triangle_normals()
        return MeshData(vertices, triangles, source, kind, split, split_triangles)
    device = o3d.core.Device(state["device"])
    source = o3d.t.geometry.TriangleMesh(device)
    for group in ("vertex", "triangle"):
        target = getattr(source, group)
        for key, (array, dtype) in state[group].items():
            target[key] = o3d.core.Tensor(array, device=device).to(getattr(o3d.core, dtype.lower()))
    if state["material"] is not None:
        source.material = _material_from_state(state["material"])
    return MeshData(vertices, triangles, source, kind, split, split_triangles)
