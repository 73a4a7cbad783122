"""Run an operation, or a pipeline of them, over many mesh files: :func:`run` (``docs/batch.md``)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import warnings
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Callable

from ..core.errors import InputError, InputTypeError, O3DLSMeshWarning
from ..core.progress import Progress
from ..core.validate import as_bool, as_choice, as_count, as_positive_float
from .files import READABLE, WRITABLE, collect_inputs, digest, inside, output_path, same_file
from .ops import OPS, BatchOp, Option, register_op
from .tasks import Task, check_scheduler_file, dispatch, failure_record, local_cluster

__all__ = [
    "OPS",
    "BatchOp",
    "Option",
    "collect_inputs",
    "local_cluster",
    "parse_ops",
    "register_op",
    "resolve_options",
    "run",
    "summarize",
]


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
    return all(
        (outdir / name).is_file() and digest(outdir / name) == expected for name, expected in files.items()
    )


# --------------------------------------------------------------------------- the pipeline and its options


def parse_ops(op: Any) -> list[BatchOp]:
    """``"fill,denoise"``, ``["fill", "denoise"]`` or BatchOp objects -> the pipeline, checked."""
    if isinstance(op, (str, BatchOp)):
        items: list[Any] = op.split(",") if isinstance(op, str) else [op]
    elif isinstance(op, Sequence):
        items = list(op)
    else:
        raise InputTypeError(
            f"op must be a name, a comma-separated pipeline or a list of names, got {type(op).__name__}",
            param="op",
        )
    ops = []
    for item in items:
        name = item.name if isinstance(item, BatchOp) else str(item).strip()
        if not isinstance(item, BatchOp) and name not in OPS:
            raise InputError(
                f"op must be one of {', '.join(sorted(OPS))} or a pipeline like 'denoise,compare', got {name!r}",
                param="op",
            )
        ops.append(item if isinstance(item, BatchOp) else OPS[name])
    if not ops:
        raise InputError(f"op must name at least one operation, got {op!r}", param="op")
    for first in ops[:-1]:
        if first.output != "mesh":
            raise InputError(
                f"op {first.name!r} writes {first.output}, not a mesh, so it must be last in a pipeline",
                param="op",
            )
    return ops


def parse_option(op: BatchOp, option: Option, value: Any) -> Any:
    """``option.parse(value)`` (``None`` for an option whose default it is); ``InputError`` naming the
    option (``param``) and its op."""
    if value is None and option.default is None:
        return None
    try:
        return option.parse(value)
    except ValueError as error:
        raise InputError(f"{option.name} {error} (an option of op {op.name})", param=option.name) from None


def resolve_options(ops: Sequence[BatchOp], options: Mapping[str, Any] | None) -> list[dict]:
    """Parse ``options`` for each op of a pipeline; return one ``{name: value}`` dict per op.

    A key ``"name"`` applies to every op of the pipeline that has that option; a key
    ``"op.name"`` (or a nested ``{"op": {"name": value}}``) to that op only. Unknown names and bad
    values raise :class:`~o3d_lsmesh.core.errors.InputError` naming the option.
    """
    shared: dict[str, Any] = {}
    specific: dict[tuple[str, str], Any] = {}
    names = {op.name for op in ops}
    for key, value in dict(options or {}).items():
        if isinstance(value, Mapping) and key in names:
            specific.update({(key, str(k).replace("-", "_")): v for k, v in value.items()})
        elif "." in key and key.split(".", 1)[0] in names:
            op_name, name = key.split(".", 1)
            specific[(op_name, name.replace("-", "_"))] = value
        else:
            shared[key.replace("-", "_")] = value
    known = {option.name for op in ops for option in op.options}
    pipeline = ",".join(op.name for op in ops)
    for name in shared:
        if name not in known:
            raise InputError(
                f"{name} is not an option of op {pipeline} (its options: {', '.join(sorted(known)) or 'none'})",
                param=name,
            )
    for op_name, name in specific:
        op = next(op for op in ops if op.name == op_name)
        if name not in {option.name for option in op.options}:
            raise InputError(
                f"options: {op_name} has no option {name!r} (its options: "
                f"{', '.join(o.name for o in op.options) or 'none'})",
                param="options",
            )
    resolved = []
    for op in ops:
        # its defaults written as text ("2%": parsed as if given, as argparse does for the flags), the
        # values given to every op, then those given to this one
        given = {o.name: o.default for o in op.options if isinstance(o.default, str)} | shared
        given |= {name: value for (owner, name), value in specific.items() if owner == op.name}
        values = {o.name: parse_option(op, o, given[o.name]) for o in op.options if o.name in given}
        resolved.append({o.name: values.get(o.name, o.default) for o in op.options})
    return resolved


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

    Each parameter is the ``o3d-lsmesh batch`` flag of the same name (``docs/batch.md``, section
    Python, says what each does); ``options`` maps ``"name"`` (every op that has it) or
    ``"op.name"`` (one op) to a value; ``client`` is an existing ``dask.distributed.Client`` (left
    running); ``on_record`` is called with each record (an exception it raises stops the batch).

    Returns
    -------
    list of dict
        One record per input, in order (fields: :data:`~o3d_lsmesh.app.tasks.RECORD_FIELDS`).

    Raises
    ------
    InputError
        A bad argument (``param`` names it or the option), no input, two inputs with one output.
    InputTypeError
        ``inputs`` or ``op`` of the wrong kind.

    Examples
    --------
    >>> import tempfile, open3d as o3d
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     _ = o3d.io.write_triangle_mesh(f"{folder}/ball.ply", o3d.geometry.TriangleMesh.create_sphere())
    ...     [r["status"] for r in run(folder, f"{folder}/out", op="denoise", workers=0, progress=False)]
    ['ok']
    """
    ops = parse_ops(op)
    pipeline = ",".join(o.name for o in ops)
    values = resolve_options(ops, options)
    for checked, given in zip(ops, values):  # before any worker starts or file is read
        if checked.check is not None:
            checked.check(given)

    suffix = as_choice(suffix.lower() if isinstance(suffix, str) else suffix, WRITABLE, name="suffix")
    threads_per_worker = as_count(threads_per_worker, name="threads_per_worker", minimum=1)
    retries = as_count(retries, name="retries")
    workers = None if workers is None else as_count(workers, name="workers")
    if scheduler is not None and scheduler_file is not None:
        message = "scheduler_file must be None when scheduler is given (not both)"
        raise InputError(message, param="scheduler_file")
    if task_timeout is not None:  # 0: no limit
        task_timeout = as_positive_float(task_timeout, name="task_timeout", allow_zero=True)
    if scheduler_file is not None:
        check_scheduler_file(scheduler_file)
    progress = as_bool(progress, name="progress")
    if resume and report is None:
        raise InputError("resume needs a report (the file that says which inputs are done)", param="report")

    outdir = Path(outdir).absolute()
    items = collect_inputs(inputs, exclude=outdir)
    if outdir.exists() and not outdir.is_dir():
        raise InputError(f"OUTDIR {str(outdir)!r} exists and is not a folder", param="outdir")
    # (resume without a report was refused above)
    previous = _read_report(Path(report)) if resume and report is not None else {}
    tasks: list[Task] = []
    todo: list[Task] = []
    records: list[dict | None] = [None] * len(items)
    outputs: dict[str, str] = {}
    refused: list[dict] = []
    for index, (path, relative) in enumerate(items):
        target = output_path(outdir, relative, ops[-1], suffix)
        output = None if target is None else str(target)
        task = Task(index, os.path.abspath(path), relative, output, key=task_key(path, ops, values, suffix))
        tasks.append(task)
        if output is not None and not inside(output, outdir):  # a symbolic link inside OUTDIR leads out
            message = f"output {output!r} resolves to {os.path.realpath(output)!r}, outside OUTDIR"
            refused.append(failure_record(task, pipeline, message, stage="write"))
            continue
        if output is not None:
            if output in outputs:
                raise InputError(
                    f"INPUT files {outputs[output]!r} and {path!r} would both write {output!r} (outputs "
                    "take an input's name below its folder, without its suffix): run them in two batches "
                    "with two OUTDIRs, or pass one folder holding both so that outputs keep the subfolders",
                    param="inputs",
                )
            outputs[output] = path
            if not force and same_file(output, path):
                raise InputError(
                    f"OUTDIR {str(outdir)!r} would overwrite the input {path!r} (use another OUTDIR or "
                    "suffix, or force)",
                    param="outdir",
                )
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
    if report is not None:  # a report written over a mesh (a slip of the shell: --report *.ply) loses it
        name = os.fspath(report)
        meshes = [path for path, _ in items] + list(outputs)
        clash = [
            path for path in meshes if os.path.abspath(name) == os.path.abspath(path) or same_file(name, path)
        ]
        if clash or Path(name).suffix.lower() in READABLE:
            got = f"the batch's input or output {clash[0]!r}" if clash else "a mesh file's name"
            raise InputError(
                f"report must name a file of its own (JSON lines, e.g. report.jsonl), got {name!r}, {got}",
                param="report",
            )
    outdir.mkdir(parents=True, exist_ok=True)
    # the workers need the op functions, not the option parsers (closures only cloudpickle can send)
    shipped = [dataclasses.replace(o, options=()) for o in ops]
    job = {
        "outdir": str(outdir),
        "ops": shipped,
        "options": values,
        "suffix": suffix,
        "threads": threads_per_worker,
        "timeout": task_timeout or None,
    }

    bar = Progress(progress, f"batch {pipeline}").bar(
        len(tasks), initial=len(tasks) - len(todo) - len(refused), unit="file", dynamic_ncols=True
    )
    counts: Counter = Counter()
    index_of = {task.path: task.index for task in tasks}
    handle = None
    if report is not None:
        Path(report).parent.mkdir(parents=True, exist_ok=True)
        handle = open(report, "a+b" if resume else "wb")
        if handle.tell():
            handle.seek(-1, os.SEEK_END)
            if handle.read(1) != b"\n":
                handle.write(b"\n")  # a killed run's torn last line: the next record starts a line of its own

    def emit(record: dict) -> bool:
        """Store, report and show one result; False asks the engine to stop (``fail_fast``)."""
        records[index_of[record["input"]]] = record
        counts[record["status"]] += 1
        if handle is not None:
            handle.write(json.dumps(record).encode() + b"\n")
            handle.flush()
        bar.update(1)
        bar.set_postfix(ok=counts["ok"], failed=counts["failed"], refresh=False)
        for text in record.get("warnings") or ():  # (after the report: a warning made an error stops here)
            warnings.warn(f"{record['input']}: {text}", O3DLSMeshWarning, stacklevel=2)
        if on_record is not None:
            on_record(record)
        return not (fail_fast and record["status"] == "failed")

    try:
        if all(emit(record) for record in refused) and todo:
            dispatch(
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
        else failure_record(task, pipeline, "not run (fail_fast stopped the batch)", stage="cancelled")
        | {"status": "cancelled"}
        for task, record in zip(tasks, records)
    ]


def summarize(records: Sequence[dict], seconds: float | None = None) -> str:
    """A plain-text summary table of ``records`` (counts and time per status, then the failures)."""
    lines = [f"{'status':<10} {'files':>7} {'task s':>9} {'s/file':>8}"]
    for status in ("ok", "failed", "skipped", "cancelled"):
        chosen = [r for r in records if r["status"] == status]
        if chosen or status in ("ok", "failed"):
            times = [r["seconds"] for r in chosen if r.get("seconds") is not None and status != "skipped"]
            mean = sum(times) / len(times) if times else 0.0
            lines.append(f"{status:<10} {len(chosen):>7} {sum(times):>9.1f} {mean:>8.2f}")
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
