"""Finding holes: every boundary loop with its size and whether it is an outer border.

See docs/algorithms/hole_filling.rst.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from ..core.boundary import boundary_loops
from ..core.connectivity import Connectivity
from .tuning import BORDER_FACING_AWAY, SIDEWAYS

__all__ = ["Hole", "find_holes"]


def _loop_rows(triangles: np.ndarray, n: int, conn: Connectivity) -> list[tuple[np.ndarray, np.ndarray]]:
    """The loops of :func:`o3d_lsmesh.core.boundary.boundary_loops`, each with the row (of
    :func:`o3d_lsmesh.core.connectivity.halfedges`) of the one half-edge on each loop edge ``(loop[i], loop[i + 1])``;
    ``conn`` is the mesh's Connectivity."""
    es = conn.edge_structure
    edges, counts, inverse = es.edges.astype(np.int64), es.counts, es.inverse
    loops = boundary_loops(triangles, n, conn=conn, join_fans=True)  # a hole's rim crosses a pinch
    if not loops:
        return []
    single = np.flatnonzero(counts[inverse] == 1)
    row_of_edge = np.full(len(edges), -1, dtype=np.int64)
    row_of_edge[inverse[single]] = single
    tail = np.concatenate(loops)
    head = np.concatenate([np.roll(loop, -1) for loop in loops])
    keys = np.minimum(tail, head) * n + np.maximum(tail, head)
    rows = row_of_edge[np.searchsorted(edges[:, 0] * n + edges[:, 1], keys)]
    return list(zip(loops, np.split(rows, np.cumsum([len(loop) for loop in loops])[:-1])))


@dataclass(frozen=True)
class Hole:
    """One boundary loop: vertices along the orientation of the triangles around it.

    Attributes
    ----------
    vertices : (k,) int64
    edges : int
        ``k``, the number of boundary edges.
    perimeter, diameter : float
        Sum of the edge lengths; largest distance between two of its vertices.
    component : int
        Connected component of the mesh (by shared vertices) the loop lies on.
    border : bool
        Whether it is its component's outer border (see :data:`BORDER_FACING_AWAY`).
    rows : (k,) int64
        The half-edge of each loop edge, row of :func:`o3d_lsmesh.core.connectivity.halfedges`.
    """

    vertices: np.ndarray
    edges: int
    perimeter: float
    diameter: float
    component: int
    border: bool
    rows: np.ndarray = field(repr=False)


def _diameter(points: np.ndarray) -> float:
    """The largest distance between two of ``points`` ``(k, 3)``.

    A pair longer than ``d``, the distance from the point farthest from the centroid to the point farthest
    from it, has both ends farther than ``d - R`` from the centroid (``R`` the largest such distance): only
    those points are paired, each pair as ``|a|^2 + |b|^2 - 2 a.b`` about the centroid (a matrix product; a
    scan's 5,000-edge silhouette took a second as differences of every pair), each block of rows against
    the rows from its own on (memory: 512 k distances)."""
    if len(points) < 2:
        return 0.0
    p = points - points.mean(axis=0)
    square = np.einsum("ij,ij->i", p, p)
    far = p[np.argmax(square)]
    largest = float(((p - far) ** 2).sum(axis=1).max())
    radius = np.sqrt(square)
    # the bound's rounding: a point within 1e-9 R of it is kept
    kept = radius >= np.sqrt(largest) - radius.max() * (1.0 + 1e-9)
    p, square = p[kept], square[kept]
    for s in range(0, len(p), 512):
        block = square[s : s + 512, None] + square[None, s:] - 2.0 * (p[s : s + 512] @ p[s:].T)
        largest = max(largest, float(block.max()))
    return float(np.sqrt(largest))


