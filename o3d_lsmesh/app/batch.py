"""Run an operation over many mesh files: on a local Dask cluster by default, or on an existing one.

Each file is one task (:func:`~o3d_lsmesh.app.tasks.run_task`) that reads, runs and writes inside
a worker process and returns a small JSON record: meshes never travel between processes, and a file
that fails, even one that crashes its worker, costs that file only. A local cluster's workers are
*spawned* (a forked worker deadlocks once the parent has used CHOLMOD's OpenMP runtime); without
Dask the files run one after another in this process. Tasks are submitted in a window a few times
the cluster's threads (:class:`_Window`). Docs: ``docs/batch.md``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import time
import warnings
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from itertools import islice
from pathlib import Path
from typing import Any, Callable

from ..core.errors import InputError, O3DLSMeshWarning
from ..core.progress import check_progress, progress_bar
from ..core.validate import as_workers
from .files import WRITABLE, collect_inputs, digest, inside, output_path
from .ops import OPS, BatchOp, Option, parse_ops, register_op, resolve_options
from .tasks import new_record, run_task

__all__ = ["OPS", "BatchOp", "Option", "collect_inputs", "local_cluster", "register_op", "run", "summarize"]


@dataclass(frozen=True)
class _Task:
    index: int
    path: str
    relative: str
    output: str | None
    key: str


def task_key(path: str, ops: Sequence[BatchOp], options: Sequence[dict], suffix: str) -> str:
    """Hash of the pipeline, its options, the output suffix and the input's size and mtime (the resume key)."""
    stat = os.stat(path)
    payload = json.dumps(
        {
            "op": [op.name for op in ops],
            "options": options,
            "suffix": suffix,
            "size": stat.st_size,
            "mtime_ns": stat.st_mtime_ns,
        },
        sort_keys=True,
        default=str,
    )
    return hashlib.sha256(payload.encode()).hexdigest()[:32]


def _read_report(path: Path) -> dict[str, dict]:
    """Last record per input of an existing report; a damaged line (not a JSON record in UTF-8, e.g. the
    torn last line of a killed run) is skipped with a warning naming it."""
    last: dict[str, dict] = {}
    if not path.exists():
        return last
    damaged = []
    with open(path, "rb") as handle:
        for number, line in enumerate(handle, 1):
            try:
                record = json.loads(line.decode("utf-8"))
            except ValueError:  # UnicodeDecodeError and JSONDecodeError both are
                record = None
            if isinstance(record, dict) and isinstance(record.get("input"), str):
                last[record["input"]] = record
            elif line.strip():
                damaged.append(number)
    if damaged:
        shown = ", ".join(map(str, damaged[:10])) + (", ..." if len(damaged) > 10 else "")
        warnings.warn(
            f"report {str(path)!r}: lines {shown} are damaged (not a JSON record in UTF-8) and were "
            "skipped; their files run again",
            O3DLSMeshWarning,
            stacklevel=3,
        )
    return last


def _intact(outdir: Path, files: Any) -> bool:
    """Whether every file a report record lists is in ``outdir`` with the recorded size and sha256."""
    if not isinstance(files, dict) or not files:
        return False  # a record of an older version, or damaged: run the file again
    for name, expected in files.items():
        path = outdir / name
        if (
            not isinstance(expected, dict)
            or not path.is_file()
            or path.stat().st_size != expected.get("bytes")
        ):
            return False
        if digest(path) != expected:
            return False
    return True


# --------------------------------------------------------------------------- engines


def _dask_available() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def _scheduler_address() -> str | None:
    address = os.environ.get("DASK_SCHEDULER_ADDRESS")
    if address:
        return address
    try:
        import dask

        return dask.config.get("scheduler-address", None)
    except ImportError:
        return None


def _check_scheduler_file(path: str | os.PathLike) -> None:
    """Refuse a scheduler file that is missing or holds no address (Dask's client would wait for it forever)."""
    expected = "scheduler_file must be the JSON file a running Dask scheduler wrote"
    if not os.path.isfile(path):
        raise InputError(f"{expected}, got {os.fspath(path)!r}, which does not exist", param="scheduler_file")
    try:
        with open(path, encoding="utf-8") as handle:
            address = json.load(handle).get("address")
    except (ValueError, AttributeError):
        address = None
    if not isinstance(address, str):
        raise InputError(
            f"{expected}, got {os.fspath(path)!r}, which holds no JSON 'address'", param="scheduler_file"
        )


