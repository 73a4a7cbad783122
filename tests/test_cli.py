"""The o3d-lsmesh command line, end to end on real PLY, OBJ and STL files, including every error exit."""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from conftest import REPO, load_mesh

from o3d_lsmesh.app import batch
from o3d_lsmesh.app.cli import CLIError, build_parser, main
from o3d_lsmesh.app.commands import parse_index_spec
from o3d_lsmesh.app.metrics import signed_volume
from o3d_lsmesh.app.shapes import add_noise, demo_mesh, mean_edge_length
from o3d_lsmesh.fairing import constrained_fairing


@pytest.fixture(scope="module")
def clean():
    return demo_mesh(3)  # 642 vertices, closed


@pytest.fixture(scope="module")
def noisy(clean):
    return add_noise(clean, 0.3 * mean_edge_length(clean), seed=4)


def _write(mesh, path: Path) -> Path:
    mesh = o3d.geometry.TriangleMesh(mesh)
    if path.suffix == ".stl":
        mesh.compute_triangle_normals()
    assert o3d.io.write_triangle_mesh(str(path), mesh)
    return path


def _read(path: Path):
    mesh = o3d.io.read_triangle_mesh(str(path))
    return mesh.remove_duplicated_vertices() if path.suffix == ".stl" else mesh


def run_json(capsys, argv):
    code = main([*argv, "--json", "--quiet"])
    out = capsys.readouterr()
    assert code == 0, out.err
    return json.loads(out.out)


def run_error(capsys, argv):
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2
    lines = [line for line in err.replace("\r", "\n").splitlines() if line.strip()]
    assert "Traceback" not in err
    return lines[-1]


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".stl"])
def test_denoise_round_trip_per_format(tmp_path, capsys, noisy, suffix):
    source = _write(noisy, tmp_path / f"noisy{suffix}")
    target = tmp_path / f"out{suffix}"
    report = run_json(capsys, ["denoise", str(source), str(target), "--iterations", "6"])
    result, given = _read(target), _read(source)
    # STL has no shared vertices: the CLI merges them, so every format gives the same surface.
    assert len(result.vertices) == len(given.vertices) == len(noisy.vertices)
    np.testing.assert_array_equal(np.asarray(result.triangles), np.asarray(given.triangles))
    expected = np.asarray(constrained_fairing(given, 6).vertices)
    tolerance = {".ply": 1e-12, ".obj": 1e-5, ".stl": 1e-5}[suffix]  # text and float32 formats round
    np.testing.assert_allclose(np.asarray(result.vertices), expected, atol=tolerance)
    assert report["vertices"] == len(noisy.vertices) and report["iterations"] == 6
    v0, v1 = signed_volume(given), signed_volume(result)
    assert report["volume_change_percent"] == pytest.approx(100 * (v1 - v0) / v0, abs=1e-4)
    moved = np.linalg.norm(np.asarray(result.vertices) - np.asarray(given.vertices), axis=1)
    assert report["displacement_mean"] == pytest.approx(moved.mean(), rel=1e-4)


def test_denoise_multiresolution_and_global(tmp_path, capsys, noisy):
    from o3d_lsmesh.fairing.multiresolution import multiresolution_fairing

    source = _write(noisy, tmp_path / "noisy.ply")
    report = run_json(capsys, ["denoise", str(source), str(tmp_path / "multi.ply"), "--level", "2"])
    assert report["level"] == 2 and report["iterations"] == 5
    np.testing.assert_allclose(
        np.asarray(_read(tmp_path / "multi.ply").vertices),
        np.asarray(multiresolution_fairing(_read(source), 2, number_of_iterations=5).vertices),
        atol=1e-12,
    )
    report = run_json(
        capsys,
        [
            "denoise",
            str(source),
            str(tmp_path / "global.ply"),
            "--method",
            "global",
            "--iterations",
            "1",
            "--mu",
            "0.5",
        ],
    )
    np.testing.assert_allclose(
        np.asarray(_read(tmp_path / "global.ply").vertices),
        np.asarray(constrained_fairing(_read(source), 1, method="global", mu=0.5).vertices),
        atol=1e-12,
    )


def test_real_mesh_denoise_and_compare(tmp_path, capsys):
    mesh = load_mesh("venus.ply")  # open: one boundary loop
    source = _write(add_noise(mesh, 0.2 * mean_edge_length(mesh), seed=1), tmp_path / "venus_noisy.ply")
    clean = _write(mesh, tmp_path / "venus.ply")
    # synthetic Gaussian noise on a clean open boundary: the paper's global method (the default, made for raw
    # scans, pulls the rim inward along the surface: see constrained_fairing's docstring)
    run_json(
        capsys,
        ["denoise", str(source), str(tmp_path / "venus_out.ply"), "--method", "global", "--iterations", "1"],
    )
    before = run_json(capsys, ["compare", str(source), str(clean), "--points", "20000"])
    after = run_json(capsys, ["compare", str(tmp_path / "venus_out.ply"), str(clean), "--points", "20000"])
    assert after["vertex_error"]["mean"] < before["vertex_error"]["mean"]
    assert after["topology_a"]["boundary_loops"] == 1


def test_compare_identical_and_different_meshes(tmp_path, capsys, clean, noisy):
    a = _write(clean, tmp_path / "a.ply")
    report = run_json(capsys, ["compare", str(a), str(a), "--points", "5000"])
    assert report["vertex_error"]["linf"] == 0.0 and report["normal_deviation_deg"] < 1e-5  # arccos near 1
    assert report["surface_distance"]["hausdorff"] < 1e-6
    assert report["topology_a"]["genus"] == 0 and report["shape_change"]["volume_change_percent"] == 0.0
    b = _write(noisy, tmp_path / "b.ply")  # (an OBJ is renumbered as read: no vertex correspondence)
    report = run_json(capsys, ["compare", str(a), str(b), "--points", "5000"])
    expected = np.linalg.norm(np.asarray(clean.vertices) - np.asarray(noisy.vertices), axis=1).max()
    assert report["vertex_error"]["linf"] == pytest.approx(expected, rel=1e-6)
    # A decimated mesh has another vertex count: only the surface measures apply.
    c = _write(clean.simplify_quadric_decimation(300), tmp_path / "c.ply")
    report = run_json(capsys, ["compare", str(a), str(c), "--points", "5000"])
    assert "vertex_error" not in report and report["surface_distance"]["mean"] > 0


def test_human_report_goes_to_stdout_and_json_alone_to_stdout(tmp_path, capsys, noisy):
    source = _write(noisy, tmp_path / "n.ply")
    assert main(["compare", str(source), str(source), "--points", "1000"]) == 0
    out = capsys.readouterr().out
    assert "surface distance: Hausdorff" in out
    assert main(["denoise", str(source), str(tmp_path / "o.ply"), "--json"]) == 0
    captured = capsys.readouterr()
    json.loads(captured.out)  # nothing but the JSON object
    assert "denoised" in captured.err


def test_approximate_writes_mesh_and_indices(tmp_path, capsys, clean):
    from o3d_lsmesh.lsmesh.selection import approximate

    source = _write(clean, tmp_path / "clean.ply")
    report = run_json(
        capsys,
        [
            "approximate",
            str(source),
            str(tmp_path / "approx.ply"),
            "--count",
            "40",
            "--indices",
            str(tmp_path / "idx.txt"),
        ],
    )
    indices = np.loadtxt(tmp_path / "idx.txt", dtype=np.int64)
    expected, expected_indices = approximate(_read(source), 40, method="greedy")
    np.testing.assert_array_equal(indices, expected_indices)
    np.testing.assert_allclose(
        np.asarray(_read(tmp_path / "approx.ply").vertices), np.asarray(expected.vertices), atol=1e-12
    )
    error = np.linalg.norm(np.asarray(expected.vertices) - np.asarray(clean.vertices), axis=1)
    assert report["count"] == 40 and report["error_linf"] == pytest.approx(error.max())


