"""Every builder of core.operators against an independent reference: plain loops over triangles or edges."""

import numpy as np
import open3d as o3d
import pytest
import scipy.sparse as sp
from conftest import grid, triangle_soups
from hypothesis import given, settings
from hypothesis import strategies as st

from o3d_lsmesh import laplacian
from o3d_lsmesh.core import liu
from o3d_lsmesh.core import operators as ops
from o3d_lsmesh.core.connectivity import Connectivity


def uniform_laplacian(triangles, n):
    return ops.uniform_laplacian(Connectivity(triangles, n))


def cotangent_laplacian(vertices, triangles):
    return ops.cotangent_laplacian(vertices, Connectivity(triangles, len(vertices)))


def plain_neighbours(triangles, n):
    neighbours = [set() for _ in range(n)]
    for tri in np.asarray(triangles).tolist():
        for a in tri:
            neighbours[a] |= {b for b in tri if b != a}
    return neighbours


def reference_uniform(triangles, n):
    neighbours = [set() for _ in range(n)]
    for a, b, c in triangles.tolist():
        for i, j in ((a, b), (b, c), (c, a)):
            neighbours[i].add(j)
            neighbours[j].add(i)
    L = np.zeros((n, n))
    for i, ring in enumerate(neighbours):
        if ring:
            L[i, i] = 1.0
            for j in ring:
                L[i, j] = -1.0 / len(ring)
    return L


def test_uniform_matches_plain_loop_and_eq1(sphere):
    V, F = np.asarray(sphere.vertices), np.asarray(sphere.triangles)
    L = laplacian(sphere)
    assert sp.isspmatrix_csr(L)
    np.testing.assert_allclose(L.toarray(), reference_uniform(F, len(V)), atol=1e-15)
    np.testing.assert_allclose(L @ np.ones(len(V)), 0, atol=1e-14)


def test_sign_convention_vertex_minus_average():
    V, F = grid(3, 3)
    V[4, 2] = 1.0  # lift the centre of the grid
    L = uniform_laplacian(F, len(V))
    assert (L @ V)[4, 2] == pytest.approx(1.0)


def test_isolated_vertex_row_is_zero():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5.0]])
    L = uniform_laplacian(np.array([[0, 1, 2]]), 4)
    assert np.all(L.toarray()[3] == 0)
    # an isolated vertex is a fixed point of smoothing: its Laplacian is zero wherever it sits
    assert np.all((L @ V)[3] == 0) and np.any((L @ V)[:3] != 0)


def test_cotangent_reproduces_linear_functions_inside_flat_grid():
    V, F = grid(7, 7)
    rng = np.random.default_rng(0)
    V[:, :2] += rng.normal(scale=0.02, size=(len(V), 2))
    L = laplacian((V, F), kind="cotangent")
    interior = np.flatnonzero((np.abs(V[:, 0] - 0.5) < 0.4) & (np.abs(V[:, 1] - 0.5) < 0.4))
    # cotangent weights have linear precision on flat meshes; uniform weights do not
    np.testing.assert_allclose((L @ V)[interior], 0, atol=1e-12)
    assert np.abs((laplacian((V, F)) @ V)[interior]).max() > 1e-4
    np.testing.assert_allclose(L @ np.ones(len(V)), 0, atol=1e-12)


def test_cotangent_degenerate_triangle_stays_finite():
    V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 1, 0.0]])
    F = np.array([[0, 1, 3], [1, 2, 3], [0, 2, 1]])
    L = cotangent_laplacian(V, F)
    assert np.all(np.isfinite(L.toarray()))


def test_cotangent_rows_it_cannot_normalize_take_uniform_weights():
    # a collinear sliver beside a grid: at its end vertices the clamped cotangents (+1e4 for the zero
    # angle, -1e4 for the straight one) cancel, a row with no weight to normalize by
    G, FG = grid(4, 4)
    sliver = np.array([[0, 0, 4.0], [1, 0, 4], [2, 0, 4]])
    V = np.vstack([G, sliver])
    F = np.vstack([FG, [[16, 17, 18]]])
    L = cotangent_laplacian(V, F).toarray()
    uniform = reference_uniform(F, len(V))
    for i in (16, 18):  # both ends: the average of their two neighbours, as the uniform Laplacian
        np.testing.assert_allclose(L[i], uniform[i], atol=1e-15)
    # every referenced vertex keeps a row that averages its neighbours: 1 on the diagonal, rows sum to 0
    np.testing.assert_allclose(np.diag(L), 1.0, atol=1e-15)
    np.testing.assert_allclose(L.sum(axis=1), 0.0, atol=1e-12)
    # the rest is the grid's own cotangent Laplacian, untouched by the fallback
    np.testing.assert_allclose(L[:16, :16], cotangent_laplacian(G, FG).toarray(), atol=1e-15)