def _start_method() -> str:
    """The worker start method: the configured one unless it is ``fork`` (then ``spawn``)."""
    import dask

    method = dask.config.get("distributed.worker.multiprocessing-method", "spawn")
    return "spawn" if method not in ("spawn", "forkserver") else method


def local_cluster(workers: int, threads_per_worker: int = 1, *, retries: int = 1, **kwargs: Any) -> Any:
    """A ``LocalCluster`` of ``workers`` spawned processes with ``threads_per_worker`` threads each.

    BLAS/OpenMP thread variables are set before the workers start (CHOLMOD and
    OpenBLAS read them once, when they load), Dask's ``MALLOC_TRIM_THRESHOLD_``
    is left out (it doubles the time of array-heavy tasks), a task may kill at most
    ``retries + 1`` workers before it is reported failed (Dask's
    ``allowed-failures``), and the dashboard takes a free port on 127.0.0.1.
    """
    import dask
    from distributed import LocalCluster

    threads = str(threads_per_worker)
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}) or {})
    environ.update(OMP_NUM_THREADS=threads, OPENBLAS_NUM_THREADS=threads, MKL_NUM_THREADS=threads)
    # Dask sets MALLOC_TRIM_THRESHOLD_=65536, which turns off glibc's dynamic mmap threshold: every array
    # above 128 KiB becomes a fresh mmap whose pages fault in zeroed (benchmarks/results/batch.md)
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    with dask.config.set(
        {
            "distributed.worker.multiprocessing-method": _start_method(),
            "distributed.scheduler.allowed-failures": retries,
            # One task per worker thread at a time: a dying worker takes no queued task along.
            "distributed.scheduler.worker-saturation": 1.0,
            "distributed.nanny.pre-spawn-environ": environ,
        }
    ):
        # The scheduler always serves HTTP (8787 unless told): a free local port avoids clashing with another
        # cluster on this machine (and gives a dashboard when bokeh is installed).
        kwargs.setdefault("dashboard_address", "127.0.0.1:0")
        kwargs.setdefault("silence_logs", logging.ERROR)
        return LocalCluster(
            n_workers=workers, threads_per_worker=threads_per_worker, processes=True, **kwargs
        )


class _Window:
    """How many tasks to keep submitted: sized from the cluster's worker threads, re-read at most once a second.

    Above ``2 x threads`` tasks, Dask treats the tasks as root tasks and queues them on the scheduler,
    handing each worker only ``worker-saturation x threads`` at a time (1 on :func:`local_cluster`): so a
    worker that dies holds no innocent task (Dask counts every task held by a dying worker as suspect),
    and a finished worker gets its next file without a round trip through this client. A window of
    ``4 x threads + 4`` keeps that queue filled; a batch of at most ``2 x threads`` files, which Dask
    would hand out all at once, gets a window of ``threads`` instead.
    """

    def __init__(self, client: Any, total: int):
        self.client, self.total, self.value, self.when = client, total, 1, -1.0

    def __call__(self) -> int:
        now = time.monotonic()
        if now - self.when > 1.0:
            threads = max(1, sum(self.client.nthreads().values()))
            self.value = threads if self.total <= 2 * threads else 4 * threads + 4
            self.when = now
        return self.value


def _failure(task: _Task, op: str, message: str, stage: str = "worker") -> dict:
    return new_record(input=task.path, error=message, stage=stage, op=op, key=task.key)


