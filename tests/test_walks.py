"""How a mesh walks through the package (#36): each public call validates its mesh once and builds
one connectivity of it, and a batch task validates its input once for every stage."""

from __future__ import annotations

import sys
from collections import Counter

import numpy as np
import open3d as o3d
import pytest

import o3d_lsmesh
from o3d_lsmesh.core import connectivity, validate


@pytest.fixture
def counts(monkeypatch):
    """Count mesh validations, and note the triangle count of every Connectivity built (a hole patch's or
    the new triangles' own small connectivity is not the mesh's)."""
    seen: Counter = Counter()
    check, init = validate.mesh_arrays, connectivity.Connectivity.__init__

    def counting_check(*args, **kwargs):
        seen["validated"] += 1
        return check(*args, **kwargs)

    def counting_init(self, triangles, n=None, *args, **kwargs):
        init(self, triangles, n, *args, **kwargs)
        seen[("connectivity", len(self.triangles))] += 1

    # every module that took the function by name (the import rules let only a few)
    for name, module in list(sys.modules.items()):
        if name.startswith("o3d_lsmesh") and getattr(module, "mesh_arrays", None) is check:
            monkeypatch.setattr(module, "mesh_arrays", counting_check)
    monkeypatch.setattr(connectivity.Connectivity, "__init__", counting_init)
    return seen


def sphere(holes: int = 0) -> o3d.geometry.TriangleMesh:
    mesh = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=16)
    V = np.asarray(mesh.vertices)
    mesh.vertices = o3d.utility.Vector3dVector(V + 0.01 * np.random.default_rng(0).standard_normal(V.shape))
    if holes:
        mesh.remove_triangles_by_index(list(range(0, 10 * holes, 10)))
        mesh.remove_unreferenced_vertices()
    return mesh


@pytest.mark.parametrize(
    ("holes", "call"),
    [
        (0, lambda mesh: o3d_lsmesh.constrained_fairing(mesh)),
        (0, lambda mesh: o3d_lsmesh.constrained_fairing(mesh, 3, method="local")),
        (0, lambda mesh: o3d_lsmesh.constrained_fairing(mesh, 2, method="global")),
        (0, lambda mesh: o3d_lsmesh.constrained_fairing(mesh, method="features")),
        (3, lambda mesh: o3d_lsmesh.fill_holes(mesh)),
        (0, lambda mesh: o3d_lsmesh.ls_mesh(mesh, np.arange(0, 200, 7))),
        (0, lambda mesh: o3d_lsmesh.topology_summary(mesh)),
        (0, lambda mesh: o3d_lsmesh.select_control_points(mesh, 12)),
        (0, lambda mesh: o3d_lsmesh.select_control_points(mesh, 40, method="combined", batch=8)),
    ],
    ids=[
        "scan",
        "local",
        "global",
        "features",
        "fill_holes",
        "ls_mesh",
        "topology_summary",
        "greedy",
        "combined",
    ],
)
def test_a_public_call_validates_once_and_builds_one_connectivity(counts, holes, call):
    mesh = sphere(holes)
    call(mesh)
    assert counts["validated"] == 1, counts
    whole = len(mesh.triangles)
    assert counts[("connectivity", whole)] == 1, counts
    # any other is of a part: a patch, the new triangles beside their ring (never a second whole)
    sizes = [key[1] for key in counts if isinstance(key, tuple)]
    assert all(size < whole for size in sizes if size != whole), counts


def test_a_batch_task_validates_its_input_once(counts, tmp_path):
    from o3d_lsmesh.app.batch import run

    (tmp_path / "in").mkdir()
    o3d.io.write_triangle_mesh(str(tmp_path / "in" / "a.ply"), sphere(holes=2))
    # two stages: the input once, each stage's output once (the next stage's input or the metrics')
    records = run([str(tmp_path / "in")], str(tmp_path / "out"), op=["fill", "denoise"], workers=0)
    assert [r["status"] for r in records] == ["ok"], records
    assert counts["validated"] == 3, counts


@pytest.mark.parametrize("op, checks", [("encode", 2), ("approximate", 2), ("hierarchy", 1)])
def test_a_batch_op_validates_its_input_once(counts, tmp_path, op, checks):
    # the input once, and the mesh the record measures (the decoded one, the approximation) once
    from o3d_lsmesh.app.batch import run

    (tmp_path / "in").mkdir()
    o3d.io.write_triangle_mesh(str(tmp_path / "in" / "a.ply"), sphere())
    records = run([str(tmp_path / "in")], str(tmp_path / "out"), op=op, workers=0, progress=False)
    assert [r["status"] for r in records] == ["ok"], records
    assert counts["validated"] == checks, counts


@pytest.mark.parametrize("method", ["scan", "local", "global"])
def test_a_mesh_read_once_is_not_written_by_the_calls_it_is_handed_to(method):
    # read_mesh hands a MeshData on without a second check: the callee gets its own positions
    from o3d_lsmesh._o3d import read_mesh

    data = read_mesh(sphere())
    before = data.vertices.copy()
    out = o3d_lsmesh.constrained_fairing(data, 1 if method == "scan" else 2, method=method)
    np.testing.assert_array_equal(data.vertices, before)
    assert not np.array_equal(np.asarray(out.vertices), before)
