"""The operations of the command line and the batch, each with its options declared once
(:data:`OPS`; ``docs/batch.md``, section How it runs)."""

from __future__ import annotations

import contextlib
import io
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .. import fairing
from .._o3d import new_mesh, read_mesh
from ..core.errors import InputError, InputTypeError
from ..core.validate import as_choice
from ..fairing.constrained import resolved_options
from ..fairing.multiresolution import multiresolution_fairing
from ..hierarchy import build_hierarchy
from ..holes import fill_holes
from ..lsmesh.encoding import decode_geometry, encode_geometry
from ..lsmesh.selection import approximate
from .files import READABLE, read_mesh_file
from .metrics import (
    MAX_SAMPLE_POINTS,
    corresponding,
    normal_change,
    shape_change,
    surface_distance,
    vertex_error,
)

__all__ = [
    "OPS",
    "RESERVED",
    "RUN_FLAGS",
    "BatchOp",
    "Option",
    "TaskContext",
    "register_op",
]

# --------------------------------------------------------------------------- parsers: value -> value or ValueError


def number(kind: type, minimum: float = -np.inf, maximum: float | None = None, rule: str = "") -> Callable:
    """Parser of a finite ``kind`` (int or float) in ``[minimum, maximum]``, given as itself (not a bool;
    an int for an int) or its text; ``rule`` says what it must be."""
    accepted = (int, np.integer, str) if kind is int else (int, float, np.integer, np.floating, str)

    def parse(value: Any) -> Any:
        parsed = np.nan  # refused unless value is one of accepted (not a bool) and converts
        if isinstance(value, accepted) and not isinstance(value, (bool, np.bool_)):
            with contextlib.suppress(ValueError):
                parsed = kind(value)
        if not (abs(parsed) < np.inf and parsed >= minimum):  # (NaN compares False)
            raise ValueError(f"must be {rule}, got {value!r}")
        if maximum is not None and parsed > maximum:
            raise ValueError(f"must be at most {maximum:,}, got {value!r}")
        return parsed

    return parse


def int_at_least(minimum: int, maximum: int | None = None, rule: str = "") -> Callable[[Any], int]:
    """Parser of an integer in ``[minimum, maximum]`` given as an int or its text (``rule``: what it must be)."""
    usual = {0: "a non-negative integer", 1: "a positive integer"}.get(minimum, f"an integer >= {minimum}")
    return number(int, minimum, maximum, rule or usual)


real = number(float, rule="a finite number")


def choice(*choices: Any) -> Callable[[Any], Any]:
    """Parser of one of ``choices`` (given as itself or its text)."""

    def parse(value: Any) -> Any:
        for item in choices:
            if value == item or (isinstance(value, str) and value == str(item)):
                return item
        raise ValueError(f"must be one of {', '.join(map(str, choices))}, got {value!r}")

    parse.choices = choices  # type: ignore[attr-defined]
    return parse


def flag(value: Any) -> bool:
    """Parser of a boolean (``True``/``False`` or the strings true/false/1/0/yes/no)."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    text = str(value).strip().lower()
    if text in ("1", "true", "yes", "on", "0", "false", "no", "off"):
        return text in ("1", "true", "yes", "on")
    raise ValueError(f"must be true or false, got {value!r}")


def count_or_percent(value: Any) -> int | float:
    """A vertex count >= 1, or a share of each mesh's vertices like ``"2%"`` (a float in (0, 1])."""
    if isinstance(value, str) and value.strip().endswith("%"):
        share = real(value.strip()[:-1])
        if not 0 < share <= 100:
            raise ValueError(f"must be a percentage in (0, 100], got {value!r}")
        return share / 100.0
    return int_at_least(1)(value)


def resolve_count(value: int | float, n: int) -> int:
    """The count ``value`` stands for in a mesh of ``n`` vertices."""
    return max(1, int(np.ceil(value * n))) if isinstance(value, float) else int(value)


def levels_spec(value: Any) -> str:
    """Parser of ``'all'`` or comma-separated level numbers >= 0 (checked against the hierarchy later)."""
    text = str(value).strip()
    with contextlib.suppress(ValueError):
        levels = [int(item) for item in text.split(",") if item.strip()] if text != "all" else [0]
        if levels and min(levels) >= 0:
            return text
    raise ValueError(f"must be 'all' or comma-separated level numbers >= 0, got {value!r}")


def folder(value: Any) -> str:
    """Parser of an existing folder (returned absolute)."""
    if not os.path.isdir(str(value)):
        raise ValueError(f"must be an existing folder, got {value!r}")
    return os.path.abspath(str(value))


