"""The ``o3d-lsmesh`` command line.

Reads and writes every triangle-mesh format Open3D reads and writes (PLY, OBJ,
STL, OFF, glTF, ...). Subcommands::

    o3d-lsmesh denoise INPUT OUTPUT [--iterations N] [--method local|global] [--level L] [--render PNG]
    o3d-lsmesh approximate INPUT OUTPUT --count N [--method greedy|random|combined]
    o3d-lsmesh reconstruct INPUT OUTPUT --unknown SPEC
    o3d-lsmesh hierarchy INPUT OUTDIR [--levels 0,2,4|all]
    o3d-lsmesh encode INPUT OUTPUT [--count N] [--bits B]
    o3d-lsmesh decode MESH DATA OUTPUT [--anchors K]
    o3d-lsmesh compare A B
    o3d-lsmesh fill INPUT OUTPUT [--max-hole-edges K] [--max-hole-diameter D] [--continuity 0|1|2] [--density X] [--fill-border]
    o3d-lsmesh demo [--out demo_out]

Every subcommand takes ``--quiet`` (no progress, no report), ``--json``
(print one JSON object with the metrics on stdout, nothing else goes there)
and ``--force`` (allow OUTPUT to be an input file). Exit codes: 0 success,
2 for a missing file, an unreadable or empty mesh, bad arguments or input the
algorithms reject (one line on stderr, no traceback), 1 when a picture could
not be drawn.

STL files store every triangle with its own three vertices; they are read
with duplicated vertices merged, so the algorithms see one surface.
"""

from __future__ import annotations

import argparse
import contextlib
import inspect
import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

__all__ = ["main", "build_parser", "parse_index_spec", "CLIError"]

PROG = "o3d-lsmesh"
#: Extensions Open3D 0.20 writes back readably (its .glb writer produces files it cannot read back).
WRITABLE = (".ply", ".obj", ".stl", ".off", ".gltf")


class CLIError(Exception):
    """A user error: reported as one line on stderr with exit code 2."""


