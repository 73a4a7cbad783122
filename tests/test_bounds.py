"""Iteration counts: bounded everywhere by ``core.validate.MAX_ITERATIONS``; an iteration count on the default
(one-solve) scan energy means the iterative local operator, and ``method="scan"`` refuses more than one solve."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import grid

from o3d_lsmesh import constrained_fairing, multiresolution_fairing, smooth_boundary_curves
from o3d_lsmesh.app.cli import main
from o3d_lsmesh.core.validate import MAX_ITERATIONS, as_iterations
from o3d_lsmesh.fairing.boundary_curve import smooth_boundary_curves_arrays
from o3d_lsmesh.fairing.constrained import constrained_fairing_arrays

TOO_MANY = f"number_of_iterations must be <= {MAX_ITERATIONS}, got 1000000000"


def _mesh():
    return grid(6, 6, z=lambda x, y: 0.1 * np.sin(4 * x + 3 * y))


def test_as_iterations_bounds_and_names():
    assert as_iterations(MAX_ITERATIONS) == MAX_ITERATIONS and as_iterations(0) == 0
    with pytest.raises(
        ValueError, match=f"final_iterations must be <= {MAX_ITERATIONS}, got {MAX_ITERATIONS + 1}"
    ):
        as_iterations(MAX_ITERATIONS + 1, name="final_iterations")
    with pytest.raises(ValueError, match="number_of_iterations must be >= 0, got -1"):
        as_iterations(-1)


@pytest.mark.parametrize("method", ["local", "global", None])
def test_every_fairing_method_refuses_a_huge_count(method):
    V, F = _mesh()
    with pytest.raises(ValueError, match=TOO_MANY):
        constrained_fairing((V, F), 10**9, method=method)
    with pytest.raises(ValueError, match=TOO_MANY):
        constrained_fairing_arrays(V, F, 10**9, method=method)


def test_boundary_curves_and_multiresolution_refuse_a_huge_count():
    V, F = _mesh()
    with pytest.raises(ValueError, match=TOO_MANY):
        smooth_boundary_curves((V, F), 10**9)
    with pytest.raises(ValueError, match=TOO_MANY):
        smooth_boundary_curves_arrays(V, F, 10**9)
    with pytest.raises(ValueError, match=TOO_MANY):
        multiresolution_fairing((V, F), 1, number_of_iterations=10**9)
    with pytest.raises(ValueError, match=f"final_iterations must be <= {MAX_ITERATIONS}"):
        multiresolution_fairing((V, F), 1, final_iterations=10**9)


def test_cli_refuses_a_huge_count(tmp_path, capsys):
    import open3d as o3d

    V, F = _mesh()
    source = tmp_path / "in.ply"
    o3d.io.write_triangle_mesh(
        str(source), o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F))
    )
    assert main(["denoise", str(source), str(tmp_path / "out.ply"), "--iterations", str(10**9)]) == 2
    err = capsys.readouterr().err
    assert f"--iterations must be <= {MAX_ITERATIONS}" in err and not (tmp_path / "out.ply").exists()


def test_an_iteration_count_without_a_method_means_the_local_operator():
    V, F = _mesh()
    assert np.array_equal(
        constrained_fairing_arrays(V, F, 5, method=None), constrained_fairing_arrays(V, F, 5, method="local")
    )
    # no count: the one-solve scan energy
    assert np.array_equal(
        constrained_fairing_arrays(V, F, None, method=None),
        constrained_fairing_arrays(V, F, 1, method="scan"),
    )


def test_scan_refuses_re_taken_solves_and_points_to_local():
    V, F = _mesh()
    with pytest.raises(
        ValueError, match=r"number_of_iterations must be 0 or 1 for method='scan'.*method='local'"
    ):
        constrained_fairing((V, F), 10, method="scan")
    assert np.array_equal(constrained_fairing_arrays(V, F, 0, method="scan"), V)
