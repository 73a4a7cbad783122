"""The ``o3d-lsmesh`` command line.

Reads and writes every triangle-mesh format Open3D reads and writes (PLY, OBJ,
STL, OFF, glTF, ...). Subcommands::

    o3d-lsmesh denoise INPUT OUTPUT [--iterations N] [--method local|global] [--level L] [--render PNG]
    o3d-lsmesh approximate INPUT OUTPUT --count N [--method greedy|random|combined]
    o3d-lsmesh reconstruct INPUT OUTPUT --unknown SPEC
    o3d-lsmesh hierarchy INPUT OUTDIR [--levels 0,2,4|all]
    o3d-lsmesh encode INPUT OUTPUT [--count N] [--bits B]
    o3d-lsmesh decode MESH DATA OUTPUT [--anchors K]
    o3d-lsmesh compare A B [--render PNG]
    o3d-lsmesh fill INPUT OUTPUT [--max-hole-edges K] [--max-hole-diameter D] [--continuity 0|1|2] [--density X] [--fill-border]
    o3d-lsmesh demo [--out demo_out]

Every subcommand takes ``--quiet`` (no progress, no report), ``--json``
(print one JSON object with the metrics on stdout, nothing else goes there)
and ``--force`` (allow OUTPUT to be an input file). Exit codes: 0 success;
2 for every user failure: a missing, unreadable, truncated or empty mesh file,
bad arguments, a request too large for memory, or input the algorithms reject
(one line on stderr naming the CLI flag, no traceback); 1 when a picture could
not be drawn, and 1 with a traceback for an internal error (a bug: please
report it). Errors the library raises on purpose (``ValueError``,
``TypeError``, ``SingularSystemError`` from its own checks) are user errors;
the same exception types raised anywhere else (numpy, a mistake in our code)
are internal errors.

STL files store every triangle with its own three vertices; they are read
with duplicated vertices merged, so the algorithms see one surface. Other
formats keep the layout Open3D reads (OBJ and glTF split vertices at UV
seams): fairing welds exactly coincident vertices itself and writes the
input's layout back, so seams stay closed and UVs stay valid.
"""

from __future__ import annotations

import argparse
import contextlib
import dis
import json
import os
import re
import sys
import tempfile
import textwrap
import time
import traceback
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CLIError", "build_parser", "main", "parse_index_spec"]

PROG = "o3d-lsmesh"
#: Extensions Open3D 0.20 writes back readably (its .glb writer produces files it cannot read back).
WRITABLE = (".ply", ".obj", ".stl", ".off", ".gltf")


class CLIError(Exception):
    """A user error: reported as one line on stderr with exit code 2."""


#: Phrases of library messages that name an API option, and the CLI flag the user typed instead.
_PHRASES = {
    "pass smooth_boundary=False to keep it fixed": "pass --fixed-boundary to keep it fixed",
    "smooth_boundary=False": "--fixed-boundary",
    "must be None for method='global'": "cannot be used with --method global",
    "must be None for method='local'": "cannot be used with --method local",
    "(outside unknown_vertex_indices)": "(outside --unknown)",
}


@contextlib.contextmanager
def _flags(*, mesh: str | None = None, **flag_of: str) -> Iterator[None]:
    """Re-raise the library's user errors in the block as :class:`CLIError` naming CLI flags, not API parameters.

    ``flag_of`` maps a flag (``unknown`` for ``--unknown``) to the API parameter
    it feeds (``unknown_vertex_indices``); messages start "<param> must ...".
    ``mesh`` replaces the word "mesh" that starts a message about the input
    mesh (``"INPUT 'scan.ply'"``).
    """
    try:
        yield
    except (ValueError, TypeError) as error:
        if not _is_user_error(error):
            raise
        text = str(error)
        for flag, param in flag_of.items():
            text = re.sub(rf"(?<![\w.-]){re.escape(param)}(?= must\b)", "--" + flag.replace("_", "-"), text)
        for phrase, replacement in _PHRASES.items():
            text = text.replace(phrase, replacement)
        if mesh is not None:
            text = re.sub(r"^mesh\b", lambda _: mesh, text)
        raise CLIError(text) from error