# --------------------------------------------------------------------------- the table


@dataclass(frozen=True)
class Option:
    """One option of an operation: its flag is ``--`` + ``name`` with ``-`` for ``_``.

    ``parse`` takes the value as given (text from the command line or any Python value) and returns
    it parsed or raises ``ValueError`` saying what it must be (``None`` is taken as it is when it is
    the default); ``is_flag`` makes the flag a switch; ``param`` is the Python API parameter it maps
    to (default: ``name``); ``cli`` whether the subcommand of the same name has the flag (else batch
    only); ``required`` and ``metavar`` on the command line.
    """

    name: str
    parse: Callable[[Any], Any]
    default: Any = None
    help: str = ""
    is_flag: bool = False
    param: str = ""
    cli: bool = True
    required: bool = False
    metavar: str | None = None

    @property
    def cli_flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    @property
    def api_param(self) -> str:
        return self.param or self.name


@dataclass(frozen=True)
class BatchOp:
    """A registered operation.

    ``output`` is what ``function`` returns first: ``"mesh"`` (written as ``<name><suffix>``),
    ``"bytes"`` (``<name><extension>``), ``"files"`` (a dict ``{file name: mesh or bytes}`` written
    into the folder ``<name>/``; meshes get ``<suffix>``) or ``"none"`` (metrics only). Only
    ``"mesh"`` operations can feed a later operation of a pipeline.
    """

    name: str
    function: Callable[[Any, dict, TaskContext], tuple[Any, dict]]
    options: tuple[Option, ...] = ()
    output: str = "mesh"
    extension: str = ""
    help: str = ""
    # refuses a combination of parsed options before any file is read (the command and batch alike)
    check: Callable[[dict], None] | None = None

    def __post_init__(self) -> None:
        as_choice(self.output, ("mesh", "bytes", "files", "none"), name="output")
        if self.output == "bytes" and not self.extension.startswith("."):
            message = f"extension must start with '.' for a bytes output, got {self.extension!r}"
            raise InputError(message, param="extension")
        for option in self.options:
            if option.name in RESERVED:
                given = f"option name {option.name!r} of op {self.name!r}"
                message = f"options must not reuse a parameter of the batch itself, got {given}"
                raise InputError(message, param="options")


@dataclass(frozen=True)
class TaskContext:
    """What an operation knows about the file it runs on."""

    input: str  # path of the input file
    relative: str  # its name relative to the INPUT it came from (output and reference names)
    threads: int | None  # thread budget of this worker (None: not managed, e.g. in the serial loop)
    progress: bool = False  # progress bars (the single-file CLI commands; never in a batch)


OPS: dict[str, BatchOp] = {}
OpFunction = Callable[[Any, dict, TaskContext], tuple[Any, dict]]


def register_op(op: BatchOp) -> BatchOp:
    """Add ``op`` to :data:`OPS` (replacing an op of the same name) and return it."""
    if not isinstance(op, BatchOp):
        raise InputTypeError(f"op must be a BatchOp, got {type(op).__name__}", param="op")
    OPS[op.name] = op
    return op


def operation(name: str, **fields: Any) -> Callable[[OpFunction], OpFunction]:
    """Decorator: register the function as the operation ``name`` (``fields`` as in :class:`BatchOp`)."""

    def add(function: OpFunction) -> OpFunction:
        register_op(BatchOp(name, function, **fields))
        return function

    return add


# --------------------------------------------------------------------------- the operations


_LEVELS = "levels of the volume-cost collapse hierarchy, written to OUTDIR/<name>/level_NN<suffix>"
_ANCHORS = "quantized LS-mesh anchors, written as OUTDIR/<name>.bin"
_APPROXIMATE = "LS-mesh approximation from control points"
_AGAINST = "metrics against the matching file in --reference"
_SELECTIONS = ("greedy", "random", "combined")
_SCHEDULER = "existing Dask scheduler, e.g. tcp://host:8786 (default: $DASK_SCHEDULER_ADDRESS)"
_REPORT = "JSON-lines report, one record per file (default: OUTDIR/batch_report.jsonl)"
_TIMEOUT = "a file still running after this long fails (TaskTimeout; 0: no limit; default: 3600)"
_METHODS = ("scan", "local", "global", "features", "auto")

