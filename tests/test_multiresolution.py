"""Multiresolution fairing (issue 4, section 4.2): level 0, kinds, scale of the removed details, errors."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from conftest import grid
from o3d_lsmesh.fairing.constrained import constrained_fairing_arrays
from o3d_lsmesh.fairing.multiresolution import multiresolution_fairing
from o3d_lsmesh.hierarchy import build_hierarchy, from_fast_simplification


def _ripple(w):
    phi = np.arctan2(w[:, 1], w[:, 0])
    return np.cos(8 * phi) * (1 - w[:, 2] ** 2) ** 4


@pytest.fixture(scope="module")
def rippled():
    """Unit sphere with a mid-scale ripple (8 waves around the equator) and fine noise."""
    sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=30)
    V = np.asarray(sphere.vertices)
    u = V / np.linalg.norm(V, axis=1, keepdims=True)
    noise = 0.01 * np.random.default_rng(0).standard_normal(len(V))
    V = u * (1 + 0.04 * _ripple(u) + noise)[:, None]
    F = np.asarray(sphere.triangles).astype(np.int64)
    return (V, F), build_hierarchy((V, F))


def _ripple_amplitude(P):
    r = np.linalg.norm(P, axis=1)
    basis = _ripple(P / r[:, None])
    dev = r - r.mean()
    return (dev @ basis) / (basis @ basis)


def test_level_zero_is_constrained_fairing(rippled):
    (V, F), h = rippled
    out, tris = multiresolution_fairing((V, F), 0, hierarchy=h, number_of_iterations=4)
    np.testing.assert_array_equal(out, constrained_fairing_arrays(V, F, 4))
    assert np.array_equal(tris, F)


def test_larger_level_removes_larger_details(rippled):
    (V, F), h = rippled
    amplitude = [_ripple_amplitude(multiresolution_fairing((V, F), lv, hierarchy=h)[0]) for lv in (0, 4, 8)]
    # measured: about 0.038, 0.026, 0.007 for the 0.04 ripple
    assert amplitude[0] > 0.03
    assert amplitude[1] < 0.8 * amplitude[0]
    assert abs(amplitude[2]) < 0.3 * amplitude[0]
    # the fine noise is gone at every level: what is left off the ripple is well below 1%
    for lv in (0, 4):
        P = multiresolution_fairing((V, F), lv, hierarchy=h)[0]
        r = np.linalg.norm(P, axis=1)
        residual = r - r.mean() - _ripple_amplitude(P) * _ripple(P / r[:, None])
        assert residual.std() < 0.006


def test_one_level_is_fair_then_refine(rippled):
    (V, F), h = rippled
    coarse = constrained_fairing_arrays(h.level_arrays(1)[0], h.triangles[1], 3)
    expected = h.refine(1, coarse)
    out, _ = multiresolution_fairing((V, F), 1, hierarchy=h, number_of_iterations=3)
    np.testing.assert_allclose(out, expected, atol=0)


def test_default_hierarchy_equals_a_given_one(rippled):
    (V, F), h = rippled
    a, _ = multiresolution_fairing((V, F), 3)
    b, _ = multiresolution_fairing((V, F), 3, hierarchy=h)
    np.testing.assert_array_equal(a, b)


def test_kinds_connectivity_and_input_untouched():
    sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=16)
    sphere.compute_vertex_normals()
    before = np.asarray(sphere.vertices).copy()
    out = multiresolution_fairing(sphere, 2, method="global")
    assert isinstance(out, o3d.geometry.TriangleMesh)
    assert np.array_equal(np.asarray(out.triangles), np.asarray(sphere.triangles))
    assert out.has_vertex_normals()
    assert np.array_equal(np.asarray(sphere.vertices), before)
    tensor = o3d.t.geometry.TriangleMesh.from_legacy(sphere)
    out_t = multiresolution_fairing(tensor, 2, progress=True)
    assert isinstance(out_t, o3d.t.geometry.TriangleMesh)
    assert out_t.vertex.positions.shape == tensor.vertex.positions.shape


def test_runs_on_a_fast_simplification_hierarchy_and_open_meshes(rippled):
    (V, F), _ = rippled
    h = from_fast_simplification((V, F), levels=[900, 450, 220])
    out, _ = multiresolution_fairing((V, F), 3, hierarchy=h)
    assert np.isfinite(out).all()
    assert abs(_ripple_amplitude(out)) < 0.5 * _ripple_amplitude(V)
    # an open grid: boundary vertices stay on the boundary plane z = 0 of a flat sheet
    G, T = grid(12, 12)
    flat, _ = multiresolution_fairing((G, T), 3)
    assert np.abs(flat[:, 2]).max() < 1e-12


def test_a_moved_copy_reuses_the_hierarchy(rippled):
    (V, F), h = rippled
    shifted = V + np.array([1.0, 2.0, 3.0])
    out, _ = multiresolution_fairing((shifted, F), 2, hierarchy=h)
    base, _ = multiresolution_fairing((V, F), 2, hierarchy=h)
    np.testing.assert_allclose(out, base + np.array([1.0, 2.0, 3.0]), atol=1e-9)


def test_bad_input_raises(rippled):
    (V, F), h = rippled
    with pytest.raises(ValueError, match=f"level must be < len\\(hierarchy\\) = {len(h)}, got {len(h)}"):
        multiresolution_fairing((V, F), len(h), hierarchy=h)
    with pytest.raises(ValueError, match="level must be >= 0, got -1"):
        multiresolution_fairing((V, F), -1)
    with pytest.raises(TypeError, match="level must be an integer"):
        multiresolution_fairing((V, F), 1.5)
    with pytest.raises(ValueError, match="level must be < 1 \\(the levels build_hierarchy reaches"):
        multiresolution_fairing(o3d.geometry.TriangleMesh.create_tetrahedron(), 2)
    with pytest.raises(TypeError, match="hierarchy must be a MeshHierarchy"):
        multiresolution_fairing((V, F), 1, hierarchy="h")
    small = o3d.geometry.TriangleMesh.create_sphere(resolution=6)
    with pytest.raises(ValueError, match="hierarchy must be built from mesh"):
        multiresolution_fairing(small, 1, hierarchy=h)
    with pytest.raises(ValueError, match="number_of_iterations must be >= 0"):
        multiresolution_fairing((V, F), 1, hierarchy=h, number_of_iterations=-3)
    with pytest.raises(ValueError, match="method must be one of"):
        multiresolution_fairing((V, F), 1, hierarchy=h, method="cotangent")
    with pytest.raises(TypeError, match="progress must be a bool"):
        multiresolution_fairing((V, F), 1, hierarchy=h, progress=1)
    bad = (np.eye(3).tolist() + [[0.0, 0.0, 1.0], [1.0, 1.0, 1.0]], [[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    with pytest.raises(ValueError, match="edge-manifold"):
        multiresolution_fairing((np.array(bad[0]), np.array(bad[1])), 1)
