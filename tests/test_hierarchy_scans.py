"""Real scans through the hierarchies and multiresolution fairing with default options (issue 12), and the
exact relation between a fast-simplification level and the one above it (issue 13)."""

from __future__ import annotations

import _hierarchy_oracle as oracle
import numpy as np
import pytest
from conftest import SCANS, load_mesh

from o3d_lsmesh import (
    build_hierarchy,
    from_fast_simplification,
    multiresolution_fairing,
)

SCAN_NAMES = [f"scans/{p.name}" for p in sorted(SCANS.glob("*.ply"))] or ["scans/(none found)"]


def _load(name):
    if name == "bunny_scan.ply":
        return load_mesh(name)
    path = SCANS / name.split("/", 1)[1]
    if not path.exists():
        pytest.skip(f"raw scans not found in {SCANS} (set O3D_LSMESH_SCANS to the scans folder)")
    import open3d as o3d

    return o3d.io.read_triangle_mesh(str(path))


@pytest.mark.parametrize("name", ["bunny_scan.ply"] + SCAN_NAMES)
def test_scans_keep_their_topology_at_every_level_and_fair_by_scale(name):
    mesh = _load(name)
    V, F = np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).astype(np.int64)
    expected = oracle.topology(F, len(V), np.arange(len(V)))
    assert expected["nonmanifold_vertices"] and expected["components"] > 10  # what a raw scan has
    h = build_hierarchy(mesh)
    assert len(h) > 10 and h.vertex_count(len(h) - 1) < 0.05 * len(V)
    for i in [*range(1, len(h), 3), len(h) - 1]:  # every third level and the last (test time)
        assert oracle.topology(h.triangles[i], h.vertex_count(i), h.representatives[i]) == expected, i
        vmap = h.vertex_map(i)
        assert np.array_equal(vmap[h.representatives[i]], np.arange(h.vertex_count(i)))
    fast = from_fast_simplification(mesh, levels=4)
    assert len(fast) > 2
    for hierarchy in (h, fast):
        P = np.asarray(multiresolution_fairing(mesh, 1, hierarchy=hierarchy).vertices)
        assert P.shape == V.shape and np.isfinite(P).all()
        # no vertex travels: a merge across components would put split vertices on another one
        assert np.abs(P - V).max() < 0.05 * np.ptp(V, axis=0).max()
    assert np.array_equal(np.asarray(mesh.vertices), V)  # input untouched


def _reference_level(previous, parent):
    """A fast-simplification level from the one above, by a plain loop over its rules."""
    kept, seen, per_edge = [], set(), {}
    for t in previous.tolist():
        a, b, c = (int(parent[v]) for v in t)
        if a == b or b == c or c == a:
            continue  # (1) collapsed
        key = tuple(sorted((a, b, c)))
        if key in seen:
            continue  # (2) a repeat of a vertex set
        seen.add(key)
        kept.append((a, b, c))
    out = []
    for a, b, c in kept:  # (3) at most two triangles per edge, the first ones
        edges = [tuple(sorted(e)) for e in ((a, b), (b, c), (c, a))]
        for e in edges:
            per_edge[e] = per_edge.get(e, 0) + 1
        if all(per_edge[e] <= 2 for e in edges):
            out.append((a, b, c))
    return np.array(out, dtype=np.int64).reshape(-1, 3)


def test_fast_simplification_levels_are_the_image_of_the_level_above_by_its_rules():
    mesh = load_mesh("bunny.ply")
    F = np.asarray(mesh.triangles).astype(np.int64)
    h = from_fast_simplification(mesh)
    image_differs = 0
    for i in range(1, len(h)):
        # rule (3) of _reference_level drops triangles the second pass sees after dropping others:
        # recompute it the way the module does, then compare exactly, in order
        expected = _reference_level(h.triangles[i - 1], h.parents[i])
        assert np.array_equal(h.triangles[i], expected), i
        vmap = h.vertex_map(i)
        image = vmap[F]
        image = image[
            (image[:, 0] != image[:, 1]) & (image[:, 1] != image[:, 2]) & (image[:, 2] != image[:, 0])
        ]
        got = {tuple(sorted(t)) for t in h.triangles[i].tolist()}
        wanted = {tuple(sorted(t)) for t in image.tolist()}
        assert got <= wanted
        image_differs += got != wanted
    assert 0 < image_differs < len(h) - 1  # the exception occurs, and only at some levels (3 of 8)
