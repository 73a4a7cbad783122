"""No bad input may give a wrong answer (issue 12): one test per defect class, plus probes over the public API.

Class 1 (ill-conditioned weights, overflow inside solves) is tested with the solver gateway.
"""

from __future__ import annotations

import pickle
import threading

import numpy as np
import open3d as o3d
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import o3d_lsmesh as lsm
from o3d_lsmesh import metrics
from o3d_lsmesh._o3d import read_mesh
from o3d_lsmesh.core.validate import COORDINATE_LIMIT

RTOL = 1e-9


def _sphere(resolution: int = 8) -> o3d.geometry.TriangleMesh:
    return o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=resolution)


def _arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).astype(np.int64)


def _tensor(vertices: np.ndarray, triangles: np.ndarray) -> o3d.t.geometry.TriangleMesh:
    mesh = o3d.t.geometry.TriangleMesh()
    mesh.vertex.positions = o3d.core.Tensor(vertices)
    mesh.triangle.indices = o3d.core.Tensor(triangles)
    return mesh


def _vertices_of(mesh) -> np.ndarray:
    if isinstance(mesh, tuple):
        return np.asarray(mesh[0])
    if isinstance(mesh, o3d.geometry.TriangleMesh):
        return np.asarray(mesh.vertices)
    return mesh.vertex.positions.numpy()


# --------------------------------------------------------------------------- class 2: the adapter


@pytest.mark.parametrize("kind", ["tensor", "arrays"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.bool_])
def test_non_integer_indices_are_a_type_error_for_every_kind(kind, dtype):
    vertices, triangles = _arrays(_sphere())
    bad = (
        triangles.astype(dtype) if dtype is np.bool_ else triangles.astype(dtype) + 0.5
    )  # truncation would hide .5
    mesh = _tensor(vertices, bad) if kind == "tensor" else (vertices, bad)
    with pytest.raises(TypeError, match=r"mesh triangles must be an \(m, 3\) integer array, got dtype"):
        lsm.ls_mesh(mesh, [0, 5])


@pytest.mark.parametrize("kind", ["tensor", "arrays"])
@pytest.mark.parametrize(
    "which, reshape, match",
    [
        ("vertices", lambda a: a.reshape(-1, 1), r"mesh vertices must have shape \(n, 3\), got \(\d+, 1\)"),
        ("vertices", lambda a: a.reshape(-1), r"mesh vertices must have shape \(n, 3\), got \(\d+,\)"),
        ("vertices", lambda a: a[:, :2].copy(), r"mesh vertices must have shape \(n, 3\), got \(\d+, 2\)"),
        (
            "vertices",
            lambda a: a.reshape(-1, 3, 1),
            r"mesh vertices must have shape \(n, 3\), got \(\d+, 3, 1\)",
        ),
        ("triangles", lambda a: a.reshape(-1, 1), r"mesh triangles must have shape \(m, 3\), got \(\d+, 1\)"),
        ("triangles", lambda a: a.reshape(-1), r"mesh triangles must have shape \(m, 3\), got \(\d+,\)"),
        ("triangles", lambda a: a.reshape(-1, 6), r"mesh triangles must have shape \(m, 3\), got \(\d+, 6\)"),
    ],
)
def test_wrong_shapes_are_never_reshaped(kind, which, reshape, match):
    vertices, triangles = _arrays(_sphere())
    if which == "vertices":
        vertices = reshape(vertices)
    else:
        triangles = reshape(triangles)
    mesh = _tensor(vertices, triangles) if kind == "tensor" else (vertices, triangles)
    with pytest.raises(ValueError, match=match):
        lsm.ls_mesh(mesh, [0, 5])


