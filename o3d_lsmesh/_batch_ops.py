"""The operations ``o3d-lsmesh batch`` runs on every file, and the task a worker runs for one file.

An operation is one :class:`BatchOp` entry registered with :func:`register_op`:
a function ``function(mesh, options, context) -> (output, metrics)`` that takes
the mesh read from the file (or the previous operation's result in a
pipeline), a dict of its parsed options and a :class:`TaskContext` (input
path, relative name, thread budget), and returns the result and a small dict
of JSON-able metrics. Its options are :class:`Option` entries; the CLI makes a
flag of each (``--iterations``); :func:`fill_op` and the ``register_op`` calls
at the end of this module show how an operation is added.

The task (:func:`run_task`) reads, runs and writes inside the worker and
returns a small JSON record, so meshes never travel between processes. Every
failure (unreadable, empty or corrupt file, an operation raising, a write that
Open3D refuses) becomes a failure record instead of an exception. Outputs are
written under a temporary name and moved into place with ``os.replace``, so a
killed batch never leaves a half-written output under the final name.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import os
import re
import shutil
import sys
import tempfile
import threading
import time
import uuid
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

__all__ = [
    "OPS",
    "READABLE",
    "RESERVED",
    "WRITABLE",
    "BatchOp",
    "Option",
    "TaskContext",
    "parse_ops",
    "register_op",
    "resolve_options",
    "run_task",
]

#: Mesh files a folder INPUT is searched for.
READABLE = (".ply", ".obj", ".stl", ".off", ".gltf", ".glb")
#: Extensions Open3D 0.20 writes back readably (its .glb writer produces files it cannot read back).
WRITABLE = (".ply", ".obj", ".stl", ".off", ".gltf")
#: Names an operation option may not take: they are flags of ``o3d-lsmesh batch`` itself.
RESERVED = frozenset(
    "op workers threads_per_worker scheduler scheduler_file resume report retries fail_fast suffix set "
    "task_timeout "
    "quiet json force help".split()
)
#: The fields of a report record, in the order they are written.
RECORD_FIELDS = (
    "input output status error stage op key seconds cpu_seconds worker pid "
    "vertices_before triangles_before vertices_after triangles_after metrics files warnings"
).split()


def new_record(**fields: Any) -> dict:
    """A report record: ``fields`` over a failed one with nothing else known (``None``, no metrics)."""
    return {**dict.fromkeys(RECORD_FIELDS), "status": "failed", "metrics": {}, **fields}


# --------------------------------------------------------------------------- option parsers


def int_at_least(minimum: int) -> Callable[[Any], int]:
    """Parser of an integer ``>= minimum`` given as an int or a string."""

    def parse(value: Any) -> int:
        number = minimum - 1  # refused unless value is an int (not a bool) or its text
        if isinstance(value, (int, np.integer, str)) and not isinstance(value, (bool, np.bool_)):
            with contextlib.suppress(ValueError):
                number = int(value)
        if number < minimum:
            raise ValueError(f"must be an integer >= {minimum}, got {value!r}")
        return number

    return parse


def optional(parse: Callable[[Any], Any]) -> Callable[[Any], Any]:
    """Parser accepting ``None`` as well."""
    return lambda value: None if value is None else parse(value)


def real(value: Any) -> float:
    """Parser of a finite float."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"must be a number, got {value!r}") from None
    if not np.isfinite(number):
        raise ValueError(f"must be a finite number, got {value!r}")
    return number


def choice(*choices: str) -> Callable[[Any], str]:
    def parse(value: Any) -> str:
        if value not in choices:
            raise ValueError(f"must be one of {', '.join(choices)}, got {value!r}")
        return value

    return parse


