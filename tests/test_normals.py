"""area_weighted_normals against a plain loop over triangles and against Open3D's vertex normals."""

from __future__ import annotations

import numpy as np
import open3d as o3d

from o3d_lsmesh._normals import area_weighted_normals


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