def _is_user_error(error: BaseException) -> bool:
    """Whether ``error`` is one the library raised on purpose (a ``raise`` statement in o3d_lsmesh).

    A ``ValueError`` or ``TypeError`` from numpy, Open3D or a slip in our own
    code (a bad format string) is an internal error and must show its
    traceback, not pass as the user's fault.
    """
    from ._errors import SingularSystemError

    if isinstance(error, (CLIError, SingularSystemError)):
        return True
    tb = error.__traceback__
    if tb is None:
        return False
    while tb.tb_next is not None:
        tb = tb.tb_next
    code = tb.tb_frame.f_code
    package = os.path.dirname(os.path.abspath(__file__))
    if not os.path.abspath(code.co_filename).startswith(package + os.sep):
        return False
    # the instruction that raised: an explicit `raise` statement, not an operation failing
    return any(i.offset == tb.tb_lasti and i.opname == "RAISE_VARARGS" for i in dis.get_instructions(code))


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        # every subcommand's --help shows the defaults (subparsers are made with this class too)
        kwargs.setdefault("formatter_class", _HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:  # one line, no usage block
        raise CLIError(f"{self.prog}: error: {message} (see {self.prog} --help)")


# --------------------------------------------------------------------------- helpers


class _Run:
    """Output policy of one invocation: progress bars, human report, JSON."""

    def __init__(self, args: argparse.Namespace):
        self.quiet = bool(getattr(args, "quiet", False))
        self.json = bool(getattr(args, "json", False))
        self.progress = not self.quiet

    def say(self, text: str) -> None:
        # With --json, stdout carries only the JSON object: the report goes to stderr.
        if not self.quiet:
            print(text, file=sys.stderr if self.json else sys.stdout, flush=True)

    def call(self, function: Any, *args: Any, desc: str = "", **kwargs: Any) -> Any:
        """Call ``function(*args, **kwargs)``; kept for subcommands written against the old helper.

        It no longer inspects signatures nor draws a one-step bar ("0/1 -> 1/1"
        is noise): pass ``progress=run.progress`` to functions that take it.
        """
        return function(*args, **kwargs)

    def finish(self, report: dict) -> int:
        if self.json:
            print(json.dumps(report, indent=2, default=_jsonable), flush=True)
        return 0


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serializable: {type(value).__name__}")


def _o3d():
    from ._o3d import open3d

    o3d = open3d()
    # Open3D prints its own read/write warnings on stdout; ours are clearer and --json needs stdout clean.
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    return o3d


@contextlib.contextmanager
def _captured_native_output() -> Iterator[list]:
    """Capture what C/C++ libraries write straight to file descriptors 1 and 2 (RPly, Assimp, Open3D).

    Yields a list that holds the captured text once the block ends: it keeps
    ``--json`` output clean and lets :func:`read_input` see the reader's
    complaints (Open3D returns what it read so far from a truncated file and
    only says so in a warning).
    """
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    captured: list = []
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


# Open3D's readers report a file they could not read to the end with these words (and return what they got)
_READ_FAILURE = re.compile(
    r"(?i)(read \w+ failed|rply: error|unable to read|error reading|unexpected end)[^\n]*"
)
_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def _ply_header_counts(path: str) -> dict:
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


def read_input(path: str, *, what: str = "INPUT") -> Any:
    """Read a triangle mesh or raise :class:`CLIError` naming the problem (missing, unreadable, truncated, empty)."""
    o3d = _o3d()
    if not os.path.exists(path):
        raise CLIError(f"{what} {path!r} does not exist")
    if os.path.isdir(path):
        raise CLIError(f"{what} {path!r} is a folder, not a mesh file")
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Warning)
    try:
        with _captured_native_output() as captured:
            mesh = o3d.io.read_triangle_mesh(path)
    finally:
        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    failure = _READ_FAILURE.search(_ANSI.sub("", captured[0]))
    if failure and len(mesh.vertices):
        raise CLIError(
            f"{what} {path!r} is truncated or corrupt: Open3D read only part of it ({failure.group(0).strip()})"
        )
    if Path(path).suffix.lower() == ".ply" and len(mesh.vertices):
        header = _ply_header_counts(path)
        # a polygon face gives at least one triangle: fewer triangles than faces means faces were lost
        if header.get("vertex", len(mesh.vertices)) != len(mesh.vertices) or header.get("face", 0) > len(
            mesh.triangles
        ):
            raise CLIError(
                f"{what} {path!r} is truncated or corrupt: its header declares {header.get('vertex')} vertices "
                f"and {header.get('face', 0)} faces, Open3D read {len(mesh.vertices)} and {len(mesh.triangles)} triangles"
            )
    if len(mesh.vertices) == 0:
        raise CLIError(
            f"{what} {path!r} could not be read as a triangle mesh (empty, corrupt or unsupported format)"
        )
    if len(mesh.triangles) == 0:
        raise CLIError(f"{what} {path!r} has {len(mesh.vertices)} vertices but no triangles")
    if Path(path).suffix.lower() == ".stl":
        mesh = mesh.remove_duplicated_vertices()
    # the checks every command would make, made once here so that the message names the file
    # (an index past the vertices is also how a cut-off text file shows: "3 18" read as 182)
    from ._o3d import read_mesh

    try:
        read_mesh(mesh, name=f"{what} {path!r}")
    except (ValueError, TypeError) as error:
        raise CLIError(str(error)) from None
    return mesh


def _same_file(a: str, b: str) -> bool:
    try:
        return os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b)
    except OSError:
        return False


def check_output(
    path: str, inputs: Sequence[str], *, force: bool, suffixes: Sequence[str] | None = WRITABLE
) -> None:
    """Refuse, before any work, an output that would overwrite an input or cannot be written."""
    for source in inputs:
        if _same_file(path, source) and not force:
            raise CLIError(
                f"OUTPUT {path!r} is the input file {source!r}; refusing to overwrite it (use --force)"
            )
    if suffixes is not None and Path(path).suffix.lower() not in suffixes:
        hint = ""
        if Path(path).suffix.lower() == ".glb" and ".gltf" in suffixes:
            hint = " (Open3D writes .glb files it cannot read back: use .gltf)"
        raise CLIError(f"OUTPUT {path!r} must end in one of {', '.join(suffixes)}{hint}")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise CLIError(f"OUTPUT folder {folder!r} does not exist")


def write_output(path: str, mesh: Any) -> None:
    o3d = _o3d()
    if Path(path).suffix.lower() == ".stl":
        # Open3D's STL writer needs triangle normals and refuses without them.
        mesh = o3d.geometry.TriangleMesh(mesh)
        mesh.compute_triangle_normals()
    with _captured_native_output():
        written = o3d.io.write_triangle_mesh(path, mesh)
    if not written:
        raise CLIError(f"could not write OUTPUT {path!r}")


