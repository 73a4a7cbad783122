"""Connectivity against plain walks over triangles and edges (hypothesis soups and hand meshes)."""

from __future__ import annotations

import pickle
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from conftest import grid, triangle_soups
from defect_meshes import DEFECTS, all_defects
from hypothesis import given, settings
from hypothesis import strategies as st

from o3d_lsmesh._scan_kernel import edge_groups, ring_slots
from o3d_lsmesh.core.connectivity import Connectivity, halfedges, ring_pattern


def plain_edges(triangles):
    """{(lo, hi): [half-edge rows]} walking triangle by triangle (row q * m + t is edge q of t)."""
    m = len(triangles)
    edges = {}
    for t, tri in enumerate(triangles):
        for q in range(3):
            a, b = tri[q], tri[(q + 1) % 3]
            edges.setdefault((min(a, b), max(a, b)), []).append(q * m + t)
    return edges


def plain_neighbours(triangles, n):
    ring = [set() for _ in range(n)]
    for tri in triangles:
        for a in tri:
            ring[a] |= {b for b in tri if b != a}
    return ring


@settings(max_examples=100, deadline=None)
@given(triangle_soups())
def test_edges_valence_and_incidence_match_plain_walks(soup):
    n, triangles = soup
    c = Connectivity(np.array(triangles, dtype=np.int64), n)
    edges = plain_edges(triangles)
    keys = sorted(edges)
    assert c.edges.tolist() == [list(k) for k in keys]
    assert c.edge_triangles.tolist() == [len(edges[k]) for k in keys]
    for k, key in enumerate(keys):
        assert all(c.halfedge_edge[row] == k for row in edges[key])
    assert c.boundary_edges.tolist() == [len(edges[k]) == 1 for k in keys]
    ring = plain_neighbours(triangles, n)
    assert c.valence.tolist() == [len(r) for r in ring]
    on_rim, edge_valence = c.rim
    assert on_rim.tolist() == [any(v in k for k in keys if len(edges[k]) == 1) for v in range(n)]
    assert edge_valence.tolist() == [len(r) for r in ring]
    assert not (on_rim.flags.writeable or edge_valence.flags.writeable)  # shared by a call's steps
    indptr, triangle = c.vertex_triangles
    for v in range(n):
        corners = [t for t, tri in enumerate(triangles) for a in tri if a == v]
        assert triangle[indptr[v] : indptr[v + 1]].tolist() == corners
    assert [set(c.adjacency[v].indices.tolist()) for v in range(n)] == ring
    rpi, rpx = c.ring_pattern[:2]
    assert [rpx[rpi[v] : rpi[v + 1]].tolist() for v in range(n)] == [
        sorted(r | {v}) for v, r in enumerate(ring)
    ]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(*[st.integers(0, 6)] * 3), min_size=1, max_size=12))
def test_adjacency_keeps_a_repeated_corners_self_loop(triangles):
    # any triangles, a vertex repeated in some: each corner's other two corners are its neighbours
    ring = [set() for _ in range(7)]
    for tri in triangles:
        for p in range(3):
            ring[tri[p]] |= {tri[q] for q in range(3) if q != p}
    adjacency = Connectivity(np.array(triangles), 7).adjacency
    assert [set(adjacency[v].indices.tolist()) for v in range(7)] == ring
    assert adjacency.has_sorted_indices and np.all(adjacency.data == 1.0)


@settings(max_examples=100, deadline=None)
@given(triangle_soups())
def test_components_and_k_rings_match_a_breadth_first_walk(soup):
    n, triangles = soup
    c = Connectivity(np.array(triangles, dtype=np.int64), n)
    ring = plain_neighbours(triangles, n)
    label = [-1] * n
    count = 0
    for s in range(n):
        if label[s] < 0:
            stack, label[s] = [s], count
            while stack:
                for w in ring[stack.pop()]:
                    if label[w] < 0:
                        label[w] = count
                        stack.append(w)
            count += 1
    got_count, got = c.components
    assert got_count == count
    assert len({(a, b) for a, b in zip(label, got.tolist())}) == count  # the same partition
    for k in (0, 1, 2):
        reached = {0} if n else set()
        for _ in range(k):
            reached |= {w for v in reached for w in ring[v]}
        assert c.k_rings([0] if n else [], k).tolist() == sorted(reached)