def _run_dask(client: Any, tasks: list[_Task], job: dict, emit: Callable[[dict], bool], retries: int) -> None:
    from concurrent.futures import CancelledError

    from distributed import KilledWorker, as_completed

    cancelled: tuple[type[BaseException], ...]
    try:
        from distributed.client import FutureCancelledError

        cancelled = (CancelledError, FutureCancelledError)
    except ImportError:  # pragma: no cover - distributed before 2024.8
        cancelled = (CancelledError,)

    token = os.urandom(4).hex()
    pending = iter(tasks)
    by_key: dict[str, _Task] = {}
    queue = as_completed()

    def submit(n: int) -> None:
        chunk = list(islice(pending, max(0, n)))
        if not chunk:
            return
        keys = [f"o3d-lsmesh-batch-{token}-{task.index}" for task in chunk]
        futures = client.map(
            run_task,
            [t.path for t in chunk],
            [t.relative for t in chunk],
            [t.key for t in chunk],
            key=keys,
            pure=False,
            **job,
        )
        for task, future in zip(chunk, futures):
            by_key[future.key] = task
            queue.add(future)

    window = _Window(client, len(tasks))
    submit(window())
    op_name = ",".join(op.name for op in job["ops"])
    try:
        for future in queue:
            task = by_key.pop(future.key)
            try:
                record = future.result()
            except KilledWorker as error:
                tries = getattr(error, "allowed_failures", retries) + 1
                last = getattr(getattr(error, "last_worker", None), "address", "?")
                record = _failure(
                    task,
                    op_name,
                    f"KilledWorker: each of the {tries} workers that ran it died (a crash "
                    f"such as a segfault, or killed, e.g. for memory); last worker {last}",
                )
                record["worker"] = last
            except cancelled:
                record = _failure(task, op_name, "cancelled")
            except Exception as error:
                record = _failure(task, op_name, f"{type(error).__name__}: {error}")
            future.release()
            if str(record.get("error")).startswith("TaskTimeout"):
                record["error"] += _restart(client, record.get("worker"))
            if not emit(record):
                break
            size, held = window(), queue.count()
            if held <= size // 2:  # refill in chunks: each client.map is one graph update on the scheduler
                submit(size - held)
    finally:
        # Whatever stopped the loop (--fail-fast, an exception, Ctrl-C): drop what is still queued or running.
        remaining = list(getattr(queue, "futures", ()))
        if remaining:
            client.cancel(remaining)


def _restart(client: Any, worker: Any) -> str:
    """Restart the worker running an abandoned task (only a nanny can: else it runs on there)."""
    try:
        status = client.restart_workers([worker], raise_for_error=False).get(worker)
    except Exception as error:  # whatever it is, the record says so
        status = f"{type(error).__name__}: {error}"
    if status == "OK":
        return "; its worker was restarted"
    return f"; its worker could not be restarted ({status}), so it runs on there"


# --------------------------------------------------------------------------- the API


