"""Where a batch's tasks run: one task per file (:func:`run_task`), on Dask or in this process
(:func:`dispatch`; ``docs/batch.md``, section How it runs)."""

from __future__ import annotations

import importlib.util
import json
import logging
import os
import signal
import threading
import time
import warnings
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import islice
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .._o3d.io import cap_threads
from ..core.errors import InputError, O3DLSMeshWarning
from ..core.validate import as_workers
from .files import output_path, read_mesh_file, write_atomic
from .ops import BatchOp, TaskContext

__all__ = ["RECORD_FIELDS", "configure_threads", "jsonable", "local_cluster", "new_record", "run_task"]

#: The fields of a report record, in the order they are written.
RECORD_FIELDS = (
    "input output status error stage op key seconds cpu_seconds worker pid "
    "vertices_before triangles_before vertices_after triangles_after metrics files warnings"
).split()


def new_record(**fields: Any) -> dict:
    """A report record: ``fields`` over a failed one with nothing else known (``None``, no metrics)."""
    return {**dict.fromkeys(RECORD_FIELDS), "status": "failed", "metrics": {}, **fields}


_THREADS_SET: list[int] = []
#: The thread counts BLAS and OpenMP read when they load.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def configure_threads(threads: int | None) -> None:
    """Cap this process's BLAS/OpenMP/Open3D threads at ``threads`` (once per process).

    The environment variables only reach libraries not loaded yet (CHOLMOD's libgomp and OpenBLAS
    read them when they load), which is why a local cluster also sets them before spawning workers.
    """
    if threads is None or _THREADS_SET == [threads]:
        return
    os.environ.update(dict.fromkeys(THREAD_VARIABLES, str(threads)))
    cap_threads(threads)
    _THREADS_SET[:] = [threads]


def _worker_address() -> str:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return "local"