def test_kind_is_validated(sphere):
    with pytest.raises(ValueError, match="kind must be one of"):
        laplacian(sphere, kind="robust")
    with pytest.raises(TypeError, match="mesh must be"):
        laplacian(np.zeros((3, 3)))


def test_tensor_mesh_gives_same_operator(sphere):
    tmesh = o3d.t.geometry.TriangleMesh.from_legacy(sphere)
    assert abs(laplacian(tmesh) - laplacian(sphere)).max() < 1e-12


@settings(max_examples=60, deadline=None)
@given(triangle_soups())
def test_uniform_is_canonical_and_matches_loop_on_any_triangle_soup(case):
    # non-manifold edges, mixed orientations, repeated triangles and unreferenced vertices included
    n, triangles = case
    F = np.array(triangles, dtype=np.int64)
    L = uniform_laplacian(F, n)
    np.testing.assert_allclose(L.toarray(), reference_uniform(F, n), atol=1e-15)
    canonical = L.copy()
    canonical.sum_duplicates()
    canonical.sort_indices()
    assert np.array_equal(L.indices, canonical.indices) and np.array_equal(L.indptr, canonical.indptr)


@settings(max_examples=60, deadline=None)
@given(triangle_soups(), st.integers(0, 2**32 - 1))
def test_cotangent_matches_a_loop_over_triangles(case, seed):
    n, triangles = case
    F = np.array(triangles, dtype=np.int64)
    V = np.random.default_rng(seed).normal(size=(n, 3))
    W = np.zeros((n, n))
    for tri in triangles:
        for p in range(3):  # the angle at corner p weighs the opposite edge
            a, b = V[tri[(p + 1) % 3]] - V[tri[p]], V[tri[(p + 2) % 3]] - V[tri[p]]
            cot = np.clip(np.dot(a, b) / np.linalg.norm(np.cross(a, b)), -1e4, 1e4)
            i, j = tri[(p + 1) % 3], tri[(p + 2) % 3]
            W[i, j] += 0.5 * cot
            W[j, i] += 0.5 * cot
    expected = np.zeros((n, n))
    for i, ring in enumerate(plain_neighbours(F, n)):
        row = (
            W[i] if W[i].sum() > 1e-12 * max(1.0, np.abs(W).sum() / n) else np.isin(np.arange(n), list(ring))
        )
        if row.sum() > 0:
            expected[i] = -row / row.sum()
            expected[i, i] += 1.0
    np.testing.assert_allclose(cotangent_laplacian(V, F).toarray(), expected, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(triangle_soups())
def test_graph_laplacian_is_degree_minus_adjacency(case):
    n, triangles = case
    expected = np.zeros((n, n))
    for i, ring in enumerate(plain_neighbours(triangles, n)):
        expected[i, i] = len(ring)
        expected[i, list(ring)] = -1.0
    L = ops.graph_laplacian(Connectivity(np.array(triangles), n))
    assert sp.isspmatrix_csc(L) and np.array_equal(L.toarray(), expected)


@settings(max_examples=40, deadline=None)
@given(triangle_soups(), st.integers(0, 2**32 - 1))
def test_umbrellas_match_plain_means_of_the_rings(case, seed):
    n, triangles = case
    F = np.array(triangles, dtype=np.int64)
    V = np.random.default_rng(seed).normal(size=(n, 3))
    c = Connectivity(F, n)
    ring = plain_neighbours(F, n)
    mask = np.array([len(r) > 0 for r in ring])
    expected = [V[sorted(ring[i])].mean(axis=0) - V[i] for i in np.flatnonzero(mask)]
    np.testing.assert_allclose(ops.umbrella(V, c.edges, mask), np.reshape(expected, (-1, 3)), atol=1e-12)
    rows = np.flatnonzero(mask)[::-1]  # any order, a row twice
    rows = np.r_[rows, rows[:1]]
    values = np.random.default_rng(seed + 1).normal(size=(n, 4))
    counts, sums = ops.two_ring_sums(c.adjacency, rows, values)
    for k, i in enumerate(rows):
        reach = sorted((set(ring[i]) | {w for v in ring[i] for w in ring[v]}) - {i})
        assert counts[k] == len(reach)
        np.testing.assert_allclose(sums[k], values[reach].sum(axis=0), rtol=1e-12, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(triangle_soups())
def test_umbrella_weights_average_the_rim_on_the_rim_and_the_ring_inside(case):
    n, triangles = case
    F = np.array(triangles, dtype=np.int64)
    c = Connectivity(F, n)
    count = {}
    for tri in triangles:
        for q in range(3):
            key = tuple(sorted((tri[q], tri[(q + 1) % 3])))
            count[key] = count.get(key, 0) + 1
    rim = [
        {b for (a, b) in count if a == v and count[(a, b)] == 1}
        | {a for (a, b) in count if b == v and count[(a, b)] == 1}
        for v in range(n)
    ]
    W, _, on_boundary = ops.umbrella_weights(c.rings)
    expected = np.zeros((n, n))
    for v, ring in enumerate(plain_neighbours(F, n)):
        chosen = rim[v] if rim[v] else ring
        expected[v, list(chosen)] = 1.0 / len(chosen) if chosen else 0.0
    np.testing.assert_allclose(W.toarray(), expected, atol=1e-15)
    assert (on_boundary is None) == (not any(rim)) and (
        on_boundary is None or on_boundary.tolist() == [bool(r) for r in rim]
    )
    movable = np.arange(n) % 2 == 0
    pattern = [part.copy() for part in c.ring_pattern]
    N = ops.rim_neighbours(c, movable).toarray()
    assert all(np.array_equal(a, b) for a, b in zip(c.ring_pattern, pattern))  # the cached pattern kept
    for v in range(n):
        expected_row = (rim[v] if rim[v] else plain_neighbours(F, n)[v]) if movable[v] else set()
        assert set(np.flatnonzero(N[v]).tolist()) == expected_row


def _local_reference(F, n, X, X0):
    """One step of Liu's local operator written per triangle: eq. 6 solved as a least-squares problem
    on the constraint's null space, then each vertex averages its interior triangles' estimates."""
    ring = plain_neighbours(F, n)
    edge_count = {}
    for tri in F.tolist():
        for q in range(3):
            key = frozenset((tri[q], tri[(q + 1) % 3]))
            edge_count[key] = edge_count.get(key, 0) + 1
    boundary = {v for key, c in edge_count.items() if c != 2 for v in key}
    sums, counts = np.zeros((n, 3)), np.zeros(n)
    basis = np.array([[1.0, 0.0], [-1.0, 1.0], [0.0, -1.0]])  # B basis = 0 for B = [1, 1, 1]
    for tri in F.tolist():
        if boundary & set(tri):
            continue
        A = np.zeros((3, 3))
        Q = np.zeros((3, 3))
        for a in range(3):
            v = tri[a]
            A[a, a] = 1.0
            for b in range(3):
                if b != a:
                    A[a, b] = -1.0 / len(ring[v])
            others = [w for w in ring[v] if w not in tri]
            Q[a] = X[others].sum(axis=0) / len(ring[v])
        C = X0[tri].sum(axis=0)
        P0 = np.repeat(C[None] / 3.0, 3, axis=0)
        z = np.linalg.lstsq(A @ basis, Q - A @ P0, rcond=None)[0]
        P = P0 + basis @ z
        for a in range(3):
            sums[tri[a]] += P[a]
            counts[tri[a]] += 1
    out = X.copy()
    out[counts > 0] = sums[counts > 0] / counts[counts > 0, None]
    return out


LOCAL_CASES = {
    "octahedron": (
        6,
        [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]],
    ),
    "grid": (36, grid(6, 6)[1].tolist()),
}


@pytest.mark.parametrize("case", sorted(LOCAL_CASES))
def test_local_operator_is_one_eq7_step_per_triangle_averaged(case):
    n, triangles = LOCAL_CASES[case]
    F = np.array(triangles, dtype=np.int64)
    rng = np.random.default_rng(1)
    X, X0 = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    local = liu.local_operator(Connectivity(F, n), positions0=X0, block_rows=5)
    step = local.e1 @ (local.adjacency @ X) + local.e2 @ X + local.e3 @ X0
    np.testing.assert_allclose(step, _local_reference(F, n, X, X0), atol=1e-10)
    np.testing.assert_allclose(local.initial, local.e3 @ X0, atol=1e-13)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.integers(1, 40), min_size=3, max_size=3))
