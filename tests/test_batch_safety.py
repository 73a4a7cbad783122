"""``o3d-lsmesh batch`` cannot lose data: outputs stay inside OUTDIR, outputs are never inputs, resume checks.

Serial runs (``workers=0``) on tiny generated meshes; the references are the files on disk (their
names, bytes and hashes before and after), never the batch code's own bookkeeping.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from o3d_lsmesh.app import batch
from o3d_lsmesh.app.cli import main
from o3d_lsmesh.app.ops import OPS, BatchOp
from o3d_lsmesh.core.errors import O3DLSMeshWarning


def _sphere(path: Path, resolution: int = 4, shift: float = 0.0) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=resolution)
    assert o3d.io.write_triangle_mesh(str(path), sphere.translate((shift, 0.0, 0.0)))
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
    (record,) = batch.run(
        source, tmp_path / "out", op="hierarchy", options={"levels": "0"}, workers=0, progress=False
    )
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


def test_a_report_is_never_written_over_a_mesh(tmp_path):
    # "--report scans/*.ply out": the shell makes the first match the report, which truncated that mesh
    scans = [_sphere(tmp_path / "scans" / name) for name in ("a.ply", "b.ply")]
    before = _tree(tmp_path / "scans")
    for report in (scans[0], tmp_path / "notes" / "report.ply", scans[1]):
        with pytest.raises(ValueError, match="report must name a file of its own") as info:
            batch.run(scans[1:], tmp_path / "out", report=report, workers=0, progress=False)
        assert info.value.param == "report"
    assert _tree(tmp_path / "scans") == before and not (tmp_path / "out").exists()
    # an output's name without a mesh suffix (encode writes .bin): refused before the run writes it
    with pytest.raises(ValueError, match=r"a\.bin', the batch's input or output"):
        batch.run(scans[0], tmp_path / "out", op="encode", report=tmp_path / "out" / "a.bin", workers=0)


def test_two_names_of_one_file_each_write_their_output(tmp_path):
    # a dataset split as links (two names, one file): each name is an input of its own, none dropped
    source = _sphere(tmp_path / "data" / "scan.ply")
    for name in ("train_0.ply", "test_0.ply"):
        (tmp_path / "in").mkdir(exist_ok=True)
        (tmp_path / "in" / name).symlink_to(source)
    records = batch.run(tmp_path / "in", tmp_path / "out", workers=0, progress=False)
    assert sorted(Path(r["output"]).name for r in records if r["status"] == "ok") == [
        "test_0.ply",
        "train_0.ply",
    ]
    # a path given twice (a folder and a file in it) is still one input
    assert len(batch.run([tmp_path / "in", tmp_path / "in" / "test_0.ply"], tmp_path / "o2", workers=0)) == 2


def test_outdir_inside_an_input_folder_and_leftover_temporaries_are_never_inputs(tmp_path):
    folder = tmp_path / "in"
    _sphere(folder / "a.ply")
    _sphere(folder / "sub" / "b.ply")
    # what a killed batch leaves: temporary files and folders of this version and the one before
    _sphere(folder / ".c.0123456789ab.tmp.ply")
    _sphere(folder / ".d.ply.0123456789ab.tmp" / "d.ply")
    _sphere(folder / "sub" / ".e.0123456789ab.old" / "level_00.ply")
    out = folder / "results"
    for _ in range(2):  # the second run must not take the first one's outputs as inputs
        records = batch.run(folder, out, op="hierarchy", options={"levels": "0"}, workers=0, progress=False)
        assert sorted(Path(r["input"]).relative_to(folder).as_posix() for r in records) == [
            "a.ply",
            "sub/b.ply",
        ]
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*.ply")) == [
        "a/level_00.ply",
        "sub/b/level_00.ply",
    ]
    # a glob matching OUTDIR among the input folders leaves it out
    records = batch.run(
        str(folder / "*"), out, op="hierarchy", options={"levels": "0"}, workers=0, progress=False
    )
    assert sorted(Path(r["input"]).name for r in records) == ["a.ply", "b.ply"]
    with pytest.raises(ValueError, match="lies inside OUTDIR"):
        batch.run(out, folder, workers=0)
    with pytest.raises(ValueError, match="lies inside OUTDIR"):
        batch.run(folder, folder, workers=0)


def test_resume_reruns_outputs_that_are_damaged_or_missing(tmp_path):
    folder, out, report = tmp_path / "in", tmp_path / "out", tmp_path / "report.jsonl"
    for name in "abcde":
        _sphere(folder / f"{name}.ply")
    first = batch.run(
        folder, out, op="hierarchy", options={"levels": "0"}, workers=0, report=report, progress=False
    )
    for record in first:  # the record holds each written file's size and hash, as on disk
        (path,) = Path(record["output"]).iterdir()
        assert record["files"] == {
            f"{path.parent.name}/{path.name}": {
                "bytes": path.stat().st_size,
                "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
            }
        }
    whole = (out / "a" / "level_00.ply").read_bytes()
    (out / "a" / "level_00.ply").write_bytes(b"")  # emptied
    (out / "b" / "level_00.ply").write_bytes(whole[:-10])  # truncated
    (out / "c" / "level_00.ply").write_bytes(whole[:-1] + bytes([whole[-1] ^ 1]))  # same size, one bit
    (out / "d" / "level_00.ply").unlink()  # gone
    again = batch.run(
        folder,
        out,
        op="hierarchy",
        options={"levels": "0"},
        workers=0,
        report=report,
        resume=True,
        progress=False,
    )
    assert {Path(r["input"]).name: r["status"] for r in again} == {
        "a.ply": "ok",
        "b.ply": "ok",
        "c.ply": "ok",
        "d.ply": "ok",
        "e.ply": "skipped",
    }
    for name in "abcd":
        assert (out / name / "level_00.ply").read_bytes() == whole


def test_resume_reports_and_skips_damaged_report_lines(tmp_path):
    folder, out, report = tmp_path / "in", tmp_path / "out", tmp_path / "report.jsonl"
    for name in "abc":
        _sphere(folder / f"{name}.ply")
    batch.run(folder, out, workers=0, report=report, progress=False, options={"iterations": 1})
    lines = report.read_bytes().splitlines(keepends=True)
    # line 2 (b's record) gets non-UTF-8 bytes; a killed run left a torn line 4 without its newline
    report.write_bytes(lines[0] + b"\xff\xfe" + lines[1][2:] + lines[2] + lines[0][:20])
    with pytest.warns(O3DLSMeshWarning, match=r"report .* lines 2, 4 .*damaged.* skipped"):
        again = batch.run(
            folder, out, workers=0, report=report, resume=True, progress=False, options={"iterations": 1}
        )
    assert {Path(r["input"]).name: r["status"] for r in again} == {
        "a.ply": "skipped",
        "b.ply": "ok",
        "c.ply": "skipped",
    }
    tail = report.read_bytes().splitlines()[4:]  # what this run appended starts on a line of its own
    assert [Path(json.loads(line)["input"]).name for line in tail] == ["b.ply"]


def test_a_missing_or_unreadable_scheduler_file_is_an_error_not_a_hang(tmp_path, capsys):
    source = _sphere(tmp_path / "a.ply")
    (tmp_path / "bad.json").write_text("{not json")
    errors: list[BaseException] = []

    def attempt(name):
        try:
            batch.run(source, tmp_path / "out", scheduler_file=tmp_path / name, progress=False)
        except BaseException as error:  # the test inspects what came
            errors.append(error)

    for name in ("missing.json", "bad.json"):
        thread = threading.Thread(target=attempt, args=(name,), daemon=True)
        thread.start()
        thread.join(30)  # Dask's client waits for the file to appear, forever
        assert not thread.is_alive(), f"batch.run waited for {name}"
    assert [isinstance(e, ValueError) for e in errors] == [True, True]
    assert "scheduler_file must" in str(errors[0]) and "does not exist" in str(errors[0])
    assert "scheduler_file must" in str(errors[1]) and "address" in str(errors[1])
    argv = [
        "batch",
        str(source),
        str(tmp_path / "out"),
        "--op",
        "denoise",
        "--scheduler-file",
        str(tmp_path / "missing.json"),
    ]
    assert main(argv) == 2
    assert "--scheduler-file must" in capsys.readouterr().err


_RELEASE = threading.Event()


def _slow_or_copy(mesh, options, context):
    """Test-only op: files named slow* wait (for the test's release, at most a minute), warn* warn
    twice, the rest copy."""
    name = Path(context.relative).name
    if name.startswith("slow"):
        _RELEASE.wait(60) if context.threads is None else time.sleep(60)  # serial: this process's event
    for _ in range(2 if name.startswith("warn") else 0):
        warnings.warn("odd mesh", O3DLSMeshWarning, stacklevel=1)
    return o3d.geometry.TriangleMesh(mesh), {}


@pytest.fixture
def slow_op():
    batch.register_op(BatchOp("_test_slow", _slow_or_copy))
    yield "_test_slow"
    OPS.pop("_test_slow")


def test_a_task_over_its_time_limit_is_a_failure_that_never_writes(tmp_path, slow_op):
    folder, out = tmp_path / "in", tmp_path / "out"
    for name in ("fast.ply", "slow.ply", "zfast.ply"):
        _sphere(folder / name)
    _RELEASE.clear()
    records = {
        Path(r["input"]).name: r
        for r in batch.run(folder, out, op=slow_op, workers=0, task_timeout=0.5, progress=False)
    }
    _RELEASE.set()  # the abandoned task goes on to its end, and must not write
    for thread in threading.enumerate():
        if thread.name.startswith("o3d-lsmesh task"):
            thread.join(30)
    assert records["fast.ply"]["status"] == records["zfast.ply"]["status"] == "ok"
    slow = records["slow.ply"]
    assert (slow["status"], slow["stage"]) == ("failed", slow_op)
    assert slow["error"].startswith("TaskTimeout: still running after 0.5 s")
    assert sorted(p.name for p in out.iterdir()) == ["fast.ply", "zfast.ply"]  # no output, no temporary
    for bad in (-1, float("nan"), "1", True):
        with pytest.raises((ValueError, TypeError), match="task_timeout must"):
            batch.run(folder, out, workers=0, task_timeout=bad)


def test_on_dask_a_task_over_its_time_limit_fails_and_its_worker_is_restarted(tmp_path, slow_op):
    pytest.importorskip("distributed")
    folder, out = tmp_path / "in", tmp_path / "out"
    for name in ("fast.ply", "slow.ply"):
        _sphere(folder / name)
    records = {
        Path(r["input"]).name: r
        for r in batch.run(folder, out, op=slow_op, workers=1, task_timeout=1, progress=False)
    }
    assert records["fast.ply"]["status"] == "ok"
    slow = records["slow.ply"]
    assert slow["status"] == "failed" and slow["error"].startswith("TaskTimeout: still running after 1 s")
    assert "worker was restarted" in slow["error"]
    assert sorted(p.name for p in out.iterdir()) == ["fast.ply"]


@pytest.mark.parametrize("workers", [0, 1])
def test_each_file_warnings_go_to_its_record_and_are_shown_with_its_name(tmp_path, slow_op, workers):
    if workers:
        pytest.importorskip("distributed")
    folder = tmp_path / "in"
    for name in ("warn1.ply", "quiet.ply", "warn2.ply"):
        _sphere(folder / name)
    with pytest.warns(O3DLSMeshWarning) as caught:
        records = batch.run(folder, tmp_path / "out", op=slow_op, workers=workers, progress=False)
    by_name = {Path(r["input"]).name: r["warnings"] for r in records}
    assert by_name == {  # the same warning from the same line, once per file and counted (one process)
        "quiet.ply": [],
        "warn1.ply": ["O3DLSMeshWarning: odd mesh (2 times)"],
        "warn2.ply": ["O3DLSMeshWarning: odd mesh (2 times)"],
    }
    shown = sorted(str(w.message) for w in caught)
    assert shown == [
        f"{folder / n}: O3DLSMeshWarning: odd mesh (2 times)" for n in ("warn1.ply", "warn2.ply")
    ]


def _textured_obj(tmp_path):
    """A folder holding ``tex.obj`` (a small sphere, its UVs, one grey texture), and an output folder."""
    mesh = o3d.geometry.TriangleMesh.create_sphere(resolution=4)
    mesh.triangle_uvs = o3d.utility.Vector2dVector(np.tile([[0.1, 0.2]], (3 * len(mesh.triangles), 1)))
    mesh.textures = [o3d.geometry.Image(np.full((4, 4, 3), 200, np.uint8))]
    mesh.triangle_material_ids = o3d.utility.IntVector([0] * len(mesh.triangles))
    folder = tmp_path / "in"
    folder.mkdir()
    assert o3d.io.write_triangle_mesh(str(folder / "tex.obj"), mesh)
    return folder, tmp_path / "out"


def test_obj_outputs_name_their_material_and_texture_after_the_output_and_leave_no_temporary(
    tmp_path, slow_op
):
    folder, out = _textured_obj(tmp_path)
    (record,) = batch.run(folder / "tex.obj", out, op=slow_op, suffix=".obj", workers=0, progress=False)
    assert record["status"] == "ok"
    assert sorted(p.name for p in out.iterdir()) == ["tex.mtl", "tex.obj", "tex_0.png"]  # nothing hidden
    assert "mtllib tex.mtl" in (out / "tex.obj").read_text().splitlines()
    assert "map_Kd tex_0.png" in (out / "tex.mtl").read_text().splitlines()
    assert sorted(record["files"]) == ["tex.mtl", "tex.obj", "tex_0.png"]
    back = o3d.io.read_triangle_mesh(str(out / "tex.obj"))
    # (Open3D's reader puts an empty slot first)
    assert [np.asarray(t).mean() for t in back.textures if not t.is_empty()] == [200]


@pytest.mark.parametrize("suffix", [".ply", ".off"])
def test_a_textured_input_written_where_the_format_cannot_hold_it_says_so(tmp_path, slow_op, suffix):
    # the OBJ's UVs and texture cannot go into a .ply or .off output: the file's record names what was
    # not written (it went without a word), as the single-file command line does
    folder, out = _textured_obj(tmp_path)
    with pytest.warns(O3DLSMeshWarning, match="texture coordinates or textures"):
        (record,) = batch.run(folder / "tex.obj", out, op=slow_op, suffix=suffix, workers=0, progress=False)
    assert record["status"] == "ok" and sorted(record["files"]) == [f"tex{suffix}"]
    (said,) = record["warnings"]
    assert f"OUTPUT {str(out / f'tex{suffix}')!r}: the {suffix} output has no texture coordinates" in said
    assert ".tmp" not in said  # the output's name, not the temporary one


# --------------------------------------------------------------------------- acceptance fuzz (#40)

_STEMS = ["..", ".", "...", "-x", "-", "a b", " ", "ü", "名前", "x", ".hidden", "_dot"]
_FOLDERS = ["", "-d", "é è", ".h", "sub/deeper"]


@st.composite
def _layouts(draw):
    """Input files (folder, stem, extension), OUTDIR inside the input folder or beside it, and the op."""
    files = draw(
        st.lists(
            st.tuples(
                st.sampled_from(_FOLDERS), st.sampled_from(_STEMS), st.sampled_from([".ply", ".obj", ".off"])
            ),
            min_size=1,
            max_size=5,
            unique_by=lambda f: (f[0], f[1]),
        )
    )
    outdir = draw(st.sampled_from(["out", "in/out", "in/-d/out", "in/.h/o u t"]))
    return files, outdir, draw(st.sampled_from(["hierarchy", "denoise"]))


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_layouts())
def test_fuzz_names_and_layouts_touch_nothing_outside_outdir_and_outputs_are_never_inputs(layout):
    files, outdir_name, op = layout
    options = {"levels": "0"} if op == "hierarchy" else {"iterations": 1}
    with tempfile.TemporaryDirectory() as name:
        root = Path(name)
        for folder, stem, extension in files:
            _sphere(root / "in" / folder / (stem + extension))
        (root / "in" / "keep.txt").write_text("the user's")
        outdir = root / outdir_name
        # (OUTDIR, what is in it and the folders made to hold it)
        outside = lambda tree: {
            k: v
            for k, v in tree.items()
            if not ((root / k).is_relative_to(outdir) or outdir.is_relative_to(root / k))
        }
        before = _tree(root)
        for _ in range(2):  # a second run over the first one's outputs
            try:
                with warnings.catch_warnings():  # (an OBJ's material ids do not follow a hierarchy)
                    warnings.simplefilter("ignore", O3DLSMeshWarning)
                    records = batch.run(
                        root / "in", outdir, op=op, options=options, workers=0, progress=False
                    )
            except ValueError as error:  # e.g. '_dot.ply' beside '..ply': refused as a whole, nothing written
                assert "would both write" in str(error)
                assert _tree(root) == before
                return
            assert outside(_tree(root)) == outside(before)
            found = sorted(r["input"] for r in records)  # outputs never become inputs
            assert found == sorted(str(root / "in" / f / (s + e)) for f, s, e in files)
            assert all(r["status"] == "ok" for r in records)
            outputs = [Path(r["output"]) for r in records]
            assert len(set(outputs)) == len(outputs)
            assert all(
                os.path.realpath(outdir) in map(str, Path(os.path.realpath(p)).parents) for p in outputs
            )


_HIERARCHY = {"op": "hierarchy", "options": {"levels": "all"}, "workers": 0, "progress": False}


@pytest.fixture(scope="module")
def six_files(tmp_path_factory):
    """Six distinct meshes and the outputs of a clean run over them."""
    root = tmp_path_factory.mktemp("six")
    for i in range(6):
        _sphere(root / "in" / f"m{i}.ply", resolution=8, shift=i)
    batch.run(root / "in", root / "reference", **_HIERARCHY)
    return root


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 6), st.sampled_from([0.0, 0.001, 0.005, 0.02]), st.integers(0, 5))
def test_fuzz_resume_after_sigkill_neither_loses_nor_duplicates_and_reruns_damaged(
    six_files, stop_after, delay, pick
):
    with tempfile.TemporaryDirectory() as name:
        out = Path(name) / "out"
        report = out / "batch_report.jsonl"
        options = ["--op", "hierarchy", "--levels", "all", "--workers", "0", "--quiet"]
        argv = [sys.executable, "-m", "o3d_lsmesh.cli", "batch", str(six_files / "in"), str(out), *options]
        process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        # SIGKILL a moment after the report holds stop_after records: before any, between, during a write
        while (
            process.poll() is None
            and (report.read_bytes().count(b"\n") if report.exists() else 0) < stop_after
        ):
            time.sleep(0.002)
        time.sleep(delay)
        process.kill()
        process.wait()
        done = sorted(out.glob("m*/level_00.ply"))
        if done:  # damage one output the killed run completed
            victim = done[pick % len(done)]
            victim.write_bytes(victim.read_bytes()[:-7])
        with warnings.catch_warnings():  # (a torn last report line is reported)
            warnings.simplefilter("ignore", O3DLSMeshWarning)
            records = batch.run(six_files / "in", out, report=report, resume=True, **_HIERARCHY)
        assert all(r["status"] in ("ok", "skipped") for r in records)
        if done:
            assert {Path(r["input"]).stem: r["status"] for r in records}[victim.parent.name] == "ok"
        visible = sorted(
            p.relative_to(out)
            for p in out.rglob("*")
            if p.is_file() and not str(p.relative_to(out)).startswith(".")
        )
        visible.remove(Path("batch_report.jsonl"))
        # neither lost nor duplicated: a clean run's files, byte for byte (hidden leftovers of the kill aside)
        reference = six_files / "reference"
        assert visible == sorted(p.relative_to(reference) for p in reference.rglob("*") if p.is_file())
        for path in visible:
            assert (out / path).read_bytes() == (reference / path).read_bytes()


def test_ctrl_c_on_a_running_batch_stops_it_without_a_traceback(tmp_path):
    # a terminal's Ctrl-C reaches the whole process group: the Dask workers printed their tracebacks
    # (interrupted mid-task or mid-import) below the command's "interrupted"
    sphere = o3d.geometry.TriangleMesh.create_sphere(resolution=200)  # about a second a file
    for i in range(10):
        assert o3d.io.write_triangle_mesh(str(tmp_path / f"s{i}.ply"), sphere)
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "o3d_lsmesh.cli", "batch", *sorted(map(str, tmp_path.glob("s*.ply")))]
    argv += [str(out), "--op", "denoise", "--workers", "2", "--report", str(tmp_path / "r.jsonl")]
    process = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    report, start = tmp_path / "r.jsonl", time.monotonic()
    while process.poll() is None and time.monotonic() - start < 120:
        if report.exists() and b"\n" in report.read_bytes():
            break  # a file is done: the workers are running the others
        time.sleep(0.01)
    os.killpg(process.pid, 2)  # SIGINT to the group, as a terminal sends it
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130 and "interrupted" in err, err[-2000:]
    assert "Traceback" not in err, err[-2000:]