def jsonable(value: Any) -> Any:
    """``value`` with numpy values as Python ones, NaN and inf as None (JSON has neither), the rest as text."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    return str(value)


_LOCAL = threading.local()  # .warnings: the list the task running in this thread collects its warnings in
_SHOW: list[Callable[..., Any]] = []  # the warnings.showwarning that _route_warning replaced


def _route_warning(message: Any, category: type[Warning], *args: Any, **kwargs: Any) -> None:
    caught = getattr(_LOCAL, "warnings", None)
    if caught is None:
        _SHOW[0](message, category, *args, **kwargs)
    else:
        caught.append(f"{category.__name__}: {message}")


def capture_warnings() -> None:
    """Route each warning raised in a task's thread into that task's record (once per process).

    Every warning is taken (``always``): a file's warning must not be hidden because another file
    of this process raised it first. The serial loop restores the caller's warning state.
    """
    if warnings.showwarning is not _route_warning:
        _SHOW[:] = [warnings.showwarning]
        warnings.showwarning = _route_warning
        warnings.simplefilter("always")


def _summary(caught: list[str], limit: int = 20) -> list[str]:
    lines = [text if n == 1 else f"{text} ({n} times)" for text, n in Counter(caught).items()]
    return lines[:limit] + ([f"... and {len(lines) - limit} more"] if len(lines) > limit else [])


@dataclass(frozen=True)
class Task:
    index: int
    path: str
    relative: str
    output: str | None
    key: str


def run_task(
    task: Task,
    *,
    outdir: str,
    ops: Sequence[BatchOp],
    options: Sequence[dict],
    suffix: str,
    threads: int | None,
    timeout: float | None = None,
) -> dict:
    """Read ``task.path``, run the pipeline, write the result; return the JSON record (never raises an Exception).

    The pipeline runs in a thread of its own, given ``timeout`` seconds: past them the record says
    ``TaskTimeout`` and the task is abandoned (it can no longer write; Python cannot stop a thread,
    so it runs on until it ends, unless its process is restarted, as the Dask engine does).
    """
    start, cpu = time.perf_counter(), time.process_time()
    record = new_record(
        input=task.path,
        stage="read",
        op=",".join(op.name for op in ops),
        key=task.key,
        worker=_worker_address(),
        pid=os.getpid(),
        warnings=[],
    )
    capture_warnings()
    # stops an abandoned (timed-out) task from writing: the write and the abandonment exclude each other
    lock, gate = threading.Lock(), {"abandoned": False, "written": False}

    def pipeline(record: dict) -> None:  # (the record it fills: an abandoned task's is copied below)
        _LOCAL.warnings = record["warnings"]
        try:
            configure_threads(threads)
            current = read_mesh_file(task.path)
            record.update(vertices_before=len(current.vertices), triangles_before=len(current.triangles))
            context = TaskContext(input=task.path, relative=task.relative, threads=threads)
            kept: Any
            # written: the last op's output, or (a metrics op last) the last mesh made
            last, kept = ops[-1], None
            for index, (op, values) in enumerate(zip(ops, options)):
                record["stage"] = op.name
                current, metrics = op.function(current, dict(values), context)
                slot = f"{op.name}#{index + 1}" if op.name in record["metrics"] else op.name  # (run twice)
                record["metrics"][slot] = {k: v for k, v in metrics.items() if not k.startswith("_")}
                if op.output != "none":  # (a metrics op is last, parse_ops says)
                    last, kept = op, current
            current = kept
            if last.output == "mesh":
                record.update(vertices_after=len(current.vertices), triangles_after=len(current.triangles))
            target = output_path(Path(outdir), task.relative, last, suffix)  # (None: compare alone)
            with lock:
                if gate["abandoned"]:
                    return
                if target is not None:
                    record["stage"] = "write"
                    record["files"] = write_atomic(
                        current, target, kind=last.output, suffix=suffix, root=Path(outdir)
                    )
                    record["output"] = str(target)
                gate["written"] = True
            record["status"], record["stage"] = "ok", None
        except Exception as error:
            record["error"] = f"{type(error).__name__}: {error}"
        finally:
            _LOCAL.warnings = None

    thread = threading.Thread(
        target=pipeline,
        args=(record,),
        name=f"o3d-lsmesh task {task.relative}",
        daemon=True,  # an abandoned task must not keep the process alive
    )
    thread.start()
    thread.join(timeout)
    if thread.is_alive():
        with lock:  # (waits for a write under way: a written output is reported as such)
            gate["abandoned"] = not gate["written"]
    if gate["abandoned"]:
        record = {**record, "metrics": dict(record["metrics"]), "warnings": list(record["warnings"])}
        record["error"] = f"TaskTimeout: still running after {timeout:g} s (task_timeout), abandoned"
    else:
        thread.join()
    record["warnings"] = _summary(record["warnings"])
    record["seconds"] = time.perf_counter() - start
    record["cpu_seconds"] = time.process_time() - cpu  # CPU time of this worker process (all its threads)
    return jsonable(record)


# --------------------------------------------------------------------------- engines


def _dask_available() -> bool:
    return importlib.util.find_spec("distributed") is not None


def _scheduler_address() -> str | None:
    address = os.environ.get("DASK_SCHEDULER_ADDRESS")
    if address:
        return address
    try:
        import dask

        return dask.config.get("scheduler-address", None)
    except ImportError:
        return None


def check_scheduler_file(path: str | os.PathLike) -> None:
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
            f"{expected}, got {os.fspath(path)!r}, which holds no 'address'", param="scheduler_file"
        )


def local_cluster(workers: int, threads_per_worker: int = 1, *, retries: int = 1, **kwargs: Any) -> Any:
    """A ``LocalCluster`` of ``workers`` spawned processes with ``threads_per_worker`` threads each.

    BLAS/OpenMP thread variables are set before the workers start (CHOLMOD and OpenBLAS read them
    when they load), without Dask's ``MALLOC_TRIM_THRESHOLD_``; a task may kill ``retries + 1``
    workers before it fails (``allowed-failures``); the dashboard takes a free port on 127.0.0.1.
    """
    import dask
    from distributed import LocalCluster

    method = dask.config.get("distributed.worker.multiprocessing-method", "spawn")  # never fork
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}) or {})
    environ.update(dict.fromkeys(THREAD_VARIABLES, str(threads_per_worker)))
    # Dask sets MALLOC_TRIM_THRESHOLD_=65536, which turns off glibc's dynamic mmap threshold: every array
    # above 128 KiB becomes a fresh mmap whose pages fault in zeroed (benchmarks/results/batch.md)
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    with dask.config.set(
        {
            "distributed.worker.multiprocessing-method": method if method == "forkserver" else "spawn",
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
        # A terminal's Ctrl-C reaches the whole process group: the workers, interrupted mid-import or
        # mid-task, printed tracebacks, and so did a cluster interrupted half-built. SIGINT is ignored
        # while the cluster starts: its processes keep ignoring it (Python keeps an inherited SIG_IGN), the
        # caller closes them. (Blocking it instead did not reach the workers.) The cost: a Ctrl-C in that
        # second is not seen (docs/limits)
        ignoring = threading.current_thread() is threading.main_thread()  # (only it may set handlers)
        handler = signal.signal(signal.SIGINT, signal.SIG_IGN) if ignoring else None
        try:
            return LocalCluster(
                n_workers=workers, threads_per_worker=threads_per_worker, processes=True, **kwargs
            )
        finally:
            if ignoring:
                signal.signal(signal.SIGINT, handler)


def failure_record(task: Task, op: str, message: str, stage: str = "worker") -> dict:
    return new_record(input=task.path, error=message, stage=stage, op=op, key=task.key)


def _run_dask(client: Any, tasks: list[Task], job: dict, emit: Callable[[dict], bool], retries: int) -> None:
    from concurrent.futures import CancelledError  # (distributed's FutureCancelledError is one)

    from distributed import KilledWorker, as_completed

    token = os.urandom(4).hex()
    pending = iter(tasks)
    by_key: dict[str, Task] = {}
    queue = as_completed()

    def submit(n: int) -> None:
        chunk = list(islice(pending, max(0, n)))
        if not chunk:
            return
        keys = [f"o3d-lsmesh-batch-{token}-{task.index}" for task in chunk]
        futures = client.map(run_task, chunk, key=keys, pure=False, **job)
        for task, future in zip(chunk, futures):
            by_key[future.key] = task
            queue.add(future)

    seen = {"size": 1, "when": -1.0}

    def window() -> int:
        """How many tasks to keep submitted, from the cluster's threads (re-read at most once a second).

        Above ``2 x threads`` tasks Dask queues them on the scheduler and hands each worker one at a
        time (``worker-saturation`` 1): a dying worker holds no innocent task. ``4 x threads + 4`` keeps
        that queue filled; a batch of at most ``2 x threads`` files gets ``threads``.
        """
        if time.monotonic() - seen["when"] > 1.0:
            threads = max(1, sum(client.nthreads().values()))
            seen.update(size=threads if len(tasks) <= 2 * threads else 4 * threads + 4, when=time.monotonic())
        return int(seen["size"])

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
                message = f"KilledWorker: each of the {tries} workers that ran it died (a crash such as a "
                record = failure_record(
                    task, op_name, message + f"segfault, or killed for memory); last {last}"
                )
                record["worker"] = last
            except CancelledError:
                record = failure_record(task, op_name, "cancelled")
            except Exception as error:
                record = failure_record(task, op_name, f"{type(error).__name__}: {error}")
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


def dispatch(
    todo: list[Task],
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
            warnings.warn("workers is ignored with an existing cluster", O3DLSMeshWarning, stacklevel=3)
        where = (
            {"address": address} if scheduler_file is None else {"scheduler_file": os.fspath(scheduler_file)}
        )
        with Client(**where) as own:
            return _run_dask(own, todo, job, emit, retries)
    n = workers if workers is not None else max(1, as_workers(None) // threads_per_worker)
    n = min(n, len(todo))  # no worker that would never get a file
    with local_cluster(n, threads_per_worker, retries=retries) as cluster, Client(cluster) as own:
        return _run_dask(own, todo, job, emit, retries)


def _run_serial(todo: list[Task], job: dict, emit: Callable[[dict], bool]) -> None:
    # Threads are left as the caller's process has them: this loop runs in the caller's process, whose
    # warning state each task restores (a task routes its warnings into its record; emit re-issues them).
    for task in todo:
        with warnings.catch_warnings():
            record = run_task(task, **{**job, "threads": None})
        if not emit(record):
            return