def run(
    inputs: str | os.PathLike | Iterable[str | os.PathLike],
    outdir: str | os.PathLike,
    *,
    op: str | Sequence[str] | BatchOp = "denoise",
    options: Mapping[str, Any] | None = None,
    client: Any = None,
    workers: int | None = None,
    threads_per_worker: int = 1,
    scheduler: str | None = None,
    scheduler_file: str | os.PathLike | None = None,
    resume: bool = False,
    report: str | os.PathLike | None = None,
    retries: int = 1,
    fail_fast: bool = False,
    suffix: str = ".ply",
    force: bool = False,
    progress: bool = True,
    on_record: Callable[[dict], None] | None = None,
    task_timeout: float | None = 3600.0,
) -> list[dict]:
    """Run ``op`` on every mesh file of ``inputs`` and write the results into ``outdir``.

    Parameters
    ----------
    inputs : path, glob pattern, or a list of them
        Files, folders (searched recursively for ``.ply .obj .stl .off .gltf .glb``) and globs;
        folder searches and globs leave out ``outdir`` and a killed batch's hidden temporary names.
    outdir : path
        Output folder (created). The result of ``a/b.ply`` from a folder INPUT
        is ``outdir/a/b<suffix>``; ``encode`` writes ``<name>.bin``,
        ``hierarchy`` a folder ``<name>/``, ``compare`` nothing. A stem ``.`` or
        ``..`` (the file ``..ply``) is written as ``_dot`` or ``_dotdot``. Nothing
        is written outside ``outdir`` and nothing this call did not write is
        removed (an existing output folder is updated file by file).
    op : str, keyword-only
        An operation of :data:`OPS` (``denoise``, ``hierarchy``,
        ``approximate``, ``encode``, ``compare``, ...) or a pipeline run in
        order on each file, e.g. ``"denoise,compare"``.
    options : dict, keyword-only
        Options of the operations, e.g. ``{"iterations": 5, "method": "global"}``
        (applies to every op of the pipeline that has the option) or
        ``{"denoise.method": "global"}`` for one op.
    client : dask.distributed.Client, keyword-only
        Use this client (its cluster is left running). Otherwise ``scheduler``,
        ``scheduler_file`` or ``DASK_SCHEDULER_ADDRESS`` connect to an existing
        cluster, else a local cluster of ``workers`` spawned processes is
        started for this call and closed at the end.
    workers : int, keyword-only
        Local worker processes (default: CPUs // ``threads_per_worker``);
        ``0`` runs the files one after another in this process.
    threads_per_worker : int, keyword-only
        Threads of each worker and its BLAS/OpenMP/Open3D thread cap.
    resume : bool, keyword-only
        Skip inputs whose last ``report`` entry is ``ok`` for the same key
        (pipeline, options, suffix, input size and mtime) and output, and
        whose output files are all there with the recorded size and sha256;
        they come back with status ``skipped``.
    report : path, keyword-only
        JSON-lines file getting one record per result as it arrives (appended
        to with ``resume``, else overwritten).
    retries : int, keyword-only
        How many times a task whose worker died is run again on a new worker
        (Dask's ``allowed-failures`` of the local cluster; an existing
        cluster keeps its own setting).
    fail_fast : bool, keyword-only
        Stop at the first failure; files not run come back as ``cancelled``.
    suffix : str, keyword-only
        Output mesh format, one of ``.ply .obj .stl .off .gltf``.
    force : bool, keyword-only
        Allow an output path to be one of the input files.
    progress : bool, keyword-only
        Show a tqdm bar with done/failed counts and an ETA.
    on_record : callable, keyword-only
        Called with each record as it arrives; an exception it raises stops the batch.
    task_timeout : float or None, keyword-only
        Seconds a file may take (``None`` or 0: no limit). Past them its record says
        ``TaskTimeout`` and the task can no longer write; on Dask its worker process is
        restarted (a nanny's worker; else it runs on there). In the serial loop
        (``workers=0``) Python cannot stop it: it runs on in a background thread of this
        process until it ends, taking a core, while the next files run.

    Returns
    -------
    list of dict
        One record per input, in input order: ``input``, ``output``,
        ``status`` (``ok``, ``failed``, ``skipped`` or ``cancelled``),
        ``error``, ``stage`` (where it failed: ``read``, an op name, ``write``
        or ``worker``), ``seconds`` and ``cpu_seconds`` of the task, ``vertices_before/after``,
        ``triangles_before/after``, ``metrics`` (per op), ``key``, ``worker``,
        ``files`` (each written file's ``bytes`` and ``sha256``) and ``warnings``
        (what the task warned, also re-issued here with the file name).

    Raises
    ------
    InputError
        Unknown op or option, a bad value (``param`` names the parameter or option), no input
        file, two inputs with the same output, an output that is an input file (without ``force``).
    InputTypeError
        ``inputs`` or ``op`` of the wrong kind.

    Examples
    --------
    >>> import tempfile, open3d as o3d
    >>> from o3d_lsmesh.app import batch
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     ball = o3d.geometry.TriangleMesh.create_sphere(resolution=8)
    ...     _ = o3d.io.write_triangle_mesh(f"{folder}/ball.ply", ball)
    ...     records = batch.run(folder, f"{folder}/out", op="denoise", workers=0, progress=False)
    >>> [r["status"] for r in records]
    ['ok']
    """
    ops = parse_ops(op)
    pipeline = ",".join(o.name for o in ops)
    values = resolve_options(ops, options)
    if not isinstance(suffix, str) or suffix.lower() not in WRITABLE:
        raise InputError(f"suffix must be one of {', '.join(WRITABLE)}, got {suffix!r}", param="suffix")
    suffix = suffix.lower()
    for name, value, minimum in (
        ("threads_per_worker", threads_per_worker, 1),
        ("retries", retries, 0),
        ("workers", 0 if workers is None else workers, 0),
    ):
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}", param=name)
    if scheduler is not None and scheduler_file is not None:
        raise InputError(
            "scheduler_file must be None when scheduler is given (not both)", param="scheduler_file"
        )
    if scheduler_file is not None:
        _check_scheduler_file(scheduler_file)
    if task_timeout is not None and (
        isinstance(task_timeout, bool)
        or not isinstance(task_timeout, (int, float))
        or not 0 <= task_timeout < float("inf")
    ):
        raise InputError(
            f"task_timeout must be a number of seconds >= 0 (0: no limit) or None, got {task_timeout!r}",
            param="task_timeout",
        )
    progress = check_progress(progress)
    if resume and report is None:
        raise InputError("resume needs a report (the file that says which inputs are done)", param="report")

    outdir = Path(outdir).absolute()
    items = collect_inputs(inputs, exclude=outdir)
    if outdir.exists() and not outdir.is_dir():
        raise InputError(f"OUTDIR {str(outdir)!r} exists and is not a folder", param="outdir")
    tasks: list[_Task] = []
    outputs: dict[str, str] = {}
    refused: list[dict] = []
    for index, (path, relative) in enumerate(items):
        target = output_path(outdir, relative, ops[-1], suffix)
        output = None if target is None else str(target)
        key = task_key(path, ops, values, suffix)
        if output is not None and not inside(output, outdir):  # a symbolic link inside OUTDIR leads out
            message = f"output {output!r} resolves to {os.path.realpath(output)!r}, outside OUTDIR"
            refused.append(
                new_record(input=os.path.abspath(path), error=message, stage="write", op=pipeline, key=key)
            )
        elif output is not None:
            if output in outputs:
                raise InputError(
                    f"INPUT files {outputs[output]!r} and {path!r} would both write {output!r}; "
                    "pass their folder instead of a glob so that outputs keep the subfolders",
                    param="inputs",
                )
            outputs[output] = path
            if not force and os.path.exists(output) and os.path.samefile(output, path):
                raise InputError(
                    f"OUTDIR {str(outdir)!r} would overwrite the input {path!r} (use another OUTDIR or "
                    "suffix, or force)",
                    param="outdir",
                )
        tasks.append(_Task(index, os.path.abspath(path), relative, output, key))

    report_path = None if report is None else Path(report)
    # (resume without a report was refused above)
    previous = _read_report(report_path) if resume and report_path is not None else {}
    records: list[dict | None] = [None] * len(tasks)
    todo = []
    not_run = {record["input"] for record in refused}
    for task in tasks:
        if task.path in not_run:
            continue
        old = previous.get(task.path, {})
        if (
            old.get("status") == "ok"
            and old.get("key") == task.key
            and old.get("output") == task.output
            and (task.output is None or _intact(outdir, old.get("files")))
        ):
            records[task.index] = {**old, "status": "skipped"}
        else:
            todo.append(task)
    outdir.mkdir(parents=True, exist_ok=True)
    # The workers need the op functions, not the option parsers: without them (closures that only cloudpickle
    # can send) every task pickles in ~200 bytes with the standard pickle instead of ~3 kB.
    shipped = [dataclasses.replace(o, options=()) for o in ops]
    job = {
        "outdir": str(outdir),
        "ops": shipped,
        "options": values,
        "suffix": suffix,
        "threads": threads_per_worker,
        "timeout": task_timeout or None,
    }

    bar = progress_bar(
        progress,
        total=len(tasks),
        initial=len(tasks) - len(todo) - len(refused),
        desc=f"batch {pipeline}",
        unit="file",
        dynamic_ncols=True,
    )
    counts: Counter = Counter()
    index_of = {task.path: task.index for task in tasks}
    handle = None
    if report_path is not None:
        report_path.parent.mkdir(parents=True, exist_ok=True)
        handle = open(report_path, "a+b" if resume else "wb")
        if handle.tell():
            handle.seek(-1, os.SEEK_END)
            if handle.read(1) != b"\n":
                handle.write(b"\n")  # a killed run's torn last line: the next record starts a line of its own

    def emit(record: dict) -> bool:
        """Store, report and show one result; False asks the engine to stop (--fail-fast)."""
        records[index_of[record["input"]]] = record
        counts[record["status"]] += 1
        if handle is not None:
            handle.write(json.dumps(record).encode() + b"\n")
            handle.flush()
        bar.update(1)
        bar.set_postfix(ok=counts["ok"], failed=counts["failed"], refresh=False)
        for text in (
            record.get("warnings") or ()
        ):  # (after the report: a warning filtered to an error stops here)
            warnings.warn(f"{record['input']}: {text}", O3DLSMeshWarning, stacklevel=2)
        if on_record is not None:
            on_record(record)
        return not (fail_fast and record["status"] == "failed")

    try:
        if all(emit(record) for record in refused) and todo:
            _dispatch(
                todo,
                job,
                emit,
                client=client,
                workers=workers,
                threads_per_worker=threads_per_worker,
                scheduler=scheduler,
                scheduler_file=scheduler_file,
                retries=retries,
            )
    finally:
        bar.close()
        if handle is not None:
            handle.close()
    return [
        record
        if record is not None
        else _failure(task, pipeline, "not run (--fail-fast stopped the batch)", stage="cancelled")
        | {"status": "cancelled"}
        for task, record in zip(tasks, records)
    ]


