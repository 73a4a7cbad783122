"""Every public function and CLI subcommand on raw scans and generated scan defects, with default options (issue 12).

The corpus: the raw range scans in ``O3D_LSMESH_SCANS`` (default ``../shared/data/scans``;
their MANIFEST gives independent counts), ``bunny_scan.ply`` from ``O3D_LSMESH_DATA``,
and the generated defects of ``defect_meshes.py``. Each test asserts a result, finite
positions, the input untouched and, where the function keeps the connectivity, the
same triangles. The costly API calls (greedy selection, encoding, spectral, render)
run on ``bunny_scan`` and the defects, and on every scan with ``O3D_LSMESH_FULL=1``;
the CLI runs on two scans (all three scan-sized meshes with ``O3D_LSMESH_FULL=1``). Hierarchy tests (``hierarchy``, ``multiresolution`` and
``level`` in their names) check the topology invariants of every level.
"""

from __future__ import annotations

import functools
import json
import os
import re
import warnings

import numpy as np
import open3d as o3d
import pytest
from conftest import DATA, SCANS
from defect_meshes import DEFECTS, all_defects

import o3d_lsmesh
from o3d_lsmesh import O3DLSMeshWarning, metrics
from o3d_lsmesh._o3d import weld_map
from o3d_lsmesh.app.cli import main
from o3d_lsmesh.core.boundary import boundary_halfedges
from o3d_lsmesh.core.connectivity import Connectivity
from o3d_lsmesh.lsmesh.selection import start_vertices

FULL = os.environ.get("O3D_LSMESH_FULL") == "1"
SCAN_NAMES = sorted(p.stem for p in SCANS.glob("*.ply")) if SCANS.is_dir() else ["(no scans)"]
LIGHT_SCANS = [name for name in ("bun090", "chin") if name in SCAN_NAMES] or SCAN_NAMES[
    :2
]  # costly calls, CLI
DEFECT_NAMES = [*DEFECTS, "all_defects"]
ALL = [f"scan:{name}" for name in SCAN_NAMES] + ["bunny_scan"] + [f"defect:{name}" for name in DEFECT_NAMES]
COSTLY = (
    ["bunny_scan"]
    + [f"defect:{name}" for name in DEFECT_NAMES]
    + [f"scan:{name}" for name in (SCAN_NAMES if FULL else LIGHT_SCANS[:1])]
)


@functools.cache
def _arrays(key: str):
    if key.startswith("scan:"):
        path = SCANS / f"{key[5:]}.ply"
        if not path.exists():
            return None, f"raw scans not found in {SCANS} (set O3D_LSMESH_SCANS to the scans folder)"
    elif key == "bunny_scan":
        path = DATA / "bunny_scan.ply"
        if not path.exists():
            return None, f"bunny_scan.ply not found in {DATA} (set O3D_LSMESH_DATA to the meshes folder)"
    else:
        name = key[7:]
        V, F, _ = all_defects() if name == "all_defects" else DEFECTS[name]()
        return (V, F), None
    mesh = o3d.io.read_triangle_mesh(str(path))
    return (np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).astype(np.int64)), None


def corpus(key: str):
    """A fresh legacy mesh of ``key`` and copies of its arrays, or skip with the reason."""
    arrays, reason = _arrays(key)
    if arrays is None:
        pytest.skip(reason)
    V, F = arrays
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32))
    )
    return mesh, V.copy(), F.copy()


def _untouched(mesh, V, F):
    assert np.array_equal(np.asarray(mesh.vertices), V) and np.array_equal(np.asarray(mesh.triangles), F)


def _same_connectivity(out, V, F):
    W = np.asarray(out.vertices)
    assert W.shape == V.shape and np.isfinite(W).all()
    assert np.array_equal(np.asarray(out.triangles), F)
    return W


def _scale(V):
    return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))


