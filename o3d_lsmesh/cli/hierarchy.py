"""``o3d-lsmesh hierarchy``: write levels of the volume-cost collapse hierarchy."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from .._batch_ops import parse_levels
from ._common import CLIError, Run, add_command, mesh_suffix, positive_int
from ._files import check_output, read_input, write_output


def add_parsers(sub: Any, common: argparse.ArgumentParser) -> None:
    p = add_command(
        sub,
        common,
        hierarchy,
        {"input": "mesh file", "outdir": "folder for level_NN files (created if needed)"},
    )
    p.add_argument("--levels", default="all", help="'all' or comma-separated level numbers (0 is the input)")
    p.add_argument("--min-vertices", type=positive_int, default=100, help="stop at this many vertices")
    p.add_argument("--max-levels", type=positive_int, help="stop after this many levels (default: no limit)")
    p.add_argument(
        "--format", type=mesh_suffix, default=".ply", help="file format of the levels (.ply .obj ...)"
    )
    p.add_argument(
        "--maps", action="store_true", help="also write vertex_maps.npz (input vertex -> level vertex)"
    )


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
    from ..hierarchy import build_hierarchy

    start = time.perf_counter()
    built = build_hierarchy(
        mesh, min_vertices=args.min_vertices, max_levels=args.max_levels, progress=run.progress
    )
    seconds = time.perf_counter() - start
    chosen = parse_levels(args.levels, len(built))
    outdir.mkdir(parents=True, exist_ok=True)
    files: list[str] = []
    for level in chosen:
        path = str(outdir / f"level_{level:02d}{args.format}")
        check_output(path, [args.input], force=args.force, suffixes=None)
        write_output(path, built.level(level))
        files.append(path)
    if args.maps:  # each map composes the parents of every level above it: only when asked
        maps: dict[str, Any] = {f"level_{level:02d}": built.vertex_map(level) for level in chosen}
        np.savez_compressed(outdir / "vertex_maps.npz", **maps)
        files.append(str(outdir / "vertex_maps.npz"))
    counts = [int(built.vertex_count(i)) for i in range(len(built))]
    run.say(
        f"hierarchy of {args.input}: {len(built)} levels ({counts[0]} -> {counts[-1]} vertices) "
        f"in {seconds:.2f} s; wrote {len(files)} files to {outdir}/"
    )
    return run.finish(mesh, levels=len(built), vertex_counts=counts, written=files, seconds=seconds)