def parse_index_spec(spec: str, n: int) -> np.ndarray:
    """Vertex indices from a file (``.npy``, or integers separated by spaces, commas or newlines) or a list like ``0:100,250,300:310``.

    ``a:b`` is the half-open range ``a, ..., b-1`` (Python slicing, without negative indices).
    """
    if os.path.exists(spec):
        try:
            if spec.endswith(".npy"):
                values = np.load(spec, allow_pickle=False)
            else:
                text = Path(spec).read_text().replace(",", " ").split()
                values = np.array([int(t) for t in text], dtype=np.int64)
        except (ValueError, OSError) as error:
            raise CLIError(f"--unknown file {spec!r} must hold integer vertex indices ({error})") from None
        values = np.asarray(values).ravel()
        if values.size and not np.issubdtype(values.dtype, np.integer):
            raise CLIError(
                f"--unknown file {spec!r} must hold integer vertex indices, got dtype {values.dtype}"
            )
        if values.size == 0:
            raise CLIError(f"--unknown file {spec!r} must name at least one vertex, got none")
        bad = (values < 0) | (values >= n)
        if bad.any():
            raise CLIError(
                f"--unknown file {spec!r} must hold vertex indices in 0..{n - 1} (the mesh has {n} "
                f"vertices), got {int(values[bad][0])}"
            )
        return np.unique(values.astype(np.int64))
    parts = []
    for item in spec.split(","):
        item = item.strip()
        try:
            if ":" in item:
                start, stop = item.split(":")
                start, stop = int(start) if start else 0, int(stop) if stop else n
                if start < 0 or stop < start:
                    raise ValueError
            elif item:
                start = int(item)
                stop = start + 1
            else:
                continue
        except ValueError:
            raise CLIError(
                f"--unknown must be an existing index file or a list like '0:100,250', got {spec!r}"
            ) from None
        if start < 0 or stop > n:
            # checked before any array is made: '0:99999999999' must not allocate 800 GB
            what = f"range {item!r}" if ":" in item else f"index {item!r}"
            raise CLIError(
                f"--unknown must name vertices in 0..{n - 1} (the mesh has {n} vertices), got {what}"
            )
        parts.append(np.arange(start, stop, dtype=np.int64))
    if not parts:
        raise CLIError(f"--unknown must name at least one vertex, got {spec!r}")
    # overlapping items ('0:10,5') name a vertex twice: the union is meant
    return np.unique(np.concatenate(parts))


def _volume(mesh: Any) -> float:
    from .metrics import signed_volume

    return signed_volume(mesh)


def _normal_deviation(a: Any, b: Any) -> float | None:
    """Mean normal deviation, or None when no triangle has an area in both meshes (the angle is undefined)."""
    from ._o3d import read_mesh
    from .metrics import face_normals, normal_deviation

    da, db = read_mesh(a), read_mesh(b)
    if not (
        (np.abs(face_normals(da.vertices, da.triangles)).sum(axis=1) > 0)
        & (np.abs(face_normals(db.vertices, db.triangles)).sum(axis=1) > 0)
    ).any():
        return None
    return normal_deviation(a, b)


def _change_report(before: Any, after: Any) -> dict:
    from .metrics import vertex_error

    moved = vertex_error(after, before)
    v0, v1 = _volume(before), _volume(after)
    return {
        "displacement_mean": moved["mean"],
        "displacement_max": moved["linf"],
        "volume_change_percent": 100.0 * (v1 - v0) / v0 if v0 != 0 else None,
        "normal_change_deg": _normal_deviation(after, before),
    }


def _mesh_size(mesh: Any) -> dict:
    return {"vertices": len(mesh.vertices), "triangles": len(mesh.triangles)}


# --------------------------------------------------------------------------- subcommands


def _percent(value: float | None) -> str:
    # a flat or open mesh can enclose no volume: there is no relative change to print
    return "n/a (input volume 0)" if value is None else f"{value:.3f}%"


def cmd_denoise(args: argparse.Namespace, run: _Run) -> int:
    if args.level:
        # multiresolution fairing fairs every level with its own defaults: these options would be ignored
        given = [
            flag
            for flag, value in (
                ("--mu", args.mu),
                ("--reimpose-every", args.reimpose_every),
                ("--fixed-boundary", args.fixed_boundary or None),
            )
            if value is not None
        ]
        if given:
            raise CLIError(
                f"{', '.join(given)} cannot be combined with --level (multiresolution fairing "
                f"does not take {'them' if len(given) > 1 else 'it'}), got --level {args.level}"
            )
    check_output(args.output, [args.input], force=args.force)
    if args.render:
        check_output(args.render, [args.input], force=args.force, suffixes=(".png",))
    mesh = read_input(args.input)
    start = time.perf_counter()
    with _flags(
        mesh=f"INPUT {args.input!r}",
        iterations="number_of_iterations",
        level="level",
        mu="mu",
        reimpose_every="reimpose_every",
        method="method",
    ):
        if args.level:
            from .fairing.multiresolution import multiresolution_fairing

            args.iterations = 5 if args.iterations is None else args.iterations
            args.method = args.method or "local"
            out = multiresolution_fairing(
                mesh,
                args.level,
                number_of_iterations=args.iterations,
                method=args.method,
                progress=run.progress,
            )
        else:
            from .fairing import constrained_fairing
            from .fairing.constrained import resolved_options

            # no flag: the API's defaults (method='scan'); the report names what ran
            args.method, args.iterations = resolved_options(args.method, args.iterations, args.reimpose_every)
            out = constrained_fairing(
                mesh,
                args.iterations,
                method=args.method,
                mu=args.mu,
                smooth_boundary=not args.fixed_boundary,
                reimpose_every=args.reimpose_every,
                progress=run.progress,
            )
    seconds = time.perf_counter() - start
    report = {
        "command": "denoise",
        "input": args.input,
        "output": args.output,
        **_mesh_size(mesh),
        "method": args.method,
        "iterations": args.iterations,
        "level": args.level,
        "seconds": seconds,
        **_change_report(mesh, out),
    }
    message = (
        f"denoised {args.input} ({report['vertices']} vertices) in {seconds:.2f} s -> {args.output}; "
        f"mean displacement {report['displacement_mean']:.4g}, "
        f"volume change {_percent(report['volume_change_percent'])}"
    )
    write_output(args.output, out)
    run.say(message)
    if args.render:
        method = (
            f"multiresolution fairing, level {args.level}"
            if args.level
            else f"{args.method} fairing" + (f", mu {args.mu:g}" if args.mu is not None else "")
        )
        titles = [f"input: {Path(args.input).name}", f"{method}, {args.iterations} iterations"]
        report["render"] = _render([mesh, out], args.render, run, titles=titles)
    return run.finish(report)


