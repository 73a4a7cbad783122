"""The subcommands of the operations run on one file (denoise, fill, approximate, hierarchy, encode):
their flags come from the option tables of :mod:`o3d_lsmesh.app.ops`; each handler checks its
files, runs its operation and reports. Docs: ``docs/cli.rst``.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from .._o3d import read_mesh
from ..fairing.constrained import resolved_options
from ..holes import find_holes
from .cli_kit import Run, draw, run_file_op, run_op, shape_change_text
from .files import CLIError, check_output, read_input, write_output
from .ops import level_conflicts


def denoise(args: argparse.Namespace, run: Run) -> int:
    """Barycenter-constrained (or multiresolution) fairing.

    Remove noise with barycenter-constrained fairing (Liu et al. 2001, section 3): the membrane
    energy is minimized while every triangle keeps its barycenter. With --level L, multiresolution
    fairing (section 4.2): fair a coarse level of the volume-cost hierarchy, then split back up
    (--mu, --reimpose-every and --fixed-boundary are refused with it).

    example: scan.ply smooth.ply --iterations 20 --render before_after.png
    """
    given = ["--" + name.replace("_", "-") for name in level_conflicts(vars(args))]
    if given:  # before the mesh is read (denoise_op refuses them too, for batch)
        raise CLIError(
            f"{', '.join(given)} cannot be combined with --level (multiresolution fairing does not take "
            f"{'them' if len(given) > 1 else 'it'}), got --level {args.level}"
        )
    scan = resolved_options(args.method, args.iterations, args.reimpose_every)[0] == "scan"
    if not args.level and args.fixed_boundary and scan:
        raise CLIError(
            "--fixed-boundary cannot be used with --method scan, the default (its boundary moves with "
            "the surface): add --method local or --method global"
        )
    mesh, out, report, seconds = run_file_op("denoise", args, run, (args.render, (".png",)))
    report["seconds"] = seconds
    run.say(
        f"denoised {args.input} ({len(mesh.vertices)} vertices) by {report['method']} fairing in {seconds:.2f} s "
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
        borders_left_open=0 if args.fill_border else sum(hole.border for hole in before),
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
    mesh, _, metrics, seconds = run_file_op("approximate", args, run, (args.indices, (".npy", ".txt")))
    indices = metrics.pop("_indices")
    if args.indices:
        np.save(args.indices, indices) if args.indices.endswith(".npy") else np.savetxt(
            args.indices, indices, fmt="%d"
        )
    run.say(
        f"approximated {args.input} from {len(indices)} control points in {seconds:.2f} s -> {args.output}; "
        f"L-inf error {metrics['error_linf']:.4g}, RMS {metrics['error_rms']:.4g}"
    )
    return run.finish(mesh, **metrics, seconds=seconds)


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
