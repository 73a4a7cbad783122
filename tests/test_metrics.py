"""``metrics.shape_change``: the volume change of a closed mesh, the inward shift along the normals of an open one."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from conftest import WORLD, grid

from o3d_lsmesh.app.metrics import shape_change, signed_volume


def _plain_shift(before_v, triangles, after_v):
    """Inward shift per region by plain loops: each vertex's normal summed over its triangles' cross products,
    rings from the boundary by repeated neighbour passes."""
    n = len(before_v)
    normals = np.zeros((n, 3))
    for a, b, c in triangles:
        cross = np.cross(before_v[b] - before_v[a], before_v[c] - before_v[a])
        for v in (a, b, c):
            normals[v] += cross
    edges: dict = {}
    for tri in triangles:
        for k in range(3):
            key = tuple(sorted((tri[k], tri[(k + 1) % 3])))
            edges[key] = edges.get(key, 0) + 1
    ring = np.full(n, 10**9)
    for (a, b), count in edges.items():
        if count == 1:
            ring[a] = ring[b] = 0
    for r in (1, 2):
        for a, b in edges:
            if ring[a] == r - 1 and ring[b] > r:
                ring[b] = r
            if ring[b] == r - 1 and ring[a] > r:
                ring[a] = r
    shift = {"rim": [], "interior": [], "all": []}
    for v in range(n):
        length = np.linalg.norm(normals[v])
        if length == 0:
            continue
        s = -float(np.dot(after_v[v] - before_v[v], normals[v] / length))
        shift["all"].append(s)
        shift["rim" if ring[v] <= 2 else "interior"].append(s)
    return {key: float(np.mean(values)) for key, values in shift.items()}


def test_open_mesh_reports_the_inward_shift_by_region_and_no_volume():
    vertices, triangles = grid(9, 9, z=lambda x, y: 0.3 * np.sin(3 * x) * np.cos(2 * y))
    rng = np.random.default_rng(3)
    moved = vertices + 0.01 * rng.standard_normal(vertices.shape)
    got = shape_change((vertices, triangles), (moved, triangles))
    want = _plain_shift(vertices, triangles, moved)
    assert got["closed"] is False and "volume_change_percent" not in got
    assert np.isclose(got["inward_shift_mean"], want["all"])
    assert np.isclose(got["inward_shift_rim"], want["rim"])
    assert np.isclose(got["inward_shift_interior"], want["interior"])
    # a move along the normals by -d is an inward shift of d, whatever the origin
    normals = np.asarray(
        o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(triangles))
        .compute_vertex_normals()
        .vertex_normals
    )
    far = vertices + 1e3
    shrunk = shape_change((far, triangles), (far - 0.002 * normals, triangles))
    assert np.isclose(shrunk["inward_shift_mean"], 0.002)


def test_open_mesh_without_correspondence_reports_no_shift():
    vertices, triangles = grid(5, 5)
    got = shape_change((vertices, triangles), grid(4, 4))
    assert got == {
        "closed": False,
        "inward_shift_mean": None,
        "inward_shift_rim": None,
        "inward_shift_interior": None,
    }


def test_closed_mesh_reports_the_volume_change(sphere):
    shrunk = o3d.geometry.TriangleMesh(sphere).scale(0.9, center=(0.0, 0.0, 0.0))
    got = shape_change(sphere, shrunk)
    assert got["closed"] is True and "inward_shift_mean" not in got
    assert np.isclose(got["volume_before"], signed_volume(sphere))
    assert np.isclose(got["volume_change_percent"], 100.0 * (0.9**3 - 1.0))
    # the same 4,200 km from the origin: the triple products about the origin lost their digits there
    # (this sphere's volume read 0.98 of itself; a faired 0.5 m sphere's change -58% for none)
    far, far_shrunk = (o3d.geometry.TriangleMesh(m).translate(WORLD) for m in (sphere, shrunk))
    assert signed_volume(far) == pytest.approx(signed_volume(sphere), rel=1e-6)
    assert shape_change(far, far_shrunk)["volume_change_percent"] == pytest.approx(100.0 * (0.9**3 - 1.0))