def _render(
    meshes: list, path: str, run: _Run, *, what: str = "left: input, right: result", **options
) -> str:
    from .rendering import render

    start = time.perf_counter()
    render(meshes, path, **options)
    run.say(f"picture ({time.perf_counter() - start:.1f} s): {path}  ({what})")
    return path


def cmd_approximate(args: argparse.Namespace, run: _Run) -> int:
    check_output(args.output, [args.input], force=args.force)
    if args.indices:
        check_output(args.indices, [args.input], force=args.force, suffixes=(".npy", ".txt"))
    mesh = read_input(args.input)
    from .metrics import vertex_error
    from .selection import approximate

    start = time.perf_counter()
    with _flags(mesh=f"INPUT {args.input!r}", count="count", method="method", seed="seed"):
        out, indices = approximate(
            mesh,
            args.count,
            method=args.method,
            interpolate=args.interpolate,
            seed=args.seed,
            progress=run.progress,
        )
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    if args.indices:
        if args.indices.endswith(".npy"):
            np.save(args.indices, np.asarray(indices, dtype=np.int64))
        else:
            np.savetxt(args.indices, np.asarray(indices, dtype=np.int64), fmt="%d")
    error = vertex_error(out, mesh)
    report = {
        "command": "approximate",
        "input": args.input,
        "output": args.output,
        **_mesh_size(mesh),
        "count": len(indices),
        "method": args.method,
        "seconds": seconds,
        "error_linf": error["linf"],
        "error_rms": error["rms"],
    }
    run.say(
        f"approximated {args.input} from {report['count']} control points in {seconds:.2f} s -> {args.output}; "
        f"L-inf error {error['linf']:.4g}, RMS {error['rms']:.4g}"
    )
    return run.finish(report)


def cmd_reconstruct(args: argparse.Namespace, run: _Run) -> int:
    check_output(args.output, [args.input], force=args.force)
    mesh = read_input(args.input)
    unknown = parse_index_spec(args.unknown, len(mesh.vertices))
    from .lsmesh import reconstruct_geometry

    start = time.perf_counter()
    with _flags(mesh=f"INPUT {args.input!r}", unknown="unknown_vertex_indices"):
        out = reconstruct_geometry(mesh, unknown, interpolate=not args.soft, progress=run.progress)
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    unknown_unique = np.unique(unknown)
    moved = np.linalg.norm(
        np.asarray(out.vertices)[unknown_unique] - np.asarray(mesh.vertices)[unknown_unique], axis=1
    )
    report = {
        "command": "reconstruct",
        "input": args.input,
        "output": args.output,
        **_mesh_size(mesh),
        "unknown": len(unknown_unique),
        "seconds": seconds,
        "distance_to_input_mean": float(moved.mean()),
        "distance_to_input_max": float(moved.max()),
    }
    run.say(
        f"reconstructed {report['unknown']} vertices of {args.input} in {seconds:.2f} s -> {args.output}; "
        f"mean distance to the file's positions {report['distance_to_input_mean']:.4g}"
    )
    return run.finish(report)


def _parse_levels(spec: str, count: int) -> list[int]:
    if spec == "all":
        return list(range(count))
    try:
        levels = sorted({int(item) for item in spec.split(",") if item.strip()})
    except ValueError:
        raise CLIError(f"--levels must be 'all' or comma-separated integers, got {spec!r}") from None
    bad = [level for level in levels if not 0 <= level < count]
    if bad or not levels:
        raise CLIError(f"--levels must be in 0..{count - 1} (the hierarchy has {count} levels), got {spec!r}")
    return levels


def cmd_hierarchy(args: argparse.Namespace, run: _Run) -> int:
    mesh = read_input(args.input)
    suffix = "." + args.format.lstrip(".").lower()
    if suffix not in WRITABLE:
        raise CLIError(f"--format must be one of {', '.join(s[1:] for s in WRITABLE)}, got {args.format!r}")
    outdir = Path(args.outdir)
    if outdir.exists() and not outdir.is_dir():
        raise CLIError(f"OUTDIR {args.outdir!r} exists and is not a folder")
    from .hierarchy import build_hierarchy

    start = time.perf_counter()
    with _flags(mesh=f"INPUT {args.input!r}", min_vertices="min_vertices", max_levels="max_levels"):
        hierarchy = build_hierarchy(
            mesh, min_vertices=args.min_vertices, max_levels=args.max_levels, progress=run.progress
        )
    seconds = time.perf_counter() - start
    levels = _parse_levels(args.levels, len(hierarchy))
    outdir.mkdir(parents=True, exist_ok=True)
    files, maps = [], {}
    for level in levels:
        path = outdir / f"level_{level:02d}{suffix}"
        check_output(str(path), [args.input], force=args.force, suffixes=None)
        write_output(str(path), hierarchy.level(level))
        files.append(str(path))
        maps[f"level_{level:02d}"] = np.asarray(hierarchy.vertex_map(level), dtype=np.int64)
    if args.maps:
        np.savez_compressed(outdir / "vertex_maps.npz", **maps)
        files.append(str(outdir / "vertex_maps.npz"))
    report = {
        "command": "hierarchy",
        "input": args.input,
        "outdir": str(outdir),
        **_mesh_size(mesh),
        "levels": len(hierarchy),
        "vertex_counts": [int(hierarchy.vertex_count(i)) for i in range(len(hierarchy))],
        "written": files,
        "seconds": seconds,
    }
    run.say(
        f"hierarchy of {args.input}: {len(hierarchy)} levels ({report['vertex_counts'][0]} -> "
        f"{report['vertex_counts'][-1]} vertices) in {seconds:.2f} s; wrote {len(files)} files to {outdir}/"
    )
    return run.finish(report)