class _Parser(argparse.ArgumentParser):
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

    def call(self, function: Callable, *args: Any, desc: str = "", **kwargs: Any) -> Any:
        """Call ``function``; give it ``progress=`` if it takes one, else show a one-step bar."""
        try:
            accepts = "progress" in inspect.signature(function).parameters
        except (TypeError, ValueError):
            accepts = False
        if accepts:
            return function(*args, progress=self.progress, **kwargs)
        if not self.progress:
            return function(*args, **kwargs)
        from tqdm.auto import tqdm

        with tqdm(total=1, desc=desc or getattr(function, "__name__", "working"), file=sys.stderr) as bar:
            result = function(*args, **kwargs)
            bar.update(1)
        return result

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
def _quiet_native_output():
    """Silence C/C++ libraries writing straight to file descriptors 1 and 2 (RPly, Assimp) for the duration."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved + [devnull]:
            os.close(fd)


def read_input(path: str, *, what: str = "INPUT") -> Any:
    """Read a triangle mesh or raise :class:`CLIError` naming the problem."""
    o3d = _o3d()
    if not os.path.exists(path):
        raise CLIError(f"{what} {path!r} does not exist")
    if os.path.isdir(path):
        raise CLIError(f"{what} {path!r} is a folder, not a mesh file")
    with _quiet_native_output():
        mesh = o3d.io.read_triangle_mesh(path)
    if len(mesh.vertices) == 0:
        raise CLIError(f"{what} {path!r} could not be read as a triangle mesh (empty, corrupt or unsupported format)")
    if len(mesh.triangles) == 0:
        raise CLIError(f"{what} {path!r} has {len(mesh.vertices)} vertices but no triangles")
    if Path(path).suffix.lower() == ".stl":
        mesh = mesh.remove_duplicated_vertices()
    return mesh


def _same_file(a: str, b: str) -> bool:
    try:
        return os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b)
    except OSError:
        return False


def check_output(path: str, inputs: Sequence[str], *, force: bool, suffixes: Sequence[str] | None = WRITABLE) -> None:
    """Refuse, before any work, an output that would overwrite an input or cannot be written."""
    for source in inputs:
        if _same_file(path, source) and not force:
            raise CLIError(f"OUTPUT {path!r} is the input file {source!r}; refusing to overwrite it (use --force)")
    if suffixes is not None and Path(path).suffix.lower() not in suffixes:
        raise CLIError(f"OUTPUT {path!r} must end in one of {', '.join(suffixes)}")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise CLIError(f"OUTPUT folder {folder!r} does not exist")


def write_output(path: str, mesh: Any) -> None:
    o3d = _o3d()
    if Path(path).suffix.lower() == ".stl":
        # Open3D's STL writer needs triangle normals and refuses without them.
        mesh = o3d.geometry.TriangleMesh(mesh)
        mesh.compute_triangle_normals()
    with _quiet_native_output():
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
            raise CLIError(f"--unknown file {spec!r} must hold integer vertex indices, got dtype {values.dtype}")
        return values.astype(np.int64)
    parts = []
    for item in spec.split(","):
        item = item.strip()
        try:
            if ":" in item:
                start, stop = item.split(":")
                start, stop = int(start) if start else 0, int(stop) if stop else n
                if start < 0 or stop < start:
                    raise ValueError
                parts.append(np.arange(start, stop, dtype=np.int64))
            elif item:
                parts.append(np.array([int(item)], dtype=np.int64))
        except ValueError:
            raise CLIError(
                f"--unknown must be an existing index file or a list like '0:100,250', got {spec!r}"
            ) from None
    if not parts:
        raise CLIError(f"--unknown must name at least one vertex, got {spec!r}")
    return np.concatenate(parts)


def _volume(mesh: Any) -> float:
    from .metrics import signed_volume

    return signed_volume(mesh)


def _change_report(before: Any, after: Any) -> dict:
    from .metrics import normal_deviation, vertex_error

    moved = vertex_error(after, before)
    v0, v1 = _volume(before), _volume(after)
    return {
        "displacement_mean": moved["mean"],
        "displacement_max": moved["linf"],
        "volume_change_percent": 100.0 * (v1 - v0) / v0 if v0 != 0 else None,
        "normal_change_deg": normal_deviation(after, before),
    }


def _mesh_size(mesh: Any) -> dict:
    return {"vertices": len(mesh.vertices), "triangles": len(mesh.triangles)}


# --------------------------------------------------------------------------- subcommands


def cmd_denoise(args: argparse.Namespace, run: _Run) -> int:
    check_output(args.output, [args.input], force=args.force)
    if args.render:
        check_output(args.render, [args.input], force=args.force, suffixes=(".png",))
    mesh = read_input(args.input)
    if args.iterations is None:
        args.iterations = 5 if args.level else 10
    start = time.perf_counter()
    if args.level:
        from .fairing.multiresolution import multiresolution_fairing

        out = run.call(multiresolution_fairing, mesh, args.level, number_of_iterations=args.iterations,
                       method=args.method, desc="multiresolution fairing")
    else:
        from .fairing import constrained_fairing

        out = run.call(constrained_fairing, mesh, args.iterations, method=args.method, mu=args.mu,
                       smooth_boundary=not args.fixed_boundary, reimpose_every=args.reimpose_every,
                       desc="constrained fairing")
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    report = {"command": "denoise", "input": args.input, "output": args.output, **_mesh_size(mesh),
              "method": args.method, "iterations": args.iterations, "level": args.level, "seconds": seconds,
              **_change_report(mesh, out)}
    run.say(f"denoised {args.input} ({report['vertices']} vertices) in {seconds:.2f} s -> {args.output}; "
            f"mean displacement {report['displacement_mean']:.4g}, volume change {report['volume_change_percent']:.3f}%")
    if args.render:
        report["render"] = _render([mesh, out], args.render, run)
    return run.finish(report)


def _render(meshes: list, path: str, run: _Run) -> str:
    from .rendering import render

    start = time.perf_counter()
    run.call(render, meshes, path, desc="rendering")
    run.say(f"picture ({time.perf_counter() - start:.1f} s): {path}  (left: input, right: result)")
    return path


def cmd_approximate(args: argparse.Namespace, run: _Run) -> int:
    check_output(args.output, [args.input], force=args.force)
    if args.indices:
        check_output(args.indices, [args.input], force=args.force, suffixes=(".npy", ".txt"))
    mesh = read_input(args.input)
    from .metrics import vertex_error
    from .selection import approximate

    start = time.perf_counter()
    out, indices = run.call(approximate, mesh, args.count, method=args.method, interpolate=args.interpolate,
                            seed=args.seed, desc="approximate")
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    if args.indices:
        if args.indices.endswith(".npy"):
            np.save(args.indices, np.asarray(indices, dtype=np.int64))
        else:
            np.savetxt(args.indices, np.asarray(indices, dtype=np.int64), fmt="%d")
    error = vertex_error(out, mesh)
    report = {"command": "approximate", "input": args.input, "output": args.output, **_mesh_size(mesh),
              "count": int(len(indices)), "method": args.method, "seconds": seconds,
              "error_linf": error["linf"], "error_rms": error["rms"]}
    run.say(f"approximated {args.input} from {report['count']} control points in {seconds:.2f} s -> {args.output}; "
            f"L-inf error {error['linf']:.4g}, RMS {error['rms']:.4g}")
    return run.finish(report)


def cmd_reconstruct(args: argparse.Namespace, run: _Run) -> int:
    check_output(args.output, [args.input], force=args.force)
    mesh = read_input(args.input)
    unknown = parse_index_spec(args.unknown, len(mesh.vertices))
    from .lsmesh import reconstruct_geometry

    start = time.perf_counter()
    out = run.call(reconstruct_geometry, mesh, unknown, interpolate=not args.soft, desc="reconstruct")
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    unknown_unique = np.unique(unknown)
    moved = np.linalg.norm(np.asarray(out.vertices)[unknown_unique] - np.asarray(mesh.vertices)[unknown_unique], axis=1)
    report = {"command": "reconstruct", "input": args.input, "output": args.output, **_mesh_size(mesh),
              "unknown": int(len(unknown_unique)), "seconds": seconds,
              "distance_to_input_mean": float(moved.mean()), "distance_to_input_max": float(moved.max())}
    run.say(f"reconstructed {report['unknown']} vertices of {args.input} in {seconds:.2f} s -> {args.output}; "
            f"mean distance to the file's positions {report['distance_to_input_mean']:.4g}")
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
    hierarchy = run.call(build_hierarchy, mesh, min_vertices=args.min_vertices, max_levels=args.max_levels,
                         desc="hierarchy")
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
    report = {"command": "hierarchy", "input": args.input, "outdir": str(outdir), **_mesh_size(mesh),
              "levels": len(hierarchy), "vertex_counts": [int(hierarchy.vertex_count(i)) for i in range(len(hierarchy))],
              "written": files, "seconds": seconds}
    run.say(f"hierarchy of {args.input}: {len(hierarchy)} levels ({report['vertex_counts'][0]} -> "
            f"{report['vertex_counts'][-1]} vertices) in {seconds:.2f} s; wrote {len(files)} files to {outdir}/")
    return run.finish(report)


def cmd_encode(args: argparse.Namespace, run: _Run) -> int:
    check_output(args.output, [args.input], force=args.force, suffixes=None)
    mesh = read_input(args.input)
    n = len(mesh.vertices)
    count = args.count if args.count is not None else max(1, int(np.ceil(0.02 * n)))
    from .encoding import decode_geometry, encode_geometry
    from .metrics import vertex_error

    start = time.perf_counter()
    data = run.call(encode_geometry, mesh, count, bits=args.bits, method=args.method, desc="encode")
    seconds = time.perf_counter() - start
    Path(args.output).write_bytes(data)
    error = vertex_error(decode_geometry(mesh, data), mesh)
    report = {"command": "encode", "input": args.input, "output": args.output, **_mesh_size(mesh),
              "anchors": count, "bits": args.bits, "bytes": len(data), "bits_per_vertex": 8.0 * len(data) / n,
              "seconds": seconds, "decoded_error_linf": error["linf"], "decoded_error_rms": error["rms"]}
    run.say(f"encoded {args.input}: {count} anchors at {args.bits} bits -> {len(data)} bytes "
            f"({report['bits_per_vertex']:.3f} bits/vertex) in {seconds:.2f} s; decoded L-inf error {error['linf']:.4g}")
    return run.finish(report)


def cmd_decode(args: argparse.Namespace, run: _Run) -> int:
    check_output(args.output, [args.mesh, args.data], force=args.force)
    mesh = read_input(args.mesh, what="MESH")
    if not os.path.exists(args.data):
        raise CLIError(f"DATA {args.data!r} does not exist")
    data = Path(args.data).read_bytes()
    from .encoding import decode_geometry

    start = time.perf_counter()
    out = run.call(decode_geometry, mesh, data, anchors=args.anchors, desc="decode")
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    report = {"command": "decode", "mesh": args.mesh, "data": args.data, "output": args.output, **_mesh_size(mesh),
              "anchors": args.anchors, "seconds": seconds}
    run.say(f"decoded {args.data} on the connectivity of {args.mesh} in {seconds:.2f} s -> {args.output}")
    return run.finish(report)


def cmd_compare(args: argparse.Namespace, run: _Run) -> int:
    a, b = read_input(args.a, what="A"), read_input(args.b, what="B")
    from .metrics import normal_deviation, surface_distance, topology_summary, triangle_angles, vertex_error

    report: dict = {"command": "compare", "a": args.a, "b": args.b, "size_a": _mesh_size(a), "size_b": _mesh_size(b)}
    report["surface_distance"] = run.call(surface_distance, a, b, number_of_points=args.points, desc="surface distance")
    if len(a.vertices) == len(b.vertices):
        report["vertex_error"] = vertex_error(a, b)
        if np.array_equal(np.asarray(a.triangles), np.asarray(b.triangles)):
            report["normal_deviation_deg"] = normal_deviation(a, b)
    va, vb = _volume(a), _volume(b)
    report["volume_a"], report["volume_b"] = va, vb
    report["volume_change_percent"] = 100.0 * (vb - va) / va if va != 0 else None
    report["angles_a"], report["angles_b"] = triangle_angles(a), triangle_angles(b)
    report["topology_a"], report["topology_b"] = topology_summary(a), topology_summary(b)
    if not run.quiet and not run.json:
        sd = report["surface_distance"]
        lines = [f"A {args.a}: {report['size_a']['vertices']} vertices, B {args.b}: {report['size_b']['vertices']} vertices",
                 f"surface distance: Hausdorff {sd['hausdorff']:.6g}, mean {sd['mean']:.6g}, RMS {sd['rms']:.6g}"]
        if "vertex_error" in report:
            ve = report["vertex_error"]
            lines.append(f"vertex error: L-inf {ve['linf']:.6g}, RMS {ve['rms']:.6g}, mean {ve['mean']:.6g}")
        if "normal_deviation_deg" in report:
            lines.append(f"face normal deviation: {report['normal_deviation_deg']:.4f} degrees")
        change = report["volume_change_percent"]
        lines.append(f"volume: A {va:.6g}, B {vb:.6g}" + (f" ({change:+.4f}%)" if change is not None else ""))
        for key in ("a", "b"):
            angles, topo = report[f"angles_{key}"], report[f"topology_{key}"]
            lines.append(f"{key.upper()}: min angle {angles['min_angle']:.2f} deg, {100 * angles['share_under_10']:.2f}% "
                         f"under 10 deg, components {topo['components']}, boundary loops {topo['boundary_loops']}, "
                         f"genus {topo['genus']}, edge-manifold {topo['edge_manifold']}")
        for line in lines:
            run.say(line)
    return run.finish(report)


def cmd_demo(args: argparse.Namespace, run: _Run) -> int:
    from .demo import run_demo

    result = run_demo(args.out, subdivisions=args.subdivisions, noise=args.noise, seed=args.seed,
                      render=not args.no_render, quiet=run.quiet, progress=run.progress,
                      stream=sys.stderr if run.json else sys.stdout)
    return run.finish({"command": "demo", **result})


def cmd_fill(args: argparse.Namespace, run: _Run) -> int:
    check_output(args.output, [args.input], force=args.force)
    mesh = read_input(args.input)
    from .hole_filling import fill_holes, find_holes

    vertices, triangles = np.asarray(mesh.vertices), np.asarray(mesh.triangles).astype(np.int64)
    before = find_holes(vertices, triangles)
    start = time.perf_counter()
    try:
        out = run.call(fill_holes, mesh, max_hole_edges=args.max_hole_edges, max_hole_diameter=args.max_hole_diameter,
                       continuity=args.continuity, density=args.density, fill_border=args.fill_border, desc="fill")
    except (TypeError, ValueError) as error:  # name the flag, not the keyword
        text = str(error)
        for keyword in ("max_hole_edges", "max_hole_diameter", "continuity", "density"):
            text = text.replace(keyword, "--" + keyword.replace("_", "-"))
        raise CLIError(text) from None
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    after = find_holes(np.asarray(out.vertices), np.asarray(out.triangles).astype(np.int64))
    report = {"command": "fill", "input": args.input, "output": args.output, **_mesh_size(mesh),
              "holes_before": len(before), "holes_after": len(after),
              "borders_left_open": sum(hole.border for hole in before) if not args.fill_border else 0,
              "new_vertices": len(out.vertices) - len(mesh.vertices),
              "new_triangles": len(out.triangles) - len(mesh.triangles), "seconds": seconds}
    run.say(f"filled {len(before) - len(after)} of {len(before)} holes of {args.input} in {seconds:.2f} s "
            f"({report['new_vertices']} new vertices) -> {args.output}; {len(after)} loops left open")
    return run.finish(report)


# --------------------------------------------------------------------------- parser


def _int_at_least(minimum: int, description: str):
    """An argparse type for integers ``>= minimum`` with a one-line error naming the rule."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum:
            raise argparse.ArgumentTypeError(f"must be a {description} integer, got {text!r}")
        return value

    return parse


