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
    np.testing.assert_array_equal(out, constrained_fairing_arrays(V, F, 4, method="local"))
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
    coarse = constrained_fairing_arrays(h.level_arrays(1)[0], h.triangles[1], 3, method="local")
    expected = constrained_fairing_arrays(h.refine(1, coarse), F, 2, method="local")
    out, _ = multiresolution_fairing((V, F), 1, hierarchy=h, number_of_iterations=3, final_iterations=2)
    np.testing.assert_allclose(out, expected, atol=0)
    # final_iterations=None repeats number_of_iterations on M_0; 0 leaves the splits as they are
    out, _ = multiresolution_fairing((V, F), 1, hierarchy=h, number_of_iterations=3)
    np.testing.assert_allclose(
        out, constrained_fairing_arrays(h.refine(1, coarse), F, 3, method="local"), atol=0
    )
    out, _ = multiresolution_fairing((V, F), 1, hierarchy=h, number_of_iterations=3, final_iterations=0)
    np.testing.assert_allclose(out, h.refine(1, coarse), atol=0)


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
    with pytest.raises(ValueError, match="final_iterations must be >= 0"):
        multiresolution_fairing((V, F), 1, hierarchy=h, final_iterations=-1)
    with pytest.raises(TypeError, match="final_iterations must be an integer"):
        multiresolution_fairing((V, F), 1, hierarchy=h, final_iterations=1.5)
    with pytest.raises(ValueError, match="method must be one of"):
        multiresolution_fairing((V, F), 1, hierarchy=h, method="cotangent")
    with pytest.raises(TypeError, match="progress must be a bool"):
        multiresolution_fairing((V, F), 1, hierarchy=h, progress=1)


# ----------------------------------------------------- smoothing by scale (issue 13)


def _blob():
    sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=40)
    V = np.asarray(sphere.vertices)
    u = V / np.linalg.norm(V, axis=1, keepdims=True)
    r = 1 + 0.15 * np.sin(3 * u[:, 0]) * np.cos(2 * u[:, 1]) + 0.1 * u[:, 2] ** 2
    return u * r[:, None], np.asarray(sphere.triangles).astype(np.int64)


def _normal_laplacian_energy(P, F):
    """Mean squared normal component of the uniform Laplacian, over the squared mean edge length: the
    roughness of the shape (its tangential part measures the triangulation, not the surface)."""
    import scipy.sparse as sp

    n = len(P)
    edges = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)
    A = sp.coo_matrix(
        (np.ones(2 * len(edges)), (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])),
        shape=(n, n),
    ).tocsr()
    laplacian = A @ P / np.asarray(A.sum(axis=1)) - P
    normals = np.zeros_like(P)
    face = np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])
    for c in range(3):
        np.add.at(normals, F[:, c], face)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    h = np.linalg.norm(P[edges[:, 0]] - P[edges[:, 1]], axis=1).mean()
    return np.mean(np.einsum("ij,ij->i", laplacian, normals) ** 2) / h**2


def _signed_volume(P, F):
    return np.einsum("ij,ij->i", P[F[:, 0]], np.cross(P[F[:, 1]], P[F[:, 2]])).sum() / 6


@pytest.mark.parametrize("name", ["blob", "horse.ply", "bunny.ply"])
def test_a_coarser_start_gives_a_smoother_result_that_keeps_the_volume(name):
    from conftest import load_mesh

    if name == "blob":
        V, F = _blob()
    else:
        mesh = load_mesh(name)
        V, F = np.asarray(mesh.vertices), np.asarray(mesh.triangles).astype(np.int64)
    spacing = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).mean()
    noisy = V + np.random.default_rng(0).normal(scale=0.3 * spacing, size=V.shape)
    h = build_hierarchy((noisy, F), max_levels=6, min_vertices=4)
    energy, volume = [], []
    for level in range(7):
        P, _ = multiresolution_fairing((noisy, F), level, hierarchy=h)
        energy.append(_normal_laplacian_energy(P, F))
        volume.append(_signed_volume(P, F) / _signed_volume(V, F) - 1)
    assert all(a > b for a, b in zip(energy, energy[1:])), energy
    assert energy[0] < 0.5 * _normal_laplacian_energy(noisy, F)
    assert np.abs(volume).max() < 0.005, volume


def test_at_low_noise_the_result_stays_near_the_clean_surface():
    V, F = _blob()
    spacing = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).mean()
    noisy = V + np.random.default_rng(1).normal(scale=0.1 * spacing, size=V.shape)
    h = build_hierarchy((noisy, F), max_levels=6, min_vertices=4)
    noise = np.linalg.norm(noisy - V, axis=1).mean()
    for level in (1, 3, 6):
        P, _ = multiresolution_fairing((noisy, F), level, hierarchy=h)
        # measured 0.10, 0.18, 0.31 edge lengths (the noise is 0.16): coarser starts drift by their scale
        assert np.linalg.norm(P - V, axis=1).mean() < 0.4 * spacing + noise, level
