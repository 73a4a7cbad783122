import numpy as np
import open3d as o3d
import pytest
import scipy.linalg as sla
from conftest import grid

import o3d_lsmesh.lsmesh.spectral as spectral
from o3d_lsmesh.core.connectivity import Connectivity
from o3d_lsmesh.lsmesh.spectral import (
    combinatorial_laplacian,
    quantize_coefficients,
    spectral_approximation,
    spectral_basis,
)


def bumpy_grid(n=16):
    return grid(n, n, z=lambda x, y: 0.2 * np.sin(6 * x) * np.cos(5 * y) + 0.05 * x * y)


def test_laplacian_is_d_minus_a():
    V, F = bumpy_grid(6)
    L = combinatorial_laplacian(F, len(V))
    A = Connectivity(F, len(V)).adjacency.toarray()
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
    # the same mesh far from the origin: the same approximation, moved (the constant vectors' coefficients
    # took the quantizer's range, and 12 bits lost the shape)
    far = 1000.0 * np.ptp(V, axis=0).max()
    moved = spectral_approximation((V + far, F), 30, bits=12)[0] - far
    np.testing.assert_allclose(moved, spectral_approximation((V, F), 30, bits=12)[0], rtol=0, atol=1e-9 * far)
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


def several_components():
    """Four grids of different sizes side by side plus an unreferenced vertex: 5 components, 187 vertices."""
    parts, offset = [], 0
    vertices, triangles = [], []
    for i, (nx, ny) in enumerate(((11, 7), (8, 6), (6, 5), (4, 3))):
        V, F = grid(nx, ny, z=lambda x, y: 0.1 * np.sin(3 * x + y))
        vertices.append(V + [2.0 * i, 0.5 * i, 0.0])
        triangles.append(F + offset)
        parts.append(np.arange(offset, offset + len(V)))
        offset += len(V)
    vertices.append(np.array([[10.0, 10.0, 10.0]]))  # isolated: a component of its own
    parts.append(np.array([offset]))
    return np.vstack(vertices), np.vstack(triangles), parts


def test_multi_component_basis_matches_dense_eigh():
    V, F, parts = several_components()
    n, c = len(V), len(parts)
    dense_values, dense_vectors = sla.eigh(combinatorial_laplacian(F, n).toarray())
    assert np.abs(dense_values[:c]).max() < 1e-10 < dense_values[c]  # c zero eigenvalues, as the components
    # every cut between distinct eigenvalues past the null space, on both sides of n / 4 (sparse and dense paths)
    cuts = np.flatnonzero(np.diff(dense_values) > 1e-6) + 1
    cuts = cuts[(cuts > c) & (cuts < n)]
    chosen = [int(cuts[0]), int(cuts[cuts <= n // 4].max()), int(cuts[cuts > n // 4].min())]
    for k in chosen:
        values, vectors = spectral_basis(F, n, k)
        np.testing.assert_allclose(values, dense_values[:k], atol=1e-9, err_msg=f"k={k}")
        np.testing.assert_allclose(vectors.T @ vectors, np.eye(k), atol=1e-9, err_msg=f"k={k}")
        reference = dense_vectors[:, :k] @ (dense_vectors[:, :k].T @ V)
        np.testing.assert_allclose(
            spectral_approximation((V, F), k)[0], reference, atol=1e-8, err_msg=f"k={k}"
        )


def test_fewer_eigenvectors_than_components_keeps_the_largest_components():
    V, F, parts = several_components()
    n = len(V)
    for k in (1, 3, 5):
        values, vectors = spectral_basis(F, n, k)
        np.testing.assert_array_equal(values, np.zeros(k))
        L = combinatorial_laplacian(F, n)
        np.testing.assert_allclose(L @ vectors, 0, atol=1e-12)
        out = spectral_approximation((V, F), k)[0]
        expected = np.tile(V.mean(axis=0), (n, 1))
        # parts are listed largest first: each kept one goes to its centroid, the rest to the mesh's (the
        # approximation is about it: a translation of the mesh translates it)
        for part in parts[:k]:
            expected[part] = V[part].mean(axis=0)
        np.testing.assert_allclose(out, expected, atol=1e-12)


def test_progress():
    V, F = bumpy_grid(8)
    dense = spectral_approximation((V, F), 8)[0]
    np.testing.assert_allclose(spectral_approximation((V, F), 8, progress=True)[0], dense, atol=1e-12)
    for bad in (1, "yes", None):
        with pytest.raises(TypeError, match="progress must be a bool"):
            spectral_approximation((V, F), 8, progress=bad)