def find_holes(
    vertices: np.ndarray, triangles: np.ndarray, *, _conn: Connectivity | None = None
) -> list[Hole]:
    """Every boundary loop of the mesh with its size and whether it is an outer border.

    A component's outer border is its longest loop when less than :data:`BORDER_FACING_AWAY` of the
    component's area faces away from or sideways to the loop (a scan's silhouette, a small island's
    rim); on a closed surface with holes, none is.

    Parameters
    ----------
    vertices : (n, 3) float64
    triangles : (m, 3) int64

    Returns
    -------
    list of Hole
        In the order of :func:`o3d_lsmesh.core.boundary.boundary_loops` (by smallest vertex index).

    Examples
    --------
    >>> import numpy as np
    >>> holes = find_holes(np.eye(3), np.array([[0, 1, 2]]))
    >>> holes[0].edges, holes[0].border  # a lone triangle: its loop is its border
    (3, True)
    """
    n = len(vertices)
    conn = Connectivity(triangles, n) if _conn is None else _conn
    loops = _loop_rows(triangles, n, conn)
    if not loops:
        return []
    edges = conn.edges.astype(np.int64)
    # components over the sorted edges: the upper triangle of the adjacency in CSR order (no second sort)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(edges[:, 0], minlength=n), out=indptr[1:])
    _, label = csgraph.connected_components(
        sp.csr_matrix((np.ones(len(edges)), edges[:, 1], indptr), shape=(n, n)), directed=False
    )
    perimeters = np.array(
        [np.linalg.norm(np.roll(vertices[lp], -1, axis=0) - vertices[lp], axis=1).sum() for lp, _ in loops]
    )
    components = np.array([label[loop[0]] for loop, _ in loops], dtype=np.int64)
    by_length = np.lexsort((-perimeters, components))  # the longest loop of each component first
    first = np.ones(len(loops), dtype=bool)
    first[1:] = components[by_length][1:] != components[by_length][:-1]
    longest = by_length[first]
    # each judged component's triangles against its longest loop's vector area: the area facing away
    judged = np.full(label.max() + 1, -1)
    judged[components[longest]] = longest
    tri_loop = judged[label[triangles[:, 0]]]
    mine = np.flatnonzero(tri_loop >= 0)
    loop_vector = np.zeros((len(loops), 3))
    for i in longest:
        p = vertices[loops[i][0]] - vertices[loops[i][0][0]]
        loop_vector[i] = _cross(p, np.roll(p, -1, axis=0)).sum(axis=0)
        loop_vector[i] /= max(float(np.sqrt((loop_vector[i] ** 2).sum())), 1e-300)
    facing_away = np.zeros(len(loops))
    total = np.zeros(len(loops))
    for start in range(0, len(mine), 65536):  # bounded memory on large meshes
        rows = mine[start : start + 65536]
        p = vertices[triangles[rows]]
        vector = 0.5 * _cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        size = np.sqrt((vector**2).sum(axis=1))
        away = (vector * loop_vector[tri_loop[rows]]).sum(axis=1) < SIDEWAYS * size
        total += np.bincount(tri_loop[rows], weights=size, minlength=len(loops))
        facing_away += np.bincount(tri_loop[rows], weights=np.where(away, size, 0.0), minlength=len(loops))
    border = np.zeros(len(loops), dtype=bool)
    border[longest] = facing_away[longest] < BORDER_FACING_AWAY * total[longest]
    diameters = [_diameter(vertices[loop]) for loop, _ in loops]  # loops come sorted by first vertex
    return [
        Hole(loop, len(loop), float(perimeters[i]), diameters[i], int(components[i]), bool(border[i]), rows)
        for i, (loop, rows) in enumerate(loops)
    ]


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``np.cross`` over the last axis of 3-vectors, without its axis juggling (it dominates small calls)."""
    shape = u.shape if u.shape == v.shape else np.broadcast_shapes(u.shape, v.shape)
    out = np.empty(shape)
    u0, u1, u2 = u[..., 0], u[..., 1], u[..., 2]
    v0, v1, v2 = v[..., 0], v[..., 1], v[..., 2]
    np.subtract(u1 * v2, u2 * v1, out=out[..., 0])
    np.subtract(u2 * v0, u0 * v2, out=out[..., 1])
    np.subtract(u0 * v1, u1 * v0, out=out[..., 2])
    return out
