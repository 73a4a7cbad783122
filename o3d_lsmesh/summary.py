"""What a scan user wants to know about a mesh's connectivity, on any mesh: :func:`topology_summary`."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from ._o3d import read_mesh, weld_map, welded_triangles
from .core.boundary import boundary_curves, boundary_halfedges, boundary_rows, corner_fans
from .core.connectivity import Connectivity
from .core.validate import mesh_arrays

if TYPE_CHECKING:
    from ._types import AnyMesh

__all__ = ["HOLE_SIZE_BINS", "topology_summary", "topology_summary_arrays"]

#: Edge-count bins of ``holes_by_size``: a loop of ``k`` edges falls in the bin ``lo <= k <= hi``.
HOLE_SIZE_BINS = ((3, 3), (4, 9), (10, 99), (100, 999), (1000, None))

#: A triangle is degenerate when twice its area is at most this times its longest edge squared
#: (an angle below about 1e-10 rad: collinear or coincident corners up to rounding).
DEGENERATE_TOLERANCE = 1e-10


def topology_summary_arrays(vertices: np.ndarray, triangles: np.ndarray) -> dict:
    """Array core of :func:`topology_summary` (``(n, 3) float64`` vertices, ``(m, 3) int64`` triangles)."""
    return _summary(*mesh_arrays(vertices, triangles))


def _summary(vertices: np.ndarray, F: np.ndarray) -> dict:
    n, m = len(vertices), len(F)
    referenced = np.zeros(n, dtype=bool)
    referenced[F.ravel()] = True
    conn = Connectivity(F, n)
    runs = conn.edge_structure.runs
    order, starts, counts = runs
    edge_count = len(counts)
    crowded_edges = int(np.count_nonzero(counts > 2))
    # fans: corners linked through manifold edges; a vertex with several is non-manifold
    fan_count, fan = corner_fans(F, n, runs)
    tail = F.T.reshape(-1)
    vertex_of_fan = np.zeros(fan_count, dtype=np.int64)
    vertex_of_fan[fan] = tail
    fans_per_vertex = np.bincount(vertex_of_fan, minlength=n)
    nonmanifold_vertex_count = int(np.count_nonzero(fans_per_vertex > 1))
    # components over vertices (what Open3D's cluster_connected_triangles would join at a shared vertex)
    _, labels = conn.components
    components = len(np.unique(labels[referenced]))
    # surface pieces: triangles joined through edges of exactly two triangles (a pinch or fin separates)
    pair = starts[counts == 2]
    a, b = order[pair] % m, order[pair + 1] % m  # (mesh_arrays refuses a mesh without triangles)
    graph = sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(m, m))
    pieces = csgraph.connected_components(graph, directed=False)[0]
    # a manifold edge run twice in the same direction: the two triangles disagree in orientation
    misoriented = int(np.count_nonzero(tail[order[pair]] == tail[order[pair + 1]]))
    # boundary
    rows, _, head, _ = boundary_rows(F, n, runs)
    boundary_edges = len(rows)
    curves = boundary_curves(F, n, conn=conn)
    loop_edges = np.array([len(loop) for loop in curves.loops], dtype=np.int64)
    holes = {}
    for lo, hi in HOLE_SIZE_BINS:
        inside = (loop_edges >= lo) & (loop_edges <= (np.iinfo(np.int64).max if hi is None else hi))
        label = f"{lo}+" if hi is None else (str(lo) if lo == hi else f"{lo}-{hi}")
        holes[label] = int(np.count_nonzero(inside))
    graph = sp.coo_matrix((np.ones(boundary_edges), (tail[rows], head[rows])), shape=(n, n))
    boundary_label = csgraph.connected_components(graph, directed=False)[1]
    boundary_components = len(np.unique(boundary_label[tail[rows]]))
    # UV seams and normal creases as Open3D's readers split them: boundary edges that vertices at equal
    # coordinates close (fill_holes and the fairing functions work on that welded surface, without the
    # triangles that lose a corner so)
    split = weld_map(vertices, F)
    seam_edges = (
        0 if split is None else boundary_edges - len(boundary_halfedges(welded_triangles(split, F)[0], n))
    )
    # degenerate triangles: (near) zero area relative to the longest edge
    corners = vertices[F]
    sides = corners[:, [1, 2, 0]] - corners
    twice_area = np.linalg.norm(np.cross(sides[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    longest = np.einsum("ijk,ijk->ij", sides, sides).max(axis=1)
    degenerate = int(np.count_nonzero(twice_area <= DEGENERATE_TOLERANCE * longest))
    sorted_triangles = np.sort(F, axis=1)
    if n**3 < 2**62:  # one packed key per triangle: a plain sort
        keys = (sorted_triangles[:, 0] * n + sorted_triangles[:, 1]) * n + sorted_triangles[:, 2]
        keys.sort()
        duplicate = int(np.count_nonzero(keys[1:] == keys[:-1]))
    else:  # rows in lexicographic order, equal neighbours
        sorted_triangles = sorted_triangles[np.lexsort(sorted_triangles.T[::-1])]
        duplicate = int(np.count_nonzero((sorted_triangles[1:] == sorted_triangles[:-1]).all(axis=1)))
    chi = int(np.count_nonzero(referenced)) - edge_count + m
    edge_manifold = crowded_edges == 0
    vertex_manifold = edge_manifold and nonmanifold_vertex_count == 0
    loops = len(curves.loops)
    genus = (2 - chi - loops) // 2 if components == 1 and vertex_manifold else None
    # total genus of the surface with every non-manifold vertex split into its fans (an oriented
    # surface of `pieces` parts, each sum (2 - 2 g - b) = V' - E + F)
    total_genus = None
    if edge_manifold and misoriented == 0:
        split_chi = fan_count - edge_count + m
        total_genus = (2 * pieces - split_chi - loops) // 2
    return {
        "vertices": n,
        "triangles": m,
        "edge_manifold": edge_manifold,
        "vertex_manifold": vertex_manifold,
        "components": components,
        "surface_pieces": int(pieces),
        "boundary_loops": loops,
        "boundary_components": boundary_components,
        "boundary_edges": boundary_edges,
        "seam_edges": seam_edges,
        "open_boundary_chains": len(curves.chains),
        "holes_by_size": holes,
        "largest_hole_edges": int(loop_edges.max()) if len(loop_edges) else 0,
        "nonmanifold_edges": crowded_edges,
        "nonmanifold_vertices": nonmanifold_vertex_count,
        "unreferenced_vertices": int(n - np.count_nonzero(referenced)),
        "degenerate_triangles": degenerate,
        "duplicate_triangles": int(duplicate),
        "misoriented_edges": misoriented,
        "euler": chi,
        "genus": genus,
        "total_genus": total_genus,
    }


def topology_summary(mesh: AnyMesh) -> dict:
    """Connectivity facts of any mesh, raw scans included: the numbers a scan user checks.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)

    Returns
    -------
    dict
        ``vertices``, ``triangles``, ``edge_manifold``, ``vertex_manifold``, ``components``,
        ``surface_pieces``, ``boundary_loops``, ``boundary_components``, ``boundary_edges``,
        ``seam_edges``, ``open_boundary_chains``, ``holes_by_size``, ``largest_hole_edges``,
        ``nonmanifold_edges``, ``nonmanifold_vertices``, ``unreferenced_vertices``,
        ``degenerate_triangles``, ``duplicate_triangles``, ``misoriented_edges``, ``euler``, ``genus``,
        ``total_genus``: each defined in ``docs/algorithms/connectivity.rst``.

    Examples
    --------
    >>> import numpy as np
    >>> bowtie = np.array([[0, 1, 2], [0, 3, 4]])  # two triangles touching at vertex 0
    >>> s = topology_summary((np.random.default_rng(0).random((5, 3)), bowtie))
    >>> s["boundary_loops"], s["boundary_components"], s["nonmanifold_vertices"], s["total_genus"]
    (2, 1, 1, 0)
    """
    data = read_mesh(mesh)  # validated once
    summary = _summary(data.vertices, data.triangles)
    if data.split_triangles is not None:  # triangles repeating a vertex, left out of the analysis: degenerate
        left_out = len(data.split_triangles) - len(data.triangles)
        summary["triangles"] += left_out
        summary["degenerate_triangles"] += left_out
    return summary