# fmt: off
DENOISE = (
    Option("iterations", int_at_least(0), None, "number of fairing iterations (default: the API's, "
           "10 for local; with --level, 5 per level)", param="number_of_iterations"),
    Option("method", choice(*_METHODS), None, "fairing energy (default: auto, the API's default; "
           "local with --level, --iterations or --reimpose-every); features keeps sharp creases (guided normal "
           "filtering), scan is made for raw scans; auto runs features where its passes reach their cap, "
           "scan elsewhere"),
    Option("level", int_at_least(0), 0, "multiresolution level (0: plain fairing)"),
    Option("mu", real, None, "barycenter penalty weight of --method global or scan (default: the API's)"),
    Option("reimpose_every", int_at_least(1), None, "re-take the barycenters every k iterations "
           "(default: never)"),
    Option("fixed_boundary", flag, False, "keep boundary vertices fixed (default: smooth the boundary curves)",
           is_flag=True, param="smooth_boundary"),
)
FILL = (
    Option("max_hole_edges", int_at_least(3), None, "fill only holes of at most this many edges "
           "(default: no limit)"),
    Option("max_hole_diameter", real, None, "fill only holes at most this wide (default: no limit)"),
    Option("continuity", choice(0, 1, 2), 2, "0 harmonic, 1 LS mesh, 2 tri-Laplacian"),
    Option("density", real, 1.0, "new vertex density relative to the surroundings (0 to 4)"),
    Option("fill_border", flag, False, "also fill the outer border of open components", is_flag=True),
)
HIERARCHY = (
    Option("levels", levels_spec, "all", "'all' or comma-separated level numbers (0 is the input)"),
    Option("min_vertices", int_at_least(1), 100, "stop at this many vertices"),
    Option("max_levels", int_at_least(1), None, "stop after this many levels (default: no limit)"),
    Option("maps", flag, False, "also write vertex_maps.npz (input vertex -> level vertex)", is_flag=True),
)
APPROXIMATE = (
    Option("count", count_or_percent, "2%", "control points: a count, or a share of each mesh's vertices "
           "like 2%", required=True),
    Option("method", choice(*_SELECTIONS), "greedy", "how the control points are chosen"),
    Option("interpolate", flag, False, "interpolate the control points exactly", is_flag=True),
    Option("seed", int_at_least(0), None, "random seed of --method random (default: 0 there)"),
)
ENCODE = (
    Option("count", count_or_percent, "2%", "anchors: a count, or a share of each mesh's vertices like 2%"),
    Option("bits", int_at_least(1), 12, "quantization bits per coordinate"),
    Option("method", choice(*_SELECTIONS), "greedy", "how the anchors are chosen"),
)
COMPARE = (
    Option("reference", folder, None, "folder holding a reference for every input (same name or "
           "stem)", cli=False),
    Option("points", int_at_least(1, MAX_SAMPLE_POINTS), 100_000, "surface samples per mesh", param="number_of_points"),
)
# fmt: on


#: batch.run's own parameters, the flags of ``o3d-lsmesh batch`` (the scheduler's two exclude each other)
RUN_FLAGS = (
    Option("workers", int, None, "local worker processes (default: CPUs; 0: this process)"),
    Option("threads_per_worker", int, 1, "threads of each worker"),
    Option("scheduler", str, None, _SCHEDULER, metavar="ADDRESS"),
    Option("scheduler_file", str, None, "existing scheduler's JSON file (default: none)", metavar="FILE"),
    Option("resume", flag, False, "skip inputs the report lists as ok with the same key", is_flag=True),
    Option("report", str, None, _REPORT, metavar="FILE"),
    Option("retries", int, 1, "runs of a task whose worker died before it fails"),
    Option("fail_fast", flag, False, "stop at the first failure", is_flag=True),
    Option("task_timeout", float, 3600.0, _TIMEOUT, metavar="SECONDS"),
    Option("suffix", str, ".ply", "output mesh format (.ply .obj .stl .off .gltf)"),
)
#: Names an operation option may not take: they are flags of ``o3d-lsmesh batch`` itself.
RESERVED = frozenset([option.name for option in RUN_FLAGS] + "op set quiet json force help".split())


def change_metrics(before: Any, after: Any) -> dict:
    """Vertex displacement, shape change and (same triangles) normal change, on arrays read once."""
    # read once: the metrics take a MeshData as it is (Any: their annotations name the public mesh kinds)
    a: Any = read_mesh(before, name="before")
    b: Any = read_mesh(after, name="after")
    out: dict[str, Any] = {}
    if corresponding(a, b):
        moved = vertex_error(b, a)
        out["displacement_mean"], out["displacement_max"] = moved["mean"], moved["linf"]
        out["normal_change_deg"] = normal_change(b, a)
    out.update(shape_change(a, b))
    return out