@pytest.mark.parametrize("dtype", [np.int8, np.int32, np.int64, np.uint16])
def test_integer_positions_give_the_float_answer(dtype):
    # a grid with integer coordinates: the result must equal the result on the same float positions,
    # not rounded back to integers (tensor) or wrapped (int8)
    vertices, triangles = _arrays(_sphere())
    integer = (
        np.round(vertices * 50).astype(dtype)
        if dtype is not np.uint16
        else np.round(vertices * 50 + 60).astype(dtype)
    )
    reference = lsm.ls_mesh((integer.astype(np.float64), triangles), [0, 5, 40], weights=3.0)[0]
    for mesh in (_tensor(integer, triangles), (integer, triangles)):
        out = _vertices_of(lsm.ls_mesh(mesh, [0, 5, 40], weights=3.0))
        assert out.dtype == np.float64
        np.testing.assert_allclose(out, reference, rtol=RTOL, atol=1e-9)
        assert not np.allclose(out, np.round(out))  # the LS mesh is not on the integer grid


@pytest.mark.parametrize("kind", ["tensor", "arrays"])
def test_unsigned_indices_out_of_range_are_reported_as_given(kind):
    vertices, triangles = _arrays(_sphere())
    bad = triangles.astype(np.uint64)
    bad[3, 1] = np.iinfo(np.uint64).max  # would wrap to -1 as int64
    mesh = _tensor(vertices, bad) if kind == "tensor" else (vertices, bad)
    with pytest.raises(
        ValueError,
        match=r"triangle indices must lie in \[0, \d+\), got \[\d+, 18446744073709551615, \d+\] at triangle 3",
    ):
        lsm.ls_mesh(mesh, [0, 5])


@pytest.mark.parametrize(
    "vertices, match",
    [
        (lambda v: v.astype(complex), "got dtype complex128"),
        (lambda v: v > 0, "got dtype bool"),
        (lambda v: v.astype(str), "got dtype <U"),
        (lambda v: v.astype(object), "got dtype object"),
    ],
)
def test_positions_that_are_not_real_numbers_are_a_type_error(vertices, match):
    v, f = _arrays(_sphere())
    with pytest.raises(
        TypeError, match="mesh vertices must be an \\(n, 3\\) array of real numbers, " + match
    ):
        lsm.constrained_fairing((vertices(v), f), 2)


_DTYPES = st.sampled_from(
    ["float32", "float64", "int8", "int32", "int64", "uint8", "uint64", "bool", "complex128"]
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    vdtype=_DTYPES,
    tdtype=_DTYPES,
    vshape=st.sampled_from([(4, 3), (12,), (4, 3, 1), (4, 2), (3, 4)]),
    tshape=st.sampled_from([(2, 3), (6,), (2, 3, 1), (3, 2)]),
    tensor=st.booleans(),
)
def test_read_mesh_returns_exactly_the_input_or_raises(vdtype, tdtype, vshape, tshape, tensor):
    # the adapter's contract for any dtype and shape: the same numbers in (n,3) float64 / (m,3) int64, or an error
    tet_v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    tet_f = np.array([[0, 1, 2], [0, 3, 1]], dtype=np.int64)
    raw_v = tet_v.astype(vdtype).reshape(vshape) if np.prod(vshape) == 12 else tet_v[:, :2].astype(vdtype)
    raw_f = tet_f.astype(tdtype).reshape(tshape)
    if tensor:
        try:
            mesh = _tensor(raw_v, raw_f)
        except (RuntimeError, TypeError):  # Open3D has no tensor of this dtype
            return
    else:
        mesh = (raw_v, raw_f)
    try:
        data = read_mesh(mesh)
    except (TypeError, ValueError):
        ok_v = vdtype not in ("bool", "complex128") and vshape == (4, 3)
        ok_f = tdtype.startswith(("int", "uint")) and tshape == (2, 3)
        assert not (ok_v and ok_f), "a valid mesh was refused"
        return
    assert vshape == (4, 3) and tshape == (2, 3)
    assert data.vertices.dtype == np.float64 and data.triangles.dtype == np.int64
    np.testing.assert_array_equal(data.vertices, tet_v)
    np.testing.assert_array_equal(data.triangles, tet_f)


# --------------------------------------------------------------------------- class 4: coordinates near the float range


