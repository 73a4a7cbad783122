"""The ``o3d-lsmesh`` subcommands: those of the operations (denoise, fill, approximate, hierarchy,
encode: their flags come from the option tables of :mod:`o3d_lsmesh.app.ops`) and those with a flow of
their own (reconstruct, decode, compare, batch, demo). Each checks its files, runs and reports with the
kit of :mod:`o3d_lsmesh.app.cli_kit`. Docs: ``docs/cli.rst``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
import warnings
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from .._o3d import read_mesh
from ..core.errors import O3DLSMeshWarning
from ..core.validate import as_indices
from ..holes import find_holes
from ..lsmesh import reconstruct_geometry
from ..lsmesh.encoding import decode_geometry
from .batch import run as run_batch
from .batch import summarize
from .cli_kit import Run, draw, run_file_op, run_op, shape_change_text
from .demo import run_demo
from .files import CLIError, check_output, read_input, write_output
from .metrics import (
    corresponding,
    normal_change,
    shape_change,
    surface_distance,
    topology_summary,
    triangle_angles,
    vertex_error,
)
from .ops import RUN_FLAGS

__all__ = ["parse_index_spec"]


def denoise(args: argparse.Namespace, run: Run) -> int:
    """Barycenter-constrained (or multiresolution) fairing.

    Remove noise with barycenter-constrained fairing (Liu et al. 2001, section 3): the membrane
    energy is minimized while every triangle keeps its barycenter. With --level L, multiresolution
    fairing (section 4.2): fair a coarse level of the volume-cost hierarchy, then split back up
    (--mu, --reimpose-every and --fixed-boundary are refused with it).

    example: scan.ply smooth.ply --iterations 20 --render before_after.png
    """
    mesh, out, report, seconds = run_file_op("denoise", args, run, (args.render, (".png",), "--render"))
    report["seconds"] = seconds
    how = f"{report['method']} fairing"
    if args.level:
        how = f"multiresolution fairing (level {args.level}, {how} per level)"
    run.say(
        f"denoised {args.input} ({len(mesh.vertices)} vertices) by {how} in {seconds:.2f} s "
        f"-> {args.output}; mean displacement {report['displacement_mean']:.4g}, {shape_change_text(report)}"
    )
    if args.render:
        method, iterations = report["method"], report["iterations"]  # what ran
        title = f"{method} fairing" + (f", mu {args.mu:g}" if args.mu is not None else "")
        if args.level:
            title = f"multiresolution fairing, level {args.level}, {iterations} iterations per level"
        elif method not in ("scan", "features"):  # one solve / a measured pass count: no iteration count
            title += f", {iterations} iteration{'s' if iterations != 1 else ''}"
        report["render"] = draw(
            [mesh, out], args.render, run, titles=[f"input: {Path(args.input).name}", title]
        )
    return run.finish(mesh, **report)


def fill(args: argparse.Namespace, run: Run) -> int:
    """Fill holes with faired patches (LS meshes).

    Close holes: minimum-weight triangulation (Liepa 2003), refinement to the surrounding edge
    density, then LS-mesh fairing of the new vertices with the hole's rings as anchors. Each open
    component's outer border stays open unless --fill-border. --max-hole-diameter is in model units.
    Every loop left open is listed with why (outer border, size limits, every fill crossing the mesh).

    example: scan.ply filled.ply --max-hole-edges 200
    """

    def holes(mesh: Any) -> list:  # of the welded surface, as fill_holes sees it: a UV seam is no hole
        welded = read_mesh(mesh, weld=True)
        return find_holes(welded.vertices, welded.triangles)

    mesh, out, metrics, seconds = run_file_op("fill", args, run)
    before, after, report = holes(mesh), holes(out), metrics["_report"]
    run.say(
        f"filled {len(report.filled)} of {len(report.holes)} holes of {args.input} in {seconds:.2f} s "
        f"({metrics['new_vertices']} new vertices) -> {args.output}; {len(after)} loops left open"
    )
    for hole in report.skipped:  # every loop left open, and why
        run.say(f"  left open: loop {hole.id} ({hole.edges} edges, diameter {hole.diameter:.4g}): {hole.how}")
    return run.finish(
        mesh,
        holes_before=len(before),
        holes_after=len(after),
        borders_left_open=sum(before[hole.id].border for hole in report.skipped),  # (report ids: before's)
        new_vertices=metrics["new_vertices"],
        new_triangles=metrics["new_triangles"],
        holes_filled=len(report.filled),
        skipped=[dataclasses.asdict(hole) for hole in report.skipped],
        seconds=seconds,
    )


def approximate(args: argparse.Namespace, run: Run) -> int:
    """LS-mesh approximation from N control points.

    Rebuild the geometry from the connectivity and N control points chosen on the mesh
    (least-squares meshes, Sorkine and Cohen-Or 2004).

    example: bunny.ply approx.ply --count 400 --indices controls.npy
    """
    mesh, _, metrics, seconds = run_file_op(
        "approximate", args, run, (args.indices, (".npy", ".txt"), "--indices")
    )
    indices = metrics.pop("_indices")
    if args.indices and args.indices.lower().endswith(".npy"):
        with open(args.indices, "wb") as handle:  # (np.save adds ".npy" to a name ending ".NPY")
            np.save(handle, indices)
    elif args.indices:
        np.savetxt(args.indices, indices, fmt="%d")
    run.say(
        f"approximated {args.input} from {len(indices)} control points in {seconds:.2f} s -> {args.output}; "
        f"L-inf error {metrics['error_linf']:.4g}, RMS {metrics['error_rms']:.4g}"
    )
    return run.finish(mesh, **metrics, seconds=seconds)


#: Open3D's readers of these formats number the vertices as the faces first use them, not as the file does
_RENUMBERED = {".obj": "an OBJ", ".gltf": "a glTF", ".glb": "a glTF"}


def hierarchy(args: argparse.Namespace, run: Run) -> int:
    """Write levels of the volume-cost collapse hierarchy.

    Build the volume-cost edge-collapse hierarchy (Liu et al. 2001, section 4.1) and write the
    chosen levels as mesh files, level_00 being the input.

    example: bunny.ply levels/ --levels 0,2,4 --maps
    """
    mesh = read_input(args.input)
    outdir = Path(args.outdir)
    if outdir.exists() and not outdir.is_dir():
        raise CLIError(f"OUTDIR {args.outdir!r} exists and is not a folder")
    if args.maps and args.format.lower() in _RENUMBERED:
        warnings.warn(
            f"--maps numbers each level's vertices as {args.format} files list them, and Open3D reads "
            f"{_RENUMBERED[args.format.lower()]} in another order (as its faces first use them): read the "
            "levels with another reader, or write them as .ply",
            O3DLSMeshWarning,
            stacklevel=2,
        )
    built, metrics, seconds = run_op("hierarchy", mesh, args, run)
    outdir.mkdir(parents=True, exist_ok=True)
    written: list[str] = []
    for name, item in built.items():
        path = str(outdir / (name if isinstance(item, bytes) else name + args.format))
        if isinstance(item, bytes):
            Path(path).write_bytes(item)
        else:
            check_output(path, [args.input], force=args.force, suffixes=None)
            write_output(path, item)
        written.append(path)
    counts = metrics["vertex_counts"]
    run.say(
        f"hierarchy of {args.input}: {len(counts)} levels ({counts[0]} -> {counts[-1]} vertices) "
        f"in {seconds:.2f} s; wrote {len(written)} files to {outdir}/"
    )
    return run.finish(mesh, levels=len(counts), vertex_counts=counts, written=written, seconds=seconds)


def encode(args: argparse.Namespace, run: Run) -> int:
    """Encode the geometry as quantized LS-mesh anchors.

    Store the geometry as the quantized positions of a few anchors; decode rebuilds it from the
    connectivity (geometry-aware bases, Sorkine et al.).

    example: bunny.ply bunny.lsm --count 500 --bits 12
    """
    mesh, data, metrics, seconds = run_file_op("encode", args, run)
    run.say(
        f"encoded {args.input}: {metrics['anchors']} anchors at {args.bits} bits -> {len(data)} bytes "
        f"({metrics['bits_per_vertex']:.3f} bits/vertex) in {seconds:.2f} s; "
        f"decoded L-inf error {metrics['decoded_error_linf']:.4g}"
    )
    return run.finish(mesh, **metrics, seconds=seconds)


def parse_index_spec(spec: str, n: int) -> np.ndarray:
    """Vertex indices from a file (``.npy``, or integers separated by spaces, commas or newlines) or a
    list like ``0:100,250,300:310`` (``a:b`` half-open; the union of the items).

    >>> parse_index_spec("0:3,5,2", 10)
    array([0, 1, 2, 5])
    """
    if os.path.exists(spec):
        try:
            if spec.lower().endswith(".npy"):
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
            message = f"--unknown must be an existing index file or a list like '0:100,250', got {spec!r}"
            raise CLIError(message) from None
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
    renumbered = _RENUMBERED.get(Path(args.input).suffix.lower())
    if renumbered:
        # Open3D's OBJ and glTF readers number the vertices as the faces first use them, not as the file does
        warnings.warn(
            f"INPUT {args.input!r}: --unknown counts the vertices of {renumbered} as Open3D reads them (in the "
            "order the faces first use them, not the file's); the output lists them so too",
            O3DLSMeshWarning,
            stacklevel=2,
        )
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
    if args.units != "model" and not args.render:  # (the metrics are in model units)
        raise CLIError(f"--units {args.units} applies to the distance map of --render, which was not given")
    if args.render:
        check_output(args.render, [args.a, args.b], force=args.force, suffixes=(".png",), what="--render")
    a, b = read_input(args.a, what="A"), read_input(args.b, what="B")
    report: dict[str, Any] = {"a": args.a, "b": args.b}
    for key, mesh in (("size_a", a), ("size_b", b)):
        report[key] = {"vertices": len(mesh.vertices), "triangles": len(mesh.triangles)}
    report["surface_distance"] = surface_distance(a, b, number_of_points=args.points)
    if corresponding(a, b):
        report["vertex_error"] = vertex_error(a, b)
        report["normal_deviation_deg"] = normal_change(a, b)
    report["shape_change"] = shape_change(a, b)
    report["angles_a"], report["angles_b"] = triangle_angles(a), triangle_angles(b)
    report["topology_a"], report["topology_b"] = topology_summary(a), topology_summary(b)
    if not run.json:
        run.say("\n".join(_lines(report)))
    if args.render:
        units = "mean edge lengths of A" if args.units == "edge" else "model units"
        titles = [f"A: {Path(args.a).name} (reference)", f"B: {Path(args.b).name}"]
        kw = dict(reference=a, units=args.units, titles=titles, colorbar_title="distance to A")
        report["render"] = draw(
            [a, b], args.render, run, what=f"B colored by distance to A, in {units}", **kw
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
    run.say(f"{summarize(records, seconds)}\nreport: {report}")
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
    scan = {name: getattr(args, name) for name in ("resolution", "noise", "seed")}
    result = run_demo(args.out, **scan, render=not args.no_render, say=run.say, progress=run.progress)
    return run.finish(**result)
