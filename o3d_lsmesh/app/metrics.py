"""Error and quality measures between meshes, used by the tests, the CLI's ``compare`` and every benchmark.

All functions accept Open3D meshes (legacy or tensor) or ``(vertices, triangles)`` tuples.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .._o3d import read_mesh
from .._o3d.io import distances_to_surface, raycasting_scene
from ..core.arrays import area_weighted_normals, face_normals
from ..core.connectivity import Connectivity, halfedges
from ..core.errors import InputError
from ..core.validate import as_count
from ..summary import topology_summary  # re-exported: metrics.topology_summary is the historical name

if TYPE_CHECKING:
    from .._types import AnyMesh

#: Largest ``number_of_points`` of :func:`surface_distance`: about 100 bytes a sample, so 1e7
#: samples per mesh stay near 2 GB; more would not change a distance estimate.
MAX_SAMPLE_POINTS = 10_000_000

__all__ = [
    "MAX_SAMPLE_POINTS",
    "normal_deviation",
    "raycasting_scene",
    "shape_change",
    "signed_volume",
    "surface_distance",
    "topology_summary",
    "triangle_angles",
    "vertex_error",
]


def vertex_error(a: AnyMesh, b: AnyMesh) -> dict:
    """Per-vertex distances of two meshes with one vertex count: ``linf``, ``rms`` and ``mean`` of ``|a_i - b_i|``.

    Examples
    --------
    >>> import open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> moved = o3d.geometry.TriangleMesh(box).translate((0.0, 0.0, 0.1))
    >>> {key: round(value, 12) for key, value in vertex_error(box, moved).items()}
    {'linf': 0.1, 'rms': 0.1, 'mean': 0.1}
    """
    va, vb = read_mesh(a, name="a").vertices, read_mesh(b, name="b").vertices
    if va.shape != vb.shape:
        raise InputError(f"b must have the vertex count of a ({len(va)}), got {len(vb)}", param="b")
    d = np.linalg.norm(va - vb, axis=1)
    return {"linf": float(d.max()), "rms": float(np.sqrt(np.mean(d**2))), "mean": float(d.mean())}


def _sample_surface(
    vertices: np.ndarray, triangles: np.ndarray, count: int, rng: np.random.Generator
) -> np.ndarray:
    corners, area = vertices[triangles], face_normals(vertices, triangles)[1]
    total = area.sum()
    probabilities = area / total if total > 0 else np.full(len(area), 1.0 / len(area))
    chosen = rng.choice(len(triangles), size=count, p=probabilities)
    r1, r2 = rng.random(count), rng.random(count)
    s = np.sqrt(r1)
    u, v, w = 1 - s, s * (1 - r2), s * r2
    c = corners[chosen]
    # include the vertices themselves so that spikes at vertices are never missed
    return np.concatenate(
        [u[:, None] * c[:, 0] + v[:, None] * c[:, 1] + w[:, None] * c[:, 2], vertices[np.unique(triangles)]]
    )


def surface_distance(a: AnyMesh, b: AnyMesh, *, number_of_points: int = 100_000, seed: int = 0) -> dict:
    """Two-sided sampled surface distance (Metro style): ``hausdorff``, ``mean`` and ``rms`` in a dict.

    ``number_of_points`` samples uniform by area on each surface, plus its vertices, measured to the
    other by Open3D's ``RaycastingScene`` (float32: below ~1e-7 of the size is noise) at unit size.

    Examples
    --------
    >>> import open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> moved = o3d.geometry.TriangleMesh(box).translate((0.0, 0.0, 0.1))
    >>> round(surface_distance(box, moved, number_of_points=1000)["hausdorff"], 6)  # the top and bottom faces
    0.1
    """
    number_of_points = as_count(
        number_of_points, name="number_of_points", minimum=1, maximum=MAX_SAMPLE_POINTS
    )
    seed = as_count(seed, name="seed")
    da, db = read_mesh(a, name="a"), read_mesh(b, name="b")
    center, scale = common_frame(da.vertices, db.vertices)
    va, vb = (da.vertices - center) / scale, (db.vertices - center) / scale
    rng = np.random.default_rng(seed)
    pa = _sample_surface(va, da.triangles, number_of_points, rng)
    pb = _sample_surface(vb, db.triangles, number_of_points, rng)
    ab = scale * distances_to_surface(pa, vb, db.triangles)
    ba = scale * distances_to_surface(pb, va, da.triangles)
    both = np.concatenate([ab, ba])
    return {
        "hausdorff": float(max(ab.max(), ba.max())),
        "mean": float(both.mean()),
        "rms": float(np.sqrt(np.mean(both**2))),
    }


def common_frame(*vertex_arrays: np.ndarray) -> tuple[np.ndarray, float]:
    """Center (of the joint bounding box) and half extent of the arrays, for scale-free computations."""
    low = np.min([v.min(axis=0) for v in vertex_arrays], axis=0)
    high = np.max([v.max(axis=0) for v in vertex_arrays], axis=0)
    center = 0.5 * (low + high)
    scale = float(np.max(high - low)) * 0.5
    return center, scale if scale > 0 else 1.0


def _unit_scale(vertices: np.ndarray) -> np.ndarray:
    """``vertices`` divided by their largest magnitude: angles and normals without overflow or underflow."""
    top = float(np.abs(vertices).max())
    return vertices / top if top > 0 else vertices


def signed_volume(mesh: AnyMesh) -> float:
    """Signed volume enclosed by the mesh (divergence theorem); positive when wound outward.

    Computed about the centre of the mesh's bounding box at unit size and scaled back, so that no
    coordinate overflows or underflows the triple products and a mesh far from the origin (in world
    coordinates) keeps its digits; an open mesh's value depends on that centre.

    >>> import open3d as o3d
    >>> signed_volume(o3d.geometry.TriangleMesh.create_box(2.0, 1.0, 1.0))
    2.0
    """
    data = read_mesh(mesh)
    return _volume(data.vertices, data.triangles)


def _volume(vertices: np.ndarray, triangles: np.ndarray) -> float:
    if not len(triangles):
        return 0.0
    corners = vertices[triangles]
    centre, half = common_frame(corners.reshape(-1, 3))
    c = (corners - centre) / half
    return float(np.einsum("ij,ij->i", c[:, 0], np.cross(c[:, 1], c[:, 2])).sum() / 6.0) * half**3


#: Vertices within this many edges of the boundary are the rim of :func:`shape_change`.
RIM_RINGS = 2


def shape_change(before: AnyMesh, after: AnyMesh) -> dict:
    """How a filter changed a mesh's shape: the volume change of a closed mesh, the inward shift of an open one.

    Closed: every edge has as many triangles along it one way as the other. The inward shift of
    vertex ``i`` is ``-(b_i - a_i) . n_i`` (``n_i``: ``before``'s unit area-weighted normal), averaged
    over the vertices with a normal, the rim (boundary and :data:`RIM_RINGS` rings) and the interior.

    Returns
    -------
    dict
        ``closed``; closed: ``volume_before``, ``volume_after``, ``volume_change_percent`` (None for a
        zero volume); open: ``inward_shift_mean``, ``_rim``, ``_interior`` (None: empty, or no correspondence).

    Examples
    --------
    >>> square = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]), np.array([[0, 1, 2], [0, 2, 3]])
    >>> shape_change(square, (square[0] + [0, 0, 0.25], square[1]))["inward_shift_mean"]  # out along +z
    -0.25
    """
    a, b = read_mesh(before, name="before"), read_mesh(after, name="after")
    n, triangles = len(a.vertices), a.triangles
    conn = Connectivity(triangles, n)
    half = halfedges(triangles)
    direction = np.where(half[:, 0] < half[:, 1], 1.0, -1.0)
    unmatched = np.bincount(conn.halfedge_edge, weights=direction, minlength=len(conn.edges)) != 0
    if not unmatched.any():
        volume_before, volume_after = _volume(a.vertices, triangles), _volume(b.vertices, b.triangles)
        change = 100.0 * (volume_after - volume_before) / volume_before if volume_before != 0 else None
        return dict(
            closed=True, volume_before=volume_before, volume_after=volume_after, volume_change_percent=change
        )
    out: dict[str, Any] = dict(
        closed=False, inward_shift_mean=None, inward_shift_rim=None, inward_shift_interior=None
    )
    if not corresponding(a, b):
        return out
    normals = area_weighted_normals(_unit_scale(a.vertices), triangles)
    length = np.linalg.norm(normals, axis=1)
    has = length > 0
    shift = -np.einsum("ij,ij->i", b.vertices - a.vertices, normals) / np.where(has, length, 1.0)
    rim = rim_mask(conn, RIM_RINGS)
    for key, region in (("mean", has), ("rim", has & rim), ("interior", has & ~rim)):
        out[f"inward_shift_{key}"] = float(shift[region].mean()) if region.any() else None
    return out


def corresponding(a: Any, b: Any) -> bool:
    """Whether vertex ``i`` of ``a`` is vertex ``i`` of ``b``: the same triangles on as many vertices (a
    filter's result; not the same mesh from a format that renumbers, as OBJ and glTF are read)."""
    a_triangles, b_triangles = np.asarray(a.triangles), np.asarray(b.triangles)
    return len(a.vertices) == len(b.vertices) and np.array_equal(a_triangles, b_triangles)


def rim_mask(conn: Connectivity, rings: int) -> np.ndarray:
    """``(n,) bool``: the boundary vertices and those within ``rings`` edges of them."""
    rim = np.zeros(conn.n, dtype=bool)
    rim[conn.k_rings(np.unique(conn.edges[conn.boundary_edges]), rings)] = True
    return rim


def normal_deviation(a: AnyMesh, b: AnyMesh) -> float:
    """Mean angle in degrees between corresponding face normals of two meshes with the same triangles.

    A triangle of zero area (in either mesh) is left out; ``InputError`` if no triangle is left or
    the triangles differ.

    Examples
    --------
    >>> import numpy as np, open3d as o3d
    >>> box = o3d.geometry.TriangleMesh.create_box()
    >>> turned = o3d.geometry.TriangleMesh(box).rotate(box.get_rotation_matrix_from_xyz((0, 0, np.pi / 6)))
    >>> round(normal_deviation(box, turned), 9)  # 8 of 12 normals turn by 30 degrees
    20.0
    """
    da, db = read_mesh(a, name="a"), read_mesh(b, name="b")
    if da.triangles.shape != db.triangles.shape or not np.array_equal(da.triangles, db.triangles):
        raise InputError("b must have the same triangles as a", param="b")
    na = face_normals(_unit_scale(da.vertices), da.triangles)[0]
    nb = face_normals(_unit_scale(db.vertices), db.triangles)[0]
    defined = (np.abs(na).sum(axis=1) > 0) & (np.abs(nb).sum(axis=1) > 0)
    if not defined.any():
        raise InputError(
            f"a and b must share a triangle of non-zero area to compare normals, got {len(na)} triangles "
            "all of zero area in a or b",
            param="b",
        )
    na, nb = na[defined], nb[defined]
    # atan2(|a x b|, a . b): accurate for small angles, where arccos(a . b) turns round-off
    # into 1e-6 degrees between identical normals
    sine = np.linalg.norm(np.cross(na, nb), axis=1)
    cosine = np.einsum("ij,ij->i", na, nb)
    return float(np.degrees(np.arctan2(sine, cosine)).mean())


def normal_change(a: Any, b: Any) -> float | None:
    """:func:`normal_deviation`, or None when no triangle has an area in both (the angle is undefined)."""
    try:
        return normal_deviation(a, b)
    except ValueError:
        return None


def triangle_angles(mesh: AnyMesh) -> dict:
    """Smallest interior angle (degrees) and the share of triangles with an angle under 10 degrees.

    >>> import open3d as o3d
    >>> angles = triangle_angles(o3d.geometry.TriangleMesh.create_box())  # right isosceles halves of squares
    >>> round(angles["min_angle"], 9), angles["share_under_10"]
    (45.0, 0.0)
    """
    data = read_mesh(mesh)
    c = _unit_scale(data.vertices)[data.triangles]
    u, v = c[:, [1, 2, 0]] - c, c[:, [2, 0, 1]] - c  # the two sides at each corner
    lengths = np.linalg.norm(u, axis=2) * np.linalg.norm(v, axis=2)
    cos = np.einsum("ijk,ijk->ij", u, v) / np.maximum(lengths, 1e-300)
    smallest = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).min(axis=1)
    return {"min_angle": float(smallest.min()), "share_under_10": float(np.mean(smallest < 10.0))}
