"""The parsers of every ``o3d-lsmesh`` subcommand and the commands with a flow of their own
(reconstruct, decode, compare, batch with every op's options, demo); the operations' commands are in
:mod:`o3d_lsmesh.app.op_commands`, what all use in :mod:`o3d_lsmesh.app.cli_kit`. Docs: ``docs/cli.rst``.
"""

from __future__ import annotations

import argparse
import os
import textwrap
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from ..core.validate import as_indices
from ..lsmesh import reconstruct_geometry
from ..lsmesh.encoding import decode_geometry
from .batch import run as run_batch
from .batch import summarize
from .cli_kit import Run, add_command, add_option, draw, shape_change_text
from .demo import run_demo
from .files import WRITABLE, CLIError, check_output, mesh_suffix, read_input, write_output
from .metrics import shape_change, surface_distance, topology_summary, triangle_angles, vertex_error
from .op_commands import approximate, denoise, encode, fill, hierarchy
from .ops import OPS, RUN_FLAGS, Option, choice, flag, int_at_least, non_negative, normal_change

__all__ = ["add_parsers", "parse_index_spec"]

#: the demo scan has up to about 0.55 * resolution**2 vertices: 2000 gives about 2.2 million
MAX_RESOLUTION = 2000
_FILES = {"input": "mesh file", "output": "mesh file to write"}
#: the demo's flags
DEMO = (
    Option("out", str, "demo_out", "output folder"),
    Option("no_render", flag, False, "skip the picture", is_flag=True),
    Option(
        "resolution",
        int_at_least(20, MAX_RESOLUTION, "a grid size of at least 20 rays"),
        200,
        "the scanner's grid of R x R rays (200: about 22,000 vertices)",
    ),
    Option("noise", non_negative, 0.3, "range noise in grid spacings where the surface faces the scanner"),
    Option("seed", int, 0, "random seed of the noise and dropouts"),
)


def add_parsers(sub: Any, writing: argparse.ArgumentParser, common: argparse.ArgumentParser) -> None:
    """Add every subcommand; ``writing`` adds ``--force`` to ``common`` (not for the demo: it reads no file)."""
    files = {"input": "mesh file to denoise", "output": f"mesh file to write ({', '.join(WRITABLE)})"}
    picture = Option("render", str, help="write a before/after picture (default: none)", metavar="PNG")
    add_command(sub, writing, denoise, files, picture)
    add_command(sub, writing, fill, _FILES)
    help = "also write the control indices, .npy or .txt (default: not written)"
    add_command(sub, writing, approximate, _FILES, Option("indices", str, help=help, metavar="FILE"))
    help = "index file (.npy or text) or list of indices and a:b ranges, e.g. '0:100,250'"
    unknown = Option("unknown", str, help=help, param="unknown_vertex_indices", required=True, metavar="SPEC")
    help = "known vertices as soft constraints (whole mesh re-solved)"
    add_command(sub, writing, reconstruct, _FILES, unknown, Option("soft", flag, False, help, is_flag=True))
    add_command(sub, writing, encode, {"input": "mesh file", "output": "file for the encoded bytes"})
    names = {"mesh": "mesh file the data was encoded on", "data": "file written by encode"}
    anchors = Option("anchors", int_at_least(1), help="use only the first K anchors (default: all)")
    add_command(sub, writing, decode, names | {"output": _FILES["output"]}, anchors)
    names = {"input": "mesh file", "outdir": "folder for level_NN files (created if needed)"}
    help = "file format of the levels (.ply .obj ...)"
    add_command(sub, writing, hierarchy, names, Option("format", mesh_suffix, ".ply", help))
    names = {"a": "first mesh file (the reference)", "b": "second mesh file"}
    help = "write a distance map: A and B side by side, colored by distance to A (default: none)"
    units = Option("units", choice("model", "edge"), "model", "model units or mean edge lengths of A")
    add_command(sub, writing, compare, names, Option("render", str, help=help, metavar="PNG"), units)
    _add_batch(add_command(sub, writing, batch, {}))
    add_command(sub, common, demo, {}, *DEMO)


