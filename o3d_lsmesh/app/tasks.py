"""One batch task: read a file, run the pipeline in a thread of its own, write the result atomically.

:func:`run_task` runs inside a worker and returns a small JSON record, so meshes never travel
between processes. Every failure (unreadable file, an operation raising, a write Open3D refuses,
the time limit) becomes a failure record, never an exception; each task's warnings go into its
record. Docs: ``docs/batch.md``.
"""

from __future__ import annotations

import os
import threading
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .._o3d.io import cap_threads
from .files import output_path, read_mesh_file, write_atomic
from .ops import BatchOp, TaskContext

__all__ = ["RECORD_FIELDS", "configure_threads", "jsonable", "new_record", "run_task"]

#: The fields of a report record, in the order they are written.
RECORD_FIELDS = (
    "input output status error stage op key seconds cpu_seconds worker pid "
    "vertices_before triangles_before vertices_after triangles_after metrics files warnings"
).split()


def new_record(**fields: Any) -> dict:
    """A report record: ``fields`` over a failed one with nothing else known (``None``, no metrics)."""
    return {**dict.fromkeys(RECORD_FIELDS), "status": "failed", "metrics": {}, **fields}


_THREADS_SET: list[int] = []


def configure_threads(threads: int | None) -> None:
    """Cap this process's BLAS/OpenMP/Open3D threads at ``threads`` (once per process).

    The environment variables only reach libraries not loaded yet (CHOLMOD's libgomp and OpenBLAS
    read them when they load), which is why a local cluster also sets them before spawning workers.
    """
    if threads is None or _THREADS_SET == [threads]:
        return
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[name] = str(threads)
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
    counts = dict.fromkeys(caught, 0)
    for text in caught:
        counts[text] += 1
    lines = [text if n == 1 else f"{text} ({n} times)" for text, n in counts.items()]
    return lines[:limit] + ([f"... and {len(lines) - limit} more"] if len(lines) > limit else [])


@dataclass
class _Gate:
    """Stops an abandoned (timed-out) task from writing: the write and the abandonment exclude each other."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    abandoned: bool = False
    written: bool = False


def run_task(
    path: str,
    relative: str,
    key: str,
    *,
    outdir: str,
    ops: Sequence[BatchOp],
    options: Sequence[dict],
    suffix: str,
    threads: int | None,
    timeout: float | None = None,
) -> dict:
    """Read ``path``, run the pipeline, write the result; return the JSON record (never raises an Exception).

    The pipeline runs in a thread of its own, given ``timeout`` seconds: past them the record says
    ``TaskTimeout`` and the task is abandoned (it can no longer write; Python cannot stop a thread,
    so it runs on until it ends, unless its process is restarted, as the Dask engine does).
    """
    start, cpu = time.perf_counter(), time.process_time()
    record = new_record(
        input=path,
        stage="read",
        op=",".join(op.name for op in ops),
        key=key,
        worker=_worker_address(),
        pid=os.getpid(),
        warnings=[],
    )
    capture_warnings()
    gate = _Gate()
    task = threading.Thread(
        target=_run_pipeline,
        args=(record, gate, path, relative, outdir, ops, options, suffix, threads),
        name=f"o3d-lsmesh task {relative}",
        daemon=True,  # an abandoned task must not keep the process alive
    )
    task.start()
    task.join(timeout)
    if task.is_alive():
        with gate.lock:  # (waits for a write under way: a written output is reported as such)
            gate.abandoned = not gate.written
    if gate.abandoned:
        record = {**record, "metrics": dict(record["metrics"]), "warnings": list(record["warnings"])}
        record["error"] = f"TaskTimeout: still running after {timeout:g} s (task_timeout), abandoned"
    else:
        task.join()
    record["warnings"] = _summary(record["warnings"])
    record["seconds"] = time.perf_counter() - start
    record["cpu_seconds"] = time.process_time() - cpu  # CPU time of this worker process (all its threads)
    return jsonable(record)


def _run_pipeline(
    record: dict,
    gate: _Gate,
    path: str,
    relative: str,
    outdir: str,
    ops: Sequence[BatchOp],
    options: Sequence[dict],
    suffix: str,
    threads: int | None,
) -> None:
    _LOCAL.warnings = record["warnings"]
    try:
        configure_threads(threads)
        current = read_mesh_file(path)
        record["vertices_before"], record["triangles_before"] = len(current.vertices), len(current.triangles)
        context = TaskContext(input=path, relative=relative, threads=threads)
        for index, (op, values) in enumerate(zip(ops, options)):
            record["stage"] = op.name
            current, metrics = op.function(current, dict(values), context)
            slot = op.name if op.name not in record["metrics"] else f"{op.name}#{index + 1}"  # (op run twice)
            record["metrics"][slot] = {k: v for k, v in metrics.items() if not k.startswith("_")}
        last = ops[-1]
        if last.output == "mesh":
            record["vertices_after"], record["triangles_after"] = (
                len(current.vertices),
                len(current.triangles),
            )
        target = output_path(Path(outdir), relative, last, suffix)
        with gate.lock:
            if gate.abandoned:
                return
            if target is not None:
                record["stage"] = "write"
                record["files"] = write_atomic(
                    current, target, kind=last.output, suffix=suffix, root=Path(outdir)
                )
                record["output"] = str(target)
            gate.written = True
        record["status"], record["stage"] = "ok", None
    except Exception as error:
        record["error"] = f"{type(error).__name__}: {error}"
    finally:
        _LOCAL.warnings = None