def _manifest(name: str) -> dict:
    """The scan's row of the scans MANIFEST table: an independent count of V, F, components, non-manifold vertices."""
    text = (SCANS / "MANIFEST.md").read_text()
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells and cells[0] == f"{name}.ply":
            v, f, comp, nmv = (int(c.replace(",", "")) for c in cells[1:5])
            return {"vertices": v, "triangles": f, "surface_pieces": comp, "nonmanifold_vertices": nmv}
    pytest.skip(f"{name}.ply is not in {SCANS / 'MANIFEST.md'}")


# --------------------------------------------------------------------------- topology_summary


@pytest.mark.parametrize("key", ALL)
def test_topology_summary_counts_against_independent_ones(key):
    mesh, V, F = corpus(key)
    s = o3d_lsmesh.topology_summary(mesh)
    _untouched(mesh, V, F)
    n = len(V)
    assert s["vertices"] == n and s["triangles"] == len(F)
    # independent: the scans' MANIFEST below, Open3D's counts elsewhere (Open3D does not count a
    # vertex whose fans end at an edge of more than two triangles, so only on edge-manifold meshes)
    if not key.startswith("scan:"):
        assert s["nonmanifold_edges"] == len(
            np.asarray(mesh.get_non_manifold_edges(allow_boundary_edges=True))
        )
        if s["edge_manifold"]:
            assert s["nonmanifold_vertices"] == len(np.asarray(mesh.get_non_manifold_vertices()))
    assert s["boundary_edges"] == len(boundary_halfedges(F, n))
    assert s["unreferenced_vertices"] == n - len(np.unique(F))
    assert sum(s["holes_by_size"].values()) == s["boundary_loops"]
    assert s["boundary_components"] <= s["boundary_loops"] + s["open_boundary_chains"]
    if s["total_genus"] is not None:
        assert s["total_genus"] >= 0
    if key.startswith("scan:"):
        expected = _manifest(key[5:])
        assert {k: s[k] for k in expected} == expected
        assert (
            s["total_genus"] == 0
        )  # every piece of a range scan is a disk with holes: Euler agrees with the loops
    if key == "bunny_scan":
        # the meshes MANIFEST: 32 components, 2,898 boundary edges in 109 connected boundary pieces
        assert (s["components"], s["boundary_edges"], s["boundary_components"]) == (32, 2898, 109)
        assert s["boundary_loops"] == 131 and s["total_genus"] == 0
    if key.startswith("defect:") and key != "defect:all_defects":
        _, _, expected = DEFECTS[key[7:]]()
        assert {k: s[k] for k in expected} == expected


