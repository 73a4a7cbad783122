"""The feature pass's compiled loops (``triangle_normals``, ``pair_jumps``) and its once-formed vertex
grouping against plain Python loops over the triangles and pairs."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse as sp

from o3d_lsmesh._block_kernel import triangle_normals
from o3d_lsmesh._feature_kernel import pair_jumps
from o3d_lsmesh.core.arrays import face_normals
from o3d_lsmesh.core.connectivity import Connectivity
from o3d_lsmesh.fairing.features import _vertex_grouping, normal_steps


def _mesh(seed: int, index: type) -> tuple[np.ndarray, np.ndarray]:
    """A small random mesh with a degenerate face (two equal corners) and a -0.0 coordinate."""
    rng = np.random.default_rng(seed)
    n, m = 9, 14
    vertices = rng.normal(size=(n, 3))
    vertices[0, 2] = -0.0
    triangles = np.stack([rng.choice(n, 3, replace=False) for _ in range(m)]).astype(index)
    triangles[-1] = [3, 3, 5]
    return vertices, triangles


def _normal_loop(vertices, triangle):
    """One triangle's unit normal and area as the NumPy code computes them, in plain floats."""
    a, b, c = (vertices[int(v)] for v in triangle)
    u = [float(b[k] - a[k]) for k in range(3)]
    w = [float(c[k] - a[k]) for k in range(3)]
    cross = [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]]
    length = math.sqrt((cross[0] * cross[0] + cross[1] * cross[1]) + cross[2] * cross[2])
    divisor = max(length, np.finfo(float).tiny)
    return [x / divisor for x in cross], 0.5 * length


@pytest.mark.parametrize("index", [np.int32, np.int64])
@pytest.mark.parametrize("seed", range(4))
def test_triangle_normals_match_loop(seed, index):
    vertices, triangles = _mesh(seed, index)
    normals, area, centroid = triangle_normals(vertices, triangles, True)
    for t, triangle in enumerate(triangles):
        normal, size = _normal_loop(vertices, triangle)
        assert normals[t].tolist() == normal and area[t] == size
        for k in range(3):
            s = 0.0  # the sparse product's sum starts at zero
            for v in triangle:
                s = s + float(vertices[int(v), k])
            assert centroid[t, k] == s / 3.0
    assert normals[-1].tolist() == [0.0, 0.0, 0.0] and area[-1] == 0.0  # the degenerate face
    assert triangle_normals(vertices, triangles)[2] is None


@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_face_normals_and_centroids_equal_numpy(index):
    vertices, triangles = _mesh(7, index)
    p0 = vertices[triangles[:, 0]]
    cross = np.cross(vertices[triangles[:, 1]] - p0, vertices[triangles[:, 2]] - p0)
    length = np.linalg.norm(cross, axis=1)
    normals, area = face_normals(vertices, triangles)
    assert np.array_equal(normals, cross / np.maximum(length, np.finfo(float).tiny)[:, None])
    assert np.array_equal(area, 0.5 * length)
    m = len(triangles)
    incidence = sp.csr_matrix(
        (np.ones(3 * m), triangles.ravel(), np.arange(0, 3 * m + 1, 3)), shape=(m, len(vertices))
    )
    assert np.array_equal(triangle_normals(vertices, triangles, True)[2], (incidence @ vertices) / 3.0)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_face_normals_other_dtypes_equal_numpy(dtype):
    # float32 positions and unsigned triangles: computed in float64, as NumPy does on the cast positions
    vertices, triangles = _mesh(3, np.int64)
    vertices, triangles = vertices.astype(dtype), triangles.astype(np.uint16)
    wide = vertices.astype(np.float64)
    p0 = wide[triangles[:, 0]]
    cross = np.cross(wide[triangles[:, 1]] - p0, wide[triangles[:, 2]] - p0)
    length = np.linalg.norm(cross, axis=1)
    normals, area = face_normals(vertices, triangles)
    assert np.array_equal(normals, cross / np.maximum(length, np.finfo(float).tiny)[:, None])
    assert np.array_equal(area, 0.5 * length) and area.dtype == np.float64


@pytest.mark.parametrize("seed", range(4))
def test_pair_jumps_match_loop(seed):
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(8, 3))
    pairs = rng.integers(0, 8, size=(12, 2))
    pairs[0] = [2, 2]  # a pair of one face: no jump
    jumps = pair_jumps(pairs, normals)
    for k, (a, b) in enumerate(pairs):
        d = [float(normals[a, c] - normals[b, c]) for c in range(3)]
        assert jumps[k] == math.sqrt((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2])
    assert jumps[0] == 0.0
    assert np.array_equal(jumps, np.linalg.norm(normals[pairs[:, 0]] - normals[pairs[:, 1]], axis=1))


@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_normal_steps_grouping_kept_equals_formed(index):
    vertices, triangles = _mesh(5, index)
    incidence = Connectivity(triangles, len(vertices)).face_adjacency.incidence
    normals = face_normals(vertices, triangles)[0]
    formed = normal_steps(vertices, triangles, normals, incidence=incidence)
    kept = normal_steps(
        vertices, triangles, normals, incidence=incidence, grouping=_vertex_grouping(incidence)
    )
    assert np.array_equal(formed, kept)


def test_triangle_normals_raises():
    vertices, triangles = _mesh(0, np.int64)
    with pytest.raises(ValueError, match=r"positions must have shape \(n, 3\), got \(9, 2\)"):
        triangle_normals(np.ascontiguousarray(vertices[:, :2]), triangles)
    with pytest.raises(ValueError, match=r"triangles must have shape \(m, 3\), got \(14, 2\)"):
        triangle_normals(vertices, np.ascontiguousarray(triangles[:, :2]))
    bad = triangles.copy()
    bad[2, 1] = 9
    with pytest.raises(ValueError, match=r"triangles must name vertices in 0\.\.8, got 9 in triangle 2"):
        triangle_normals(vertices, bad)


def test_pair_jumps_raises():
    normals = np.zeros((4, 3))
    with pytest.raises(ValueError, match=r"pairs must have shape \(p, 2\), got \(2, 3\)"):
        pair_jumps(np.zeros((2, 3), dtype=np.int64), normals)
    with pytest.raises(ValueError, match=r"normals must have shape \(m, 3\), got \(4, 2\)"):
        pair_jumps(np.zeros((2, 2), dtype=np.int64), np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"pairs must name rows of normals in 0\.\.3, got pair 1: 0, 4"):
        pair_jumps(np.array([[0, 1], [0, 4]]), normals)


@pytest.mark.parametrize("count", [1, 2, 3, 4, 7, 10, 33])
def test_median_angle_is_the_median_of_every_pairs_angle(count):
    import statistics

    from o3d_lsmesh.fairing.features import median_angle

    rng = np.random.default_rng(count)
    normals = rng.standard_normal((12, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[3] = normals[2]  # a pair at angle 0 and repeated angles: ties in the middle
    pairs = rng.integers(0, 12, size=(count, 2))
    pairs[0] = [2, 3]
    angles = [math.acos(max(-1.0, min(1.0, float(normals[a] @ normals[b])))) for a, b in pairs.tolist()]
    assert median_angle(normals, pairs) == pytest.approx(statistics.median(angles), rel=1e-12, abs=1e-15)
    assert median_angle(normals, np.zeros((0, 2), dtype=np.int64)) == 0.0