def test_triangle_coefficients_solve_the_constrained_least_squares(valences):
    M, u = liu.triangle_coefficients(np.array([valences]))
    A = np.eye(3) - (1.0 - np.eye(3)) / np.array(valences, dtype=float)[:, None]
    Q, C = np.random.default_rng(sum(valences)).normal(size=(2, 3))
    basis = np.array([[1.0, 0.0], [-1.0, 1.0], [0.0, -1.0]])
    P = C[0] / 3.0 + basis @ np.linalg.lstsq(A @ basis, Q - A @ np.full(3, C[0] / 3.0), rcond=None)[0]
    np.testing.assert_allclose(M[0] @ Q + u[0] * C[0], P, atol=1e-9)


@pytest.mark.parametrize("case", sorted(LOCAL_CASES))
def test_penalty_matrix_is_the_eq5_energy_on_the_free_vertices(case):
    n, triangles = LOCAL_CASES[case]
    F = np.array(triangles, dtype=np.int64)
    mu = 0.3
    p = ops.penalty_matrix(Connectivity(F, n), mu)
    K = reference_uniform(F, n)
    ring = plain_neighbours(F, n)
    edge_count = {}
    for tri in triangles:
        for q in range(3):
            key = frozenset((tri[q], tri[(q + 1) % 3]))
            edge_count[key] = edge_count.get(key, 0) + 1
    boundary = {v for key, c in edge_count.items() if c != 2 for v in key}
    free = [v for v in range(n) if ring[v] and v not in boundary]
    known = [v for v in range(n) if v not in free]
    H = np.array([[1.0 if v in tri else 0.0 for v in free] for tri in triangles if not boundary & set(tri)])
    K_F, K_B = K[np.ix_(free, free)], K[np.ix_(free, known)]
    assert p.free.tolist() == free and p.known.tolist() == known
    np.testing.assert_allclose(p.normal.toarray(), K_F.T @ K_F + mu * H.T @ H, atol=1e-13)
    if known:
        np.testing.assert_allclose(p.pull.toarray(), K_F.T @ K_B, atol=1e-13)


