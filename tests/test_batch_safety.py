"""``o3d-lsmesh batch`` cannot lose data: outputs stay inside OUTDIR, outputs are never inputs, resume checks.

Serial runs (``workers=0``) on tiny generated meshes; the references are the files on disk (their
names, bytes and hashes before and after), never the batch code's own bookkeeping.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import open3d as o3d

from o3d_lsmesh import batch
from o3d_lsmesh.cli import main


def _sphere(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert o3d.io.write_triangle_mesh(str(path), o3d.geometry.TriangleMesh.create_sphere(resolution=4))
    return path


def _tree(root: Path) -> dict[str, str]:
    """Every file and folder below ``root``: relative path -> sha256 of the bytes ("dir" for a folder)."""
    return {
        str(p.relative_to(root)): "dir" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
    }


def test_issue_40_reproducer_dot_names_never_replace_outdir(tmp_path, monkeypatch):
    # #40: '..ply' gave OUTDIR itself as its hierarchy folder, and the atomic swap deleted OUTDIR
    monkeypatch.chdir(tmp_path)
    for name in ("-a.ply", "..ply", "b.ply", "...ply"):
        _sphere(Path("in") / name)
    Path("out").mkdir()
    Path("out/earlier_result.txt").write_text("keep\n")
    before = _tree(tmp_path)
    argv = ["batch", "in", "out", "--op", "hierarchy", "--levels", "0", "--workers", "0", "--quiet"]
    assert main(argv) == 0
    assert Path("out/earlier_result.txt").read_text() == "keep\n"
    after = _tree(tmp_path)
    assert {k: v for k, v in after.items() if not k.startswith("out/")} == {
        k: v for k, v in before.items() if not k.startswith("out/")
    }  # nothing outside OUTDIR created, changed or removed
    lines = [json.loads(line) for line in Path("out/batch_report.jsonl").read_text().splitlines()]
    assert sorted(Path(r["input"]).name for r in lines) == ["-a.ply", "...ply", "..ply", "b.ply"]
    outdir = (tmp_path / "out").resolve()
    outputs = [Path(r["output"]).resolve() for r in lines]
    assert all(r["status"] == "ok" for r in lines) and len(set(outputs)) == 4
    for output in outputs:  # each its own folder strictly inside OUTDIR, holding the level
        assert output.parent == outdir and (output / "level_00.ply").is_file()
    # a second run replaces the outputs and still keeps the user's file
    assert main(argv) == 0
    assert Path("out/earlier_result.txt").read_text() == "keep\n"


def test_an_existing_folder_is_never_removed_by_an_output(tmp_path):
    source = _sphere(tmp_path / "in" / "b.ply")
    mine = tmp_path / "out" / "b" / "notes.txt"
    mine.parent.mkdir(parents=True)
    mine.write_text("mine")
    (record,) = batch.run(source, tmp_path / "out", op="hierarchy", options={"levels": "0"}, workers=0)
    assert record["status"] == "ok" and (tmp_path / "out" / "b" / "level_00.ply").is_file()
    assert mine.read_text() == "mine"
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["b"]  # no temporary left


def test_an_output_behind_a_symbolic_link_out_of_outdir_is_refused_per_file(tmp_path):
    _sphere(tmp_path / "in" / "sub" / "x.ply")
    _sphere(tmp_path / "in" / "y.ply")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "sub").symlink_to(elsewhere)
    records = {Path(r["input"]).name: r for r in batch.run(tmp_path / "in", tmp_path / "out", workers=0)}
    assert records["y.ply"]["status"] == "ok"
    assert (records["x.ply"]["status"], records["x.ply"]["stage"]) == ("failed", "write")
    assert "outside OUTDIR" in records["x.ply"]["error"] and list(elsewhere.iterdir()) == []