def _calls():
    """Public functions on a mesh, each returning an array or float of its result."""
    return {
        "ls_mesh": lambda m: lsm.ls_mesh(m, [0, 5, 40])[0],
        "constrained_fairing local": lambda m: lsm.constrained_fairing(m, 3)[0],
        "constrained_fairing global": lambda m: lsm.constrained_fairing(m, 3, method="global")[0],
        "spectral_approximation": lambda m: lsm.spectral_approximation(m, 10)[0],
        "approximate": lambda m: lsm.approximate(m, 10)[0][0],
        "reconstruct_geometry": lambda m: lsm.reconstruct_geometry(m, np.arange(10))[0],
        "multiresolution_fairing": lambda m: lsm.multiresolution_fairing(m, 1)[0],
        "encode/decode": lambda m: lsm.decode_geometry(m, lsm.encode_geometry(m, 20, bits=16))[0],
        "smooth_boundary_curves": lambda m: lsm.smooth_boundary_curves((m[0], m[1][:-40]), 3)[0],
        "signed_volume": metrics.signed_volume,
        "triangle_angles": lambda m: metrics.triangle_angles(m)["min_angle"],
        "normal_deviation": lambda m: metrics.normal_deviation(m, m),
        "surface_distance": lambda m: metrics.surface_distance(m, (m[0] * 0.99, m[1]), number_of_points=2000)[
            "mean"
        ],
        "vertex_error": lambda m: metrics.vertex_error(m, (m[0] * 0.99, m[1]))["rms"],
    }


@pytest.mark.parametrize("scale", [1e300, 1e308, -1e31])
@pytest.mark.parametrize("name", list(_calls()))
def test_coordinates_beyond_the_limit_are_refused_naming_the_limit(name, scale):
    v, f = _arrays(_sphere())
    with pytest.raises(ValueError, match=r"vertices must have coordinates of magnitude at most 1e\+30"):
        _calls()[name]((v * scale, f))


# how each result scales with the coordinates: positions and distances by s, volumes by s^3, angles not at all
_POWER = {"signed_volume": 3, "triangle_angles": 0, "normal_deviation": 0}


@pytest.mark.parametrize("scale", [COORDINATE_LIMIT, 1e-30])
@pytest.mark.parametrize("name", list(_calls()))
def test_results_at_the_limits_are_finite_and_scale_with_the_mesh(name, scale):
    # the algorithms are scale-equivariant: at 1e30 (and 1e-30) the result is the unit result times s^p
    v, f = _arrays(_sphere())
    # off-center (the volume and the fairing see an offset too) and bumpy (no ties in greedy selection)
    v = v + np.array([0.1, -0.2, 0.3]) + 0.02 * np.random.default_rng(7).standard_normal(v.shape)
    unit = np.asarray(_calls()[name]((v, f)), dtype=np.float64)
    scale = (
        scale / np.abs(v).max() * (1 - 1e-15)
    )  # the largest coordinate at the limit (not rounded above it)
    big = np.asarray(_calls()[name]((v * scale, f)), dtype=np.float64)
    assert np.isfinite(big).all()
    tolerance = 1e-4 if name == "surface_distance" else 1e-7  # surface_distance samples in float32
    np.testing.assert_allclose(big, unit * scale ** _POWER.get(name, 1), rtol=tolerance, atol=0)


def test_control_positions_beyond_the_limit_are_refused():
    with pytest.raises(
        ValueError, match=r"constraint_vertex_positions must have coordinates of magnitude at most"
    ):
        lsm.ls_mesh(_sphere(), [0, 5], [[0, 0, 1e300], [0, 0, 0]])
    solver = lsm.LSMeshSolver(_sphere(), [0, 5])
    with pytest.raises(ValueError, match=r"positions must have coordinates of magnitude at most 1e\+30"):
        solver.add_anchors([7], [[1e31, 0, 0]])


