"""``o3d-lsmesh demo``: denoise a simulated raw range scan and compare with Open3D's filters (``make demo``)."""

from __future__ import annotations

import argparse
from typing import Any

from ._common import Run, add_command, bounded, nonnegative_float

#: the scan has up to about 0.55 * resolution**2 vertices: 2000 gives about 2.2 million (about 3 GB to denoise)
MAX_RESOLUTION = 2000


def add_parsers(sub: Any, common: argparse.ArgumentParser) -> None:
    p = add_command(sub, common, demo, {})
    p.add_argument("--out", default="demo_out", help="output folder")
    p.add_argument("--no-render", action="store_true", help="skip the picture")
    p.add_argument(
        "--resolution",
        type=bounded(int, 20, "grid size of at least 20 rays", MAX_RESOLUTION),
        default=200,
        help="the scanner's grid of R x R rays (200: about 22,000 vertices)",
    )
    p.add_argument(
        "--noise",
        type=nonnegative_float,
        default=0.3,
        help="range noise in grid spacings where the surface faces the scanner",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed of the noise and dropouts")


def demo(args: argparse.Namespace, run: Run) -> int:
    """Denoise a simulated raw range scan and compare with Open3D's filters.

    Scan a built-in blob from one view on a scanner's grid (noise along the rays, correlated along
    the scanlines and larger at grazing angles, a ragged silhouette, islands and dropout holes),
    denoise it with this package's defaults and with Open3D's filters, each of those at the best
    count of a small sweep, and print the distances to the true surface (and a picture).

    example: --out demo_out --resolution 150
    """
    from ..demo import run_demo

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