def cmd_encode(args: argparse.Namespace, run: _Run) -> int:
    check_output(args.output, [args.input], force=args.force, suffixes=None)
    mesh = read_input(args.input)
    n = len(mesh.vertices)
    count = args.count if args.count is not None else max(1, int(np.ceil(0.02 * n)))
    from .encoding import decode_geometry, encode_geometry
    from .metrics import vertex_error

    start = time.perf_counter()
    with _flags(mesh=f"INPUT {args.input!r}", count="count", bits="bits", method="method"):
        data = encode_geometry(mesh, count, bits=args.bits, method=args.method, progress=run.progress)
    seconds = time.perf_counter() - start
    Path(args.output).write_bytes(data)
    error = vertex_error(decode_geometry(mesh, data, progress=run.progress), mesh)
    report = {
        "command": "encode",
        "input": args.input,
        "output": args.output,
        **_mesh_size(mesh),
        "anchors": count,
        "bits": args.bits,
        "bytes": len(data),
        "bits_per_vertex": 8.0 * len(data) / n,
        "seconds": seconds,
        "decoded_error_linf": error["linf"],
        "decoded_error_rms": error["rms"],
    }
    run.say(
        f"encoded {args.input}: {count} anchors at {args.bits} bits -> {len(data)} bytes "
        f"({report['bits_per_vertex']:.3f} bits/vertex) in {seconds:.2f} s; decoded L-inf error {error['linf']:.4g}"
    )
    return run.finish(report)


def cmd_decode(args: argparse.Namespace, run: _Run) -> int:
    check_output(args.output, [args.mesh, args.data], force=args.force)
    mesh = read_input(args.mesh, what="MESH")
    if not os.path.exists(args.data):
        raise CLIError(f"DATA {args.data!r} does not exist")
    data = Path(args.data).read_bytes()
    from .encoding import decode_geometry

    start = time.perf_counter()
    with _flags(mesh=f"MESH {args.mesh!r}", anchors="anchors"):
        out = decode_geometry(mesh, data, anchors=args.anchors, progress=run.progress)
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    report = {
        "command": "decode",
        "mesh": args.mesh,
        "data": args.data,
        "output": args.output,
        **_mesh_size(mesh),
        "anchors": args.anchors,
        "seconds": seconds,
    }
    run.say(f"decoded {args.data} on the connectivity of {args.mesh} in {seconds:.2f} s -> {args.output}")
    return run.finish(report)


def cmd_compare(args: argparse.Namespace, run: _Run) -> int:
    if args.render:
        check_output(args.render, [args.a, args.b], force=args.force, suffixes=(".png",))
    a, b = read_input(args.a, what="A"), read_input(args.b, what="B")
    from .metrics import surface_distance, topology_summary, triangle_angles, vertex_error

    report: dict = {
        "command": "compare",
        "a": args.a,
        "b": args.b,
        "size_a": _mesh_size(a),
        "size_b": _mesh_size(b),
    }
    with _flags(points="number_of_points"):
        report["surface_distance"] = surface_distance(a, b, number_of_points=args.points)
    if len(a.vertices) == len(b.vertices):
        report["vertex_error"] = vertex_error(a, b)
        if np.array_equal(np.asarray(a.triangles), np.asarray(b.triangles)):
            report["normal_deviation_deg"] = _normal_deviation(a, b)
    va, vb = _volume(a), _volume(b)
    report["volume_a"], report["volume_b"] = va, vb
    report["volume_change_percent"] = 100.0 * (vb - va) / va if va != 0 else None
    report["angles_a"], report["angles_b"] = triangle_angles(a), triangle_angles(b)
    report["topology_a"], report["topology_b"] = topology_summary(a), topology_summary(b)
    if not run.quiet and not run.json:
        sd = report["surface_distance"]
        lines = [
            f"A {args.a}: {report['size_a']['vertices']} vertices, B {args.b}: {report['size_b']['vertices']} vertices",
            f"surface distance: Hausdorff {sd['hausdorff']:.6g}, mean {sd['mean']:.6g}, RMS {sd['rms']:.6g}",
        ]
        if "vertex_error" in report:
            ve = report["vertex_error"]
            lines.append(f"vertex error: L-inf {ve['linf']:.6g}, RMS {ve['rms']:.6g}, mean {ve['mean']:.6g}")
        if report.get("normal_deviation_deg") is not None:
            lines.append(f"face normal deviation: {report['normal_deviation_deg']:.4f} degrees")
        change = report["volume_change_percent"]
        lines.append(f"volume: A {va:.6g}, B {vb:.6g}" + (f" ({change:+.4f}%)" if change is not None else ""))
        for key in ("a", "b"):
            angles, topo = report[f"angles_{key}"], report[f"topology_{key}"]
            lines.append(
                f"{key.upper()}: min angle {angles['min_angle']:.2f} deg, {100 * angles['share_under_10']:.2f}% "
                f"under 10 deg, components {topo['components']}, boundary loops {topo['boundary_loops']}, "
                f"genus {topo['genus']}, edge-manifold {topo['edge_manifold']}"
            )
            holes = ", ".join(f"{size}: {count}" for size, count in topo["holes_by_size"].items())
            lines.append(
                f"{key.upper()}: surface pieces {topo['surface_pieces']}, boundary edges {topo['boundary_edges']} "
                f"in {topo['boundary_components']} connected pieces, holes by edge count ({holes}), "
                f"non-manifold vertices {topo['nonmanifold_vertices']}, non-manifold edges "
                f"{topo['nonmanifold_edges']}, unreferenced vertices {topo['unreferenced_vertices']}, "
                f"degenerate triangles {topo['degenerate_triangles']}"
            )
        for line in lines:
            run.say(line)
    if args.render:
        units = "mean edge lengths of A" if args.units == "edge" else "model units"
        report["render"] = _render(
            [a, b],
            args.render,
            run,
            reference=a,
            units=args.units,
            what=f"B colored by distance to A, in {units}",
            titles=[f"A: {Path(args.a).name} (reference)", f"B: {Path(args.b).name}"],
            colorbar_title="distance to A",
        )
    return run.finish(report)


