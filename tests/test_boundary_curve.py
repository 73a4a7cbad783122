"""Boundary-curve fairing (Liu et al. 2001, section 3.3) against plain loops and closed-form responses."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from conftest import grid, load_mesh
from numpy.testing import assert_allclose

from o3d_lsmesh.fairing import smooth_boundary_curves, smooth_boundary_curves_arrays
from o3d_lsmesh.fairing.boundary_curve import curve_operator
from o3d_lsmesh.topology import boundary_halfedges, boundary_loops

TIGHT = 1e-12


def fan(points: np.ndarray):
    """A disk: centre vertex 0 joined to the closed polygon ``points`` (vertices 1..l), one boundary loop."""
    l = len(points)
    vertices = np.vstack([points.mean(axis=0), points])
    ring = np.arange(1, l + 1)
    triangles = np.stack([np.zeros(l, dtype=np.int64), ring, np.roll(ring, -1)], axis=1)
    return vertices, triangles


def paper_curve_step(curve: np.ndarray, curve0: np.ndarray) -> np.ndarray:
    """One step written from the paper: relax every segment with its midpoint held, average the two estimates."""
    l = len(curve)
    total = np.zeros_like(curve)
    count = np.zeros(l)
    relax = np.array([[2 / 3, 1 / 3], [1 / 3, 2 / 3]])
    for i in range(l):  # segment (p_{i-1}, p_i)
        outer = np.array([curve[(i - 2) % l], curve[(i + 1) % l]])
        d = 0.5 * ((curve0[(i - 1) % l] + curve0[i]) - (outer[0] + outer[1]))
        new = relax @ outer + d
        total[(i - 1) % l] += new[0]
        total[i] += new[1]
        count[(i - 1) % l] += 1
        count[i] += 1
    return total / count[:, None]


def test_one_step_equals_plain_loop_of_the_paper(rng):
    points = rng.normal(size=(11, 3))
    V, F = fan(points)
    out = smooth_boundary_curves_arrays(V, F, 1)
    loop = boundary_loops(F, len(V))[0]
    assert_allclose(out[loop], paper_curve_step(V[loop], V[loop]), atol=TIGHT)
    assert_allclose(out[0], V[0], atol=0)  # the interior vertex does not move


def test_several_steps_equal_plain_loop_with_fixed_targets(rng):
    V, F = fan(rng.normal(size=(9, 3)))
    loop = boundary_loops(F, len(V))[0]
    curve = V[loop]
    for _ in range(4):
        curve = paper_curve_step(curve, V[loop])
    assert_allclose(smooth_boundary_curves_arrays(V, F, 4)[loop], curve, atol=TIGHT)


def test_regular_polygon_shrinks_by_the_closed_form_factor():
    # the fundamental mode e^{i w k}, w = 2 pi / l, is scaled by (cos w - cos 2w)/6 + (1 + cos w)/2 in one step
    l = 24
    w = 2 * np.pi / l
    angles = w * np.arange(l)
    V, F = fan(np.stack([np.cos(angles), np.sin(angles), np.zeros(l)], axis=1))
    out = smooth_boundary_curves_arrays(V, F, 1)
    factor = (np.cos(w) - np.cos(2 * w)) / 6 + (1 + np.cos(w)) / 2
    assert_allclose(np.linalg.norm(out[1:, :2], axis=1), factor, atol=TIGHT)


def test_straight_evenly_spaced_boundary_is_kept():
    V, F = grid(9, 9)
    out = smooth_boundary_curves_arrays(V, F, 1)
    # one step reaches two vertices along the loop: x = 0.25 .. 0.75 does not see the corner
    edge_middle = (V[:, 1] == 0) & (V[:, 0] > 0.2) & (V[:, 0] < 0.8)
    assert edge_middle.sum() == 5
    assert_allclose(out[edge_middle], V[edge_middle], atol=TIGHT)
    assert not np.allclose(out[0], V[0])  # the corner (0, 0) is rounded off
    assert_allclose(out[:, 2], 0.0, atol=0)


def test_closed_mesh_and_interior_vertices_are_unchanged(sphere):
    V = np.asarray(sphere.vertices)
    assert_allclose(np.asarray(smooth_boundary_curves(sphere, 5).vertices), V, atol=0)
    Vg, Fg = grid(6, 6)
    Vg = Vg + np.random.default_rng(3).normal(0, 0.02, Vg.shape)
    out = smooth_boundary_curves_arrays(Vg, Fg, 5)
    boundary = np.zeros(len(Vg), dtype=bool)
    boundary[boundary_halfedges(Fg).ravel()] = True
    assert_allclose(out[~boundary], Vg[~boundary], atol=0)
    assert np.abs(out[boundary] - Vg[boundary]).max() > 1e-3


def test_triangle_loops_are_held_fixed():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    out = smooth_boundary_curves_arrays(V, np.array([[0, 1, 2]]), 3)
    assert_allclose(out, V, atol=0)


def grid_with_holes():
    """9x9 grid with the triangles around vertices 20 and 60 removed: 3 loops of known order and size."""
    V, F = grid(9, 9)
    keep = ~np.isin(F, [20, 60]).any(axis=1)
    return V, F[keep]


def test_loops_of_a_grid_with_two_holes_are_found_in_order():
    V, F = grid_with_holes()
    loops = boundary_loops(F, len(V))
    assert sorted(len(loop) for loop in loops) == [6, 6, 32]
    assert [int(loop[0]) for loop in loops] == sorted(int(loop.min()) for loop in loops)
    hole = next(loop for loop in loops if 20 not in loop and len(loop) == 6 and loop.min() < 20)
    assert set(hole.tolist()) == {10, 11, 19, 21, 29, 30}  # the 1-ring of vertex 20 (diagonals run +10)
    _assert_operator_walks_the_boundary(F, len(V), loops)


def _assert_operator_walks_the_boundary(F, n, loops):
    op = curve_operator(loops)
    bhe = boundary_halfedges(F, n)
    assert sorted(op.vertex.tolist()) == sorted(set(bhe.ravel().tolist()))  # every boundary vertex moves once
    # each row reads the vertex's loop neighbours one and two steps away (weights +1/12 and -1/12 each)
    for loop in loops:
        for i, v in enumerate(loop.tolist()):
            row = op.moving.getrow(int(np.searchsorted(op.vertex, v)))
            read = dict(zip(op.support[row.indices].tolist(), (12 * row.data).round().tolist()))
            expected = {}
            for step, weight in ((1, 1), (-1, 1), (2, -1), (-2, -1)):
                w = int(loop[(i + step) % len(loop)])
                expected[w] = expected.get(w, 0) + weight
            assert read == {k: float(w) for k, w in expected.items() if w}


def test_loops_of_plane_with_holes_real_mesh():
    mesh = load_mesh("plane_holes.ply")
    F = np.asarray(mesh.triangles).astype(np.int64)
    n = len(mesh.vertices)
    loops = boundary_loops(F, n)
    assert len(loops) == 27
    assert sum(len(loop) for loop in loops) == 341
    _assert_operator_walks_the_boundary(F, n, loops)
    out = smooth_boundary_curves(mesh, 3)
    assert np.isfinite(np.asarray(out.vertices)).all()


def test_zero_iterations_copy_and_kinds(sphere):
    V, F = grid_with_holes()
    out = smooth_boundary_curves((V, F), 0)
    assert out[0] is not V and np.array_equal(out[0], V)
    tensor = o3d.t.geometry.TriangleMesh.from_legacy(o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32))))
    result = smooth_boundary_curves(tensor, 2)
    assert isinstance(result, o3d.t.geometry.TriangleMesh)
    assert_allclose(result.vertex.positions.numpy(), smooth_boundary_curves_arrays(V, F, 2), atol=1e-6)


def test_reimpose_every_one_equals_chained_single_steps(rng):
    V, F = fan(rng.normal(size=(10, 3)))
    chained = V
    for _ in range(3):
        chained = smooth_boundary_curves_arrays(chained, F, 1)
    assert_allclose(smooth_boundary_curves_arrays(V, F, 3, reimpose_every=1), chained, atol=TIGHT)


def test_raises():
    V, F = grid(4, 4)
    with pytest.raises(ValueError, match="number_of_iterations must be >= 0, got -1"):
        smooth_boundary_curves((V, F), -1)
    with pytest.raises(TypeError, match="number_of_iterations must be an integer, got 2.0"):
        smooth_boundary_curves((V, F), 2.0)
    with pytest.raises(TypeError, match="number_of_iterations must be an integer"):
        smooth_boundary_curves_arrays(V, F, True)
    with pytest.raises(ValueError, match="reimpose_every must be >= 1, got 0"):
        smooth_boundary_curves_arrays(V, F, 2, reimpose_every=0)
    with pytest.raises(TypeError, match="mesh must be an open3d"):
        smooth_boundary_curves("not a mesh", 2)


def test_fin_and_bowtie_boundaries_are_smoothed_with_their_junctions_fixed(rng):
    V, F = grid(4, 4)
    # a third and fourth triangle on edge (0, 1): vertices 0 and 1 are fin junctions
    extra = np.vstack([V, [[0.5, -0.5, 0.3]]])
    F2 = np.vstack([F, [[0, 1, 16], [1, 0, 16]]])
    noisy = extra + rng.normal(0, 0.01, extra.shape)
    out = smooth_boundary_curves_arrays(noisy, F2, 3)
    assert np.isfinite(out).all() and np.array_equal(out[[0, 1]], noisy[[0, 1]])
    assert np.abs(out - noisy).max() > 1e-4  # the rest of the outer loop is smoothed
    # two triangles touching at vertex 0 only: a boundary bow-tie; every chain is a triangle's rim, held
    bow = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0.0]])
    assert_allclose(smooth_boundary_curves_arrays(bow, np.array([[0, 1, 2], [0, 3, 4]]), 1), bow, atol=0)
