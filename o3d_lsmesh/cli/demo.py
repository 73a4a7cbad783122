"""``o3d-lsmesh demo``: denoise a built-in noisy mesh and compare with Open3D's filters (``make demo``)."""

from __future__ import annotations

import argparse
from typing import Any

from ._common import Run, add_command, bounded, nonnegative_float

#: the demo's blob has 10 * 4**s + 2 vertices: 9 gives 2.6 million (about 3 GB to denoise), 12 would need 170 million
MAX_SUBDIVISIONS = 9


def add_parsers(sub: Any, common: argparse.ArgumentParser) -> None:
    p = add_command(sub, common, demo, {})
    p.add_argument("--out", default="demo_out", help="output folder")
    p.add_argument("--no-render", action="store_true", help="skip the picture")
    p.add_argument(
        "--subdivisions",
        type=bounded(int, 1, "positive integer", MAX_SUBDIVISIONS),
        default=6,
        help="size of the built-in mesh: 10 * 4**s + 2 vertices (6: 40,962)",
    )
    p.add_argument("--noise", type=nonnegative_float, default=0.3, help="noise sigma in mean edge lengths")
    p.add_argument("--seed", type=int, default=0, help="random seed of the noise")


def demo(args: argparse.Namespace, run: Run) -> int:
    """Denoise a built-in mesh and compare with Open3D's filters.

    Add noise to a built-in blob, denoise it with every method of this package and Open3D's
    filters, each at the best value of a small sweep, and print a table of errors (and a picture).

    example: --out demo_out --subdivisions 5
    """
    from ..demo import run_demo

    result = run_demo(
        args.out,
        subdivisions=args.subdivisions,
        noise=args.noise,
        seed=args.seed,
        render=not args.no_render,
        quiet=run.quiet,
        progress=run.progress,
        stream=run.stream,
    )
    return run.finish(**result)