@settings(max_examples=60, deadline=None)
@given(triangle_soups())
def test_face_adjacency_pairs_the_triangles_of_every_edge(soup):
    n, triangles = soup
    c = Connectivity(np.array(triangles, dtype=np.int64), n)
    fa = c.face_adjacency
    m = len(triangles)
    expected = []
    for k, rows in enumerate(plain_edges(triangles)[key] for key in sorted(plain_edges(triangles))):
        faces = sorted(rows)
        expected += [(faces[i] % m, faces[i + 1] % m, k) for i in range(len(faces) - 1)]
    got = [(a, b, e) for (a, b), e in zip(fa.pairs.tolist(), fa.pair_edge.tolist())]
    assert got == expected
    for t in range(m):
        share = sorted(u for u in range(m) if set(triangles[t]) & set(triangles[u]))
        assert fa.ring[t].indices.tolist() == share


def test_submesh_renumbers_the_chosen_triangles():
    V, F = grid(5, 5)
    c = Connectivity(F, len(V))
    chosen = np.array([3, 7, 8, 20])
    local, vertices = c.submesh(chosen)
    assert np.array_equal(vertices[local], F[chosen])
    assert vertices.tolist() == sorted(set(F[chosen].ravel().tolist()))


def test_pickles_and_reads_from_threads():
    V, F = grid(30, 30)
    c = Connectivity(F, len(V))
    with ThreadPoolExecutor(4) as pool:
        valences = list(pool.map(lambda _: c.valence, range(8)))
    assert all(np.array_equal(v, valences[0]) for v in valences)
    back = pickle.loads(pickle.dumps(c))
    assert np.array_equal(back.valence, c.valence) and np.array_equal(back.edges, c.edges) and back.n == c.n


def test_empty_mesh():
    c = Connectivity(np.zeros((0, 3), dtype=np.int64), 3)
    assert len(c.edges) == 0 and c.valence.tolist() == [0, 0, 0] and c.components[0] == 3


@settings(max_examples=80, deadline=None)
@given(triangle_soups(), st.sampled_from([2, 1 << 14]))
def test_ring_slots_hold_the_triangles_of_their_edge(soup, block):
    # every slot (v, w) of the 1-ring pattern names triangles on the edge {v, w}: its two entries are
    # the edge's two triangles, its one entry twice, or two of three and more; the diagonal 6 m
    from o3d_lsmesh.core.connectivity import RING_COLUMN_SLOT, RING_ROW_SLOT, _vertex_rings

    n, triangles = soup
    F = np.array(triangles, dtype=np.int64)
    m = len(F)
    rings = _vertex_rings(F, n, block)
    entries = {}
    for t, tri in enumerate(triangles):
        for d, (a, b) in enumerate(zip(RING_ROW_SLOT, RING_COLUMN_SLOT)):
            entries.setdefault((tri[a], tri[b]), []).append(d * m + t)
    ring = plain_neighbours(triangles, n)
    for v in range(n):
        row = range(rings.indptr[v], rings.indptr[v + 1])
        assert rings.indices[row.start : row.stop].tolist() == sorted(ring[v] | {v})
        assert rings.indices[rings.diagonal[v]] == v and rings.valence[v] == len(ring[v])
        for slot in row:
            w = int(rings.indices[slot])
            first, second = rings.pairs[:, slot].tolist()
            if w == v:
                assert first == second == 6 * m
                continue
            on_edge = entries[(v, w)]
            assert first in on_edge and second in on_edge
            assert (first == second) == (len(on_edge) == 1)
        on_odd_edge = any(len(entries[(v, w)]) != 2 for w in ring[v])
        assert rings.boundary[v] == on_odd_edge


def plain_edge_groups(lo, hi):
    """The half-edges in (lo, hi, row) order by a plain sort, and their runs of one edge: (order, starts, counts, edges)."""
    order = sorted(range(len(lo)), key=lambda i: (lo[i], hi[i], i))
    starts = [
        s
        for s in range(len(order))
        if s == 0 or (lo[order[s]], hi[order[s]]) != (lo[order[s - 1]], hi[order[s - 1]])
    ]
    counts = [b - a for a, b in zip(starts, starts[1:] + [len(order)])]
    return order, starts, counts, [[lo[order[s]], hi[order[s]]] for s in starts]


@settings(max_examples=60, deadline=None)
@given(triangle_soups(), st.sampled_from([np.int32, np.int64]))
def test_edge_groups_against_a_plain_sort(soup, dtype):
    n, triangles = soup
    pairs = np.sort(halfedges(np.array(triangles, dtype=np.int64).reshape(-1, 3)), axis=1).astype(dtype)
    lo, hi = np.ascontiguousarray(pairs[:, 0]), np.ascontiguousarray(pairs[:, 1])
    got = edge_groups(lo, hi, n)
    assert [part.tolist() for part in got] == list(plain_edge_groups(lo.tolist(), hi.tolist()))
    assert all(part.dtype == dtype for part in got)


