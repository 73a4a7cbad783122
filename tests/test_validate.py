import numpy as np
import open3d as o3d
import pytest
from conftest import grid

from o3d_lsmesh._o3d import new_mesh, read_mesh
from o3d_lsmesh._validate import (
    as_choice,
    as_count,
    as_indices,
    as_positions,
    as_positive_float,
    as_weights,
    as_workers,
)


def test_read_mesh_copies_and_casts(sphere):
    data = read_mesh(sphere)
    assert data.vertices.dtype == np.float64 and data.triangles.dtype == np.int64
    data.vertices[0] = 99.0  # must not write through to the caller's mesh
    assert np.asarray(sphere.vertices)[0, 0] != 99.0


def test_new_mesh_policy_legacy(sphere):
    sphere.vertex_colors = o3d.utility.Vector3dVector(np.full((len(sphere.vertices), 3), 0.5))
    data = read_mesh(sphere)
    same = new_mesh(data, data.vertices * 2)
    assert same.has_vertex_colors() and not same.has_vertex_normals()
    changed = new_mesh(data, data.vertices[:3], np.array([[0, 1, 2]]))
    assert not changed.has_vertex_colors()
    sphere.compute_vertex_normals()
    with_normals = new_mesh(read_mesh(sphere), data.vertices * 2)
    assert with_normals.has_vertex_normals()


def test_new_mesh_policy_tensor_keeps_dtype_and_attributes(sphere):
    t = o3d.t.geometry.TriangleMesh.from_legacy(sphere)
    t.vertex.colors = o3d.core.Tensor(np.full((len(sphere.vertices), 3), 0.25, dtype=np.float32))
    t.triangle.indices = t.triangle.indices.to(o3d.core.int32)
    data = read_mesh(t)
    out = new_mesh(data, data.vertices + 1)
    assert out.triangle.indices.dtype == o3d.core.int32
    assert out.vertex.positions.dtype == t.vertex.positions.dtype
    assert out.vertex.positions.device == t.vertex.positions.device
    np.testing.assert_array_equal(out.vertex.colors.numpy(), t.vertex.colors.numpy())
    np.testing.assert_allclose(out.vertex.positions.numpy(), data.vertices + 1, rtol=1e-6)


def test_arrays_kind_round_trip():
    V, F = grid(3, 3)
    data = read_mesh((V, F))
    out_v, out_f = new_mesh(data, V + 1)
    np.testing.assert_array_equal(out_v, V + 1)
    np.testing.assert_array_equal(out_f, F)


def test_read_mesh_errors():
    with pytest.raises(TypeError, match="mesh must be an open3d.geometry.TriangleMesh"):
        read_mesh("bunny.ply")
    with pytest.raises(ValueError, match="must have vertex positions"):
        read_mesh(o3d.t.geometry.TriangleMesh())
    pc = o3d.t.geometry.TriangleMesh()
    pc.vertex.positions = o3d.core.Tensor(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="must have triangles"):
        read_mesh(pc)
    V, F = grid(3, 3)
    with pytest.raises(ValueError, match="unreferenced vertices, got 1"):
        read_mesh((np.concatenate([V, [[9, 9, 9]]]), F), allow_isolated=False)
    with pytest.raises(TypeError, match="vertices must be an"):
        read_mesh((object(), F))


def test_small_validators():
    with pytest.raises(TypeError, match="must be an integer"):
        as_count(2.0, name="count")
    with pytest.raises(TypeError, match="must be an integer"):
        as_count(True, name="count")
    with pytest.raises(ValueError, match="count must be >= 1, got 0"):
        as_count(0, name="count", minimum=1)
    with pytest.raises(ValueError, match="count must be <= 3, got 4"):
        as_count(4, name="count", maximum=3)
    with pytest.raises(TypeError, match="mu must be a number"):
        as_positive_float("1", name="mu")
    with pytest.raises(ValueError, match="mu must be positive and finite, got 0.0"):
        as_positive_float(0, name="mu")
    with pytest.raises(ValueError, match="mu must be non-negative and finite, got -1.0"):
        as_positive_float(-1, name="mu", allow_zero=True)
    with pytest.raises(TypeError, match="method must be one of"):
        as_choice(3, ("a",), name="method")
    with pytest.raises(TypeError, match="weights must be a positive number"):
        as_weights(True, 2)
    with pytest.raises(TypeError, match="weights must be a positive number"):
        as_weights("x", 2)
    with pytest.raises(TypeError, match="idx must be a sequence"):
        as_indices(None, 5, name="idx")
    with pytest.raises(TypeError, match="idx must be a sequence"):
        as_indices([[1], [2, 3]], 5, name="idx")
    with pytest.raises(ValueError, match="idx must be one-dimensional"):
        as_indices([[1, 2]], 5, name="idx")
    with pytest.raises(TypeError, match="positions must be an array"):
        as_positions([["a", "b", "c"]], 1, name="positions")
    assert as_indices(o3d.utility.IntVector([1, 2]), 5, name="idx").tolist() == [1, 2]
    assert as_indices([], 5, name="idx", allow_empty=True).shape == (0,)
    assert as_positions(o3d.utility.Vector3dVector(np.ones((2, 3))), 2, name="p").shape == (2, 3)


def test_workers_default_to_the_cpus_this_process_may_use():
    import os

    expected = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert as_workers(None) == max(1, expected)
    assert as_workers(3) == 3 and isinstance(as_workers(np.int64(2)), int)
    with pytest.raises(ValueError, match="workers must be >= 1, got -1"):
        as_workers(-1)
    with pytest.raises(TypeError, match="workers must be an integer, got 'all'"):
        as_workers("all")
