"""Every format, every attribute: split vertices (UV seams) and attributes survive processing."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

o3d = pytest.importorskip("open3d")

from conftest import REPO  # noqa: E402

import o3d_lsmesh  # noqa: E402
from o3d_lsmesh import O3DLSMeshWarning  # noqa: E402
from o3d_lsmesh._o3d import new_mesh, read_mesh, weld_map  # noqa: E402


def _noisy_uv_sphere(tmp_path):
    """A UV sphere with noise, written to OBJ and read back: Open3D splits its vertices at the UV seam."""
    sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=20, create_uv_map=True)
    rng = np.random.default_rng(3)
    v = np.asarray(sphere.vertices)
    sphere.vertices = o3d.utility.Vector3dVector(v + rng.normal(scale=0.02, size=v.shape))
    path = tmp_path / "sphere.obj"
    assert o3d.io.write_triangle_mesh(str(path), sphere)
    mesh = o3d.io.read_triangle_mesh(str(path))
    return mesh, path


def _coincident_groups(vertices):
    """Groups of vertex indices at exactly equal coordinates, by a plain dictionary (independent of np.unique)."""
    groups: dict = {}
    for i, p in enumerate(np.asarray(vertices)):
        groups.setdefault(tuple(p), []).append(i)
    return [g for g in groups.values() if len(g) > 1]


def _assert_seams_closed(mesh_in, mesh_out):
    groups = _coincident_groups(mesh_in.vertices)
    assert groups, "the OBJ reader was expected to split the sphere at its UV seam"
    out = np.asarray(mesh_out.vertices)
    for group in groups:
        np.testing.assert_array_equal(out[group], np.repeat(out[group[:1]], len(group), axis=0))
    return groups


def test_weld_map_reference():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [-0.0, 0, 0]], dtype=float)
    triangles = np.array([[0, 1, 2], [3, 4, 2], [5, 3, 4]])
    split = weld_map(vertices, triangles)
    # duplicates: 3 -> 1, 5 -> 0 (-0.0 == 0.0); numbered by first occurrence
    np.testing.assert_array_equal(split, [0, 1, 2, 1, 3, 0])
    assert weld_map(vertices[:3], triangles[:1]) is None  # no duplicates
    # a triangle with two coincident corners would collapse: the mesh is not welded
    assert weld_map(vertices, np.array([[0, 1, 3]])) is None


def test_read_mesh_weld_round_trip_arrays():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0]], dtype=float)
    triangles = np.array([[0, 1, 2], [3, 4, 2]])
    data = read_mesh((vertices, triangles), weld=True)
    assert len(data.vertices) == 4 and data.triangles.tolist() == [[0, 1, 2], [1, 3, 2]]
    out_v, out_t = new_mesh(data, data.vertices + 1.0)
    np.testing.assert_array_equal(out_t, triangles)
    np.testing.assert_array_equal(out_v, vertices + 1.0)


def test_obj_seams_stay_closed_api(tmp_path):
    mesh, _ = _noisy_uv_sphere(tmp_path)
    n_unique = len(np.unique(np.asarray(mesh.vertices), axis=0))
    assert len(mesh.vertices) > n_unique
    # welded, the sphere is closed: the seam is no boundary curve, so boundary smoothing moves nothing
    still = o3d_lsmesh.smooth_boundary_curves(mesh, 3)
    np.testing.assert_array_equal(np.asarray(still.vertices), np.asarray(mesh.vertices))
    for out in (
        o3d_lsmesh.constrained_fairing(mesh, 10),
        o3d_lsmesh.constrained_fairing(mesh, 5, method="global"),
        o3d_lsmesh.multiresolution_fairing(mesh, 2),
    ):
        assert len(out.vertices) == len(mesh.vertices)
        np.testing.assert_array_equal(np.asarray(out.triangles), np.asarray(mesh.triangles))
        _assert_seams_closed(mesh, out)
        np.testing.assert_array_equal(np.asarray(out.triangle_uvs), np.asarray(mesh.triangle_uvs))
        # the surface did move (fairing ran on it)
        assert np.abs(np.asarray(out.vertices) - np.asarray(mesh.vertices)).max() > 1e-3


def test_fairing_welded_equals_fairing_of_welded_mesh(tmp_path):
    """Fairing the split mesh gives, on each vertex, what fairing the welded mesh gives (plain reference weld)."""
    mesh, _ = _noisy_uv_sphere(tmp_path)
    v = np.asarray(mesh.vertices)
    index: dict = {}
    split = np.array([index.setdefault(tuple(p), len(index)) for p in v])
    welded_v = np.zeros((len(index), 3))
    welded_v[split] = v
    welded_t = split[np.asarray(mesh.triangles)]
    ref_v, _ = o3d_lsmesh.constrained_fairing((welded_v, welded_t), 10)
    out = o3d_lsmesh.constrained_fairing(mesh, 10)
    np.testing.assert_allclose(np.asarray(out.vertices), ref_v[split], rtol=0, atol=1e-12)


def test_obj_seams_stay_closed_cli(tmp_path):
    mesh, path = _noisy_uv_sphere(tmp_path)
    out_path = tmp_path / "out.obj"
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "o3d_lsmesh.cli",
            "denoise",
            str(path),
            str(out_path),
            "--iterations",
            "10",
            "--quiet",
        ],
        capture_output=True,
        text=True,
        check=False,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    out = o3d.io.read_triangle_mesh(str(out_path))
    assert len(out.vertices) == len(mesh.vertices)
    _assert_seams_closed(mesh, out)
    np.testing.assert_allclose(np.asarray(out.triangle_uvs), np.asarray(mesh.triangle_uvs), atol=1e-6)
    assert np.abs(np.asarray(out.vertices) - np.asarray(mesh.vertices)).max() > 1e-3


def test_legacy_uvs_and_material_ids_survive_fairing():
    mesh = o3d.geometry.TriangleMesh.create_sphere(resolution=10, create_uv_map=True)
    m = len(mesh.triangles)
    ids = np.arange(m, dtype=np.int32) % 3
    mesh.triangle_material_ids = o3d.utility.IntVector(ids)
    uvs = np.asarray(mesh.triangle_uvs).copy()
    out = o3d_lsmesh.constrained_fairing(mesh, 3)
    np.testing.assert_array_equal(np.asarray(out.triangle_uvs), uvs)
    np.testing.assert_array_equal(np.asarray(out.triangle_material_ids), ids)
    # the result's attributes are copies: editing them leaves the input alone
    np.asarray(out.triangle_uvs)[:] = 0.5
    np.testing.assert_array_equal(np.asarray(mesh.triangle_uvs), uvs)


def test_tensor_material_and_triangle_attributes_survive_fairing():
    mesh = o3d.t.geometry.TriangleMesh.from_legacy(
        o3d.geometry.TriangleMesh.create_sphere(resolution=10, create_uv_map=True)
    )
    mesh.material.set_default_properties()
    mesh.material.material_name = "defaultLit"
    mesh.material.scalar_properties["roughness"] = 0.25
    uvs = mesh.triangle.texture_uvs.numpy().copy()
    out = o3d_lsmesh.constrained_fairing(mesh, 3)
    assert out.has_valid_material()
    assert out.material.material_name == "defaultLit"
    assert out.material.scalar_properties["roughness"] == pytest.approx(0.25)
    np.testing.assert_array_equal(out.triangle.texture_uvs.numpy(), uvs)
    out.material.scalar_properties["roughness"] = 0.9
    assert mesh.material.scalar_properties["roughness"] == pytest.approx(0.25)


def test_new_connectivity_drops_uvs_with_one_warning():
    mesh = o3d.geometry.TriangleMesh.create_sphere(resolution=10, create_uv_map=True)
    mesh.triangle_material_ids = o3d.utility.IntVector(np.zeros(len(mesh.triangles), dtype=np.int32))
    data = read_mesh(mesh)
    with pytest.warns(O3DLSMeshWarning, match="triangle UVs, triangle material ids") as record:
        out = new_mesh(data, data.vertices, data.triangles[:-2])
    assert len(record) == 1
    assert not out.has_triangle_uvs() and not out.has_triangle_material_ids()
    assert len(out.triangles) == len(mesh.triangles) - 2


def test_obj_seams_stay_closed_through_encoding(tmp_path):
    mesh, _ = _noisy_uv_sphere(tmp_path)
    stream = o3d_lsmesh.encode_geometry(mesh, 60, bits=12)
    for out in (
        o3d_lsmesh.decode_geometry(mesh, stream),
        list(o3d_lsmesh.iter_decode_geometry(mesh, stream, step=30))[-1],
    ):
        assert len(out.vertices) == len(mesh.vertices)
        np.testing.assert_array_equal(np.asarray(out.triangles), np.asarray(mesh.triangles))
        _assert_seams_closed(mesh, out)
        np.testing.assert_array_equal(np.asarray(out.triangle_uvs), np.asarray(mesh.triangle_uvs))
    # the decoded surface approximates the input (60 anchors on ~760 welded vertices: a smooth sphere)
    err = np.linalg.norm(np.asarray(out.vertices) - np.asarray(mesh.vertices), axis=1)
    assert err.mean() < 0.1


def test_spectral_approximation_keeps_seams_closed(tmp_path):
    mesh, _ = _noisy_uv_sphere(tmp_path)
    out = o3d_lsmesh.spectral_approximation(mesh, 30)
    _assert_seams_closed(mesh, out)


def test_warn_dropped_attributes_names_what_is_lost():
    from o3d_lsmesh._o3d import warn_dropped_attributes

    plain = read_mesh(o3d.geometry.TriangleMesh.create_sphere(resolution=5))
    assert warn_dropped_attributes(plain, "levels") is False  # nothing to drop: no warning
    tensor = o3d.t.geometry.TriangleMesh.from_legacy(
        o3d.geometry.TriangleMesh.create_sphere(resolution=5, create_uv_map=True)
    )
    with pytest.warns(O3DLSMeshWarning, match=r"^levels: triangle attribute 'texture_uvs' of the input"):
        assert warn_dropped_attributes(read_mesh(tensor), "levels") is True


def test_hierarchy_levels_warn_once_that_uvs_are_dropped():
    mesh = o3d.geometry.TriangleMesh.create_sphere(resolution=10, create_uv_map=True)
    with pytest.warns(
        O3DLSMeshWarning, match="hierarchy levels have new connectivity: triangle UVs"
    ) as record:
        hierarchy = o3d_lsmesh.build_hierarchy(mesh, max_levels=3)
    assert len(record) == 1
    level = hierarchy.level(len(hierarchy.triangles) - 1)
    assert len(level.triangles) < len(mesh.triangles) and not level.has_triangle_uvs()
