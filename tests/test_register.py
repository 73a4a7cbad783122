"""register(): Open3D methods that chain, on both mesh kinds; explicit, idempotent, reversible."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import open3d as o3d
import pytest
from conftest import REPO, grid

from o3d_lsmesh import ls_mesh, reconstruct_geometry
from o3d_lsmesh.app.registration import METHOD_NAMES, register, registered_methods, unregister
from o3d_lsmesh.fairing import constrained_fairing, smooth_boundary_curves

CLASSES = (o3d.geometry.TriangleMesh, o3d.t.geometry.TriangleMesh)


@pytest.fixture
def registered():
    names = register()
    yield names
    unregister()


@pytest.fixture
def noisy():
    mesh = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=16)
    vertices = np.asarray(mesh.vertices)
    vertices += np.random.default_rng(3).normal(scale=0.02, size=vertices.shape)
    return mesh


def test_importing_the_package_patches_nothing():
    # A fresh interpreter: the test process itself may have registered before.
    code = textwrap.dedent(
        """
        import open3d as o3d
        classes = (o3d.geometry.TriangleMesh, o3d.t.geometry.TriangleMesh)
        before = [set(vars(c)) for c in classes]
        import o3d_lsmesh, o3d_lsmesh.app.registration, o3d_lsmesh.app.render, o3d_lsmesh.cli, o3d_lsmesh.app.demo
        import o3d_lsmesh.fairing, o3d_lsmesh.hierarchy
        added = [sorted(set(vars(c)) - b) for c, b in zip(classes, before)]
        print(added)
        """
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[[], []]"


def test_register_adds_every_method_to_both_classes_and_unregister_removes_them():
    try:
        names = register()
        assert names == METHOD_NAMES
        for cls in CLASSES:
            for name in names:
                assert callable(getattr(cls, name))
        assert all(found == METHOD_NAMES for found in registered_methods().values())
    finally:
        unregister()
    for cls in CLASSES:
        for name in METHOD_NAMES:
            assert name not in vars(cls)
    assert all(found == () for found in registered_methods().values())


def test_register_is_idempotent(noisy):
    try:
        first = register()
        method = o3d.geometry.TriangleMesh.filter_smooth_constrained
        assert register() == first
        # The second call re-installs the same operation: results are identical.
        again = o3d.geometry.TriangleMesh.filter_smooth_constrained
        np.testing.assert_array_equal(
            np.asarray(method(noisy, 3).vertices), np.asarray(again(noisy, 3).vertices)
        )
    finally:
        unregister()
        unregister()  # harmless when nothing is registered
    assert not hasattr(noisy, "filter_smooth_constrained")


def test_register_refuses_to_replace_an_open3d_method():
    cls = o3d.geometry.TriangleMesh
    cls.ls_mesh = lambda self: "Open3D's own"  # stands in for a future Open3D method of that name
    try:
        with pytest.raises(RuntimeError, match="already defines 'ls_mesh'"):
            register()
        # Nothing was installed, and the foreign method is untouched.
        assert all(found == () for found in registered_methods().values())
        assert cls.ls_mesh(None) == "Open3D's own"
    finally:
        del cls.ls_mesh
        unregister()


def test_legacy_chain_with_open3d_methods(registered, noisy):
    before = np.asarray(noisy.vertices).copy()
    out = noisy.remove_duplicated_vertices().filter_smooth_constrained(5).simplify_quadric_decimation(200)
    assert isinstance(out, o3d.geometry.TriangleMesh)
    assert 0 < len(out.triangles) <= 200
    np.testing.assert_array_equal(np.asarray(noisy.vertices), before)  # input untouched
    # The method is the function: same result as calling constrained_fairing directly.
    merged = noisy.remove_duplicated_vertices()
    np.testing.assert_array_equal(
        np.asarray(merged.filter_smooth_constrained(5).vertices),
        np.asarray(constrained_fairing(merged, 5).vertices),
    )


def test_tensor_chain_keeps_kind_device_and_dtype(registered, noisy):
    mesh = o3d.t.geometry.TriangleMesh.from_legacy(noisy)
    assert mesh.vertex.positions.dtype == o3d.core.float32
    smoothed = mesh.filter_smooth_constrained(4, method="local")
    assert isinstance(smoothed, o3d.t.geometry.TriangleMesh)
    assert smoothed is not mesh
    assert smoothed.vertex.positions.dtype == o3d.core.float32
    assert smoothed.device == mesh.device
    expected = np.asarray(constrained_fairing(noisy, 4, method="local").vertices)
    np.testing.assert_allclose(smoothed.vertex.positions.numpy(), expected, atol=1e-5)
    decimated = smoothed.simplify_quadric_decimation(target_reduction=0.5)
    assert 0 < decimated.triangle.indices.shape[0] < mesh.triangle.indices.shape[0]
    # And back to one of ours after Open3D's step.
    again = decimated.filter_smooth_constrained(2)
    assert again.vertex.positions.shape == decimated.vertex.positions.shape


def test_ls_methods_equal_the_functions(registered, noisy):
    indices = np.array([0, 17, 60, 150, 200])
    np.testing.assert_array_equal(
        np.asarray(noisy.ls_mesh(indices, weights=3.0).vertices),
        np.asarray(ls_mesh(noisy, indices, weights=3.0).vertices),
    )
    unknown = np.arange(30, 60)
    np.testing.assert_array_equal(
        np.asarray(noisy.reconstruct_geometry(unknown).vertices),
        np.asarray(reconstruct_geometry(noisy, unknown).vertices),
    )
    tensor = o3d.t.geometry.TriangleMesh.from_legacy(noisy)
    out = tensor.ls_mesh(indices).reconstruct_geometry(unknown)
    assert isinstance(out, o3d.t.geometry.TriangleMesh)


def test_approximate_and_decode_methods(registered, noisy):
    from o3d_lsmesh.lsmesh.encoding import decode_geometry, encode_geometry
    from o3d_lsmesh.lsmesh.selection import approximate

    expected, _ = approximate(noisy, 20, method="greedy")
    np.testing.assert_array_equal(
        np.asarray(noisy.approximate_ls(20, method="greedy").vertices), np.asarray(expected.vertices)
    )
    data = encode_geometry(noisy, 15)
    np.testing.assert_array_equal(
        np.asarray(noisy.decode_geometry(data, anchors=10).vertices),
        np.asarray(decode_geometry(noisy, data, anchors=10).vertices),
    )


def test_multiresolution_and_boundary_methods(registered):
    from o3d_lsmesh.fairing.multiresolution import multiresolution_fairing

    sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=20)
    np.asarray(sphere.vertices)[:] += np.random.default_rng(5).normal(
        scale=0.01, size=(len(sphere.vertices), 3)
    )
    np.testing.assert_array_equal(
        np.asarray(sphere.filter_smooth_multiresolution(1).vertices),
        np.asarray(multiresolution_fairing(sphere, 1).vertices),
    )
    vertices, triangles = grid(8, 8, z=lambda x, y: 0.05 * np.sin(9 * x))
    vertices[:, :2] += np.random.default_rng(1).normal(scale=0.01, size=(len(vertices), 2))
    plane = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(triangles)
    )
    np.testing.assert_array_equal(
        np.asarray(plane.filter_smooth_boundary_curves(3).vertices),
        np.asarray(smooth_boundary_curves(plane, 3).vertices),
    )


def test_methods_carry_docs_and_signatures(registered):
    import inspect

    import o3d_lsmesh

    method = o3d.geometry.TriangleMesh.filter_smooth_constrained
    assert "Liu et al. 2001" in " ".join(method.__doc__.split())
    assert "not the Taubin factor" in " ".join(method.__doc__.split())  # its mu is not filter_smooth_taubin's
    # each method shows its function's options (help(), completion), self in place of the mesh
    functions = ["constrained_fairing", "multiresolution_fairing", "smooth_boundary_curves", "ls_mesh"]
    functions += ["reconstruct_geometry", "approximate", "decode_geometry", "fill_holes"]
    for cls in CLASSES:
        for name, function in zip(METHOD_NAMES, functions):
            shown = list(inspect.signature(getattr(cls, name)).parameters.values())
            expected = list(inspect.signature(getattr(o3d_lsmesh, function)).parameters.values())
            assert shown[0].name == "self" and shown[1:] == expected[1:], name
            assert f"o3d_lsmesh.{function}`" in " ".join(getattr(cls, name).__doc__.split())
    assert "mu" in inspect.signature(method).parameters