def cmd_demo(args: argparse.Namespace, run: _Run) -> int:
    from .demo import run_demo

    result = run_demo(
        args.out,
        subdivisions=args.subdivisions,
        noise=args.noise,
        seed=args.seed,
        render=not args.no_render,
        quiet=run.quiet,
        progress=run.progress,
        stream=sys.stderr if run.json else sys.stdout,
    )
    return run.finish({"command": "demo", **result})


def cmd_fill(args: argparse.Namespace, run: _Run) -> int:
    check_output(args.output, [args.input], force=args.force)
    mesh = read_input(args.input)
    from .hole_filling import fill_holes, find_holes

    vertices, triangles = np.asarray(mesh.vertices), np.asarray(mesh.triangles).astype(np.int64)
    before = find_holes(vertices, triangles)
    start = time.perf_counter()
    with _flags(
        mesh=f"INPUT {args.input!r}",
        max_hole_edges="max_hole_edges",
        max_hole_diameter="max_hole_diameter",
        continuity="continuity",
        density="density",
    ):
        out = fill_holes(
            mesh,
            max_hole_edges=args.max_hole_edges,
            max_hole_diameter=args.max_hole_diameter,
            continuity=args.continuity,
            density=args.density,
            fill_border=args.fill_border,
            progress=run.progress,
        )
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    after = find_holes(np.asarray(out.vertices), np.asarray(out.triangles).astype(np.int64))
    report = {
        "command": "fill",
        "input": args.input,
        "output": args.output,
        **_mesh_size(mesh),
        "holes_before": len(before),
        "holes_after": len(after),
        "borders_left_open": sum(hole.border for hole in before) if not args.fill_border else 0,
        "new_vertices": len(out.vertices) - len(mesh.vertices),
        "new_triangles": len(out.triangles) - len(mesh.triangles),
        "seconds": seconds,
    }
    run.say(
        f"filled {len(before) - len(after)} of {len(before)} holes of {args.input} in {seconds:.2f} s "
        f"({report['new_vertices']} new vertices) -> {args.output}; {len(after)} loops left open"
    )
    return run.finish(report)


# --------------------------------------------------------------------------- parser


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """``--help`` shows every option's default and keeps the examples' line breaks."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        # an option whose default is resolved later (None standing for the API's choice) says so itself
        if action.help and "(default:" in action.help:
            return action.help
        return super()._get_help_string(action)


def _int_at_least(minimum: int, description: str, maximum: int | None = None):
    """An argparse type for integers in ``[minimum, maximum]`` with a one-line error naming the rule."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum:
            raise argparse.ArgumentTypeError(f"must be a {description} integer, got {text!r}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {maximum:,}, got {text!r}")
        return value

    return parse


def _nonnegative_float(text: str) -> float:
    """An argparse type for finite floats ``>= 0`` (``nan``, ``inf`` and negatives refused)."""
    try:
        value = float(text)
    except ValueError:
        value = None
    if value is None or not np.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"must be a non-negative finite number, got {text!r}")
    return value


_positive_int = _int_at_least(1, "positive")
_nonnegative_int = _int_at_least(0, "non-negative")
#: metrics.MAX_SAMPLE_POINTS (not imported here: --help must not load the numeric modules)
MAX_POINTS = 10_000_000
#: the demo's blob has 10 * 4**s + 2 vertices: 9 gives 2.6 million (about 3 GB to denoise), 12 would need 170 million
MAX_SUBDIVISIONS = 9