def test_reconstruct_from_range_and_file(tmp_path, capsys, clean):
    from o3d_lsmesh import reconstruct_geometry

    source = _write(clean, tmp_path / "clean.ply")
    run_json(capsys, ["reconstruct", str(source), str(tmp_path / "r1.ply"), "--unknown", "0:30,100,200:210"])
    unknown = np.r_[0:30, 100, 200:210]
    result = np.asarray(_read(tmp_path / "r1.ply").vertices)
    np.testing.assert_allclose(result, np.asarray(reconstruct_geometry(clean, unknown).vertices), atol=1e-12)
    known = np.setdiff1d(np.arange(len(result)), unknown)
    np.testing.assert_array_equal(result[known], np.asarray(clean.vertices)[known])
    (tmp_path / "unknown.txt").write_text(" ".join(map(str, unknown)) + "\n")
    report = run_json(
        capsys,
        ["reconstruct", str(source), str(tmp_path / "r2.ply"), "--unknown", str(tmp_path / "unknown.txt")],
    )
    np.testing.assert_array_equal(np.asarray(_read(tmp_path / "r2.ply").vertices), result)
    assert report["unknown"] == len(unknown)
    np.save(tmp_path / "unknown.npy", unknown)
    run_json(
        capsys,
        ["reconstruct", str(source), str(tmp_path / "r3.ply"), "--unknown", str(tmp_path / "unknown.npy")],
    )
    np.testing.assert_array_equal(np.asarray(_read(tmp_path / "r3.ply").vertices), result)
    # a suffix in capitals is the same format (it was read as text, and written as text by approximate)
    argv = ["approximate", str(source), str(tmp_path / "a.ply"), "--count", "40", "--indices"]
    run_json(capsys, [*argv, str(tmp_path / "chosen.NPY")])
    assert np.load(tmp_path / "chosen.NPY").shape == (40,)
    (tmp_path / "unknown.NPY").write_bytes((tmp_path / "unknown.npy").read_bytes())
    argv = ["reconstruct", str(source), str(tmp_path / "r4.ply"), "--unknown", str(tmp_path / "unknown.NPY")]
    run_json(capsys, argv)
    np.testing.assert_array_equal(np.asarray(_read(tmp_path / "r4.ply").vertices), result)


def test_parse_index_spec():
    np.testing.assert_array_equal(parse_index_spec("3,5:8, 10", 20), [3, 5, 6, 7, 10])
    np.testing.assert_array_equal(parse_index_spec("17:", 20), [17, 18, 19])
    for bad in ("a", "5:2", "-3:4", ",", "1:2:3"):
        with pytest.raises(CLIError, match="--unknown must"):
            parse_index_spec(bad, 20)


def test_hierarchy_writes_chosen_levels(tmp_path, capsys, clean):
    from o3d_lsmesh.hierarchy import build_hierarchy

    source = _write(clean, tmp_path / "clean.ply")
    outdir = tmp_path / "levels"
    argv = ["hierarchy", str(source), str(outdir), "--levels", "0,2,4", "--maps", "--format", "obj"]
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as in a shell (the suite turns warnings into errors)
        assert main([*argv, "--json", "--quiet"]) == 0
    out = capsys.readouterr()
    report = json.loads(out.out)
    # the maps number the OBJ's 'v' lines; Open3D reads an OBJ's vertices in another order: said
    assert "--maps numbers each level's vertices as .obj files list them" in out.err
    hierarchy = build_hierarchy(_read(source))
    assert report["levels"] == len(hierarchy)
    assert report["vertex_counts"] == [hierarchy.vertex_count(i) for i in range(len(hierarchy))]
    for level in (0, 2, 4):
        written = _read(outdir / f"level_{level:02d}.obj")
        assert len(written.vertices) == hierarchy.vertex_count(level)
        assert len(written.triangles) == len(hierarchy.level(level).triangles)
    maps = np.load(outdir / "vertex_maps.npz")
    np.testing.assert_array_equal(maps["level_04"], hierarchy.vertex_map(4))
    assert not (outdir / "level_01.obj").exists()


def test_hierarchy_builds_vertex_maps_only_with_maps(tmp_path, capsys, clean, monkeypatch):
    from o3d_lsmesh.hierarchy import MeshHierarchy

    source = _write(clean, tmp_path / "clean.ply")
    real_map, calls = MeshHierarchy.vertex_map, []

    def spy(self, i):
        calls.append(i)
        return real_map(self, i)

    monkeypatch.setattr(MeshHierarchy, "vertex_map", spy)
    report = run_json(capsys, ["hierarchy", str(source), str(tmp_path / "plain"), "--levels", "0,3"])
    assert calls == [] and not (tmp_path / "plain" / "vertex_maps.npz").exists()
    assert len(report["written"]) == 2
    report = run_json(capsys, ["hierarchy", str(source), str(tmp_path / "maps"), "--levels", "0,3", "--maps"])
    assert sorted(calls) == [0, 3] and report["written"][-1].endswith("vertex_maps.npz")
    with np.load(tmp_path / "maps" / "vertex_maps.npz") as maps:
        assert sorted(maps.files) == ["level_00", "level_03"]
        np.testing.assert_array_equal(maps["level_00"], np.arange(len(clean.vertices)))
        level3 = maps["level_03"]
    # every input vertex maps to a level-3 vertex, and each level-3 vertex represents itself and others
    assert level3.dtype == np.int64 and len(level3) == len(clean.vertices)
    count = report["vertex_counts"][3]
    assert level3.min() == 0 and level3.max() == count - 1 and len(np.unique(level3)) == count


def test_encode_then_decode(tmp_path, capsys, clean):
    from o3d_lsmesh.lsmesh.encoding import decode_geometry

    source = _write(clean, tmp_path / "clean.ply")
    report = run_json(
        capsys, ["encode", str(source), str(tmp_path / "geo.bin"), "--count", "30", "--bits", "10"]
    )
    data = (tmp_path / "geo.bin").read_bytes()
    assert report["bytes"] == len(data) and report["anchors"] == 30
    assert report["bits_per_vertex"] == pytest.approx(8 * len(data) / len(clean.vertices))
    run_json(
        capsys,
        ["decode", str(source), str(tmp_path / "geo.bin"), str(tmp_path / "dec.ply"), "--anchors", "20"],
    )
    np.testing.assert_allclose(
        np.asarray(_read(tmp_path / "dec.ply").vertices),
        np.asarray(decode_geometry(_read(source), data, anchors=20).vertices),
        atol=1e-12,
    )


def _closest_point_distances(points, vertices, triangles):
    """Distance from each point to the nearest triangle: the textbook closest-point-on-triangle regions,
    every point against every triangle (an independent check of the demo's ray-casting distances)."""
    a, b, c = (vertices[triangles[:, k]][None] for k in range(3))
    p = points[:, None]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    bp, cp = p - b, p - c
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v, w = vb / denom, vc / denom
        inside = a + ab * v[..., None] + ac * w[..., None]
        candidates = [inside, a, b, c]
        for x, y in ((a, b), (b, c), (a, c)):  # the three edges, clamped
            t = np.clip(((p - x) * (y - x)).sum(-1) / ((y - x) ** 2).sum(-1), 0, 1)
            candidates.append(x + (y - x) * t[..., None])
    ok = (va >= 0) & (vb >= 0) & (vc >= 0) & (denom > 0)
    distances = [np.where(ok, np.linalg.norm(p - inside, axis=-1), np.inf)]
    distances += [np.linalg.norm(p - q, axis=-1) for q in candidates[1:]]
    return np.min(np.stack(distances), axis=(0, 2))


def test_demo_small(tmp_path, capsys):
    report = run_json(capsys, ["demo", "--out", str(tmp_path / "demo"), "--resolution", "60", "--no-render"])
    rows = {row["key"]: row for row in report["rows"]}
    assert set(rows) == {"scan", "ours", "o3d_simple", "o3d_laplacian", "o3d_taubin"}
    assert not any("skipped" in row for row in rows.values())
    scan = o3d.io.read_triangle_mesh(str(tmp_path / "demo" / "scan.ply"))
    # what a raw range scan has: a boundary, islands
    assert not scan.is_watertight() and len(np.asarray(scan.cluster_connected_triangles()[1])) > 1
    ours, laplacian, raw = rows["ours"], rows["o3d_laplacian"], rows["scan"]
    assert ours["mean_distance"] < 0.6 * raw["mean_distance"]  # the default removes most of the noise
    assert abs(ours["mean_offset"]) < abs(laplacian["mean_offset"])  # and does not shrink the scan
    # The table's distances are those of the written meshes, in grid spacings, to the written surface.
    written = np.asarray(o3d.io.read_triangle_mesh(str(tmp_path / "demo" / "ours.ply")).vertices)
    surface = o3d.io.read_triangle_mesh(str(tmp_path / "demo" / "surface.ply"))
    sample = np.random.default_rng(0).choice(len(written), 20, replace=False)
    exact = _closest_point_distances(
        written[sample], np.asarray(surface.vertices), np.asarray(surface.triangles)
    )
    measured = np.abs(report["spacing"] * np.asarray([rows["ours"]["mean_distance"]]))
    assert exact.mean() == pytest.approx(measured[0], rel=0.35)  # 20 of the vertices against all of them
    for name in ("surface.ply", "scan.ply", "ours.ply", "o3d_taubin.ply", "metrics.json", "metrics.md"):
        assert (tmp_path / "demo" / name).exists()


