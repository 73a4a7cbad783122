"""``o3d-lsmesh fill``: fill holes with faired patches."""

from __future__ import annotations

import argparse
import dataclasses
import time
from typing import Any

from ._common import Run, add_command, bounded
from ._files import check_output, read_input, write_output


def add_parsers(sub: Any, common: argparse.ArgumentParser) -> None:
    p = add_command(sub, common, fill, {"input": "mesh file", "output": "mesh file to write"})
    p.add_argument(
        "--max-hole-edges",
        type=bounded(int, 3, "integer >= 3"),
        help="fill only holes of at most this many edges (default: no limit)",
    )
    p.add_argument(
        "--max-hole-diameter", type=float, help="fill only holes at most this wide (default: no limit)"
    )
    p.add_argument(
        "--continuity", type=int, choices=(0, 1, 2), default=2, help="0 harmonic, 1 LS mesh, 2 tri-Laplacian"
    )
    p.add_argument(
        "--density", type=float, default=1.0, help="new vertex density relative to the surroundings (0 to 4)"
    )
    p.add_argument("--fill-border", action="store_true", help="also fill the outer border of open components")


def fill(args: argparse.Namespace, run: Run) -> int:
    """Fill holes with faired patches (LS meshes).

    Close holes: minimum-weight triangulation (Liepa 2003), refinement to the surrounding edge
    density, then LS-mesh fairing of the new vertices with the hole's rings as anchors. Each open
    component's outer border stays open unless --fill-border. --max-hole-diameter is in model units.
    Every loop left open is listed with why (outer border, size limits, every fill crossing the mesh).

    example: scan.ply filled.ply --max-hole-edges 200
    """
    check_output(args.output, [args.input], force=args.force)
    mesh = read_input(args.input)
    from .._o3d import read_mesh
    from ..hole_filling import fill_holes, find_holes

    def holes(mesh: Any) -> list:  # of the welded surface, as fill_holes sees it: a UV seam is no hole
        welded = read_mesh(mesh, weld=True)
        return find_holes(welded.vertices, welded.triangles)

    before = holes(mesh)
    start = time.perf_counter()
    names = ("max_hole_edges", "max_hole_diameter", "continuity", "density", "fill_border")
    out, report = fill_holes(
        mesh, **{name: getattr(args, name) for name in names}, progress=run.progress, return_report=True
    )
    seconds = time.perf_counter() - start
    write_output(args.output, out)
    after = holes(out)
    new_vertices = len(out.vertices) - len(mesh.vertices)
    run.say(
        f"filled {len(report.filled)} of {len(report.holes)} holes of {args.input} in {seconds:.2f} s "
        f"({new_vertices} new vertices) -> {args.output}; {len(after)} loops left open"
    )
    for hole in report.skipped:  # every loop left open, and why
        run.say(f"  left open: loop {hole.id} ({hole.edges} edges, diameter {hole.diameter:.4g}): {hole.how}")
    return run.finish(
        mesh,
        holes_before=len(before),
        holes_after=len(after),
        borders_left_open=0 if args.fill_border else sum(hole.border for hole in before),
        new_vertices=new_vertices,
        new_triangles=len(out.triangles) - len(mesh.triangles),
        holes_filled=len(report.filled),
        skipped=[dataclasses.asdict(hole) for hole in report.skipped],
        seconds=seconds,
    )
