"""``o3d-lsmesh compare``: metrics between two meshes and a distance map; the reports and pictures of the other commands."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from .._batch_ops import normal_change
from ._common import PictureError, Run, add_command, bounded, shape_change_text
from ._files import check_output, read_input

#: metrics.MAX_SAMPLE_POINTS (not imported here: --help must not load the numeric modules)
MAX_POINTS = 10_000_000


def add_parsers(sub: Any, common: argparse.ArgumentParser) -> None:
    p = add_command(sub, common, compare, {"a": "first mesh file (the reference)", "b": "second mesh file"})
    p.add_argument(
        "--points",
        type=bounded(int, 1, "positive integer", MAX_POINTS),
        default=100_000,
        help="surface samples per mesh",
    )
    p.add_argument(
        "--render",
        metavar="PNG",
        help="write a distance map: A and B side by side, colored by distance to A (default: none)",
    )
    p.add_argument(
        "--units", choices=("model", "edge"), default="model", help="model units or mean edge lengths of A"
    )


def mesh_size(mesh: Any) -> dict[str, int]:
    return {"vertices": len(mesh.vertices), "triangles": len(mesh.triangles)}


def draw(
    meshes: list[Any], path: str, run: Run, *, what: str = "left: input, right: result", **options: Any
) -> str:
    """Draw ``meshes`` side by side into ``path``; :class:`PictureError` when no renderer works."""
    from ..rendering import render

    start = time.perf_counter()
    try:
        render(meshes, path, **options)
    except RuntimeError as error:  # Filament and the raycasting fallback both failed: not the input's fault
        raise PictureError(str(error)) from error
    run.say(f"picture ({time.perf_counter() - start:.1f} s): {path}  ({what})")
    return path


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
    from ..metrics import shape_change, surface_distance, topology_summary, triangle_angles, vertex_error

    report: dict[str, Any] = {"a": args.a, "b": args.b, "size_a": mesh_size(a), "size_b": mesh_size(b)}
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
    sd = report["surface_distance"]
    lines = [
        f"A {report['a']}: {report['size_a']['vertices']} vertices, "
        f"B {report['b']}: {report['size_b']['vertices']} vertices",
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