def test_demo_replaces_its_own_files_and_never_the_users(tmp_path, capsys):
    mine = tmp_path / "work"
    mine.mkdir()
    (mine / "scan.ply").write_bytes(b"my scan")  # the name every example uses
    argv = ["demo", "--out", str(mine), "--resolution", "20", "--no-render", "--quiet"]
    line = run_error(capsys, argv)
    assert "--out" in line and "holds scan.ply, which the demo would replace" in line
    assert (mine / "scan.ply").read_bytes() == b"my scan" and sorted(os.listdir(mine)) == ["scan.ply"]
    again = ["demo", "--out", str(tmp_path / "demo"), "--resolution", "20", "--no-render", "--quiet"]
    assert main(again) == 0 and main(again) == 0  # a second run replaces the first's files
    assert "--out must be a folder, got the file" in run_error(
        capsys, [*argv[:2], str(mine / "scan.ply"), *argv[3:]]
    )


# ----------------------------------------------------------------- error exits: code 2, one line


def test_missing_input(tmp_path, capsys):
    line = run_error(capsys, ["denoise", str(tmp_path / "nope.ply"), str(tmp_path / "o.ply")])
    assert line == f"o3d-lsmesh: error: INPUT {str(tmp_path / 'nope.ply')!r} does not exist"
    line = run_error(capsys, ["decode", str(tmp_path / "nope.ply"), "x.bin", str(tmp_path / "o.ply")])
    assert "MESH" in line and "does not exist" in line


def test_unreadable_and_empty_meshes(tmp_path, capsys, clean):
    (tmp_path / "garbage.ply").write_bytes(b"\x00\x01 not a ply at all")
    line = run_error(capsys, ["denoise", str(tmp_path / "garbage.ply"), str(tmp_path / "o.ply")])
    assert "could not be read as a triangle mesh" in line
    (tmp_path / "empty.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 0\nproperty list uchar int vertex_indices\nend_header\n"
    )
    line = run_error(capsys, ["compare", str(tmp_path / "empty.ply"), str(tmp_path / "empty.ply")])
    assert "could not be read as a triangle mesh (empty" in line
    points = o3d.geometry.TriangleMesh()
    points.vertices = o3d.utility.Vector3dVector(np.random.default_rng(0).random((5, 3)))
    o3d.io.write_triangle_mesh(str(tmp_path / "points.ply"), points)
    line = run_error(
        capsys, ["approximate", str(tmp_path / "points.ply"), str(tmp_path / "o.ply"), "--count", "2"]
    )
    assert line.endswith("has 5 vertices but no triangles")
    line = run_error(capsys, ["denoise", str(tmp_path), str(tmp_path / "o.ply")])
    assert "is a folder" in line
    source = _write(clean, tmp_path / "clean.ply")
    (tmp_path / "bad.bin").write_bytes(b"definitely not a stream")
    line = run_error(capsys, ["decode", str(source), str(tmp_path / "bad.bin"), str(tmp_path / "d.ply")])
    # the library's "data must ..." names the file the user gave as DATA
    assert line.startswith(f"o3d-lsmesh: error: DATA '{tmp_path / 'bad.bin'}' must start with the magic")
    line = run_error(capsys, ["decode", str(source), str(tmp_path / "missing.bin"), str(tmp_path / "d.ply")])
    assert line.startswith("o3d-lsmesh: error: DATA")


@pytest.mark.parametrize(
    "argv, expected",
    [
        ([], "the following arguments are required: COMMAND"),
        (["smooth"], "invalid choice: 'smooth'"),
        (["denoise", "{src}"], "the following arguments are required: OUTPUT"),
        (["denoise", "{src}", "{out}", "--iterations", "-2"], "--iterations: must be a non-negative integer"),
        (["denoise", "{src}", "{out}", "--method", "spline"], "invalid choice: 'spline'"),
        (["approximate", "{src}", "{out}"], "the following arguments are required: --count"),
        (["approximate", "{src}", "{out}", "--count", "zero"], "--count: must be a positive integer"),
        (
            ["fill", "{src}", "{out}", "--max-hole-edges", "2"],
            "--max-hole-edges: must be an integer >= 3, got '2'",
        ),
        (["demo", "--force"], "unrecognized arguments: --force"),  # demo reads no file to protect
        (["reconstruct", "{src}", "{out}", "--unknown", "4:x"], "--unknown must be an existing index file"),
        (["hierarchy", "{src}", "{dir}", "--levels", "99"], "--levels must be in 0.."),
        (["hierarchy", "{src}", "{dir}", "--levels", "one"], "--levels: must be 'all' or comma-separated"),
        (["hierarchy", "{src}", "{dir}", "--format", "xyz"], "--format: must be one of .ply, .obj"),
        (
            ["hierarchy", "{src}", "{dir}", "--format", "glb"],
            "(Open3D writes .glb files it cannot read back: use .gltf)",
        ),
        (["denoise", "{src}", "{dir}/out.xyz"], "must end in one of .ply, .obj, .stl, .off, .gltf"),
        (["denoise", "{src}", "{dir}/out.glb"], "(Open3D writes .glb files it cannot read back: use .gltf)"),
        (["denoise", "{src}", "{dir}/missing/out.ply"], "OUTPUT folder"),
        (["denoise", "{src}", "{out}", "--render", "{dir}/picture.jpg"], "--render '"),  # (not "OUTPUT")
        (["denoise", "{src}", "{out}", "--render", "{dir}/picture.jpg"], "must end in one of .png"),
        (["approximate", "{src}", "{out}", "--count", "5", "--indices", "{dir}/i.csv"], "--indices '"),
        (["approximate", "{src}", "{out}", "--count", "100000"], "--count must be <= 642, got 100000"),
        (["reconstruct", "{src}", "{out}", "--unknown", "100000"], "--unknown must name vertices in 0..641"),
        (["reconstruct", "{src}", "{out}", "--unknown", "0:99999999999"], "got range '0:99999999999'"),
        (
            ["reconstruct", "{src}", "{out}", "--unknown", "0:642"],
            "needs at least one known vertex (outside --unknown)",
        ),
        (["reconstruct", "{src}", "{out}", "--unknown", "0:642", "--soft"], "(outside --unknown)"),
        (["compare", "{src}", "{src}", "--points", "10000000000"], "--points: must be at most 10,000,000"),
        (["demo", "--resolution", "5000"], "--resolution: must be at most 2,000"),
        (["demo", "--resolution", "5"], "--resolution: must be a grid size of at least 20 rays, got '5'"),
        (["demo", "--noise", "-1"], "--noise: must be a number in [0, 10], got '-1'"),
        (["demo", "--noise", "nan"], "--noise: must be a number in [0, 10], got 'nan'"),
        (["demo", "--noise", "1e308"], "--noise: must be at most 10.0, got '1e308'"),  # (a NaN vertex)
        (
            ["denoise", "{src}", "{out}", "--level", "2", "--mu", "1"],
            "--mu 1.0 cannot be combined with --level 2",
        ),
        (
            [
                "batch",
                "{src}",
                "{out}",
                "--op",
                "denoise",
                "--level",
                "2",
                "--method",
                "scan",
                "--workers",
                "0",
            ],
            "--method scan cannot be combined with --level 2 (multiresolution fairing does not take it: it takes --method local",
        ),
        # batch refuses what the command refuses, in its flags, before a worker starts or a file is read
        (
            ["batch", "{src}", "{out}", "--op", "denoise", "--fixed-boundary", "--workers", "0"],
            "--fixed-boundary cannot be used with --method auto (the default): its boundary moves",
        ),
        (
            ["batch", "{src}", "{out}", "--op", "compare", "--workers", "0"],
            "--reference is required by op compare",
        ),
        (
            ["compare", "{src}", "{src}", "--units", "edge"],
            "--units edge applies to the distance map of --render",
        ),
        (
            ["denoise", "{src}", "{out}", "--level", "2", "--reimpose-every", "2", "--fixed-boundary"],
            "--reimpose-every 2, --fixed-boundary cannot be combined with --level 2",
        ),
        (
            ["denoise", "{src}", "{out}", "--iterations", "1", "--method", "global", "--reimpose-every", "2"],
            "--reimpose-every does not apply to --method global",
        ),
        (
            ["denoise", "{src}", "{out}", "--method", "local", "--mu", "1"],
            "--mu does not apply to --method local",
        ),
        (["denoise", "{src}", "{out}", "--method", "global", "--mu", "-1"], "--mu must be"),
    ],
)
def test_bad_arguments_exit_2(tmp_path, capsys, clean, argv, expected):
    src = _write(clean, tmp_path / "clean.ply")
    names = {"src": str(src), "out": str(tmp_path / "out.ply"), "dir": str(tmp_path)}
    line = run_error(capsys, [a.format(**names) for a in argv])
    assert expected in line and line.startswith("o3d-lsmesh")