def _command(
    sub: Any,
    name: str,
    *,
    summary: str,
    description: str,
    example: str,
    handler: Any,
    parents: Sequence[argparse.ArgumentParser],
) -> argparse.ArgumentParser:
    """Add subcommand ``name`` with its one-line summary, description and an example in ``--help``."""
    parser = sub.add_parser(
        name,
        parents=list(parents),
        help=summary,
        description=textwrap.fill(description, 79),
        epilog=f"example:\n  {example}",
    )
    parser.set_defaults(handler=handler)
    return parser


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog=PROG,
        description=textwrap.fill(
            "Least-squares meshes and constrained fairing for Open3D meshes. Reads and "
            "writes every triangle-mesh format Open3D does (PLY, OBJ, STL, OFF, glTF). Each "
            "call imports Open3D (about 2 s).",
            79,
        ),
        epilog=f"example:\n  {PROG} denoise scan.ply smooth.ply\n  {PROG} denoise --help",
    )
    from . import __version__

    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--quiet", action="store_true", help="no progress bars and no report")
    common.add_argument("--json", action="store_true", help="print the metrics as one JSON object on stdout")
    common.add_argument("--force", action="store_true", help="allow overwriting an input file")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    both = [common]

    p = _command(
        sub,
        "denoise",
        parents=both,
        handler=cmd_denoise,
        summary="barycenter-constrained (or multiresolution) fairing",
        description="Remove noise with barycenter-constrained fairing (Liu et al. 2001, section 3): the "
        "membrane energy is minimized while every triangle keeps its barycenter. With "
        "--level L, multiresolution fairing (section 4.2): fair a coarse level of the "
        "volume-cost hierarchy, then split back up.",
        example=f"{PROG} denoise scan.ply smooth.ply --iterations 20 --render before_after.png",
    )
    p.add_argument("input", metavar="INPUT", help="mesh file to denoise")
    p.add_argument("output", metavar="OUTPUT", help="mesh file to write (.ply, .obj, .stl, .off, .gltf)")
    p.add_argument(
        "--iterations",
        type=_nonnegative_int,
        default=None,
        help="number of fairing iterations (default: the API's, 10 for local; with --level, 5 per level)",
    )
    p.add_argument(
        "--method",
        choices=("scan", "local", "global"),
        default=None,
        help="fairing energy (default: scan, the API's default; local with --level or --reimpose-every)",
    )
    p.add_argument(
        "--level", type=_nonnegative_int, default=0, help="multiresolution level (0: plain fairing)"
    )
    p.add_argument(
        "--mu",
        type=float,
        default=None,
        help="barycenter penalty weight of --method global or scan (not with --level)",
    )
    p.add_argument(
        "--reimpose-every",
        type=_positive_int,
        default=None,
        help="re-take the barycenters every k iterations (not with --level)",
    )
    p.add_argument(
        "--fixed-boundary",
        action="store_true",
        help="keep boundary vertices fixed instead of smoothing the boundary curves (not with --level)",
    )
    p.add_argument("--render", metavar="PNG", default=None, help="write a before/after picture")

    p = _command(
        sub,
        "approximate",
        parents=both,
        handler=cmd_approximate,
        summary="LS-mesh approximation from N control points",
        description="Rebuild the geometry from the connectivity and N control points chosen on the "
        "mesh (least-squares meshes, Sorkine and Cohen-Or 2004).",
        example=f"{PROG} approximate bunny.ply approx.ply --count 400 --indices controls.npy",
    )
    p.add_argument("input", metavar="INPUT", help="mesh file")
    p.add_argument("output", metavar="OUTPUT", help="mesh file to write")
    # (required options: no "(default: None)" in --help)
    p.add_argument(
        "--count",
        type=_positive_int,
        required=True,
        default=argparse.SUPPRESS,
        help="number of control points",
    )
    p.add_argument(
        "--method",
        choices=("greedy", "random", "combined"),
        default="greedy",
        help="how the control points are chosen",
    )
    p.add_argument("--interpolate", action="store_true", help="interpolate the control points exactly")
    p.add_argument("--seed", type=int, default=0, help="random seed of --method random/combined")
    p.add_argument(
        "--indices", metavar="FILE", default=None, help="also write the control indices (.npy or .txt)"
    )

    p = _command(
        sub,
        "reconstruct",
        parents=both,
        handler=cmd_reconstruct,
        summary="rebuild the geometry of unknown vertices",
        description="Replace the positions of the --unknown vertices by the least-squares mesh of the "
        "known ones (LS meshes, figures 5 and 8); known vertices stay as they are unless "
        "--soft.",
        example=f"{PROG} reconstruct scan.ply filled.ply --unknown 0:100,250",
    )
    p.add_argument("input", metavar="INPUT", help="mesh file")
    p.add_argument("output", metavar="OUTPUT", help="mesh file to write")
    p.add_argument(
        "--unknown",
        required=True,
        metavar="SPEC",
        default=argparse.SUPPRESS,
        help="index file (.npy or text) or list of indices and a:b ranges, e.g. '0:100,250'",
    )
    p.add_argument(
        "--soft", action="store_true", help="known vertices as soft constraints (whole mesh re-solved)"
    )

    p = _command(
        sub,
        "hierarchy",
        parents=both,
        handler=cmd_hierarchy,
        summary="write levels of the volume-cost collapse hierarchy",
        description="Build the volume-cost edge-collapse hierarchy (Liu et al. 2001, section 4.1) and "
        "write the chosen levels as mesh files.",
        example=f"{PROG} hierarchy bunny.ply levels/ --levels 0,2,4 --maps",
    )
    p.add_argument("input", metavar="INPUT", help="mesh file")
    p.add_argument("outdir", metavar="OUTDIR", help="folder for level_NN files (created if needed)")
    p.add_argument("--levels", default="all", help="'all' or comma-separated level numbers (0 is the input)")
    p.add_argument("--min-vertices", type=_positive_int, default=100, help="stop at this many vertices")
    p.add_argument(
        "--max-levels", type=_positive_int, default=None, help="stop after this many levels (None: no limit)"
    )
    p.add_argument("--format", default="ply", help="file format of the levels (ply, obj, stl, off, gltf)")
    p.add_argument(
        "--maps", action="store_true", help="also write vertex_maps.npz (input vertex -> level vertex)"
    )

    p = _command(
        sub,
        "encode",
        parents=both,
        handler=cmd_encode,
        summary="encode the geometry as quantized LS-mesh anchors",
        description="Store the geometry as the quantized positions of a few anchors; decode rebuilds it "
        "from the connectivity (geometry-aware bases, Sorkine et al.).",
        example=f"{PROG} encode bunny.ply bunny.lsm --count 500 --bits 12",
    )
    p.add_argument("input", metavar="INPUT", help="mesh file")
    p.add_argument("output", metavar="OUTPUT", help="file for the encoded bytes")
    p.add_argument("--count", type=_positive_int, default=None, help="anchors (None: 2%% of the vertices)")
    p.add_argument("--bits", type=_positive_int, default=12, help="quantization bits per coordinate")
    p.add_argument(
        "--method",
        choices=("greedy", "random", "combined"),
        default="greedy",
        help="how the anchors are chosen",
    )

    p = _command(
        sub,
        "decode",
        parents=both,
        handler=cmd_decode,
        summary="decode geometry onto a mesh's connectivity",
        description="Rebuild the geometry stored by encode on the connectivity of MESH.",
        example=f"{PROG} decode bunny.ply bunny.lsm decoded.ply --anchors 200",
    )
    p.add_argument("mesh", metavar="MESH", help="mesh file whose connectivity the data was encoded on")
    p.add_argument("data", metavar="DATA", help="file written by encode")
    p.add_argument("output", metavar="OUTPUT", help="mesh file to write")
    p.add_argument(
        "--anchors", type=_positive_int, default=None, help="use only the first K anchors (None: all)"
    )

    p = _command(
        sub,
        "compare",
        parents=both,
        handler=cmd_compare,
        summary="metrics between two meshes",
        description="Surface distance (sampled, both ways), vertex error and normal deviation when the "
        "meshes correspond, volume, triangle angles and topology of both.",
        example=f"{PROG} compare clean.ply smooth.ply --json",
    )
    p.add_argument("a", metavar="A", help="first mesh file")
    p.add_argument("b", metavar="B", help="second mesh file")
    p.add_argument(
        "--points",
        type=_int_at_least(1, "positive", MAX_POINTS),
        default=100_000,
        help="surface samples per mesh",
    )
    p.add_argument(
        "--render",
        metavar="PNG",
        default=None,
        help="write a distance map: A and B side by side, colored by distance to A, with a color bar",
    )
    p.add_argument(
        "--units",
        choices=("model", "edge"),
        default="model",
        help="units of the distance map: model units or mean edge lengths of A",
    )

    p = _command(
        sub,
        "demo",
        parents=both,
        handler=cmd_demo,
        summary="denoise a built-in mesh and compare with Open3D's filters",
        description="Add noise to a built-in blob, denoise it with every method of this package and "
        "Open3D's filters, and print a table of errors (and a picture).",
        example=f"{PROG} demo --out demo_out --subdivisions 5",
    )
    p.add_argument("--out", default="demo_out", help="output folder")
    p.add_argument("--no-render", action="store_true", help="skip the picture")
    p.add_argument(
        "--subdivisions",
        type=_int_at_least(1, "positive", MAX_SUBDIVISIONS),
        default=6,
        help="size of the built-in mesh: 10 * 4**s + 2 vertices (6: 40,962)",
    )
    p.add_argument("--noise", type=_nonnegative_float, default=0.3, help="noise sigma in mean edge lengths")
    p.add_argument("--seed", type=int, default=0, help="random seed of the noise")

    p = _command(
        sub,
        "fill",
        parents=both,
        handler=cmd_fill,
        summary="fill holes with faired patches (LS meshes)",
        description="Close holes: minimum-weight triangulation (Liepa 2003), refinement to the "
        "surrounding edge density, then LS-mesh fairing of the new vertices with the "
        "hole's rings as anchors. Each open component's outer border stays open unless "
        "--fill-border.",
        example=f"{PROG} fill scan.ply filled.ply --max-hole-edges 200",
    )
    p.add_argument("input", metavar="INPUT", help="mesh file")
    p.add_argument("output", metavar="OUTPUT", help="mesh file to write")
    p.add_argument(
        "--max-hole-edges",
        type=_int_at_least(3, "3-or-more"),
        default=None,
        help="fill only holes of at most this many edges (None: no limit)",
    )
    p.add_argument(
        "--max-hole-diameter",
        type=float,
        default=None,
        help="fill only holes at most this wide, in mesh units (None: no limit)",
    )
    p.add_argument(
        "--continuity",
        type=int,
        choices=(0, 1, 2),
        default=2,
        help="0 harmonic, 1 LS mesh (bi-Laplacian), 2 tri-Laplacian",
    )
    p.add_argument(
        "--density", type=float, default=1.0, help="new vertex density relative to the surroundings"
    )
    p.add_argument("--fill-border", action="store_true", help="also fill the outer border of open components")

    # o3d-lsmesh batch INPUT... OUTDIR --op OP: parser and handler live in o3d_lsmesh/batch.py.
    from .batch import add_parser as add_batch_parser

    add_batch_parser(sub, common)
    return parser


