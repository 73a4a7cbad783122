"""Every raise of the core's checks, reached once: the class, the parameter it names, the message.

A table of calls, one row per ``raise`` in ``core/validate.py``, ``core/solve.py``, ``core/_direct.py`` and
``core/_iterative.py``: an :class:`InputError` names its parameter in
``param``, an :class:`InputTypeError` is also a ``TypeError``.
"""

import pickle
import warnings

import numpy as np
import pytest
import scipy.sparse as sp

from o3d_lsmesh.core import solve
from o3d_lsmesh.core import validate as v
from o3d_lsmesh.core._iterative import block_cg
from o3d_lsmesh.core.errors import (
    ConvergenceError,
    InputError,
    InputTypeError,
    SingularSystemError,
    called_from_outside,
    warn,
)
from o3d_lsmesh.core.solve import Plan, SPDSolver

TRI = [[0, 1, 2]]
V3 = [[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]
EYE = sp.identity(3, format="csc")
ORDER = {"a": {"k": v.Option(v.as_count, 1)}, "b": {"j": v.Option(why="only for a")}}


def spd(lower=False):
    return SPDSolver(EYE * 2.0, backend="scipy")


VALIDATE = [
    # (call, class, param, message)
    (
        lambda: v.mesh_arrays(np.zeros((0, 3)), np.zeros((0, 3), int)),
        InputError,
        "mesh",
        "must have vertices",
    ),
    (lambda: v.mesh_arrays(V3, np.zeros((0, 3), int)), InputError, "mesh", "must have triangles"),
    (lambda: v.mesh_arrays([[0, 0, np.nan], *V3[1:]], TRI), InputError, "mesh", "vertices must be finite"),
    (lambda: v.mesh_arrays([[0, 0, 1e31], *V3[1:]], TRI), InputError, "mesh", "magnitude at most"),
    (lambda: v.mesh_arrays(V3, [[0, 0, 1]]), InputError, "mesh", "three distinct vertices"),
    (lambda: v.as_vertex_array("abc", name="target"), InputTypeError, "target", "target vertices must be"),
    (lambda: v.as_vertex_array([[0, 0], [1]], name="m"), InputTypeError, "m", "m vertices must be"),
    (lambda: v.as_vertex_array([[True] * 3]), InputTypeError, "mesh", "of real numbers"),
    (lambda: v.as_vertex_array(np.zeros((2, 2))), InputError, "mesh", r"shape \(n, 3\)"),
    (lambda: v.as_triangle_array(np.zeros((1, 3)), 3), InputTypeError, "mesh", "integer array, got dtype"),
    (lambda: v.as_triangle_array(np.zeros((1, 2), int), 3), InputError, "mesh", r"shape \(m, 3\)"),
    (lambda: v.as_triangle_array([[0, 1, 5]], 3), InputError, "mesh", r"lie in \[0, 3\)"),
    (lambda: v.as_bool(1, name="flag"), InputTypeError, "flag", "must be a bool"),
    (lambda: v.as_real_vector([1, 2], 3, name="color"), InputError, "color", "sequence of 3 numbers"),
    (lambda: v.as_real_vector([1, 2, 9], 3, name="color", low=0, high=1), InputError, "color", "entries in"),
    (lambda: v.as_indices([[1]], 3, name="ix"), InputError, "ix", "one-dimensional"),
    (lambda: v.as_indices([], 3, name="ix"), InputError, "ix", "at least one"),
    (lambda: v.as_indices([1.0], 3, name="ix"), InputTypeError, "ix", "astype"),
    (lambda: v.as_indices(["a"], 3, name="ix"), InputTypeError, "ix", "integer vertex indices"),
    (lambda: v.as_indices([7], 3, name="ix"), InputError, "ix", "position 0"),
    (lambda: v.as_indices([1, 1], 3, name="ix"), InputError, "ix", "repeat"),
    (lambda: v.as_positions(np.zeros((2, 3)), 3, name="p"), InputError, "p", r"shape \(3, 3\)"),
    (lambda: v.as_positions(np.full((1, 3), np.inf), 1, name="p"), InputError, "p", "finite"),
    (lambda: v.as_positions(np.full((1, 3), 1e31), 1, name="p", limit=True), InputError, "p", "magnitude"),
    (lambda: v.as_weights(True, 3), InputTypeError, "weights", "positive number"),
    (lambda: v.as_weights([1.0, 2.0], 3), InputError, "weights", r"shape \(3,\)"),
    (lambda: v.as_weights(-1.0, 3), InputError, "weights", "positive and finite"),
    (lambda: v.as_count(1.5, name="n"), InputTypeError, "n", "an integer"),
    (lambda: v.as_count(-1, name="n"), InputError, "n", ">= 0"),
    (lambda: v.as_count(5, name="n", maximum=4), InputError, "n", "<= 4"),
    (lambda: v.as_iterations(10**9), InputError, "number_of_iterations", "<= 10000"),
    (lambda: v.as_workers(0), InputError, "workers", ">= 1"),
    (lambda: v.as_positive_float("x", name="mu"), InputTypeError, "mu", "a number"),
    (lambda: v.as_positive_float(0.0, name="mu"), InputError, "mu", "positive and finite"),
    (lambda: v.as_choice(3, ["a"], name="kind"), InputTypeError, "kind", "one of"),
    (lambda: v.as_choice("b", ["a"], name="kind"), InputError, "kind", "one of"),
    (lambda: v.check_options(ORDER, "c", {}), InputError, "method", "method must be one of"),
    (lambda: v.check_options(ORDER, "b", {"k": 2}), InputError, "k", r"k does not apply to method='b'"),
    (lambda: v.check_options(ORDER, "a", {"j": 2}), InputError, "j", r"\(only for a\)"),
    (lambda: v.check_options(ORDER, "a", {"z": 2}), InputError, "z", "not an option of any method"),
    (lambda: v.check_options(ORDER, "a", {"k": 0.5}), InputTypeError, "k", "k must be an integer"),
]


def _cg(matrix, b, **options):
    return block_cg(sp.csr_matrix(matrix), np.asarray(b, float), None, lambda r: r, progress=False, **options)


SOLVE = [
    (lambda: SPDSolver(EYE, magic=1), InputTypeError, "magic", "unexpected keyword argument 'magic'"),
    (lambda: SPDSolver(EYE, _plan=Plan(product_of=EYE)), InputTypeError, "matrix", "exactly one of"),
    (
        lambda: SPDSolver(EYE, backend="iterative", _plan=Plan(locality_of=sp.identity(2))),
        InputError,
        "locality_of",
        "locality_of must have shape",
    ),
    (lambda: SPDSolver(EYE, _plan=Plan(pattern_of=sp.identity(2))), InputError, "pattern_of", "3 rows"),
    (
        lambda: SPDSolver(sp.csc_matrix([[1.0, 0], [0, 0]]), backend="scipy"),
        SingularSystemError,
        None,
        "non-singular",
    ),
    (
        lambda: SPDSolver(sp.csc_matrix(np.diag([1.0, 1e-320])), backend="scipy").solve(np.ones(2)),
        SingularSystemError,
        None,
        "numerically singular",
    ),
    (
        lambda: SPDSolver(_plan=Plan(product_of=EYE)).refactor(EYE),
        InputTypeError,
        "matrix",
        "factors a product",
    ),
    (lambda: spd().refactor(sp.identity(2, format="csc")), InputError, "matrix", r"shape \(3, 3\)"),
    (lambda: spd().solve(object()), InputTypeError, "rhs", "array of real numbers"),
    (lambda: spd().solve(np.ones(4)), InputError, "rhs", r"shape \(3,\) or \(3, k\)"),
    (lambda: spd().solve([1.0, np.nan, 1.0]), InputError, "rhs", "rhs must be finite"),
    (lambda: SPDSolver(EYE, backend="iterative").solve(np.ones(3), x0=np.ones(2)), InputError, "x0", "shape"),
    (
        lambda: SPDSolver(EYE, backend="iterative").solve(np.ones(3), x0=[np.nan] * 3),
        InputError,
        "x0",
        "finite",
    ),
    (lambda: spd().update(object()), InputTypeError, "c", "C must be a sparse matrix"),
    (lambda: spd().update(sp.csc_matrix((2, 1))), InputError, "c", "C must have 3 rows"),
    (lambda: spd().update(sp.csc_matrix([[np.inf], [0], [0]])), InputError, "c", "finite entries"),
    (
        lambda: solve.solve_spd(np.array([[1.0, 2.0], [2.0, 1.0]]), np.ones(2)),
        SingularSystemError,
        None,
        None,
    ),
    (lambda: solve.check_finite(np.array([1.0, np.inf]), name="w", what="w**2"), InputError, "w", "overflow"),
    (
        lambda: solve.check_constant_modes(
            np.array([1e-20, 1.0]), np.array([0, 1]), scale=1.0, name="weights", value=1e-10
        ),
        InputError,
        "weights",
        "too small",
    ),
    (lambda: SPDSolver(np.eye(3)), InputTypeError, "matrix", "scipy sparse matrix, got ndarray"),
    (lambda: SPDSolver(sp.csc_matrix(np.ones((2, 3)))), InputError, "matrix", "square"),
    (lambda: SPDSolver(EYE * 1j), InputTypeError, "matrix", "real entries"),
    (lambda: SPDSolver(EYE * np.nan), InputError, "matrix", "finite entries"),
    (
        lambda: SPDSolver(sp.csc_matrix(np.triu(np.ones((2, 2)))), lower=True),
        InputError,
        "matrix",
        "lower triangle",
    ),
    (lambda: SPDSolver(sp.csc_matrix([[2.0, 1.0], [0.0, 2.0]])), InputError, "matrix", "must be symmetric"),
    (lambda: SPDSolver(EYE, tol=0), InputError, "tol", r"tol must be a number in \(0, 1\)"),
    (
        lambda: SPDSolver(EYE, _plan=Plan(reduction="x")),
        InputTypeError,
        "reduction",
        "reduction must be None",
    ),
    (lambda: SPDSolver(EYE, _plan=Plan(reduction=2.0)), InputError, "reduction", "reduction must be None"),
    (lambda: SPDSolver(EYE, max_iterations=0), InputError, "max_iterations", "positive integer"),
    (lambda: SPDSolver(EYE, _plan=Plan(memory_budget=-1)), InputError, "memory_budget", "non-negative"),
    (
        lambda: SPDSolver(
            sp.csc_matrix([[1.0, 0], [0, 0]]), backend="iterative", _plan=Plan(preconditioner="ic0")
        ).solve(np.ones(2)),
        SingularSystemError,
        None,
        "symmetric positive definite",
    ),
    (
        lambda: SPDSolver(
            sp.csc_matrix([[1.0, 2.0], [2.0, -1.0]]), backend="iterative", _plan=Plan(preconditioner="ic0")
        ).solve(np.ones(2)),
        SingularSystemError,
        None,
        "breaks down",
    ),
    (
        lambda: _cg(sp.diags(np.linspace(1, 1e6, 50)), np.ones(50), tol=1e-14, max_iterations=1),
        ConvergenceError,
        None,
        "raise max_iterations",
    ),
    (
        lambda: _cg([[1.0, 0.0], [0.0, -1.0]], [0.0, 1.0], tol=1e-9, max_iterations=10),
        SingularSystemError,
        None,
        "non-positive curvature",
    ),
    (
        lambda: block_cg(
            sp.csr_matrix(np.eye(2)),
            np.ones(2),
            None,
            lambda r: r * np.nan,
            tol=1e-9,
            max_iterations=3,
            progress=False,
        ),
        SingularSystemError,
        None,
        "diverged",
    ),
]


@pytest.mark.parametrize(
    ("call", "kind", "param", "match"), VALIDATE + SOLVE, ids=range(len(VALIDATE + SOLVE))
)
def test_every_raise_names_its_parameter(call, kind, param, match):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        with pytest.raises(kind, match=match) as caught:
            call()
    if isinstance(caught.value, InputError):
        assert caught.value.param == param
    if issubclass(kind, InputTypeError):
        assert isinstance(caught.value, TypeError)


def test_the_memory_budget_variable_and_the_missing_cholmod(monkeypatch):
    monkeypatch.setenv("O3D_LSMESH_MEMORY_BUDGET", "lots")
    with pytest.raises(InputError, match="O3D_LSMESH_MEMORY_BUDGET must be a number"):
        solve.default_memory_budget()
    monkeypatch.setattr(solve, "_cholmod", None)
    with pytest.raises(ImportError, match="backend='cholmod' needs scikit-sparse"):
        SPDSolver(EYE, backend="cholmod")


@pytest.mark.skipif(not solve.cholmod_available(), reason="scikit-sparse is not installed")
def test_cholmod_reports_a_failing_pivot():
    with pytest.raises(SingularSystemError, match="failing pivot at column 1"):
        SPDSolver(sp.csc_matrix([[1.0, -1.0], [-1.0, 1.0]]), backend="cholmod")


def test_errors_pickle_with_their_parameter_and_warn_points_outside():
    error = pickle.loads(pickle.dumps(InputTypeError("k must be an integer", param="k")))
    assert isinstance(error, TypeError) and isinstance(error, ValueError) and error.param == "k"
    assert issubclass(SingularSystemError, InputError) and not issubclass(ConvergenceError, ValueError)
    with pytest.warns(UserWarning, match="look here") as record:
        warn("look here")
    assert record[0].filename == __file__
    assert called_from_outside()  # pytest's frames are outside the package
