"""The SciPy fallback of the solver gateway: SPD-set SuperLU, the opt-out variable and the warning's location."""

import subprocess
import sys
import warnings

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from conftest import PACKAGE_HOME, REPO, grid

import o3d_lsmesh
import o3d_lsmesh.core.solve as solvers
from o3d_lsmesh import O3DLSMeshWarning, ls_mesh
from o3d_lsmesh.core._iterative import splu_spd


def test_fallback_warning_points_at_the_users_call_once_per_process(monkeypatch):
    monkeypatch.setattr(solvers, "_cholmod", None)
    monkeypatch.setattr(solvers, "_fallback_warned", False)  # as in a fresh process
    monkeypatch.delenv(solvers.NO_CHOLMOD_ENV, raising=False)
    V, F = grid(6, 6)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        line = sys._getframe().f_lineno + 1  # the call's own line, the next one
        ls_mesh((V, F), [0, 7])
        # further solvers, from other lines and other functions, each of which factors: no repeat
        ls_mesh((V, F), [0, 9])
        encoded = o3d_lsmesh.encode_geometry((V, F), 6)
        list(o3d_lsmesh.iter_decode_geometry((V, F), encoded, step=2))
        o3d_lsmesh.approximate((V, F), 5, interpolate=True)
    ours = [w for w in caught if issubclass(w.category, O3DLSMeshWarning)]
    assert len(ours) == 1
    assert ours[0].filename == __file__ and ours[0].lineno == line
    assert "O3D_LSMESH_NO_CHOLMOD=1" in str(ours[0].message)


def test_fallback_warns_once_in_a_fresh_process_running_several_operations():
    code = (
        "import sys, warnings; sys.modules['sksparse'] = None\n"
        "import o3d_lsmesh\n"
        "from o3d_lsmesh.app.shapes import demo_mesh\n"
        "mesh = demo_mesh(2)\n"
        "o3d_lsmesh.approximate(mesh, 30)\n"
        "list(o3d_lsmesh.iter_decode_geometry(mesh, o3d_lsmesh.encode_geometry(mesh, 30), step=10))\n"
        "o3d_lsmesh.fill_holes(mesh)\n"
    )
    # the package the suite imports (in `make matrix` the installed wheel, whose kernels are compiled)
    env = {"PYTHONPATH": PACKAGE_HOME, "PATH": "/usr/bin:/bin"}
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True, cwd=PACKAGE_HOME
    )
    assert out.stderr.count("scikit-sparse is not importable") == 1, out.stderr


def test_the_environment_variable_chooses_scipy_without_warning(monkeypatch):
    monkeypatch.setattr(solvers, "_cholmod", None)
    monkeypatch.setenv(solvers.NO_CHOLMOD_ENV, "1")
    A = (sp.random(50, 50, density=0.1, random_state=0) + sp.identity(50)).tocsc()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        solver = solvers.SPDSolver((A @ A.T).tocsc())
    assert solver.backend == "scipy"
    with pytest.raises(ImportError, match="O3D_LSMESH_NO_CHOLMOD is set"):
        solvers.SPDSolver((A @ A.T).tocsc(), backend="cholmod")


@pytest.mark.parametrize(
    "value, disabled", [("1", True), ("yes", True), ("0", False), ("", False), ("false", False)]
)
def test_environment_values(monkeypatch, value, disabled):
    monkeypatch.setenv(solvers.NO_CHOLMOD_ENV, value)
    assert solvers._cholmod_disabled() is disabled


def test_the_variable_is_read_at_import():
    code = "import o3d_lsmesh.core.solve as s; print(s.cholmod_available())"
    env = {"O3D_LSMESH_NO_CHOLMOD": "1", "PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_spd_superlu_equals_partial_pivoting_and_does_not_pivot():
    # the LS-mesh normal matrix of a bumpy grid: SPD, diagonally heavy
    from o3d_lsmesh.laplacian import laplacian_matrix

    V, F = grid(40, 40, z=lambda x, y: np.sin(5 * x) * np.cos(3 * y))
    L = laplacian_matrix(V, F).tocsc()
    W = sp.diags(np.where(np.arange(len(V)) % 29 == 0, 1.0, 0.0))
    N = (L.T @ L + W).tocsc()
    b = W @ V
    fast = splu_spd(N)
    reference = spla.splu(N, permc_spec="MMD_AT_PLUS_A").solve(b)
    np.testing.assert_allclose(fast.solve(b), reference, rtol=1e-9, atol=1e-12)
    # symmetric ordering without pivoting: rows and columns get the same permutation
    np.testing.assert_array_equal(fast.perm_r, fast.perm_c)
    # and the fill is that of a symmetric factorization: U has the pattern of L^T
    assert abs(fast.U.nnz - fast.L.nnz) <= N.shape[0]