def _add_batch(p: argparse.ArgumentParser) -> None:
    """``batch``: its own flags (:func:`~o3d_lsmesh.app.batch.run`'s parameters) and every op's options."""
    p.add_argument(
        "inputs", nargs="+", metavar="INPUT", help="files, folders (searched recursively) or globs"
    )
    p.add_argument("outdir", metavar="OUTDIR", help="folder for the outputs and the report")
    operations = ", ".join(f"{name} ({op.help})" for name, op in OPS.items())
    p.description = f"{p.description}\n\n" + textwrap.fill(f"Operations: {operations}.", 79)
    help = "an operation or a pipeline in order, e.g. denoise or denoise,compare"
    p.add_argument("--op", required=True, help=help)
    p.add_argument("--set", action="append", default=[], metavar="OP.NAME=VALUE", help="an option of one op")
    where = p.add_mutually_exclusive_group()
    for option in RUN_FLAGS:
        add_option(where if option.name.startswith("scheduler") else p, option)
    group = p.add_argument_group(
        "operation options (each applies to every op of the pipeline that has it; "
        "--set OP.NAME=VALUE for one op)"
    )
    owners: dict[str, list[tuple[str, Option]]] = {}
    for op in OPS.values():
        for option in op.options:
            owners.setdefault(option.name, []).append((op.name, option))
    for name, pairs in owners.items():
        option = pairs[0][1]
        helps = {o.help for _, o in pairs}
        text = (
            f"{option.help} [{', '.join(n for n, _ in pairs)}]"
            if len(helps) == 1
            else "; ".join(f"{n}: {o.help}" for n, o in pairs)
        )
        # SUPPRESS: an option not given is left to each op's default (and --help shows none); values are
        # parsed per op by batch.run, from the same table
        kwargs: dict[str, Any] = {"action": "store_true"} if option.is_flag else {"metavar": "VALUE"}
        text = text.replace("%", "%%").replace("(default:", "(op default:")
        group.add_argument(
            option.cli_flag, dest=f"opt_{name}", default=argparse.SUPPRESS, help=text, **kwargs
        )
    flags = {name: "--" + name.replace("_", "-") for name in [*owners, "op"]}
    flags |= {option.name: option.cli_flag for option in RUN_FLAGS}
    p.set_defaults(positionals=("inputs", "outdir"), flags=flags)


# --------------------------------------------------------------------------- commands with a flow of their own


def parse_index_spec(spec: str, n: int) -> np.ndarray:
    """Vertex indices from a file (``.npy``, or integers separated by spaces, commas or newlines) or a
    list like ``0:100,250,300:310`` (``a:b`` half-open; the union of the items).

    >>> parse_index_spec("0:3,5,2", 10)
    array([0, 1, 2, 5])
    """
    if os.path.exists(spec):
        try:
            if spec.endswith(".npy"):
                values = np.asarray(np.load(spec, allow_pickle=False)).ravel()
            else:
                values = np.array([int(t) for t in Path(spec).read_text().replace(",", " ").split()])
        except (ValueError, OSError) as error:
            raise CLIError(f"--unknown file {spec!r} must hold integer vertex indices ({error})") from None
        # (an InputError naming unknown_vertex_indices, which the command line spells --unknown)
        return np.unique(as_indices(values, n, name="unknown_vertex_indices", allow_repeats=True))
    parts = []
    for item in filter(None, (item.strip() for item in spec.split(","))):
        try:
            start_text, colon, stop_text = item.partition(":")
            start = int(start_text) if start_text or not colon else 0
            stop = (int(stop_text) if stop_text else n) if colon else start + 1
        except ValueError:
            raise CLIError(
                f"--unknown must be an existing index file or a list like '0:100,250', got {spec!r}"
            ) from None
        # checked before any array: '0:99999999999' must not allocate 800 GB
        if start < 0 or stop > n or stop < start:
            what = f"range {item!r}" if colon else f"index {item!r}"
            raise CLIError(
                f"--unknown must name vertices in 0..{n - 1} (the mesh has {n} vertices), got {what}"
            )
        parts.append(np.arange(start, stop, dtype=np.int64))
    if not parts:
        raise CLIError(f"--unknown must name at least one vertex, got {spec!r}")
    return np.unique(np.concatenate(parts))


