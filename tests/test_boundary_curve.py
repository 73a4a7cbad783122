"""Boundary-curve fairing (Liu et al. 2001, section 3.3) against plain loops and closed-form responses."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from conftest import grid, load_mesh
from numpy.testing import assert_allclose

from o3d_lsmesh.core.boundary import (
    BoundaryCurves,
    boundary_chains,
    boundary_curves,
    boundary_halfedges,
    boundary_loops,
)
from o3d_lsmesh.fairing import smooth_boundary_curves, smooth_boundary_curves_arrays
from o3d_lsmesh.fairing.boundary_curve import curve_operator

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
    tensor = o3d.t.geometry.TriangleMesh.from_legacy(
        o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32))
        )
    )
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


def plain_estimates(curves, positions, positions0, held=(), closed=True):
    """The section 3.3 step written per segment with Python loops: every segment's estimates for its
    free ends, a held end keeping the midpoint alone; each vertex averages all its estimates."""
    total, count = {}, {}

    def add(v, p):
        total[v] = total.get(v, 0) + p
        count[v] = count.get(v, 0) + 1

    for curve in curves:
        c = [int(v) for v in curve]
        l = len(c)
        segments = range(l) if closed else range(l - 1)
        for j in segments:
            a, b = c[j], c[(j + 1) % l]
            mid2 = positions0[a] + positions0[b]
            if a in held and b in held:
                continue
            if a in held:
                add(b, mid2 - positions[a])
            elif b in held:
                add(a, mid2 - positions[b])
            else:
                oa, ob = positions[c[(j - 1) % l]], positions[c[(j + 2) % l]]
                add(a, (oa - ob) / 6 + mid2 / 2)
                add(b, (ob - oa) / 6 + mid2 / 2)
    out = positions.copy()
    for v in total:
        out[v] = total[v] / count[v]
    return out


def pinched_grid(rng):
    """5x5 grid with cells (1,1) and (2,2) removed: their rim is one loop through vertex 12 twice."""
    V, F = grid(5, 5)
    F = F[[not (set(t) <= {6, 7, 11, 12} or set(t) <= {12, 13, 17, 18}) for t in F.tolist()]]
    return V + rng.normal(0, 0.02, V.shape), F


def test_pinch_vertex_averages_its_estimates_from_every_passage(rng):
    V, F = pinched_grid(rng)
    loops = boundary_loops(F, len(V))
    assert [loop.tolist().count(12) for loop in loops] == [0, 2]
    out = smooth_boundary_curves_arrays(V, F, 1)
    assert_allclose(out, plain_estimates(loops, V, V), atol=TIGHT)
    assert np.abs(out[12] - V[12]).max() > 1e-4  # the pinch moves
    # two steps with fixed targets
    expected = plain_estimates(loops, plain_estimates(loops, V, V), V)
    assert_allclose(smooth_boundary_curves_arrays(V, F, 2), expected, atol=TIGHT)


def test_chains_at_a_fin_hold_their_ends(rng):
    # a strip of 6 cells plus a third triangle on the interior edge (1, 8): the outer boundary runs into
    # the fin's edge at vertices 1 and 8 and becomes open chains held there
    V, F = grid(7, 2)
    V = np.vstack([V, [[0.2, 0.5, 0.4]]]) + rng.normal(0, 0.02, (15, 3))
    F = np.vstack([F, [[1, 8, 14]]])
    curves = boundary_curves(F, len(V))
    assert curves.loops == [] and curves.junctions.tolist() == [1, 8]
    long_chains = [c for c in curves.chains if len(c) > 4]
    assert long_chains, [c.tolist() for c in curves.chains]
    out = smooth_boundary_curves_arrays(V, F, 1)
    expected = plain_estimates(long_chains, V, V, held={1, 8}, closed=False)
    assert_allclose(out, expected, atol=TIGHT)
    assert np.array_equal(out[[1, 8, 14]], V[[1, 8, 14]])


def test_short_curves_are_held():
    # three-edge loops (a lone triangle), chains of one to three edges between junctions (a fin's rims)
    V = np.random.default_rng(1).normal(size=(5, 3))
    fin = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    assert_allclose(smooth_boundary_curves_arrays(V, fin, 3), V, atol=0)
    assert_allclose(smooth_boundary_curves_arrays(V[:3], fin[:1], 3), V[:3], atol=0)
    assert len(curve_operator(boundary_chains(fin, 5))) == 0


def test_curve_operator_takes_loops_or_curves_and_pickles():
    import pickle

    loop = np.array([5, 6, 7, 8, 9])
    from_list = curve_operator([loop])
    from_curves = curve_operator(BoundaryCurves([loop], [], np.zeros(0, dtype=np.int64)))
    positions = np.random.default_rng(2).normal(size=(10, 3))
    assert_allclose(
        from_list.step(positions, from_list.target(positions)),
        from_curves.step(positions, from_curves.target(positions)),
        atol=0,
    )
    again = pickle.loads(pickle.dumps(from_list))
    assert_allclose(
        again.step(positions, again.target(positions)),
        from_list.step(positions, from_list.target(positions)),
        atol=0,
    )
    assert len(curve_operator([])) == 0 and len(curve_operator([np.array([1, 2, 3])])) == 0


def test_bunny_scan_boundary_is_smoothed_with_its_pinches():
    mesh = load_mesh("bunny_scan.ply")
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.triangles).astype(np.int64)
    out = smooth_boundary_curves_arrays(V, F, 10)
    bhe = boundary_halfedges(F, len(V))
    boundary = np.zeros(len(V), dtype=bool)
    boundary[bhe.ravel()] = True
    assert np.isfinite(out).all() and np.array_equal(out[~boundary], V[~boundary])
    pinches = boundary_chains(F, len(V)).junctions
    assert len(pinches) == 51 and np.all(np.linalg.norm(out[pinches] - V[pinches], axis=1) > 0)
    # the curve gets shorter (fairer) but not shrunk away: total boundary length drops by under a third
    length = lambda P: np.linalg.norm(P[bhe[:, 0]] - P[bhe[:, 1]], axis=1).sum()
    assert 0.67 * length(V) < length(out) < length(V)
