import numpy as np
import open3d as o3d
import pytest
from conftest import grid
from hypothesis import given, settings
from hypothesis import strategies as st

from o3d_lsmesh import O3DLSMeshWarning
from o3d_lsmesh._o3d import new_mesh, read_mesh
from o3d_lsmesh._o3d.state import mesh_from_state, mesh_state
from o3d_lsmesh.core.validate import (
    COORDINATE_LIMIT,
    as_bool,
    as_choice,
    as_count,
    as_indices,
    as_positions,
    as_positive_float,
    as_real_vector,
    as_triangle_array,
    as_vertex_array,
    as_weights,
    as_workers,
    mesh_arrays,
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
    with pytest.warns(O3DLSMeshWarning, match="vertex colors"):
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
    F = grid(3, 3)[1]
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
    with pytest.raises(TypeError, match=r"weights must be a positive number or an array of them, got True$"):
        as_weights(True, 2)  # named as given, not as the bool array numpy makes of it
    with pytest.raises(TypeError, match="idx must be a sequence"):
        as_indices(None, 5, name="idx")
    with pytest.raises(TypeError, match="idx must be a sequence"):
        as_indices([[1], [2, 3]], 5, name="idx")
    with pytest.raises(ValueError, match="idx must be one-dimensional"):
        as_indices([[1, 2]], 5, name="idx")
    with pytest.raises(TypeError, match="positions must be an array"):
        as_positions([["a", "b", "c"]], 1, name="positions")
    assert as_indices(o3d.utility.IntVector([1, 2]), 5, name="idx").tolist() == [1, 2]
    with pytest.raises(ValueError, match="idx must hold at least one vertex index, got none"):
        as_indices([], 5, name="idx")
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


def test_vertex_and_triangle_arrays_check_dtype_and_shape_without_casting_first():
    v = as_vertex_array(np.arange(12, dtype=np.int8).reshape(4, 3))
    assert v.dtype == np.float64 and v[3, 2] == 11.0
    for bad, error, match in [
        (
            np.ones((4, 3), complex),
            TypeError,
            r"mesh vertices must be an \(n, 3\) array of real numbers, got dtype complex128",
        ),
        (np.ones((4, 3), bool), TypeError, "got dtype bool"),
        ([["1", "2", "3"]], TypeError, "got dtype <U1"),
        ("vertices", TypeError, "mesh vertices must be an \\(n, 3\\) array, got 'vertices'"),
        ([[1, 2, 3], [4, 5]], TypeError, "mesh vertices must be an \\(n, 3\\) array"),
        (np.ones(12), ValueError, r"mesh vertices must have shape \(n, 3\), got \(12,\)"),
        (np.ones((4, 4)), ValueError, r"got \(4, 4\)"),
    ]:
        with pytest.raises(error, match=match):
            as_vertex_array(bad)
    assert as_vertex_array(np.zeros((0,))).shape == (0, 3)

    t = as_triangle_array(np.array([[0, 1, 2]], dtype=np.uint8), 3)
    assert t.dtype == np.int64 and t.tolist() == [[0, 1, 2]]
    assert as_triangle_array([], 3, name="m").shape == (0, 3)
    for bad, error, match in [
        (
            np.array([[0, 1, 2.5]]),
            TypeError,
            r"mesh triangles must be an \(m, 3\) integer array, got dtype float64",
        ),
        (np.array([[0.0, 1.0, 2.0]]), TypeError, "got dtype float64"),  # integral floats too: no silent cast
        (np.ones((1, 3), bool), TypeError, "got dtype bool"),
        (np.arange(6), ValueError, r"mesh triangles must have shape \(m, 3\), got \(6,\)"),
        (
            np.array([[0, 1, 2**64 - 1]], dtype=np.uint64),
            ValueError,
            r"mesh triangle indices must lie in \[0, 3\), got \[0, 1, 18446744073709551615\] at triangle 0",
        ),
        (np.array([[0, 1, 2], [0, -1, 2]]), ValueError, r"got \[0, -1, 2\] at triangle 1"),
        # named as given, not as the array numpy would make of them
        ("faces", TypeError, r"mesh triangles must be an \(m, 3\) integer array, got 'faces'$"),
        (None, TypeError, "integer array, got None$"),
        ([[0, 1, 2], [0, 1]], TypeError, r"integer array, got \[\[0, 1, 2\], \[0, 1\]\]$"),
    ]:
        with pytest.raises(error, match=match):
            as_triangle_array(bad, 3)


def test_bool_and_real_vector_validators():
    assert as_bool(np.bool_(True), name="x") is True
    assert as_bool(None, name="x", allow_none=True) is None
    for bad in (1, "yes", None, np.array([True])):
        with pytest.raises(TypeError, match="x must be a bool, got"):
            as_bool(bad, name="x")
    np.testing.assert_array_equal(as_real_vector([0, 1, 0.5], 3, name="c", low=0, high=1), [0, 1, 0.5])
    with pytest.raises(TypeError, match="c must be a sequence of 3 numbers, got 'red'"):
        as_real_vector("red", 3, name="c")
    with pytest.raises(ValueError, match=r"c must have 3 entries in \[0, 1\], got \[0.0, 2.0, 0.0\]"):
        as_real_vector([0, 2, 0], 3, name="c", low=0, high=1)
    with pytest.raises(ValueError, match=r"c must have 3 entries finite, got \[0.0, nan, 0.0\]"):
        as_real_vector([0, np.nan, 0], 3, name="c")
    for bad, shape in (([0.5, 0.5], r"\(2,\)"), ([[0, 0, 1]], r"\(1, 3\)"), (0.5, r"\(\)")):
        with pytest.raises(ValueError, match=rf"c must be a sequence of 3 numbers, got shape {shape}"):
            as_real_vector(bad, 3, name="c")


def test_weights_and_positions_refuse_what_is_not_a_real_number():
    for bad in ("2", True, np.array([1j]), np.array([True]), ["a"], None):
        with pytest.raises(TypeError, match="w must be a positive number"):
            as_weights(bad, 1, name="w")
    for bad in ([["1", "2", "3"]], np.ones((1, 3), complex), np.ones((1, 3), bool), "abc"):
        with pytest.raises(TypeError, match=r"p must be an array of shape \(1, 3\)"):
            as_positions(bad, 1, name="p")
    # user coordinates have the mesh's limit, computed ones (limit=False) do not
    assert as_positions([[2 * COORDINATE_LIMIT, 0, 0]], 1, name="p")[0, 0] == 2 * COORDINATE_LIMIT
    with pytest.raises(ValueError, match=r"p must have coordinates of magnitude at most 1e\+30"):
        as_positions([[2 * COORDINATE_LIMIT, 0, 0]], 1, name="p", limit=True)
    with pytest.raises(ValueError, match=r"i must lie in \[0, 5\), got 18446744073709551615 at position 1"):
        as_indices(np.array([1, 2**64 - 1], dtype=np.uint64), 5, name="i")


def test_mesh_limit_is_inclusive_and_names_the_vertex():
    v, f = grid(3, 3)
    read_mesh((v * COORDINATE_LIMIT, f))
    big = v.copy()
    big[4, 1] = -1.5 * COORDINATE_LIMIT
    with pytest.raises(
        ValueError, match=r"mesh vertices must have coordinates of magnitude at most 1e\+30 .* at vertex 4"
    ):
        read_mesh((big, f))


def test_mesh_state_rebuilds_every_kind(sphere):
    sphere.vertex_colors = o3d.utility.Vector3dVector(np.full((len(sphere.vertices), 3), 0.5))
    sphere.compute_triangle_normals()
    tensor = o3d.t.geometry.TriangleMesh.from_legacy(sphere)
    tensor.vertex.positions = tensor.vertex.positions.to(o3d.core.float32)
    tensor.triangle.indices = tensor.triangle.indices.to(o3d.core.int32)
    tensor.vertex.labels = o3d.core.Tensor(np.arange(len(sphere.vertices), dtype=np.int16).reshape(-1, 1))
    for mesh in (sphere, tensor, grid(4, 4)):
        data = read_mesh(mesh)
        state = mesh_state(data)
        import pickle

        rebuilt = mesh_from_state(pickle.loads(pickle.dumps(state)))
        assert rebuilt.kind == data.kind
        a, b = new_mesh(data, data.vertices * 2), new_mesh(rebuilt, data.vertices * 2)
        assert type(a) is type(b)
        if data.kind == "legacy":
            np.testing.assert_array_equal(np.asarray(a.vertex_colors), np.asarray(b.vertex_colors))
            np.testing.assert_array_equal(np.asarray(a.triangle_normals), np.asarray(b.triangle_normals))
            assert b.has_triangle_normals() and not b.has_vertex_normals()
        elif data.kind == "tensor":
            assert b.vertex.positions.dtype == o3d.core.float32 and b.triangle.indices.dtype == o3d.core.int32
            assert b.vertex.labels.dtype == o3d.core.int16
            np.testing.assert_array_equal(a.vertex.labels.numpy(), b.vertex.labels.numpy())
            np.testing.assert_array_equal(a.vertex.colors.numpy(), b.vertex.colors.numpy())
        else:
            np.testing.assert_array_equal(a[0], b[0])


def test_tensor_with_integer_positions_gives_float_positions():
    v, f = grid(3, 3)
    mesh = o3d.t.geometry.TriangleMesh()
    mesh.vertex.positions = o3d.core.Tensor((v * 10).astype(np.int32))
    mesh.triangle.indices = o3d.core.Tensor(f)
    out = new_mesh(read_mesh(mesh), v * 10 + 0.25)
    assert out.vertex.positions.dtype == o3d.core.float64
    np.testing.assert_array_equal(out.vertex.positions.numpy(), v * 10 + 0.25)


@settings(max_examples=80, deadline=None)
@given(
    value=st.one_of(
        st.text(max_size=5),
        st.booleans(),
        st.complex_numbers(),
        st.none(),
        st.lists(st.text(max_size=3), min_size=1, max_size=3),
        st.lists(st.complex_numbers(allow_nan=False), min_size=3, max_size=3),
        st.lists(st.booleans(), min_size=3, max_size=3),
    )
)
def test_weights_positions_and_vectors_never_accept_non_numbers(value):
    # strings, bools, complex numbers, None and lists of them are refused, never converted
    for check in (
        lambda: as_weights(value, 3, name="w"),
        lambda: as_positions(value, 1, name="p"),
        lambda: as_real_vector(value, 3, name="v"),
    ):
        with pytest.raises((TypeError, ValueError), match="^[wpv] must"):
            check()


def test_mesh_arrays_is_the_one_check_of_array_functions_and_read_mesh():
    from o3d_lsmesh.core.validate import mesh_arrays
    from o3d_lsmesh.fairing import constrained_fairing_arrays
    from o3d_lsmesh.fairing.boundary_curve import smooth_boundary_curves_arrays
    from o3d_lsmesh.hierarchy.hierarchy import build_hierarchy_arrays
    from o3d_lsmesh.holes import fill_holes_arrays
    from o3d_lsmesh.summary import topology_summary_arrays

    v, f = grid(3, 3)
    bad = {
        "nan": (np.where(np.arange(27).reshape(9, 3) == 4, np.nan, v), f),
        "range": (v, np.where(f == 8, 9, f)),
        "repeat": (v, np.vstack([f, [[0, 0, 1]]])),
        "float index": (v, f.astype(float)),
        "shape": (v[:, :2], f),
        "empty": (np.zeros((0, 3)), f[:0]),
    }
    for case, (vertices, triangles) in bad.items():
        errors = []
        for check, args in (
            (mesh_arrays, (vertices, triangles)),
            (read_mesh, ((vertices, triangles),)),
            (constrained_fairing_arrays, (vertices, triangles, 1)),
            (smooth_boundary_curves_arrays, (vertices, triangles, 1)),
            (build_hierarchy_arrays, (vertices, triangles)),
            (fill_holes_arrays, (vertices, triangles)),
            (topology_summary_arrays, (vertices, triangles)),
        ):
            if case == "repeat" and check is read_mesh:
                continue  # a mesh's are left out (test_defect_soups); the array functions refuse them
            with pytest.raises((TypeError, ValueError)) as info:
                check(*args)
            errors.append((type(info.value), str(info.value)))
        assert all(error == errors[0] for error in errors), case
    # C order whatever the caller's layout (the compiled hierarchy kernel reads rows)
    fortran_v, fortran_f = mesh_arrays(np.asfortranarray(v), np.asfortranarray(f))
    assert fortran_v.flags.c_contiguous and fortran_f.flags.c_contiguous
    # copies: the caller's arrays are never the results
    out_v, out_f = mesh_arrays(v, f)
    assert not np.shares_memory(out_v, v) and not np.shares_memory(out_f, f)
    np.testing.assert_array_equal(out_v, v)


def test_mesh_arrays_refuses_each_defect_on_its_own():
    # the array core's validator, one defect at a time
    V, F = grid(3, 3)
    assert all(np.array_equal(a, b) for a, b in zip(mesh_arrays(V, F), (V, F)))
    cases = [
        (np.zeros((0, 3)), F[:0], {}, "mesh must have vertices, got an empty mesh"),
        (V, F[:0], {}, "mesh must have triangles, got 9 vertices and no triangles"),
        (
            np.where(np.arange(9)[:, None] == 4, np.nan, V),
            F,
            {},
            r"vertices must be finite, got .* at vertex 4",
        ),
        (
            V * np.where(np.arange(9)[:, None] == 2, 1e31, 1.0),
            F,
            {},
            "magnitude at most 1e\\+30.* at vertex 2",
        ),
        (V, np.vstack([F, [[0, 1, 9]]]), {}, r"indices must lie in \[0, 9\), got \[0, 1, 9\] at triangle 8"),
        (
            V,
            np.vstack([F, [[0, -1, 2]]]),
            {},
            r"indices must lie in \[0, 9\), got \[0, -1, 2\] at triangle 8",
        ),
        (V, np.vstack([F, [[3, 5, 3]]]), {}, r"three distinct vertices, got \[3, 5, 3\] at triangle 8"),
    ]
    for vertices, triangles, options, message in cases:
        with pytest.raises(ValueError, match=message):
            mesh_arrays(vertices, triangles, **options)
    mesh_arrays(np.vstack([V, [[5.0, 5, 5]]]), F)  # an unreferenced vertex is allowed


def test_plain_sequences_are_read_as_written():
    # numpy reads [True, 5] as [1, 5] (a bool taken for vertex 1) and [int64, uint64] as floats (then
    # refused as "cast with astype(int)")
    from o3d_lsmesh.core.validate import as_indices, as_weights

    with pytest.raises(TypeError, match="got bools among numbers"):
        as_indices([True, 5], 10, name="indices")
    with pytest.raises(TypeError, match="got bools among numbers"):
        as_weights([True, 2.0], 2)
    np.testing.assert_array_equal(as_indices([np.int64(3), np.uint64(7), 2], 10, name="i"), [3, 7, 2])
    assert as_indices([np.int64(3), np.uint64(7)], 10, name="i").dtype == np.int64
    np.testing.assert_array_equal(as_weights([1, 2.5], 2), [1.0, 2.5])  # numbers of two kinds, as before


def test_spd_solver_flags_are_bools():
    import scipy.sparse as sp

    from o3d_lsmesh import SPDSolver

    matrix = sp.csc_matrix(np.diag([2.0, 3.0]))
    for flag in ("lower", "progress"):
        with pytest.raises(TypeError, match=f"{flag} must be a bool, got str 'no'"):
            SPDSolver(matrix, **{flag: "no"})


def test_a_mesh_too_small_for_double_precision_is_refused():
    # at 1e-40 the hierarchy made no level, at 1e-100 the feature mode returned NaN, the cotangent LS mesh
    # was off by 73% of its size and fill_holes added nothing: powers of the lengths underflow
    from o3d_lsmesh import constrained_fairing

    V, F = grid(6, 6, z=lambda x, y: 0.1 * x * y)
    for scale in (1e-40, 1e-100):
        with pytest.raises(ValueError, match="mesh vertices must span at least 1e-30 .* scale the mesh up"):
            constrained_fairing((V * scale, F), method="features")
    out = constrained_fairing((V * 1e-20, F), method="features")[0]  # small, but within range
    assert np.isfinite(out).all()
    # a mesh whose vertices all coincide spans nothing: not this error (its own, or none)
    mesh_arrays(np.zeros((3, 3)), np.array([[0, 1, 2]]))