def test_compare_prints_scan_topology(capsys, tmp_path):
    mesh, _V, _F = corpus("bunny_scan")
    path = tmp_path / "scan.ply"
    o3d.io.write_triangle_mesh(str(path), mesh)
    assert main(["compare", str(path), str(path), "--points", "2000", "--quiet", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    topo = report["topology_a"]
    assert topo["boundary_loops"] == 131 and topo["boundary_components"] == 109
    assert topo["nonmanifold_vertices"] == 51 and topo["holes_by_size"]["3"] == 9
    assert main(["compare", str(path), str(path), "--points", "2000"]) == 0
    out = capsys.readouterr().out
    assert (
        "boundary loops 131" in out and "in 109 connected pieces" in out and "non-manifold vertices 51" in out
    )


# --------------------------------------------------------------------------- fairing


@pytest.mark.parametrize("method", [None, "local", "global"])
@pytest.mark.parametrize("key", ALL)
def test_constrained_fairing_defaults(key, method):
    mesh, V, F = corpus(key)
    out = o3d_lsmesh.constrained_fairing(mesh, method=method)
    _untouched(mesh, V, F)
    W = _same_connectivity(out, V, F)
    # fairing moves vertices by a fraction of the noise, never across the model
    assert np.abs(W - V).max() < 0.5 * _scale(V)
    assert not np.array_equal(W, V)


@pytest.mark.parametrize("key", ALL)
def test_smooth_boundary_curves_and_registered_filters(key):
    mesh, V, F = corpus(key)
    out = o3d_lsmesh.smooth_boundary_curves(mesh)
    _untouched(mesh, V, F)
    W = _same_connectivity(out, V, F)
    boundary = np.zeros(len(V), dtype=bool)
    boundary[boundary_halfedges(F, len(V)).ravel()] = True
    assert np.array_equal(W[~boundary], V[~boundary])  # only boundary vertices move
    names = o3d_lsmesh.register()
    try:
        filtered = mesh.filter_smooth_constrained()
        _same_connectivity(filtered, V, F)
        assert np.array_equal(
            np.asarray(filtered.vertices), np.asarray(o3d_lsmesh.constrained_fairing(mesh).vertices)
        )
        _same_connectivity(mesh.filter_smooth_boundary_curves(), V, F)
    finally:
        o3d_lsmesh.unregister()
    _untouched(mesh, V, F)
    assert "filter_smooth_constrained" in names


@pytest.mark.parametrize("key", [f"defect:{name}" for name in DEFECT_NAMES])
def test_small_components_fair_without_nan(key):
    # isolated triangles (all valences 2: eq. 7's A is singular, the KKT form is not) and slivers
    mesh, _V, _F = corpus(key)
    for method in ("local", "global"):
        for smooth_boundary in (True, False):
            W = np.asarray(
                o3d_lsmesh.constrained_fairing(
                    mesh, 20, method=method, smooth_boundary=smooth_boundary
                ).vertices
            )
            assert np.isfinite(W).all()


# --------------------------------------------------------------------------- hole filling


# known defect (issue 15 stays open): on ear_back the refined patch of one hole holds a triangle and its
# reverse among new vertices (one non-manifold edge); strict, so the fix shows here
def _new_edges_valid(V, T, first_new):
    """What a fill adds on a mesh non-manifold elsewhere: every edge of a new triangle is used at most twice
    and once per direction (manifold, oriented), and no new triangle crosses another (Open3D's test on
    the triangles near them)."""
    from scipy.spatial import cKDTree

    n = len(V)
    e = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
    is_new = np.tile(np.arange(len(T)) >= first_new, 3)
    undirected = np.minimum(e[:, 0], e[:, 1]) * n + np.maximum(e[:, 0], e[:, 1])
    keys, counts = np.unique(undirected, return_counts=True)
    assert not is_new.any() or counts[np.searchsorted(keys, np.unique(undirected[is_new]))].max() <= 2
    directed = e[:, 0] * n + e[:, 1]
    keys, counts = np.unique(directed, return_counts=True)
    assert not is_new.any() or counts[np.searchsorted(keys, np.unique(directed[is_new]))].max() == 1
    new = np.arange(first_new, len(T))
    if len(new) == 0:
        return
    centroid = V[T].mean(axis=1)
    reach = np.linalg.norm(V[T] - centroid[:, None, :], axis=2).max()
    near = cKDTree(centroid).query_ball_point(centroid[new], r=2 * reach)
    local = np.unique(np.concatenate([np.asarray(x, dtype=np.int64) for x in near] + [new]))
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(T[local].astype(np.int32))
    )
    pairs = np.asarray(mesh.get_self_intersecting_triangles())
    assert len(pairs) == 0 or not (local[pairs] >= first_new).any()


@pytest.mark.parametrize("key", ALL)
def test_fill_holes_defaults(key):
    mesh, V, F = corpus(key)
    before = o3d_lsmesh.topology_summary(mesh)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = o3d_lsmesh.fill_holes(mesh)
    # the one warning allowed: a raw scan's own folds next to a hole make every fill cross them: those
    # holes are left open (said, not hidden)
    for warning in caught:
        assert issubclass(warning.category, O3DLSMeshWarning) and "left open" in str(warning.message)
    _untouched(mesh, V, F)
    W, G = np.asarray(out.vertices), np.asarray(out.triangles)
    assert np.isfinite(W).all()
    # the input is kept as it is, new vertices and triangles are appended
    assert np.array_equal(W[: len(V)], V) and np.array_equal(G[: len(F)], F)
    after = o3d_lsmesh.topology_summary(out)
    assert after["boundary_loops"] <= before["boundary_loops"]
    assert after["nonmanifold_edges"] <= before["nonmanifold_edges"]
    assert after["duplicate_triangles"] <= before["duplicate_triangles"]
    if before["boundary_loops"] > before["surface_pieces"]:  # inner holes beside each piece's border
        assert after["boundary_loops"] < before["boundary_loops"]
    # what the fills add is edge-manifold, consistently oriented and crosses nothing (ear_back's chord
    # split once made a triangle and its reverse)
    _new_edges_valid(W, G.astype(np.int64), len(F))
    # new vertices stay within the mesh's extent (a faired patch, not a spike)
    assert np.all(W[len(V) :] >= V.min(axis=0) - 0.1 * _scale(V))
    assert np.all(W[len(V) :] <= V.max(axis=0) + 0.1 * _scale(V))


# --------------------------------------------------------------------------- LS meshes, selection, encoding


@pytest.mark.parametrize("key", ALL)
def test_ls_mesh_and_reconstruct_geometry(key):
    mesh, V, F = corpus(key)
    n = len(V)
    controls = start_vertices(V, F)
    rng = np.random.default_rng(0)
    controls = np.union1d(controls, rng.choice(n, size=min(n, 50), replace=False))
    out = o3d_lsmesh.ls_mesh(mesh, controls)
    _untouched(mesh, V, F)
    _same_connectivity(out, V, F)
    # ls_mesh welds vertices at equal coordinates (a seam the reader left split): its components
    split = weld_map(V, F)
    welded = F if split is None else split[F]
    # the triangles that lose a corner welded (zero-area needles) are left out of the welded surface
    welded = welded[
        (welded[:, 0] != welded[:, 1]) & (welded[:, 1] != welded[:, 2]) & (welded[:, 2] != welded[:, 0])
    ]
    count, labels = Connectivity(welded, n if split is None else split.max() + 1).components
    labels = labels if split is None else labels[split]
    if count > 1:  # the user's system: a component without a control is refused, naming the cause
        missing = np.flatnonzero(labels != labels[controls[0]])
        lonely = controls[~np.isin(controls, missing)]
        with pytest.raises(o3d_lsmesh.SingularSystemError, match="every connected component"):
            o3d_lsmesh.ls_mesh(mesh, lonely)
    unknown = rng.choice(n, size=max(1, n // 50), replace=False)
    rebuilt = o3d_lsmesh.reconstruct_geometry(mesh, unknown)
    W = _same_connectivity(rebuilt, V, F)
    known = np.setdiff1d(np.arange(n), unknown)
    assert np.array_equal(W[known], V[known])
    L = o3d_lsmesh.laplacian(mesh)
    assert L.shape == (n, n) and np.isfinite(L.data).all()
    assert np.abs(L @ np.ones(n)).max() < 1e-12


@pytest.mark.parametrize("key", COSTLY)
def test_selection_approximation_and_encoding_seed_every_component(key):
    mesh, V, F = corpus(key)
    n = len(V)
    count, labels = Connectivity(F, n).components
    k = min(n, count + 20)
    indices = o3d_lsmesh.select_control_points(mesh, k)
    assert len(np.unique(indices)) == k and set(labels[indices].tolist()) == set(range(count))
    approx, chosen = o3d_lsmesh.approximate(mesh, k)
    _same_connectivity(approx, V, F)
    assert set(labels[chosen].tolist()) == set(range(count))
    data = o3d_lsmesh.encode_geometry(mesh, k)
    decoded = o3d_lsmesh.decode_geometry(mesh, data)
    W = _same_connectivity(decoded, V, F)
    assert np.abs(W - V).max() < _scale(V)
    last = None
    for last in o3d_lsmesh.iter_decode_geometry(mesh, data):  # noqa: B007 (the last one is kept)
        pass
    assert last is not None and np.isfinite(np.asarray(last.vertices)).all()
    _untouched(mesh, V, F)


# spectral_approximation is slow on scans (tens of seconds on bun090: the k smallest eigenvalues are
# all 0 when a scan has more than k components, a degenerate cluster for shift-invert Lanczos), so it
# runs on the scans only with O3D_LSMESH_FULL=1
@pytest.mark.parametrize(
    "key",
    [f"defect:{name}" for name in DEFECT_NAMES]
    + (["bunny_scan"] + [f"scan:{name}" for name in SCAN_NAMES] if FULL else []),
)
def test_spectral_approximation(key):
    mesh, V, F = corpus(key)
    out = o3d_lsmesh.spectral_approximation(mesh, min(len(V) - 1, 20))
    _same_connectivity(out, V, F)
    _untouched(mesh, V, F)


@pytest.mark.parametrize("key", ALL)
def test_metrics(key):
    mesh, V, F = corpus(key)
    other = o3d_lsmesh.constrained_fairing(mesh)
    values = [
        *metrics.vertex_error(mesh, other).values(),
        *metrics.surface_distance(mesh, other, number_of_points=5000).values(),
        metrics.signed_volume(mesh),
        metrics.normal_deviation(mesh, other),
        *metrics.triangle_angles(mesh).values(),
    ]
    assert np.isfinite(values).all()
    _untouched(mesh, V, F)


@pytest.mark.parametrize("key", ["defect:all_defects"] + (["bunny_scan"] if FULL else []))
def test_render(key, tmp_path):
    mesh, V, F = corpus(key)
    image = o3d_lsmesh.render(
        [mesh, o3d_lsmesh.constrained_fairing(mesh)], tmp_path / "out.png", width=160, height=120
    )
    assert image.ndim == 3 and image.shape[:2] == (120, 320 if image.shape[1] > 160 else 160)
    _untouched(mesh, V, F)


# --------------------------------------------------------------------------- hierarchy (fixed by helper `kernel`)


def _level_invariants(hierarchy, F0, n0):
    base = o3d_lsmesh.topology_summary((np.zeros((n0, 3)), F0))
    keys = ("euler", "components", "boundary_loops", "nonmanifold_vertices", "nonmanifold_edges")
    assert len(hierarchy) >= 2 or len(F0) < 200
    for i in range(len(hierarchy)):
        Vi, Fi = hierarchy.level_arrays(i)
        assert np.isfinite(Vi).all()
        s = o3d_lsmesh.topology_summary((Vi, Fi))
        assert {k: s[k] for k in keys} == {k: base[k] for k in keys}, i
        vmap = hierarchy.vertex_map(i)
        assert len(vmap) == n0 and vmap.min() >= 0 and vmap.max() < len(Vi)


@pytest.mark.parametrize("key", ALL)
def test_build_hierarchy_keeps_scan_topology(key):
    mesh, V, F = corpus(key)
    hierarchy = o3d_lsmesh.build_hierarchy(mesh)
    _untouched(mesh, V, F)
    _level_invariants(hierarchy, F, len(V))


@pytest.mark.parametrize("key", COSTLY)
def test_from_fast_simplification_hierarchy(key):
    mesh, V, F = corpus(key)
    hierarchy = o3d_lsmesh.from_fast_simplification(mesh)
    _untouched(mesh, V, F)
    for i in range(len(hierarchy)):
        Vi, Fi = hierarchy.level_arrays(i)
        assert np.isfinite(Vi).all() and (len(Fi) == 0 or Fi.max() < len(Vi))
        vmap = hierarchy.vertex_map(i)
        assert len(vmap) == len(V) and vmap.min() >= 0 and vmap.max() < len(Vi)


@pytest.mark.parametrize("key", ALL)
def test_multiresolution_fairing_on_scans(key):
    mesh, V, F = corpus(key)
    out = o3d_lsmesh.multiresolution_fairing(mesh, 1)
    _untouched(mesh, V, F)
    _same_connectivity(out, V, F)


# --------------------------------------------------------------------------- CLI


CLI_KEYS = (
    ["defect:all_defects"] + [f"scan:{name}" for name in LIGHT_SCANS] + (["bunny_scan"] if FULL else [])
)


@pytest.fixture
def scan_file(request, tmp_path):
    mesh, V, F = corpus(request.param)
    path = tmp_path / "in.ply"
    assert o3d.io.write_triangle_mesh(str(path), mesh)
    return path, V, F


def _cli(capsys, argv):
    code = main([*argv, "--json", "--quiet"])
    out = capsys.readouterr()
    assert code == 0, out.err
    return json.loads(out.out)


def _read(path):
    mesh = o3d.io.read_triangle_mesh(str(path))
    return np.asarray(mesh.vertices), np.asarray(mesh.triangles)


# a raw scan's own folds next to a hole can make every fill cross them: fill_holes leaves those holes
# open and says so with a warning (as it does for the outer borders it leaves open)
@pytest.mark.filterwarnings("default:(.*. O3DLSMeshWarning. )?fill_holes. [0-9]+ of [0-9]+ loops left open")
@pytest.mark.parametrize("scan_file", CLI_KEYS, indirect=True)
def test_cli_subcommands_on_scans(scan_file, tmp_path, capsys):
    path, V, F = scan_file
    before = path.read_bytes()
    out = tmp_path / "denoised.ply"
    _cli(capsys, ["denoise", str(path), str(out)])
    W, G = _read(out)
    assert np.isfinite(W).all() and np.array_equal(G, F) and not np.array_equal(W, V)
    _cli(capsys, ["denoise", str(path), str(tmp_path / "global.ply"), "--method", "global"])
    count = Connectivity(F, len(V)).components[0] + 10
    _cli(capsys, ["approximate", str(path), str(tmp_path / "approx.ply"), "--count", str(count)])
    assert np.isfinite(_read(tmp_path / "approx.ply")[0]).all()
    _cli(capsys, ["reconstruct", str(path), str(tmp_path / "rec.ply"), "--unknown", "0:20"])
    assert np.isfinite(_read(tmp_path / "rec.ply")[0]).all()
    _cli(capsys, ["encode", str(path), str(tmp_path / "geo.bin"), "--count", str(count)])
    _cli(capsys, ["decode", str(path), str(tmp_path / "geo.bin"), str(tmp_path / "dec.ply")])
    assert np.isfinite(_read(tmp_path / "dec.ply")[0]).all()
    report = _cli(capsys, ["compare", str(path), str(out), "--points", "2000"])
    assert report["topology_a"]["boundary_loops"] == report["topology_b"]["boundary_loops"]
    report = _cli(capsys, ["fill", str(path), str(tmp_path / "filled.ply")])
    W, G = _read(tmp_path / "filled.ply")
    assert (
        np.isfinite(W).all()
        and np.array_equal(G[: len(F)], F)
        and report["holes_after"] < report["holes_before"]
    )
    _cli(capsys, ["batch", str(path), str(tmp_path / "batch"), "--op", "fill,denoise", "--workers", "0"])
    W, G = _read(tmp_path / "batch" / path.name)
    assert np.isfinite(W).all() and len(G) > len(F)
    assert path.read_bytes() == before


@pytest.mark.parametrize("scan_file", CLI_KEYS, indirect=True)
def test_cli_hierarchy_and_denoise_level_on_scans(scan_file, tmp_path, capsys):
    path, _V, F = scan_file
    _cli(capsys, ["hierarchy", str(path), str(tmp_path / "levels")])
    assert any((tmp_path / "levels").iterdir())
    _cli(capsys, ["denoise", str(path), str(tmp_path / "level.ply"), "--level", "1"])
    W, G = _read(tmp_path / "level.ply")
    assert np.isfinite(W).all() and np.array_equal(G, F)


def test_corpus_is_named_in_the_manifest():
    if not SCANS.is_dir():
        pytest.skip(f"raw scans not found in {SCANS} (set O3D_LSMESH_SCANS to the scans folder)")
    names = re.findall(r"\|\s*(\S+)\.ply\s*\|", (SCANS / "MANIFEST.md").read_text())
    assert sorted(names) == SCAN_NAMES
