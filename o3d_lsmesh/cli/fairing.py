"""``o3d-lsmesh denoise``: barycenter-constrained or multiresolution fairing."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from ._common import WRITABLE, CLIError, Run, add_command, nonnegative_int, positive_int, shape_change_text
from ._files import check_output, read_input, write_output
from .compare import draw


def add_parsers(sub: Any, common: argparse.ArgumentParser) -> None:
    p = add_command(
        sub,
        common,
        denoise,
        {"input": "mesh file to denoise", "output": f"mesh file to write ({', '.join(WRITABLE)})"},
    )
    p.add_argument(
        "--iterations",
        type=nonnegative_int,
        help="number of fairing iterations (default: the API's, 10 for local; with --level, 5 per level)",
    )
    p.add_argument(
        "--method",
        choices=("scan", "local", "global", "features"),
        help="fairing energy (default: scan, the API's default; local with --level, --iterations or "
        "--reimpose-every); features keeps sharp creases (guided normal filtering)",
    )
    p.add_argument(
        "--level", type=nonnegative_int, default=0, help="multiresolution level (0: plain fairing)"
    )
    p.add_argument(
        "--mu", type=float, help="barycenter penalty weight of --method global or scan (default: the API's)"
    )
    p.add_argument(
        "--reimpose-every",
        type=positive_int,
        help="re-take the barycenters every k iterations (default: never)",
    )
    p.add_argument(
        "--fixed-boundary",
        action="store_true",
        help="keep boundary vertices fixed (default: smooth the boundary curves)",
    )
    p.add_argument("--render", metavar="PNG", help="write a before/after picture (default: none)")


def denoise(args: argparse.Namespace, run: Run) -> int:
    """Barycenter-constrained (or multiresolution) fairing.

    Remove noise with barycenter-constrained fairing (Liu et al. 2001, section 3): the membrane
    energy is minimized while every triangle keeps its barycenter. With --level L, multiresolution
    fairing (section 4.2): fair a coarse level of the volume-cost hierarchy, then split back up
    (--mu, --reimpose-every and --fixed-boundary are refused with it).

    example: scan.ply smooth.ply --iterations 20 --render before_after.png
    """
    options = {
        "--mu": args.mu,
        "--reimpose-every": args.reimpose_every,
        "--fixed-boundary": args.fixed_boundary or None,
    }
    given = [flag for flag, value in options.items() if value is not None]
    if args.level and given:
        # multiresolution fairing fairs every level with its own defaults: these options would be ignored
        raise CLIError(
            f"{', '.join(given)} cannot be combined with --level "
            f"(multiresolution fairing does not take {'them' if len(given) > 1 else 'it'}), got --level {args.level}"
        )
    check_output(args.output, [args.input], force=args.force)
    if args.render:
        check_output(args.render, [args.input], force=args.force, suffixes=(".png",))
    mesh = read_input(args.input)
    from .._batch_ops import TaskContext, denoise_op
    from ..fairing.constrained import resolved_options

    scan = resolved_options(args.method, args.iterations, args.reimpose_every)[0] == "scan"
    if not args.level and args.fixed_boundary and scan:
        raise CLIError(
            "--fixed-boundary cannot be used with --method scan, the default (its boundary moves with "
            "the surface): add --method local or --method global"
        )
    start = time.perf_counter()
    names = ("iterations", "method", "level", "mu", "reimpose_every", "fixed_boundary")
    context = TaskContext(args.input, args.input, None, progress=run.progress)
    out, report = denoise_op(mesh, {name: getattr(args, name) for name in names}, context)
    seconds = report["seconds"] = time.perf_counter() - start
    args.method, args.iterations = report["method"], report["iterations"]  # what ran, for the picture's title
    write_output(args.output, out)
    run.say(
        f"denoised {args.input} ({len(mesh.vertices)} vertices) by {report['method']} fairing in {seconds:.2f} s "
        f"-> {args.output}; "
        f"mean displacement {report['displacement_mean']:.4g}, {shape_change_text(report)}"
    )
    if args.render:
        method = f"{args.method} fairing" + (f", mu {args.mu:g}" if args.mu is not None else "")
        if args.level:
            method = f"multiresolution fairing, level {args.level}, {args.iterations} iterations per level"
        elif args.method not in ("scan", "features"):  # one solve / a measured pass count: no iteration count
            method += f", {args.iterations} iteration{'s' if args.iterations != 1 else ''}"
        titles = [f"input: {Path(args.input).name}", method]
        report["render"] = draw([mesh, out], args.render, run, titles=titles)
    return run.finish(mesh, **report)
