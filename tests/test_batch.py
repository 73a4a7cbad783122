"""o3d_lsmesh.batch and ``o3d-lsmesh batch`` on generated files, with a real 2-worker LocalCluster.

One cluster serves the whole module (fixture ``client``); the tests that need
their own cluster (the start-method check) start a 1-worker one. The
references are independent of the batch code: the library called directly in
this process, Dask's own view of its workers, and the files on disk.
"""

from __future__ import annotations

import ctypes
import json
import multiprocessing
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest

from o3d_lsmesh.app import batch, tasks
from o3d_lsmesh.app.cli import main
from o3d_lsmesh.app.ops import OPS, BatchOp, Option, int_at_least
from o3d_lsmesh.app.shapes import add_noise, demo_mesh, mean_edge_length
from o3d_lsmesh.core.errors import O3DLSMeshWarning
from o3d_lsmesh.fairing import constrained_fairing

distributed = pytest.importorskip(
    "distributed", reason="dask.distributed is the batch engine: pip install '.[dask]'"
)

# A module a forked child would inherit and a spawned one cannot have (it exists only in this process).
_SENTINEL = "_o3d_lsmesh_batch_test_parent_only"


def _write(mesh, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert o3d.io.write_triangle_mesh(str(path), mesh)
    return path


def _read(path) -> tuple[np.ndarray, np.ndarray]:
    mesh = o3d.io.read_triangle_mesh(str(path))
    return np.asarray(mesh.vertices).copy(), np.asarray(mesh.triangles).copy()


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """``good/`` (4 noisy spheres, one in a subfolder) and ``mixed/`` (2 good, corrupt, empty, NaN)."""
    root = tmp_path_factory.mktemp("batch")
    clean = demo_mesh(3)  # 642 vertices, closed
    sigma = 0.3 * mean_edge_length(clean)
    good = [
        _write(add_noise(clean, sigma, seed=s), root / "good" / name)
        for s, name in enumerate(["a.ply", "b.ply", "c.ply", "sub/d.ply"])
    ]
    mixed = [_write(add_noise(clean, sigma, seed=10 + s), root / "mixed" / f"ok{s}.ply") for s in range(2)]
    (root / "mixed" / "corrupt.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\n" + os.urandom(200))
    (root / "mixed" / "empty.ply").write_bytes(b"")
    nan = add_noise(clean, sigma, seed=20)
    vertices = np.asarray(nan.vertices).copy()
    vertices[5] = np.nan
    nan.vertices = o3d.utility.Vector3dVector(vertices)
    _write(nan, root / "mixed" / "nan.ply")  # reads fine; fairing refuses non-finite coordinates
    return types.SimpleNamespace(
        root=root, good=good, good_dir=root / "good", mixed=mixed, mixed_dir=root / "mixed"
    )


@pytest.fixture(scope="module")
def cluster():
    sys.modules[_SENTINEL] = types.ModuleType(_SENTINEL)
    try:
        with batch.local_cluster(2, 1, retries=1) as local:
            yield local
    finally:
        sys.modules.pop(_SENTINEL, None)


@pytest.fixture(scope="module")
def client(cluster):
    with distributed.Client(cluster) as c:
        yield c


def _by_name(records):
    return {Path(r["input"]).name: r for r in records}


# --------------------------------------------------------------------------- results


def test_outputs_equal_direct_library_calls_bit_for_bit(data, client, tmp_path):
    records = batch.run(
        data.good_dir,
        tmp_path / "out",
        op="denoise",
        options={"iterations": 4, "method": "local"},
        client=client,
        progress=False,
    )
    assert [r["status"] for r in records] == ["ok"] * 4
    assert len({r["pid"] for r in records}) == 2  # both workers took files
    for path, record in zip(sorted(data.good), sorted(records, key=lambda r: r["input"])):
        assert record["output"] == str(tmp_path / "out" / path.relative_to(data.good_dir))
        source = o3d.io.read_triangle_mesh(str(path))
        expected = constrained_fairing(source, 4, method="local")
        vertices, triangles = _read(record["output"])
        np.testing.assert_array_equal(vertices, np.asarray(expected.vertices))
        np.testing.assert_array_equal(triangles, np.asarray(expected.triangles))
        assert (record["vertices_before"], record["vertices_after"]) == (642, 642)
        moved = np.linalg.norm(vertices - np.asarray(source.vertices), axis=1)
        assert record["metrics"]["denoise"]["displacement_max"] == pytest.approx(moved.max(), rel=1e-12)
    assert not [p for p in (tmp_path / "out").rglob("*") if ".tmp" in p.name]


def test_global_method_equals_the_serial_cli_with_the_same_threads_bit_for_bit(data, client, tmp_path):
    # CHOLMOD's supernodal factor sums in an order that depends on the BLAS thread count, so the serial
    # reference runs where the workers' thread cap (1) holds from the start: a fresh process.
    records = batch.run(
        data.good_dir,
        tmp_path / "out",
        op="denoise",
        options={"method": "global"},
        client=client,
        progress=False,
    )
    environ = {
        **os.environ,
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
        "PYTHONPATH": os.pathsep.join(
            [str(Path(batch.__file__).parents[2]), os.environ.get("PYTHONPATH", "")]
        ),
    }
    argv = [
        sys.executable,
        "-m",
        "o3d_lsmesh.cli",
        "batch",
        str(data.good_dir),
        str(tmp_path / "serial"),
        "--op",
        "denoise",
        "--method",
        "global",
        "--workers",
        "0",
        "--quiet",
    ]
    done = subprocess.run(argv, env=environ, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    for record in records:
        relative = Path(record["output"]).relative_to(tmp_path / "out")
        assert Path(record["output"]).read_bytes() == (tmp_path / "serial" / relative).read_bytes()


def test_failures_are_records_and_the_rest_succeed(data, client, tmp_path):
    report = tmp_path / "report.jsonl"
    records = _by_name(
        batch.run(data.mixed_dir, tmp_path / "out", client=client, report=report, progress=False)
    )
    assert {n: r["status"] for n, r in records.items()} == {
        "ok0.ply": "ok",
        "ok1.ply": "ok",
        "corrupt.ply": "failed",
        "empty.ply": "failed",
        "nan.ply": "failed",
    }
    assert (
        records["corrupt.ply"]["stage"] == "read" and "could not be read" in records["corrupt.ply"]["error"]
    )
    assert records["empty.ply"]["stage"] == "read" and "empty file" in records["empty.ply"]["error"]
    assert records["nan.ply"]["stage"] == "denoise" and records["nan.ply"]["error"].startswith(
        ("ValueError", "InputError")
    )
    assert records["nan.ply"]["vertices_before"] == 642
    for name in ("corrupt", "empty", "nan"):
        assert not (tmp_path / "out" / f"{name}.ply").exists()
    # The report: one parseable JSON line per input, the same records.
    lines = [json.loads(line) for line in report.read_text().splitlines()]
    assert sorted(r["input"] for r in lines) == sorted(str(p) for p in data.mixed_dir.iterdir())
    assert {Path(r["input"]).name: r["status"] for r in lines} == {n: r["status"] for n, r in records.items()}


def _crash_or_copy(mesh, options, context):
    """Test-only op: segfaults its worker on files named crash*, else returns the mesh shifted by ``shift``."""
    if Path(context.relative).name.startswith("crash"):
        ctypes.string_at(0)  # reads address 0: SIGSEGV, the worker process dies
    out = o3d.geometry.TriangleMesh(mesh)
    out.translate((float(options["shift"]), 0.0, 0.0))
    return out, {"shift": options["shift"]}


def test_a_task_that_kills_its_worker_fails_alone(data, client, cluster, tmp_path):
    folder = tmp_path / "in"
    for path in data.good:
        _write(o3d.io.read_triangle_mesh(str(path)), folder / path.name)
    _write(o3d.io.read_triangle_mesh(str(data.good[0])), folder / "crash.ply")
    batch.register_op(BatchOp("_test_crash", _crash_or_copy, options=(Option("shift", int_at_least(0), 1),)))
    try:
        records = _by_name(
            batch.run(
                folder,
                tmp_path / "out",
                op="_test_crash",
                options={"shift": 2},
                client=client,
                retries=1,
                progress=False,
            )
        )
    finally:
        OPS.pop("_test_crash")
    assert records["crash.ply"]["status"] == "failed"
    assert records["crash.ply"]["error"].startswith(
        "KilledWorker: each of the 2 workers"
    )  # --retries 1: 2 runs
    for name in ("a.ply", "b.ply", "c.ply", "d.ply"):
        assert records[name]["status"] == "ok", records[name]
        vertices, _ = _read(records[name]["output"])
        original, _ = _read(folder / name)
        np.testing.assert_array_equal(vertices, original + [2.0, 0.0, 0.0])
    client.wait_for_workers(2, timeout=60)  # the nanny replaced the dead workers


def test_resume_after_an_interrupted_batch_redoes_only_what_is_missing(data, client, tmp_path):
    report, out = tmp_path / "report.jsonl", tmp_path / "out"
    folder = tmp_path / "in"
    clean = demo_mesh(3)
    for s in range(6):
        _write(add_noise(clean, 0.3 * mean_edge_length(clean), seed=100 + s), folder / f"m{s}.ply")

    class Interrupt(Exception):
        pass

    seen = []

    def stop_after_two(record):
        seen.append(record)
        if len(seen) == 2:
            raise Interrupt

    with pytest.raises(Interrupt):
        batch.run(folder, out, client=client, report=report, on_record=stop_after_two, progress=False)
    done = {r["input"] for r in seen}
    assert len(done) == 2
    assert [json.loads(line)["input"] for line in report.read_text().splitlines()] == [
        r["input"] for r in seen
    ]
    stamps = {p: os.stat(Path(r["output"])).st_mtime_ns for p, r in ((r["input"], r) for r in seen)}

    records = batch.run(folder, out, client=client, report=report, resume=True, progress=False)
    status = {r["input"]: r["status"] for r in records}
    assert {p for p, s in status.items() if s == "skipped"} == done
    assert {p for p, s in status.items() if s == "ok"} == {str(p) for p in folder.iterdir()} - done
    for path, stamp in stamps.items():
        assert os.stat(out / Path(path).name).st_mtime_ns == stamp  # not written again
    lines = [json.loads(line) for line in report.read_text().splitlines()]
    assert sorted(r["input"] for r in lines) == sorted(str(p) for p in folder.iterdir())  # each input once
    assert all(r["status"] == "ok" for r in lines)

    # A touched input, a deleted output and other options are redone; the rest stays skipped.
    touched = folder / "m0.ply"
    os.utime(touched, ns=(touched.stat().st_atime_ns, touched.stat().st_mtime_ns + 10**9))
    (out / "m1.ply").unlink()
    again = batch.run(folder, out, workers=0, report=report, resume=True, progress=False)
    assert {Path(r["input"]).name for r in again if r["status"] == "ok"} == {"m0.ply", "m1.ply"}
    assert sum(r["status"] == "skipped" for r in again) == 4
    other = batch.run(
        folder, out, workers=0, report=report, resume=True, options={"iterations": 3}, progress=False
    )
    assert all(r["status"] == "ok" for r in other)


# --------------------------------------------------------------------------- the CLI and the engine


def test_cli_uses_an_existing_scheduler(data, client, cluster, tmp_path, capsys, monkeypatch):
    workers = set(client.scheduler_info()["workers"])
    out = tmp_path / "out"
    code = main(
        [
            "batch",
            str(data.good_dir),
            str(out),
            "--op",
            "denoise",
            "--iterations",
            "3",
            "--scheduler",
            cluster.scheduler_address,
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    lines = [json.loads(line) for line in (out / "batch_report.jsonl").read_text().splitlines()]
    assert len(lines) == 4 and all(r["status"] == "ok" for r in lines)
    assert {r["worker"] for r in lines} <= workers  # the test's workers ran them, not a new cluster
    assert (out / "sub" / "d.ply").exists()  # folder structure kept

    # --scheduler-file and DASK_SCHEDULER_ADDRESS reach the same cluster.
    scheduler_file = tmp_path / "scheduler.json"
    scheduler_file.write_text(json.dumps({"address": cluster.scheduler_address}))
    records = batch.run(data.good[:2], tmp_path / "f", scheduler_file=scheduler_file, progress=False)
    assert {r["worker"] for r in records} <= workers and all(r["status"] == "ok" for r in records)
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", cluster.scheduler_address)
    records = batch.run(data.good[:2], tmp_path / "e", progress=False)
    assert {r["worker"] for r in records} <= workers and all(r["status"] == "ok" for r in records)


def test_cli_exit_codes_summary_and_report(data, cluster, tmp_path, capsys):
    address = cluster.scheduler_address
    report = tmp_path / "r.jsonl"
    code = main(
        [
            "batch",
            str(data.mixed_dir),
            str(tmp_path / "out"),
            "--op",
            "denoise",
            "--scheduler",
            address,
            "--report",
            str(report),
        ]
    )
    out = capsys.readouterr().out
    assert code == 2
    assert any(line.split()[:2] == ["failed", "3"] for line in out.splitlines())
    assert any(line.split()[:2] == ["ok", "2"] for line in out.splitlines())
    assert "FAILED" in out and "corrupt.ply" in out
    assert len(report.read_text().splitlines()) == 5
    code = main(
        [
            "batch",
            *map(str, data.mixed),
            str(tmp_path / "out2"),
            "--op",
            "denoise",
            "--scheduler",
            address,
            "--quiet",
            "--json",
        ]
    )
    assert code == 0
    assert json.loads(capsys.readouterr().out)["counts"] == {"ok": 2}


def test_cli_help_lists_every_op_option(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["batch", "--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    for op in OPS.values():
        assert op.name in text
        for option in op.options:
            assert option.cli_flag in text


@pytest.mark.parametrize(
    "argv, message",
    [
        (["MISSING", "OUT", "--op", "denoise"], "does not exist"),
        (["GOOD", "OUT", "--op", "nope"], "--op must be one of"),
        (["GOOD", "OUT", "--op", "denoise", "--count", "5"], "--count is not an option of op denoise"),
        (
            ["GOOD", "OUT", "--op", "denoise", "--iterations", "-1"],
            "--iterations must be a non-negative integer, got '-1' (an option of op denoise)",
        ),
        (["GOOD", "OUT", "--op", "denoise", "--suffix", ".xyz"], "--suffix must be one of"),
        (["GOOD", "OUT", "--op", "denoise", "--set", "method=global"], "--set must look like OP.NAME=VALUE"),
        (["GOOD", "OUT", "--op", "denoise", "--set", "denoise.count=3"], "denoise has no option 'count'"),
        (["GOOD", "OUT", "--op", "encode,denoise"], "must be last in a pipeline"),
        (["GOOD", "OUT", "--op", "compare", "--reference", "NOWHERE"], "must be an existing folder"),
        (["GOOD", "OUT", "--op", "denoise", "--threads-per-worker", "0"], "--threads-per-worker must be"),
        (["GOOD", "OUT", "--op", "denoise", "--retries", "-1"], "--retries must be"),
        (["GOOD", "OUT", "--op", "denoise", "--workers", "-2"], "--workers must be"),
    ],
)
def test_cli_bad_arguments_exit_2_with_one_line(data, tmp_path, capsys, argv, message):
    replace = {
        "MISSING": str(tmp_path / "nothing.ply"),
        "GOOD": str(data.good_dir),
        "OUT": str(tmp_path / "o"),
        "NOWHERE": str(tmp_path / "nowhere"),
    }
    code = main(["batch", *(replace.get(a, a) for a in argv)])
    err = capsys.readouterr().err
    assert code == 2
    assert "Traceback" not in err
    assert message in err.strip().splitlines()[-1]


def test_local_cluster_workers_are_spawned_never_forked(data, tmp_path, monkeypatch, client):
    import dask

    # The module's cluster: its workers lack a module only this process has, so they were not forked.
    assert not any(client.run(lambda: _SENTINEL in sys.modules).values())
    assert _SENTINEL in sys.modules

    methods = []
    real = multiprocessing.get_context

    def spy(method=None):
        methods.append(method)
        return real(method)

    monkeypatch.setattr(multiprocessing, "get_context", spy)
    batch.register_op(BatchOp("_test_env", _environment))
    try:
        # Even with Dask configured for fork, the batch's own cluster spawns its workers.
        with dask.config.set({"distributed.worker.multiprocessing-method": "fork"}):
            records = batch.run(
                data.good[:2],
                tmp_path / "out",
                op="_test_env",
                workers=1,
                threads_per_worker=2,
                progress=False,
            )
    finally:
        OPS.pop("_test_env")
    assert "fork" not in methods and "spawn" in methods
    assert [r["status"] for r in records] == ["ok", "ok"]
    metrics = records[0]["metrics"]["_test_env"]
    assert metrics["forked"] is False
    assert metrics["OMP_NUM_THREADS"] == metrics["OPENBLAS_NUM_THREADS"] == "2"
    assert metrics["MALLOC_TRIM_THRESHOLD_"] is None  # Dask's default, which doubles array-heavy tasks' time


def _environment(mesh, options, context):
    """Test-only op: what the worker process looks like from inside."""
    return o3d.geometry.TriangleMesh(mesh), {
        "forked": _SENTINEL in sys.modules,
        "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS"),
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
        "MALLOC_TRIM_THRESHOLD_": os.environ.get("MALLOC_TRIM_THRESHOLD_"),
    }


def test_no_fork_based_pool_in_the_package():
    package = Path(batch.__file__).parents[1]
    for path in package.rglob("*.py"):
        text = path.read_text()
        for banned in (
            "ProcessPoolExecutor",
            "multiprocessing.Pool",
            "os.fork(",
            'get_context("fork")',
            "get_context('fork')",
        ):
            assert banned not in text, f"{path.name} uses {banned}"


# --------------------------------------------------------------------------- serial path and the other ops


def test_without_dask_a_serial_loop_with_a_message(data, tmp_path, monkeypatch):
    monkeypatch.setattr(tasks, "_dask_available", lambda: False)
    with pytest.warns(O3DLSMeshWarning, match="dask.distributed is not installed.*one after another"):
        records = batch.run(data.good[:2], tmp_path / "out", progress=False)
    assert [(r["status"], r["worker"]) for r in records] == [("ok", "local"), ("ok", "local")]
    with pytest.raises(ImportError, match=r"o3d_lsmesh\[dask\]"):
        batch.run(data.good[:1], tmp_path / "out", scheduler="tcp://127.0.0.1:1", progress=False)


def test_a_write_open3d_refuses_is_a_failure_record(data, tmp_path, monkeypatch):
    monkeypatch.setattr(o3d.io, "write_triangle_mesh", lambda *args, **kwargs: False)
    (record,) = batch.run(data.good[:1], tmp_path / "out", workers=0, progress=False)
    assert (record["status"], record["stage"]) == ("failed", "write")
    assert "could not write" in record["error"]
    assert list((tmp_path / "out").iterdir()) == []  # neither the output nor a temporary file


def test_batch_and_cli_refuse_a_bad_file_with_the_same_message(data, tmp_path, capsys):
    # one reader for both: each defect is a "read" failure record holding the CLI's exact message
    whole = data.good[0].read_bytes()
    points = o3d.geometry.TriangleMesh()
    points.vertices = o3d.utility.Vector3dVector(np.random.default_rng(0).random((5, 3)))
    bad = tmp_path / "bad"
    bad.mkdir()
    o3d.io.write_triangle_mesh(str(bad / "points.ply"), points)
    (bad / "empty.ply").write_bytes(b"")
    (bad / "garbage.ply").write_bytes(b"\x00\x01 not a ply at all")
    (bad / "cut.ply").write_bytes(whole[: len(whole) // 2])  # batch read half the mesh before
    expected = {
        "points.ply": "has 5 vertices but no triangles",
        "empty.ply": "is an empty file",
        "garbage.ply": "could not be read as a triangle mesh",
        "cut.ply": "is truncated or corrupt",
    }
    records = _by_name(batch.run(bad, tmp_path / "out", workers=0, progress=False))
    assert sorted(records) == sorted(expected)
    for name, words in expected.items():
        record = records[name]
        assert (record["status"], record["stage"]) == ("failed", "read")
        assert main(["denoise", str(bad / name), str(tmp_path / "o.ply")]) == 2
        line = capsys.readouterr().err.strip().splitlines()[-1]
        message = f"INPUT {str(bad / name)!r} "
        assert line.startswith(f"o3d-lsmesh: error: {message}") and words in line
        kind, _, message = record["error"].partition(": ")
        assert kind in ("ValueError", "InputError") and message == line.removeprefix("o3d-lsmesh: error: ")


def test_fail_fast_stops_at_the_first_failure(data, tmp_path):
    records = _by_name(
        batch.run(
            [data.mixed_dir / "corrupt.ply", *data.mixed],
            tmp_path / "out",
            workers=0,
            fail_fast=True,
            progress=False,
        )
    )
    assert records["corrupt.ply"]["status"] == "failed"
    assert records["ok0.ply"]["status"] == records["ok1.ply"]["status"] == "cancelled"


@pytest.mark.parametrize("option", [{"mu": 0.5}, {"reimpose_every": 2}, {"fixed_boundary": True}])
def test_denoise_at_a_level_refuses_what_multiresolution_fairing_does_not_take(data, tmp_path, option):
    # the command line refuses these flags beside --level; a batch must not drop them without a word,
    # and refuses them as the command does: before any file is read
    with pytest.raises(ValueError, match=r"cannot be combined with level=1") as info:
        batch.run(data.mixed[:1], tmp_path / "out", options={"level": 1, **option}, workers=0, progress=False)
    name, value = next(iter(option.items()))
    assert f"{name}={value!r}" in str(info.value) and info.value.param == "level"
    assert not (tmp_path / "out").exists()


def test_other_ops_and_a_pipeline_match_the_library(data, tmp_path):
    from o3d_lsmesh.app.metrics import surface_distance
    from o3d_lsmesh.hierarchy import build_hierarchy
    from o3d_lsmesh.lsmesh.encoding import decode_geometry, encode_geometry
    from o3d_lsmesh.lsmesh.selection import approximate

    source = data.good[0]
    mesh = o3d.io.read_triangle_mesh(str(source))

    (record,) = batch.run(
        source,
        tmp_path / "a",
        op="approximate",
        options={"count": "5%"},
        workers=0,
        progress=False,
        suffix=".off",
    )
    expected, indices = approximate(mesh, int(np.ceil(0.05 * 642)))
    assert (
        record["output"].endswith("a.off") and record["metrics"]["approximate"]["count"] == len(indices) == 33
    )
    # OFF stores 6 significant digits.
    np.testing.assert_allclose(
        _read(record["output"])[0], np.asarray(expected.vertices), rtol=1e-5, atol=1e-6
    )

    (record,) = batch.run(
        source, tmp_path / "e", op="encode", options={"count": 20, "bits": 10}, workers=0, progress=False
    )
    data_bytes = Path(record["output"]).read_bytes()
    assert record["output"].endswith("a.bin") and data_bytes == encode_geometry(mesh, 20, bits=10)
    np.testing.assert_array_equal(
        np.asarray(decode_geometry(mesh, data_bytes).vertices),
        np.asarray(decode_geometry(mesh, encode_geometry(mesh, 20, bits=10)).vertices),
    )

    # the default count "2%" is parsed as if given (it reached the op as text before)
    (record,) = batch.run(source, tmp_path / "d", op="approximate,encode", workers=0, progress=False)
    assert record["status"] == "ok" and record["metrics"]["encode"]["anchors"] == int(np.ceil(0.02 * 642))

    (record,) = batch.run(
        source,
        tmp_path / "h",
        op="hierarchy",
        options={"levels": "0,2", "maps": True},
        workers=0,
        progress=False,
    )
    hierarchy = build_hierarchy(mesh)
    folder = Path(record["output"])
    assert sorted(p.name for p in folder.iterdir()) == ["level_00.ply", "level_02.ply", "vertex_maps.npz"]
    np.testing.assert_array_equal(_read(folder / "level_02.ply")[1], np.asarray(hierarchy.level(2).triangles))
    np.testing.assert_array_equal(np.load(folder / "vertex_maps.npz")["level_02"], hierarchy.vertex_map(2))

    # denoise, then compare with the matching file of the reference folder (here: the noisy input itself).
    (record,) = batch.run(
        source,
        tmp_path / "c",
        op="denoise,compare",
        options={"reference": data.good_dir, "iterations": 3},
        workers=0,
        progress=False,
    )
    faired = constrained_fairing(mesh, 3)
    # the denoised meshes are written (a metrics-only last op wrote nothing: the pipeline's meshes were lost)
    assert record["status"] == "ok" and Path(record["output"]) == tmp_path / "c" / Path(source).name
    np.testing.assert_allclose(_read(record["output"])[0], np.asarray(faired.vertices), rtol=0, atol=1e-12)
    distance = surface_distance(faired, mesh, number_of_points=100_000)
    assert record["metrics"]["compare"]["surface_distance"]["hausdorff"] == pytest.approx(
        distance["hausdorff"]
    )
    missing = batch.run(
        source, tmp_path / "m", op="compare", options={"reference": tmp_path}, workers=0, progress=False
    )
    assert missing[0]["status"] == "failed" and "has no file matching" in missing[0]["error"]


def test_api_errors(data, tmp_path):
    with pytest.raises(TypeError, match="op must be"):
        batch.run(data.good[0], tmp_path, op=3, workers=0)
    with pytest.raises(TypeError, match="inputs must be paths"):
        batch.run([3], tmp_path, workers=0)
    with pytest.raises(ValueError, match="matches no file"):
        batch.run(str(tmp_path / "*.ply"), tmp_path, workers=0)
    with pytest.raises(ValueError, match="resume needs a report"):
        batch.run(data.good[0], tmp_path, resume=True, workers=0)
    with pytest.raises(ValueError, match="not both"):
        batch.run(data.good[0], tmp_path, scheduler="tcp://x:1", scheduler_file="f.json")
    twin = _write(o3d.io.read_triangle_mesh(str(data.good[0])), tmp_path / "twin" / "a.ply")
    with pytest.raises(ValueError, match="would both write"):
        batch.run([str(data.good_dir / "**" / "*.ply"), twin], tmp_path / "o", workers=0)
    copy = _write(o3d.io.read_triangle_mesh(str(data.good[0])), tmp_path / "same" / "x.ply")
    with pytest.raises(ValueError, match="would overwrite the input"):
        batch.run(copy, copy.parent, workers=0)
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="exists and is not a folder"):
        batch.run(data.good[0], tmp_path / "file", workers=0)
    with pytest.raises(ValueError, match="option name 'workers'"):
        BatchOp("x", _environment, options=(Option("workers", int),))
    with pytest.raises(TypeError, match="BatchOp"):
        batch.register_op("denoise")


def test_fill_op_and_a_fill_denoise_pipeline_match_the_library(data, tmp_path):
    from o3d_lsmesh import fill_holes

    mesh = o3d.io.read_triangle_mesh(str(data.good[0]))
    # cut a hole: drop the triangles around vertex 0
    triangles = np.asarray(mesh.triangles)
    holed = o3d.geometry.TriangleMesh(
        mesh.vertices, o3d.utility.Vector3iVector(triangles[(triangles != 0).all(1)])
    )
    holed.remove_unreferenced_vertices()
    source = tmp_path / "holed.ply"
    o3d.io.write_triangle_mesh(str(source), holed)
    holed = o3d.io.read_triangle_mesh(str(source))

    (record,) = batch.run(
        source, tmp_path / "f", op="fill", options={"continuity": "1"}, workers=0, progress=False
    )
    expected = fill_holes(holed, continuity=1)
    vertices, filled = _read(record["output"])
    np.testing.assert_array_equal(filled, np.asarray(expected.triangles))
    np.testing.assert_allclose(vertices, np.asarray(expected.vertices), rtol=0, atol=1e-12)
    assert record["metrics"]["fill"]["new_triangles"] == len(filled) - len(holed.triangles) > 0
    assert (record["metrics"]["fill"]["holes_filled"], record["metrics"]["fill"]["holes_skipped"]) == (1, 0)
    (record,) = batch.run(
        source, tmp_path / "f3", op="fill", options={"max_hole_edges": 3}, workers=0, progress=False
    )
    fill = record["metrics"]["fill"]
    ring = len(np.unique(triangles[(triangles == 0).any(1)])) - 1  # the hole's edges: vertex 0's neighbours
    assert (fill["holes_filled"], fill["holes_skipped"], fill["new_triangles"]) == (0, 1, 0)
    assert fill["left_open"].startswith(f"loop 0 ({ring} edges")

    (record,) = batch.run(
        source,
        tmp_path / "fd",
        op="fill,denoise",
        options={"method": "local", "iterations": 2},
        workers=0,
        progress=False,
    )
    assert record["status"] == "ok"
    np.testing.assert_array_equal(_read(record["output"])[1], np.asarray(expected.triangles))


def test_the_batch_flags_are_run_s_parameters_and_reserved_for_it():
    # one table (ops.RUN_FLAGS) makes the flags of `o3d-lsmesh batch` and hands them to batch.run;
    # an op option may not take any of their names
    import inspect

    from o3d_lsmesh.app.ops import RESERVED, RUN_FLAGS

    names = {option.name for option in RUN_FLAGS}
    assert names <= set(inspect.signature(batch.run).parameters)
    assert RESERVED == names | {"op", "set", "quiet", "json", "force", "help"}