#: denoise options that multiresolution fairing does not take: it fairs every level with its own defaults
NOT_WITH_LEVEL = ("mu", "reimpose_every", "fixed_boundary")


def _denoise_check(options: dict) -> None:
    level = options["level"]
    # a batch would otherwise drop them without a word; a method but Liu's per-level operators too
    conflicts = [name for name in NOT_WITH_LEVEL if options[name] not in (None, False)]
    conflicts += ["method"] if options["method"] not in (None, "local", "global") else []
    if level and conflicts:
        given = ", ".join(f"{name}={options[name]!r}" for name in conflicts)
        raise InputError(
            f"{given} cannot be combined with level={level!r} (multiresolution fairing does not take "
            f"{'them' if len(conflicts) > 1 else 'it'}: it takes method='local' or method='global')",
            param="level",
        )
    method = resolved_options(options["method"], options["iterations"], options["reimpose_every"])[0]
    if not level and options["fixed_boundary"] and method in ("scan", "auto"):
        default = " (the default)" if options["method"] is None else ""
        raise InputError(
            f"fixed_boundary=True cannot be used with method={method!r}{default}: its boundary moves with the "
            "surface; add method='local' or method='global'",
            param="fixed_boundary",
        )


@operation(
    "denoise",
    options=DENOISE,
    help="barycenter-constrained (or multiresolution with --level) fairing",
    check=_denoise_check,
)
def denoise_op(mesh: Any, options: dict, context: TaskContext) -> tuple[Any, dict]:
    """``--op denoise`` and ``o3d-lsmesh denoise``: fairing with the method and iterations that ran."""
    mesh = read_mesh(mesh)  # validated once: the fairing and the metrics take it as it is
    level, progress = options["level"], context.progress
    if level:
        iterations = 5 if options["iterations"] is None else options["iterations"]
        method = options["method"] or "local"
        out = multiresolution_fairing(
            mesh, level, number_of_iterations=iterations, method=method, progress=progress
        )
    else:
        # no flag: the API's defaults; the record names what ran (auto's choice included)
        given = {name: options[name] for name in ("method", "mu", "reimpose_every")}
        given["smooth_boundary"] = not options["fixed_boundary"]
        out, ran = fairing.constrained_fairing(
            mesh, options["iterations"], **given, progress=progress, return_report=True
        )
        method, iterations = resolved_options(ran.method, options["iterations"], options["reimpose_every"])
    return out, {"method": method, "iterations": iterations, "level": level, **change_metrics(mesh, out)}


@operation("fill", options=FILL, help="fill holes with faired patches (LS meshes)")
def fill_op(mesh: Any, options: dict, context: TaskContext) -> tuple[Any, dict]:
    """``--op fill`` and ``o3d-lsmesh fill``: counts of new elements and of the loops filled and left open."""
    mesh = read_mesh(mesh)  # validated once (fill_holes welds it without a second check)
    out, report = fill_holes(mesh, **options, progress=context.progress, return_report=True)
    return out, {
        "new_vertices": len(out.vertices) - len(mesh.vertices),
        "new_triangles": len(out.triangles) - len(mesh.triangles),
        "holes_filled": len(report.filled),
        "holes_skipped": len(report.skipped),
        "left_open": report.describe(10),
        "_report": report,  # (the CLI lists every loop left open; records drop "_" keys)
    }


def parse_levels(spec: str, count: int) -> list[int]:
    """The levels ``spec`` names (``"all"`` or comma-separated numbers) in a hierarchy of ``count`` levels."""
    if spec == "all":
        return list(range(count))
    levels = sorted({int(item) for item in levels_spec(spec).split(",") if item.strip()})
    if not all(0 <= level < count for level in levels):
        raise InputError(
            f"levels must be in 0..{count - 1} (the hierarchy has {count} levels), got {spec!r}",
            param="levels",
        )
    return levels