def test_refuses_to_overwrite_the_input_unless_forced(tmp_path, capsys, noisy):
    source = _write(noisy, tmp_path / "scan.ply")
    original = source.read_bytes()
    line = run_error(capsys, ["denoise", str(source), str(source)])
    assert "refusing to overwrite it (use --force)" in line
    # The same file under another name is still the input.
    line = run_error(capsys, ["denoise", str(source), str(tmp_path / "." / "scan.ply")])
    assert "refusing" in line
    line = run_error(capsys, ["decode", str(source), str(source), str(source)])
    assert "refusing" in line
    assert source.read_bytes() == original
    assert main(["denoise", str(source), str(source), "--force", "--quiet"]) == 0
    assert source.read_bytes() != original


def test_bad_index_files_outdir_and_write_failures(tmp_path, capsys, clean, monkeypatch):
    src = str(_write(clean, tmp_path / "clean.ply"))
    (tmp_path / "words.txt").write_text("1 2 three")
    line = run_error(
        capsys, ["reconstruct", src, str(tmp_path / "r.ply"), "--unknown", str(tmp_path / "words.txt")]
    )
    assert "must hold integer vertex indices" in line
    np.save(tmp_path / "floats.npy", np.array([1.5, 2.0]))
    line = run_error(
        capsys, ["reconstruct", src, str(tmp_path / "r.ply"), "--unknown", str(tmp_path / "floats.npy")]
    )
    assert "must hold integer vertex indices, got dtype float64" in line
    (tmp_path / "plainfile").write_text("x")
    line = run_error(capsys, ["hierarchy", src, str(tmp_path / "plainfile")])
    assert "exists and is not a folder" in line
    monkeypatch.setattr(o3d.io, "write_triangle_mesh", lambda *args, **kwargs: False)
    line = run_error(capsys, ["denoise", src, str(tmp_path / "o.ply")])
    assert line == f"o3d-lsmesh: error: could not write OUTPUT {str(tmp_path / 'o.ply')!r}"


