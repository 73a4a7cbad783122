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