_positive_int = _int_at_least(1, "positive")
_nonnegative_int = _int_at_least(0, "non-negative")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Least-squares meshes and constrained fairing for Open3D meshes.")
    from . import __version__

    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--quiet", action="store_true", help="no progress bars and no report")
    common.add_argument("--json", action="store_true", help="print the metrics as one JSON object on stdout")
    common.add_argument("--force", action="store_true", help="allow overwriting an input file")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser("denoise", parents=[common], help="barycenter-constrained (or multiresolution) fairing",
                       description="Remove noise with barycenter-constrained fairing (Liu et al. 2001).")
    p.add_argument("input", metavar="INPUT")
    p.add_argument("output", metavar="OUTPUT")
    p.add_argument("--iterations", type=_nonnegative_int, default=None,
                   help="number_of_iterations (default 10; with --level, 5 per level)")
    p.add_argument("--method", choices=("local", "global"), default="local")
    p.add_argument("--level", type=_nonnegative_int, default=0, help="multiresolution level (0: plain fairing)")
    p.add_argument("--mu", type=float, default=None, help="penalty weight of --method global")
    p.add_argument("--reimpose-every", type=_positive_int, default=None, help="re-take the barycenters every k iterations")
    p.add_argument("--fixed-boundary", action="store_true", help="keep boundary vertices fixed")
    p.add_argument("--render", metavar="PNG", default=None, help="write a before/after picture")
    p.set_defaults(handler=cmd_denoise)

    p = sub.add_parser("approximate", parents=[common], help="LS-mesh approximation from N control points")
    p.add_argument("input", metavar="INPUT")
    p.add_argument("output", metavar="OUTPUT")
    p.add_argument("--count", type=_positive_int, required=True)
    p.add_argument("--method", choices=("greedy", "random", "combined"), default="greedy")
    p.add_argument("--interpolate", action="store_true", help="interpolate the control points exactly")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--indices", metavar="FILE", default=None, help="also write the control indices (.npy or .txt)")
    p.set_defaults(handler=cmd_approximate)

    p = sub.add_parser("reconstruct", parents=[common], help="rebuild the geometry of unknown vertices")
    p.add_argument("input", metavar="INPUT")
    p.add_argument("output", metavar="OUTPUT")
    p.add_argument("--unknown", required=True, metavar="SPEC",
                   help="index file (.npy or text) or list of indices and a:b ranges, e.g. '0:100,250'")
    p.add_argument("--soft", action="store_true", help="known vertices as soft constraints (whole mesh re-solved)")
    p.set_defaults(handler=cmd_reconstruct)

    p = sub.add_parser("hierarchy", parents=[common], help="write levels of the volume-cost collapse hierarchy")
    p.add_argument("input", metavar="INPUT")
    p.add_argument("outdir", metavar="OUTDIR")
    p.add_argument("--levels", default="all", help="'all' or comma-separated level numbers (0 is the input)")
    p.add_argument("--min-vertices", type=_positive_int, default=100)
    p.add_argument("--max-levels", type=_positive_int, default=None)
    p.add_argument("--format", default="ply", help="file format of the levels (ply, obj, stl, off, gltf)")
    p.add_argument("--maps", action="store_true", help="also write vertex_maps.npz (input vertex -> level vertex)")
    p.set_defaults(handler=cmd_hierarchy)

    p = sub.add_parser("encode", parents=[common], help="encode the geometry as quantized LS-mesh anchors")
    p.add_argument("input", metavar="INPUT")
    p.add_argument("output", metavar="OUTPUT")
    p.add_argument("--count", type=_positive_int, default=None, help="anchors (default 2%% of the vertices)")
    p.add_argument("--bits", type=_positive_int, default=12)
    p.add_argument("--method", choices=("greedy", "random", "combined"), default="greedy")
    p.set_defaults(handler=cmd_encode)

    p = sub.add_parser("decode", parents=[common], help="decode geometry onto a mesh's connectivity")
    p.add_argument("mesh", metavar="MESH")
    p.add_argument("data", metavar="DATA")
    p.add_argument("output", metavar="OUTPUT")
    p.add_argument("--anchors", type=_positive_int, default=None, help="use only the first K anchors")
    p.set_defaults(handler=cmd_decode)

    p = sub.add_parser("compare", parents=[common], help="metrics between two meshes")
    p.add_argument("a", metavar="A")
    p.add_argument("b", metavar="B")
    p.add_argument("--points", type=_positive_int, default=100_000, help="surface samples per mesh")
    p.set_defaults(handler=cmd_compare)

    p = sub.add_parser("demo", parents=[common], help="denoise a built-in mesh and compare with Open3D's filters")
    p.add_argument("--out", default="demo_out", help="output folder (default demo_out)")
    p.add_argument("--no-render", action="store_true", help="skip the picture")
    p.add_argument("--subdivisions", type=_positive_int, default=6, help="size of the built-in mesh (6: 40,962 vertices)")
    p.add_argument("--noise", type=float, default=0.3, help="noise sigma in mean edge lengths")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(handler=cmd_demo)

    p = sub.add_parser("fill", parents=[common], help="fill holes with faired patches (LS meshes)",
                       description="Close holes: minimum-weight triangulation, refinement, LS-mesh fairing. "
                                   "Each open component's outer border stays open unless --fill-border.")
    p.add_argument("input", metavar="INPUT")
    p.add_argument("output", metavar="OUTPUT")
    p.add_argument("--max-hole-edges", type=_int_at_least(3, ">= 3"), default=None, help="fill only holes this small")
    p.add_argument("--max-hole-diameter", type=float, default=None, help="fill only holes this narrow (mesh units)")
    p.add_argument("--continuity", type=int, choices=(0, 1, 2), default=2, help="0 harmonic, 1 LS mesh, 2 tri-Laplacian")
    p.add_argument("--density", type=float, default=1.0, help="new vertex density relative to the surroundings")
    p.add_argument("--fill-border", action="store_true", help="also fill outer borders")
    p.set_defaults(handler=cmd_fill)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``o3d-lsmesh`` with ``argv`` (default ``sys.argv[1:]``); return the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        return args.handler(args, _Run(args))
    except CLIError as error:
        text = str(error)
        print(text if text.startswith(PROG) else f"{PROG}: error: {text}", file=sys.stderr)
        return 2
    except (ValueError, TypeError) as error:
        # The library's messages name the parameter, what was expected and what came.
        print(f"{PROG}: error: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        print(f"{PROG}: error: {error.strerror or error}: {error.filename or ''}".rstrip(": "), file=sys.stderr)
        return 2
    except RuntimeError as error:
        print(f"{PROG}: error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
