"""A :class:`MeshHierarchy` from fast-simplification's QEM edge collapses.

``fast_simplification.simplify(..., return_collapses=True)`` decimates once to the coarsest level; each
level is the ``replay_simplification`` of a prefix of its collapses (whose vertex mapping accounts for
later merges too). The extension keeps module-global state: every call goes through one lock.
Docs: ``docs/algorithms/mesh_hierarchy.rst``.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .._o3d import read_mesh, tensor_format_of, warn_dropped_attributes
from ..core.connectivity import Connectivity, run_heads
from ..core.errors import InputError, InputTypeError
from ..core.progress import Progress
from ..core.validate import as_bool, as_count, as_positive_float, collapsed_triangles
from .hierarchy import MeshHierarchy

if TYPE_CHECKING:
    from .._types import AnyMesh

__all__ = ["from_fast_simplification"]

_LOCK = threading.Lock()


def _level_counts(levels: Any, n: int, min_vertices: int) -> np.ndarray:
    if isinstance(levels, (int, np.integer)) and not isinstance(levels, bool):
        # more levels than vertices could not be distinct: the limit also keeps the request's memory bounded
        count = as_count(levels, name="levels", minimum=1, maximum=max(n, 1))
        low = max(min(min_vertices, n - 1), 4)
        ratios = (low / n) ** (np.arange(1, count + 1) / count)
        counts = np.round(n * ratios).astype(np.int64)
    else:
        try:
            counts = np.asarray(levels)
        except Exception:  # ragged input
            counts = np.zeros(0, dtype=np.int64)
        # (a bool is a 0-d array here)
        if counts.ndim != 1 or counts.size == 0 or not np.issubdtype(counts.dtype, np.integer):
            raise InputTypeError(
                f"levels must be an integer or a sequence of integer vertex counts, got {levels!r}",
                param="levels",
            )
        counts = counts.astype(np.int64)
        if np.any(counts < 4) or np.any(counts >= n) or np.any(np.diff(counts) >= 0):
            raise InputError(
                f"levels must be strictly decreasing vertex counts in [4, {n}), got {counts.tolist()}",
                param="levels",
            )
    return counts[np.r_[True, np.diff(counts) < 0]]


def from_fast_simplification(
    mesh: AnyMesh,
    *,
    levels: int | Sequence[int] = 8,
    min_vertices: int = 100,
    agg: float = 7.0,
    progress: bool = False,
) -> MeshHierarchy:
    """Build a :class:`MeshHierarchy` from fast-simplification's quadric-error collapses.

    The structure of :func:`build_hierarchy`, but the collapses are neither independent nor checked for
    topology; levels stay edge-manifold and keep unreferenced vertices (rules:
    ``docs/algorithms/mesh_hierarchy.rst``). A level whose target is not reached is left out.

    Parameters
    ----------
    mesh : open3d.geometry.TriangleMesh, open3d.t.geometry.TriangleMesh or (vertices, triangles)
    levels : int or sequence of int, keyword-only
        Number of levels (vertex counts decreasing geometrically to ``min_vertices``), or the strictly
        decreasing target vertex counts.
    min_vertices, agg, progress : keyword-only
        The coarsest count for an integer ``levels``; fast-simplification's aggressiveness; a progress bar.

    Examples
    --------
    >>> import open3d as o3d
    >>> h = from_fast_simplification(o3d.geometry.TriangleMesh.create_sphere(resolution=20), levels=[400, 200])
    >>> [h.vertex_count(i) for i in range(len(h))]
    [762, 400, 200]
    """
    try:  # an extra: only this function uses it
        import fast_simplification
    except ImportError as error:
        raise ImportError(
            'from_fast_simplification needs fast-simplification: pip install "o3d_lsmesh[simplify]"'
        ) from error

    min_vertices = as_count(min_vertices, name="min_vertices", minimum=4)
    agg = as_positive_float(agg, name="agg", allow_zero=True)
    progress = as_bool(progress, name="progress")
    data = read_mesh(mesh)
    warn_dropped_attributes(data, "hierarchy levels have new connectivity", normals=True)
    V, F = data.vertices, data.triangles
    n0, m0 = len(V), len(F)
    if n0 < 5:
        # levels are vertex counts in [4, n): a mesh of four or fewer vertices has no coarser level
        raise InputError(f"mesh must have at least 5 vertices to be simplified, got {n0}", param="mesh")
    counts = _level_counts(levels, n0, min_vertices)

    target_triangles = max(int(m0 * counts[-1] / n0 * 0.95), 4)
    # fast-simplification merges unreferenced vertices too: it runs on the referenced ones only, and
    # the others are carried through every level as they are
    conn = Connectivity(F, n0)
    Fr, referenced = conn.submesh(np.arange(m0))
    # in a unit box about their centroid: the extension's error thresholds are absolute and its replay reads
    # single precision (at 1e8 no level was made; a million units from the origin, other levels)
    Vr = V[referenced] - V[referenced].mean(axis=0)
    Vr = np.ascontiguousarray(Vr / (np.ptp(Vr, axis=0).max() or 1.0))
    points32 = Vr.astype(np.float32)
    with _LOCK:
        _, _, collapses = fast_simplification.simplify(
            Vr, Fr.astype(np.int32), target_count=target_triangles, agg=float(agg), return_collapses=True
        )
        collapses = np.asarray(collapses, dtype=np.int32).reshape(-1, 2)
        mappings = []
        with Progress(progress, "fast-simplification levels").bar(len(counts), unit="level") as bar:
            for count in counts:
                bar.update(1)
                prefix = min(n0 - int(count), len(collapses))
                if prefix <= 0:
                    continue
                _, _, mapping = fast_simplification.replay_simplification(points32, Fr, collapses[:prefix])
                full = np.arange(n0, dtype=np.int64) + len(referenced)  # unreferenced: labels of their own
                full[referenced] = np.asarray(mapping, dtype=np.int64)
                mappings.append((prefix, full))
    collapses = referenced[collapses] if len(collapses) else collapses.astype(np.int64)

    n_components, component = conn.components
    empty = np.zeros(0, dtype=np.int64)
    # per level: triangles, representatives, parents, removed, targets, ring offsets, rings
    built: list[tuple[np.ndarray, ...]] = [
        (F, np.arange(n0, dtype=np.int64), empty, empty, empty, np.zeros(1, dtype=np.int64), empty)
    ]
    for prefix, mapping in mappings:
        previous, reps = built[-1][:2]
        n_prev = len(reps)
        # nesting by construction: a level-(i-1) vertex goes where its input representative goes;
        # a component whose triangles all collapsed is mapped anywhere by the replay: merges stay
        # within the input's components (else split vertices land on another component). The
        # inverse of np.unique numbers the level-i vertices 0..n_new-1.
        key = mapping[reps] * np.int64(n_components) + component[reps]
        parent = np.unique(key, return_inverse=True)[1].reshape(-1).astype(np.int64)
        n_new = int(parent.max()) + 1
        if n_new >= n_prev:
            continue
        # the kept child of each level-i vertex: one never collapsed in this prefix, else the first
        collapsed = np.zeros(n0, dtype=bool)
        collapsed[collapses[:prefix, 1]] = True
        order = np.lexsort((np.arange(n_prev), collapsed[reps], parent))
        keep = np.zeros(n_prev, dtype=bool)
        keep[order[run_heads(parent[order])]] = True
        # renumber level i in the order of its kept children, like the volume hierarchy
        renumber = np.empty(n_new, dtype=np.int64)
        renumber[parent[np.flatnonzero(keep)]] = np.arange(n_new)
        parent = renumber[parent]
        gone = np.flatnonzero(~keep)
        mapped = parent[previous]
        mapped = _drop_nonmanifold(
            _drop_duplicate_triangles(mapped[~collapsed_triangles(mapped)], n_new), n_new
        )
        rings = Connectivity(previous, n_prev).adjacency[gone]  # the removed vertices' 1-rings, CSR rows
        ring, ring_offsets = rings.indices.astype(np.int64), rings.indptr.astype(np.int64)
        built.append(
            (mapped, reps[keep], parent, gone, np.flatnonzero(keep)[parent[gone]], ring_offsets, ring)
        )
    tris, reps, parents, removed, targets, offsets, rings = zip(*built)
    kind = (False, "fast_simplification", data.kind, tensor_format_of(data))
    return MeshHierarchy(V, tris, reps, parents, removed, targets, offsets, rings, *kind)


def _drop_duplicate_triangles(triangles: np.ndarray, n: int) -> np.ndarray:
    """Keep the first of triangles over the same three vertices (sort-and-mask)."""
    if len(triangles) == 0:
        return triangles.astype(np.int64)
    s = np.sort(triangles, axis=1)
    keys = (s[:, 0] * np.int64(n) + s[:, 1]) * np.int64(n) + s[:, 2]
    order = np.argsort(keys, kind="stable")
    first = run_heads(keys[order])
    return np.ascontiguousarray(triangles[np.sort(order[first])], dtype=np.int64)


def _drop_nonmanifold(triangles: np.ndarray, n: int) -> np.ndarray:
    """Drop every triangle beyond the first two on an edge (QEM collapses can fold three onto one)."""
    conn = Connectivity(triangles, n)
    if not np.any(conn.edge_triangles > 2):
        return triangles
    inverse = conn.halfedge_edge
    m = len(triangles)
    tri = np.tile(np.arange(m), 3)
    order = np.lexsort((tri, inverse))
    start = run_heads(inverse[order])
    position = np.arange(len(order)) - np.maximum.accumulate(np.where(start, np.arange(len(order)), 0))
    drop = np.zeros(m, dtype=bool)
    drop[tri[order[position >= 2]]] = True
    return np.ascontiguousarray(triangles[~drop])