def test_render_at_the_coordinate_limit_draws_the_unit_picture():
    v, f = _arrays(_sphere(16))
    unit = lsm.render((v, f), None, width=48, height=48, backend="raycast")
    big = lsm.render((v * COORDINATE_LIMIT, f), None, width=48, height=48, backend="raycast")
    assert (unit != 255).any()
    assert np.abs(unit.astype(int) - big.astype(int)).max() <= 2


# --------------------------------------------------------------------------- class 5: state objects


def _colored_legacy():
    mesh = _sphere()
    mesh.vertex_colors = o3d.utility.Vector3dVector(np.random.default_rng(0).random((len(mesh.vertices), 3)))
    mesh.compute_vertex_normals()
    return mesh


def _tensor_float32():
    mesh = o3d.t.geometry.TriangleMesh.from_legacy(_colored_legacy())
    mesh.vertex.positions = mesh.vertex.positions.to(o3d.core.float32)
    mesh.triangle.indices = mesh.triangle.indices.to(o3d.core.int32)
    return mesh


@pytest.mark.parametrize("make", [_colored_legacy, _tensor_float32, lambda: _arrays(_sphere())])
def test_unpickled_solver_returns_the_input_kind(make):
    mesh = make()
    solver = lsm.LSMeshSolver(mesh, [0, 5, 40], weights=2.0)
    solver.add_anchors([7, 9], weights=3.0)
    before = solver.mesh()
    after = pickle.loads(pickle.dumps(solver)).mesh()
    assert type(after) is type(before)
    # the unpickled factor is refactored from the matrix (CHOLMOD factors do not pickle): equal to round-off
    np.testing.assert_allclose(_vertices_of(after), _vertices_of(before), rtol=0, atol=1e-12)
    if isinstance(before, o3d.geometry.TriangleMesh):
        np.testing.assert_array_equal(np.asarray(after.vertex_colors), np.asarray(mesh.vertex_colors))
        assert after.has_vertex_normals()
        np.testing.assert_allclose(np.asarray(after.vertex_normals), np.asarray(before.vertex_normals))
    elif not isinstance(before, tuple):
        assert after.vertex.positions.dtype == o3d.core.float32
        assert after.triangle.indices.dtype == o3d.core.int32
        np.testing.assert_array_equal(after.vertex.colors.numpy(), mesh.vertex.colors.numpy())
        assert "normals" in after.vertex


def test_unpickled_hierarchy_arrays_stay_read_only():
    hierarchy = lsm.build_hierarchy(_sphere(12), min_vertices=20)
    copy = pickle.loads(pickle.dumps(hierarchy))
    assert copy == hierarchy
    arrays = [copy.vertices, *copy.triangles, *copy.representatives, *copy.parents, *copy.rings]
    assert arrays and not any(a.flags.writeable for a in arrays)
    with pytest.raises(ValueError, match="read-only"):
        copy.vertices[0, 0] = 1.0


