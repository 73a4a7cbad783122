"""Random triangle soups with scan defects through fairing, the hierarchy, multiresolution fairing and ls_mesh.

The soups (``conftest.triangle_soups``) hold every defect a raw scan has in small form:
edges of three or more triangles (fins), vertices joining several fans (bow-ties,
pinched boundaries), isolated triangles and small components, repeated triangles,
mixed orientations (flipped triangles) and unreferenced vertices; positions may
repeat (zero-area triangles) or be collinear. Each call has a documented outcome:

* ``constrained_fairing`` (both methods, with and without boundary smoothing) and
  ``smooth_boundary_curves``: always a result, finite, same triangles, input untouched;
  unreferenced vertices stay where they are.
* ``ls_mesh`` with a control in every component: a finite result that interpolates the
  controls up to the least-squares weight's pull; a component without a control:
  ``SingularSystemError`` naming the cause.
* ``build_hierarchy`` and ``multiresolution_fairing``: a result whose every level keeps
  the input's Euler characteristic, components, boundary loops and non-manifold vertices,
  or a ``ValueError`` naming ``mesh`` (what the hierarchy cannot simplify).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import triangle_soups, welded_surface
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import o3d_lsmesh
from o3d_lsmesh.core.connectivity import Connectivity
from o3d_lsmesh.fairing import constrained_fairing_arrays, smooth_boundary_curves_arrays


@st.composite
def defect_soups(draw):
    """``(V, F)``: a soup of up to 25 triangles on up to 12 vertices, with coincident or collinear positions."""
    n, triangles = draw(triangle_soups())
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    V = rng.normal(size=(n, 3))
    kind = draw(st.sampled_from(["generic", "coincident", "collinear", "flat"]))
    if kind == "coincident":
        V[1] = V[0]  # zero-area triangles wherever 0 and 1 meet
    elif kind == "collinear":
        V[2] = 0.5 * (V[0] + V[1])
    elif kind == "flat":
        V[:, 2] = 0.0
    return V, np.array(triangles, dtype=np.int64)


SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(defect_soups(), st.sampled_from(["local", "global"]), st.booleans())
def test_fairing_gives_a_finite_result_on_any_soup(soup, method, smooth_boundary):
    V, F = soup
    V0, F0 = V.copy(), F.copy()
    out = constrained_fairing_arrays(V, F, 5, method=method, smooth_boundary=smooth_boundary)
    assert out.shape == V.shape and np.isfinite(out).all()
    assert np.array_equal(V, V0) and np.array_equal(F, F0)
    unreferenced = np.setdiff1d(np.arange(len(V)), F)
    assert np.array_equal(out[unreferenced], V[unreferenced])
    curves = smooth_boundary_curves_arrays(V, F, 3)
    assert np.isfinite(curves).all()
    mesh = o3d_lsmesh.constrained_fairing((V, F), 2, method=method, smooth_boundary=smooth_boundary)
    assert np.array_equal(mesh[1], F) and np.isfinite(mesh[0]).all()


@SETTINGS
@given(defect_soups())
def test_ls_mesh_on_any_soup(soup):
    V, F = soup
    # ls_mesh welds exactly coincident vertices (first occurrence wins) and leaves out the triangles
    # that lose a corner so: the components it sees are those of that welded surface
    to, welded = welded_surface(V, F)
    labels = Connectivity(welded, len(V)).components[1][to]  # each vertex's component there
    count = len(set(labels.tolist()))
    controls = np.unique(labels, return_index=True)[1]  # a vertex of each
    out = o3d_lsmesh.ls_mesh((V, F), controls)[0]
    assert np.isfinite(out).all()
    exact = o3d_lsmesh.ls_mesh((V, F), controls, interpolate=True)[0]
    np.testing.assert_allclose(exact[controls], V[controls], atol=1e-9)
    if count > 1:
        with pytest.raises(o3d_lsmesh.SingularSystemError, match="every connected component needs"):
            o3d_lsmesh.ls_mesh((V, F), controls[:1])


def _summary(V, F):
    s = o3d_lsmesh.topology_summary((V, F))
    return {
        k: s[k]
        for k in ("euler", "components", "boundary_loops", "nonmanifold_vertices", "nonmanifold_edges")
    }


@SETTINGS
@given(defect_soups())
def test_hierarchy_and_multiresolution_fairing_on_any_soup(soup):
    V, F = soup
    V = V[
        : int(F.max()) + 1
    ]  # the hierarchy takes referenced vertices (unreferenced ones are tested elsewhere)
    if len(np.unique(F)) < len(V):
        return
    try:
        hierarchy = o3d_lsmesh.build_hierarchy((V, F), min_vertices=3)
    except ValueError as error:
        assert str(error).startswith("mesh"), error
        return
    base = _summary(V, F)
    for i in range(len(hierarchy)):
        Vi, Fi = hierarchy.level_arrays(i)
        assert np.isfinite(Vi).all() and _summary(Vi, Fi) == base, i
    try:
        out = o3d_lsmesh.multiresolution_fairing((V, F), min(1, len(hierarchy) - 1), hierarchy=hierarchy)
    except ValueError as error:
        assert str(error).startswith(("mesh", "level")), error
        return
    assert np.array_equal(out[1], F) and np.isfinite(out[0]).all()


def _sphere_with_a_hole():
    import open3d as o3d

    sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=10)
    V = np.asarray(sphere.vertices) + np.random.default_rng(3).normal(0.0, 0.01, (len(sphere.vertices), 3))
    T = np.asarray(sphere.triangles).astype(np.int64)
    T = T[V[T].mean(axis=1)[:, 2] < 0.8]  # a cap cut off: one hole
    used, T = np.unique(T, return_inverse=True)
    return V[used], T.reshape(-1, 3)


_SAME_CONNECTIVITY = {
    "default": lambda m: o3d_lsmesh.constrained_fairing(m),
    "features": lambda m: o3d_lsmesh.constrained_fairing(m, method="features"),
    "local": lambda m: o3d_lsmesh.constrained_fairing(m, 3, method="local"),
    "boundary curves": lambda m: o3d_lsmesh.smooth_boundary_curves(m),
    "ls_mesh": lambda m: o3d_lsmesh.ls_mesh(m, [0, 40, 80]),
    "reconstruct": lambda m: o3d_lsmesh.reconstruct_geometry(m, np.arange(20, 40)),
    "multiresolution": lambda m: o3d_lsmesh.multiresolution_fairing(m, 1),
}


@pytest.mark.parametrize("op", sorted(_SAME_CONNECTIVITY))
def test_triangles_repeating_a_vertex_are_left_out_and_kept(op):
    # a triangle repeating a vertex has no surface (a raw scan's, an STL soup's once merged): every operation
    # gives what it gives without it, and a result of the same connectivity keeps it in place
    V, T = _sphere_with_a_hole()
    T2 = np.insert(T, [4, len(T)], [[3, 3, 7], [9, 20, 20]], axis=0)
    without, with_them = _SAME_CONNECTIVITY[op]((V, T)), _SAME_CONNECTIVITY[op]((V, T2))
    np.testing.assert_array_equal(with_them[0], without[0])
    np.testing.assert_array_equal(with_them[1], T2)


def test_triangles_repeating_a_vertex_in_hole_filling_the_hierarchy_and_the_summary():
    V, T = _sphere_with_a_hole()
    T2 = np.insert(T, [4, len(T)], [[3, 3, 7], [9, 20, 20]], axis=0)
    (V1, F1), (V2, F2) = o3d_lsmesh.fill_holes((V, T)), o3d_lsmesh.fill_holes((V, T2))
    np.testing.assert_array_equal(V2, V1)  # the same new vertices
    np.testing.assert_array_equal(F2[: len(T2)], T2)  # the input's triangles first, in order
    np.testing.assert_array_equal(F2[len(T2) :], F1[len(T) :])  # then the same new ones
    h1, h2 = o3d_lsmesh.build_hierarchy((V, T)), o3d_lsmesh.build_hierarchy((V, T2))
    for level in range(len(h1.triangles)):
        for a, b in zip(h1.level_arrays(level), h2.level_arrays(level)):
            np.testing.assert_array_equal(a, b)
    s1, s2 = o3d_lsmesh.topology_summary((V, T)), o3d_lsmesh.topology_summary((V, T2))
    assert (s2["triangles"], s2["degenerate_triangles"]) == (
        s1["triangles"] + 2,
        s1["degenerate_triangles"] + 2,
    )
    assert {k: v for k, v in s2.items() if "triangles" not in k} == {
        k: v for k, v in s1.items() if "triangles" not in k
    }
    with pytest.raises(ValueError, match="mesh must have a triangle of three distinct vertices, got 2"):
        o3d_lsmesh.constrained_fairing((V, np.array([[0, 0, 1], [2, 3, 3]])))