def flag(value: Any) -> bool:
    """Parser of a boolean (``True``/``False`` or the strings true/false/1/0/yes/no)."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    text = str(value).strip().lower()
    if text in ("1", "true", "yes", "on"):
        return True
    if text in ("0", "false", "no", "off"):
        return False
    raise ValueError(f"must be true or false, got {value!r}")


def count_or_percent(value: Any) -> int | float:
    """Parser of a vertex count: an integer >= 1, or a share of each mesh's vertices like ``"2%"``.

    A share is returned as a float in (0, 1]; :func:`resolve_count` turns it into a count per mesh,
    since one count rarely suits every file of a batch.
    """
    if isinstance(value, str) and value.strip().endswith("%"):
        share = real(value.strip()[:-1])
        if not 0 < share <= 100:
            raise ValueError(f"must be a percentage in (0, 100], got {value!r}")
        return share / 100.0
    return int_at_least(1)(value)


def resolve_count(value: int | float, n: int) -> int:
    return max(1, int(np.ceil(value * n))) if isinstance(value, float) else int(value)


# --------------------------------------------------------------------------- registry


@dataclass(frozen=True)
class Option:
    """One option of a batch operation; the CLI flag is ``--`` + ``name`` with ``-`` for ``_``.

    ``parse`` takes the value as given (a string from the command line, or any
    value from Python) and returns the parsed value or raises ``ValueError``
    saying what it must be; ``is_flag`` makes the CLI flag a switch.
    """

    name: str
    parse: Callable[[Any], Any]
    default: Any = None
    help: str = ""
    is_flag: bool = False

    @property
    def cli_flag(self) -> str:
        return "--" + self.name.replace("_", "-")


@dataclass(frozen=True)
class BatchOp:
    """A registered batch operation.

    ``output`` is what ``function`` returns as its first value: ``"mesh"`` (a
    TriangleMesh, written as ``<name><suffix>``), ``"bytes"`` (written as
    ``<name><extension>``), ``"files"`` (a dict ``{file name: mesh or bytes}``
    written into the folder ``<name>/``; meshes get ``<suffix>``) or ``"none"``
    (metrics only). Only ``"mesh"`` operations can feed a later operation of a
    pipeline.
    """

    name: str
    function: Callable[[Any, dict, TaskContext], tuple[Any, dict]]
    options: tuple[Option, ...] = ()
    output: str = "mesh"
    extension: str = ""
    help: str = ""

    def __post_init__(self) -> None:
        if self.output not in ("mesh", "bytes", "files", "none"):
            raise ValueError(f"output must be one of mesh, bytes, files, none, got {self.output!r}")
        if self.output == "bytes" and not self.extension.startswith("."):
            raise ValueError(f"extension must start with '.' for a bytes output, got {self.extension!r}")
        for option in self.options:
            if option.name in RESERVED:
                raise ValueError(
                    f"option name {option.name!r} of op {self.name!r} is a flag of the batch itself"
                )


@dataclass(frozen=True)
class TaskContext:
    """What an operation knows about the file it runs on."""

    input: str  # path of the input file
    relative: str  # its name relative to the INPUT it came from (used for the output and reference names)
    threads: int | None  # thread budget of this worker (None: not managed, e.g. in the serial loop)
    progress: bool = False  # tqdm bars (the single-file CLI commands; never in a batch)


OPS: dict[str, BatchOp] = {}
OpFunction = Callable[[Any, dict, TaskContext], tuple[Any, dict]]


def register_op(op: BatchOp) -> BatchOp:
    """Add ``op`` to :data:`OPS` (replacing an op of the same name) and return it."""
    if not isinstance(op, BatchOp):
        raise TypeError(f"op must be a BatchOp, got {type(op).__name__}")
    OPS[op.name] = op
    return op


def operation(name: str, **fields: Any) -> Callable[[OpFunction], OpFunction]:
    """Decorator: register the function as the batch operation ``name`` (``fields`` as in :class:`BatchOp`)."""

    def add(function: OpFunction) -> OpFunction:
        register_op(BatchOp(name, function, **fields))
        return function

    return add


def parse_ops(op: Any) -> list[BatchOp]:
    """``"fill,denoise"``, ``["fill", "denoise"]`` or BatchOp objects -> the pipeline, checked."""
    if isinstance(op, (str, BatchOp)):
        items: list[Any] = op.split(",") if isinstance(op, str) else [op]
    elif isinstance(op, Sequence):
        items = list(op)
    else:
        raise TypeError(
            f"op must be a name, a comma-separated pipeline or a list of names, got {type(op).__name__}"
        )
    ops = []
    for item in items:
        if isinstance(item, BatchOp):
            ops.append(item)
            continue
        name = str(item).strip()
        if name not in OPS:
            raise ValueError(
                f"--op must be one of {', '.join(sorted(OPS))} or a pipeline like 'denoise,compare', "
                f"got {name!r}"
            )
        ops.append(OPS[name])
    if not ops:
        raise ValueError(f"--op must name at least one operation, got {op!r}")
    for first in ops[:-1]:
        if first.output != "mesh":
            raise ValueError(
                f"--op {first.name!r} writes {first.output}, not a mesh, so it must be last in a pipeline"
            )
    return ops


def resolve_options(ops: Sequence[BatchOp], options: Mapping[str, Any] | None) -> list[dict]:
    """Parse ``options`` for each op of a pipeline; return one ``{name: value}`` dict per op.

    A key ``"name"`` applies to every op of the pipeline that has that option; a
    key ``"op.name"`` (or a nested ``{"op": {"name": value}}``) to that op only.
    Unknown names and bad values raise ``ValueError`` naming the CLI flag.
    """
    options = dict(options or {})
    shared: dict[str, Any] = {}
    specific: dict[tuple[str, str], Any] = {}
    names = {op.name for op in ops}
    for key, value in options.items():
        if isinstance(value, Mapping) and key in names:
            specific.update({(key, k): v for k, v in value.items()})
        elif "." in key and key.split(".", 1)[0] in names:
            op_name, name = key.split(".", 1)
            specific[(op_name, name.replace("-", "_"))] = value
        else:
            shared[key.replace("-", "_")] = value
    known = {option.name for op in ops for option in op.options}
    pipeline = ",".join(op.name for op in ops)
    for name in shared:
        if name not in known:
            raise ValueError(
                f"--{name.replace('_', '-')} is not an option of --op {pipeline} "
                f"(its options: {', '.join(sorted(known)) or 'none'})"
            )
    for op_name, name in specific:
        op = next(op for op in ops if op.name == op_name)
        if name not in {option.name for option in op.options}:
            raise ValueError(
                f"--set {op_name}.{name}: {op_name} has no option {name!r} "
                f"(its options: {', '.join(o.name for o in op.options) or 'none'})"
            )
    resolved = []
    for op in ops:
        values = {}
        for option in op.options:
            if (op.name, option.name) in specific:
                given, where = specific[(op.name, option.name)], f"--set {op.name}.{option.name}"
            elif option.name in shared:
                given, where = shared[option.name], option.cli_flag
            else:
                values[option.name] = option.default
                continue
            try:
                values[option.name] = option.parse(given)
            except ValueError as error:
                raise ValueError(f"{where} (option {option.name} of --op {op.name}) {error}") from None
        resolved.append(values)
    return resolved


# --------------------------------------------------------------------------- reading and writing


@contextlib.contextmanager
def captured_native_output() -> Iterator[list[str]]:
    """Capture what C/C++ libraries write straight to file descriptors 1 and 2 (RPly, Assimp, Open3D).

    Yields a list that holds the captured text once the block ends: it keeps
    ``--json`` output clean and lets the CLI see the reader's complaints
    (Open3D returns what it read so far from a truncated file and only says so
    in a warning).
    """
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    captured: list[str] = []
    with tempfile.TemporaryFile() as sink:
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            yield captured
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            sink.seek(0)
            captured.append(sink.read().decode("utf-8", "replace"))


def quiet_open3d() -> Any:
    """The ``open3d`` module with its own messages off (ours are clearer and ``--json`` needs stdout clean)."""
    from ._o3d import open3d

    o3d = open3d()
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    return o3d


# Open3D's readers report a file they could not read to the end with these words (and return what they got)
_READ_FAILURE = re.compile(
    r"(?i)(read \w+ failed|rply: error|unable to read|error reading|unexpected end)[^\n]*"
)
_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def _ply_header_counts(path: str) -> dict[str, int]:
    """Element counts of a PLY header (``{"vertex": n, "face": m}``); empty if the header is unreadable."""
    counts = {}
    try:
        with open(path, "rb") as handle:
            if handle.readline().strip() != b"ply":
                return {}
            for _ in range(10_000):
                line = handle.readline()
                if not line or line.strip() == b"end_header":
                    break
                parts = line.split()
                if len(parts) == 3 and parts[0] == b"element":
                    counts[parts[1].decode("ascii", "replace")] = int(parts[2])
    except (OSError, ValueError):
        return {}
    return counts


def read_mesh_file(path: str, *, what: str = "INPUT") -> Any:
    """Read a triangle mesh; ``ValueError`` naming ``what`` and the file when it is missing, a folder,
    empty, unreadable, truncated or corrupt, or has no triangles.

    The one reader of the CLI and the batch workers. Open3D returns an empty or
    partial mesh instead of raising for a corrupt or cut-off file, and only
    says so in a warning: hence the checks on its output, its warnings and the
    PLY header. STL files are welded (they store three vertices per triangle).
    """
    o3d = quiet_open3d()
    name = f"{what} {path!r}"
    if not os.path.exists(path):
        raise ValueError(f"{name} does not exist")
    if os.path.isdir(path):
        raise ValueError(f"{name} is a folder, not a mesh file")
    if os.path.getsize(path) == 0:
        raise ValueError(f"{name} is an empty file")
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Warning)
    try:
        with captured_native_output() as captured:
            mesh = o3d.io.read_triangle_mesh(path)
    finally:
        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    n, m = len(mesh.vertices), len(mesh.triangles)
    failure = _READ_FAILURE.search(_ANSI.sub("", captured[0]))
    if failure and n:
        raise ValueError(
            f"{name} is truncated or corrupt: Open3D read only part of it ({failure.group(0).strip()})"
        )
    header = _ply_header_counts(path) if Path(path).suffix.lower() == ".ply" and n else {}
    # a polygon face gives at least one triangle: fewer triangles than faces means faces were lost
    if header.get("vertex", n) != n or header.get("face", 0) > m:
        raise ValueError(
            f"{name} is truncated or corrupt: its header declares {header.get('vertex')} vertices "
            f"and {header.get('face', 0)} faces, Open3D read {n} and {m} triangles"
        )
    if n == 0:
        raise ValueError(
            f"{name} could not be read as a triangle mesh (empty, corrupt or unsupported format)"
        )
    if m == 0:
        raise ValueError(f"{name} has {n} vertices but no triangles")
    return mesh.remove_duplicated_vertices() if Path(path).suffix.lower() == ".stl" else mesh


def write_mesh(mesh: Any, path: Path) -> None:
    """Write a mesh file (an OBJ with its ``.mtl`` and textures, :func:`~o3d_lsmesh._o3d.obj_writable`);
    ``OSError`` when Open3D cannot (it returns False instead of raising)."""
    o3d = quiet_open3d()
    if path.suffix.lower() == ".stl":
        mesh = o3d.geometry.TriangleMesh(mesh)
        mesh.compute_triangle_normals()  # Open3D's STL writer refuses a mesh without them
    if path.suffix.lower() == ".obj" and mesh.has_triangle_uvs():
        from ._o3d import obj_writable

        mesh = obj_writable(mesh)
    with captured_native_output():
        written = o3d.io.write_triangle_mesh(str(path), mesh)
    if not written or not path.exists() or path.stat().st_size == 0:
        raise OSError(f"Open3D could not write {str(path)!r}")


def _write_item(value: Any, path: Path) -> None:
    if isinstance(value, (bytes, bytearray)):
        path.write_bytes(bytes(value))
    else:
        write_mesh(value, path)


def digest(path: Path) -> dict:
    """Size and sha256 of a written file: what ``--resume`` checks an output against."""
    hasher = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            hasher.update(block)
    return {"bytes": path.stat().st_size, "sha256": hasher.hexdigest()}


def inside(path: str | os.PathLike, root: str | os.PathLike) -> bool:
    """Whether ``path`` resolves (symbolic links followed) to a place strictly below ``root``."""
    real, base = Path(os.path.realpath(path)), Path(os.path.realpath(root))
    return base in real.parents


#: Hidden temporary names of :func:`write_atomic` (and of the versions before it: ``.<stem>.<hex>.tmp.<ext>``
#: files and ``.<name>.<hex>.old`` folders): what a killed batch may leave; never taken as inputs.
TEMPORARY = re.compile(r"\..*\.[0-9a-f]{12}\.(tmp|old)(\.[^.]+)?")


def write_atomic(value: Any, final: Path, *, kind: str, suffix: str, root: Path) -> dict[str, dict]:
    """Write ``value`` as ``final`` (strictly inside ``root``); return ``{path below root: size and sha256}``.

    Everything is written into a hidden temporary folder beside ``final`` (the only thing this
    removes: it holds nothing else), then moved into place file by file with ``os.replace``, so a
    killed batch never leaves a half-written file under a final name, and a mesh format with
    companion files (OBJ: its ``.mtl`` and textures) names them after ``final``. A new folder
    output moves into place whole; into an existing folder, file by file: nothing already there is
    removed, be it another run's or the user's.
    """
    if not inside(final, root):
        raise ValueError(f"output {str(final)!r} does not resolve to a place inside OUTDIR {str(root)!r}")
    final.parent.mkdir(parents=True, exist_ok=True)
    temporary = final.with_name(f".{final.name}.{uuid.uuid4().hex[:12]}.tmp")
    temporary.mkdir()
    try:
        if kind == "files":
            for name, item in value.items():
                _write_item(
                    item, temporary / (name if isinstance(item, (bytes, bytearray)) else name + suffix)
                )
        else:
            _write_item(value, temporary / final.name)
        where = final if kind == "files" else final.parent
        base = Path(os.path.relpath(where, root))
        files = {(base / p.name).as_posix(): digest(p) for p in sorted(temporary.iterdir())}
        if kind == "files" and not os.path.lexists(final):
            os.replace(temporary, final)
        else:
            for path in sorted(temporary.iterdir()):
                os.replace(path, where / path.name)
    finally:
        shutil.rmtree(temporary, ignore_errors=True)
    return files


def _safe_name(part: str) -> str:
    # '', '.' and '..' would name OUTDIR itself or its parent (#40: a file '..ply'): a visible fixed name
    return {"": "_", ".": "_dot", "..": "_dotdot"}.get(part, part)


def output_path(outdir: Path, relative: str, op: BatchOp, suffix: str) -> Path | None:
    """Where the result of ``op`` on the input named ``relative`` goes (None for metrics-only ops).

    The stem (``relative`` without its extension) names the output; a folder or stem that is
    empty, ``.`` or ``..`` (the file ``..ply``) becomes ``_``, ``_dot`` or ``_dotdot``, so every
    output lies strictly inside ``outdir``.
    """
    if op.output == "none":
        return None
    path = Path(relative)
    parts = [
        _safe_name(part) for part in (*path.parent.parts, path.name[: len(path.name) - len(path.suffix)])
    ]
    ending = {"mesh": suffix, "bytes": op.extension}.get(op.output, "")
    return outdir.joinpath(*parts[:-1], parts[-1] + ending)


# --------------------------------------------------------------------------- worker set-up and the task

_THREADS_SET: list[int] = []


def configure_threads(threads: int | None) -> None:
    """Cap this process's BLAS/OpenMP/Open3D threads at ``threads`` (once per process).

    The environment variables only take effect for libraries not loaded yet
    (CHOLMOD's libgomp and OpenBLAS read them when they load), which is why a
    local cluster also sets them before spawning its workers.
    """
    if threads is None or _THREADS_SET == [threads]:
        return
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[name] = str(threads)
    o3d = quiet_open3d()
    if hasattr(o3d.utility, "set_max_threads"):
        o3d.utility.set_max_threads(threads)
    _THREADS_SET[:] = [threads]


def _worker_address() -> str:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return "local"


def jsonable(value: Any) -> Any:
    """``value`` with numpy values as Python ones, NaN and inf as None (JSON has neither) and the rest as text."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None  # JSON has no NaN/inf
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    return str(value)


def _size(mesh: Any) -> tuple[int, int]:
    return len(mesh.vertices), len(mesh.triangles)


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

    Every warning is taken (``always``): a file's warning must not be hidden because another
    file of this process raised it first. A worker keeps this; the serial loop restores the
    caller's warning state when it ends.
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

    The pipeline runs in a thread of its own, given ``timeout`` seconds: past them the record
    says ``TaskTimeout`` and the task is abandoned (it can no longer write; Python cannot stop a
    thread, so it runs on until it ends, unless its process is restarted, as the Dask engine does).
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
        mesh = read_mesh_file(path)
        record["vertices_before"], record["triangles_before"] = _size(mesh)
        context = TaskContext(input=path, relative=relative, threads=threads)
        current = mesh
        for index, (op, values) in enumerate(zip(ops, options)):
            record["stage"] = op.name
            current, metrics = op.function(current, dict(values), context)
            slot = op.name if op.name not in record["metrics"] else f"{op.name}#{index + 1}"  # (op run twice)
            record["metrics"][slot] = metrics
        last = ops[-1]
        if last.output == "mesh":
            record["vertices_after"], record["triangles_after"] = _size(current)
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


# --------------------------------------------------------------------------- the operations


_METHODS = ("greedy", "random", "combined")


def normal_change(a: Any, b: Any) -> float | None:
    """Mean face-normal deviation of two meshes with the same triangles; None when no triangle has an area in both."""
    from .metrics import normal_deviation

    try:
        return normal_deviation(a, b)
    except ValueError:  # every triangle of zero area in a or b: the angle is undefined
        return None


def change_metrics(before: Any, after: Any) -> dict:
    """How far the vertices moved, the shape change (:func:`~o3d_lsmesh.metrics.shape_change`: volume when closed,
    inward shift when open) and, with the same triangles, how much the face normals turned."""
    from .metrics import shape_change, vertex_error

    out: dict[str, Any] = {}
    if len(before.vertices) == len(after.vertices):
        moved = vertex_error(after, before)
        out["displacement_mean"], out["displacement_max"] = moved["mean"], moved["linf"]
        if np.array_equal(np.asarray(before.triangles), np.asarray(after.triangles)):
            out["normal_change_deg"] = normal_change(after, before)
    out.update(shape_change(before, after))
    return out


@operation(
    "denoise",
    help="barycenter-constrained (or multiresolution with --level) fairing",
    options=(
        Option(
            "iterations",
            optional(int_at_least(0)),
            None,
            "number_of_iterations (default: the API's; with --level, 5 per level)",
        ),
        Option(
            "method",
            optional(choice("scan", "local", "global", "features")),
            None,
            "fairing energy (default: scan, the API's; local with --level or --reimpose-every; features keeps "
            "sharp creases)",
        ),
        Option("level", int_at_least(0), 0, "multiresolution level (0: plain fairing)"),
        Option("mu", optional(real), None, "barycenter penalty weight of --method global or scan"),
        Option(
            "reimpose_every", optional(int_at_least(1)), None, "re-take the barycenters every k iterations"
        ),
        Option("fixed_boundary", flag, False, "keep boundary vertices fixed", is_flag=True),
    ),
)
def denoise_op(mesh: Any, options: dict, context: TaskContext) -> tuple[Any, dict]:
    """``--op denoise`` and ``o3d-lsmesh denoise``: fairing with the method and iterations that ran."""
    level, progress = options["level"], context.progress
    if level:
        from .fairing.multiresolution import multiresolution_fairing

        iterations = 5 if options["iterations"] is None else options["iterations"]
        method = options["method"] or "local"
        out = multiresolution_fairing(
            mesh, level, number_of_iterations=iterations, method=method, progress=progress
        )
    else:
        from .fairing import constrained_fairing
        from .fairing.constrained import resolved_options

        # no flag: the API's defaults (method='scan'); the record names what ran
        method, iterations = resolved_options(
            options["method"], options["iterations"], options["reimpose_every"]
        )
        out = constrained_fairing(
            mesh,
            iterations,
            method=method,
            mu=options["mu"],
            smooth_boundary=not options["fixed_boundary"],
            reimpose_every=options["reimpose_every"],
            progress=progress,
        )
    return out, {"method": method, "iterations": iterations, "level": level, **change_metrics(mesh, out)}


@operation(
    "fill",
    help="fill holes with faired patches (LS meshes)",
    options=(
        Option(
            "max_hole_edges", optional(int_at_least(3)), None, "fill only holes of at most this many edges"
        ),
        Option("max_hole_diameter", optional(real), None, "fill only holes at most this wide (mesh units)"),
        Option("continuity", choice("0", "1", "2"), "2", "0 harmonic, 1 LS mesh, 2 tri-Laplacian"),
        Option("density", real, 1.0, "new vertex density relative to the surroundings"),
        Option("fill_border", flag, False, "also fill the outer border of open components", is_flag=True),
    ),
)
def fill_op(mesh: Any, options: dict, context: TaskContext) -> tuple[Any, dict]:
    """``--op fill`` and ``o3d-lsmesh fill``: hole filling with the counts of new vertices and triangles,
    of the loops filled and left open, and why the first ten were left open."""
    from .hole_filling import fill_holes

    # the options are fill_holes' own (--continuity comes as the text of a choice)
    options = {**options, "continuity": int(options["continuity"])}
    out, report = fill_holes(mesh, **options, progress=context.progress, return_report=True)
    return out, {
        "new_vertices": len(out.vertices) - len(mesh.vertices),
        "new_triangles": len(out.triangles) - len(mesh.triangles),
        "holes_filled": len(report.filled),
        "holes_skipped": len(report.skipped),
        "left_open": report.describe(10),
    }


def parse_levels(spec: str, count: int) -> list[int]:
    """The levels ``spec`` names (``"all"`` or comma-separated numbers) in a hierarchy of ``count`` levels."""
    if spec == "all":
        return list(range(count))
    try:
        levels = sorted({int(item) for item in spec.split(",") if item.strip()})
    except ValueError:
        raise ValueError(f"--levels must be 'all' or comma-separated integers, got {spec!r}") from None
    if not levels or not all(0 <= level < count for level in levels):
        raise ValueError(
            f"--levels must be in 0..{count - 1} (the hierarchy has {count} levels), got {spec!r}"
        )
    return levels


def _levels_spec(value: Any) -> str:
    text = str(value).strip()
    if text == "all":
        return text
    try:
        levels = [int(item) for item in text.split(",") if item.strip()]
    except ValueError:
        levels = []
    if not levels or min(levels) < 0:
        raise ValueError(f"must be 'all' or comma-separated level numbers >= 0, got {value!r}")
    return text


@operation(
    "hierarchy",
    output="files",
    help="levels of the volume-cost collapse hierarchy, written to OUTDIR/<name>/level_NN<suffix>",
    options=(
        Option("levels", _levels_spec, "all", "'all' or comma-separated level numbers (0 is the input)"),
        Option("min_vertices", int_at_least(1), 100, "stop coarsening below this many vertices"),
        Option("max_levels", optional(int_at_least(1)), None, "at most this many levels"),
        Option("maps", flag, False, "also write vertex_maps.npz", is_flag=True),
    ),
)
def _hierarchy(mesh: Any, options: dict, context: TaskContext) -> tuple[Any, dict]:
    from .hierarchy import build_hierarchy

    hierarchy = build_hierarchy(mesh, min_vertices=options["min_vertices"], max_levels=options["max_levels"])
    levels = parse_levels(options["levels"], len(hierarchy))
    files: dict[str, Any] = {f"level_{level:02d}": hierarchy.level(level) for level in levels}
    if options["maps"]:
        buffer = io.BytesIO()
        maps: dict[str, Any] = {
            f"level_{level:02d}": np.asarray(hierarchy.vertex_map(level), dtype=np.int64) for level in levels
        }
        np.savez_compressed(buffer, **maps)
        files["vertex_maps.npz"] = buffer.getvalue()
    return files, {
        "levels": len(hierarchy),
        "written_levels": levels,
        "vertex_counts": [int(hierarchy.vertex_count(i)) for i in range(len(hierarchy))],
    }


@operation(
    "approximate",
    help="LS-mesh approximation from control points",
    options=(
        Option(
            "count",
            count_or_percent,
            "2%",
            "control points: a count, or a share of each mesh's vertices like 2%",
        ),
        Option("method", choice(*_METHODS), "greedy", "control point selection: greedy, random or combined"),
        Option("interpolate", flag, False, "interpolate the control points exactly", is_flag=True),
        Option("seed", int_at_least(0), 0, "seed of the random selections"),
    ),
)
def _approximate(mesh: Any, options: dict, context: TaskContext) -> tuple[Any, dict]:
    from .metrics import vertex_error
    from .selection import approximate

    count = resolve_count(options["count"], len(mesh.vertices))
    out, indices = approximate(
        mesh, count, method=options["method"], interpolate=options["interpolate"], seed=options["seed"]
    )
    error = vertex_error(out, mesh)
    return out, {
        "count": len(indices),
        "method": options["method"],
        "error_linf": error["linf"],
        "error_rms": error["rms"],
    }


@operation(
    "encode",
    output="bytes",
    extension=".bin",
    help="quantized LS-mesh anchors, written as OUTDIR/<name>.bin",
    options=(
        Option(
            "count", count_or_percent, "2%", "anchors: a count, or a share of each mesh's vertices like 2%"
        ),
        Option("bits", int_at_least(1), 12, "bits per quantized coordinate"),
        Option("method", choice(*_METHODS), "greedy", "anchor selection: greedy, random or combined"),
    ),
)
def _encode(mesh: Any, options: dict, context: TaskContext) -> tuple[Any, dict]:
    from .encoding import decode_geometry, encode_geometry
    from .metrics import vertex_error

    n = len(mesh.vertices)
    count = resolve_count(options["count"], n)
    data = encode_geometry(mesh, count, bits=options["bits"], method=options["method"])
    error = vertex_error(decode_geometry(mesh, data), mesh)
    return data, {
        "anchors": count,
        "bits": options["bits"],
        "bytes": len(data),
        "bits_per_vertex": 8.0 * len(data) / n,
        "decoded_error_linf": error["linf"],
        "decoded_error_rms": error["rms"],
    }


def find_reference(folder: str, relative: str) -> str:
    """The reference for the input named ``relative``: same relative path, else same stem with any mesh extension."""
    base = Path(folder)
    exact = base / relative
    if exact.is_file():
        return str(exact)
    stem = Path(relative).with_suffix("")
    for extension in READABLE:
        candidate = base / stem.with_name(stem.name + extension)
        if candidate.is_file():
            return str(candidate)
    raise ValueError(
        f"--reference {folder!r} has no file matching {relative!r} (same name, or same stem with "
        f"one of {', '.join(READABLE)})"
    )


def _folder(value: Any) -> str:
    text = str(value)
    if not os.path.isdir(text):
        raise ValueError(f"must be an existing folder, got {value!r}")
    return os.path.abspath(text)


@operation(
    "compare",
    output="none",
    help="metrics against the matching file in --reference",
    options=(
        Option(
            "reference",
            optional(_folder),
            None,
            "folder holding a reference for every input (same name or stem)",
        ),
        Option("points", int_at_least(1), 100_000, "surface samples per mesh"),
    ),
)
def _compare(mesh: Any, options: dict, context: TaskContext) -> tuple[Any, dict]:
    from .metrics import surface_distance, vertex_error

    if options["reference"] is None:
        raise ValueError(
            "--reference FOLDER is required by --op compare (the file each input is compared with)"
        )
    reference_path = find_reference(options["reference"], context.relative)
    reference = read_mesh_file(reference_path)
    metrics: dict[str, Any] = {
        "reference": reference_path,
        "vertices_reference": len(reference.vertices),
        "surface_distance": surface_distance(mesh, reference, number_of_points=options["points"]),
    }
    if len(mesh.vertices) == len(reference.vertices):
        metrics["vertex_error"] = vertex_error(mesh, reference)
    metrics.update(change_metrics(reference, mesh))
    return None, metrics