@settings(max_examples=40, deadline=None)
@given(triangle_soups(), st.sampled_from([0.0, 0.4]))
def test_scan_normal_matrix_is_the_sum_of_its_energy_rows(case, t):
    # E(X) = mu sum_t w_t |H_t X|^2 + lambda sum_edges |x_i - x_j|^2 + sum_i |K_i X|^2: the matrix is
    # the sum of the outer products of its rows, written here as plain loops
    n, triangles = case
    mu, membrane, rim_weight = 0.03, 0.45, 0.1
    edges = {}
    for tri in triangles:
        for q in range(3):
            key = tuple(sorted((tri[q], tri[(q + 1) % 3])))
            edges[key] = edges.get(key, 0) + 1
    ring = plain_neighbours(triangles, n)
    rim = [
        {b for (a, b), c in edges.items() if c == 1 and a == v}
        | {a for (a, b), c in edges.items() if c == 1 and b == v}
        for v in range(n)
    ]
    expected = np.zeros((n, n))

    def add(row, weight=1.0):
        expected[:, :] += weight * np.outer(row, row)

    for tri in triangles:
        row = np.zeros(n)
        row[tri] = 1.0
        add(row, mu * (rim_weight if any(rim[v] for v in tri) else 1.0))
    for a, b in edges:
        row = np.zeros(n)
        row[a], row[b] = 1.0, -1.0
        add(row, membrane)
    for v in range(n):
        row = np.zeros(n)
        if not ring[v]:
            expected[v, v] += 1.0
            continue
        row[v] = 1.0
        for w in ring[v]:
            row[w] -= (1.0 - t if rim[v] else 1.0) / len(ring[v])
        for w in rim[v]:
            row[w] -= t / len(rim[v])
        add(row)
    N, _, w = ops.scan_normal_matrix(Connectivity(np.array(triangles), n), mu, membrane, rim_weight, t)
    np.testing.assert_allclose(N.toarray(), expected, atol=1e-12)
    assert N.has_sorted_indices and np.array_equal(ops.lower_csc(N).toarray(), np.tril(N.toarray()))
    assert w.tolist() == [rim_weight if any(rim[v] for v in tri) else 1.0 for tri in triangles]