def test_add_anchors_and_solve_on_other_threads_see_whole_updates():
    # every solve() running while anchors are added must return the solution of some whole state:
    # compare with the states of a solver that adds the same anchors on one thread
    mesh = _sphere(16)
    n = len(mesh.vertices)
    batches = [np.arange(10 + 7 * i, 13 + 7 * i) for i in range(12)]
    reference = lsm.LSMeshSolver(mesh, [0, 1, 2])
    states = [reference.solve()]
    for batch in batches:
        reference.add_anchors(batch, weights=10.0 * n)
        states.append(reference.solve())

    solver = lsm.LSMeshSolver(mesh, [0, 1, 2])
    results, errors = [], []
    stop = threading.Event()

    def solve_loop():
        try:
            while not stop.is_set():
                results.append(solver.solve())
        except Exception as error:
            errors.append(error)

    threads = [threading.Thread(target=solve_loop) for _ in range(3)]
    for thread in threads:
        thread.start()
    try:
        for batch in batches:
            solver.add_anchors(batch, weights=10.0 * n)
    finally:
        stop.set()
        for thread in threads:
            thread.join()
    assert not errors, errors
    assert results
    for result in results:
        assert any(np.allclose(result, state, rtol=0, atol=1e-9) for state in states)
    np.testing.assert_allclose(solver.solve(), states[-1], rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- class 6: wrong types


@pytest.mark.parametrize(
    "call, match",
    [
        (
            lambda m: lsm.ls_mesh(m, [0, 5], weights="2"),
            r"weights must be a positive number or an array, got '2'",
        ),
        (lambda m: lsm.ls_mesh(m, [0, 5], weights=True), r"weights must be a positive number"),
        (
            lambda m: lsm.ls_mesh(m, [0, 5], weights=np.array([1 + 0j, 2])),
            r"weights must be .* real numbers, got dtype complex",
        ),
        (
            lambda m: lsm.ls_mesh(m, [0, 5], weights=np.array([True, True])),
            r"weights must be .* real numbers, got dtype bool",
        ),
        (
            lambda m: lsm.ls_mesh(m, [0, 5], [["1", "2", "3"], ["4", "5", "6"]]),
            r"constraint_vertex_positions must .* got dtype <U1",
        ),
        (
            lambda m: lsm.ls_mesh(m, [0, 5], np.ones((2, 3), complex)),
            r"constraint_vertex_positions must .* got dtype complex",
        ),
        (
            lambda m: lsm.ls_mesh(m, [0, 5], np.ones((2, 3), bool)),
            r"constraint_vertex_positions must .* got dtype bool",
        ),
        (
            lambda m: lsm.LSMeshSolver(m, [0, 5]).solve(refine="no"),
            r"refine must be a bool or None, got str 'no'",
        ),
        (lambda m: lsm.LSMeshSolver(m, [0, 5]).solve(refine=1), r"refine must be a bool or None, got int"),
        (lambda m: lsm.LSMeshSolver(m, [0, 5], interpolate="yes"), r"interpolate must be a bool, got str"),
        (
            lambda m: lsm.reconstruct_geometry(m, [0, 5], interpolate=0),
            r"interpolate must be a bool, got int",
        ),
        (
            lambda m: lsm.LSMeshSolver(m, [0, 5]).add_anchors([7], weights="3"),
            r"weights must be a positive number",
        ),
        (
            lambda m: lsm.LSMeshSolver(m, [0, 5]).add_anchors([7], [["a", "b", "c"]]),
            r"positions must .* got dtype <U1",
        ),
        (lambda m: metrics.surface_distance(m, m, seed="0"), r"seed must be an integer, got '0'"),
        (lambda m: metrics.surface_distance(m, m, seed=1.5), r"seed must be an integer, got 1.5"),
        (
            lambda m: lsm.render(m, None, up="up", backend="raycast"),
            r"up must be a sequence of 3 numbers, got 'up'",
        ),
        (
            lambda m: lsm.render(m, None, background=[1, 1, 1j], backend="raycast"),
            r"background must .* got dtype complex",
        ),
    ],
)
def test_wrong_types_are_a_type_error(call, match):
    with pytest.raises(TypeError, match=match):
        call(_sphere())


# --------------------------------------------------------------------------- class 7: absurd sizes


def test_negative_seed_is_named():
    with pytest.raises(ValueError, match="seed must be >= 0, got -1"):
        metrics.surface_distance(_sphere(), _sphere(), seed=-1)


def test_absurd_sample_count_is_refused_with_the_limit():
    with pytest.raises(
        ValueError, match=rf"number_of_points must be <= {metrics.MAX_SAMPLE_POINTS}, got 10000000000"
    ):
        metrics.surface_distance(_sphere(), _sphere(), number_of_points=10**10)
    # the limit itself is accepted by the check (the sampling is not run here: 10 million points)
    assert metrics.MAX_SAMPLE_POINTS >= 1_000_000


def test_absurd_index_counts_are_refused_before_allocating():
    n = len(_sphere().vertices)
    with pytest.raises(ValueError, match=rf"k must be <= {n}, got 10000000000"):
        lsm.spectral_approximation(_sphere(), 10**10)
    with pytest.raises(ValueError, match=rf"count must be <= {n}, got 10000000000"):
        lsm.approximate(_sphere(), 10**10)


# --------------------------------------------------------------------------- class 8: messages that name the right thing


def test_messages_name_the_argument_at_fault():
    sphere = _sphere()
    with pytest.raises(TypeError, match=r"^meshes\[1\] must be an open3d"):
        lsm.render([sphere, "x"], None, backend="raycast")
    with pytest.raises(TypeError, match=r"^color must be a sequence of 3 numbers, got 'red'"):
        lsm.render(sphere, None, color="red", backend="raycast")
    with pytest.raises(
        ValueError, match=r"constraint_vertex_indices must lie in \[0, \d+\), got 18446744073709551615"
    ):
        lsm.ls_mesh(sphere, np.array([3, 2**64 - 1], dtype=np.uint64))
    n = len(sphere.vertices)
    for interpolate in (True, False):
        with pytest.raises(lsm.SingularSystemError, match=r"known vertex \(outside unknown_vertex_indices\)"):
            lsm.reconstruct_geometry(sphere, np.arange(n), interpolate=interpolate)


def test_normal_deviation_leaves_out_zero_area_triangles():
    # two triangles with area and one needle of zero area: identical meshes deviate by 0 degrees, not 30
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.5], [2, 0, 0]], dtype=float)
    triangles = np.array([[0, 1, 2], [1, 3, 2], [0, 1, 4]])
    assert metrics.normal_deviation((vertices, triangles), (vertices, triangles)) == 0.0
    # tilted by 90 degrees in one triangle of two with area: the mean is 45 degrees
    moved = vertices.copy()
    moved[3] = [0.5, 0.5, 1.0]  # triangle 1 now stands upright
    expected = np.degrees(
        np.arccos(
            np.dot(
                *[
                    np.cross(v[3] - v[1], v[2] - v[1]) / np.linalg.norm(np.cross(v[3] - v[1], v[2] - v[1]))
                    for v in (vertices, moved)
                ]
            )
        )
    )
    assert metrics.normal_deviation((vertices, triangles), (moved, triangles)) == pytest.approx(
        expected / 2, rel=1e-12
    )
    flat = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], dtype=float)
    with pytest.raises(ValueError, match="a and b must share a triangle of non-zero area"):
        metrics.normal_deviation((flat, [[0, 1, 2]]), (flat, [[0, 1, 2]]))


