import numpy as np
import open3d as o3d
import pytest
import scipy.linalg as sla
from conftest import grid

import o3d_lsmesh.spectral as spectral
from o3d_lsmesh.spectral import combinatorial_laplacian, quantize_coefficients, spectral_approximation, spectral_basis
from o3d_lsmesh.topology import adjacency_matrix


def bumpy_grid(n=16):
    return grid(n, n, z=lambda x, y: 0.2 * np.sin(6 * x) * np.cos(5 * y) + 0.05 * x * y)


def test_laplacian_is_d_minus_a():
    V, F = bumpy_grid(6)
    L = combinatorial_laplacian(F, len(V))
    A = adjacency_matrix(F, len(V)).toarray()
    np.testing.assert_array_equal(L.toarray(), np.diag(A.sum(axis=1)) - A)
    assert abs(L - L.T).max() == 0


def test_all_eigenvectors_reproduce_the_mesh():
    mesh = o3d.geometry.TriangleMesh.create_sphere(resolution=10)
    V = np.asarray(mesh.vertices)
    out = spectral_approximation(mesh, len(V))
    assert isinstance(out, o3d.geometry.TriangleMesh)
    np.testing.assert_allclose(np.asarray(out.vertices), V, atol=1e-10)


def test_shift_invert_basis_matches_dense_eigh():
    V, F = bumpy_grid(16)
    n = len(V)
    dense_values, dense_vectors = sla.eigh(combinatorial_laplacian(F, n).toarray())
    gaps = np.flatnonzero(np.diff(dense_values[: n // 4 + 1]) > 1e-6) + 1
    k = int(gaps[gaps <= n // 4].max())  # a cut between distinct eigenvalues: the subspace is unique
    values, vectors = spectral_basis(F, n, k)
    np.testing.assert_allclose(values, dense_values[:k], atol=1e-9)
    np.testing.assert_allclose(vectors.T @ vectors, np.eye(k), atol=1e-9)
    projector = vectors @ vectors.T
    np.testing.assert_allclose(projector, dense_vectors[:, :k] @ dense_vectors[:, :k].T, atol=1e-8)
    out = spectral_approximation((V, F), k)[0]
    np.testing.assert_allclose(out, dense_vectors[:, :k] @ (dense_vectors[:, :k].T @ V), atol=1e-8)


def test_first_eigenvector_gives_the_centroid():
    V, F = bumpy_grid(8)
    out = spectral_approximation((V, F), 1)[0]
    np.testing.assert_allclose(out, np.broadcast_to(V.mean(axis=0), V.shape), atol=1e-10)


def test_error_decreases_with_k():
    V, F = bumpy_grid(16)
    errors = [np.linalg.norm(spectral_approximation((V, F), k)[0] - V) for k in (4, 16, 40, 64, 128, 256)]
    assert all(b < a for a, b in zip(errors, errors[1:])), errors


def test_quantized_coefficients():
    V, F = bumpy_grid(10)
    exact = spectral_approximation((V, F), 30)[0]
    coarse = spectral_approximation((V, F), 30, bits=6)[0]
    fine = spectral_approximation((V, F), 30, bits=20)[0]
    assert np.abs(fine - exact).max() < 1e-4 < np.abs(coarse - exact).max()
    c = np.random.default_rng(0).standard_normal((50, 3))
    q = quantize_coefficients(c, 8)
    step = np.ptp(c, axis=0) / 255
    assert (np.abs(q - c) <= step / 2 + 1e-12).all()
    assert len(np.unique(q[:, 0])) <= 256


def test_tensor_mesh_kind():
    mesh = o3d.t.geometry.TriangleMesh.from_legacy(o3d.geometry.TriangleMesh.create_sphere(resolution=8))
    assert isinstance(spectral_approximation(mesh, 10), o3d.t.geometry.TriangleMesh)


def test_errors(monkeypatch):
    V, F = bumpy_grid(8)
    n = len(V)
    with pytest.raises(ValueError, match="k must be >= 1"):
        spectral_approximation((V, F), 0)
    with pytest.raises(ValueError, match=f"k must be <= {n}"):
        spectral_approximation((V, F), n + 1)
    with pytest.raises(ValueError, match="bits must be >= 1"):
        spectral_approximation((V, F), 4, bits=0)
    with pytest.raises(ValueError, match="bits must be <= 31"):
        spectral_approximation((V, F), 4, bits=40)
    monkeypatch.setattr(spectral, "SPECTRAL_MAX_VERTICES", n - 1)
    with pytest.raises(ValueError, match=f"at most {n - 1} vertices for the spectral baseline"):
        spectral_approximation((V, F), 4)
    monkeypatch.setattr(spectral, "SPECTRAL_MAX_VERTICES", 10**6)
    monkeypatch.setattr(spectral, "DENSE_MAX_VERTICES", n - 1)
    with pytest.raises(ValueError, match=f"k must be at most n / 4 = {n // 4}"):
        spectral_approximation((V, F), n // 4 + 1)
    monkeypatch.setattr(spectral, "SPECTRAL_MAX_WORK", n * 3)
    with pytest.raises(ValueError, match="k must be at most 3 for a mesh of"):
        spectral_approximation((V, F), 4)