def _curve_step_reference(curves, X, X0, min_length=4):
    """Section 3.3 written per segment: estimates of both ends, held ends fixed, averaged per vertex."""
    from o3d_lsmesh.core.boundary import BoundaryCurves

    if isinstance(curves, BoundaryCurves):
        loops, chains, held = curves.loops, curves.chains, set(curves.junctions.tolist())
    else:
        loops, chains, held = curves, [], set()
    loops = [list(map(int, c)) for c in loops if len(c) >= min_length]
    chains = [list(map(int, c)) for c in chains if len(c) > min_length]
    held |= {c[0] for c in chains} | {c[-1] for c in chains}
    estimates = {}
    segments = []
    for c in loops:
        k = len(c)
        segments += [(c[i], c[(i + 1) % k], c[i - 1], c[(i + 2) % k]) for i in range(k)]
    for c in chains:
        k = len(c)
        segments += [
            (c[i], c[i + 1], c[i - 1] if i > 0 else -1, c[i + 2] if i + 2 < k else -1) for i in range(k - 1)
        ]
    for a, b, oa, ob in segments:
        mid = 0.5 * (X0[a] + X0[b])
        if a not in held and b not in held:
            estimates.setdefault(a, []).append((X[oa] - X[ob]) / 6 + mid)
            estimates.setdefault(b, []).append((X[ob] - X[oa]) / 6 + mid)
        elif a in held and b not in held:
            estimates.setdefault(b, []).append(X0[a] + X0[b] - X[a])
        elif b in held and a not in held:
            estimates.setdefault(a, []).append(X0[a] + X0[b] - X[b])
    return {v: np.mean(e, axis=0) for v, e in estimates.items()}


@pytest.mark.parametrize("case", ["loops", "fin", "pinch"])
def test_curve_laplacian_step_matches_per_segment_estimates(case):
    from o3d_lsmesh.core.boundary import boundary_curves

    if case == "loops":
        curves = [np.array([5, 6, 7, 8, 9]), np.array([0, 1, 2]), np.array([10, 11, 12, 13])]
    else:
        F = grid(6, 6)[1]
        if case == "fin":  # a flap on an inner edge: chains ending at the fin's ends
            F = np.vstack([F, [[14, 15, 36]]])
        else:  # two grids sharing one corner vertex
            F = np.vstack([F, F + 35])
        curves = boundary_curves(F, int(F.max()) + 1)
    rng = np.random.default_rng(0)
    X, X0 = rng.normal(size=(80, 3)), rng.normal(size=(80, 3))
    op = liu.curve_laplacian(curves)
    new = op.step(X, op.target(X0))
    expected = _curve_step_reference(curves, X, X0)
    assert sorted(expected) == op.vertex.tolist()
    np.testing.assert_allclose(new, np.array([expected[v] for v in op.vertex.tolist()]), atol=1e-13)


def test_triangle_coefficients_with_hundreds_of_distinct_valences():
    # more distinct valences than the dense look-up of valence triples holds
    valences = np.stack([np.arange(3, 303), np.arange(303, 3, -1), np.full(300, 7)], axis=1)
    M, u = liu.triangle_coefficients(valences)
    basis = np.array([[1.0, 0.0], [-1.0, 1.0], [0.0, -1.0]])
    rng = np.random.default_rng(0)
    for k in (0, 150, 299):
        A = np.eye(3) - (1.0 - np.eye(3)) / valences[k].astype(float)[:, None]
        Q, C = rng.normal(size=3), rng.normal()
        P = C / 3.0 + basis @ np.linalg.lstsq(A @ basis, Q - A @ np.full(3, C / 3.0), rcond=None)[0]
        np.testing.assert_allclose(M[k] @ Q + u[k] * C, P, atol=1e-9)


def test_scan_normal_matrix_takes_triangles_of_three_distinct_vertices():
    with pytest.raises(ValueError, match="three distinct vertices"):
        ops.scan_normal_matrix(Connectivity(np.array([[0, 1, 2], [2, 2, 3]])), 0.03, 0.45, 0.1)