@operation("hierarchy", options=HIERARCHY, output="files", help=_LEVELS)
def hierarchy_op(mesh: Any, options: dict, context: TaskContext) -> tuple[Any, dict]:
    """``--op hierarchy`` and ``o3d-lsmesh hierarchy``: ``{level_NN: mesh, vertex_maps.npz: bytes}``."""
    mesh = read_mesh(mesh)  # validated once (Any: the API's annotations name the public mesh kinds)
    sizes = {key: options[key] for key in ("min_vertices", "max_levels")}
    built = build_hierarchy(mesh, **sizes, progress=context.progress)
    levels = parse_levels(options["levels"], len(built))
    # level 0 is the input: with its attributes (the others have new connectivity: dropped, said)
    files: dict[str, Any] = {
        f"level_{i:02d}": built.level(i) if i else new_mesh(mesh, mesh.vertices) for i in levels
    }
    if options["maps"]:  # each map composes the parents of every level above it: only when asked
        buffer = io.BytesIO()
        maps = {f"level_{level:02d}": np.asarray(built.vertex_map(level), dtype=np.int64) for level in levels}
        np.savez_compressed(buffer, **maps)  # type: ignore[arg-type]
        files["vertex_maps.npz"] = buffer.getvalue()
    counts = [int(built.vertex_count(i)) for i in range(len(built))]
    return files, {"levels": len(built), "written_levels": levels, "vertex_counts": counts}


def _approximate_check(options: dict) -> None:
    method, seed = options["method"], options["seed"]
    if seed is not None and method != "random":  # the others draw nothing
        message = f"seed={seed!r} applies only to method='random', got method={method!r}"
        raise InputError(message, param="seed")


@operation("approximate", options=APPROXIMATE, help=_APPROXIMATE, check=_approximate_check)
def approximate_op(mesh: Any, options: dict, context: TaskContext) -> tuple[Any, dict]:
    """``--op approximate`` and ``o3d-lsmesh approximate``: the result, its control indices and errors."""
    mesh = read_mesh(mesh)  # validated once: the selection and the metrics take it as it is
    count = resolve_count(options["count"], len(mesh.vertices))
    method, interpolate, seed = options["method"], options["interpolate"], options["seed"]
    seed = 0 if seed is None and method == "random" else seed  # the same selection each run
    out, indices = approximate(
        mesh, count, method=method, interpolate=interpolate, seed=seed, progress=context.progress
    )
    error = vertex_error(out, mesh)
    indices = np.asarray(indices, dtype=np.int64)  # ("_" keys: for the CLI, not in records)
    return out, dict(
        count=len(indices), method=method, error_linf=error["linf"], error_rms=error["rms"], _indices=indices
    )


@operation("encode", options=ENCODE, output="bytes", extension=".bin", help=_ANCHORS)
def encode_op(mesh: Any, options: dict, context: TaskContext) -> tuple[Any, dict]:
    """``--op encode`` and ``o3d-lsmesh encode``: the bytes, their size and the decoded error."""
    mesh = read_mesh(mesh)  # validated once: the encoder, the decoder and the error take it as it is
    n = len(mesh.vertices)
    count = resolve_count(options["count"], n)
    progress = context.progress
    data = encode_geometry(mesh, count, bits=options["bits"], method=options["method"], progress=progress)
    error = vertex_error(decode_geometry(mesh, data, progress=progress), mesh)
    decoded = {"decoded_error_linf": error["linf"], "decoded_error_rms": error["rms"]}
    return data, dict(
        anchors=count, bits=options["bits"], bytes=len(data), bits_per_vertex=8.0 * len(data) / n, **decoded
    )


def find_reference(base: str, relative: str) -> str:
    """The reference for the input named ``relative``: same relative path, else same stem with any mesh extension."""
    exact = Path(base) / relative
    if exact.is_file():
        return str(exact)
    stem = Path(relative).with_suffix("")
    for extension in READABLE:
        candidate = Path(base) / stem.with_name(stem.name + extension)
        if candidate.is_file():
            return str(candidate)
    raise InputError(
        f"reference {base!r} has no file matching {relative!r} (same name, or same stem with one of "
        f"{', '.join(READABLE)})",
        param="reference",
    )


def _compare_check(options: dict) -> None:
    if options["reference"] is None:
        message = "reference is required by op compare (a folder of the files to compare with)"
        raise InputError(message, param="reference")


@operation("compare", options=COMPARE, output="none", help=_AGAINST, check=_compare_check)
def compare_op(mesh: Any, options: dict, context: TaskContext) -> tuple[Any, dict]:
    """``--op compare``: metrics against the matching file of ``reference``."""
    reference_path = find_reference(options["reference"], context.relative)
    reference: Any = read_mesh(read_mesh_file(reference_path), name="reference")  # each read once
    mesh = read_mesh(mesh)
    metrics: dict[str, Any] = {
        "reference": reference_path,
        "vertices_reference": len(reference.vertices),
        "surface_distance": surface_distance(mesh, reference, number_of_points=options["points"]),
    }
    if corresponding(mesh, reference):
        metrics["vertex_error"] = vertex_error(mesh, reference)
    metrics.update(change_metrics(reference, mesh))
    return None, metrics