# --------------------------------------------------------------------------- the probe: every public option x wrong values


def _probe_cases():
    sphere = _sphere()
    data = lsm.encode_geometry(sphere, 10)
    return [
        (lsm.laplacian, (sphere,), {}, ["kind"]),
        (
            lsm.LSMeshSolver,
            (sphere, [0, 5]),
            {},
            ["weights", "interpolate", "laplacian", "backend", "ordering"],
        ),
        (
            lsm.ls_mesh,
            (sphere,),
            {"constraint_vertex_indices": [0, 5]},
            [
                "constraint_vertex_indices",
                "constraint_vertex_positions",
                "weights",
                "interpolate",
                "laplacian",
                "progress",
            ],
        ),
        (
            lsm.reconstruct_geometry,
            (sphere,),
            {"unknown_vertex_indices": [0, 5]},
            ["unknown_vertex_indices", "interpolate", "weights", "laplacian", "progress"],
        ),
        (
            lsm.select_control_points,
            (sphere,),
            {"count": 5},
            ["count", "method", "batch", "weights", "seed", "progress"],
        ),
        (
            lsm.approximate,
            (sphere,),
            {"count": 5},
            ["count", "method", "weights", "interpolate", "batch", "seed", "progress"],
        ),
        (lsm.encode_geometry, (sphere,), {"count": 5}, ["count", "bits", "method", "weight", "progress"]),
        (lsm.decode_geometry, (sphere,), {"data": data}, ["data", "anchors", "progress"]),
        (
            lambda m, **k: list(lsm.iter_decode_geometry(m, **k)),
            (sphere,),
            {"data": data},
            ["step", "progress"],
        ),
        (lsm.spectral_approximation, (sphere,), {"k": 5}, ["k", "bits", "progress"]),
        (
            lsm.constrained_fairing,
            (sphere,),
            {"number_of_iterations": 2},
            ["number_of_iterations", "method", "mu", "smooth_boundary", "reimpose_every", "progress"],
        ),
        (lsm.smooth_boundary_curves, (sphere,), {"number_of_iterations": 2}, ["number_of_iterations"]),
        (
            lsm.multiresolution_fairing,
            (sphere,),
            {"level": 1},
            ["level", "hierarchy", "number_of_iterations", "method", "progress"],
        ),
        (lsm.build_hierarchy, (sphere,), {}, ["alpha", "beta", "min_vertices", "max_levels", "progress"]),
        (lsm.from_fast_simplification, (sphere,), {}, ["levels", "min_vertices", "agg", "progress"]),
        (
            lsm.render,
            (sphere, None),
            {"backend": "raycast", "width": 16, "height": 16},
            [
                "width",
                "height",
                "reference",
                "error_max",
                "color",
                "background",
                "view_direction",
                "up",
                "margin",
                "align",
                "backend",
                "timeout",
            ],
        ),
        (metrics.surface_distance, (sphere, sphere), {"number_of_points": 100}, ["number_of_points", "seed"]),
    ]