def reconstruct(args: argparse.Namespace, run: Run) -> int:
    """Rebuild the geometry of unknown vertices.

    Replace the positions of the --unknown vertices by the least-squares mesh of the known ones
    (LS meshes, figures 5 and 8); known vertices stay as they are unless --soft.

    example: scan.ply filled.ply --unknown 0:100,250
    """
    check_output(args.output, [args.input], force=args.force)
    mesh = read_input(args.input)
    unknown = parse_index_spec(args.unknown, len(mesh.vertices))
    start = time.perf_counter()
    out = reconstruct_geometry(mesh, unknown, interpolate=not args.soft, progress=run.progress)
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    moved = np.linalg.norm(np.asarray(out.vertices)[unknown] - np.asarray(mesh.vertices)[unknown], axis=1)
    run.say(
        f"reconstructed {len(unknown)} vertices of {args.input} in {seconds:.2f} s -> {args.output}; "
        f"mean distance to the file's positions {moved.mean():.4g}"
    )
    return run.finish(
        mesh,
        unknown=len(unknown),
        seconds=seconds,
        distance_to_input_mean=float(moved.mean()),
        distance_to_input_max=float(moved.max()),
    )


def decode(args: argparse.Namespace, run: Run) -> int:
    """Decode geometry onto a mesh's connectivity.

    Rebuild the geometry stored by encode on the connectivity of MESH, from all its anchors or
    the first K (progressive decoding).

    example: bunny.ply bunny.lsm decoded.ply --anchors 200
    """
    check_output(args.output, [args.mesh, args.data], force=args.force)
    mesh = read_input(args.mesh, what="MESH")
    if not os.path.exists(args.data):
        raise CLIError(f"DATA {args.data!r} does not exist")
    start = time.perf_counter()
    out = decode_geometry(mesh, Path(args.data).read_bytes(), anchors=args.anchors, progress=run.progress)
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    run.say(f"decoded {args.data} on the connectivity of {args.mesh} in {seconds:.2f} s -> {args.output}")
    return run.finish(mesh, anchors=args.anchors, seconds=seconds)


def compare(args: argparse.Namespace, run: Run) -> int:
    """Metrics between two meshes.

    Surface distance (sampled, both ways), vertex error and normal deviation when the meshes
    correspond, the volume change (closed A) or the inward shift along A's
    normals (open A), triangle angles and topology of both; with --render, a distance map.

    example: clean.ply smooth.ply --json --render distance.png
    """
    if args.render:
        check_output(args.render, [args.a, args.b], force=args.force, suffixes=(".png",))
    a, b = read_input(args.a, what="A"), read_input(args.b, what="B")
    size = {
        key: {"vertices": len(m.vertices), "triangles": len(m.triangles)} for key, m in (("a", a), ("b", b))
    }
    report: dict[str, Any] = {"a": args.a, "b": args.b, "size_a": size["a"], "size_b": size["b"]}
    report["surface_distance"] = surface_distance(a, b, number_of_points=args.points)
    if len(a.vertices) == len(b.vertices):
        report["vertex_error"] = vertex_error(a, b)
        if np.array_equal(np.asarray(a.triangles), np.asarray(b.triangles)):
            report["normal_deviation_deg"] = normal_change(a, b)
    report["shape_change"] = shape_change(a, b)
    report["angles_a"], report["angles_b"] = triangle_angles(a), triangle_angles(b)
    report["topology_a"], report["topology_b"] = topology_summary(a), topology_summary(b)
    if not run.json:
        for line in _lines(report):
            run.say(line)
    if args.render:
        units = "mean edge lengths of A" if args.units == "edge" else "model units"
        report["render"] = draw(
            [a, b],
            args.render,
            run,
            reference=a,
            units=args.units,
            what=f"B colored by distance to A, in {units}",
            titles=[f"A: {Path(args.a).name} (reference)", f"B: {Path(args.b).name}"],
            colorbar_title="distance to A",
        )
    return run.finish(**report)