def _close_progress_bars() -> None:
    """End every live tqdm bar with its newline, so that an error message starts on a line of its own.

    A bar left open by an exception (held alive by the traceback) would otherwise
    have the message printed after its last ``\r``, on the bar's line.
    """
    tqdm_module = sys.modules.get("tqdm.std")
    if tqdm_module is None:
        return
    for bar in list(getattr(tqdm_module.tqdm, "_instances", ())):
        with contextlib.suppress(Exception):
            bar.close()


def _fail(text: str, code: int) -> int:
    _close_progress_bars()
    sys.stdout.flush()
    print(text if text.startswith(PROG) else f"{PROG}: error: {text}", file=sys.stderr, flush=True)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``o3d-lsmesh`` with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    Exit codes: 0 success, 2 a user error (one line on stderr), 1 a picture
    that could not be drawn or an internal error (with its traceback), 130 an
    interrupt.
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        return args.handler(args, _Run(args))
    except CLIError as error:
        return _fail(str(error), 2)
    except (ValueError, TypeError) as error:
        if not _is_user_error(error):
            return _internal_error(error)
        # The library's own checks: the message names the parameter, what was expected and what came.
        return _fail(str(error), 2)
    except MemoryError:
        return _fail("not enough memory for this request: try a smaller mesh or smaller options", 2)
    except OSError as error:
        return _fail(f"{error.strerror or error}: {error.filename or ''}".rstrip(": "), 2)
    except RuntimeError as error:  # a picture that could not be drawn (exit 1, not a user error)
        return _fail(str(error), 1)
    except KeyboardInterrupt:
        _close_progress_bars()
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except Exception as error:
        return _internal_error(error)


def _internal_error(error: BaseException) -> int:
    _close_progress_bars()
    traceback.print_exception(type(error), error, error.__traceback__, file=sys.stderr)
    print(
        f"{PROG}: internal error (a bug in o3d-lsmesh, not in your input: please report it with the "
        "traceback above)",
        file=sys.stderr,
        flush=True,
    )
    return 1


if __name__ == "__main__":
    sys.exit(main())
