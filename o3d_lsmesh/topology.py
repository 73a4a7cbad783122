"""Moved to :mod:`o3d_lsmesh.core.connectivity` and :mod:`o3d_lsmesh.core.boundary` (silent re-export)."""

import numpy as np

from .core.arrays import _runs, gather, run_heads
from .core.boundary import (
    BoundaryCurves,
    boundary_chains,
    boundary_curves,
    boundary_halfedges,
    boundary_loops,
    boundary_rows,
    corner_fans,
    nonmanifold_edges,
    nonmanifold_vertices,
)
from .core.connectivity import (
    _RING_BLOCK,
    RING_COLUMN_SLOT,
    RING_ROW_SLOT,
    Connectivity,
    EdgeStructure,
    VertexRings,
    _vertex_rings,
    halfedges,
    ring_pattern,
)

# the former free builders: each is a part of Connectivity now (core/connectivity.py)


def edge_structure(triangles, n=None) -> EdgeStructure:
    return Connectivity(triangles, n).edge_structure


def edge_runs(triangles, n):
    return edge_structure(triangles, n).runs


def unique_edges_and_runs(triangles, n=None):
    es = edge_structure(triangles, n)
    return (es.edges.astype(np.int64), es.counts.astype(np.int64), es.inverse.astype(np.int64)), es.runs


def unique_edges(triangles, n=None):
    return unique_edges_and_runs(triangles, n)[0]


def vertex_rings(triangles, n, *, block=_RING_BLOCK) -> VertexRings:
    return _vertex_rings(np.asarray(triangles), n, block)


def adjacency_matrix(triangles, n):
    return Connectivity(triangles, n).adjacency


def connected_components(triangles, n):
    return Connectivity(triangles, n).components


def group_keys(keys, bound):
    order = np.argsort(keys, kind="stable")
    _, starts, counts = _runs(keys[order])
    inverse = np.empty(len(keys), dtype=np.int64)
    inverse[order] = np.repeat(np.arange(len(starts), dtype=np.int64), counts)
    return order, starts, counts, inverse


def directed_edges(triangles, n):
    _ = Connectivity(np.zeros((0, 3), dtype=np.int64), n).adjacency  # the same refusal of 2**31 vertices
    half = halfedges(np.asarray(triangles, dtype=np.int64))
    both = np.concatenate([half, half[:, ::-1]])
    keys, count = np.unique(both[:, 0] * n + both[:, 1], return_counts=True)
    return keys // n, keys % n, count


__all__ = [
    "RING_COLUMN_SLOT",
    "RING_ROW_SLOT",
    "BoundaryCurves",
    "Connectivity",
    "EdgeStructure",
    "VertexRings",
    "adjacency_matrix",
    "boundary_chains",
    "boundary_curves",
    "boundary_halfedges",
    "boundary_loops",
    "boundary_rows",
    "connected_components",
    "corner_fans",
    "directed_edges",
    "edge_runs",
    "edge_structure",
    "gather",
    "group_keys",
    "halfedges",
    "nonmanifold_edges",
    "nonmanifold_vertices",
    "ring_pattern",
    "run_heads",
    "unique_edges",
    "unique_edges_and_runs",
    "vertex_rings",
]