def _dispatch(
    todo: list[_Task],
    job: dict,
    emit: Callable[[dict], bool],
    *,
    client: Any,
    workers: int | None,
    threads_per_worker: int,
    scheduler: Any,
    scheduler_file: Any,
    retries: int,
) -> None:
    address = None if client is not None else (scheduler or _scheduler_address())
    remote = client is not None or address is not None or scheduler_file is not None
    if not remote and workers == 0:
        return _run_serial(todo, job, emit)
    if not _dask_available():
        if remote:
            raise ImportError(
                "connecting to a Dask scheduler needs dask.distributed: pip install 'o3d_lsmesh[dask]'"
            )
        warnings.warn(
            "dask.distributed is not installed, so the files run one after another in this process; "
            "pip install 'o3d_lsmesh[dask]' to use every core or a cluster",
            O3DLSMeshWarning,
            stacklevel=3,
        )
        return _run_serial(todo, job, emit)
    from distributed import Client

    if client is not None:
        return _run_dask(client, todo, job, emit, retries)
    if remote:
        if workers is not None:
            warnings.warn(
                "--workers is ignored when connecting to an existing cluster", O3DLSMeshWarning, stacklevel=3
            )
        kwargs = (
            {"scheduler_file": os.fspath(scheduler_file)}
            if scheduler_file is not None
            else {"address": address}
        )
        with Client(**kwargs) as own:
            return _run_dask(own, todo, job, emit, retries)
    n = workers if workers is not None else max(1, as_workers(None) // threads_per_worker)
    n = min(n, len(todo))  # no worker that would never get a file
    with local_cluster(n, threads_per_worker, retries=retries) as cluster, Client(cluster) as own:
        return _run_dask(own, todo, job, emit, retries)


def _run_serial(todo: list[_Task], job: dict, emit: Callable[[dict], bool]) -> None:
    # Threads are left as the caller's process has them: this loop runs in the caller's process, whose
    # warning state each task restores (a task routes its warnings into its record; emit re-issues them).
    for task in todo:
        with warnings.catch_warnings():
            record = run_task(task.path, task.relative, task.key, **{**job, "threads": None})
        if not emit(record):
            return


def summarize(records: Sequence[dict], seconds: float | None = None) -> str:
    """A plain-text summary table of ``records`` (counts and time per status, then the failures)."""
    rows = []
    for status in ("ok", "failed", "skipped", "cancelled"):
        chosen = [r for r in records if r["status"] == status]
        if chosen or status in ("ok", "failed"):
            times = [r["seconds"] for r in chosen if r.get("seconds") is not None and status != "skipped"]
            rows.append((status, len(chosen), sum(times), (sum(times) / len(times)) if times else 0.0))
    lines = [f"{'status':<10} {'files':>7} {'task s':>9} {'s/file':>8}"]
    lines += [f"{s:<10} {n:>7} {t:>9.1f} {m:>8.2f}" for s, n, t, m in rows]
    if seconds is not None:
        done = sum(1 for r in records if r["status"] in ("ok", "failed"))
        lines.append(
            f"wall time {seconds:.1f} s" + (f", {done / seconds:.2f} files/s" if seconds > 0 and done else "")
        )
    failed = [r for r in records if r["status"] == "failed"]
    for record in failed[:20]:
        lines.append(f"FAILED {record['input']} [{record.get('stage')}]: {record['error']}")
    if len(failed) > 20:
        lines.append(f"... and {len(failed) - 20} more failures (see the report)")
    return "\n".join(lines)