_WRONG = {
    "a string": "2",
    "a complex array": np.array([1j, 2j]),
    "NaN": float("nan"),
    "a list of strings": ["a", "b"],
}


def test_every_public_option_refuses_wrong_values_by_name():
    # for every option of every public function: a string, a complex array, NaN and a list of strings are
    # refused with TypeError or ValueError whose message names the option (never accepted, never another error)
    failures = []
    for function, args, base, params in _probe_cases():
        for param in params:
            for label, value in _WRONG.items():
                kwargs = {**base, param: value}
                name = getattr(function, "__name__", "iter_decode_geometry")
                try:
                    function(*args, **kwargs)
                    failures.append(f"{name}({param}={label}) accepted")
                except (TypeError, ValueError) as error:
                    if param not in str(error):
                        failures.append(f"{name}({param}={label}): message does not name it: {error}")
                except Exception as error:
                    failures.append(f"{name}({param}={label}) raised {type(error).__name__}: {error}")
    assert not failures, "\n".join(failures)


def test_open3d_tensors_as_indices_and_positions_are_checked_like_arrays():
    # the tensor API's users pass o3d.core.Tensor arguments: same answers and same errors as numpy arrays
    sphere = _sphere()
    reference = _vertices_of(lsm.ls_mesh(sphere, [0, 5], [[0, 0, 2], [1, 0, 0]]))
    out = lsm.ls_mesh(
        sphere,
        o3d.core.Tensor(np.array([0, 5], dtype=np.int32)),
        o3d.core.Tensor(np.array([[0, 0, 2], [1, 0, 0]], dtype=np.float32)),
    )
    np.testing.assert_allclose(_vertices_of(out), reference, rtol=0, atol=1e-12)
    with pytest.raises(TypeError, match="constraint_vertex_indices must have an integer dtype, got float64"):
        lsm.ls_mesh(sphere, o3d.core.Tensor(np.array([0.0, 5.0])))
    with pytest.raises(ValueError, match=r"constraint_vertex_positions must have shape \(2, 3\), got \(6,\)"):
        lsm.ls_mesh(sphere, [0, 5], o3d.core.Tensor(np.zeros(6)))
    with pytest.raises(TypeError, match="constraint_vertex_positions must .* real numbers, got dtype bool"):
        lsm.ls_mesh(sphere, [0, 5], o3d.core.Tensor(np.zeros((2, 3), dtype=bool)))