@pytest.mark.parametrize("name", [*DEFECTS, "all"])
def test_edge_groups_on_raw_scan_defects(name):
    vertices, triangles = (all_defects() if name == "all" else DEFECTS[name]())[:2]
    pairs = np.sort(halfedges(triangles), axis=1).astype(np.int32)
    lo, hi = np.ascontiguousarray(pairs[:, 0]), np.ascontiguousarray(pairs[:, 1])
    got = edge_groups(lo, hi, len(vertices))
    assert [part.tolist() for part in got] == list(plain_edge_groups(lo.tolist(), hi.tolist()))
    es = Connectivity(triangles, len(vertices)).edge_structure
    assert [es.order.tolist(), es.starts.tolist(), es.counts.tolist(), es.edges.tolist()] == [
        part.tolist() for part in got
    ]


def test_edge_groups_refuses_arrays_it_would_index_out_of_bounds():
    lo, hi = np.array([0, 1], dtype=np.int32), np.array([1, 2], dtype=np.int32)
    with pytest.raises(ValueError, match="hi must have as many entries as lo"):
        edge_groups(lo, hi[:1], 3)
    with pytest.raises(ValueError, match="lo and hi must lie in 0..1"):
        edge_groups(lo, hi, 2)
    with pytest.raises(ValueError, match="lo and hi must lie in 0..2"):
        edge_groups(np.array([-1, 0], dtype=np.int32), hi, 3)
    with pytest.raises(ValueError, match="n must be at least 0"):
        edge_groups(lo[:0], hi[:0], -1)


def plain_ring_slots(edges, n):
    """Row by row: the edges ending at v (in edge order), v, the edges starting at v; each edge's two slots."""
    rows, diagonal, forward, backward = [], [], [0] * len(edges), [0] * len(edges)
    for v in range(n):
        before = [t for t, (lo, hi) in enumerate(edges) if hi == v]
        after = [t for t, (lo, hi) in enumerate(edges) if lo == v]
        start = sum(len(r) for r in rows)
        for k, t in enumerate(before):
            backward[t] = start + k
        diagonal.append(start + len(before))
        for k, t in enumerate(after):
            forward[t] = start + len(before) + 1 + k
        rows.append([edges[t][0] for t in before] + [v] + [edges[t][1] for t in after])
    indptr = np.cumsum([0] + [len(r) for r in rows]).tolist()
    return indptr, [c for r in rows for c in r], diagonal, forward, backward


@settings(max_examples=60, deadline=None)
@given(triangle_soups())
def test_ring_pattern_against_plain_rows(soup):
    n, triangles = soup
    c = Connectivity(np.array(triangles, dtype=np.int64).reshape(-1, 3), n)
    got = ring_pattern(c.edges, n)
    assert [part.tolist() for part in got] == list(plain_ring_slots(c.edges.tolist(), n))
    assert got[0].dtype == np.int32


@pytest.mark.parametrize("name", [*DEFECTS, "all"])
def test_ring_pattern_on_raw_scan_defects(name):
    vertices, triangles = (all_defects() if name == "all" else DEFECTS[name]())[:2]
    c = Connectivity(triangles, len(vertices))
    for edges in (c.edges, c.edges.astype(np.int64), c.edges.astype(np.int16)):
        got = ring_pattern(edges, len(vertices))
        assert [part.tolist() for part in got] == list(plain_ring_slots(c.edges.tolist(), len(vertices)))


def test_ring_slots_refuses_arrays_of_another_shape():
    edges = np.array([[0, 1], [0, 2], [1, 2]], dtype=np.int32)
    parts = [np.zeros(k, dtype=np.int64) for k in (4, 9, 3, 3, 3)]  # n = 3
    ring_slots(edges, *parts)
    assert parts[1].tolist() == [0, 1, 2, 0, 1, 2, 0, 1, 2]
    with pytest.raises(ValueError, match="edges must have 2 columns"):
        ring_slots(np.zeros((3, 3), dtype=np.int32), *parts)
    with pytest.raises(ValueError, match="diagonal and indices must have 3 and 9"):
        ring_slots(edges, parts[0], parts[1][:8], *parts[2:])
    with pytest.raises(ValueError, match="forward and backward must have 3"):
        ring_slots(edges, *parts[:4], parts[4][:2])
    with pytest.raises(ValueError, match="edges must name vertices in 0..2"):
        ring_slots(np.array([[0, 1], [0, 3], [1, 2]], dtype=np.int32), *parts)