def test_render_failure_exits_1(tmp_path, capsys, clean, monkeypatch):
    import importlib

    def broken(*args, **kwargs):
        raise RuntimeError("Filament OffscreenRenderer failed: no device")

    monkeypatch.setattr(importlib.import_module("o3d_lsmesh.app.render"), "render", broken)
    src = str(_write(clean, tmp_path / "clean.ply"))
    code = main(["denoise", src, str(tmp_path / "o.ply"), "--render", str(tmp_path / "p.png"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and err.strip() == "o3d-lsmesh: error: Filament OffscreenRenderer failed: no device"


# ----------------------------------------------------------------- real processes


def _python(*args, cwd, module="o3d_lsmesh.cli"):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run(
        [sys.executable, "-m", module, *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=300,
    )


@pytest.mark.parametrize("module", ["o3d_lsmesh.cli", "o3d_lsmesh"])
def test_module_entry_point_error_is_one_line(tmp_path, module):
    done = _python("denoise", "missing.ply", "out.ply", cwd=tmp_path, module=module)
    assert done.returncode == 2
    assert done.stderr.strip() == "o3d-lsmesh: error: INPUT 'missing.ply' does not exist"
    assert done.stdout == ""


def test_module_entry_point_json_with_render_keeps_stdout_clean(tmp_path, noisy):
    # Filament prints a banner on stdout, Open3D and RPly warnings too: none may reach --json output.
    _write(noisy, tmp_path / "scan.ply")
    done = _python("denoise", "scan.ply", "out.ply", "--render", "before_after.png", "--json", cwd=tmp_path)
    assert done.returncode in (0, 1), done.stderr
    report = json.loads(done.stdout) if done.returncode == 0 else None
    if done.returncode == 1:
        pytest.skip(f"rendering is impossible on this machine: {done.stderr.strip().splitlines()[-1]}")
    assert report["render"] == "before_after.png"
    image = np.asarray(o3d.io.read_image(str(tmp_path / "before_after.png")))
    assert image.ndim == 3 and image.std() > 5
    assert (tmp_path / "out.ply").exists()


def test_console_script_is_installed():
    script = Path(sys.executable).parent / "o3d-lsmesh"
    if not script.exists():
        pytest.skip(f"console script not installed next to {sys.executable} (pip install -e . creates it)")
    done = subprocess.run([str(script), "--help"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0
    for command in [*COMMANDS, "demo"]:
        assert command in done.stdout


# --------------------------------------------------------------------------- issue 12 class 3 and issue 19


def test_open_mesh_reports_the_inward_shift_and_no_volume(tmp_path, capsys):
    # an open surface encloses no volume (its signed volume is about the origin): denoise, --json and compare
    # report the inward shift along the normals, rim and interior, of metrics.shape_change
    from conftest import grid

    from o3d_lsmesh.app.metrics import shape_change

    vertices, triangles = grid(12, 12, z=lambda x, y: 0.1 * np.sin(5 * x) * np.cos(4 * y))
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(vertices + 5.0), o3d.utility.Vector3iVector(triangles)
    )
    source = _write(mesh, tmp_path / "open.ply")
    code = main(["denoise", str(source), str(tmp_path / "out.ply")])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "inward shift along the normals" in out.out and "volume" not in out.out.replace("(no volume", "")
    report = run_json(capsys, ["denoise", str(source), str(tmp_path / "out2.ply")])
    want = shape_change(_read(source), _read(tmp_path / "out2.ply"))
    assert "volume_change_percent" not in report and report["closed"] is False
    for key in ("mean", "rim", "interior"):
        assert report[f"inward_shift_{key}"] == pytest.approx(want[f"inward_shift_{key}"], rel=1e-9)
    compared = run_json(capsys, ["compare", str(source), str(tmp_path / "out2.ply"), "--points", "1000"])
    assert compared["shape_change"] == pytest.approx(want)


@pytest.mark.parametrize("keep", [0.3, 0.6, 0.97])
@pytest.mark.parametrize("encoding", ["binary", "ascii"])
def test_truncated_ply_is_refused(tmp_path, capsys, clean, keep, encoding):
    whole = tmp_path / "whole.ply"
    assert o3d.io.write_triangle_mesh(str(whole), clean, write_ascii=encoding == "ascii")
    data = whole.read_bytes()
    cut = tmp_path / "cut.ply"
    cut.write_bytes(data[: int(len(data) * keep)])
    line = run_error(capsys, ["denoise", str(cut), str(tmp_path / "out.ply")])
    assert line.startswith(f"o3d-lsmesh: error: INPUT '{cut}' is truncated or corrupt")
    assert not (tmp_path / "out.ply").exists()
    # the whole file still reads
    assert main(["compare", str(whole), str(whole), "--quiet", "--points", "100"]) == 0


def test_ply_header_counts_are_checked(tmp_path, capsys, clean):
    # a header that promises more faces than the file holds (a writer that died early, Open3D silent)
    whole = tmp_path / "whole.ply"
    assert o3d.io.write_triangle_mesh(str(whole), clean, write_ascii=True)
    text = whole.read_text().replace(
        f"element face {len(clean.triangles)}", f"element face {len(clean.triangles) + 5}"
    )
    (tmp_path / "lying.ply").write_text(text)
    line = run_error(capsys, ["compare", str(tmp_path / "lying.ply"), str(whole)])
    assert (
        "truncated or corrupt" in line and f"{len(clean.triangles) + 5} faces" in line
    ) or "Open3D read only part" in line


def test_internal_errors_show_a_traceback_and_exit_1(tmp_path, capsys, clean, monkeypatch):
    # a numpy error inside the package is a bug, not the user's input: exit 1 with the traceback
    import importlib

    def broken(*args, **kwargs):
        return np.zeros(3) + np.zeros(2)  # ValueError from numpy, not from a check of ours

    monkeypatch.setattr(importlib.import_module("o3d_lsmesh.fairing"), "constrained_fairing", broken)
    source = _write(clean, tmp_path / "clean.ply")
    code = main(["denoise", str(source), str(tmp_path / "out.ply"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1
    assert "Traceback" in err and "operands could not be broadcast" in err
    assert err.strip().splitlines()[-1].startswith("o3d-lsmesh: internal error")

    def typo(*args, **kwargs):
        return format(None, ".3f")  # the old flat-mesh bug: a TypeError that is ours but not a check

    monkeypatch.setattr(importlib.import_module("o3d_lsmesh.fairing"), "constrained_fairing", typo)
    assert main(["denoise", str(source), str(tmp_path / "out.ply"), "--quiet"]) == 1
    assert "Traceback" in capsys.readouterr().err

    def invariant(*args, **kwargs):  # a plain ValueError raised by o3d_lsmesh itself: a bug all the same
        from o3d_lsmesh.core.connectivity import Connectivity

        return Connectivity(np.zeros((2, 2), np.int64))

    monkeypatch.setattr(importlib.import_module("o3d_lsmesh.fairing"), "constrained_fairing", invariant)
    assert main(["denoise", str(source), str(tmp_path / "out.ply"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert (
        "o3d_lsmesh/core/connectivity.py" in err.replace(os.sep, "/") and "triangles must have shape" in err
    )
    assert err.strip().splitlines()[-1].startswith("o3d-lsmesh: internal error")


def test_only_expected_user_errors_exit_2(tmp_path, capsys, clean, monkeypatch):
    import importlib

    fairing = importlib.import_module("o3d_lsmesh.fairing")
    source = _write(clean, tmp_path / "clean.ply")
    argv = ["denoise", str(source), str(tmp_path / "out.ply"), "--quiet"]

    def raising(error):
        def function(*args, **kwargs):
            raise error

        return function

    # I/O errors are the user's (a full disk, a folder without write permission): one line, exit 2
    monkeypatch.setattr(
        fairing, "constrained_fairing", raising(PermissionError(13, "Permission denied", "x.ply"))
    )
    assert run_error(capsys, argv) == "o3d-lsmesh: error: Permission denied: x.ply"
    # a ValueError raised outside o3d_lsmesh (here: this test file), a RuntimeError from a solver, an
    # AssertionError: internal errors, shown with their traceback and exit 1
    for error in (ValueError("x must be 1"), RuntimeError("CHOLMOD failed"), AssertionError("bug")):
        monkeypatch.setattr(fairing, "constrained_fairing", raising(error))
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert "Traceback (most recent call last):" in err and str(error) in err
        assert err.splitlines()[-1].startswith("o3d-lsmesh: internal error")
    # a picture that cannot be drawn is not a bug: one line, exit 1 (test_render_failure_exits_1)


def test_library_checks_are_user_errors_naming_flags(tmp_path, capsys, clean):
    source = _write(clean, tmp_path / "clean.ply")
    line = run_error(capsys, ["encode", str(source), str(tmp_path / "x.bin"), "--bits", "40"])
    assert line.startswith("o3d-lsmesh: error: --bits must")
    line = run_error(capsys, ["encode", str(source), str(tmp_path / "x.bin"), "--count", "5000"])
    assert line.startswith("o3d-lsmesh: error: --count must be <= 642, got 5000")
    line = run_error(capsys, ["decode", str(source), str(tmp_path / "x.bin"), str(tmp_path / "d.ply")])
    assert "DATA" in line


def test_error_during_a_bar_starts_its_own_line(tmp_path, capsys, clean, monkeypatch):
    import importlib

    from o3d_lsmesh.core.progress import Progress
    from o3d_lsmesh.core.validate import as_count

    def failing(mesh, iterations, **kwargs):
        bar = Progress(True, "fairing").bar(10)  # left open, as when an exception leaves its loop
        bar.update(3)
        as_count(-1, name="number_of_iterations")  # a check of ours fails mid-bar

    def crashing(mesh, iterations, **kwargs):
        bar = Progress(True, "fairing").bar(10)
        bar.update(3)
        return np.zeros(3) + np.zeros(2)  # a bug mid-bar: the traceback too starts on its own line

    fairing = importlib.import_module("o3d_lsmesh.fairing")
    source = _write(clean, tmp_path / "clean.ply")
    monkeypatch.setattr(fairing, "constrained_fairing", failing)
    assert main(["denoise", str(source), str(tmp_path / "out.ply")]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert lines[-1] == "o3d-lsmesh: error: --iterations must be >= 0, got -1"
    assert "fairing:  30%" in lines[-2]  # the bar kept its own line, ended by a newline
    monkeypatch.setattr(fairing, "constrained_fairing", crashing)
    assert main(["denoise", str(source), str(tmp_path / "out.ply")]) == 1
    lines = capsys.readouterr().err.splitlines()
    assert "Traceback (most recent call last):" in lines
    assert "fairing:  30%" in lines[lines.index("Traceback (most recent call last):") - 1]


_BAR = re.compile(r"^(?P<desc>[^\r\n]*?):\s+\d+%\|[^|]*\|\s*(?P<n>\d+)/(?P<total>\d+)")


def _bars(err: str) -> dict[str, list[tuple[int, int]]]:
    """Every state each tqdm bar printed, by description, in order."""
    states: dict[str, list[tuple[int, int]]] = {}
    for piece in re.split(r"[\r\n]+", err):
        match = _BAR.match(piece.strip())
        if match:
            states.setdefault(match["desc"], []).append((int(match["n"]), int(match["total"])))
    return states


def test_approximate_bar_ends_at_its_count_on_a_mesh_of_several_pieces(tmp_path, capsys):
    # one seed per component is placed before the greedy loop: the bar counts them (it ended at 399/400)
    pieces = demo_mesh(4) + demo_mesh(3).translate((3, 0, 0)) + demo_mesh(2).translate((6, 0, 0))
    source = _write(pieces, tmp_path / "three.ply")
    assert main(["approximate", str(source), str(tmp_path / "a.ply"), "--count", "400"]) == 0
    bars = _bars(capsys.readouterr().err)
    assert bars, "no progress bar drawn"
    for desc, states in bars.items():
        assert states[-1] == (400, 400), (desc, states[-1])
        assert all(total == 400 for _, total in states)


def test_every_bar_ends_at_its_total_and_none_has_one_step(tmp_path, capsys, clean):
    source = str(_write(clean, tmp_path / "clean.ply"))
    holed = o3d.geometry.TriangleMesh(clean)
    holed.remove_triangles_by_index(list(range(0, 40, 3)))
    holed_file = str(_write(holed, tmp_path / "holed.ply"))
    runs = [
        ["denoise", source, str(tmp_path / "d.ply")],
        ["denoise", source, str(tmp_path / "d.ply"), "--level", "2"],
        ["denoise", source, str(tmp_path / "d.ply"), "--method", "global", "--iterations", "2"],
        ["fill", holed_file, str(tmp_path / "f.ply")],
        ["approximate", source, str(tmp_path / "a.ply"), "--count", "30", "--method", "combined"],
        ["reconstruct", source, str(tmp_path / "r.ply"), "--unknown", "0:50"],
        ["hierarchy", source, str(tmp_path / "levels"), "--levels", "0"],
        ["encode", source, str(tmp_path / "c.bin"), "--count", "40"],
        ["decode", source, str(tmp_path / "c.bin"), str(tmp_path / "e.ply")],
        ["compare", source, str(tmp_path / "d.ply"), "--points", "500"],
    ]
    drawn = set()
    for argv in runs:
        assert main(argv) == 0, argv
        for desc, states in _bars(capsys.readouterr().err).items():
            n, total = states[-1]
            assert n == total, (argv, desc, states[-1])
            assert total > 1, (argv, desc, "a one-step bar is noise")
            drawn.add(argv[0])
    # the long operations show a bar (compare only samples and measures)
    assert drawn >= {"denoise", "fill", "approximate", "reconstruct", "hierarchy", "encode", "decode"}


def _commands() -> list[str]:
    parser = build_parser()
    (sub,) = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return list(sub.choices)


def test_every_subcommand_is_checked_below():
    assert sorted(_commands()) == sorted(COMMANDS)


COMMANDS = [
    "denoise",
    "fill",
    "approximate",
    "reconstruct",
    "hierarchy",
    "encode",
    "decode",
    "compare",
    "batch",
]
COMMANDS += ["demo"]


@pytest.mark.parametrize("command", COMMANDS)
def test_help_shows_defaults_description_and_example(capsys, command):
    with pytest.raises(SystemExit) as exit_:
        main([command, "--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    assert f"example:\n  o3d-lsmesh {command} " in text
    description = text.split("\n\n")[1]
    assert len(description.split()) >= 8  # a sentence, not a title
    # every option (but --help, the required ones and the switches of batch's ops) names its default
    options = re.split(r"\n  (?=-)", text.split("options:", 1)[1])[1:]
    assert options
    for entry in options:
        flag = entry.split()[0].rstrip(",")
        if flag in ("-h", "--help") or entry.startswith(("--op ", "--count COUNT", "--unknown SPEC")):
            continue
        if command == "batch" and "operation options" in text.split(entry)[0]:
            continue  # left to each op's default, which may differ between ops (listed in the op's help)
        assert "(default:" in " ".join(entry.split()), f"{command} {flag} does not show its default"
    assert "(default: None)" not in text  # an unset option says what happens (never, no limit, the API's)


def test_top_level_help_states_the_start_up_cost_and_points_to_batch(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "Each call imports Open3D (about 2 s): for many files use 'o3d-lsmesh batch'" in text
    for command in COMMANDS:
        assert f" {command} " in text
    readme = " ".join((REPO / "README.md").read_text().split())
    assert "imports Open3D (about 2 s): for many files use `batch`" in readme


@pytest.mark.parametrize(
    "argv, expected",
    [
        (
            ["denoise", "{src}", "{out}", "--fixed-boundary"],
            "--fixed-boundary cannot be used with --method auto (the default)",
        ),
        (
            ["denoise", "{src}", "{out}", "--method", "local", "--mu", "2"],
            "--mu does not apply to --method local",
        ),
        (
            ["denoise", "{src}", "{out}", "--method", "scan", "--reimpose-every", "2"],
            "--reimpose-every does not apply to --method scan",
        ),
        (["denoise", "{src}", "{out}", "--method", "global", "--mu", "0"], "--mu must be positive"),
        (["denoise", "{src}", "{out}", "--level", "50"], "--level must be <"),
        (["fill", "{src}", "{out}", "--max-hole-diameter", "-1"], "--max-hole-diameter must be positive"),
        (["fill", "{src}", "{out}", "--density", "nan"], "--density: must be a finite number"),
        (
            ["approximate", "{src}", "{out}", "--count", "10", "--method", "random", "--seed", "-1"],
            "--seed: must be a non-negative integer",
        ),
        (
            ["approximate", "{src}", "{out}", "--count", "10", "--seed", "3"],
            "--seed 3 applies only to --method random, got --method greedy",
        ),
        (["encode", "{src}", "{dir}/x.bin", "--bits", "64"], "--bits must be <= "),
        (
            ["decode", "{src}", "{dir}/c.bin", "{out}", "--anchors", "1000"],
            "--anchors must be <= 20, got 1000",
        ),
        (["reconstruct", "{src}", "{out}", "--unknown", "0:642"], "(outside --unknown)"),
    ],
)
def test_errors_name_cli_flags_not_api_parameters(tmp_path, capsys, clean, argv, expected):
    src = _write(clean, tmp_path / "clean.ply")
    assert main(["encode", str(src), str(tmp_path / "c.bin"), "--count", "20", "--quiet"]) == 0
    names = {"src": str(src), "out": str(tmp_path / "out.ply"), "dir": str(tmp_path)}
    line = run_error(capsys, [a.format(**names) for a in argv])
    assert expected in line
    words = re.sub(r"'[^']*'", "", line)  # file names may hold anything
    words = words.replace("build_hierarchy", "")  # multiresolution_fairing's own wording of --level (library)
    # no Python identifier (number_of_iterations, smooth_boundary, build_hierarchy) and no keyword=value
    assert not re.search(r"\b[a-z]+_[a-z_]+\b|\w=", words), line


def test_help_lists_the_real_defaults(capsys):
    with pytest.raises(SystemExit):
        main(["compare", "--help"])
    assert "surface samples per mesh (default: 100000)" in " ".join(capsys.readouterr().out.split())
    with pytest.raises(SystemExit):
        main(["denoise", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert (
        "(default: auto, the API's default" in text
        and "multiresolution level (0: plain fairing) (default: 0)" in text
    )
    with pytest.raises(SystemExit):
        main(["reconstruct", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert (
        "e.g. '0:100,250'" in text and "'0:100,250' (default" not in text
    )  # a required option has no default


def test_denoise_level_passes_or_refuses_every_option(tmp_path, capsys, noisy):
    # --level with the options multiresolution fairing does not take is refused, never silently ignored
    source = _write(noisy, tmp_path / "noisy.ply")
    for option in (["--mu", "0.5"], ["--reimpose-every", "2"], ["--fixed-boundary"]):
        line = run_error(capsys, ["denoise", str(source), str(tmp_path / "o.ply"), "--level", "1", *option])
        assert f"{' '.join(option)} cannot be combined with --level 1" in line
    assert main(["denoise", str(source), str(tmp_path / "l.ply"), "--level", "1"]) == 0
    assert "by multiresolution fairing (level 1, local fairing per level)" in capsys.readouterr().out
    # the options it does take change the result
    a = run_json(
        capsys, ["denoise", str(source), str(tmp_path / "a.ply"), "--level", "1", "--iterations", "1"]
    )
    b = run_json(
        capsys, ["denoise", str(source), str(tmp_path / "b.ply"), "--level", "1", "--iterations", "4"]
    )
    assert a["displacement_mean"] != b["displacement_mean"]
    c = run_json(
        capsys,
        [
            "denoise",
            str(source),
            str(tmp_path / "c.ply"),
            "--level",
            "1",
            "--method",
            "global",
            "--iterations",
            "4",
        ],
    )
    assert not np.array_equal(
        np.asarray(_read(tmp_path / "b.ply").vertices), np.asarray(_read(tmp_path / "c.ply").vertices)
    )
    assert c["method"] == "global"


def test_out_of_memory_is_a_user_error(tmp_path, capsys, clean, monkeypatch):
    import importlib

    def greedy(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(importlib.import_module("o3d_lsmesh.fairing"), "constrained_fairing", greedy)
    source = _write(clean, tmp_path / "clean.ply")
    line = run_error(capsys, ["denoise", str(source), str(tmp_path / "out.ply")])
    assert (
        line == "o3d-lsmesh: error: not enough memory for this request: try a smaller mesh or smaller options"
    )


def test_input_errors_are_mapped_to_flags_by_param_not_by_words():
    from o3d_lsmesh.app.cli import user_message
    from o3d_lsmesh.core.errors import InputError

    args = build_parser().parse_args(["reconstruct", "scan.ply", "out.ply", "--unknown", "0"])
    error = InputError("unknown_vertex_indices must be >= 0, got -1", param="unknown_vertex_indices")
    assert user_message(error, args) == "--unknown must be >= 0, got -1"
    # the parameter is the error's, not a word of the message
    assert user_message(InputError("count must be >= 1", param=None), args) == "count must be >= 1"
    assert (
        user_message(InputError("it must be one", param="mesh"), args) == "INPUT 'scan.ply': it must be one"
    )
    assert (
        user_message(InputError("mesh must be a mesh", param="mesh"), args)
        == "INPUT 'scan.ply' must be a mesh"
    )
    args = build_parser().parse_args(["denoise", "a.ply", "b.ply", "--iterations", "3"])
    error = InputError("mu does not apply to method='local', got 1", param="mu")
    assert user_message(error, args) == "--mu does not apply to --method local, got 1"
    error = InputError("number_of_iterations must be >= 0", param="number_of_iterations")
    assert user_message(error, args) == "--iterations must be >= 0"
    # a parameter with an underscore is its flag wherever its own error names it; other words stay
    error = InputError("mu must be positive (number_of_iterations counts)", param="mu")
    assert user_message(error, args) == "--mu must be positive (number_of_iterations counts)"
    error = InputError("fewer than 10 (within number_of_iterations)", param="number_of_iterations")
    assert user_message(error, args) == "fewer than 10 (within --iterations)"
    # a switch's parameter may mean its negation: named only where it leads the message
    error = InputError("a closed mesh has no smooth_boundary", param="smooth_boundary")
    assert user_message(error, args) == "--fixed-boundary: a closed mesh has no smooth_boundary"


def test_invalid_mesh_files_are_named_in_the_error(tmp_path, capsys, clean):
    # a face past the last vertex (what a text file cut inside its last line reads as) names the file
    whole = tmp_path / "whole.ply"
    assert o3d.io.write_triangle_mesh(str(whole), clean, write_ascii=True)
    lines = whole.read_text().splitlines()
    lines[-1] = "3 0 1 99999"
    (tmp_path / "bad.ply").write_text("\n".join(lines) + "\n")
    line = run_error(capsys, ["denoise", str(tmp_path / "bad.ply"), str(tmp_path / "out.ply")])
    assert line == (
        f"o3d-lsmesh: error: INPUT '{tmp_path / 'bad.ply'}' triangle indices must lie in [0, "
        f"{len(clean.vertices)}), got [0, 1, 99999] at triangle {len(clean.triangles) - 1}"
    )
    line = run_error(capsys, ["compare", str(whole), str(tmp_path / "bad.ply")])
    assert line.startswith(f"o3d-lsmesh: error: B '{tmp_path / 'bad.ply'}' triangle indices must lie in")


def test_messages_about_the_input_mesh_name_the_file(tmp_path, capsys, clean):
    # the decoder's mesh is MESH on the command line
    source = _write(clean, tmp_path / "clean.ply")
    other = _write(demo_mesh(2), tmp_path / "other.ply")
    assert main(["encode", str(source), str(tmp_path / "c.bin"), "--quiet"]) == 0
    line = run_error(capsys, ["decode", str(other), str(tmp_path / "c.bin"), str(tmp_path / "d.ply")])
    assert line.startswith(f"o3d-lsmesh: error: MESH '{other}' must have the {len(clean.vertices)} vertices")


# ----------------------------------------------------------------- pictures


@pytest.fixture
def raycast_render(monkeypatch):
    """Draw the CLI's pictures with the in-process raycast backend (fast, no child process); record the calls."""
    import importlib

    rendering = importlib.import_module("o3d_lsmesh.app.render")
    real, calls = rendering.render, []

    def spy(*args, **kwargs):
        calls.append(kwargs)
        return real(*args, **{**kwargs, "backend": "raycast", "width": 160, "height": 160})

    monkeypatch.setattr(rendering, "render", spy)
    return calls


def _ink(region):
    return np.any(np.abs(region.astype(np.int64) - 255) > 60, axis=2)


def test_compare_render_draws_a_labelled_distance_map(tmp_path, capsys, clean, raycast_render):
    bumped = o3d.geometry.TriangleMesh(clean)
    v = np.asarray(bumped.vertices)
    top = v[:, 1] > np.percentile(v[:, 1], 90)  # move the top cap only: the +y side, the panel's upper part
    v[top] += 0.3 * mean_edge_length(clean) * np.array([0.0, 1.0, 0.0]) * 3
    a, b = _write(clean, tmp_path / "a.ply"), _write(bumped, tmp_path / "b.ply")
    picture = tmp_path / "distance.png"
    report = run_json(capsys, ["compare", str(a), str(b), "--render", str(picture), "--units", "edge"])
    assert report["render"] == str(picture)
    assert raycast_render[0]["units"] == "edge" and raycast_render[0]["titles"][1] == "B: b.ply"
    image = np.asarray(o3d.io.read_image(str(picture)))
    assert image.shape[1] == 320 and image.shape[0] > 160
    # titles over both panels, then the panels, then the labelled color bar
    rows_with_ink = np.flatnonzero(_ink(image).any(axis=1))
    assert rows_with_ink.min() < 25  # the title band holds text
    top_band = image[:22]
    assert _ink(top_band[:, :160]).sum() > 10 and _ink(top_band[:, 160:]).sum() > 10

    # B differs from A on its moved cap only: yellow-green pixels in B's panel, none in A's
    def hot(panel):
        p = panel.astype(np.int64)
        return (p[..., 1] > 110) & (p[..., 2] < 110) & (p[..., 0] < 250)

    panels = image[22 : 22 + 150]
    assert not hot(panels[:, :160]).any()
    rows = np.flatnonzero(hot(panels[:, 160:]).any(axis=1))
    assert len(rows) and rows.max() < 75  # in the upper half
    # the bottom band (color bar) has ink: tick labels and title
    assert _ink(image[-40:]).sum() > 50


def test_denoise_render_titles_name_the_method(tmp_path, capsys, noisy, raycast_render):
    src = _write(noisy, tmp_path / "scan.ply")
    run_json(
        capsys,
        [
            "denoise",
            str(src),
            str(tmp_path / "o.ply"),
            "--render",
            str(tmp_path / "p.png"),
            "--iterations",
            "3",
            "--method",
            "global",
        ],
    )
    assert raycast_render[0]["titles"] == ["input: scan.ply", "global fairing, 3 iterations"]
    out, picture = str(tmp_path / "o.ply"), str(tmp_path / "p.png")
    local = ["--method", "local", "--iterations", "1"]
    for options, title in [([], "scan fairing"), (local, "local fairing, 1 iteration")]:
        main(["denoise", str(src), out, "--render", picture, "--quiet", *options])
        assert raycast_render[-1]["titles"][1] == title  # the scan denoiser is one solve, not "1 iterations"
    image = np.asarray(o3d.io.read_image(str(tmp_path / "p.png")))
    assert image.shape[0] > 160 and _ink(image[:15]).sum() > 20


def test_compare_render_bad_values_exit_2(tmp_path, capsys, clean):
    a = str(_write(clean, tmp_path / "a.ply"))
    assert "must end in one of .png" in run_error(
        capsys, ["compare", a, a, "--render", str(tmp_path / "x.jpg")]
    )
    assert "--units" in run_error(
        capsys, ["compare", a, a, "--render", str(tmp_path / "x.png"), "--units", "inch"]
    )


def test_a_warning_is_one_line_naming_the_program_not_a_source_line(tmp_path, capsys, monkeypatch, clean):
    # without scikit-sparse the solver gateway warns; the CLI shows it as its own line, above the bar
    import o3d_lsmesh.core.solve as solvers

    monkeypatch.setattr(solvers, "_cholmod", None)
    monkeypatch.delenv(solvers.NO_CHOLMOD_ENV, raising=False)
    source = _write(clean, tmp_path / "clean.ply")
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as in a shell (the suite turns warnings into errors)
        code = main(["approximate", str(source), str(tmp_path / "o.ply"), "--count", "20"])
    err = capsys.readouterr().err
    assert code == 0, err
    lines = [line for line in err.splitlines() if "warning" in line.lower()]
    assert lines and all(line.startswith("o3d-lsmesh: warning: ") for line in lines), err
    assert "O3D_LSMESH_NO_CHOLMOD=1" in lines[0]
    assert ".py:" not in err  # no file:line of the package or of the console script


def test_denoise_features_method_says_which_mode_ran(tmp_path, capsys):
    box = o3d.geometry.TriangleMesh.create_box().subdivide_midpoint(3)
    source = _write(box, tmp_path / "box.ply")
    report = run_json(capsys, ["denoise", str(source), str(tmp_path / "out.ply"), "--method", "features"])
    assert report["method"] == "features"
    out = np.asarray(o3d.io.read_triangle_mesh(str(tmp_path / "out.ply")).vertices)
    # the same as the API call: the CLI adds nothing to the method
    expected = np.asarray(constrained_fairing(box, method="features").vertices)
    np.testing.assert_allclose(out, expected, atol=1e-6)


# ----------------------------------------------------------------- options declared once (ops.py)


def _subparsers():
    parser = build_parser()
    (sub,) = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices


def _options():
    from o3d_lsmesh.app.ops import OPS

    return [(op, option) for op in OPS.values() for option in op.options]


@pytest.mark.parametrize("op, option", _options(), ids=lambda x: getattr(x, "name", ""))
def test_each_option_is_a_flag_of_its_command_and_of_batch_with_its_default(op, option):
    from o3d_lsmesh.app.batch import resolve_options

    commands = _subparsers()
    if option.cli:  # the subcommand of the same name has the flag, with the table's default and help
        action = commands[op.name]._option_string_actions[option.cli_flag]
        assert action.dest == option.name and action.help == option.help.replace("%", "%%")
        assert action.required or action.default == option.default
    batch_flag = commands["batch"]._option_string_actions[option.cli_flag]
    assert op.name in batch_flag.help or option.help.replace("%", "%%") in batch_flag.help
    # batch.run parses the same option from the same table: the same default (text parsed, as argparse does)
    default = option.parse(option.default) if isinstance(option.default, str) else option.default
    assert resolve_options([op], {})[0][option.name] == default


@pytest.mark.parametrize(
    "op, option", [(op, o) for op, o in _options() if not o.is_flag], ids=lambda x: getattr(x, "name", "")
)
def test_a_bad_option_value_names_its_flag_on_the_cli_and_its_name_in_python(tmp_path, capsys, op, option):
    from o3d_lsmesh.core.errors import InputError

    with pytest.raises(InputError) as error:  # Python callers: the option's name, never a flag
        batch.run(tmp_path / "none.ply", tmp_path / "out", op=op.name, options={option.name: "x"}, workers=0)
    assert error.value.param == option.name and "--" not in str(error.value)
    argv = ["batch", str(tmp_path / "none.ply"), str(tmp_path / "out"), "--op", op.name, option.cli_flag, "x"]
    assert option.cli_flag in run_error(capsys, argv)
    if option.cli:
        argv = [op.name, str(tmp_path / "a.ply"), str(tmp_path / "b"), option.cli_flag, "x"]
        assert option.cli_flag in run_error(capsys, argv)


@pytest.mark.parametrize(
    "options, flag",
    [
        ({"suffix": ".xyz"}, "--suffix"),
        ({"workers": -1}, "--workers"),
        ({"threads_per_worker": 0}, "--threads-per-worker"),
        ({"retries": -1}, "--retries"),
        ({"task_timeout": -1.0}, "--task-timeout"),
        ({"scheduler_file": "missing.json"}, "--scheduler-file"),
    ],
)
def test_batch_run_errors_name_the_parameter_and_the_cli_adds_the_dashes(tmp_path, options, flag):
    from o3d_lsmesh.app.cli import user_message
    from o3d_lsmesh.core.errors import InputError

    with pytest.raises(InputError) as error:
        batch.run(tmp_path / "none.ply", tmp_path / "out", op="denoise", **options)
    (param,) = options
    assert error.value.param == param and not str(error.value).startswith("--")
    args = build_parser().parse_args(["batch", "in.ply", "out", "--op", "denoise"])
    assert user_message(error.value, args).startswith(flag)


@pytest.mark.parametrize(
    "argv, meshes",
    [
        (["denoise", "{a}", "{out}.ply"], 2),  # the input, and the output the metrics read
        (["fill", "{a}", "{out}.ply"], 2),  # the input, and the output whose holes are counted
        (["approximate", "{a}", "{out}.ply", "--count", "30"], 2),  # the input, and the output's error
        (["encode", "{a}", "{out}.bin"], 2),  # the input, and the decoded mesh's error
        (["hierarchy", "{a}", "{out}"], 1),
        (["reconstruct", "{a}", "{out}.ply", "--unknown", "0:10"], 1),
        (["compare", "{a}", "{b}"], 2),
    ],
)
def test_each_mesh_a_command_reads_or_makes_is_checked_once(
    tmp_path, capsys, monkeypatch, clean, noisy, argv, meshes
):
    # the command checks a file's arrays when it reads it; the operation and the metrics take them as they are
    import o3d_lsmesh._o3d as adapter

    checks, check = [], adapter.mesh_arrays
    monkeypatch.setattr(
        adapter, "mesh_arrays", lambda *args, **kwargs: checks.append(1) or check(*args, **kwargs)
    )
    a, b = _write(clean, tmp_path / "a.ply"), _write(noisy, tmp_path / "b.ply")
    argv = [item.format(a=a, b=b, out=tmp_path / "out") for item in argv]
    assert main([*argv, "--quiet"]) == 0, capsys.readouterr().err
    assert len(checks) == meshes


def test_reconstruct_on_an_obj_says_whose_vertex_order_unknown_counts(tmp_path, capsys):
    # Open3D's OBJ reader numbers the vertices as the faces first use them: --unknown counts those, and
    # the command says so (the file's 'v' lines are in another order)
    sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=8)
    sphere.translate(np.random.default_rng(1).normal(0.0, 0.01, 3))
    assert o3d.io.write_triangle_mesh(str(tmp_path / "s.obj"), sphere, write_vertex_normals=False)
    lines = (tmp_path / "s.obj").read_text().splitlines()
    file_order = np.array([[float(x) for x in line.split()[1:4]] for line in lines if line.startswith("v ")])
    read = np.asarray(o3d.io.read_triangle_mesh(str(tmp_path / "s.obj")).vertices)
    assert not np.allclose(read, file_order, atol=1e-5)  # the premise: the two orders differ
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as in a shell (the suite turns warnings into errors)
        assert (
            main(["reconstruct", str(tmp_path / "s.obj"), str(tmp_path / "o.obj"), "--unknown", "0:5"]) == 0
        )
    assert "--unknown counts the vertices of an OBJ as Open3D reads them" in capsys.readouterr().err
    out = np.asarray(o3d.io.read_triangle_mesh(str(tmp_path / "o.obj")).vertices)
    np.testing.assert_array_equal(np.flatnonzero(np.linalg.norm(out - read, axis=1) > 1e-4), np.arange(5))
    # and a glTF, which Open3D renumbers too
    assert o3d.io.write_triangle_mesh(str(tmp_path / "s.gltf"), sphere)
    read = np.asarray(o3d.io.read_triangle_mesh(str(tmp_path / "s.gltf")).vertices)
    assert not np.allclose(read, np.asarray(sphere.vertices), atol=1e-5)  # the premise
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        argv = ["reconstruct", str(tmp_path / "s.gltf"), str(tmp_path / "o.ply"), "--unknown", "0:5"]
        assert main(argv) == 0
    assert "--unknown counts the vertices of a glTF as Open3D reads them" in capsys.readouterr().err


def test_compare_pairs_vertices_only_where_the_meshes_correspond(tmp_path, capsys):
    # Open3D renumbers a glTF's vertices: the same sphere as .ply and .gltf has as many vertices, which
    # compare took for a correspondence (a vertex error of the sphere's diameter)
    sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=12)
    sphere.compute_vertex_normals()
    for suffix in (".ply", ".gltf"):
        assert o3d.io.write_triangle_mesh(str(tmp_path / f"s{suffix}"), sphere)
    report = run_json(capsys, ["compare", str(tmp_path / "s.ply"), str(tmp_path / "s.gltf")])
    assert report["size_a"]["vertices"] == report["size_b"]["vertices"]
    assert "vertex_error" not in report and report["surface_distance"]["hausdorff"] < 1e-5
    assert report["shape_change"]["volume_change_percent"] == pytest.approx(0.0, abs=1e-4)
    # a filter's result (the same triangles) is compared vertex by vertex
    report = run_json(capsys, ["compare", str(tmp_path / "s.ply"), str(tmp_path / "s.ply")])
    assert report["vertex_error"]["linf"] == 0.0


def test_hierarchy_level_0_is_the_input_with_its_attributes(tmp_path, capsys):
    # level 0 ("the input") was written without the input's colours and normals
    sphere = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=16)
    sphere.compute_vertex_normals()
    colours = np.random.default_rng(0).random((len(sphere.vertices), 3))
    sphere.vertex_colors = o3d.utility.Vector3dVector(colours)
    assert o3d.io.write_triangle_mesh(str(tmp_path / "s.ply"), sphere)
    given = o3d.io.read_triangle_mesh(str(tmp_path / "s.ply"))
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # (the coarse levels' colours are dropped, with a warning)
        assert main(["hierarchy", str(tmp_path / "s.ply"), str(tmp_path / "out"), "--levels", "0,1"]) == 0
    level0 = o3d.io.read_triangle_mesh(str(tmp_path / "out" / "level_00.ply"))
    np.testing.assert_array_equal(np.asarray(level0.vertex_colors), np.asarray(given.vertex_colors))
    np.testing.assert_array_equal(np.asarray(level0.triangles), np.asarray(given.triangles))
    assert level0.has_vertex_normals()
    assert not o3d.io.read_triangle_mesh(str(tmp_path / "out" / "level_01.ply")).has_vertex_colors()


def test_fill_counts_the_borders_it_left_open(tmp_path, capsys):
    # borders_left_open was 0 whenever --fill-border was given (19 border loops stay open on bun090, every
    # fill of them crossing the scan), and without it counted flaps the report does not call borders
    from conftest import load_scan

    from o3d_lsmesh._o3d import read_mesh
    from o3d_lsmesh.holes import find_holes

    V, T = load_scan("bun090.ply")
    scan = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(T.astype(np.int32))
    )
    assert o3d.io.write_triangle_mesh(str(tmp_path / "s.ply"), scan)
    welded = read_mesh((V, T), weld=True)
    before = find_holes(welded.vertices, welded.triangles)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (the loops left open are warned)
        report = run_json(capsys, ["fill", str(tmp_path / "s.ply"), str(tmp_path / "o.ply"), "--fill-border"])
    borders = [hole for hole in report["skipped"] if before[hole["id"]].border]
    assert report["borders_left_open"] == len(borders) > 0
