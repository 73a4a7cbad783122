"""Face and area-weighted vertex normals against plain loops over triangles and against Open3D's vertex normals."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from o3d_lsmesh.core.arrays import area_weighted_normals, face_normals


def test_area_weighted_normals_match_a_plain_loop_and_open3d():
    rng = np.random.default_rng(3)
    mesh = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=12)
    V = np.asarray(mesh.vertices) + rng.normal(0.0, 0.05, (len(mesh.vertices), 3))
    T = np.asarray(mesh.triangles).astype(np.int64)
    V = np.concatenate([V, [[5.0, 5.0, 5.0]]])  # a vertex on no triangle: zero normal
    expected = np.zeros_like(V)
    for a, b, c in T:
        face = np.cross(V[b] - V[a], V[c] - V[a])
        for v in (a, b, c):
            expected[v] += face
    got = area_weighted_normals(V, T)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-14)
    assert not got[-1].any()
    # Open3D's area-weighted normals, normalized
    reference = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V[:-1]), o3d.utility.Vector3iVector(T))
    reference.compute_vertex_normals()
    unit = got[:-1] / np.linalg.norm(got[:-1], axis=1, keepdims=True)
    np.testing.assert_allclose(unit, np.asarray(reference.vertex_normals), atol=1e-9)


def test_face_normals_and_areas_match_a_plain_loop():
    rng = np.random.default_rng(4)
    V = rng.normal(size=(8, 3))
    T = np.array([[0, 1, 2], [2, 3, 4], [5, 6, 7], [1, 1, 3]])  # the last one degenerate
    normals, areas = face_normals(V, T)
    for t, (a, b, c) in enumerate(T):
        cross = np.cross(V[b] - V[a], V[c] - V[a])
        length = np.linalg.norm(cross)
        assert areas[t] == pytest.approx(0.5 * length, rel=1e-14)
        np.testing.assert_allclose(normals[t], cross / length if length > 0 else 0.0, atol=1e-15)