def _lines(report: dict[str, Any]) -> list[str]:
    """The human report of :func:`compare`."""
    sd, size_a, size_b = report["surface_distance"], report["size_a"], report["size_b"]
    lines = [
        f"A {report['a']}: {size_a['vertices']} vertices, B {report['b']}: {size_b['vertices']} vertices",
        f"surface distance: Hausdorff {sd['hausdorff']:.6g}, mean {sd['mean']:.6g}, RMS {sd['rms']:.6g}",
    ]
    if "vertex_error" in report:
        ve = report["vertex_error"]
        lines.append(f"vertex error: L-inf {ve['linf']:.6g}, RMS {ve['rms']:.6g}, mean {ve['mean']:.6g}")
    if report.get("normal_deviation_deg") is not None:
        lines.append(f"face normal deviation: {report['normal_deviation_deg']:.4f} degrees")
    change = report["shape_change"]
    volumes = f": A {change['volume_before']:.6g}, B {change['volume_after']:.6g}" if change["closed"] else ""
    lines.append(f"B against A: {shape_change_text(change)}{volumes}")
    for key in ("a", "b"):
        angles, topo = report[f"angles_{key}"], report[f"topology_{key}"]
        holes = ", ".join(f"{size}: {count}" for size, count in topo["holes_by_size"].items())
        lines += [
            f"{key.upper()}: min angle {angles['min_angle']:.2f} deg, {100 * angles['share_under_10']:.2f}% "
            f"under 10 deg, components {topo['components']}, boundary loops {topo['boundary_loops']}, "
            f"genus {topo['genus']}, edge-manifold {topo['edge_manifold']}",
            f"{key.upper()}: surface pieces {topo['surface_pieces']}, boundary edges {topo['boundary_edges']} "
            f"in {topo['boundary_components']} connected pieces, holes by edge count ({holes}), "
            f"non-manifold vertices {topo['nonmanifold_vertices']}, non-manifold edges "
            f"{topo['nonmanifold_edges']}, unreferenced vertices {topo['unreferenced_vertices']}, "
            f"degenerate triangles {topo['degenerate_triangles']}",
        ]
    return lines


def batch(args: argparse.Namespace, run: Run) -> int:
    """Run an operation over many files (Dask cluster or local).

    Run an operation, or a pipeline of them, over many mesh files, each as one task on a local Dask
    cluster (default), an existing one (--scheduler), or in this process without Dask: Open3D is
    imported once per worker, not once per file. Exit code 0 when every file succeeded, 2 when
    any failed (the report lists why).

    example: scans/ out/ --op fill,denoise --workers 2
    """
    options: dict[str, Any] = {k[4:]: v for k, v in vars(args).items() if k.startswith("opt_")}
    for item in args.set:
        name, equals, value = item.partition("=")
        if not equals or "." not in name:
            raise CLIError(f"--set must look like OP.NAME=VALUE, got {item!r}")
        options[name] = value
    report = args.report if args.report is not None else os.path.join(args.outdir, "batch_report.jsonl")
    start = time.perf_counter()
    try:
        records = run_batch(
            args.inputs,
            args.outdir,
            op=args.op,
            options=options,
            report=report,
            progress=run.progress,
            force=args.force,
            **{o.name: getattr(args, o.name) for o in RUN_FLAGS if o.name != "report"},
        )
    except ImportError as error:  # --scheduler without dask installed
        raise CLIError(str(error)) from None
    seconds = time.perf_counter() - start
    counts = Counter(record["status"] for record in records)
    run.say(summarize(records, seconds))
    run.say(f"report: {report}")
    failed = [r["input"] for r in records if r["status"] == "failed"]
    run.finish(op=args.op, report=report, seconds=seconds, counts=dict(counts), failed=failed)
    return 0 if counts["failed"] == 0 and counts["cancelled"] == 0 else 2


def demo(args: argparse.Namespace, run: Run) -> int:
    """Denoise a simulated raw range scan and compare with Open3D's filters.

    Scan a built-in blob from one view on a scanner's grid (noise along the rays, correlated along
    the scanlines and larger at grazing angles, a ragged silhouette, islands and dropout holes),
    denoise it with this package's defaults and with Open3D's filters, each of those at the best
    count of a small sweep, and print the distances to the true surface (and a picture).

    example: --out demo_out --resolution 150
    """
    result = run_demo(
        args.out,
        resolution=args.resolution,
        noise=args.noise,
        seed=args.seed,
        render=not args.no_render,
        quiet=run.quiet,
        progress=run.progress,
        stream=run.stream,
    )
    return run.finish(**result)
